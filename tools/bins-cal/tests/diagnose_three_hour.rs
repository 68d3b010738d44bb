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
//!
//! `proposed_test_run_alone` runs the test the diagnosis proposes for the 3-hour case
//! (`--propose next.toml --twin scenarios/three-hour-sim.toml`; docs/diagnosis.md, "When the
//! data cannot decide") on its own: `next.toml` as SIM (`--seed 2`), the same test with REAL's
//! physics (every unit, thermal and noise value where REAL's scenario differs from SIM's,
//! `--seed 1`) as REAL, and the same test's noise alone (SIM `--seed 1`). It prints what the
//! diagnosis of each pair names and each accelerometer's held-out RMS against its white floor
//! and against what the noise alone leaves on that test, twice: with the noise model estimated
//! from the data (white and a random walk), and with the residual's noise specification from the
//! twin's `[noise]` table (`--random-walk`, `--bias-instability`, `--bias-tau`: each √2 times
//! the unit's, SIM and REAL carrying the same noise independently). `THREE_HOUR_ASSERT=1` fails it
//! unless, with the specification, the three mechanisms are named or truthfully ambiguous, the
//! noise alone names nothing, and every accelerometer's held-out RMS is within 1.25× its white
//! floor.

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
    let (sim, real) = three_hour_pair(&dir);
    let r = diagnose(&sim, &real, &dir.join("three-hour.json"));

    let worst = print_axes(&r);
    let found = truth_found(&r);
    println!("worst held-out after/floor {worst:.2}");
    if std::env::var("THREE_HOUR_ASSERT").is_ok_and(|v| v == "1") {
        assert_eq!(found.len(), 3, "the three mechanisms named or truthfully ambiguous: {found:?}");
        assert!(worst <= 1.25, "every axis within 1.25× its floor held-out: worst {worst:.2}");
    }
}

#[test]
#[ignore = "the 3-hour pair, its proposal, and three 1.86-million-row runs of the proposed test: run in release with --ignored"]
fn proposed_test_run_alone() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = work_dir(&tmp);
    let (sim, real) = three_hour_pair(&dir);
    let next = dir.join("next.toml");
    let twin = common::repo("scenarios/three-hour-sim.toml");
    let r = diagnose_with(
        &sim,
        &real,
        &dir.join("three-hour.json"),
        &["--propose", &next.to_string_lossy(), "--twin", &twin.to_string_lossy()],
    );
    let best = &r["proposal"]["candidates"][0];
    println!("proposed: {} ({:.1} h)", best["name"], best["duration_h"].as_f64().unwrap_or(f64::NAN));
    assert!(best["duration_h"].as_f64().is_some_and(|h| h <= 8.0), "a test of at most 8 h: {best}");

    // REAL's physics on the proposed steps: every value REAL's scenario holds that SIM's does not.
    let next_real = dir.join("next-real.toml");
    std::fs::write(
        &next_real,
        with_differences(&next, "scenarios/three-hour-sim.toml", "scenarios/three-hour-real.toml"),
    )
    .unwrap();
    let (run_sim, run_real, run_noise) =
        (dir.join("next-sim.csv"), dir.join("next-real.csv"), dir.join("next-sim-seed1.csv"));
    simulate(&next.to_string_lossy(), "2", &run_sim);
    simulate(&next_real.to_string_lossy(), "1", &run_real);
    simulate(&next.to_string_lossy(), "1", &run_noise);

    let spec = residual_noise_spec(&next);
    let spec_args: Vec<&str> = spec.iter().map(String::as_str).collect();
    let mut outcome = Vec::new();
    for (label, more, tag) in
        [("the noise model estimated", &[][..], ""), ("the noise specification given", &spec_args[..], "-spec")]
    {
        println!("=== {label} {}", more.join(" "));
        println!("--- the proposed test's noise alone (SIM against SIM, other noise)");
        let noise = diagnose_with(&run_sim, &run_noise, &dir.join(format!("next-noise{tag}.json")), more);
        print_axes(&noise);
        let noise_names =
            noise["effects"].as_array().map_or(0, Vec::len) + noise["ambiguous"].as_array().map_or(0, Vec::len);
        println!("--- the proposed test, REAL against SIM");
        let run = diagnose_with(&run_sim, &run_real, &dir.join(format!("next-run{tag}.json")), more);
        let worst_floor = print_axes(&run);
        let found = truth_found(&run);
        let mut worst_noise = 0.0f64;
        for a in AXES {
            let after = |v: &serde_json::Value| v["heldout_rms_after_mg"][a].as_f64().unwrap_or(f64::NAN);
            let ratio = after(&run) / after(&noise);
            println!(
                "{a}: held-out after {:.4} mg against the noise alone's {:.4} mg: {ratio:.2}×",
                after(&run),
                after(&noise)
            );
            worst_noise = worst_noise.max(ratio);
        }
        println!(
            "worst held-out after / white floor {worst_floor:.2}, / the noise alone's {worst_noise:.2}; names on the noise alone: {noise_names}"
        );
        outcome.push((noise_names, found.len(), worst_floor));
    }
    if std::env::var("THREE_HOUR_ASSERT").is_ok_and(|v| v == "1") {
        let (noise_names, found, worst) = outcome[1];
        assert_eq!(noise_names, 0, "with the specification, the proposed test's noise alone names nothing");
        assert_eq!(found, 3, "with the specification, the three mechanisms named or truthfully ambiguous");
        assert!(worst <= 1.25, "with the specification, every axis within 1.25× its floor held-out: worst {worst:.2}");
    }
}

