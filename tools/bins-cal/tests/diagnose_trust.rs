//! A diagnosis a user can trust on a recording shaped like a real unit's long static
//! warm-soak, generated here by code that shares nothing with the diagnosis or the simulator:
//! a static unit in three orientations, warming slowly, 2 mg of per-sample noise, a random
//! walk and slow structure of 0.6–1.3 mg RMS that no mechanism of the library has; SIM is the
//! offset-only cubic-in-T model a user fits to that very recording.
//!
//! Asserted: a named effect never makes the raw held-out RMS (the figure the report prints)
//! worse and cuts it by more than its fold-to-fold standard error; the verdicts tell one story
//! with the report's own figures ("at the noise" never beside a named effect or an unexplained
//! figure); the slow structure, far below the per-sample noise but far above what that noise
//! leaves at minutes to hours, is reported as unexplained at its time scale, with its size.
//! The same at the length of a three-day chamber run (74 h), and on a short fast cooling whose
//! per-sample noise is mostly coloured (a 20 Hz resonance), where sample-to-sample differences
//! misjudge the noise: nothing is named on the coloured noise, and the slow structure beside it
//! is sized at its scale.

use bins_cal::diagnose::diagnose;
use bins_cal::recording::Row;
use bins_comp::vibration::Vibration;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use std::path::Path;

/// Solves the normal equations `a·x = b` (n×n, Gaussian elimination with partial pivoting).
fn solve(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Vec<f64> {
    let n = b.len();
    for c in 0..n {
        let p = (c..n).max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs())).unwrap();
        a.swap(c, p);
        b.swap(c, p);
        for r in c + 1..n {
            let f = a[r][c] / a[c][c];
            for k in c..n {
                a[r][k] -= f * a[c][k];
            }
            b[r] -= f * b[c];
        }
    }
    let mut x = vec![0.0; n];
    for c in (0..n).rev() {
        x[c] = (b[c] - (c + 1..n).map(|k| a[c][k] * x[k]).sum::<f64>()) / a[c][c];
    }
    x
}

/// SIM as a user fits it: per axis the offset-only cubic in the thermistor's reading
/// (`(temp_C − centre_c) / scale_c` as the variable), least squares over REAL itself. Also returns
/// what REAL − SIM holds besides the `noise` put into REAL (RMS per axis, mg): the structure less
/// what the cubic took of it.
fn cubic_sim(real: &[Row], noise: &[Vec<f64>; 3], centre_c: f64, scale_c: f64) -> (Vec<Row>, [f64; 3]) {
    let n = real.len();
    let mut sim = real.to_vec();
    let x: Vec<[f64; 4]> = real
        .iter()
        .map(|r| {
            let d = (r.temp_c - centre_c) / scale_c;
            [1.0, d, d * d, d * d * d]
        })
        .collect();
    let mut slow_rms = [0.0; 3];
    for i in 0..3 {
        let mut a = vec![vec![0.0; 4]; 4];
        let mut b = vec![0.0; 4];
        for (r, xr) in real.iter().zip(&x) {
            let y = r.u_v[i] - r.f_g[i].unwrap();
            for u in 0..4 {
                b[u] += xr[u] * y;
                for v in 0..4 {
                    a[u][v] += xr[u] * xr[v];
                }
            }
        }
        let c = solve(a, b);
        for (s, xr) in sim.iter_mut().zip(&x) {
            s.u_v[i] = s.f_g[i].unwrap() + (0..4).map(|u| c[u] * xr[u]).sum::<f64>();
        }
        let clean: Vec<f64> = sim.iter().zip(real).zip(&noise[i]).map(|((s, r), e)| r.u_v[i] - e - s.u_v[i]).collect();
        let m = clean.iter().sum::<f64>() / n as f64;
        slow_rms[i] = (clean.iter().map(|v| (v - m).powi(2)).sum::<f64>() / n as f64).sqrt() * 1e3;
    }
    (sim, slow_rms)
}

