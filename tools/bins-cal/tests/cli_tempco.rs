//! `bins-cal tempco` run as a user would: the real binary on the paper's constants table
//! reproduces Table T3, and bad inputs give one-line errors naming the file and the problem.

use std::path::{Path, PathBuf};
use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_bins-cal"))
}

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data").join(name)
}

/// Table T3 as printed in the paper: (β_xx, β_yy, β_zz, α_x, α_y, α_z, γ_xy, γ_xz, γ_yx, γ_yz,
/// γ_zx, γ_zy) for −40…+20 °C and +20…+70 °C.
const T3_LOW: [f64; 12] = [
    -0.00000406,
    0.00001951,
    0.00000821,
    -0.00012202,
    -0.00008331,
    -0.00006473,
    0.00412678,
    0.00037706,
    0.00057535,
    -0.00189274,
    0.00038558,
    0.00577492,
];
const T3_HIGH: [f64; 12] = [
    0.00002884,
    0.00002850,
    0.00004391,
    -0.00001786,
    -0.00004026,
    0.00002467,
    -0.00344515,
    0.00016603,
    0.00062950,
    0.00046547,
    0.00016187,
    -0.00466918,
];

fn pick(range: &serde_json::Value) -> [f64; 12] {
    let g = |k: &str, f: &str| range[k][f].as_f64().unwrap_or_else(|| panic!("missing {k}.{f}"));
    [
        g("beta_per_C", "xx"),
        g("beta_per_C", "yy"),
        g("beta_per_C", "zz"),
        g("alpha_V_per_C", "x"),
        g("alpha_V_per_C", "y"),
        g("alpha_V_per_C", "z"),
        g("gamma_per_C", "xy"),
        g("gamma_per_C", "xz"),
        g("gamma_per_C", "yx"),
        g("gamma_per_C", "yz"),
        g("gamma_per_C", "zx"),
        g("gamma_per_C", "zy"),
    ]
}

#[test]
fn tempco_reproduces_table_t3() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("t3.json");
    let out = bin()
        .args(["tempco", "--constants"])
        .arg(data("paper-constants.csv"))
        .args(["--t0", "20", "--model", "pwl", "--json"])
        .arg(&json)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(v["model"], "pwl");
    let ranges = v["ranges"].as_array().unwrap();
    assert_eq!(ranges.len(), 2);
    assert_eq!((ranges[0]["from_C"].as_f64(), ranges[0]["to_C"].as_f64()), (Some(-40.0), Some(20.0)));
    for (range, printed) in [(&ranges[0], T3_LOW), (&ranges[1], T3_HIGH)] {
        for (k, (got, want)) in pick(range).iter().zip(printed).enumerate() {
            assert!((got - want).abs() <= 3e-7, "row {k}: {got} vs printed {want}");
        }
    }
}

#[test]
fn tempco_polynomial_through_three_temperatures() {
    let out = bin()
        .args(["tempco", "--constants"])
        .arg(data("paper-constants.csv"))
        .args(["--model", "poly:2"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(String::from_utf8_lossy(&out.stdout).contains("ΔT^2"));
}

fn fails_with(args: &[&str], file_text: Option<&str>, needle: &str) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("c.csv");
    let mut cmd = bin();
    cmd.arg("tempco").arg("--constants");
    match file_text {
        Some(t) => {
            std::fs::write(&path, t).unwrap();
            cmd.arg(&path);
        }
        None => {
            cmd.arg(data("paper-constants.csv"));
        }
    }
    cmd.args(args);
    let out = cmd.output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "should fail: {args:?}");
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
    assert!(err.contains(needle), "`{needle}` not in: {err}");
}

#[test]
fn tempco_bad_inputs_are_one_line_errors() {
    fails_with(&["--model", "poly:3"], None, "needs at least 3 temperatures besides T0");
    fails_with(&["--model", "spline"], None, "expected `pwl` or `poly:N`");
    fails_with(&["--t0", "25"], None, "no row at T0 = 25");
    let csv = std::fs::read_to_string(data("paper-constants.csv")).unwrap();
    fails_with(&[], Some(&csv.replace("Kzy", "Kzq")), "missing column `Kzy`");
    let bad_cell = csv.replacen("-0.55074263", "abc", 1);
    fails_with(&[], Some(&bad_cell), "c.csv:5: column 2 `Kxx`: `abc` is not a finite number");
    fails_with(&[], Some("temp_C,Kxx\n"), "missing column");
}
