//! The overlapping Allan and Hadamard variances of one channel in one pass, memory bounded by
//! the τ grid (`docs/noise.md`, "Estimator").
//!
//! The samples `y_k` (equally spaced, τ₀) are integrated into the phase
//! `X_p = Σ_{k<p} (y_k − y_ref)` (`y_ref` the segment's first sample), summed as an
//! unevaluated sum of two `f64` (Knuth's two-sum) and stored correctly rounded: each stored
//! phase errs by at most half a unit in its last place, however long the record, and the
//! rounding errors of the differences below are independent from term to term, so they cancel
//! in the sum of their squares. A cluster of `m` samples has the mean `(X_p − X_{p−m})/m`, and
//!
//! - Allan: `σ²(m) = Σ_p (X_p − 2X_{p−m} + X_{p−2m})² / (2 m² n)`,
//! - Hadamard: `H(m) = Σ_p (X_p − 3X_{p−m} + 3X_{p−2m} − X_{p−3m})² / (6 m² n)`,
//!
//! over every phase index `p` at which the differences exist (`n` terms): the overlapping
//! estimators (NIST SP 1065, eqs. 11 and 18; IEEE Std 952 annex C). The phase of the last
//! `order·M` samples (`M` = [`Config::exact_max_m`]) is kept in a sliding buffer, so every
//! `m ≤ M` is the fully overlapping estimate. Beyond `M` a cluster starts every
//! `s = m/`[`PARTIAL_POSITIONS`] samples: the same estimator on the phase taken every `s`
//! samples, which is the overlapping estimate of that decimated phase (partially overlapping;
//! its degrees of freedom are computed as such). Samples are taken in blocks of [`BLOCK`], and
//! each size's sum runs over the block as contiguous slices of the buffer.
//!
//! Records with gaps are several segments ([`Estimator::end_segment`]): each segment's terms
//! are pooled into the sums when it gives at least two terms at that τ, and the lengths of the
//! segments are kept (one count per distinct length) for the degrees of freedom.

use super::noise_id::Lag1;
use std::collections::BTreeMap;

/// Which variance.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// Overlapping Allan variance (second difference of the phase).
    Allan,
    /// Overlapping Hadamard variance (third difference of the phase), blind to a linear drift.
    Hadamard,
}

impl Kind {
    /// The order of the phase difference: 2 (Allan), 3 (Hadamard).
    pub fn order(self) -> usize {
        match self {
            Kind::Allan => 2,
            Kind::Hadamard => 3,
        }
    }

    fn norm(self) -> f64 {
        match self {
            Kind::Allan => 2.0,
            Kind::Hadamard => 6.0,
        }
    }
}

/// The cluster sizes `m` (samples) the variance is computed at.
#[derive(Clone, Debug, PartialEq)]
pub enum Grid {
    /// `m = 1, 2, 4, 8, …` (octaves).
    Octave,
    /// `n` points a decade: `m = round(10^(i/n))`, duplicates dropped.
    PerDecade(u32),
    /// The given sizes (each ≥ 1).
    List(Vec<usize>),
}

/// Samples a block: the phase of a block is made first, then every τ's sums over it.
pub const BLOCK: usize = 4096;

/// The largest cluster size \[samples\] of the fully overlapping estimate by default:
/// 4 096 samples, 41 s at 100 Hz, 68 min at 1 Hz. Its phase buffer (`order·M` entries of 8
/// bytes and two blocks for sliding: 128 KB for the Allan variance) stays in the processor's
/// second-level cache, which is what makes the pass fast; beyond it the estimate is partially
/// overlapping with [`PARTIAL_POSITIONS`] cluster starts a cluster length, which changes its
/// degrees of freedom by less than 1 part in 1000.
pub const EXACT_MAX_M: usize = 1 << 12;

/// Cluster means of a block the noise identification takes at most: at τ with more, the
/// first `ID_RUN` of each block of [`BLOCK`] samples, a run of adjacent means (1/64 of the
/// `m = 1` means, spread evenly through the record; every mean from `m = 64` on).
pub const ID_RUN: usize = 64;

/// Phase entries a tile of the fully overlapping sums covers (2 KB: a tile and the lagged
/// tiles of the octave sizes fit the first-level cache).
const TILE: usize = 256;

/// Cluster start positions a cluster length beyond the exact range (`s = m/P`).
pub const PARTIAL_POSITIONS: usize = 4096;

/// The largest cluster size of the octave and per-decade grids (2⁴⁰ samples: 350 years at
/// 100 Hz); sizes without two terms are not reported.
const MAX_M: usize = 1 << 40;

