//! The power-law noise type at each τ from the lag-1 autocorrelation (Riley & Greenhall 2004,
//! "Power law noise identification using the lag 1 autocorrelation"), streamed.
//!
//! The non-overlapping cluster means `z_k` of `m` samples are the frequency data of that τ.
//! For `d = 0, 1, …` differences of them, `r₁` is the lag-1 autocorrelation and
//! `δ = r₁/(1 + r₁)`; the first `d` with `δ < 0.25`, or `d = d_max` (2 for the Allan
//! variance, 3 for the Hadamard variance), gives the exponent `α = −round(2δ) − 2d` of the
//! frequency spectrum `S_y(f) ∝ f^α`: 0 white (velocity random walk for an accelerometer),
//! −1 flicker (bias instability), −2 random walk (acceleration random walk), +1 and +2 the
//! flicker and white phase noises (quantisation).
//!
//! Each differenced series is summarised by running sums (count, sum, sum of squares, lag-1
//! products and the sums of the pairs' first and second members, all shifted by the series'
//! first value), so no series is stored. Riley removes a linear trend from `z` before `d = 0`;
//! the sums here do not: a trend raises `r₁` at `d = 0`, which then differences once, and the
//! first difference has lost the trend. The rule needs at least [`MIN_CLUSTERS`] means.

/// Fewest cluster means for an identification (Riley's rule of thumb, as allantools).
pub const MIN_CLUSTERS: u64 = 30;

/// Running sums of one series for its lag-1 autocorrelation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Series {
    shift: Option<f64>,
    n: u64,
    s1: f64,
    s2: f64,
    pairs: u64,
    sxy: f64,
    sx: f64,
    sy: f64,
    prev: Option<f64>,
}

impl Series {
    fn push(&mut self, v: f64) {
        let shift = *self.shift.get_or_insert(v);
        let x = v - shift;
        self.n += 1;
        self.s1 += x;
        self.s2 += x * x;
        if let Some(p) = self.prev {
            self.pairs += 1;
            self.sxy += p * x;
            self.sx += p;
            self.sy += x;
        }
        self.prev = Some(x);
    }

    /// [`Series::push`] of every value of `vs`, in one loop.
    fn push_slice(&mut self, vs: &[f64]) {
        let Some(&first) = vs.first() else { return };
        let shift = *self.shift.get_or_insert(first);
        let (mut s1, mut s2, mut sxy, mut sx, mut sy) = (0.0, 0.0, 0.0, 0.0, 0.0);
        let mut prev = self.prev;
        let mut pairs = 0u64;
        if let Some(p) = prev {
            let x = first - shift;
            sxy += p * x;
            sx += p;
            sy += x;
            pairs += 1;
        }
        let xs = vs.iter().map(|v| v - shift);
        let mut last = first - shift;
        for (k, x) in xs.enumerate() {
            s1 += x;
            s2 += x * x;
            if k > 0 {
                sxy += last * x;
                sx += last;
                sy += x;
            }
            last = x;
        }
        pairs += vs.len() as u64 - 1;
        prev = Some(last);
        self.n += vs.len() as u64;
        self.s1 += s1;
        self.s2 += s2;
        self.sxy += sxy;
        self.sx += sx;
        self.sy += sy;
        self.pairs += pairs;
        self.prev = prev;
    }

    /// `r₁ = Σ(x_k − x̄)(x_{k+1} − x̄) / Σ(x_k − x̄)²`, pairs within segments.
    fn r1(&self) -> Option<f64> {
        if self.n < 3 || self.pairs < 2 {
            return None;
        }
        let n = self.n as f64;
        let mean = self.s1 / n;
        let den = self.s2 - n * mean * mean;
        let num = self.sxy - mean * (self.sx + self.sy) + self.pairs as f64 * mean * mean;
        (den > 0.0).then(|| num / den)
    }
}

/// The lag-1 sums of the cluster means and of their first and second differences.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Lag1 {
    series: [Series; 4],
    prev: [Option<f64>; 3],
}