/// SIM and REAL of the warm soak: `hours` at 1 Hz.
fn warm_soak(hours: f64, seed: u64) -> (Vec<Row>, Vec<Row>, [f64; 3]) {
    let n = (hours * 3600.0) as usize;
    let dur = n as f64;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let white = Normal::new(0.0, 2e-3).unwrap(); // 2 mg per sample
    let unit = Normal::new(0.0, 1.0).unwrap();
    let rw_step = 0.2e-3 / 60.0; // 0.2 mg/√h: g per √s
    let amp_g = [0.8e-3, 1.6e-3, 1.9e-3]; // slow structure: RMS 0.57 / 1.13 / 1.34 mg
    let period_s = [dur / 2.3, dur / 1.7, dur / 3.1];
    let phase = [0.3, 1.9, 4.0];
    let cubic = [[1.5e-4, -4e-6, 1e-7], [-2e-4, 3e-6, -5e-8], [1e-4, 6e-6, 2e-8]]; // g/°Cᵖ
    let mut rw = [0.0; 3];
    let mut noise: [Vec<f64>; 3] = Default::default();
    let mut real = Vec::with_capacity(n);
    for k in 0..n {
        let t = k as f64;
        let f = match 3 * k / n {
            0 => [0.0, 0.0, 1.0],
            1 => [1.0, 0.0, 0.0],
            _ => [0.0, 1.0, 0.0],
        };
        let temp = 20.0 + 12.0 * (1.0 - (-t / (0.35 * dur)).exp());
        let read = ((temp + 0.005 * unit.sample(&mut rng)) * 100.0).round() / 100.0;
        let mut row =
            Row { line: k as u64 + 2, t_s: t, temp_c: read, pos: Some(format!("p{}", 3 * k / n)), ..Row::default() };
        row.f_g = f.map(Some);
        row.set_vibration(&Vibration::None);
        for i in 0..3 {
            rw[i] += rw_step * unit.sample(&mut rng);
            let dtc = temp - 25.0;
            let bias = ((cubic[i][2] * dtc + cubic[i][1]) * dtc + cubic[i][0]) * dtc;
            let slow = amp_g[i] * (2.0 * std::f64::consts::PI * t / period_s[i] + phase[i]).sin();
            let e = white.sample(&mut rng);
            row.u_v[i] = f[i] + 0.01 * i as f64 + bias + slow + rw[i] + e;
            noise[i].push(e);
        }
        real.push(row);
    }
    let (sim, slow_rms) = cubic_sim(&real, &noise, 26.0, 6.0);
    (sim, real, slow_rms)
}

#[test]
fn slow_warm_soak_named_effects_cut_the_printed_figure_and_verdicts_agree() {
    warm_soak_tells_one_story(8.0);
}

/// The warm soak at the length of a three-day chamber run (74 h at 1 Hz, 266 400 rows): on the
/// tree before, a `thermal_lag` (τ = 8.8 h) on y printed a held-out cut of 0.278 mg beside
/// "before → after" of 2.198 → 2.096 mg, its cut measured from SIM's cubic re-fitted alone,
/// which predicts the held-out folds worse than the offset.
#[test]
fn a_three_day_warm_soak_prints_cuts_that_match_its_figures() {
    warm_soak_tells_one_story(74.0);
}

