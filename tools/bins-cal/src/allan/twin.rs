//! The simulator's noise model fitted to an Allan curve: white noise per sample, a bias
//! random walk and up to two first-order Gauss–Markov biases, each with its exact Allan
//! variance for samples at `τ₀` (`docs/noise.md`, "A twin whose noise matches"):
//!
//! - white, RMS `σ_w` per sample: `σ_w²/m`;
//! - random walk `q` [u/√s] (a step of `q√τ₀` per sample): `q²τ₀(2m² + 1)/(6m)`;
//! - Gauss–Markov, stationary RMS `σ_b`, correlation time `T` (`φ = e^(−τ₀/T)` per sample):
//!   `(V_m − C_m)/m²` with `V_m = σ_b²[m(1 + φ)/(1 − φ) − 2φ(1 − φᵐ)/(1 − φ)²]` the variance of
//!   a cluster's sum and `C_m = σ_b²φ(1 − φᵐ)²/(1 − φ)²` the covariance of two consecutive ones.
//!
//! The variances enter linearly, the correlation times do not: every time, and every pair of
//! times, on a grid of twelve a decade from `τ₀/2` to four times the longest τ is tried with
//! the amplitudes fitted by non-negative weighted least squares ([`super::terms::nnls_subsets`],
//! weights `ν/(2σ̂⁴)`); the best times are refined between their grid neighbours (golden
//! section in `log T`) and the amplitudes by reweighting from the model. Where that fit
//! leaves more than a tenth of the curve's points more than 20 % away and outside their 95 %
//! intervals, the weights' degrees of freedom are capped in steps ([`WEIGHT_EDF_CAPS`]) until
//! a fit follows nine tenths ([`follows`]). The ADC step is
//! read from the data ([`Resolution`]): its rounding is white noise of variance `Δ²/12`,
//! taken out of the white term, and the simulator rounds to the same step.

use super::terms::nnls_subsets;

/// The fitted noise of one channel, in the channel's unit `u`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TwinNoise {
    /// White noise per sample, RMS \[u\] (the ADC's rounding not included).
    pub white: f64,
    /// Random walk [u/√s].
    pub random_walk: f64,
    /// Gauss–Markov terms: stationary RMS \[u\] and correlation time \[s\]; 0 = none.
    pub gm: [(f64, f64); 2],
    /// The ADC step \[u\] (0: none found).
    pub adc_step: f64,
}

/// `1 − e^(−x)` without cancellation.
fn one_minus_exp_neg(x: f64) -> f64 {
    -(-x).exp_m1()
}

/// Allan variance of a first-order Gauss–Markov sequence of unit variance and correlation
/// time `corr_s`, sampled every `tau0_s`, at cluster size `m`.
pub fn gm_avar(m: f64, tau0_s: f64, corr_s: f64) -> f64 {
    let a = tau0_s / corr_s;
    let om = one_minus_exp_neg(a); // 1 − φ
    let phi = 1.0 - om;
    let om_m = one_minus_exp_neg(a * m); // 1 − φ^m
    let v = m * (1.0 + phi) / om - 2.0 * phi * om_m / (om * om);
    let c = phi * om_m * om_m / (om * om);
    ((v - c) / (m * m)).max(0.0)
}

/// Allan variance of a random walk of unit intensity (1 u/√s) sampled every `tau0_s`, at
/// cluster size `m`.
pub fn rw_avar(m: f64, tau0_s: f64) -> f64 {
    tau0_s * (2.0 * m * m + 1.0) / (6.0 * m)
}

impl TwinNoise {
    /// The model's Allan variance at cluster size `m` (samples of `tau0_s`), the ADC's
    /// rounding included.
    pub fn avar(&self, m: f64, tau0_s: f64) -> f64 {
        let mut v = (self.white * self.white + self.adc_step * self.adc_step / 12.0) / m;
        v += self.random_walk * self.random_walk * rw_avar(m, tau0_s);
        for &(s, t) in &self.gm {
            if s > 0.0 && t > 0.0 {
                v += s * s * gm_avar(m, tau0_s, t);
            }
        }
        v
    }
}

/// Correlation times tried a decade.
const GRID_PER_DECADE: f64 = 12.0;

/// The share of the curve's points a fit must follow ([`follows`]) to be kept.
pub const FOLLOWS: f64 = 0.9;

/// The caps on the degrees of freedom a point weighs with, tried in turn: the fit with the
/// points' own degrees of freedom first (the efficient one), then with every point known to at
/// best `√(2/cap)` in variance, so the few points at the shortest τ, known to 1 %, do not pull
/// the fit away from the rest of the curve where the model's form, not the estimate, limits
/// the agreement. The first that follows [`FOLLOWS`] of the points is kept, else the one that
/// follows the most.
pub const WEIGHT_EDF_CAPS: [f64; 4] = [f64::INFINITY, 1000.0, 300.0, 100.0];

