//! Rows reduced to block means (`diagnose --block-s`, [`bins_cal::diagnose::prep::Builder::with_blocks`])
//! against the diagnosis of every row, on suite cases sampled five times faster than the suite's
//! 1 Hz (0.2 s, 120 000 rows) and reduced to 1 s blocks: the same mechanisms named on the same
//! accelerometers, the same verdicts, the per-row noise floor and held-out "before" of every row,
//! "after" within 5 %, each parameter within the full-rate fit's 95 % interval.

use bins_cal::diagnose::{Options, cases, diagnose_with, prep};
use std::path::Path;

fn both(name: &str) {
    let mut case = cases::suite().into_iter().find(|c| c.name == name).expect("a suite case");
    case.plan.dt_s = 0.2;
    case.plan.rows = 120_000;
    let (sim, real) = cases::generate(&case);
    let (s, r) = (Path::new("sim.csv"), Path::new("real.csv"));
    let full = diagnose_with(&sim, &real, s, r, &Options::default()).expect("every row").report;
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
