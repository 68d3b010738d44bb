//! `bins-cal export`: calibrate → export → the parameter files read back and evaluated here,
//! independently, by each autopilot's formula as its firmware computes it (in `f32`):
//!
//! - PX4 `TemperatureCompensation::calc_thermal_offsets_3D`: `Δ = clamp(T, TMIN, TMAX) − TREF`,
//!   `offset = X0 + X1·Δ + X2·Δ² + X3·Δ³` \[m/s²\];
//! - ArduPilot `AP_InertialSensor::TCal::correct_sensor`: `p(clamp(T) − 35) − p(clamp(Tcal) − 35)`,
//!   `p(d) = (ACC1 + (ACC2 + ACC3·d)·d)·d·1e-6` \[m/s²\];
//!
//! against the calibration's bias computed here from the calibration file's own keys,
//! `b(T) = N·Σₙ αₙ·(T − T0)ⁿ` (N = K(T0)⁻¹ or 1 g/V), within 1 µg over the calibrated range.

#[allow(dead_code)]
mod common;

use common::{ok, repo, run};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

const G: f64 = 9.80665;

/// The small simulated campaign of the paper's unit (scenarios/test-tilter-3t.toml) and its
/// poly:2 calibration, made once.
fn campaign() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap().keep();
        let rec = dir.join("t3.csv");
        let scen = repo("scenarios/test-tilter-3t.toml");
        ok(&["simulate", scen.to_str().unwrap(), "-o", rec.to_str().unwrap(), "--seed", "1", "--quiet"]);
        let cal = dir.join("t3.toml");
        ok(&["calibrate", "--tilter", s(&rec), "--model", "poly:2", "--method", "1", "-o", s(&cal)]);
        dir
    })
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The calibration file's T0, range, K, and α terms, read with the `toml` crate.
struct Cal {
    t0: f64,
    range: (f64, f64),
    k: [[f64; 3]; 3],
    alpha: Vec<(i32, [f64; 3])>,
}

fn read_cal(path: &Path) -> Cal {
    let v: toml::Table = toml::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    let f = |x: &toml::Value| x.as_float().unwrap();
    let arr3 = |x: &toml::Value| {
        let a = x.as_array().unwrap();
        [f(&a[0]), f(&a[1]), f(&a[2])]
    };
    let r = v["temp_range_C"].as_array().unwrap();
    let k = v["k_V_per_g"].as_array().unwrap();
    let model = v["temperature_model"].as_table().unwrap();
    assert_eq!(model["kind"].as_str(), Some("poly"));
    let alpha = model["term"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| (t["power"].as_integer().unwrap() as i32, arr3(&t["alpha_V_per_Cn"])))
        .collect();
    Cal { t0: f(&v["t0_C"]), range: (f(&r[0]), f(&r[1])), k: [arr3(&k[0]), arr3(&k[1]), arr3(&k[2])], alpha }
}

/// The 3×3 inverse by cofactors.
fn inv3(m: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let c = |i: usize, j: usize| {
        let (a, b) = ((i + 1) % 3, (i + 2) % 3);
        let (x, y) = ((j + 1) % 3, (j + 2) % 3);
        m[a][x] * m[b][y] - m[a][y] * m[b][x]
    };
    let det: f64 = (0..3).map(|j| m[0][j] * c(0, j)).sum();
    [0, 1, 2].map(|i| [0, 1, 2].map(|j| c(j, i) / det))
}

/// b(T) [g]: N·ΔU0(T), T clamped to the range.
fn bias(cal: &Cal, calibrated: bool, t: f64) -> [f64; 3] {
    let t = t.clamp(cal.range.0, cal.range.1);
    let du: [f64; 3] = [0, 1, 2].map(|i| cal.alpha.iter().map(|(n, a)| a[i] * (t - cal.t0).powi(*n)).sum());
    if !calibrated {
        return du;
    }
    let n = inv3(&cal.k);
    [0, 1, 2].map(|i| (0..3).map(|j| n[i][j] * du[j]).sum())
}

/// A PX4 .params file: name → value.
fn read_px4(path: &Path) -> HashMap<String, f32> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| {
            let c: Vec<&str> = l.split('\t').collect();
            assert_eq!(c.len(), 5, "{l}");
            assert_eq!(c[4], if c[2].ends_with("_ID") || c[2] == "TC_A_ENABLE" { "6" } else { "9" }, "{l}");
            (c[2].to_string(), c[3].parse::<f32>().unwrap())
        })
        .collect()
}

/// An ArduPilot .parm file: name → value.
fn read_parm(path: &Path) -> HashMap<String, f32> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| {
            let (n, v) = l.split_once(',').unwrap();
            (n.to_string(), v.parse::<f32>().unwrap())
        })
        .collect()
}

/// PX4's offset [m/s²] at `t`, by calc_thermal_offsets_3D.
fn px4_offset(p: &HashMap<String, f32>, n: u8, t: f32) -> [f32; 3] {
    let g = |k: &str| p[&format!("TC_A{n}_{k}")];
    let (tref, tmin, tmax) = (g("TREF"), g("TMIN"), g("TMAX"));
    let d = if t > tmax {
        tmax - tref
    } else if t < tmin {
        tmin - tref
    } else {
        t - tref
    };
    let (d2, d3) = (d * d, d * d * d);
    [0, 1, 2].map(|i| {
        g(&format!("X0_{i}")) + g(&format!("X1_{i}")) * d + g(&format!("X2_{i}")) * d2 + g(&format!("X3_{i}")) * d3
    })
}