/// How to estimate.
#[derive(Clone, Debug, PartialEq)]
pub struct Config {
    /// Allan or Hadamard.
    pub kind: Kind,
    /// The cluster sizes.
    pub grid: Grid,
    /// Cluster sizes up to this are fully overlapping ([`EXACT_MAX_M`] by default).
    pub exact_max_m: usize,
}

impl Config {
    /// The Allan variance at octaves, fully overlapping up to [`EXACT_MAX_M`].
    pub fn allan_octaves() -> Self {
        Config { kind: Kind::Allan, grid: Grid::Octave, exact_max_m: EXACT_MAX_M }
    }

    /// The cluster sizes of the grid up to [`MAX_M`], ascending, each beyond the exact range
    /// rounded to a multiple of its stride; with the stride.
    fn sizes(&self) -> Vec<(usize, usize)> {
        let raw: Vec<usize> = match &self.grid {
            Grid::Octave => (0..=40).map(|k| 1usize << k).collect(),
            Grid::PerDecade(n) => {
                let n = (*n).max(1) as f64;
                let mut v = Vec::new();
                let mut i = 0.0;
                loop {
                    let m = 10f64.powf(i / n).round();
                    if m > MAX_M as f64 {
                        break;
                    }
                    v.push(m as usize);
                    i += 1.0;
                }
                v
            }
            Grid::List(v) => v.iter().copied().filter(|&m| m >= 1).collect(),
        };
        let mut out: Vec<(usize, usize)> = raw
            .into_iter()
            .map(|m| {
                if m <= self.exact_max_m {
                    (m, 1)
                } else {
                    let s = (m / PARTIAL_POSITIONS).max(1);
                    ((m / s) * s, s)
                }
            })
            .collect();
        out.sort_unstable();
        out.dedup_by_key(|x| x.0);
        out
    }
}

/// The phase as two `f64`: `hi + lo`.
#[inline]
fn two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    let bb = s - a;
    (s, (a - (s - bb)) + (b - bb))
}

/// A sliding buffer of phase values: the last `keep` entries before a block, the block after
/// them. `base` is the phase index of the first entry.
#[derive(Clone, Debug, Default)]
struct Hist {
    x: Vec<f64>,
    base: u64,
    keep: usize,
    cap: usize,
}

impl Hist {
    fn new(keep: usize, block: usize) -> Self {
        Hist { x: Vec::new(), base: 0, keep, cap: keep + (keep / 2).max(2 * block) }
    }

    fn clear(&mut self) {
        self.x.clear();
        self.base = 0;
    }

    /// Room for `extra` more entries, dropping the oldest beyond `keep`.
    fn make_room(&mut self, extra: usize) {
        let len = self.x.len();
        if len + extra > self.cap && len > self.keep {
            let drop = len - self.keep;
            self.x.copy_within(drop.., 0);
            self.x.truncate(self.keep);
            self.base += drop as u64;
        }
    }

    /// Index of phase `p` in the buffer.
    #[inline]
    fn at(&self, p: u64) -> usize {
        (p - self.base) as usize
    }
}

/// The sum of the squared `order`-th differences of the phase at lag `lag` (entries) for the
/// entries `from..to` of `x` (each at least `order·lag` from its start): Allan
/// `X_p − 2X_{p−m} + X_{p−2m}`, Hadamard `X_p − 3X_{p−m} + 3X_{p−2m} − X_{p−3m}`, over
/// contiguous slices with four accumulators, so the loop vectorises.
fn sum_sq_diff(x: &[f64], from: usize, to: usize, lag: usize, order: usize) -> f64 {
    if to <= from {
        return 0.0;
    }
    let n = to - from;
    let s = |j: usize| &x[from - j * lag..from - j * lag + n];
    if order == 2 {
        let (x0, x1, x2) = (s(0), s(1), s(2));
        lanes(
            n,
            |k| (x0[k] - x1[k]) - (x1[k] - x2[k]),
            |k, acc: &mut [f64; LANES]| {
                let (a, b, c) = (&x0[k..k + LANES], &x1[k..k + LANES], &x2[k..k + LANES]);
                for j in 0..LANES {
                    let e = (a[j] - b[j]) - (b[j] - c[j]);
                    acc[j] += e * e;
                }
            },
        )
    } else {
        let (x0, x1, x2, x3) = (s(0), s(1), s(2), s(3));
        lanes(
            n,
            |k| (x0[k] - x3[k]) - 3.0 * (x1[k] - x2[k]),
            |k, acc: &mut [f64; LANES]| {
                let (a, b, c, d) = (&x0[k..k + LANES], &x1[k..k + LANES], &x2[k..k + LANES], &x3[k..k + LANES]);
                for j in 0..LANES {
                    let e = (a[j] - d[j]) - 3.0 * (b[j] - c[j]);
                    acc[j] += e * e;
                }
            },
        )
    }
}

