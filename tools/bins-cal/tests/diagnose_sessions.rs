//! Several sessions of one unit joined in one recording (docs/recording-format.md,
//! "Sessions"): the diagnosis restarts the noise model's level and the temperature's smoothing
//! at each, runs a lag or a play on through the joins, and says how many sessions it read.
//!
//! The pairs are written here, by code that shares nothing with the diagnosis: a unit whose
//! bias is cubic in temperature (SIM and REAL alike), recorded at 1 Hz in sessions of 1.5 h
//! with an hour unpowered between them, the chamber ramping on through the gap.

use bins_cal::diagnose::{diagnose, prep};
use bins_cal::recording::{Row, VibKind};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use std::path::Path;

/// White noise of REAL [V] (scale 1 V/g: 20 µg).
const SIGMA: f64 = 20e-6;

/// The unit's bias [V] at `temp_c` (SIM and REAL).
fn bias(temp_c: f64) -> f64 {
    1e-4 * (temp_c - 20.0) + 2e-7 * (temp_c - 20.0).powi(3)
}

/// The chamber's temperature [°C] at `t_s`: a triangle in time, up 0.3 °C/min from −5 °C for
/// 1.5 h, then down.
fn chamber_c(t_s: f64) -> f64 {
    let ph = (t_s % (2.0 * 5400.0)) / 5400.0;
    if ph < 1.0 { -5.0 + 27.0 * ph } else { 22.0 - 27.0 * (ph - 1.0) }
}

/// The sign of each accelerometer's output to the bias: x and z as mounted, y reversed.
const MOUNT: [f64; 3] = [1.0, -1.0, 1.0];

/// SIM's row at `t_s` (the unit z up at `temp_c`, the bias through [`MOUNT`]) and REAL's: SIM's
/// plus `departure_v(i)` and a draw of `noise_v()` on each accelerometer `i`, in axis order.
fn rows(
    line: u64,
    t_s: f64,
    temp_c: f64,
    power_s: f64,
    departure_v: impl Fn(usize) -> f64,
    noise_v: &mut dyn FnMut() -> f64,
) -> (Row, Row) {
    let b = bias(temp_c);
    let sim = Row {
        line,
        t_s,
        temp_c,
        f_g: [0.0, 0.0, 1.0].map(Some),
        vib_kind: Some(VibKind::None),
        vib_g: [Some(0.0); 3],
        power_s: Some(power_s),
        u_v: [MOUNT[0] * b, MOUNT[1] * b, 1.0 + MOUNT[2] * b],
        ..Row::default()
    };
    let mut real = sim.clone();
    for i in 0..3 {
        real.u_v[i] += departure_v(i) + noise_v();
    }
    (sim, real)
}

/// `sessions` sessions of `len_s` at 1 Hz, `gap_s` between them; the chamber runs a triangle of
/// ±0.3 °C/min between −5 and +22 °C (on through the gaps); REAL departs from SIM by
/// `offset(session)` and, with `lag_tau_s`, by the bias at a temperature lagging the
/// thermistor's (first order, from equilibrium at the start, following the chamber every
/// second through the gaps too); with `power_only`, no time gap: a power cycle between the
/// sessions.
fn pair(
    sessions: usize,
    len_s: usize,
    gap_s: f64,
    power_only: bool,
    offset: impl Fn(usize) -> f64,
    lag_tau_s: Option<f64>,
    seed: u64,
) -> (Vec<Row>, Vec<Row>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let white = Normal::new(0.0, SIGMA).unwrap();
    let (mut sim, mut real) = (Vec::new(), Vec::new());
    let mut t0 = 0.0;
    let mut line = 2;
    let mut lagged: Option<f64> = None;
    // Euler in 10 sub-steps of one second (the input held).
    let lag_step = |x: f64, temp_c: f64, tau: f64| (0..10).fold(x, |x, _| x + 0.1 / tau * (temp_c - x));
    for s in 0..sessions {
        if s > 0
            && let (Some(x), Some(tau)) = (lagged, lag_tau_s)
        {
            // The unpowered unit follows the chamber through the gap.
            let gap_start = t0 - gap_s;
            lagged = Some((0..gap_s as usize).fold(x, |x, k| lag_step(x, chamber_c(gap_start + k as f64), tau)));
        }
        for k in 0..len_s {
            let t = t0 + k as f64;
            let temp_c = chamber_c(t);
            let te: f64 = match (lagged, lag_tau_s) {
                (Some(x), Some(tau)) => lag_step(x, temp_c, tau),
                _ => temp_c,
            };
            lagged = Some(te);
            let lag_extra = bias(te) - bias(temp_c);
            let (row, r) =
                rows(line, t, temp_c, k as f64, |i| offset(s) + MOUNT[i] * lag_extra, &mut || white.sample(&mut rng));
            sim.push(row);
            real.push(r);
            line += 1;
        }
        t0 += len_s as f64 + if power_only { 0.0 } else { gap_s };
    }
    (sim, real)
}

