//! When the thermistor reads nothing but the unit's own rise after each power-on
//! (`separate::soak_rise`), the die-rise rivals also take that rise alone as the die's path
//! (docs/diagnosis.md, section 4, the rivals of a turn-on term).
//!
//! The readings are written here, by code that shares nothing with the diagnosis: a die rising
//! with two time constants after power-on, a thermistor reading half of that rise (plus the
//! chamber's ramp, where there is one) in steps of 0.0625 °C, at 1 Hz.

use bins_cal::diagnose::mech::Context;
use bins_cal::diagnose::{prep, separate};
use bins_cal::recording::{Row, VibKind};
use std::path::Path;

/// The die's rise above the case `p` seconds after power-on [°C]: 1 °C, 80 % at 600 s and 20 %
/// at 150 s.
fn die_rise_c(p: f64) -> f64 {
    1.0 - 0.8 * (-p / 600.0).exp() - 0.2 * (-p / 150.0).exp()
}

/// Sessions of `len_s` each (power on at each start, an hour unpowered between), the case at
/// `case_c(t)`, the thermistor reading the case plus half the die's rise, quantised.
fn rows(sessions: usize, len_s: usize, case_c: impl Fn(f64) -> f64) -> Vec<Row> {
    let mut out = Vec::new();
    let mut t0 = 0.0;
    for _ in 0..sessions {
        for k in 0..len_s {
            let t = t0 + k as f64;
            let reading = case_c(t) + 0.5 * die_rise_c(k as f64);
            out.push(Row {
                line: out.len() as u64 + 2,
                t_s: t,
                temp_c: (reading / 0.0625).round() * 0.0625,
                f_g: [0.0, 0.0, 1.0].map(Some),
                vib_kind: Some(VibKind::None),
                vib_g: [Some(0.0); 3],
                power_s: Some(k as f64),
                // A deterministic wiggle of 10 µV for a signal the reading accepts.
                u_v: [(0.37 * t).sin(), (0.71 * t).cos(), 1e5 + (1.3 * t).sin()].map(|v| 1e-5 * v),
                ..Row::default()
            });
        }
        t0 += len_s as f64 + 3600.0;
    }
    out
}

fn soak_rise(rows: &[Row]) -> Option<Vec<(std::ops::Range<usize>, f64, f64)>> {
    let p = prep::prepare(rows, rows, Path::new("sim.csv"), Path::new("real.csv")).expect("prepared");
    separate::soak_rise(&Context::new(&p, 0))
}

#[test]
fn a_soak_reads_as_its_start_and_the_rise_it_sees() {
    let s = soak_rise(&rows(1, 2400, |_| 52.0)).expect("a soak");
    assert_eq!(s.len(), 1);
    let (r, t0_c, rise_c) = &s[0];
    assert_eq!(*r, 0..2400);
    // The thermistor sees half of the die's rise, which reaches 0.98 of its 1 °C by 2400 s.
    assert!((t0_c - 52.0).abs() < 0.05, "start {t0_c:.3} °C");
    assert!((rise_c - 0.5).abs() < 0.1, "rise {rise_c:.3} °C");
}

#[test]
fn soaks_joined_read_per_session() {
    let s = soak_rise(&rows(2, 2400, |t| if t < 2400.0 { 52.0 } else { 30.0 })).expect("two soaks");
    let starts: Vec<f64> = s.iter().map(|x| x.1).collect();
    assert!((starts[0] - 52.0).abs() < 0.05 && (starts[1] - 30.0).abs() < 0.05, "{starts:?}");
}

#[test]
fn a_ramp_is_not_a_soak() {
    // 0.3 °C/min from 20 °C: 12 °C over the session, far from any start and one rise.
    assert!(soak_rise(&rows(1, 2400, |t| 20.0 + 0.3 * t / 60.0)).is_none());
    // Nor is a soak of which one session ramps.
    assert!(soak_rise(&rows(2, 2400, |t| if t < 2400.0 { 52.0 } else { 30.0 - 0.3 * (t - 6000.0) / 60.0 })).is_none());
}
