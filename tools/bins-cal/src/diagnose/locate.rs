//! Where the mismatch is: the raw residual (one offset removed), or what the model leaves of
//! it, averaged over strata of the test (time window, rig position, temperature band,
//! heating/cooling/steady, ramp rate, vibration condition, time since power-on). The standard
//! error is that of the noise model: the white variances of the stratum's rows times the
//! variance inflation of the remaining autocorrelation, plus the random walk's share over the
//! stratum's time span (`q·span/3`), so a stratum is located only where the mean departs from
//! what white noise and the drift of the noise model would give.

use super::fit::AxisFit;
use super::prep::{AXES, Prepared};
use serde::Serialize;

/// One stratum that carries mismatch.
#[derive(Clone, Debug, Serialize)]
pub struct Stratum {
    /// Accelerometer.
    pub axis: String,
    /// What the stratum is cut by.
    pub dimension: String,
    /// Its value.
    pub value: String,
    /// Rows in it.
    pub rows: usize,
    /// Time spent in it \[s\].
    pub duration_s: f64,
    /// Mean residual (relative to the whole record's mean) \[mg\].
    pub mean_mg: f64,
    /// Standard error of the mean \[mg\].
    pub se_mg: f64,
    /// `mean / se`.
    pub z: f64,
    /// Effective number of independent rows (rows / variance inflation).
    pub n_eff: f64,
}

/// |z| above which a stratum is reported.
pub const Z_LOCATED: f64 = 4.0;

fn strata(p: &Prepared) -> Vec<(String, String, Vec<bool>)> {
    let n = p.t.len();
    let mut out = Vec::new();
    for (k, name) in p.pos_names.iter().enumerate() {
        out.push(("pos".into(), name.clone(), p.pos.iter().map(|x| *x == Some(k)).collect()));
    }
    let (t0, t1) = (p.t.first().copied().unwrap_or(0.0), p.t.last().copied().unwrap_or(0.0));
    if t1 > t0 {
        let nw = 8;
        let w = (t1 - t0) / nw as f64;
        for b in 0..nw {
            let (lo, hi) = (t0 + b as f64 * w, t0 + (b + 1) as f64 * w);
            let m: Vec<bool> = p.t.iter().map(|&x| x >= lo && (x < hi || (b == nw - 1 && x <= hi))).collect();
            out.push(("time".into(), format!("{lo:.0}…{hi:.0} s"), m));
        }
    }
    let (tmin, tmax) = p.temp.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
    if tmax - tmin > 1.0 {
        let nb = 5;
        let w = (tmax - tmin) / nb as f64;
        for b in 0..nb {
            let (lo, hi) = (tmin + b as f64 * w, tmin + (b + 1) as f64 * w);
            let m: Vec<bool> = p.temp.iter().map(|&x| x >= lo && (x < hi || (b == nb - 1 && x <= hi))).collect();
            out.push(("temperature".into(), format!("{lo:.1}…{hi:.1} °C"), m));
        }
        let thr = 0.05 / 60.0;
        out.push(("thermal_state".into(), "heating".into(), p.dtemp.iter().map(|&d| d > thr).collect()));
        out.push(("thermal_state".into(), "cooling".into(), p.dtemp.iter().map(|&d| d < -thr).collect()));
        out.push(("thermal_state".into(), "steady".into(), p.dtemp.iter().map(|&d| d.abs() <= thr).collect()));
        let edges = [0.05, 0.3, 1.0, 3.0, f64::INFINITY];
        for w in edges.windows(2) {
            let m: Vec<bool> = p.dtemp.iter().map(|&d| (d.abs() * 60.0) > w[0] && (d.abs() * 60.0) <= w[1]).collect();
            out.push(("ramp_rate".into(), format!("{}…{} °C/min", w[0], w[1]), m));
        }
    }
    if p.vib_names.len() > 1 {
        for (k, name) in p.vib_names.iter().enumerate() {
            out.push(("vibration".into(), name.clone(), p.vib_class.iter().map(|&c| c == k).collect()));
        }
    }
    if let Some(pw) = &p.power {
        let edges = [0.0, 60.0, 300.0, 1800.0, f64::INFINITY];
        for w in edges.windows(2) {
            out.push((
                "power_s".into(),
                format!("{}…{} s", w[0], w[1]),
                pw.iter().map(|&x| x >= w[0] && x < w[1]).collect(),
            ));
        }
    }
    out.retain(|(_, _, m)| {
        let c = m.iter().filter(|x| **x).count();
        c > 0 && c < n
    });
    out
}

/// The strata of every accelerometer whose mean residual is significant (|z| ≥ [`Z_LOCATED`]),
/// most significant first: of the raw residual, or (`after_model`) of what the model leaves.
pub fn locate(p: &Prepared, fits: &[AxisFit], after_model: bool) -> Vec<Stratum> {
    let n = p.t.len();
    let st = strata(p);
    let mut found = Vec::new();
    for fit in fits {
        let axis = fit.axis;
        let raw: Vec<f64> = if after_model {
            p.r[axis].iter().zip(&fit.prediction).map(|(v, m)| v - m).collect()
        } else {
            p.r[axis].clone()
        };
        // With blocks each row of `raw` stands for `w` of the recording's rows.
        let w = |i: usize| if p.weight.is_empty() { 1.0 } else { p.weight[i] };
        let mean_all = if p.weight.is_empty() {
            raw.iter().sum::<f64>() / n.max(1) as f64
        } else {
            raw.iter().enumerate().map(|(i, v)| v * w(i)).sum::<f64>() / p.weight.iter().sum::<f64>().max(1.0)
        };
        let y: Vec<f64> = raw.iter().map(|v| v - mean_all).collect();
        for (dim, val, mask) in &st {
            let (mut sum, mut var, mut rows, mut dur) = (0.0, 0.0, 0usize, 0.0);
            let (mut first, mut last) = (f64::NAN, f64::NAN);
            for i in 0..n {
                if mask[i] {
                    if first.is_nan() {
                        first = p.t[i];
                    }
                    last = p.t[i];
                    sum += y[i] * w(i);
                    var += p.r_white[axis][i] * w(i) * w(i);
                    rows += w(i) as usize;
                    dur += if i + 1 < n { (p.t[i + 1] - p.t[i]).min(3.0 * p.dt) } else { p.dt };
                }
            }
            let rf = rows as f64;
            let mean = sum / rf;
            let span = (last - first).max(0.0);
            let se = ((var * fit.inflation) / (rf * rf) + fit.q * span / 3.0).sqrt();
            let z = if se > 0.0 { mean / se } else { 0.0 };
            if z.abs() >= Z_LOCATED {
                found.push(Stratum {
                    axis: AXES[axis].into(),
                    dimension: dim.clone(),
                    value: val.clone(),
                    rows,
                    duration_s: dur,
                    mean_mg: mean * 1e3,
                    se_mg: se * 1e3,
                    z,
                    n_eff: rf / fit.inflation,
                });
            }
        }
    }
    found.sort_by(|a, b| b.z.abs().total_cmp(&a.z.abs()));
    found.truncate(60);
    found
}
