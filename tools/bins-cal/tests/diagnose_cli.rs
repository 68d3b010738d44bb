//! `bins-cal diagnose` end to end: a generated pair through the command (report keys, plots,
//! augmented model), unusable inputs give one-line errors and a non-zero exit, the CSV path
//! never panics on mutated files (property test), and the time of a 30 000-row pair.

use bins_cal::diagnose::{cases, diagnose, diagnose_files};
use proptest::prelude::*;
use std::path::{Path, PathBuf};
use std::process::Command;

#[allow(dead_code)] // the CLI helpers other test files use
mod common;
use common::csv_text::Csv;
use common::write_recording as write;

fn case(name: &str, rows: usize) -> cases::Case {
    let mut c = cases::suite().into_iter().find(|c| c.name == name).unwrap();
    c.plan.rows = rows;
    c
}

fn bins_cal() -> Command {
    Command::new(env!("CARGO_BIN_EXE_bins-cal"))
}

fn pair(dir: &Path, name: &str, rows: usize) -> (PathBuf, PathBuf) {
    let (s, r) = cases::generate(&case(name, rows));
    let (sp, rp) = (dir.join("sim.csv"), dir.join("real.csv"));
    write(&sp, &s);
    write(&rp, &r);
    (sp, rp)
}

#[test]
fn command_writes_report_model_and_plots() {
    let dir = tempfile::tempdir().unwrap();
    let (sp, rp) = pair(dir.path(), "lag_plus_asymmetry", 12_000);
    let (rep, plots, model) = (dir.path().join("out.json"), dir.path().join("plots"), dir.path().join("model.toml"));
    let out = diagnose_cmd(&sp, &rp, &rep).arg("--plots").arg(&plots).arg("--model").arg(&model).output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}{}", stdout, String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&rep).unwrap()).unwrap();
    for key in [
        "effects",
        "ambiguous",
        "located",
        "noise_floor_mg",
        "rms_before_mg",
        "rms_after_mg",
        "heldout_rms_before_mg",
        "heldout_rms_after_mg",
    ] {
        assert!(v.get(key).is_some(), "report lacks {key}");
    }
    let ids: Vec<&str> = v["effects"].as_array().unwrap().iter().map(|e| e["id"].as_str().unwrap()).collect();
    assert!(ids.contains(&"thermal_lag") && ids.contains(&"sf_asymmetry"), "{ids:?}");
    let e = &v["effects"][0];
    for k in ["id", "axes", "params", "ci", "explanation"] {
        assert!(e.get(k).is_some(), "effect lacks {k}");
    }
    // The mismatch is located: heating/cooling strata on every axis carry it.
    let located = v["located"].as_array().unwrap();
    assert!(located.iter().any(|s| s["dimension"] == "thermal_state"), "{located:?}");
    // Plots: one residual plot per axis and one per effect and axis, real PNGs.
    let mut n = 0;
    for f in std::fs::read_dir(&plots).unwrap() {
        let p = f.unwrap().path();
        let bytes = std::fs::read(&p).unwrap();
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{}", p.display());
        n += 1;
    }
    assert_eq!(n, 3 + 3 + 3 + 1, "residual x/y/z, Allan x/y/z, lag x/y/z, asymmetry y");
    // The Allan curve before and after the named terms, with the noise model's line: white
    // noise at the floor plus the random walk tested against, the exact Allan variance of a
    // sampled random walk written here, σ² = σ_w²/m + q·τ₀(2m² + 1)/(6m).
    let allan = v["allan"].as_array().unwrap();
    assert!(allan.len() >= 4, "{}", allan.len());
    let tau0 = allan[0]["tau_s"].as_f64().unwrap();
    for ax in ["x", "y", "z"] {
        let floor = v["noise_floor_mg"][ax].as_f64().unwrap();
        let q = (v["random_walk_mg_per_sqrt_h"][ax].as_f64().unwrap()).powi(2) / 3600.0; // mg²/s
        for pt in allan {
            let tau = pt["tau_s"].as_f64().unwrap();
            let m = (tau / tau0).round();
            let want = (floor * floor / m + q * tau0 * (2.0 * m * m + 1.0) / (6.0 * m)).sqrt();
            let got = pt["model_mg"][ax].as_f64().unwrap();
            assert!((got - want).abs() <= 1e-9 * want, "{ax} τ = {tau}: model {got} against {want}");
            assert!(pt["after_mg"][ax].as_f64().unwrap() > 0.0);
        }
        // At one row the named terms change little; where the mismatch lives (the longest
        // τ) they take it out: after is below before.
        let (first, last) = (&allan[0], &allan[allan.len() - 1]);
        let ratio = |pt: &serde_json::Value| pt["after_mg"][ax].as_f64().unwrap() / pt["adev_mg"][ax].as_f64().unwrap();
        eprintln!(
            "{ax}: after/before at τ = {} s: {:.3}, at τ = {} s: {:.3}",
            first["tau_s"],
            ratio(first),
            last["tau_s"],
            ratio(last)
        );
        assert!((ratio(first) - 1.0).abs() < 0.05, "{ax}: {}", ratio(first));
        assert!(ratio(last) < 0.7, "{ax}: {}", ratio(last));
    }
    let m: toml::Value = toml::from_str(&std::fs::read_to_string(&model).unwrap()).unwrap();
    let terms = m["term"].as_array().unwrap();
    assert!(terms.iter().any(|t| t["id"].as_str() == Some("sf_asymmetry") && t["axis"].as_str() == Some("y")));
}

