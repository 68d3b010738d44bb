//! Identification of the thermal dynamics (`calib::dynamics`) on simulated tilter recordings
//! against the simulator's truth, and with no dynamics simulated.

use bins_cal::calib::dynamics::{self, Request, Series};
use bins_cal::calib::segments::Options;
use bins_cal::sim::scenario;
use bins_comp::Method;
use std::path::{Path, PathBuf};

fn repo(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").join(rel)
}

/// Simulates `scenario_text` (seed 1) into `dir`, reads it as a series.
fn series(dir: &Path, scenario_text: &str) -> Series {
    let toml = dir.join("s.toml");
    std::fs::write(&toml, scenario_text).unwrap();
    let sim = scenario::load(&toml).unwrap();
    let rec = dir.join("rec.csv");
    sim.write("s.toml", 1, &rec, false).unwrap();
    let opt = Options { settle_s: 1.0, max_std_v: 0.01, max_rate_c_per_min: 0.5, temp_tol_c: 3.0 };
    Series::read(&rec, &opt, "TP", 10.0).unwrap()
}

fn request() -> Request {
    Request { order: 2, t0_c: 20.0, k_prior: [[0.0; 3]; 3], method: Method::CoefficientCorrection }
}

#[test]
fn identifies_the_lag_the_play_and_the_bias_play_of_the_simulated_unit() {
    let tmp = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(repo("scenarios/dynamics-tilter.toml")).unwrap();
    let s = series(tmp.path(), &text);
    let id = dynamics::identify(std::slice::from_ref(&s), &request(), &mut |l| eprintln!("{l}")).unwrap();
    for c in &id.components {
        eprintln!("{c:?}");
    }
    let th = id.fit.theta;
    eprintln!("identified {th:?}, bias play {:?} mg", id.fit.bias_play_g.map(|b| b * 1e3));
    eprintln!(
        "rms static {:?} µg, dynamic {:?} µg",
        id.static_fit.rms_g().map(|r| r * 1e6),
        id.fit.rms_g().map(|r| r * 1e6)
    );
    // The scenario's truth.
    let rel = |got: f64, truth: f64| (got - truth).abs() / truth;
    assert!(rel(th.lag_tau_s, 180.0) < 0.2, "τ = {} s, truth 180 s", th.lag_tau_s);
    assert!(rel(th.hysteresis_width_c, 1.0) < 0.2, "h = {} °C, truth 1 °C", th.hysteresis_width_c);
    assert!(rel(th.bias_play_width_c, 4.0) < 0.2, "h_b = {} °C, truth 4 °C", th.bias_play_width_c);
    for (got, truth) in id.fit.bias_play_g.iter().zip([0.3e-3, -0.2e-3, 0.25e-3]) {
        assert!((got - truth).abs() < 0.2 * truth.abs(), "bias play {got} g, truth {truth} g");
    }
}

#[test]
fn identifies_no_dynamics_when_none_is_simulated() {
    let tmp = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(repo("scenarios/dynamics-tilter.toml")).unwrap();
    let text = text
        .replace("die_tau_s = 180.0", "die_tau_s = 0.0")
        .replace("hysteresis_C = 1.0", "hysteresis_C = 0.0")
        .replace("bias_play_mg = [0.3, -0.2, 0.25]", "bias_play_mg = [0.0, 0.0, 0.0]");
    let s = series(tmp.path(), &text);
    let id = dynamics::identify(std::slice::from_ref(&s), &request(), &mut |l| eprintln!("{l}")).unwrap();
    for c in &id.components {
        eprintln!("{c:?}");
        assert!(!c.on, "{} identified where none was simulated: {c:?}", c.name);
    }
    assert_eq!(id.fit.theta, dynamics::Theta::default());
}
