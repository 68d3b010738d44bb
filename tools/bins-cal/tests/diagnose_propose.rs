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
    ScenarioFile::parse(text, Path::new("s.toml")).unwrap().build(Path::new("s.toml")).unwrap().all_rows(seed)
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

/// Writes the case's SIM and REAL recordings and the twin (SIM's scenario) into `dir`;
/// `real_has`: REAL with the warm-up and the lag, else a second SIM.
fn files(dir: &Path, real_has: bool) -> [std::path::PathBuf; 3] {
    let (s, r, t) = (dir.join("sim.csv"), dir.join("real.csv"), dir.join("twin.toml"));
    std::fs::write(&t, scenario(false)).unwrap();
    for (path, text, seed) in [(&s, scenario(false), "2"), (&r, scenario(real_has), "1")] {
        let src = dir.join("src.toml");
        std::fs::write(&src, text).unwrap();
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_bins-cal"))
            .args(["simulate"])
            .arg(&src)
            .arg("-o")
            .arg(path)
            .args(["--seed", seed])
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    }
    [s, r, t]
}

fn diagnose_propose(dir: &Path, [s, r, t]: &[std::path::PathBuf; 3]) -> (String, serde_json::Value) {
    diagnose_propose_with(dir, s, r, Some(t))
}

fn diagnose_propose_with(dir: &Path, s: &Path, r: &Path, twin: Option<&Path>) -> (String, serde_json::Value) {
    let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_bins-cal"));
    cmd.args(["diagnose", "--sim"]).arg(s).arg("--real").arg(r).arg("--report").arg(dir.join("out.json"));
    cmd.arg("--propose").arg(dir.join("next.toml"));
    if let Some(t) = twin {
        cmd.arg("--twin").arg(t);
    }
    let out = cmd.output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(out.status.success(), "{stdout}{}", String::from_utf8_lossy(&out.stderr));
    let v = serde_json::from_str(&std::fs::read_to_string(dir.join("out.json")).unwrap()).unwrap();
    (stdout, v)
}

#[test]
fn command_writes_the_best_as_a_scenario_the_simulator_runs() {
    let dir = tempfile::tempdir().unwrap();
    let f = files(dir.path(), true);
    let (stdout, v) = diagnose_propose(dir.path(), &f);
    assert!(stdout.contains("candidate 1: ") && stdout.contains("candidate 3: "), "{stdout}");
    let next = dir.path().join("next.toml");
    let best = &v["proposal"]["candidates"][0];
    assert_eq!(v["proposal"]["file"].as_str(), Some(next.to_str().unwrap()));
    assert!(best["name"].as_str().unwrap().contains("power"), "{best}");
    assert!(dir.path().join("next.png").exists());
    // The scenario runs, for as long as the proposal says, with a second power-on in it.
    let csv = dir.path().join("next.csv");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_bins-cal"))
        .arg("simulate")
        .arg(&next)
        .arg("-o")
        .arg(&csv)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let sim = ScenarioFile::read(&next).unwrap().build(&next).unwrap();
    let hours = best["duration_h"].as_f64().unwrap();
    assert!((sim.duration_s() / 3600.0 - hours).abs() < 1e-6, "{} h vs {hours} h", sim.duration_s() / 3600.0);
    let rows = rows(&std::fs::read_to_string(&next).unwrap(), 1);
    let restarts = rows.windows(2).filter(|w| w[1].power_s.unwrap() < w[0].power_s.unwrap()).count();
    assert!(restarts >= 1, "a power cycle in the proposed test");
}

#[test]
fn command_with_nothing_to_separate_writes_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let f = files(dir.path(), false);
    let (stdout, v) = diagnose_propose(dir.path(), &f);
    assert!(stdout.contains("nothing to separate"), "{stdout}");
    assert!(!dir.path().join("next.toml").exists() && !dir.path().join("next.png").exists());
    assert!(v["proposal"]["candidates"].as_array().unwrap().is_empty());
}

