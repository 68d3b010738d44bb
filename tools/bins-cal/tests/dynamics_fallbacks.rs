//! What `calibrate --dynamics identify` writes and says when the dynamics cannot be or are not
//! identified, and recordings as rigs produce them: a ramp that reverses mid-run, a file
//! without the vibration columns. The recordings come from the blind generator
//! (`dynamics_gen`), which shares no code with the calibration or the simulator, and from the
//! paper's twin (`scenarios/paper-tilter.toml`).

#[allow(dead_code)] // the helpers other test files use
mod common;
mod dynamics_gen;

use bins_cal::calfile::CalibrationFile;
use common::{ok, repo};
use dynamics_gen::Unit;
use std::path::Path;

/// True when the calibration file has a `[thermal_dynamics]` table.
fn has_table(toml: &Path) -> bool {
    std::fs::read_to_string(toml).unwrap().lines().any(|l| l.trim() == "[thermal_dynamics]")
}

#[test]
fn nothing_identified_writes_no_table_and_says_what_was_tried() {
    let tmp = tempfile::tempdir().unwrap();
    let p = |n: &str| tmp.path().join(n).to_string_lossy().into_owned();
    // A unit without dynamics (white noise and a random walk only).
    let (cal, _) = dynamics_gen::recordings(&Unit::draw(1_000_003, true));
    std::fs::write(p("cal.csv"), cal).unwrap();
    let out = ok(&[
        "calibrate",
        "--tilter",
        &p("cal.csv"),
        "--model",
        "poly:2",
        "--max-rate-c-per-min",
        "0.2",
        "--dynamics",
        "identify",
        "-o",
        &p("cal.toml"),
        "--blob",
        &p("cal.bin"),
    ]);
    assert!(!has_table(Path::new(&p("cal.toml"))), "{out}");
    let blob = std::fs::read(p("cal.bin")).unwrap();
    assert_eq!(CalibrationFile::from_blob(&blob).unwrap().thermal_dynamics, None);
    let text = std::fs::read_to_string(p("cal.toml")).unwrap();
    let note = text.lines().find(|l| l.contains("thermal dynamics not identified")).expect(&out);
    for c in ["lag off: best at", "hysteresis off: best at", "bias_play off: best at", "held-out gain"] {
        assert!(note.contains(c), "{c}: {note}");
    }
    let negative_zero = text.split(|c: char| c.is_whitespace() || ",[]=".contains(c)).any(|t| t == "-0.0" || t == "-0");
    assert!(!negative_zero && !text.contains("τ = 0.0 s"), "{text}");
    // The search is in the log: the candidates of every combination.
    for c in ["lag + hysteresis + bias_play", "hysteresis + bias_play", "static"] {
        assert!(out.contains(c), "{c}: {out}");
    }
}

#[test]
fn the_paper_twin_has_no_dwell_during_a_ramp_and_says_so() {
    let tmp = tempfile::tempdir().unwrap();
    let p = |n: &str| tmp.path().join(n).to_string_lossy().into_owned();
    let sc = repo("scenarios/paper-tilter.toml").to_string_lossy().into_owned();
    ok(&["simulate", &sc, "-o", &p("paper.csv"), "--seed", "1"]);
    let out = ok(&[
        "calibrate",
        "--tilter",
        &p("paper.csv"),
        "--model",
        "poly:2",
        "--dynamics",
        "identify",
        "-o",
        &p("cal.toml"),
    ]);
    assert!(out.contains("no dwell during a ramp: the dynamics cannot be identified from this recording"), "{out}");
    assert!(!out.contains("grid over"), "searched anyway: {out}");
    assert!(!has_table(Path::new(&p("cal.toml"))));
}

#[test]
fn a_recording_without_the_vibration_columns_is_calibrated_on_its_labels_and_the_note_names_them() {
    let tmp = tempfile::tempdir().unwrap();
    let p = |n: &str| tmp.path().join(n).to_string_lossy().into_owned();
    let u = Unit::draw(5, false);
    let mut r = dynamics_gen::Rng::new(5);
    let chamber = dynamics_gen::chamber(20.0, &dynamics_gen::calibration_program(&u, &mut r));
    std::fs::write(p("cal.csv"), dynamics_gen::record(&u, &chamber, &dynamics_gen::TP, "TP", 1, false)).unwrap();
    let out = ok(&[
        "calibrate",
        "--tilter",
        &p("cal.csv"),
        "--model",
        "poly:2",
        "--max-rate-c-per-min",
        "0.2",
        "--dynamics",
        "identify",
        "-o",
        &p("cal.toml"),
    ]);
    assert!(!out.contains("static intervals"), "switched to the free fit: {out}");
    assert!(out.contains("no column(s) vib_kind, vib_x_g, vib_y_g, vib_z_g, vib_hz, vib_bw_hz"), "{out}");
    // The labelled path, and the dynamics found on it (the unit's τ within 20 %).
    let d = CalibrationFile::read(Path::new(&p("cal.toml"))).unwrap().thermal_dynamics.expect("a table");
    assert!((d.lag_tau_s - u.tau_s).abs() < 0.2 * u.tau_s, "{d:?} against τ = {} s", u.tau_s);
}

#[test]
fn a_ramp_that_reverses_mid_run_calibrates_with_the_stray_temperature_skipped() {
    let tmp = tempfile::tempdir().unwrap();
    let p = |n: &str| tmp.path().join(n).to_string_lossy().into_owned();
    let mut u = Unit::draw(8, false);
    u.reversal = true;
    u.rates_c_per_min = [1.0; 4];
    let (cal, _) = dynamics_gen::recordings(&u);
    std::fs::write(p("cal.csv"), cal).unwrap();
    // Static: the dwells settled while the ramp turns form a temperature of their own, skipped.
    let out = ok(&["calibrate", "--tilter", &p("cal.csv"), "--model", "poly:2", "-o", &p("static.toml")]);
    assert!(out.contains("skipped (the 12 constants need at least 4 positions)"), "{out}");
    // With the dynamics: the reversal's dwells are used, the unit's τ and h_b found.
    let out = ok(&[
        "calibrate",
        "--tilter",
        &p("cal.csv"),
        "--model",
        "poly:2",
        "--dynamics",
        "identify",
        "-o",
        &p("dyn.toml"),
    ]);
    let d = CalibrationFile::read(Path::new(&p("dyn.toml"))).unwrap().thermal_dynamics.expect(&out);
    assert!((d.lag_tau_s - u.tau_s).abs() < 0.2 * u.tau_s, "{d:?} against τ = {} s", u.tau_s);
    assert!((d.bias_play_width_c - u.hb_c).abs() < 0.2 * u.hb_c, "{d:?} against h_b = {} °C", u.hb_c);
}
