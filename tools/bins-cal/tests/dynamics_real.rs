//! The thermal dynamics on real data: the 71-minute chamber sweep of a MEMS IMU
//! (`data/real/tofupilot-sweep-real.csv`, MIT, tofupilot/examples; one orientation, z down,
//! ~52 → −18 → 74 → 36 °C). A calibration with dynamics fitted on one half of the sweep must
//! predict the other half better than the static model of the same order fitted on the same
//! half, compensated by the core (held-out RMS of `a − f_ref`): per axis on interleaved
//! chunks, over the three axes together on the time halves (which extrapolate in temperature).

use bins_cal::calib::dynamics::{self, Request, Series, Theta};
use bins_cal::calib::segments::Options;
use bins_cal::recording::read_all;
use bins_comp::dynamics::ThermalDynamics;
use bins_comp::{Calibration, CalibrationParams, Method};
use std::path::{Path, PathBuf};

fn repo(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").join(rel)
}

/// Held-out RMS per axis \[g\] of the core's compensation with `params` and `d` over the rows
/// in `[from, to)` against the reference.
fn heldout_rms(
    path: &Path,
    params: &CalibrationParams,
    d: &ThermalDynamics<f64>,
    test: &dyn Fn(f64) -> bool,
) -> [f64; 3] {
    let (_, rows) = read_all(path).unwrap();
    let cal = Calibration::new(params).unwrap();
    let e = dynamics::run_core(&rows, d);
    let (mut ss, mut n) = ([0.0; 3], 0usize);
    for (r, e) in rows.iter().zip(&e) {
        let Some(f) = r.reference_f_g() else { continue };
        if !test(r.t_s) {
            continue;
        }
        let a = dynamics::compensate(&cal, d, r.u_v, e);
        for i in 0..3 {
            ss[i] += (a[i] - f[i]).powi(2);
        }
        n += 1;
    }
    ss.map(|s| (s / n as f64).sqrt())
}

/// Which rows a split fits on (by time).
type Split = Box<dyn Fn(f64) -> bool>;

pub fn halves(order: usize) -> Vec<(String, [f64; 3], [f64; 3], Theta)> {
    let path = repo("data/real/tofupilot-sweep-real.csv");
    // One orientation held throughout: the whole record is one dwell (its signals change with
    // temperature by tens of mg, so the stationarity bound is wide).
    let opt = Options { settle_s: 0.0, max_std_v: 1.0, max_rate_c_per_min: 0.5, temp_tol_c: 3.0 };
    let all = Series::read(&path, &opt, "", 10.0).unwrap();
    let (t0, t1) = (all.t_s[0], *all.t_s.last().unwrap());
    let mid = 0.5 * (t0 + t1);
    let req = Request {
        order,
        t0_c: 20.0,
        k_prior: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        method: Method::CoefficientCorrection,
    };
    let mut out = Vec::new();
    let chunk = 600.0;
    let even = move |t: f64| (((t - t0) / chunk).floor() as i64) % 2 == 0;
    let cases: [(&str, Split); 4] = [
        ("fit 1st half, predict 2nd", Box::new(move |t| t < mid)),
        ("fit 2nd half, predict 1st", Box::new(move |t| t >= mid)),
        ("fit even 10-min chunks, predict odd", Box::new(even)),
        ("fit odd 10-min chunks, predict even", Box::new(move |t| !even(t))),
    ];
    for (name, fit_in) in cases {
        let s = all.keep(|a, b| fit_in(a) && fit_in(b));
        let id = dynamics::identify(std::slice::from_ref(&s), &req, &mut |_| {}).unwrap();
        let wide = |p: &CalibrationParams| {
            let mut p = *p;
            p.temp_range_c = (-40.0, 100.0);
            p
        };
        let th = id.fit.theta;
        let d = id.dynamics();
        let stat = heldout_rms(&path, &wide(&id.static_fit.params), &ThermalDynamics::none(), &|t| !fit_in(t));
        let dynm = heldout_rms(&path, &wide(&id.fit.params), &d, &|t| !fit_in(t));
        out.push((name.to_string(), stat, dynm, th));
    }
    out
}

#[test]
fn dynamics_fitted_on_one_half_of_the_real_sweep_predict_the_other_half_better() {
    // Order 3: the source's own calibration (a cubic per axis, as PX4 and ArduPilot fit).
    let order = 3;
    let mut results = Vec::new();
    for (name, stat, dynm, th) in halves(order) {
        eprintln!(
            "order {order}, {name}: τ = {:.1} s, h = {:.3} °C, h_b = {:.3} °C; held-out RMS x/y/z static {:.3}/{:.3}/{:.3} mg, with dynamics {:.3}/{:.3}/{:.3} mg",
            th.lag_tau_s,
            th.hysteresis_width_c,
            th.bias_play_width_c,
            stat[0] * 1e3,
            stat[1] * 1e3,
            stat[2] * 1e3,
            dynm[0] * 1e3,
            dynm[1] * 1e3,
            dynm[2] * 1e3
        );
        results.push((name, stat, dynm, th));
    }
    let norm = |v: &[f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    for (name, stat, dynm, th) in &results {
        assert_ne!(*th, Theta::default(), "{name}: no dynamics kept");
        if name.contains("chunks") {
            // The interleaved chunks cover the same temperatures, heating and cooling, in both
            // halves: the dynamics predict the other half better on every axis.
            for i in 0..3 {
                assert!(
                    dynm[i] < stat[i],
                    "{name}, axis {i}: held-out RMS with dynamics {} mg not below the static {} mg",
                    dynm[i] * 1e3,
                    stat[i] * 1e3
                );
            }
        } else {
            // The time halves extrapolate in temperature (one h_b for the three axes): better
            // over the three axes together.
            assert!(norm(dynm) < norm(stat), "{name}: {dynm:?} against the static {stat:?}");
        }
    }
}