/// `bins-cal diagnose --sim SIM --real REAL --report REP`, for more arguments to be added.
fn diagnose_cmd(sim: &Path, real: &Path, rep: &Path) -> Command {
    let mut c = bins_cal();
    c.args(["diagnose", "--sim"]).arg(sim).arg("--real").arg(real).arg("--report").arg(rep);
    c
}

fn run_err(sim: &Path, real: &Path, dir: &Path) -> String {
    let out = diagnose_cmd(sim, real, &dir.join("r.json")).output().unwrap();
    assert!(!out.status.success());
    assert!(!dir.join("r.json").exists(), "no report on failure");
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
    err
}

#[test]
fn unusable_inputs_are_one_line_errors() {
    let dir = tempfile::tempdir().unwrap();
    let (s, r) = cases::generate(&case("cross_axis", 400));
    let sp = dir.path().join("sim.csv");
    write(&sp, &s);
    // Rows that do not match: one row fewer.
    let short = dir.path().join("short.csv");
    write(&short, &r[..399]);
    let e = run_err(&sp, &short, dir.path());
    assert!(e.contains("399 data rows") && e.contains("row for row"), "{e}");
    // A reference cell that differs names REAL's line and the column.
    let mut moved = r.clone();
    moved[10].f_g[1] = Some(0.5);
    let mp = dir.path().join("moved.csv");
    write(&mp, &moved);
    let e = run_err(&sp, &mp, dir.path());
    assert!(e.contains("moved.csv:") && e.contains("`fy_g`"), "{e}");
    // Missing reference columns.
    let bare = dir.path().join("bare.csv");
    let mut rec = Csv::read(&sp);
    rec.comments.clear();
    for r in std::iter::once(&mut rec.header).chain(rec.rows.iter_mut()) {
        r.truncate(5);
    }
    rec.write(&bare);
    let e = run_err(&bare, &bare, dir.path());
    assert!(e.contains("no row has a known reference"), "{e}");
    // A constant (dead) channel.
    let mut dead = r.clone();
    for row in &mut dead {
        row.u_v[2] = 0.25;
    }
    let dp = dir.path().join("dead.csv");
    write(&dp, &dead);
    let e = run_err(&sp, &dp, dir.path());
    assert!(e.contains("`uz_V` is constant"), "{e}");
    // A malformed cell names file, line and column.
    let bad = dir.path().join("bad.csv");
    let t = std::fs::read_to_string(&sp).unwrap().replacen("0.0,0.0,1.0", "0.0,zero,1.0", 1);
    std::fs::write(&bad, t).unwrap();
    let e = run_err(&sp, &bad, dir.path());
    assert!(e.contains("bad.csv:") && e.contains("column"), "{e}");
}

