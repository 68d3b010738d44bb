//! The thermal dynamics on real data: the 71-minute chamber sweep of a MEMS IMU
//! (`data/real/tofupilot-sweep-real.csv`, MIT, tofupilot/examples; one orientation, z down,
//! ~52 → −18 → 74 → 36 °C). The dynamics are identified on the whole sweep as
//! `calibrate --dynamics identify` identifies them (θ chosen on held-out chunks, then the
//! identification's time-halves check: a bias play amplitude kept on an axis only where it
//! predicts the other half better in both directions, a lag or play dropped where it predicts
//! an axis worse). Then, as that check does, the static model of the same order and the kept
//! model (the same θ, the bias play on the same axes) are refitted on one half of the sweep
//! and the core compensates the other half's rows (held-out RMS of `a − f_ref` per axis), in
//! both directions, and on interleaved 10-minute chunks: no axis may be worse with the
//! dynamics, the three axes together must be better. The dynamics identified on each part
//! alone (θ held out too, the check run on that part) may keep less, but no axis worse.

use bins_cal::calib::dynamics::{self, Identification, Request, Series, Theta};
use bins_cal::calib::segments::Options;
use bins_cal::recording::read_all;
use bins_comp::dynamics::ThermalDynamics;
use bins_comp::{Calibration, CalibrationParams, Method};
use std::path::{Path, PathBuf};

fn repo(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").join(rel)
}

/// Held-out RMS per axis \[g\] of the core's compensation with `params` and `d` over the rows
/// `test` accepts against the reference.
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

/// The model over the whole calibrated range (the held-out half may lie outside the fitted one).
fn wide(p: &CalibrationParams) -> CalibrationParams {
    let mut p = *p;
    p.temp_range_c = (-40.0, 100.0);
    p
}

/// One split: its name, the held-out RMS per axis \[g\] static and with the kept dynamics;
/// and with the dynamics identified on the split's blocks alone (its own θ and check).
pub struct Outcome {
    pub name: &'static str,
    pub static_g: [f64; 3],
    pub dynamic_g: [f64; 3],
    /// The same θ with the bias play's amplitude fitted on every axis.
    pub every_axis_g: [f64; 3],
    pub own_g: [f64; 3],
    pub own_theta: Theta,
}

/// The identification on the whole sweep (its log on standard error), then per split the
/// static model and the kept one refitted on the split's blocks and compensated by the core
/// over the other rows.
pub fn splits(order: usize) -> (Identification, Vec<Outcome>) {
    let path = repo("data/real/tofupilot-sweep-real.csv");
    // One orientation held throughout: the whole record is one dwell (its signals change with
    // temperature by tens of mg, so the stationarity bound is wide).
    let opt = Options { settle_s: 0.0, max_std_v: 1.0, max_rate_c_per_min: 0.5, temp_tol_c: 3.0 };
    let all = Series::read(&path, &opt, "", 10.0).unwrap();
    let req = Request {
        order,
        t0_c: 20.0,
        k_prior: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        method: Method::CoefficientCorrection,
    };
    let id = dynamics::identify(std::slice::from_ref(&all), &req, &mut |l| eprintln!("{l}")).unwrap();
    let th = id.fit.theta;
    let axes = id.halves.as_ref().map_or([true; 3], |h| h.bias_axes);
    let k = id.static_fit.params.constants.k_v_per_g;
    let scale = [k[0][0], k[1][1], k[2][2]];
    // The identification's split: the middle of the blocks' span.
    let mid = dynamics::split_s(&all);
    let t0 = all.t_s[0];
    let chunk = 600.0;
    let even = move |t: f64| (((t - t0) / chunk).floor() as i64) % 2 == 0;
    let cases: [(&str, Split); 4] = [
        ("fit 1st half, predict 2nd", Box::new(move |t| t < mid)),
        ("fit 2nd half, predict 1st", Box::new(move |t| t >= mid)),
        ("fit even 10-min chunks, predict odd", Box::new(even)),
        ("fit odd 10-min chunks, predict even", Box::new(move |t| !even(t))),
    ];
    let mut out = Vec::new();
    for (name, fit_in) in cases {
        let s = all.keep(|a, b| fit_in(a) && fit_in(b));
        let st = dynamics::fit_at(std::slice::from_ref(&s), &Theta::default(), &req, scale).unwrap();
        let dy = dynamics::fit_at_axes(std::slice::from_ref(&s), &th, &req, scale, axes).unwrap();
        let static_g = heldout_rms(&path, &wide(&st.params), &ThermalDynamics::none(), &|t| !fit_in(t));
        let dynamic_g = heldout_rms(&path, &wide(&dy.params), &dy.dynamics(), &|t| !fit_in(t));
        let ev = dynamics::fit_at(std::slice::from_ref(&s), &th, &req, scale).unwrap();
        let every_axis_g = heldout_rms(&path, &wide(&ev.params), &ev.dynamics(), &|t| !fit_in(t));
        let own = dynamics::identify(std::slice::from_ref(&s), &req, &mut |_| {}).unwrap();
        let own_g = heldout_rms(&path, &wide(&own.fit.params), &own.dynamics(), &|t| !fit_in(t));
        out.push(Outcome { name, static_g, dynamic_g, every_axis_g, own_g, own_theta: own.fit.theta });
    }
    (id, out)
}