#[test]
fn sessions_joined_with_unpowered_gaps_are_read_as_sessions() {
    // A turn-on bias that differs from session to session (200 σ): not a mechanism, not a
    // step, and it must not leave structure for one.
    let (sim, real) = pair(3, 5400, 3600.0, false, |s| [0.0, 4e-3, -2e-3][s], None, 1);
    let d = diagnose(&sim, &real, Path::new("sim.csv"), Path::new("real.csv")).expect("diagnosis runs");
    assert_eq!(d.prepared.session_starts, vec![0, 5400, 10_800]);
    let r = &d.report;
    assert!(r.notes.iter().any(|n| n.starts_with("3 sessions")), "{:?}", r.notes);
    assert!(r.effects.is_empty() && r.ambiguous.is_empty(), "{:?} {:?}", r.effects, r.ambiguous);
    assert!(r.steps.is_empty(), "{:?}", r.steps);
    for ax in ["x", "y", "z"] {
        // "Before" removes one offset per session: what is left is the white noise.
        let before = r.heldout_rms_before_mg[ax];
        assert!((before - SIGMA * 1e3).abs() < 0.15 * SIGMA * 1e3, "{ax}: {before} mg");
    }
}

#[test]
fn a_power_cycle_within_the_sampling_is_one_session_and_a_late_one_two() {
    // `power_s` goes back with no time missing: the temperature was recorded throughout, one
    // session (a turn-on jump of the bias is a step).
    let (sim, real) = pair(2, 5400, 0.0, true, |s| [0.0, 3e-3][s], None, 2);
    let d = diagnose(&sim, &real, Path::new("sim.csv"), Path::new("real.csv")).expect("diagnosis runs");
    assert_eq!(d.prepared.session_starts, vec![0]);
    assert!(d.report.effects.is_empty(), "{:?}", d.report.effects);
    let step = d.report.steps.iter().find(|s| (s.time_s - 5400.0).abs() < 2.0);
    assert!(step.is_some_and(|s| (s.size_mg - 3.0).abs() < 0.1), "{:?}", d.report.steps);
    // Off for 30 s (30 steps of 1 s): a session of its own.
    let (sim, real) = pair(2, 5400, 30.0, false, |s| [0.0, 3e-3][s], None, 2);
    let d = diagnose(&sim, &real, Path::new("sim.csv"), Path::new("real.csv")).expect("diagnosis runs");
    assert_eq!(d.prepared.session_starts, vec![0, 5400]);
    assert!(d.report.effects.is_empty() && d.report.steps.is_empty(), "{:?}", d.report.effects);
}

#[test]
fn a_logger_pause_while_the_unit_stays_powered_is_one_session() {
    // Two files of one powered run: `power_s` advances with `t_s` across the hour.
    let (sim, mut real) = pair(2, 3600, 3600.0, false, |_| 0.0, None, 3);
    let mut sim = sim;
    for rows in [&mut sim, &mut real] {
        for r in rows.iter_mut() {
            r.power_s = Some(r.t_s + 100.0);
        }
    }
    let p = prep::prepare(&sim, &real, Path::new("sim.csv"), Path::new("real.csv")).expect("prepared");
    assert_eq!(p.session_starts, vec![0]);
}