/// One point to fit: cluster size \[samples\], Allan variance \[u²\], degrees of freedom.
pub type FitPoint = (f64, f64, f64);

/// The columns at the correlation times `ts`: white, random walk, one per Gauss–Markov term.
fn columns(points: &[FitPoint], tau0_s: f64, ts: &[f64]) -> Vec<Vec<f64>> {
    points
        .iter()
        .map(|&(m, _, _)| {
            let mut row = vec![1.0 / m, rw_avar(m, tau0_s)];
            row.extend(ts.iter().map(|&t| gm_avar(m, tau0_s, t)));
            row
        })
        .collect()
}

fn weighted_sse(x: &[Vec<f64>], y: &[f64], w: &[f64], c: &[f64]) -> f64 {
    x.iter()
        .zip(y)
        .zip(w)
        .map(|((row, y), w)| w * (y - row.iter().zip(c).map(|(a, b)| a * b).sum::<f64>()).powi(2))
        .sum()
}

/// Fits white + random walk + up to `max_gm` Gauss–Markov terms (0, 1 or 2) to `points`
/// (`(m, σ², ν)`), with the ADC step `adc_step` (0: none) whose rounding variance
/// `Δ²/12` per sample is taken out of the white term.
pub fn fit(points: &[FitPoint], tau0_s: f64, adc_step: f64, max_gm: usize) -> TwinNoise {
    let pts: Vec<FitPoint> = points.iter().copied().filter(|p| p.0 >= 1.0 && p.1 > 0.0).collect();
    if pts.is_empty() {
        return TwinNoise { adc_step, ..TwinNoise::default() };
    }
    let mut best: Option<(usize, TwinNoise)> = None;
    for cap in WEIGHT_EDF_CAPS {
        let t = fit_capped(&pts, tau0_s, adc_step, max_gm, cap);
        let score = follows(&t, &pts, tau0_s);
        if score as f64 >= FOLLOWS * pts.len() as f64 {
            return t;
        }
        if best.as_ref().is_none_or(|b| score > b.0) {
            best = Some((score, t));
        }
    }
    best.map_or_else(TwinNoise::default, |b| b.1)
}

/// The points at which the model's deviation is within 20 % of the measured one or inside
/// its 95 % interval.
pub fn follows(t: &TwinNoise, pts: &[FitPoint], tau0_s: f64) -> usize {
    pts.iter()
        .filter(|p| {
            let (dev, model) = (p.1.sqrt(), t.avar(p.0, tau0_s).sqrt());
            let (lo, hi) = if p.2.is_finite() && p.2 > 0.0 { super::edf::interval(dev, p.2, 0.95) } else { (dev, dev) };
            (model / dev - 1.0).abs() <= 0.2 || (lo <= model && model <= hi)
        })
        .count()
}