/// Independent accumulators of [`sum_sq_diff`] (the loop vectorises into as many lanes).
const LANES: usize = 8;

/// `Σ_k e(k)²` for `k < n`: `chunk(k, acc)` adds `LANES` terms from `k` into `acc`, `e` the
/// tail's one by one.
#[inline(always)]
fn lanes(n: usize, e: impl Fn(usize) -> f64, chunk: impl Fn(usize, &mut [f64; LANES])) -> f64 {
    let mut acc = [0.0f64; LANES];
    let mut k = 0;
    while k + LANES <= n {
        chunk(k, &mut acc);
        k += LANES;
    }
    let mut tail = 0.0;
    while k < n {
        let v = e(k);
        tail += v * v;
        k += 1;
    }
    ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7])) + tail
}

/// The state of one cluster size.
#[derive(Clone, Debug)]
struct Tau {
    m: usize,
    /// Samples between cluster starts: 1 = fully overlapping.
    stride: usize,
    /// The phase every `stride` samples (partially overlapping sizes only).
    dec: Option<Hist>,
    sum: f64,
    n: u64,
    seg_sum: f64,
    seg_n: u64,
    id: Lag1,
}

/// One τ of the result: the variance, its terms and how it was estimated.
#[derive(Clone, Debug, PartialEq)]
pub struct Raw {
    /// Cluster size \[samples\].
    pub m: usize,
    /// Samples between cluster starts (1: fully overlapping).
    pub stride: usize,
    /// The variance (Allan or Hadamard) in the input's units squared.
    pub var: f64,
    /// Terms summed.
    pub n: u64,
    /// The lag-1 noise identification of the non-overlapping cluster means.
    pub id: Lag1,
}

/// The streaming estimator of one channel.
#[derive(Clone, Debug)]
pub struct Estimator {
    kind: Kind,
    taus: Vec<Tau>,
    hist: Hist,
    block: Vec<f64>,
    /// Phase index of the next phase value (samples in the segment so far).
    p: u64,
    x: (f64, f64),
    y_ref: Option<f64>,
    /// Segment lengths \[samples\] → how many segments had that length.
    segments: BTreeMap<u64, u64>,
    samples: u64,
    /// A block's cluster means of one size, and the noise identification's scratch.
    zbuf: Vec<f64>,
    zscratch: [Vec<f64>; 2],
}

impl Estimator {
    /// An estimator for `config`; nothing is allocated for the phase until samples come.
    pub fn new(config: &Config) -> Self {
        let order = config.kind.order();
        let sizes = config.sizes();
        let largest_exact = sizes.iter().filter(|s| s.1 == 1).map(|s| s.0).max().unwrap_or(1);
        let taus: Vec<Tau> = sizes
            .into_iter()
            .map(|(m, stride)| Tau {
                m,
                stride,
                dec: (stride > 1).then(|| Hist::new(order * (m / stride), BLOCK)),
                sum: 0.0,
                n: 0,
                seg_sum: 0.0,
                seg_n: 0,
                id: Lag1::default(),
            })
            .collect();
        Estimator {
            kind: config.kind,
            zbuf: Vec::new(),
            zscratch: [Vec::new(), Vec::new()],
            taus,
            hist: Hist::new(order * largest_exact, BLOCK),
            block: Vec::with_capacity(BLOCK),
            p: 0,
            x: (0.0, 0.0),
            y_ref: None,
            segments: BTreeMap::new(),
            samples: 0,
        }
    }

    /// Adds one sample (finite).
    #[inline]
    pub fn push(&mut self, y: f64) {
        self.block.push(y);
        if self.block.len() == BLOCK {
            self.process_block();
        }
    }

    /// Adds samples.
    pub fn extend(&mut self, mut ys: &[f64]) {
        while !ys.is_empty() {
            let k = (BLOCK - self.block.len()).min(ys.len());
            self.block.extend_from_slice(&ys[..k]);
            ys = &ys[k..];
            if self.block.len() == BLOCK {
                self.process_block();
            }
        }
    }

    /// Samples taken so far.
    pub fn samples(&self) -> u64 {
        self.samples + self.block.len() as u64
    }

    /// Segments ended so far (with samples).
    pub fn segments(&self) -> u64 {
        self.segments.values().sum()
    }

