//! Where the mismatch is: the residual (minus its median) averaged over strata of the test
//! (rig position, temperature range, heating/cooling/steady, ramp rate, vibration condition,
//! time since power-on), with a standard error that accounts for autocorrelation: the stratum
//! is cut into blocks of consecutive rows, and the spread of the block means is divided by the
//! effective number of blocks `n·(1 − ρ)/(1 + ρ)` (ρ = lag-1 correlation of the block means).

use super::prep::{AXES, Prepared};
use super::stats::median;
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
    /// Time spent in it [s].
    pub duration_s: f64,
    /// Mean residual (relative to the whole record's median) [mg].
    pub mean_mg: f64,
    /// Standard error of the mean [mg].
    pub se_mg: f64,
    /// `mean / se`.
    pub z: f64,
    /// Effective number of independent blocks.
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
/// most significant first.
pub fn locate(p: &Prepared, noise_floor_g: &[f64; 3]) -> Vec<Stratum> {
    let n = p.t.len();
    let block = (n / 200).max(10);
    let st = strata(p);
    let mut found = Vec::new();
    for axis in 0..3 {
        let med = median(&p.r[axis]);
        let y: Vec<f64> = p.r[axis].iter().map(|v| v - med).collect();
        for (dim, val, mask) in &st {
            // Blocks: runs of consecutive rows in the stratum, cut every `block` rows.
            let mut means = Vec::new();
            let mut counts = Vec::new();
            let mut i = 0;
            let mut dur = 0.0;
            while i < n {
                if !mask[i] {
                    i += 1;
                    continue;
                }
                let s = i;
                while i < n && mask[i] && i - s < block {
                    i += 1;
                }
                means.push(y[s..i].iter().sum::<f64>() / (i - s) as f64);
                counts.push((i - s) as f64);
                dur += p.t[i - 1] - p.t[s] + p.dt;
            }
            let rows: f64 = counts.iter().sum();
            let mean = means.iter().zip(&counts).map(|(m, c)| m * c).sum::<f64>() / rows;
            let nb = means.len();
            let white_se = noise_floor_g[axis] / rows.sqrt();
            let (se, n_eff) = if nb >= 5 {
                let var = means.iter().map(|m| (m - mean).powi(2)).sum::<f64>() / (nb - 1) as f64;
                let c0: f64 = means.iter().map(|m| (m - mean).powi(2)).sum();
                let c1: f64 = means.windows(2).map(|w| (w[0] - mean) * (w[1] - mean)).sum();
                let rho = if c0 > 0.0 { (c1 / c0).clamp(0.0, 0.95) } else { 0.0 };
                let ne = nb as f64 * (1.0 - rho) / (1.0 + rho);
                ((var / ne).sqrt().max(white_se), ne)
            } else {
                (white_se * (block as f64).sqrt(), nb as f64)
            };
            let z = if se > 0.0 { mean / se } else { 0.0 };
            if z.abs() >= Z_LOCATED {
                found.push(Stratum {
                    axis: AXES[axis].into(),
                    dimension: dim.clone(),
                    value: val.clone(),
                    rows: rows as usize,
                    duration_s: dur,
                    mean_mg: mean * 1e3,
                    se_mg: se * 1e3,
                    z,
                    n_eff,
                });
            }
        }
    }
    found.sort_by(|a, b| b.z.abs().total_cmp(&a.z.abs()));
    found
}