/// [`warm_soak`] of `hours`, diagnosed: named effects cut the printed held-out figure by more
/// than their standard error and by no more than "before" minus "after"; the verdicts agree
/// with the report's figures; the slow structure is sized at its scale.
fn warm_soak_tells_one_story(hours: f64) {
    let (sim, real, slow_rms_mg) = warm_soak(hours, 74);
    let d = diagnose(&sim, &real, Path::new("sim.csv"), Path::new("real.csv")).expect("diagnosis runs");
    let r = &d.report;
    let summary = format!(
        "effects {:?}; ambiguous {:?}; held-out {:?} → {:?}; verdict {:?}; unexplained {:?} at {:?} s; floor {:?}",
        r.effects.iter().map(|e| (&e.id, &e.axes, &e.heldout_cut_mg)).collect::<Vec<_>>(),
        r.ambiguous.iter().map(|g| (&g.ids, &g.axes)).collect::<Vec<_>>(),
        r.heldout_rms_before_mg,
        r.heldout_rms_after_mg,
        r.verdict,
        r.unexplained_rms_mg,
        r.unexplained_scale_s,
        r.noise_floor_mg
    );
    println!("{summary}");
    for (i, ax) in ["x", "y", "z"].into_iter().enumerate() {
        let named: Vec<_> = r.effects.iter().filter(|e| e.axes.iter().any(|a| a == ax)).collect();
        let modelled = !named.is_empty() || r.ambiguous.iter().any(|g| g.axes.iter().any(|a| a == ax));
        let (before, after) = (r.heldout_rms_before_mg[ax], r.heldout_rms_after_mg[ax]);
        if modelled {
            assert!(after < before, "{ax}: a modelled effect and held-out {before} → {after} mg: {summary}");
        }
        for e in &named {
            let [cut, se] = e.heldout_cut_mg[ax];
            assert!(cut > se, "{ax}: {} cuts the held-out RMS by {cut} mg, standard error {se}: {summary}", e.id);
            // The printed cut is one story with the printed figures.
            assert!(cut <= before - after + 1e-9, "{ax}: {} cut {cut} mg but {before} → {after} mg: {summary}", e.id);
        }
        // One story: "at the noise" only with nothing named and nothing unexplained.
        let v = r.verdict[ax].as_str();
        let unexplained = r.unexplained_rms_mg[ax];
        if v == "at the noise" {
            assert!(!modelled && unexplained == 0.0, "{ax}: at the noise beside a finding: {summary}");
        }
        if unexplained > 0.0 {
            assert!(v == "unexplained" || v == "partly explained", "{ax}: unexplained {unexplained} mg but {v}");
        }
        // The slow structure (well below the 2 mg per-sample noise) is seen at its scale and
        // sized: within a factor of two of what REAL − SIM holds besides the white noise.
        assert!(v == "unexplained" || v == "partly explained", "{ax}: the slow structure is missed: {summary}");
        let put_in = slow_rms_mg[i];
        assert!(
            unexplained > 0.5 * put_in && unexplained < 2.0 * put_in,
            "{ax}: unexplained {unexplained:.3} mg, structure besides the white noise {put_in:.3} mg RMS: {summary}"
        );
    }
}

/// SIM and REAL of a unit whose bias has a temperature term SIM lacks (`b·ΔT` on x,
/// 0.02 mg/°C), 6 h at 1 Hz, three static orientations, 0.1 mg white noise. `reverse`: the
/// temperature rises and falls back (a triangle); otherwise it approaches 30 °C from 20 °C
/// once, exponentially — exactly an offset plus a settling in time.
fn one_way_or_reversed(reverse: bool, seed: u64) -> (Vec<Row>, Vec<Row>) {
    let n = 6 * 3600;
    let dur = n as f64;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let white = Normal::new(0.0, 1e-4).unwrap();
    let (mut sim, mut real) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for k in 0..n {
        let t = k as f64;
        let temp = if reverse {
            20.0 + 10.0 * (1.0 - (2.0 * t / dur - 1.0).abs())
        } else {
            20.0 + 10.0 * (1.0 - (-t / (0.3162 * dur)).exp())
        };
        let f = match 3 * k / n {
            0 => [0.0, 0.0, 1.0],
            1 => [1.0, 0.0, 0.0],
            _ => [0.0, 1.0, 0.0],
        };
        let mut row = Row { line: k as u64 + 2, t_s: t, temp_c: (temp * 100.0).round() / 100.0, ..Row::default() };
        row.pos = Some(format!("p{}", 3 * k / n));
        row.f_g = f.map(Some);
        row.set_vibration(&Vibration::None);
        let mut r = row.clone();
        for i in 0..3 {
            row.u_v[i] = f[i];
            r.u_v[i] = f[i] + if i == 0 { 2e-5 * (temp - 20.0) } else { 0.0 } + white.sample(&mut rng);
        }
        sim.push(row);
        real.push(r);
    }
    (sim, real)
}