/// A 30 000-row pair (its time is measured by `cargo xtask bench`, not here).
#[test]
fn a_30000_row_pair_is_diagnosed() {
    let (s, r) = cases::generate(&case("warmup", 30_000));
    let d = diagnose(&s, &r, Path::new("sim"), Path::new("real")).unwrap();
    assert_eq!(d.report.effects.len(), 1);
    assert_eq!(d.report.effects[0].id, "warmup");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, failure_persistence: None, ..ProptestConfig::default() })]
    /// Mutated files (a cell replaced, a line cut, a line dropped) give Ok or a one-line
    /// error, never a panic.
    #[test]
    fn mutated_csv_never_panics(line in 0usize..80, cell in 0usize..16, what in 0u8..4, text in "[-a-z0-9.e,]{0,8}") {
        let dir = tempfile::tempdir().unwrap();
        let (sp, rp) = pair(dir.path(), "asymmetry_vs_k2_level", 60);
        let src = std::fs::read_to_string(&rp).unwrap();
        let mut rec = Csv::parse(&src);
        let ri = line % rec.rows.len();
        let ci = cell % rec.rows[ri].len();
        rec.rows[ri][ci] = text.clone();
        let replaced = rec.to_text();
        let mut lines: Vec<String> = src.lines().map(String::from).collect();
        let li = line % lines.len();
        match what {
            0 => lines = replaced.lines().map(String::from).collect(),
            1 => {
                let cut = lines[li].len() / 2;
                lines[li].truncate(cut);
            }
            2 => {
                lines.remove(li);
            }
            _ => lines.insert(li, text.clone()),
        }
        std::fs::write(&rp, lines.join("\n") + "\n").unwrap();
        if let Err(e) = diagnose_files(&sp, &rp, &Default::default()) {
            prop_assert!(!e.0.contains('\n'), "{}", e.0);
            prop_assert!(!e.0.is_empty());
        }
    }
}

/// `simulate --follow` writes the twin's prediction of a recording; `diagnose --calib` runs
/// against what a calibration file predicts; `--sim` and `--calib` exclude each other and one
/// is required.
#[test]
fn follow_and_calib_give_a_sim_for_a_real_recording() {
    let dir = tempfile::tempdir().unwrap();
    let (_, rp) = pair(dir.path(), "thermal_lag", 3_000);
    let scen = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios/test-tilter-3t.toml");
    let followed = dir.path().join("followed.csv");
    let out = bins_cal().arg("simulate").arg("--follow").arg(&rp).arg(&scen).arg("-o").arg(&followed).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let (_, real) = bins_cal::recording::read_all(&rp).unwrap();
    let (_, sim) = bins_cal::recording::read_all(&followed).unwrap();
    assert_eq!(real.len(), sim.len());
    assert!(sim.iter().zip(&real).all(|(s, r)| s.t_s == r.t_s && s.f_g == r.f_g && s.temp_c == r.temp_c));
    assert!(sim.iter().zip(&real).any(|(s, r)| s.u_v != r.u_v), "signals predicted, not copied");

    let cal = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../calibrations/paper-two-range.toml");
    let rep = dir.path().join("r.json");
    let out = bins_cal()
        .args(["diagnose", "--calib"])
        .arg(&cal)
        .arg("--real")
        .arg(&rp)
        .arg("--report")
        .arg(&rep)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let report: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&rep).unwrap()).unwrap();
    assert!(report["sim"].as_str().unwrap().contains("predicted by"), "{}", report["sim"]);

    let both = bins_cal()
        .args(["diagnose", "--calib"])
        .arg(&cal)
        .arg("--sim")
        .arg(&followed)
        .arg("--real")
        .arg(&rp)
        .arg("--report")
        .arg(&rep)
        .output()
        .unwrap();
    assert!(!both.status.success());
    let neither = bins_cal().args(["diagnose", "--real"]).arg(&rp).arg("--report").arg(&rep).output().unwrap();
    assert!(!neither.status.success());
    assert!(String::from_utf8_lossy(&neither.stderr).contains("--sim"), "{}", String::from_utf8_lossy(&neither.stderr));
}

