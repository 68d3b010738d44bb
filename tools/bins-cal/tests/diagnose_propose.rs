//! `diagnose --propose`: the test to run next when the recording cannot decide
//! (docs/diagnosis.md, "When the data cannot decide"). A unit warms up after its one power-on
//! at the start of a ramp, its die lagging; on that recording a warm-up and a drift in time are
//! one column (both decay from the record's start), and only a second power-on tells them
//! apart: the proposal must say so with a number, and ramps alone must not claim it.

use bins_cal::diagnose::mech::Mech;
use bins_cal::diagnose::{Options, diagnose_with, propose};
use bins_cal::recording::Row;
use bins_cal::sim::scenario::ScenarioFile;
use std::path::Path;

/// The case: REAL (`real`) with a warm-up of 0.3 mV, τ 600 s and a 120 s die lag, SIM without;
/// 1.5 h at 0.5 Hz, a ramp from +20 to −20 °C from power-on.
fn scenario(real: bool) -> String {
    let (warm, die) = if real { (3.0e-4, 120.0) } else { (0.0, 0.0) };
    format!(
        r#"
[recording]
rate_Hz = 0.5
[unit]
preset = "paper"
fit = "poly"
order = 2
warmup_V = [{warm:?}, {warm:?}, {warm:?}]
warmup_tau_s = 600.0
[thermal]
start_C = 20.0
rate_C_per_min = 1.0
case_tau_s = 300.0
die_tau_s = {die:?}
[noise]
white_V = 1.0e-5
[[step]]
kind = "soak"
chamber_C = -20.0
dwell_s = 5400.0
"#
    )
}

fn rows(text: &str, seed: u64) -> Vec<Row> {
    let sim = ScenarioFile::parse(text, Path::new("s.toml")).unwrap().build(Path::new("s.toml")).unwrap();
    let mut g = sim.rows(seed);
    let mut out = Vec::new();
    let mut r = Row::default();
    while g.next_row(&mut r) {
        out.push(r.clone());
    }
    out
}

fn twin(dir: &Path) -> propose::Twin {
    let path = dir.join("twin.toml");
    std::fs::write(&path, scenario(false)).unwrap();
    propose::Twin::read(&path).unwrap()
}

#[test]
fn a_warm_up_and_a_drift_are_separated_by_a_power_cycle_only() {
    let (s, r) = (rows(&scenario(false), 2), rows(&scenario(true), 1));
    let d = diagnose_with(&s, &r, Path::new("sim"), Path::new("real"), &Options::default()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let p = propose::propose(&d, &twin(dir.path()), None, &|_, _| {}).unwrap().expect("pairs to separate");
    // The recording cannot separate a warm-up from a drift in time on any accelerometer.
    let wd: Vec<usize> =
        (0..p.pairs.len()).filter(|&k| p.pairs[k].a == Mech::Warmup && p.pairs[k].b == Mech::Drift).collect();
    assert!(!wd.is_empty(), "warm-up / drift among the pairs: {:?}", p.pairs);
    for &k in &wd {
        assert!(p.pairs[k].recording < p.pairs[k].needed, "{:?}", p.pairs[k]);
    }
    assert!(p.ranked.len() >= 4, "candidates evaluated: {}", p.ranked.len());
    for e in &p.ranked {
        let c = &e.candidate;
        assert!(c.duration_s() <= p.limits.max_duration_s + 1e-9, "{} within the longest test", c.name);
        for &k in &wd {
            let (got, need) = (e.deviance[k], p.pairs[k].needed);
            if c.has_power_cycle() {
                assert!(got > need, "{}: a power cycle separates warm-up from drift: {got:.1} ≤ {need:.1}", c.name);
            } else {
                assert!(got < 1.0, "{}: without a power cycle a drift absorbs the warm-up: {got:.3}", c.name);
            }
        }
    }
    assert!(
        p.ranked[0].candidate.has_power_cycle(),
        "the best proposal cycles the power: {}",
        p.ranked[0].candidate.name
    );
}

#[test]
fn nothing_to_separate_gives_no_proposal() {
    let (s, r) = (rows(&scenario(false), 2), rows(&scenario(false), 1));
    let d = diagnose_with(&s, &r, Path::new("sim"), Path::new("real"), &Options::default()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    assert!(propose::propose(&d, &twin(dir.path()), None, &|_, _| {}).unwrap().is_none());
}
