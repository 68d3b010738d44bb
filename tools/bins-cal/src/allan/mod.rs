//! The unit's noise at every time scale: the overlapping Allan deviation of a channel in one
//! streaming pass, its confidence intervals, the IEEE noise terms and the simulator's noise
//! model fitted to it (`bins-cal allan`; method, figures and units in `docs/noise.md`).
//!
//! | module | owns |
//! |---|---|
//! | [`estimate`] | the streaming overlapping Allan/Hadamard variance, pooled over segments (also the diagnosis's) |
//! | [`noise_id`] | the noise type at each τ from the lag-1 autocorrelation |
//! | [`edf`] | Greenhall–Riley equivalent degrees of freedom, χ² quantiles and intervals |
//! | [`terms`] | the IEEE Std 952/1293 terms fitted to the curve |
//! | [`twin`] | white + random walk + Gauss–Markov terms fitted for the simulator; the ADC step |
//! | [`pass`] | one pass over a recording: every channel's curve, the sampling and its gaps |
//! | [`output`] | the table, JSON, CSV, the `[noise]` scenario and the Kalibr `imu.yaml` |
//! | [`plot`] | the PNG: curve, interval band, term lines |

pub mod edf;
pub mod estimate;
pub mod noise_id;
pub mod output;
pub mod pass;
pub mod plot;
pub mod terms;
pub mod twin;

pub use estimate::{Config, Estimator, Grid, Kind, Raw, pooled};

use std::collections::BTreeMap;

/// Where a point's noise type comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AlphaFrom {
    /// The lag-1 autocorrelation of this τ's cluster means.
    Lag1,
    /// Too few cluster means here: the identification of the largest shorter τ that had one.
    Carried,
    /// No τ had enough cluster means: white noise assumed.
    Assumed,
}

impl AlphaFrom {
    /// As written in the outputs.
    pub fn as_str(self) -> &'static str {
        match self {
            AlphaFrom::Lag1 => "lag1",
            AlphaFrom::Carried => "carried",
            AlphaFrom::Assumed => "assumed",
        }
    }
}

/// One τ of a curve, in the channel's unit.
#[derive(Clone, Debug, PartialEq)]
pub struct Point {
    /// Cluster size \[samples\].
    pub m: usize,
    /// Averaging time \[s\].
    pub tau_s: f64,
    /// The deviation (square root of the variance).
    pub dev: f64,
    /// Terms summed.
    pub n: u64,
    /// Samples between cluster starts: 1 = fully overlapping (exact), more = partially.
    pub stride: usize,
    /// The noise type `α` used for the degrees of freedom.
    pub alpha: i32,
    /// Where `α` comes from.
    pub alpha_from: AlphaFrom,
    /// Equivalent degrees of freedom (`None`: the variance does not converge for `α`).
    pub edf: Option<f64>,
    /// The interval's lower and upper deviation (equal to `dev` without degrees of freedom).
    pub interval: (f64, f64),
}

impl Point {
    /// The same point in another unit (deviation and interval times `factor` > 0).
    pub fn scaled(&self, factor: f64) -> Point {
        Point { dev: self.dev * factor, interval: (self.interval.0 * factor, self.interval.1 * factor), ..self.clone() }
    }
}

/// Terms a segment of `len` samples gives at cluster size `m`, stride `s`, difference order
/// `order` (0 with fewer than two: such a segment is not pooled).
fn segment_terms(len: u64, m: u64, s: u64, order: u64) -> u64 {
    let span = order * m;
    if len < span {
        return 0;
    }
    let n = len / s - span / s + 1;
    if n >= 2 { n } else { 0 }
}

/// The curve's points from an estimator's result: the noise type of each τ (carried up from
/// the largest shorter τ with [`noise_id::MIN_CLUSTERS`] means where a τ has fewer), the
/// degrees of freedom pooled over the segments (`ν = (Σnᵢ)²/Σ(nᵢ²/νᵢ)`, each segment's by
/// [`edf::greenhall`], on the decimated phase for a partially overlapping τ) and the interval
/// at confidence `level`.
pub fn points(raw: &[Raw], segments: &BTreeMap<u64, u64>, kind: Kind, tau0_s: f64, level: f64) -> Vec<Point> {
    let order = kind.order();
    let mut last: Option<i32> = None;
    raw.iter()
        .map(|r| {
            let (alpha, from) = match r.id.identify(order) {
                Some(id) => {
                    let a = id.alpha.clamp(2 - 2 * order as i32, 2);
                    last = Some(a);
                    (a, AlphaFrom::Lag1)
                }
                None => match last {
                    Some(a) => (a, AlphaFrom::Carried),
                    None => (0, AlphaFrom::Assumed),
                },
            };
            let (m, s) = (r.m as u64, r.stride as u64);
            let (mut total, mut inv) = (0.0, 0.0);
            let mut ok = true;
            for (&len, &count) in segments {
                let n_i = segment_terms(len, m, s, order as u64);
                if n_i == 0 {
                    continue;
                }
                let nu_i = if s == 1 {
                    edf::greenhall(alpha, order, m as f64, (len + 1) as f64, true)
                } else {
                    edf::greenhall(alpha, order, (m / s) as f64, (len / s + 1) as f64, true)
                };
                match nu_i {
                    Some(nu) => {
                        total += (count * n_i) as f64;
                        inv += count as f64 * (n_i * n_i) as f64 / nu;
                    }
                    None => ok = false,
                }
            }
            let edf = (ok && inv > 0.0).then(|| total * total / inv);
            let dev = r.var.max(0.0).sqrt();
            let interval = edf.map_or((dev, dev), |nu| edf::interval(dev, nu, level));
            Point {
                m: r.m,
                tau_s: r.m as f64 * tau0_s,
                dev,
                n: r.n,
                stride: r.stride,
                alpha,
                alpha_from: from,
                edf,
                interval,
            }
        })
        .collect()
}