/// The README's recipe (calibrate on `test-tilter-3t`, diagnose `diagnose-ramps` seed 2; the
/// die lags by 150 s, nothing else is concealed) with `--random-walk 0`, which the command
/// allows: the given random walk is raised to what the residual shows at short averaging
/// times (a note says so), no turn-on term is offered on a unit powered on 100 000 s before
/// the recording, no hysteresis is taken for the drift, and the model holds the lag only.
#[test]
fn recipe_with_random_walk_zero_names_only_what_the_data_has() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scen = |n: &str| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios").join(n);
    let run = |args: &[&std::ffi::OsStr]| {
        let out = bins_cal().args(args).output().unwrap();
        assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8_lossy(&out.stdout).to_string()
    };
    let os = |s: &str| std::ffi::OsString::from(s);
    let (cal, unit, ramps) = (d.join("cal.csv"), d.join("unit.toml"), d.join("ramps.csv"));
    let (rep, model) = (d.join("d.json"), d.join("model.toml"));
    run(&[
        &os("simulate"),
        scen("test-tilter-3t.toml").as_os_str(),
        &os("-o"),
        cal.as_os_str(),
        &os("--seed"),
        &os("1"),
    ]);
    run(&[
        &os("calibrate"),
        &os("--tilter"),
        cal.as_os_str(),
        &os("--model"),
        &os("poly:2"),
        &os("-o"),
        unit.as_os_str(),
    ]);
    run(&[
        &os("simulate"),
        scen("diagnose-ramps.toml").as_os_str(),
        &os("-o"),
        ramps.as_os_str(),
        &os("--seed"),
        &os("2"),
    ]);
    let stdout = run(&[
        &os("diagnose"),
        &os("--calib"),
        unit.as_os_str(),
        &os("--real"),
        ramps.as_os_str(),
        &os("--report"),
        rep.as_os_str(),
        &os("--model"),
        model.as_os_str(),
        &os("--random-walk"),
        &os("0"),
    ]);
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&rep).unwrap()).unwrap();
    let mut named: Vec<String> =
        v["effects"].as_array().unwrap().iter().map(|e| e["id"].as_str().unwrap().to_string()).collect();
    for g in v["ambiguous"].as_array().unwrap() {
        named.extend(g["ids"].as_array().unwrap().iter().map(|i| i.as_str().unwrap().to_string()));
    }
    assert!(named.iter().any(|i| i == "thermal_lag"), "{stdout}");
    for absent in ["warmup", "self_heating", "thermal_hysteresis", "bias_hysteresis"] {
        assert!(!named.iter().any(|i| i == absent), "{absent} named: {stdout}");
    }
    assert!(stdout.contains("the given random walk 0.000 mg/√h is below"), "{stdout}");
    let m: toml::Value = toml::from_str(&std::fs::read_to_string(&model).unwrap()).unwrap();
    for t in m["term"].as_array().unwrap() {
        let id = t["id"].as_str().unwrap();
        assert!(id == "thermal_lag" || id.starts_with("cross_"), "{id} in the model: {stdout}");
        for (k, p) in t["params"].as_table().unwrap() {
            let x = p.as_float().unwrap();
            assert!(x.is_finite() && x.abs() < 1e4, "{id} {k} = {x}");
        }
    }
}

