//! Rows reduced to block means (`diagnose --block-s`, [`bins_cal::diagnose::prep::Builder::with_blocks`])
//! against the diagnosis of every row, on suite cases sampled five times faster than the suite's
//! 1 Hz (0.2 s, 120 000 rows) and reduced to 1 s blocks: the same mechanisms named on the same
//! accelerometers, the same verdicts, the per-row noise floor and held-out "before" of every row,
//! "after" within 5 %, each parameter within the full-rate fit's 95 % interval.

use bins_cal::diagnose::{Options, cases, diagnose_with, prep};
use bins_cal::recording::Row;
use rand::SeedableRng;
use rand_distr::Distribution;
use std::path::Path;

fn both(name: &str) {
    let mut case = cases::suite().into_iter().find(|c| c.name == name).expect("a suite case");
    case.plan.dt_s = 0.2;
    case.plan.rows = 120_000;
    let (sim, real) = cases::generate(&case);
    let (s, r) = (Path::new("sim.csv"), Path::new("real.csv"));
    let every_row = Options { block_s: Some(0.0), ..Options::default() };
    let full = diagnose_with(&sim, &real, s, r, &every_row).expect("every row").report;
    let opt = Options { block_s: Some(1.0), ..Options::default() };
    let blocked = diagnose_with(&sim, &real, s, r, &opt).expect("1 s blocks").report;
    let names = |rep: &bins_cal::diagnose::report::Report| {
        let mut v: Vec<(String, Vec<String>)> = rep.effects.iter().map(|e| (e.id.clone(), e.axes.clone())).collect();
        v.sort();
        v
    };
    println!("{name}: every row {:?}, blocks {:?}", names(&full), names(&blocked));
    assert_eq!(names(&full), names(&blocked), "{name}: the mechanisms named");
    assert!(!names(&full).is_empty(), "{name}: the case names nothing at 0.2 s");
    assert_eq!(full.verdict, blocked.verdict, "{name}: verdicts");
    assert_eq!(full.rows_used, blocked.rows_used, "{name}: rows used");
    for ax in ["x", "y", "z"] {
        let rel = |a: f64, b: f64| (a - b).abs() / a.abs().max(1e-12);
        let (f0, b0) = (full.noise_floor_mg[ax], blocked.noise_floor_mg[ax]);
        assert!(rel(f0, b0) < 0.05, "{name} {ax}: noise floor {f0} mg, in blocks {b0} mg");
        let (f1, b1) = (full.heldout_rms_before_mg[ax], blocked.heldout_rms_before_mg[ax]);
        assert!(rel(f1, b1) < 0.01, "{name} {ax}: held-out before {f1} mg, in blocks {b1} mg");
        let (f2, b2) = (full.heldout_rms_after_mg[ax], blocked.heldout_rms_after_mg[ax]);
        assert!(rel(f2, b2) < 0.05, "{name} {ax}: held-out after {f2} mg, in blocks {b2} mg");
        println!("{name} {ax}: floor {f0:.4} / {b0:.4} mg, held-out {f1:.4} → {f2:.4} / {b1:.4} → {b2:.4} mg");
    }
    for (e, eb) in full.effects.iter().zip(&blocked.effects) {
        for (ax, params) in &e.params {
            for (k, v) in params {
                let vb = eb.params[ax][k];
                let ci = e.ci.get(ax).and_then(|c| c.get(k));
                println!("{name} {} {ax} {k}: {v:.6} / {vb:.6} (interval {ci:?})", e.id);
                let inside = ci.is_some_and(|[lo, hi]| vb >= *lo && vb <= *hi);
                assert!(
                    inside || (vb - v).abs() <= 0.1 * v.abs(),
                    "{name} {} {ax} {k}: {v} every row (interval {ci:?}), {vb} in blocks",
                    e.id
                );
            }
        }
    }
}

#[test]
fn blocks_name_what_every_row_names_warmup() {
    both("warmup");
}

#[test]
fn blocks_name_what_every_row_names_lag_and_asymmetry() {
    both("lag_plus_asymmetry");
}

/// The default reduction: every row kept until a count, then the rows kept turned into blocks
/// and blocks from there on, builds what blocks from the first row build.
#[test]
fn blocks_from_a_row_count_are_blocks_from_the_start() {
    let mut case = cases::suite().into_iter().find(|c| c.name == "lag_plus_asymmetry").expect("a suite case");
    case.plan.dt_s = 0.2;
    case.plan.rows = 20_000;
    let (sim, real) = cases::generate(&case);
    let build = |b: prep::Builder| {
        let mut b = b;
        for (s, r) in sim.iter().zip(&real) {
            b.push(s, r).expect("rows match");
        }
        let mut p = b.finish().expect("prepared");
        p.notes.retain(|n| !n.starts_with("more than"));
        p
    };
    let (s, r) = (Path::new("sim.csv"), Path::new("real.csv"));
    let from_start = build(prep::Builder::new(s, r).with_blocks(Some(1.0)));
    let switched = build(prep::Builder::new(s, r).auto_blocks(7_001, 1.0));
    let whole = build(prep::Builder::new(s, r).auto_blocks(20_001, 1.0));
    assert_eq!(format!("{from_start:?}"), format!("{switched:?}"));
    assert!(whole.weight.is_empty() && whole.t.len() == 20_000, "below the count every row is kept");
    assert!(from_start.t.len() < 5_000, "{} blocks", from_start.t.len());
}