/// [`fit`] with every point's degrees of freedom capped at `cap`.
fn fit_capped(pts: &[FitPoint], tau0_s: f64, adc_step: f64, max_gm: usize, cap: f64) -> TwinNoise {
    let y: Vec<f64> = pts.iter().map(|p| p.1).collect();
    let nu = |p: &FitPoint| if p.2.is_finite() && p.2 > 0.0 { p.2.min(cap) } else { 1.0 };
    let w: Vec<f64> = pts.iter().map(|p| nu(p) / (2.0 * p.1 * p.1)).collect();
    let m_max = pts.iter().map(|p| p.0).fold(1.0, f64::max);
    // Correlation times: GRID_PER_DECADE a decade from τ₀/2 to 4× the largest τ.
    let (lo, hi) = ((0.5 * tau0_s).log10(), (4.0 * m_max * tau0_s).log10());
    let grid: Vec<f64> =
        (0..).map(|k| lo + k as f64 / GRID_PER_DECADE).take_while(|&e| e <= hi).map(|e| 10f64.powf(e)).collect();
    let mut candidates: Vec<Vec<f64>> = vec![Vec::new()];
    if max_gm >= 1 {
        candidates.extend(grid.iter().map(|&t| vec![t]));
    }
    if max_gm >= 2 {
        for (i, &a) in grid.iter().enumerate() {
            for &b in &grid[i + 1..] {
                candidates.push(vec![a, b]);
            }
        }
    }
    let mut best = (f64::INFINITY, Vec::new(), Vec::new());
    for ts in candidates {
        let x = columns(pts, tau0_s, &ts);
        let c = nnls_subsets(&x, &y, &w);
        let sse = weighted_sse(&x, &y, &w, &c);
        if sse < best.0 {
            best = (sse, ts, c);
        }
    }
    let (_, mut ts, mut c) = best;
    // Each correlation time refined between its grid neighbours (golden section in log T),
    // the others held.
    let sse_at = |ts: &[f64]| {
        let x = columns(pts, tau0_s, ts);
        let c = nnls_subsets(&x, &y, &w);
        (weighted_sse(&x, &y, &w, &c), c)
    };
    for _round in 0..2 {
        for i in 0..ts.len() {
            let g = 0.5 * (5f64.sqrt() - 1.0);
            let step = 1.0 / GRID_PER_DECADE;
            let (mut a, mut b) = (ts[i].log10() - step, ts[i].log10() + step);
            let mut trial = ts.clone();
            let mut f = |e: f64| {
                trial[i] = 10f64.powf(e);
                sse_at(&trial).0
            };
            let (mut x1, mut x2) = (b - g * (b - a), a + g * (b - a));
            let (mut f1, mut f2) = (f(x1), f(x2));
            for _ in 0..24 {
                if f1 < f2 {
                    b = x2;
                    (x2, f2) = (x1, f1);
                    x1 = b - g * (b - a);
                    f1 = f(x1);
                } else {
                    a = x1;
                    (x1, f1) = (x2, f2);
                    x2 = a + g * (b - a);
                    f2 = f(x2);
                }
            }
            let e = 0.5 * (a + b);
            let mut cand = ts.clone();
            cand[i] = 10f64.powf(e);
            let (sse_new, c_new) = sse_at(&cand);
            if sse_new < sse_at(&ts).0 {
                ts = cand;
                c = c_new;
            }
        }
    }
    // Reweight from the model.
    let x = columns(pts, tau0_s, &ts);
    for _ in 0..3 {
        let w2: Vec<f64> = pts
            .iter()
            .zip(&x)
            .map(|(p, row)| {
                let model: f64 = row.iter().zip(&c).map(|(a, b)| a * b).sum();
                nu(p) / (2.0 * model.max(1e-3 * p.1).powi(2))
            })
            .collect();
        c = nnls_subsets(&x, &y, &w2);
    }
    let mut gm = [(0.0, 0.0); 2];
    let mut k = 0;
    for (i, &t) in ts.iter().enumerate() {
        if c[2 + i] > 0.0 {
            gm[k] = (c[2 + i].sqrt(), t);
            k += 1;
        }
    }
    let white2 = (c[0] - adc_step * adc_step / 12.0).max(0.0);
    TwinNoise { white: white2.sqrt(), random_walk: c[1].max(0.0).sqrt(), gm, adc_step }
}

/// The resolution of a channel's values: the smallest non-zero difference between
/// consecutive samples, confirmed as a step when the first [`Resolution::KEPT`] values are all
/// whole multiples of it (within 1e-6 of a step).
#[derive(Clone, Debug, Default)]
pub struct Resolution {
    first: Vec<f64>,
    last: Option<f64>,
    min_diff: f64,
}

impl Resolution {
    /// Values kept to confirm the step.
    pub const KEPT: usize = 4096;

    /// One value.
    pub fn push(&mut self, v: f64) {
        if self.first.len() < Self::KEPT {
            self.first.push(v);
        }
        if let Some(p) = self.last {
            let d = (v - p).abs();
            if d > 0.0 && (self.min_diff == 0.0 || d < self.min_diff) {
                self.min_diff = d;
            }
        }
        self.last = Some(v);
    }

    /// A gap: no difference across it.
    pub fn end_segment(&mut self) {
        self.last = None;
    }

    /// The step, or 0 when the values are not on one: the smallest difference, taken as the
    /// nearest `1/n` or short decimal within 1e-6 of it, when every kept value lies on a whole
    /// number of steps from the first (within 1e-3 of a step).
    pub fn step(&self) -> f64 {
        let d = snap(self.min_diff);
        if !(d > 0.0) || self.first.len() < 16 {
            return 0.0;
        }
        let v0 = self.first[0];
        let on_grid = self.first.iter().all(|v| {
            let k = (v - v0) / d;
            (k - k.round()).abs() < 1e-3
        });
        if on_grid { d } else { 0.0 }
    }
}

/// `d` as `1/n` or as a decimal of at most six significant digits when one is within 1e-6 of
/// it (the difference of two printed values is not exactly the step), else `d`.
fn snap(d: f64) -> f64 {
    if !(d > 0.0) {
        return 0.0;
    }
    let n = (1.0 / d).round();
    if n >= 1.0 && (n * d - 1.0).abs() < 1e-6 {
        return 1.0 / n;
    }
    for digits in 1..=6 {
        let e = 10f64.powi(digits - 1 - d.log10().floor() as i32);
        let r = (d * e).round() / e;
        if ((r - d) / d).abs() < 1e-6 {
            return r;
        }
    }
    d
}