/// `--noise` is refused beside `--random-walk` or `--bias-instability`, and a file that is
/// missing, not a scenario, or without noise on an accelerometer is named in one line with
/// nothing written.
#[test]
fn a_noise_file_is_checked() {
    let dir = tempfile::tempdir().unwrap();
    let (sp, rp) = pair(dir.path(), "null_random_walk", 2_000);
    let rep = dir.path().join("r.json");
    let noise = dir.path().join("noise.toml");
    let quiet = |noise_table: &str| {
        format!(
            "description = \"quiet\"\n[recording]\nrate_Hz = 10.0\n[unit]\npreset = \"paper\"\n[thermal]\nstart_C = 20.0\n[noise]\n{noise_table}\n[[step]]\nkind = \"soak\"\nchamber_C = 20.0\ndwell_s = 100.0\n"
        )
    };
    let n = noise.to_str().unwrap();
    for (table, more, says) in [
        (None, &["--noise", n][..], "noise.toml"),
        (Some("white_V = 1e-5"), &["--noise", n, "--random-walk", "0.1"][..], "--random-walk"),
        (
            Some("white_V = 1e-5"),
            &["--noise", n, "--bias-instability", "0.1", "--bias-tau", "60"][..],
            "--bias-instability",
        ),
        (Some("white_V = [1e-5, 0.0, 1e-5]"), &["--noise", n][..], "noise.white_V[1]"),
        (Some("white = 1e-5"), &["--noise", n][..], "white"),
    ] {
        match table {
            Some(t) => std::fs::write(&noise, quiet(t)).unwrap(),
            None => {
                let _ = std::fs::remove_file(&noise);
            }
        }
        let out = diagnose_cmd(&sp, &rp, &rep).args(more).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && err.contains(says), "{more:?}: {err}");
        assert!(!rep.exists(), "{more:?}: no report on failure");
    }
}

/// `--bias-instability` and `--bias-tau` go together and must be positive (one-line errors
/// naming the option, nothing written); given, the report carries them, the printed noise line
/// names them, and on the suite's random-walk null (a 20 µg, 600 s Gauss–Markov bias and a
/// 2 µg/√s random walk in REAL, SIM noise-free) with its own specification nothing is named.
#[test]
fn a_given_bias_instability_is_checked_and_reported() {
    let dir = tempfile::tempdir().unwrap();
    let (sp, rp) = pair(dir.path(), "null_random_walk", 12_000);
    let rep = dir.path().join("r.json");
    let run = |more: &[&str]| diagnose_cmd(&sp, &rp, &rep).args(more).output().unwrap();
    for (more, flag) in [
        (&["--bias-instability", "0", "--bias-tau", "600"][..], "--bias-instability 0"),
        (&["--bias-instability", "0.02", "--bias-tau=-5"][..], "--bias-tau -5"),
        (&["--bias-instability", "0.02"][..], "--bias-tau"),
    ] {
        let out = run(more);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && err.contains(flag), "{more:?}: {err}");
        assert!(!rep.exists(), "{more:?}: no report on failure");
    }
    let out = run(&["--random-walk", "0.12", "--bias-instability", "0.02", "--bias-tau", "600"]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(stdout.contains("beside a bias instability of 0.0200 mg, τ = 600 s (given)"), "{stdout}");
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&rep).unwrap()).unwrap();
    for ax in ["x", "y", "z"] {
        let (mg, tau_s) = (&v["bias_instability_mg_tau_s"][ax][0], &v["bias_instability_mg_tau_s"][ax][1]);
        assert!((mg.as_f64().unwrap() - 0.02).abs() < 1e-12 && tau_s.as_f64() == Some(600.0), "{ax}: {mg} {tau_s}");
    }
    let named = v["effects"].as_array().unwrap().len() + v["ambiguous"].as_array().unwrap().len();
    assert_eq!(named, 0, "the null names nothing with its own noise specification: {stdout}");
}