/// A pair at `hz` of 600 s over a 2 °C/min ramp with a 60 s lag in REAL, REAL's noise an AR(1)
/// sequence of lag-one correlation `rho` (0: white), 0.05 mg; SIM without noise. Written here
/// from the lag's definition, not by the library's generator.
fn ramp_pair(hz: f64, rho: f64) -> (Vec<Row>, Vec<Row>) {
    let n = (600.0 * hz) as usize;
    let dt = 1.0 / hz;
    let mut rng = rand::rngs::StdRng::seed_from_u64(7);
    let normal = rand_distr::Normal::new(0.0, 1.0).expect("a normal");
    let (mut lagged_c, mut ar) = (20.0, 0.0);
    let mut sim = Vec::with_capacity(n);
    let mut real = Vec::with_capacity(n);
    for k in 0..n {
        let t = k as f64 * dt;
        let temp_c = 20.0 + t / 30.0;
        lagged_c += (temp_c - lagged_c) * (1.0 - (-dt / 60.0f64).exp());
        ar = rho * ar + (1.0 - rho * rho).sqrt() * 0.05e-3 * normal.sample(&mut rng);
        let row = |u: [f64; 3]| Row {
            line: k as u64 + 2,
            t_s: t,
            u_v: u,
            temp_c,
            f_g: [Some(0.0), Some(0.0), Some(1.0)],
            ..Row::default()
        };
        // 50 µg/°C of bias on every accelerometer, 1 V/g, z up.
        let u_sim = [1e-3 + 50e-6 * (temp_c - 20.0), 2e-3 + 50e-6 * (temp_c - 20.0), 1.0 + 50e-6 * (temp_c - 20.0)];
        let u_real = u_sim.map(|u| u + 50e-6 * (lagged_c - temp_c) + ar);
        sim.push(row(u_sim));
        real.push(row(u_real));
    }
    // A second orientation for the scale factors: the first tenth upside down.
    for rows in [&mut sim, &mut real] {
        for r in rows.iter_mut().take(n / 10) {
            r.f_g[2] = Some(-1.0);
            r.u_v[2] -= 2.0;
        }
    }
    (sim, real)
}

/// The block choice of a builder fed the pair.
fn choice(sim: &[Row], real: &[Row]) -> prep::BlockChoice {
    let mut b = prep::Builder::new(Path::new("sim.csv"), Path::new("real.csv"));
    for (s, r) in sim.iter().zip(real) {
        b.push(s, r).expect("rows match");
    }
    b.block_choice().expect("a choice")
}

fn prepared(sim: &[Row], real: &[Row]) -> prep::Prepared {
    prep::prepare(sim, real, Path::new("sim.csv"), Path::new("real.csv")).expect("prepared")
}

/// By default, a 100 Hz recording of white noise is reduced to blocks of a third of a second
/// (a third of the shortest time constant searched), and the note says how much the residual
/// spreads inside them; the same recording at 2 Hz is kept whole (a block would hold one row).
#[test]
fn white_noise_at_100_hz_is_reduced_to_a_third_of_a_second() {
    let (sim, real) = ramp_pair(100.0, 0.0);
    let p = prepared(&sim, &real);
    assert!(!p.weight.is_empty(), "blocks expected; notes {:?}", p.notes);
    let rows: f64 = p.weight.iter().sum();
    assert_eq!(rows as usize, sim.len());
    let full = p.weight.iter().fold(0.0f64, |m, w| m.max(*w));
    assert_eq!(full, 34.0, "rows at 0, 0.01 … 0.33 s in a block of 1/3 s");
    assert!(
        p.notes.iter().any(|n| n.starts_with("reduced to means over blocks of 0.3333 s (34 rows")),
        "{:?}",
        p.notes
    );
    let c = choice(&sim, &real);
    assert!(c.accepts());
    for r in c.within_ratio {
        assert!((r - 1.0).abs() < 0.05, "within ratio {r}, expected 1 for white noise");
    }
    // Past a row count the same length is taken, and the rows kept are turned into blocks as
    // if the blocks had been built from the first row.
    let build = |b: prep::Builder| {
        let mut b = b;
        for (s, r) in sim.iter().zip(&real) {
            b.push(s, r).expect("rows match");
        }
        let mut p = b.finish().expect("prepared");
        p.notes.clear();
        p
    };
    let (s, r) = (Path::new("sim.csv"), Path::new("real.csv"));
    let capped = build(prep::Builder::new(s, r).blocks_from_data(20_001));
    let from_start = build(prep::Builder::new(s, r).with_blocks(Some(1.0 / 3.0)));
    assert_eq!(format!("{capped:?}"), format!("{from_start:?}"));
    let (sim, real) = ramp_pair(2.0, 0.0);
    let p = prepared(&sim, &real);
    assert!(p.weight.is_empty() && p.t.len() == sim.len(), "every row at 2 Hz");
    assert!(!p.notes.iter().any(|n| n.contains("blocks")), "{:?}", p.notes);
}

