//! In one orientation a play of a temperature the thermistor does not follow is an additive
//! bias play with the sign a held temperature gives (docs/diagnosis.md, section 4, "A play in
//! one orientation"): the report must not name the additive play alone.
//!
//! The pair (1 Hz, simulated here, sharing no code with the diagnosis), drawn as a user records
//! a chamber run: one power-on at the start, a hold at −9 °C, then one monotone ramp to +10 °C
//! at 0.5 °C/min; the case follows the chamber with a 670 s lag. The die self-heats 1.1 °C
//! after power-on (τ 285 s); the thermistor sits 38 % of the way from the case to the die, and
//! `temp_C` reads it in steps of 1/128 °C. The unit stays in one orientation. SIM was calibrated
//! in steady state, so its bias is REAL's curve at the thermistor's settled offset from the die.
//! REAL's sensing element follows the die through a play `PLAY_C` wide; white noise 8 µg.
//!
//! The negative control is `diagnose_play_resolution`: an additive difference of the other
//! sign (a bias higher while warming on a rising slope) is named as an additive play, not
//! grouped with a thermal one.

use bins_cal::diagnose::{Options, diagnose_with};
use bins_cal::recording::Row;
use rand::SeedableRng;
use rand_distr::Distribution;
use std::path::Path;

const PLAY_C: f64 = 2.0;
const RISE_C: f64 = 1.1;
const RISE_TAU_S: f64 = 285.0;
const THERMISTOR_SHARE: f64 = 0.38;

/// REAL's bias at the sensing element's temperature `temp_c` \[g\].
fn bias_g(temp_c: f64) -> f64 {
    let d = temp_c - 20.0;
    60e-6 * d + 1.0e-6 * d * d - 20e-9 * d * d * d
}

fn pair() -> (Vec<Row>, Vec<Row>) {
    let (hold_s, ramp_s) = (980.0, 2300.0);
    let (cold_c, warm_c) = (-9.0, 10.0);
    let n = (hold_s + ramp_s) as usize;
    let mut rng = rand::rngs::StdRng::seed_from_u64(11);
    let normal = rand_distr::Normal::new(0.0, 8e-6).expect("a normal");
    let (mut sim, mut real) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let mut case_c = cold_c;
    let mut held_c = case_c;
    // SIM's calibration saw the thermistor this far below the die once settled.
    let settled_offset_c = (1.0 - THERMISTOR_SHARE) * RISE_C;
    for k in 0..n {
        let t = k as f64;
        let chamber_c = if t < hold_s { cold_c } else { cold_c + (warm_c - cold_c) * (t - hold_s) / ramp_s };
        case_c += (chamber_c - case_c) * (1.0 - (-1.0f64 / 670.0).exp());
        let rise_c = RISE_C * (1.0 - (-t / RISE_TAU_S).exp());
        let die_c = case_c + rise_c;
        let thermistor_c = case_c + THERMISTOR_SHARE * rise_c;
        held_c = held_c.clamp(die_c - 0.5 * PLAY_C, die_c + 0.5 * PLAY_C);
        let read_c = (thermistor_c * 128.0).round() / 128.0;
        let row = |b: f64, noise: [f64; 3]| Row {
            line: k as u64 + 2,
            t_s: t,
            u_v: [b + noise[0], b + noise[1], 1.0 + b + noise[2]],
            temp_c: read_c,
            power_s: Some(t),
            f_g: [Some(0.0), Some(0.0), Some(1.0)],
            ..Row::default()
        };
        sim.push(row(bias_g(read_c + settled_offset_c), [0.0; 3]));
        let noise = [0, 1, 2].map(|_| normal.sample(&mut rng));
        real.push(row(bias_g(held_c), noise));
    }
    (sim, real)
}

#[test]
fn a_held_temperature_in_one_orientation_is_not_named_an_additive_play_alone() {
    let (sim, real) = pair();
    let rep = diagnose_with(&sim, &real, Path::new("sim.csv"), Path::new("real.csv"), &Options::default())
        .expect("diagnosed")
        .report;
    println!("named {:?}", rep.effects.iter().map(|e| (&e.id, &e.axes, &e.params)).collect::<Vec<_>>());
    println!("ambiguous {:?}", rep.ambiguous.iter().map(|a| (&a.ids, &a.axes, &a.modelled_as)).collect::<Vec<_>>());
    println!(
        "held-out before {:?} after {:?}; negligible {:?}",
        rep.heldout_rms_before_mg,
        rep.heldout_rms_after_mg,
        rep.negligible.iter().map(|n| (&n.id, &n.axis)).collect::<Vec<_>>()
    );
    let mut seen = 0;
    for ax in ["x", "y", "z"] {
        let additive = rep.effects.iter().any(|e| e.id == "bias_hysteresis" && e.axes.iter().any(|a| a == ax));
        assert!(!additive, "{ax}: the additive play is named alone where a held temperature makes the same");
        let grouped = rep.ambiguous.iter().any(|g| {
            g.axes.iter().any(|a| a == ax)
                && g.ids.iter().any(|i| i == "thermal_hysteresis")
                && g.ids.iter().any(|i| i == "bias_hysteresis")
        });
        let thermal = rep.effects.iter().any(|e| e.id == "thermal_hysteresis" && e.axes.iter().any(|a| a == ax));
        seen += usize::from(grouped || thermal);
    }
    assert_eq!(seen, 3, "the play is found on every accelerometer, as a thermal play or with one");
}
