//! Several mechanisms at once on a long recording (docs/diagnosis-blind.md, "The 3-hour case"):
//! REAL is `scenarios/three-hour-real.toml` (`--seed 1`: a turn-on warm-up, a 120 s die lag and a
//! 0.2 °C thermal hysteresis), SIM `scenarios/three-hour-sim.toml` (`--seed 2`: the same without
//! the three), both 3 h at 100 Hz (about 1.08 million rows each), made by `bins-cal simulate` and
//! diagnosed by `bins-cal diagnose` (the release binary: `--release`).
//!
//! `cargo test -p bins-cal --release --test diagnose_three_hour -- --ignored --nocapture` prints
//! what the diagnosis names, its ambiguous groups and each accelerometer's held-out RMS against
//! its noise floor; `THREE_HOUR_ASSERT=1` fails it unless the three mechanisms are named (or each
//! is in an ambiguous group on an accelerometer) and every accelerometer's held-out RMS after the
//! model is within 1.25× its floor. `THREE_HOUR_DIR=DIR` keeps the recordings and the report
//! there (and reuses recordings already there).
//!
//! `three_hour_noise_pair` diagnoses SIM against a second SIM of the same scenario (`--seed 1`):
//! the same unit and test with other noise, so REAL − SIM is the simulator's noise alone. Nothing
//! may be named, and it prints each accelerometer's held-out RMS against its floor: what the
//! noise alone leaves of the 1.25× target.

#[allow(dead_code)] // the helpers other test files use
mod common;

use std::path::{Path, PathBuf};

const AXES: [&str; 3] = ["x", "y", "z"];
/// The mechanisms REAL has and SIM lacks (all three act on every accelerometer).
const TRUTH: [&str; 3] = ["warmup", "thermal_lag", "thermal_hysteresis"];

#[test]
#[ignore = "two 1.08-million-row recordings and their diagnosis: run in release with --ignored"]
fn three_hour_several_mechanisms() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = work_dir(&tmp);
    let (sim, real) = (dir.join("sim.csv"), dir.join("real.csv"));
    simulate("scenarios/three-hour-sim.toml", "2", &sim);
    simulate("scenarios/three-hour-real.toml", "1", &real);
    let r = diagnose(&sim, &real, &dir.join("three-hour.json"));

    let ids = |v: &serde_json::Value| -> Vec<String> {
        v.as_array().into_iter().flatten().filter_map(|x| x.as_str().map(str::to_string)).collect()
    };
    let mut named: Vec<(String, Vec<String>)> = Vec::new();
    for e in r["effects"].as_array().into_iter().flatten() {
        let (id, axes) = (e["id"].as_str().unwrap_or("").to_string(), ids(&e["axes"]));
        println!("effect {id} on {}", axes.join(""));
        named.push((id, axes));
    }
    let mut groups: Vec<(Vec<String>, Vec<String>)> = Vec::new();
    for g in r["ambiguous"].as_array().into_iter().flatten() {
        let (set, axes) = (ids(&g["ids"]), ids(&g["axes"]));
        println!("ambiguous {} on {} (modelled as {})", set.join(" / "), axes.join(""), g["modelled_as"]);
        groups.push((set, axes));
    }
    let worst = print_axes(&r);
    let found: Vec<&str> = TRUTH
        .iter()
        .copied()
        .filter(|t| named.iter().any(|(id, _)| id == t) || groups.iter().any(|(set, _)| set.iter().any(|i| i == t)))
        .collect();
    let false_ids: Vec<&str> = named
        .iter()
        .map(|(id, _)| id.as_str())
        .chain(
            groups
                .iter()
                .filter(|(set, _)| !set.iter().any(|i| TRUTH.contains(&i.as_str())))
                .flat_map(|(s, _)| s.iter().map(String::as_str)),
        )
        .filter(|id| !TRUTH.contains(id))
        .collect();
    println!(
        "true mechanisms named or in a group: {}/3 ({}); other names: [{}]; worst held-out after/floor {worst:.2}",
        found.len(),
        found.join(", "),
        false_ids.join(", ")
    );
    if std::env::var("THREE_HOUR_ASSERT").is_ok_and(|v| v == "1") {
        assert_eq!(found.len(), 3, "the three mechanisms named or truthfully ambiguous: {found:?}");
        assert!(worst <= 1.25, "every axis within 1.25× its floor held-out: worst {worst:.2}");
    }
}

#[test]
#[ignore = "two 1.08-million-row recordings and their diagnosis: run in release with --ignored"]
fn three_hour_noise_pair() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = work_dir(&tmp);
    let (sim, sim1) = (dir.join("sim.csv"), dir.join("sim-seed1.csv"));
    simulate("scenarios/three-hour-sim.toml", "2", &sim);
    simulate("scenarios/three-hour-sim.toml", "1", &sim1);
    let r = diagnose(&sim, &sim1, &dir.join("noise-pair.json"));
    let worst = print_axes(&r);
    println!("worst held-out after/floor of the noise alone {worst:.2}");
    let effects = r["effects"].as_array().map_or(0, Vec::len);
    let groups = r["ambiguous"].as_array().map_or(0, Vec::len);
    assert_eq!((effects, groups), (0, 0), "the simulator's noise alone names nothing: {}", r["effects"]);
}

/// `THREE_HOUR_DIR` (created), or the temporary directory.
fn work_dir(tmp: &tempfile::TempDir) -> PathBuf {
    let dir = std::env::var("THREE_HOUR_DIR").map(PathBuf::from).unwrap_or_else(|_| tmp.path().to_path_buf());
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// `bins-cal simulate SCENARIO -o OUT --seed SEED`, unless `out` is already there.
fn simulate(scen: &str, seed: &str, out: &Path) {
    if out.exists() {
        return;
    }
    let t0 = std::time::Instant::now();
    common::ok(&["simulate", &common::repo(scen).to_string_lossy(), "-o", &out.to_string_lossy(), "--seed", seed]);
    println!("simulated {} in {:.0} s", out.display(), t0.elapsed().as_secs_f64());
}

/// `bins-cal diagnose --sim SIM --real REAL --report REP`, printed; the report.
fn diagnose(sim: &Path, real: &Path, rep: &Path) -> serde_json::Value {
    let t0 = std::time::Instant::now();
    let o = common::bin()
        .args(["diagnose", "--sim"])
        .arg(sim)
        .arg("--real")
        .arg(real)
        .arg("--report")
        .arg(rep)
        .output()
        .expect("bins-cal runs");
    assert!(o.status.success(), "diagnose failed: {}", String::from_utf8_lossy(&o.stderr));
    println!("diagnosed in {:.0} s\n{}", t0.elapsed().as_secs_f64(), String::from_utf8_lossy(&o.stdout));
    serde_json::from_str(&std::fs::read_to_string(rep).unwrap()).unwrap()
}

/// Prints each accelerometer's held-out RMS before and after against its floor; returns the
/// largest after / floor.
fn print_axes(r: &serde_json::Value) -> f64 {
    let mut worst = 0.0f64;
    for a in AXES {
        let f = |k: &str| r[k][a].as_f64().unwrap_or(f64::NAN);
        let (before, after, floor) = (f("heldout_rms_before_mg"), f("heldout_rms_after_mg"), f("noise_floor_mg"));
        println!(
            "{a}: held-out {before:.4} → {after:.4} mg, floor {floor:.4} mg, after/floor {:.2}, unexplained {:.4} mg, verdict {}",
            after / floor,
            f("unexplained_rms_mg"),
            r["verdict"][a]
        );
        worst = worst.max(after / floor);
    }
    worst
}
