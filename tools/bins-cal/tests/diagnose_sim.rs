//! `diagnose` on pairs made by the project's simulator (`bins_cal::sim`), not by the
//! diagnosis's own case generator: the paper's unit on the tilter during chamber ramps and
//! soaks, moves between positions (reference unknown, skipped), ADC quantisation and a
//! thermistor with resolution. SIM: no die lag, no noise. REAL: the die lags the case (where
//! the thermistor sits) by τ, plus noise; and a null pair that differs by noise only.

use bins_cal::diagnose::diagnose;
use bins_cal::recording::Row;
use bins_cal::sim::scenario::ScenarioFile;
use std::path::Path;

fn scenario(die_tau_s: f64, noise: bool) -> String {
    let mut s = String::from(
        "description = \"diagnose test: tilter during ramps and soaks\"\n\
         [recording]\nrate_Hz = 1.0\npower_on_s = 100000.0\n\
         [unit]\npreset = \"paper\"\nfit = \"poly\"\norder = 2\n\
         [thermal]\nstart_C = 20.0\nrate_C_per_min = 1.0\ncase_tau_s = 30.0\nthermistor_at = 0.0\n",
    );
    s += &format!("die_tau_s = {die_tau_s}\n");
    if noise {
        s += "[noise]\nwhite_V = 1.0e-5\nrandom_walk_V_per_sqrt_s = 2.0e-7\nbias_instability_V = 3.0e-6\nbias_tau_s = 300.0\n\
              adc_lsb_V = 1.0e-7\ntemp_noise_C = 0.005\ntemp_resolution_C = 0.01\n";
    }
    for (set, steps) in [(50.0, 8), (0.0, 11), (35.0, 8), (20.0, 5)] {
        s += &format!("[[step]]\nkind = \"soak\"\nchamber_C = {set}\ndwell_s = 10.0\n");
        for _ in 0..steps {
            s += "[[step]]\nkind = \"tilter\"\ndwell_s = 50.0\nmove_s = 10.0\n";
        }
    }
    s
}

fn rows(text: &str, seed: u64) -> Vec<Row> {
    ScenarioFile::parse(text, Path::new("test.toml")).unwrap().build(Path::new("test.toml")).unwrap().all_rows(seed)
}

#[test]
fn simulator_die_lag_is_found_and_noise_alone_is_not() {
    let sim = rows(&scenario(0.0, false), 1);
    let real_lag = rows(&scenario(150.0, true), 2);
    let real_null = rows(&scenario(0.0, true), 3);
    assert_eq!(sim.len(), real_lag.len());
    let d = diagnose(&sim, &real_lag, Path::new("sim"), Path::new("real")).unwrap();
    let r = &d.report;
    println!(
        "simulator pair, {} rows ({} used): effects {:?}",
        r.rows,
        r.rows_used,
        r.effects.iter().map(|e| (&e.id, &e.axes, &e.params)).collect::<Vec<_>>()
    );
    println!("  ambiguous {:?}", r.ambiguous.iter().map(|a| (&a.ids, &a.axes)).collect::<Vec<_>>());
    println!(
        "  held-out RMS {:?} → {:?} mg, floor {:?} mg",
        r.heldout_rms_before_mg, r.heldout_rms_after_mg, r.noise_floor_mg
    );
    assert!(r.rows_used < r.rows, "moves are skipped");
    assert_eq!(r.effects.len(), 1, "{:?}", r.effects);
    let e = &r.effects[0];
    assert_eq!(e.id, "thermal_lag");
    assert_eq!(e.axes, ["x", "y", "z"]);
    for ax in ["x", "y", "z"] {
        let tau = e.params[ax]["tau_s"];
        assert!((tau / 150.0 - 1.0).abs() < 0.2, "{ax}: τ = {tau}");
        let (b, a, fl) = (r.heldout_rms_before_mg[ax], r.heldout_rms_after_mg[ax], r.noise_floor_mg[ax]);
        assert!(a <= 1.25 * fl || b >= 3.0 * a, "{ax}: {b} → {a}, floor {fl}");
    }
    assert!(r.ambiguous.is_empty(), "{:?}", r.ambiguous);
    let d0 = diagnose(&sim, &real_null, Path::new("sim"), Path::new("real")).unwrap();
    println!("simulator null pair: effects {:?}, ambiguous {:?}", d0.report.effects.len(), d0.report.ambiguous.len());
    assert!(d0.report.effects.is_empty(), "{:?}", d0.report.effects);
    assert!(d0.report.ambiguous.is_empty(), "{:?}", d0.report.ambiguous);
}

/// SIM for a real recording: the twin without die lag follows REAL (its reference,
/// thermistor reading and power-on time, row for row: `bins-cal simulate --follow`), and the
/// diagnosis of REAL against it finds the die lag the twin does not have, and nothing else.
#[test]
fn the_twin_following_a_recording_reveals_its_die_lag() {
    let text = scenario(0.0, false);
    let twin = ScenarioFile::parse(&text, Path::new("test.toml")).unwrap().build(Path::new("test.toml")).unwrap();
    let real = rows(&scenario(150.0, true), 2);
    let sim = twin.follow(&real);
    assert_eq!(sim.len(), real.len());
    assert!(sim.iter().zip(&real).all(|(s, r)| s.t_s == r.t_s && s.temp_c == r.temp_c && s.f_g == r.f_g));
    let d = diagnose(&sim, &real, Path::new("sim"), Path::new("real")).unwrap();
    let r = &d.report;
    println!(
        "followed pair: effects {:?}, ambiguous {:?}",
        r.effects.iter().map(|e| (&e.id, &e.axes, &e.params)).collect::<Vec<_>>(),
        r.ambiguous.iter().map(|a| (&a.ids, &a.axes)).collect::<Vec<_>>()
    );
    let named: Vec<&str> = r.effects.iter().map(|e| e.id.as_str()).collect();
    assert_eq!(named, ["thermal_lag"], "{:?}", r.effects);
    assert_eq!(r.effects[0].axes, ["x", "y", "z"]);
    for ax in ["x", "y", "z"] {
        let tau = r.effects[0].params[ax]["tau_s"];
        assert!((tau / 150.0 - 1.0).abs() < 0.25, "{ax}: τ = {tau}");
    }
}