/// Noise correlated from row to row (an AR(1) sequence, lag-one correlation ρ = 0.6, as a
/// resonance or a filter leaves it) spreads inside a block of 34 rows 2.29× what the
/// consecutive differences predict (`(34 − n·var(mean)/σ²) / (33 (1 − ρ))`, with
/// `n·var(mean)/σ² = (1+ρ)/(1−ρ) − 2ρ(1−ρ³⁴)/(34 (1−ρ)²) = 3.78`): the rows stay whole and the
/// note says why.
#[test]
fn correlated_noise_keeps_every_row() {
    let (sim, real) = ramp_pair(100.0, 0.6);
    let p = prepared(&sim, &real);
    assert!(p.weight.is_empty() && p.t.len() == sim.len(), "every row expected; notes {:?}", p.notes);
    let note = p.notes.iter().find(|n| n.starts_with("every row kept")).expect("a note");
    assert!(note.contains("spreads 2."), "{note}");
    let c = choice(&sim, &real);
    assert!(!c.accepts());
    for r in c.within_ratio {
        assert!((r - 2.29).abs() < 0.15, "within ratio {r}, expected about 2.29");
    }
}

/// A record longer than the most blocks allowed: the blocks taken on reaching the row count are
/// merged at the end, k at a time, into at most that many. Merging keeps every row and the
/// residual's total sum of squares (each block's spread plus its rows times its mean's squared
/// distance from the merged mean) of the blocks it merges.
#[test]
fn a_record_longer_than_the_most_blocks_is_merged_into_longer_blocks() {
    let (sim, real) = ramp_pair(100.0, 0.0);
    let (s, r) = (Path::new("sim.csv"), Path::new("real.csv"));
    let build = |b: prep::Builder| {
        let mut b = b;
        for (s, r) in sim.iter().zip(&real) {
            b.push(s, r).expect("rows match");
        }
        b.finish().expect("prepared")
    };
    let merged = build(prep::Builder::new(s, r).blocks_from_data(20_001).max_blocks(500));
    assert!(merged.weight.len() <= 500 && merged.weight.len() > 250, "{} blocks", merged.weight.len());
    assert_eq!(merged.weight.iter().sum::<f64>() as usize, sim.len());
    let note = merged.notes.iter().find(|n| n.contains("then merged")).expect("a note on the merge");
    // 20 000 rows at 100 Hz span 200 s: 0.4 s blocks (over 500), merged three at a time.
    assert!(note.contains("blocks of 0.4000 s") && note.contains("merged 3 at a time"), "{note}");
    let unmerged = build(prep::Builder::new(s, r).with_blocks(Some(0.4)));
    assert!(unmerged.weight.len() > 1_400, "{} blocks", unmerged.weight.len());
    let total_ss = |p: &prep::Prepared, i: usize| {
        let w: f64 = p.weight.iter().sum();
        let mean = p.weight.iter().zip(&p.r[i]).map(|(w, r)| w * r).sum::<f64>() / w;
        let between: f64 = p.weight.iter().zip(&p.r[i]).map(|(w, r)| w * (r - mean).powi(2)).sum();
        between + p.within[i].iter().sum::<f64>()
    };
    for i in 0..3 {
        let (a, b) = (total_ss(&merged, i), total_ss(&unmerged, i));
        assert!((a - b).abs() <= 1e-6 * b, "axis {i}: total sum of squares {a} merged, {b} not");
        let within_share = merged.within[i].iter().sum::<f64>() / a;
        let unmerged_share = unmerged.within[i].iter().sum::<f64>() / b;
        assert!(within_share > unmerged_share, "merging moves spread between blocks into the blocks");
    }
}

/// A block never spans a power-on: its mean `power_s` would stand for neither side (a block of
/// 0.33 s with one row 5 000 s after an earlier power-on and 33 rows just after a new one has a
/// mean of 150 s, where a warm-up's `e^(−P/τ)` is at its largest).
#[test]
fn a_block_ends_at_a_power_on() {
    let (mut sim, mut real) = ramp_pair(100.0, 0.0);
    // Powered 5 000 s before the record starts, powered on again at 300.005 s (mid-block).
    for rows in [&mut sim, &mut real] {
        for r in rows.iter_mut() {
            r.power_s = Some(if r.t_s < 300.0 { r.t_s + 5_000.0 } else { r.t_s - 300.0 });
        }
    }
    let p = prepared(&sim, &real);
    assert!(!p.weight.is_empty(), "blocks expected; notes {:?}", p.notes);
    let power = p.power.as_ref().expect("power_s on every row");
    let after = (0..p.t.len()).find(|&i| p.t[i] > 300.0).expect("blocks after the power-on");
    assert!(power[after] < 1.0, "the first block after the power-on: power_s {} s", power[after]);
    assert!(power[after - 1] > 5_000.0, "the last block before: power_s {} s", power[after - 1]);
}