/// The 3-hour pair in `dir`: SIM (`three-hour-sim.toml`, `--seed 2`) and REAL
/// (`three-hour-real.toml`, `--seed 1`), simulated unless already there.
fn three_hour_pair(dir: &Path) -> (PathBuf, PathBuf) {
    let (sim, real) = (dir.join("sim.csv"), dir.join("real.csv"));
    simulate("scenarios/three-hour-sim.toml", "2", &sim);
    simulate("scenarios/three-hour-real.toml", "1", &real);
    (sim, real)
}

/// The noise specification of the residual REAL − SIM where both are simulated with the
/// `[noise]` table of `scenario`: `--random-walk`, `--bias-instability`, `--bias-tau`, each
/// amplitude √2 times the unit's (two independent draws), volts read as g (the 3-hour unit's
/// scale factor is not determinable from SIM, so the residual is at a nominal 1 V/g).
fn residual_noise_spec(scenario: &Path) -> Vec<String> {
    let t: toml::Table = toml::from_str(&std::fs::read_to_string(scenario).unwrap()).unwrap();
    let noise = t["noise"].as_table().expect("a [noise] table");
    let v = |k: &str| noise[k].as_float().unwrap_or_else(|| panic!("noise.{k}"));
    let two = std::f64::consts::SQRT_2;
    let rw_mg_per_sqrt_h = two * v("random_walk_V_per_sqrt_s") * 60.0 * 1e3;
    let gm_mg = two * v("bias_instability_V") * 1e3;
    [
        "--random-walk".to_string(),
        format!("{rw_mg_per_sqrt_h}"),
        "--bias-instability".to_string(),
        format!("{gm_mg}"),
        "--bias-tau".to_string(),
        format!("{}", v("bias_tau_s")),
    ]
    .into()
}

/// The scenario at `path` with every `[unit]`, `[thermal]` and `[noise]` value where `to`'s
/// scenario differs from `from`'s (both under the repository) set to `to`'s.
fn with_differences(path: &Path, from: &str, to: &str) -> String {
    let read = |p: &Path| -> toml::Table { toml::from_str(&std::fs::read_to_string(p).unwrap()).unwrap() };
    let (mut out, from, to) = (read(path), read(&common::repo(from)), read(&common::repo(to)));
    for table in ["unit", "thermal", "noise"] {
        let (f, t) = (from[table].as_table().unwrap(), to[table].as_table().unwrap());
        let o = out.get_mut(table).and_then(toml::Value::as_table_mut).expect("the proposal has the table");
        for (k, v) in t {
            if f.get(k) != Some(v) {
                println!("REAL's {table}.{k} = {v} (SIM {:?})", f.get(k).map(ToString::to_string));
                o.insert(k.clone(), v.clone());
            }
        }
    }
    toml::to_string(&out).unwrap()
}

/// The mechanisms of [`TRUTH`] the report names or holds in an ambiguous group; prints the
/// effects, the groups and any other name.
fn truth_found(r: &serde_json::Value) -> Vec<&'static str> {
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
    let found: Vec<&'static str> = TRUTH
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
        "true mechanisms named or in a group: {}/3 ({}); other names: [{}]",
        found.len(),
        found.join(", "),
        false_ids.join(", ")
    );
    found
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
    diagnose_with(sim, real, rep, &[])
}

/// [`diagnose`] with more arguments.
fn diagnose_with(sim: &Path, real: &Path, rep: &Path, more: &[&str]) -> serde_json::Value {
    let t0 = std::time::Instant::now();
    let o = common::bin()
        .args(["diagnose", "--sim"])
        .arg(sim)
        .arg("--real")
        .arg(real)
        .arg("--report")
        .arg(rep)
        .args(more)
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
