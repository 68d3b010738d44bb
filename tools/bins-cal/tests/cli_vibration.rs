//! `bins-cal vibration` run as a user would: Tables V4/V5 from Table V1 and the paper's
//! environments, and one-line errors for bad inputs.

use std::path::{Path, PathBuf};
use std::process::Command;

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data").join(name)
}

fn run(variant: &str, env: &Path, cf: &Path) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_bins-cal"))
        .args(["vibration", "--variant", variant, "--cf"])
        .arg(cf)
        .arg("--env")
        .arg(env)
        .output()
        .unwrap()
}

/// The numbers of one table row (the cells' low and high values, in column order).
fn row_numbers(stdout: &str, label: &str) -> Vec<f64> {
    let line = stdout.lines().find(|l| l.starts_with(label)).unwrap_or_else(|| panic!("no row {label}"));
    line[label.len()..].split_whitespace().filter_map(|w| w.parse().ok()).collect()
}

#[test]
fn paper_variant_reproduces_tables_v4_and_v5() {
    let out = run("paper", &data("vibration-env-paper.toml"), &data("al15-coefficients.csv"));
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let s = String::from_utf8_lossy(&out.stdout);
    // Table V4 (printed): Δ0(1) 13.39 µg, Δ0(2) 1.95–3.65 µg, δ(1)a 0.2307, δ(2)a² 0.5292,
    // δ(3)a³ 0.7938, total 1.571 mg.
    let v4 = row_numbers(&s, "V4 ω 50–100 1/s");
    let printed = [13.39, 13.39, 1.95, 3.65, 1.95, 3.65, 0.2307, 0.2307, 0.5292, 0.5292, 0.7938, 0.7938, 1.571];
    for (k, (got, want)) in v4.iter().zip(printed).enumerate() {
        assert!((got - want).abs() <= 0.006 * want, "V4 cell {k}: {got} vs {want}");
    }
    // Table V5 first and last rows (printed ranges): Δ0(1) 35.7–37.9 µg, total 5.68–6.04 mg;
    // 320–640 Hz: Δ0(2) 445.4 µg, δ(1)a 167, δ(2)a² 230, δ(3)a³ 346, total 762 mg.
    let first = row_numbers(&s, "V5 20–40 Hz");
    for (got, want) in [(first[0], 35.7), (first[1], 37.9), (first[12], 5.68), (first[13], 6.04)] {
        assert!((got - want).abs() <= 0.01 * want, "{got} vs {want}");
    }
    let last = row_numbers(&s, "V5 320–640 Hz");
    for (got, want) in [(last[2], 445.4), (last[6], 167.0), (last[8], 230.0), (last[10], 346.0), (last[12], 762.0)] {
        assert!((got - want).abs() <= 0.01 * want, "{got} vs {want}");
    }
}

#[test]
fn exact_variant_differs_where_the_paper_printed_wrong_moments() {
    let env = data("vibration-env-paper.toml");
    let cf = data("al15-coefficients.csv");
    let (p, e) = (run("paper", &env, &cf), run("exact", &env, &cf));
    assert!(e.status.success());
    let (p, e) = (String::from_utf8_lossy(&p.stdout), String::from_utf8_lossy(&e.stdout));
    // Random: the exact δ(2) uses 6 k4 σ² as printed, but Δ0(1) carries 3 k4 σ⁴ and the true
    // asymmetry mean, so the 320–640 Hz Δ0(1) must differ; δ(3) = 10 k5 σ² is the same.
    let (rp, re) = (row_numbers(&p, "V5 320–640 Hz"), row_numbers(&e, "V5 320–640 Hz"));
    assert!((rp[0] - re[0]).abs() > 0.05 * rp[0], "Δ0(1) {} vs {}", rp[0], re[0]);
    assert!((rp[10] - re[10]).abs() < 1e-9 * rp[10]);
}

#[test]
fn bad_inputs_are_one_line_errors() {
    let dir = tempfile::tempdir().unwrap();
    let env = dir.path().join("env.toml");
    std::fs::write(&env, "a_p3_g = 10\n[[random]]\nlabel='x'\nband_Hz=[40,20]\npsd_g2_per_Hz=[0.1,0.1]\n").unwrap();
    let out = run("paper", &env, &data("al15-coefficients.csv"));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("band_Hz") && err.trim_end().lines().count() == 1, "{err}");
    std::fs::write(&env, "a_p3_g = 10\nfrequency = 3\n").unwrap();
    let out = run("paper", &env, &data("al15-coefficients.csv"));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("frequency") && err.contains("env.toml"), "{err}");
    let cf = dir.path().join("cf.csv");
    std::fs::write(&cf, "a0_mg,K1_V_per_g\n1,2\n").unwrap();
    let out = run("paper", &data("vibration-env-paper.toml"), &cf);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("missing column `delta_1A_ppm`"), "{err}");
}