#[test]
fn a_lag_runs_on_through_the_gaps() {
    // The die lags the thermistor by 300 s and follows the chamber through the 45 min
    // unpowered between the sessions, so it starts the second one 1.5 °C from the
    // thermistor's reading (the chamber cooling at 0.3 °C/min). The lag is found, with τ
    // near 300 s, and no step at the joins.
    let tau = 300.0;
    let (sim, real) = pair(2, 5400, 2700.0, false, |_| 0.0, Some(tau), 4);
    let d = diagnose(&sim, &real, Path::new("sim.csv"), Path::new("real.csv")).expect("diagnosis runs");
    let r = &d.report;
    assert!(r.steps.is_empty(), "{:?}", r.steps);
    let lag = r.effects.iter().find(|e| e.id == "thermal_lag");
    let grouped = r.ambiguous.iter().any(|g| g.ids.iter().any(|i| i == "thermal_lag"));
    assert!(lag.is_some() || grouped, "{:?} {:?}", r.effects, r.ambiguous);
    if let Some(e) = lag {
        for (ax, p) in &e.params {
            let t = p["tau_s"];
            assert!((t - tau).abs() < 0.25 * tau, "{ax}: τ = {t}");
        }
    }
    for ax in ["x", "y", "z"] {
        let after = r.heldout_rms_after_mg[ax];
        assert!(after < 1.1 * SIGMA * 1e3, "{ax}: {after} mg after, white {} mg", SIGMA * 1e3);
    }
}

/// Three sessions of 1.5 h at 1 Hz, 45 min unpowered between them, the chamber's triangle
/// ([`chamber_c`]) running on through the gaps, and REAL with an additive bias play of width
/// `width_c`: `amp_v·(play(T) − T)/(w/2)` on each accelerometer (signs +, −, +), the play
/// followed every second through the gaps as well (the unit's state does not wait for the
/// logger).
fn play_pair(width_c: f64, amp_v: f64, seed: u64) -> (Vec<Row>, Vec<Row>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let white = Normal::new(0.0, SIGMA).unwrap();
    let (len_s, gap_s) = (5400usize, 2700usize);
    let (mut sim, mut real) = (Vec::new(), Vec::new());
    let mut pl = chamber_c(0.0);
    for k in 0..3 * len_s + 2 * gap_s {
        let t = k as f64;
        let temp_c = chamber_c(t);
        pl = pl.clamp(temp_c - 0.5 * width_c, temp_c + 0.5 * width_c);
        let (session, into) = (k / (len_s + gap_s), k % (len_s + gap_s));
        if into >= len_s {
            continue;
        }
        let h = (pl - temp_c) / (0.5 * width_c);
        let power_s = into as f64 + 60.0 * session as f64;
        let (row, r) =
            rows(sim.len() as u64 + 2, t, temp_c, power_s, |i| MOUNT[i] * amp_v * h, &mut || white.sample(&mut rng));
        sim.push(row);
        real.push(r);
    }
    (sim, real)
}

#[test]
fn a_play_runs_on_through_the_gaps() {
    // A 4 °C bias play of 10 σ. The chamber turns back inside the first gap, so the second
    // session starts with the play at its other edge from where the first ended; a play
    // restarted at each session's first temperature is half a width off there (held out,
    // 2.9–4.7× the white noise, in groups of three to seven forms). Carried through the gap it
    // is exact: the play is what the
    // model holds on every accelerometer (in one position a thermal play through SIM's slope
    // may stand beside it as a group), and every accelerometer's held-out residual is at the
    // white noise.
    let (sim, real) = play_pair(4.0, 10.0 * SIGMA, 5);
    let d = diagnose(&sim, &real, Path::new("sim.csv"), Path::new("real.csv")).expect("diagnosis runs");
    assert_eq!(d.prepared.session_starts, vec![0, 5400, 10_800]);
    let r = &d.report;
    let named = r.effects.iter().find(|e| e.id == "bias_hysteresis").map(|e| e.axes.clone());
    let grouped = r.ambiguous.iter().find(|g| g.modelled_as == "bias_hysteresis").map(|g| g.axes.clone());
    let axes: Vec<String> = named.into_iter().chain(grouped).flatten().collect();
    assert_eq!(axes.len(), 3, "{:?} {:?}", r.effects, r.ambiguous);
    for ax in ["x", "y", "z"] {
        let after = r.heldout_rms_after_mg[ax];
        assert!(after < 1.1 * SIGMA * 1e3, "{ax}: {after} mg after, white {} mg", SIGMA * 1e3);
    }
}