/// A unit whose thermal path is known: case 600 s behind the chamber, die 120 s behind the
/// case and 1.5 °C above it when powered, the thermistor 0.3 of the way to the die; ramps at
/// 1 and 0.5 °C/min, holds, and a power cycle with the chamber moving while off; 1 Hz.
fn known_thermal_path() -> String {
    r#"
[recording]
rate_Hz = 1.0
[unit]
preset = "paper"
[thermal]
start_C = 20.0
rate_C_per_min = 1.0
case_tau_s = 600.0
die_tau_s = 120.0
self_heating_C = 1.5
thermistor_at = 0.3
[noise]
temp_noise_C = 0.005
temp_resolution_C = 0.01
[[step]]
kind = "soak"
chamber_C = -10.0
dwell_s = 5400.0
[[step]]
kind = "power"
off_s = 1800.0
chamber_C = 10.0
[[step]]
kind = "soak"
chamber_C = 40.0
rate_C_per_min = 0.5
dwell_s = 7200.0
"#
    .to_string()
}

#[test]
fn the_thermal_path_is_identified_from_the_recording() {
    let rows = rows(&known_thermal_path(), 3);
    let p = bins_cal::diagnose::prep::prepare(&rows, &rows, Path::new("s"), Path::new("r")).unwrap();
    let th = propose::identify_thermal(&p).expect("a path with chamber_C");
    // On ramps the thermistor lags the chamber by the case's τ plus its share of the die's:
    // that sum, the rise it sees at a power-on and the path itself are what the data fix.
    let lag = th.case_tau_s + th.thermistor_at * th.die_tau_s;
    assert!((lag / 636.0 - 1.0).abs() < 0.1, "thermistor's lag {lag:.0} s (600 + 0.3·120 = 636): {th:?}");
    let seen = th.self_heating_c * th.thermistor_at;
    assert!((seen / 0.45 - 1.0).abs() < 0.2, "rise the thermistor sees {seen:.3} °C (0.3·1.5 = 0.45): {th:?}");
    assert!(th.rms_c < 0.02, "rms {:.4} °C: {th:?}", th.rms_c);
    // And here, with a power cycle and two rates, the split too (grids of ×1.35 and ×1.5).
    assert!((th.case_tau_s / 600.0 - 1.0).abs() < 0.2, "case τ: {th:?}");
    assert!((th.die_tau_s / 120.0).ln().abs() < 1.6_f64.ln(), "die τ: {th:?}");
    assert!((0.2..=0.45).contains(&th.thermistor_at), "thermistor's share: {th:?}");
    // Without chamber_C nothing drives the case that the recording shows.
    let bare: Vec<Row> = rows
        .iter()
        .cloned()
        .map(|mut r| {
            r.chamber_c = None;
            r
        })
        .collect();
    let p = bins_cal::diagnose::prep::prepare(&bare, &bare, Path::new("s"), Path::new("r")).unwrap();
    assert!(propose::identify_thermal(&p).is_none());
}

#[test]
fn command_without_twin_identifies_the_thermal_path_and_still_cycles_the_power() {
    let dir = tempfile::tempdir().unwrap();
    let [s, r, _] = files(dir.path(), true);
    let (stdout, v) = diagnose_propose_with(dir.path(), &s, &r, None);
    assert!(stdout.contains("thermal path identified from the recording"), "{stdout}");
    let note = v["proposal"]["thermal_path"].as_str().unwrap();
    assert!(note.contains("case τ"), "{note}");
    let best = &v["proposal"]["candidates"][0];
    assert!(best["name"].as_str().unwrap().contains("power"), "{best}");
    let next = dir.path().join("next.toml");
    let sim = ScenarioFile::read(&next).unwrap().build(&next).unwrap();
    let hours = best["duration_h"].as_f64().unwrap();
    assert!((sim.duration_s() / 3600.0 - hours).abs() < 1e-6, "{} h vs {hours} h", sim.duration_s() / 3600.0);
}