/// ArduPilot's correction [m/s²] at `t` for an accelerometer calibrated at `tcal`, by
/// correct_sensor.
fn ardupilot_correction(p: &HashMap<String, f32>, n: u8, t: f32, tcal: f32) -> [f32; 3] {
    let g = |k: &str| p[&format!("INS_TCAL{n}_{k}")];
    assert_eq!(g("ENABLE"), 1.0);
    let (tmin, tmax) = (g("TMIN"), g("TMAX"));
    let poly = |d: f32| {
        [0, 1, 2].map(|i| {
            let a = ["X", "Y", "Z"][i];
            let c = |k: u8| g(&format!("ACC{k}_{a}"));
            (c(1) + (c(2) + c(3) * d) * d) * d * 1.0e-6_f32
        })
    };
    let (a, b) = (poly(t.clamp(tmin, tmax) - 35.0), poly(tcal.clamp(tmin, tmax) - 35.0));
    [0, 1, 2].map(|i| a[i] - b[i])
}

/// Temperatures over the range and 10 °C beyond each end (where both autopilots clamp).
fn temps(cal: &Cal) -> Vec<f64> {
    let (lo, hi) = (cal.range.0 - 10.0, cal.range.1 + 10.0);
    (0..=520).map(|k| lo + (hi - lo) * k as f64 / 520.0).collect()
}

#[test]
fn px4_and_ardupilot_parameters_evaluate_to_the_calibrations_bias_within_1_ug() {
    let dir = campaign();
    let cal_path = dir.join("t3.toml");
    let cal = read_cal(&cal_path);
    for (raw, calibrated) in [("calibrated", true), ("logged", false)] {
        let px4 = dir.join(format!("{raw}.params"));
        let parm = dir.join(format!("{raw}.parm"));
        let out = ok(&[
            "export",
            s(&cal_path),
            "--px4",
            s(&px4),
            "--ardupilot",
            s(&parm),
            "--raw",
            raw,
            "--instance",
            "1",
            "--device-id",
            "2424842",
        ]);
        assert!(out.contains("not exported: scale factors and cross-axis"), "{out}");
        let p = read_px4(&px4);
        assert_eq!((p["TC_A_ENABLE"], p["TC_A1_ID"]), (1.0, 2424842.0));
        let a = read_parm(&parm);
        let mut worst: f64 = 0.0;
        for t in temps(&cal) {
            let b = bias(&cal, calibrated, t);
            let o = px4_offset(&p, 1, t as f32);
            for i in 0..3 {
                worst = worst.max((o[i] as f64 / G - b[i]).abs());
            }
            for tcal in [cal.t0, 25.0, cal.range.0, cal.range.1] {
                let c = ardupilot_correction(&a, 2, t as f32, tcal as f32);
                let b0 = bias(&cal, calibrated, tcal);
                for i in 0..3 {
                    worst = worst.max((c[i] as f64 / G - (b[i] - b0[i])).abs());
                }
            }
        }
        assert!(worst < 1e-6, "{raw}: {} µg", worst * 1e6);
        // The bias is not zero: the test compares something (mg over the range).
        let span = bias(&cal, calibrated, cal.range.1)[0] - bias(&cal, calibrated, cal.range.0)[0];
        assert!(span.abs() > 1e-3, "{raw}: {span}");
    }
}

#[test]
fn the_held_out_check_prints_the_export_beside_the_full_model() {
    let dir = campaign();
    let out =
        ok(&["export", s(&dir.join("t3.toml")), "--px4", s(&dir.join("c.params")), "--check", s(&dir.join("t3.csv"))]);
    // Per check temperature: T0 constants, full model, PX4 export [mg]. The export keeps the
    // offset and loses the scale and cross-axis terms: better than the T0 constants, worse
    // than the full model away from T0.
    let rows: Vec<Vec<f64>> = out
        .lines()
        .skip_while(|l| !l.contains("PX4 export"))
        .skip(1)
        .take_while(|l| !l.starts_with("wrote"))
        .map(|l| l.split_whitespace().map(|x| x.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), 3, "{out}");
    for r in rows.iter().filter(|r| (r[0] - 20.0).abs() > 5.0) {
        assert!(r[3] < r[1] && r[3] > r[2], "{out}");
    }
}

#[test]
fn a_piecewise_model_is_fitted_and_its_error_said() {
    let dir = tempfile::tempdir().unwrap();
    let parm = dir.path().join("two-range.parm");
    let cal = repo("calibrations/paper-two-range.toml");
    let out = ok(&["export", s(&cal), "--ardupilot", s(&parm)]);
    let line = out.lines().find(|l| l.contains("cubic fit")).unwrap();
    let err_ug: f64 = line.split("largest error ").nth(1).unwrap().split(' ').next().unwrap().parse().unwrap();
    // Two straight lines with a kink at T0: a cubic misses it by tens of µg or more.
    assert!(err_ug > 10.0, "{line}");
    let o = run(&["export", s(&cal)]);
    assert!(!o.status.success());
    let o = run(&["export", s(&cal), "--px4", s(&cal)]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("refusing to write the output over the input"));
}