/// A noise identification.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoiseId {
    /// `α` of `S_y(f) ∝ f^α`, an integer.
    pub alpha: i32,
    /// The lag-1 autocorrelation's `δ` at the chosen difference.
    pub delta: f64,
    /// Differences taken.
    pub d: usize,
}

impl Lag1 {
    /// One cluster mean (in time order within a segment).
    pub fn push(&mut self, z: f64) {
        let mut v = z;
        for d in 0..4 {
            self.series[d].push(v);
            if d == 3 {
                break;
            }
            match self.prev[d] {
                Some(p) => {
                    self.prev[d] = Some(v);
                    v -= p;
                }
                None => {
                    self.prev[d] = Some(v);
                    return;
                }
            }
        }
    }

    /// Cluster means in time order within a segment, as [`Lag1::push`] of each; `scratch`
    /// holds the differences between calls (no allocation once it has grown).
    pub fn push_slice(&mut self, zs: &[f64], scratch: &mut [Vec<f64>; 2]) {
        if zs.is_empty() {
            return;
        }
        let [a, b] = scratch;
        a.clear();
        a.extend_from_slice(zs);
        let (mut cur, mut next) = (a, b);
        for d in 0..4 {
            self.series[d].push_slice(cur);
            if d == 3 {
                break;
            }
            next.clear();
            if let Some(p) = self.prev[d] {
                next.push(cur[0] - p);
            }
            next.extend(cur.windows(2).map(|w| w[1] - w[0]));
            self.prev[d] = cur.last().copied();
            if next.is_empty() {
                return;
            }
            std::mem::swap(&mut cur, &mut next);
        }
    }

    /// A gap: no pair or difference across it.
    pub fn end_segment(&mut self) {
        self.prev = [None; 3];
        for s in &mut self.series {
            s.prev = None;
        }
    }

    /// Cluster means seen.
    pub fn clusters(&self) -> u64 {
        self.series[0].n
    }

    /// The noise type by Riley's rule with at most `d_max` differences (2 for the Allan
    /// variance), `None` with fewer than [`MIN_CLUSTERS`] means or a constant series.
    pub fn identify(&self, d_max: usize) -> Option<NoiseId> {
        if self.clusters() < MIN_CLUSTERS {
            return None;
        }
        for d in 0..=d_max.min(3) {
            let r1 = self.series[d].r1()?;
            let delta = r1 / (1.0 + r1);
            if delta < 0.25 || d == d_max {
                return Some(NoiseId { alpha: -(2.0 * delta).round() as i32 - 2 * d as i32, delta, d });
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    #[test]
    fn white_flicker_free_random_walk_and_differenced_noise_are_told_apart() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let nrm = Normal::new(0.0, 1.0).unwrap();
        let white: Vec<f64> = (0..4000).map(|_| nrm.sample(&mut rng)).collect();
        let mut walk = Vec::new();
        let mut acc = 0.0;
        for w in &white {
            acc += w;
            walk.push(acc);
        }
        let diffs: Vec<f64> = white.windows(2).map(|w| w[1] - w[0]).collect();
        for (name, series, alpha) in [("white", &white, 0), ("random walk", &walk, -2), ("differenced", &diffs, 2)] {
            let mut l = Lag1::default();
            for &z in series.iter() {
                l.push(z);
            }
            assert_eq!(l.identify(2).map(|i| i.alpha), Some(alpha), "{name}");
        }
        // In slices of any length, the same sums.
        let mut one = Lag1::default();
        let mut many = Lag1::default();
        let mut scratch = [Vec::new(), Vec::new()];
        white.iter().for_each(|&z| one.push(z));
        for chunk in white.chunks(7).chain(std::iter::empty()) {
            many.push_slice(chunk, &mut scratch);
        }
        let (a, b) = (one.identify(2).unwrap(), many.identify(2).unwrap());
        assert_eq!(a.alpha, b.alpha);
        assert!((a.delta - b.delta).abs() < 1e-12, "{a:?} {b:?}");
        let mut short = Lag1::default();
        white[..29].iter().for_each(|&z| short.push(z));
        assert_eq!(short.identify(2), None);
    }
}