#[test]
fn dynamics_identified_on_the_real_sweep_predict_each_half_from_the_other_no_axis_worse() {
    // Order 3: the source's own calibration (a cubic per axis, as PX4 and ArduPilot fit).
    let order = 3;
    let (id, outcomes) = splits(order);
    let th = id.fit.theta;
    let b = id.fit.bias_play_g;
    let mg = |v: [f64; 3]| format!("{:.3} / {:.3} / {:.3}", v[0] * 1e3, v[1] * 1e3, v[2] * 1e3);
    eprintln!(
        "order {order}, identified on the whole sweep: τ = {:.1} s, h = {:.3} °C, h_b = {:.3} °C, bias play x / y / z {:+.3} / {:+.3} / {:+.3} mg",
        th.lag_tau_s,
        th.hysteresis_width_c,
        th.bias_play_width_c,
        b[0] * 1e3,
        b[1] * 1e3,
        b[2] * 1e3
    );
    for o in &outcomes {
        eprintln!(
            "order {order}, {}: held-out RMS x / y / z static {} mg, with dynamics {} mg (the bias play's amplitude on every axis: {} mg)",
            o.name,
            mg(o.static_g),
            mg(o.dynamic_g),
            mg(o.every_axis_g)
        );
    }
    for o in &outcomes {
        let t = o.own_theta;
        eprintln!(
            "order {order}, {}, identified on the fitted part alone: τ = {:.1} s, h = {:.3} °C, h_b = {:.3} °C; with dynamics {} mg",
            o.name,
            t.lag_tau_s,
            t.hysteresis_width_c,
            t.bias_play_width_c,
            mg(o.own_g)
        );
    }
    assert_ne!(th, Theta::default(), "no dynamics kept");
    // The rule, computed independently here (the core's compensation of the rows rather than
    // the identification's block means): the amplitude is kept on the axes where, refitted on
    // either half, it predicts the other half's rows better than the same θ without it (the
    // static cubic: no lag or play is kept on this sweep).
    assert_eq!((th.lag_tau_s, th.hysteresis_width_c), (0.0, 0.0), "the rule below assumes a bias play alone");
    let axes = id.halves.as_ref().expect("the time-halves check was made").bias_axes;
    let halves: Vec<&Outcome> = outcomes.iter().filter(|o| o.name.contains("half")).collect();
    for i in 0..3 {
        let better_both = halves.iter().all(|o| o.every_axis_g[i] < o.static_g[i]);
        assert_eq!(
            axes[i],
            better_both,
            "axis {i}: kept {axes:?}, the halves with the amplitude on every axis: {:?}",
            halves.iter().map(|o| (o.every_axis_g, o.static_g)).collect::<Vec<_>>()
        );
    }
    // The identification's own check says what the core's compensation below measures.
    let h = id.halves.as_ref().expect("the time-halves check was made");
    for d in 0..2 {
        for i in 0..3 {
            assert!(h.dynamic_rms_g[d][i] <= h.static_rms_g[d][i], "the identification's check, direction {d}: {h:?}");
        }
    }
    let norm = |v: &[f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    for o in &outcomes {
        // No axis worse (an axis without the bias play's amplitude and without a lag or play
        // is the static model itself: equal to the last bit) …
        for i in 0..3 {
            assert!(
                o.dynamic_g[i] <= o.static_g[i],
                "{}, axis {i}: held-out RMS with dynamics {} mg above the static {} mg",
                o.name,
                o.dynamic_g[i] * 1e3,
                o.static_g[i] * 1e3
            );
        }
        // … and the three together better.
        assert!(
            norm(&o.dynamic_g) < norm(&o.static_g),
            "{}: {:?} against the static {:?}",
            o.name,
            o.dynamic_g,
            o.static_g
        );
        // Identified on the fitted part alone (θ held out too), no axis worse either.
        for i in 0..3 {
            assert!(o.own_g[i] <= o.static_g[i], "{}, identified on the part, axis {i}: {:?}", o.name, o.own_g);
        }
    }
}