    fn process_block(&mut self) {
        if self.block.is_empty() {
            return;
        }
        let order = self.kind.order();
        if self.y_ref.is_none() {
            self.y_ref = Some(self.block[0]);
            self.hist.clear();
            self.hist.x.push(0.0);
            for t in &mut self.taus {
                if let Some(d) = &mut t.dec {
                    d.clear();
                    d.x.push(0.0);
                }
            }
        }
        let y_ref = self.y_ref.unwrap_or(0.0);
        let n_new = self.block.len();
        self.hist.make_room(n_new);
        // The phase in two parts (two-sum), stored correctly rounded.
        let (mut hi, mut lo) = self.x;
        let start = self.hist.x.len();
        self.hist.x.resize(start + n_new, 0.0);
        for (o, &y) in self.hist.x[start..].iter_mut().zip(&self.block) {
            let (s, e) = two_sum(hi, y - y_ref);
            hi = s;
            lo += e;
            *o = hi + lo;
        }
        self.x = (hi, lo);
        // New phase indices p0..=p1 (p0 is the first new one).
        let p0 = self.p + 1;
        let p1 = self.p + n_new as u64;
        self.p = p1;
        self.samples += n_new as u64;
        self.block.clear();
        let hist = &self.hist;
        // The fully overlapping sizes' terms over the new phases, tile by tile with every size
        // in a tile, so the tile's phases (and the lagged ones the sizes share) stay in the
        // first-level cache from one size to the next.
        let mut a = p0;
        while a <= p1 {
            let b = (a + TILE as u64 - 1).min(p1);
            for t in self.taus.iter_mut().filter(|t| t.stride == 1) {
                let first = a.max(order as u64 * t.m as u64);
                if first <= b {
                    t.seg_sum += sum_sq_diff(&hist.x, hist.at(first), hist.at(b) + 1, t.m, order);
                    t.seg_n += b + 1 - first;
                }
            }
            a = b + 1;
        }
        for t in &mut self.taus {
            let (m, s) = (t.m as u64, t.stride as u64);
            let inv = 1.0 / t.m as f64;
            self.zbuf.clear();
            if s == 1 {
                if m > p1 {
                    continue;
                }
                let q = p0.div_ceil(m).max(1) * m;
                if q <= p1 {
                    let x = &hist.x;
                    let means = (q..=p1).step_by(t.m).map(|q| (x[hist.at(q)] - x[hist.at(q - m)]) * inv);
                    self.zbuf.extend(means.take(ID_RUN));
                    if (p1 - q) / m + 1 > ID_RUN as u64 {
                        // A run of the block's first means; the next block's are not adjacent.
                        t.id.push_slice(&self.zbuf, &mut self.zscratch);
                        t.id.end_segment();
                        continue;
                    }
                }
            } else {
                // Partially overlapping: the new phases every `s` samples appended, then their
                // terms in one pass.
                let lag = t.m / t.stride;
                let Some(dec) = t.dec.as_mut() else { continue };
                let q0 = p0.div_ceil(s) * s;
                if q0 > p1 {
                    continue;
                }
                let count = ((p1 - q0) / s + 1) as usize;
                dec.make_room(count);
                let first_new = dec.x.len();
                dec.x.extend((q0..=p1).step_by(t.stride).map(|q| hist.x[hist.at(q)]));
                // Decimated index of the first new entry, and of the first with a term.
                let k0 = q0 / s;
                let k_first = k0.max(order as u64 * lag as u64);
                let k_end = p1 / s + 1;
                if k_first < k_end {
                    let from = first_new + (k_first - k0) as usize;
                    t.seg_sum += sum_sq_diff(&dec.x, from, from + (k_end - k_first) as usize, lag, order);
                    t.seg_n += k_end - k_first;
                }
                let q = q0.div_ceil(m).max(1) * m;
                if q <= p1 {
                    let x = &dec.x;
                    self.zbuf.extend(
                        (q..=p1).step_by(t.m).map(|q| (x[dec.at(q / s)] - x[dec.at(q / s - lag as u64)]) * inv),
                    );
                }
            }
            t.id.push_slice(&self.zbuf, &mut self.zscratch);
        }
    }

    /// Ends the current segment (a gap follows): its terms join the sums at each τ where it
    /// gave at least two.
    pub fn end_segment(&mut self) {
        self.process_block();
        if self.p == 0 {
            return;
        }
        for t in &mut self.taus {
            if t.seg_n >= 2 {
                t.sum += t.seg_sum;
                t.n += t.seg_n;
            }
            (t.seg_sum, t.seg_n) = (0.0, 0);
            t.id.end_segment();
        }
        *self.segments.entry(self.p).or_insert(0) += 1;
        self.p = 0;
        self.x = (0.0, 0.0);
        self.y_ref = None;
    }

