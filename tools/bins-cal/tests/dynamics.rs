//! Identification of the thermal dynamics (`calib::dynamics`) on simulated tilter recordings
//! against the simulator's truth, and with no dynamics simulated.

use bins_cal::calib::dynamics::{self, Request, Series};
use bins_cal::calib::segments::Options;
use bins_cal::sim::scenario;
use bins_comp::Method;
use std::path::Path;

use common::repo;

/// Simulates `scenario_text` (seed 1) into `dir`, reads it as a series.
fn series(dir: &Path, scenario_text: &str) -> Series {
    let toml = dir.join("s.toml");
    std::fs::write(&toml, scenario_text).unwrap();
    let sim = scenario::load(&toml).unwrap();
    let rec = dir.join("rec.csv");
    sim.write("s.toml", 1, &rec, false).unwrap();
    let opt = Options { settle_s: 1.0, max_std_v: 0.01, max_rate_c_per_min: 0.5, temp_tol_c: 3.0 };
    Series::read(&rec, &opt, "TP", 10.0).unwrap()
}

fn request() -> Request {
    Request { order: 2, t0_c: 20.0, k_prior: [[0.0; 3]; 3], method: Method::CoefficientCorrection }
}

#[test]
fn identifies_the_lag_the_play_and_the_bias_play_of_the_simulated_unit() {
    let tmp = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(repo("scenarios/dynamics-tilter.toml")).unwrap();
    let s = series(tmp.path(), &text);
    let id = dynamics::identify(std::slice::from_ref(&s), &request(), &mut |l| eprintln!("{l}")).unwrap();
    for c in &id.components {
        eprintln!("{c:?}");
    }
    let th = id.fit.theta;
    eprintln!("identified {th:?}, bias play {:?} mg", id.fit.bias_play_g.map(|b| b * 1e3));
    eprintln!(
        "rms static {:?} µg, dynamic {:?} µg",
        id.static_fit.rms_g().map(|r| r * 1e6),
        id.fit.rms_g().map(|r| r * 1e6)
    );
    // The scenario's truth.
    let rel = |got: f64, truth: f64| (got - truth).abs() / truth;
    assert!(rel(th.lag_tau_s, 180.0) < 0.2, "τ = {} s, truth 180 s", th.lag_tau_s);
    assert!(rel(th.hysteresis_width_c, 1.0) < 0.2, "h = {} °C, truth 1 °C", th.hysteresis_width_c);
    assert!(rel(th.bias_play_width_c, 4.0) < 0.2, "h_b = {} °C, truth 4 °C", th.bias_play_width_c);
    for (got, truth) in id.fit.bias_play_g.iter().zip([0.3e-3, -0.2e-3, 0.25e-3]) {
        assert!((got - truth).abs() < 0.2 * truth.abs(), "bias play {got} g, truth {truth} g");
    }
}

#[test]
fn identifies_no_dynamics_when_none_is_simulated() {
    let tmp = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(repo("scenarios/dynamics-tilter.toml")).unwrap();
    let text = text
        .replace("die_tau_s = 180.0", "die_tau_s = 0.0")
        .replace("hysteresis_C = 1.0", "hysteresis_C = 0.0")
        .replace("bias_play_mg = [0.3, -0.2, 0.25]", "bias_play_mg = [0.0, 0.0, 0.0]");
    let s = series(tmp.path(), &text);
    let id = dynamics::identify(std::slice::from_ref(&s), &request(), &mut |l| eprintln!("{l}")).unwrap();
    for c in &id.components {
        eprintln!("{c:?}");
        assert!(!c.on, "{} identified where none was simulated: {c:?}", c.name);
    }
    assert_eq!(id.fit.theta, dynamics::Theta::default());
}

#[allow(dead_code)] // the helpers other test files use
mod common;

#[test]
fn a_diagnosis_merges_into_a_calibration_and_bad_tables_name_the_file_and_key() {
    let tmp = tempfile::tempdir().unwrap();
    let p = |n: &str| tmp.path().join(n).to_string_lossy().into_owned();
    let sc = |n: &str| repo(&format!("scenarios/{n}")).to_string_lossy().into_owned();
    common::ok(&["simulate", &sc("test-tilter-3t.toml"), "-o", &p("cal.csv"), "--seed", "1"]);
    common::ok(&["calibrate", "--tilter", &p("cal.csv"), "--model", "poly:2", "-o", &p("unit.toml")]);
    common::ok(&["simulate", &sc("diagnose-ramps.toml"), "-o", &p("ramps.csv"), "--seed", "2"]);
    common::ok(&[
        "diagnose",
        "--calib",
        &p("unit.toml"),
        "--real",
        &p("ramps.csv"),
        "--report",
        &p("d.json"),
        "--model",
        &p("model.toml"),
    ]);
    // The diagnosis names the die lag (150 s in the scenario) and writes it as the table.
    let model = bins_cal::calfile::DynamicsSpec::read_table(Path::new(&p("model.toml"))).unwrap();
    assert!((model.lag_tau_s - 150.0).abs() < 0.2 * 150.0, "{model:?}");
    // `calibrate` of the tilter recording with the table of `table` merged, written to `out`.
    let merge = |table: &str, out: &str| -> Vec<String> {
        ["calibrate", "--tilter", &p("cal.csv"), "--model", "poly:2", "--dynamics", &p(table), "-o", &p(out)]
            .map(String::from)
            .to_vec()
    };
    let mut args = merge("model.toml", "unit-dyn.toml");
    args.extend(["--blob".into(), p("unit-dyn.bin")]);
    common::ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let file = bins_cal::calfile::CalibrationFile::read(Path::new(&p("unit-dyn.toml"))).unwrap();
    assert_eq!(file.thermal_dynamics, Some(model));
    // The blob carries it: back to the same table.
    let blob = std::fs::read(p("unit-dyn.bin")).unwrap();
    assert_eq!(bins_cal::calfile::CalibrationFile::from_blob(&blob).unwrap().thermal_dynamics, Some(model));
    // Errors name the file and the key; nothing is written.
    for (text, key) in [
        ("[thermal_dynamics]\nlag_tau = 3.0\n", "lag_tau"),
        ("[thermal_dynamics]\nlag_tau_s = -3.0\n", "thermal_dynamics.lag_tau_s"),
        ("[thermal_dynamics]\nbias_play_mg = [1.0, 0.0, 0.0]\n", "bias_play_mg"),
        ("[other]\nx = 1\n", "[thermal_dynamics]"),
    ] {
        std::fs::write(p("bad.toml"), text).unwrap();
        let e = common::err(&merge("bad.toml", "out.toml").iter().map(String::as_str).collect::<Vec<_>>());
        assert!(e.contains("bad.toml") && e.contains(key), "{text:?}: {e}");
        assert!(!tmp.path().join("out.toml").exists());
    }
    let e = common::err(&["calibrate", "--tilter", &p("cal.csv"), "--dynamics", "identify", "-o", &p("out.toml")]);
    assert!(e.contains("--model poly:N"), "{e}");
}