#[test]
fn a_one_way_temperature_term_is_ambiguous_with_a_drift_and_a_reversal_separates_them() {
    let ids_on_x = |r: &bins_cal::diagnose::report::Report| -> (Vec<String>, Vec<(Vec<String>, String)>) {
        let named = r.effects.iter().filter(|e| e.axes.iter().any(|a| a == "x")).map(|e| e.id.clone()).collect();
        let groups = r
            .ambiguous
            .iter()
            .filter(|g| g.axes.iter().any(|a| a == "x"))
            .map(|g| (g.ids.clone(), g.separating_test.clone()))
            .collect();
        (named, groups)
    };
    let (sim, real) = one_way_or_reversed(false, 5);
    let d = diagnose(&sim, &real, Path::new("sim.csv"), Path::new("real.csv")).expect("diagnosis runs");
    let (named, groups) = ids_on_x(&d.report);
    println!("one way: named {named:?}, ambiguous {groups:?}");
    let with_drift = groups.iter().find(|(ids, _)| ids.iter().any(|i| i == "drift"));
    let (ids, test) = with_drift.unwrap_or_else(|| panic!("no drift alternative on x: {named:?} {groups:?}"));
    assert!(ids.iter().any(|i| i == "bias_temp_order"), "the truth is not in the group: {ids:?}");
    assert!(test.contains("temperature reversal"), "{test}");
    assert!(named.is_empty(), "named as a finding beside the ambiguity: {named:?}");

    let (sim, real) = one_way_or_reversed(true, 6);
    let d = diagnose(&sim, &real, Path::new("sim.csv"), Path::new("real.csv")).expect("diagnosis runs");
    let (named, groups) = ids_on_x(&d.report);
    println!("reversed: named {named:?}, ambiguous {groups:?}");
    assert_eq!(named, ["bias_temp_order"], "{groups:?}");
    assert!(groups.iter().all(|(ids, _)| !ids.iter().any(|i| i == "drift")), "{groups:?}");
}

/// SIM and REAL of a short cooling sampled fast, shaped like a bench run of several sensors: 240 s
/// at 100 Hz, one static orientation, the unit cooling 3 °C (exponentially), and per-sample
/// noise that is mostly **coloured**: a resonance near 20 Hz (1.5 mg RMS, an AR(2) with poles
/// at 0.8·e^(±i·0.4π)) over 0.3 mg of white noise, so sample-to-sample differences misjudge it.
/// Slow structure no mechanism of the library has (two sinusoids of 47 s and 83 s) on x
/// (`slow_mg[0]` RMS) and z (`slow_mg[2]`), none on y. SIM is the offset-only cubic in the
/// thermistor's reading fitted to REAL, as in [`warm_soak`]. Returns SIM, REAL and what REAL − SIM
/// holds besides the noise (RMS per axis, mg).
fn coloured_cooling(seed: u64, slow_mg: [f64; 3], resonance_hz: f64) -> (Vec<Row>, Vec<Row>, [f64; 3]) {
    let (rate_hz, dur_s) = (100.0, 240.0);
    let n = (rate_hz * dur_s) as usize;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let unit = Normal::new(0.0, 1.0).unwrap();
    let (rho, w) = (0.8f64, 2.0 * std::f64::consts::PI * resonance_hz / rate_hz);
    let (a1, a2) = (2.0 * rho * w.cos(), -rho * rho);
    // Stationary variance of the AR(2) per unit innovation variance.
    let gain = (1.0 - a2) / ((1.0 + a2) * ((1.0 - a2).powi(2) - a1 * a1));
    let innov = 1.5e-3 / gain.sqrt();
    let cubic = [[1.2e-4, -3e-6, 1e-7], [-1.5e-4, 2e-6, -4e-8], [0.8e-4, 5e-6, 2e-8]]; // g/°Cᵖ
    let mut ar = [[0.0f64; 2]; 3];
    let mut noise: [Vec<f64>; 3] = Default::default();
    let mut real = Vec::with_capacity(n);
    for k in 0..n {
        let t = k as f64 / rate_hz;
        let temp = 25.0 - 3.0 * (1.0 - (-t / 100.0).exp()) / (1.0 - (-dur_s / 100.0f64).exp());
        let read = ((temp + 0.005 * unit.sample(&mut rng)) * 100.0).round() / 100.0;
        let mut row = Row { line: k as u64 + 2, t_s: t, temp_c: read, pos: Some("zdown".into()), ..Row::default() };
        row.f_g = [Some(0.0), Some(0.0), Some(1.0)];
        row.set_vibration(&Vibration::None);
        for i in 0..3 {
            let c = a1 * ar[i][0] + a2 * ar[i][1] + innov * unit.sample(&mut rng);
            ar[i] = [c, ar[i][0]];
            let e = c + 0.3e-3 * unit.sample(&mut rng);
            let dtc = temp - 25.0;
            let bias = ((cubic[i][2] * dtc + cubic[i][1]) * dtc + cubic[i][0]) * dtc;
            // Unit RMS: two sinusoids of amplitude 1 have RMS 1.
            let slow = slow_mg[i]
                * 1e-3
                * ((2.0 * std::f64::consts::PI * t / 47.0 + 0.4 * i as f64).sin()
                    + (2.0 * std::f64::consts::PI * t / 83.0 + 1.1).sin());
            row.u_v[i] = row.f_g[i].unwrap() + 0.01 * i as f64 + bias + slow + e;
            noise[i].push(e);
        }
        real.push(row);
    }
    let (sim, slow_rms) = cubic_sim(&real, &noise, 23.5, 1.5);
    (sim, real, slow_rms)
}