    /// Ends the pass: every τ with terms, ascending, and the segment lengths.
    pub fn finish(mut self) -> (Vec<Raw>, BTreeMap<u64, u64>) {
        self.end_segment();
        let norm = self.kind.norm();
        let out = self
            .taus
            .into_iter()
            .filter(|t| t.n > 0)
            .map(|t| {
                let mf = t.m as f64;
                Raw { m: t.m, stride: t.stride, var: t.sum / (norm * mf * mf * t.n as f64), n: t.n, id: t.id }
            })
            .collect();
        (out, self.segments)
    }
}

/// The variance of `kind` at the cluster sizes `ms`, pooled over `segments` (each a run of
/// equally spaced samples), fully overlapping at every size: `(m, variance, terms)` for every
/// `m` with terms, ascending. A segment counts at a size where it gives at least two terms.
pub fn pooled(kind: Kind, segments: &[&[f64]], ms: &[usize]) -> Vec<(usize, f64, usize)> {
    let exact_max_m = ms.iter().copied().max().unwrap_or(1);
    let mut e = Estimator::new(&Config { kind, grid: Grid::List(ms.to_vec()), exact_max_m });
    for seg in segments {
        e.extend(seg);
        e.end_segment();
    }
    e.finish().0.into_iter().map(|r| (r.m, r.var, r.n as usize)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The definition by cluster means, every start, on one segment.
    fn by_definition(y: &[f64], m: usize, order: usize) -> Option<f64> {
        let mean = |k: usize| y[k..k + m].iter().sum::<f64>() / m as f64;
        let n = (y.len() + 1).checked_sub(order * m + 1)? + 1;
        if n < 2 {
            return None;
        }
        let mut s = 0.0;
        for k in 0..n {
            let d = if order == 2 { mean(k + m) - mean(k) } else { mean(k + 2 * m) - 2.0 * mean(k + m) + mean(k) };
            s += d * d;
        }
        Some(s / (if order == 2 { 2.0 } else { 6.0 } * n as f64))
    }

    #[test]
    fn small_blocks_and_segments_equal_the_definition() {
        // Integers: the estimator's sums are exact; the definition divides by m.
        let y: Vec<f64> = (0..20_000u64).map(|k| ((k * 7919 + k * k * 31) % 1009) as f64 - 504.0).collect();
        for (kind, order) in [(Kind::Allan, 2), (Kind::Hadamard, 3)] {
            let ms = [1, 2, 3, 5, 64, 1000, 4097, 6000, 9999];
            let got = pooled(kind, &[&y], &ms);
            for &(m, v, n) in &got {
                let want = by_definition(&y, m, order).unwrap();
                assert!((v - want).abs() <= 1e-12 * want, "{kind:?} m {m}: {v} vs {want}");
                assert_eq!(n, y.len() + 1 - order * m);
            }
            assert_eq!(got.len(), ms.iter().filter(|&&m| by_definition(&y, m, order).is_some()).count());
        }
    }

    #[test]
    fn partially_overlapping_sizes_start_a_cluster_every_stride() {
        let y: Vec<f64> = (0..40_000u64).map(|k| ((k * 104_729) % 2003) as f64).collect();
        // A small exact range and sizes beyond it: the stride is m / PARTIAL_POSITIONS.
        let cfg = Config { kind: Kind::Allan, grid: Grid::List(vec![8192, 12_288]), exact_max_m: 100 };
        let mut e = Estimator::new(&cfg);
        e.extend(&y);
        let (r, _) = e.finish();
        for p in &r {
            let s = p.stride;
            assert_eq!(s, p.m / PARTIAL_POSITIONS);
            // The definition on the phase every s samples.
            let mut x = vec![0.0];
            for v in &y {
                x.push(x.last().unwrap() + v);
            }
            let xs: Vec<f64> = x.iter().step_by(s).copied().collect();
            let l = p.m / s;
            let mut sum = 0.0;
            let mut n = 0;
            for k in 2 * l..xs.len() {
                let d = xs[k] - 2.0 * xs[k - l] + xs[k - 2 * l];
                sum += d * d;
                n += 1;
            }
            let want = sum / (2.0 * (p.m * p.m) as f64 * n as f64);
            assert_eq!(p.n, n as u64);
            assert!((p.var - want).abs() <= 1e-12 * want, "m {}: {} vs {want}", p.m, p.var);
        }
    }
}
