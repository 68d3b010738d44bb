//! SIM made by a simulation of its own (not `--calib`, not driven by REAL's `temp_C`) reads its
//! own temperature: where REAL's sensor lags, REAL's thermistor reads differently from SIM's.
//! SIM's temperature sensitivity, which every thermal term is built from, is a function of SIM's
//! own temperature ([`bins_cal::diagnose::mech::fit_sensitivity`] on
//! [`bins_cal::diagnose::prep::Prepared::sim_temp_s`]); fitted against REAL's it is biased.
//!
//! The pair: a case cooled at 1 °C/min from 20 °C to −20 °C (the case a first-order lag of
//! 300 s behind the chamber), then held. SIM's sensor and thermistor follow the case. REAL's
//! constants follow a die 120 s behind the case, and its thermistor sits 0.3 of the way from
//! case to die, so REAL's `temp_C` is up to 0.6 °C warmer than SIM's while it cools. The bias is
//! quadratic in temperature (80 µg/°C, 1.5 µg/°C²) on every accelerometer, 1 V/g, white noise 20 µg.

use bins_cal::diagnose::{Options, diagnose_with, mech, prep};
use bins_cal::recording::Row;
use rand::SeedableRng;
use rand_distr::Distribution;
use std::path::Path;

const B1_G_PER_C: f64 = 80e-6;
const B2_G_PER_C2: f64 = 1.5e-6;

fn bias_g(temp_c: f64) -> f64 {
    let d = temp_c - 20.0;
    B1_G_PER_C * d + B2_G_PER_C2 * d * d
}

fn pair() -> (Vec<Row>, Vec<Row>) {
    let (dt, n) = (1.0, 10_800);
    let mut rng = rand::rngs::StdRng::seed_from_u64(11);
    let normal = rand_distr::Normal::new(0.0, 20e-6).expect("a normal");
    let lag = |x: &mut f64, u: f64, tau: f64| *x += (u - *x) * (1.0 - (-dt / tau).exp());
    let (mut case_c, mut die_c) = (20.0f64, 20.0f64);
    let (mut sim, mut real) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for k in 0..n {
        let t = k as f64 * dt;
        let chamber_c = (20.0 - t / 60.0).max(-20.0);
        lag(&mut case_c, chamber_c, 300.0);
        lag(&mut die_c, case_c, 120.0);
        let real_temp_c = case_c + 0.3 * (die_c - case_c);
        // A second orientation for the scale factors: every tenth minute upside down.
        let fz = if (k / 60) % 10 == 9 { -1.0 } else { 1.0 };
        let row = |temp_c: f64, b: f64, noise: [f64; 3]| Row {
            line: k as u64 + 2,
            t_s: t,
            u_v: [b + noise[0], b + noise[1], fz + b + noise[2]],
            temp_c: (temp_c * 100.0).round() / 100.0,
            f_g: [Some(0.0), Some(0.0), Some(fz)],
            power_s: Some(1e5 + t),
            ..Row::default()
        };
        sim.push(row(case_c, bias_g(case_c), [0.0; 3]));
        let noise = [0, 1, 2].map(|_| normal.sample(&mut rng));
        real.push(row(real_temp_c, bias_g(die_c), noise));
    }
    (sim, real)
}

/// SIM's bias slope at 20 °C as fitted: the first-order bias coefficient [g/°C].
fn slope(p: &prep::Prepared, axis: usize) -> f64 {
    let s = mech::fit_sensitivity(p, axis);
    assert!(s.from_sim, "SIM's temperature terms are significant");
    s.c[0][0]
}

#[test]
fn sims_sensitivity_is_fitted_against_sims_own_temperature() {
    let (sim, real) = pair();
    let (sp, rp) = (Path::new("sim.csv"), Path::new("real.csv"));
    let p = prep::prepare(&sim, &real, sp, rp).expect("prepared");
    let diff = p.temp_s.iter().zip(&p.sim_temp_s).fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    assert!(diff > 0.4, "REAL's thermistor reads up to {diff:.3} °C off SIM's");
    assert!(p.notes.iter().any(|n| n.starts_with("SIM's temp_C is not REAL's")), "{:?}", p.notes);

    // Against SIM's own temperature the fit is SIM's law (to the 0.01 °C rounding of temp_C);
    // against REAL's, which runs warm while cooling, the slope comes out off.
    let own = slope(&p, 0);
    assert!((own - B1_G_PER_C).abs() < 0.01 * B1_G_PER_C, "slope {own:e} g/°C, SIM's {B1_G_PER_C:e}");
    let mut wrong = p.clone();
    wrong.sim_temp_s = wrong.temp_s.clone();
    let biased = slope(&wrong, 0);
    println!(
        "bias slope: SIM's law {B1_G_PER_C:e}, fitted against SIM's temp_C {own:e}, against REAL's {biased:e} g/°C"
    );
    assert!(
        (biased - B1_G_PER_C).abs() > 3.0 * (own - B1_G_PER_C).abs().max(1e-9),
        "against REAL's temperature: {biased:e} g/°C, against SIM's {own:e}, SIM's law {B1_G_PER_C:e}"
    );

    // The die lag is what the diagnosis names, on every accelerometer.
    let rep = diagnose_with(&sim, &real, sp, rp, &Options::default()).expect("diagnosed").report;
    let named: Vec<(&str, &[String])> = rep.effects.iter().map(|e| (e.id.as_str(), e.axes.as_slice())).collect();
    println!("named {named:?}; before {:?} after {:?}", rep.heldout_rms_before_mg, rep.heldout_rms_after_mg);
    let lag = rep.effects.iter().find(|e| e.id == "thermal_lag").expect("thermal_lag named");
    assert_eq!(lag.axes, ["x", "y", "z"]);
    for ax in ["x", "y", "z"] {
        let (before, after, floor) =
            (rep.heldout_rms_before_mg[ax], rep.heldout_rms_after_mg[ax], rep.noise_floor_mg[ax]);
        assert!(after < before && after < 1.1 * floor, "{ax}: held-out {before} → {after} mg, floor {floor} mg");
    }
}