#[test]
fn coloured_noise_is_neither_structure_nor_hides_it() {
    coloured_noise_case(20.0, false);
}

/// The same at a 30 Hz resonance: its noise is anti-correlated from row to row, the residual
/// spreads inside 1/3 s blocks less than its consecutive differences predict, and the default
/// reduces the rows to blocks; the same story must come out of them.
#[test]
fn coloured_noise_at_30_hz_in_blocks_is_neither_structure_nor_hides_it() {
    coloured_noise_case(30.0, true);
}

fn coloured_noise_case(resonance_hz: f64, blocks: bool) {
    for (seed, slow_mg) in [(31u64, [0.35, 0.0, 0.25]), (32, [0.5, 0.0, 0.3])] {
        let (sim, real, put_in_mg) = coloured_cooling(seed, slow_mg, resonance_hz);
        let d = diagnose(&sim, &real, Path::new("sim.csv"), Path::new("real.csv")).expect("diagnosis runs");
        let r = &d.report;
        let summary = format!(
            "seed {seed}: notes {:?}; effects {:?}; ambiguous {:?}; held-out {:?} → {:?}; verdict {:?}; unexplained {:?} at {:?} s; floor {:?}; put in {put_in_mg:?}",
            r.notes,
            r.effects.iter().map(|e| (&e.id, &e.axes, &e.heldout_cut_mg)).collect::<Vec<_>>(),
            r.ambiguous.iter().map(|g| (&g.ids, &g.axes)).collect::<Vec<_>>(),
            r.heldout_rms_before_mg,
            r.heldout_rms_after_mg,
            r.verdict,
            r.unexplained_rms_mg,
            r.unexplained_scale_s,
            r.noise_floor_mg
        );
        println!("{summary}");
        let blocked = r.notes.iter().any(|n| n.starts_with("reduced to means over blocks"));
        assert_eq!(blocked, blocks, "blocks at a {resonance_hz} Hz resonance: {summary}");
        for (i, ax) in ["x", "y", "z"].into_iter().enumerate() {
            let named: Vec<_> = r.effects.iter().filter(|e| e.axes.iter().any(|a| a == ax)).collect();
            let modelled = !named.is_empty() || r.ambiguous.iter().any(|g| g.axes.iter().any(|a| a == ax));
            let (before, after) = (r.heldout_rms_before_mg[ax], r.heldout_rms_after_mg[ax]);
            if modelled {
                assert!(after < before, "{ax}: a modelled effect and held-out {before} → {after} mg: {summary}");
            }
            for e in &named {
                let [cut, se] = e.heldout_cut_mg[ax];
                assert!(cut > se, "{ax}: {} cuts the held-out RMS by {cut} mg, standard error {se}: {summary}", e.id);
                assert!(
                    cut <= before - after + 1e-9,
                    "{ax}: {} cut {cut} mg but {before} → {after} mg: {summary}",
                    e.id
                );
            }
            let v = r.verdict[ax].as_str();
            let unexplained = r.unexplained_rms_mg[ax];
            if v == "at the noise" {
                assert!(!modelled && unexplained == 0.0, "{ax}: at the noise beside a finding: {summary}");
            }
            if unexplained > 0.0 {
                assert!(v == "unexplained" || v == "partly explained", "{ax}: unexplained {unexplained} mg but {v}");
            }
            if slow_mg[i] > 0.0 {
                // The slow part is seen and sized at its scale, not inflated by the coloured
                // noise that sample-to-sample differences understate.
                let put_in = put_in_mg[i];
                assert!(
                    unexplained > 0.5 * put_in && unexplained < 2.0 * put_in,
                    "{ax}: unexplained {unexplained:.3} mg, slow structure {put_in:.3} mg RMS: {summary}"
                );
            } else {
                // Coloured noise alone is no structure and no mechanism.
                assert!(named.is_empty(), "{ax}: named on coloured noise alone: {summary}");
                assert!(
                    unexplained < 0.05,
                    "{ax}: coloured noise reported as {unexplained:.3} mg of structure: {summary}"
                );
            }
        }
    }
}
