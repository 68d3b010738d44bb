//! Selection and fit of the mechanisms on one accelerometer's residual.
//!
//! Every model contains the nuisance null: the local-level noise model of [`super::noise`]
//! (white + random walk, so a constant offset and slow stochastic drift are noise, never a
//! mechanism). Mechanisms are added by forward search. A candidate is accepted only if all of
//! - the likelihood-ratio test against the current model, with the statistic divided by the
//!   variance inflation of the remaining autocorrelation (Bartlett-weighted sum of the
//!   whitened residual's autocorrelations), has p below α / (mechanisms × axes);
//! - BIC improves (θ counted as a parameter);
//! - the held-out score improves by more than its number of parameters: the summed squared
//!   standardized one-step-ahead innovations on time blocks left out of the fit (40 blocks,
//!   5 folds, block b in fold b mod 5, so every fold spans the whole record).
//!
//! After each addition the time constants of the model's members are re-optimised and members
//! that no longer pass are dropped (backward step). On the final model (θ refined off the grid)
//! every term must also cut the raw held-out RMS (offset removed: the figure the report prints)
//! by more than that cut's fold-to-fold standard error, with "after" below "before", and a
//! temperature form must not be beaten by a drift in time ([`Mech::Drift`]); the weakest term
//! that fails is dropped and the model refitted.
//!
//! Two mechanisms are ambiguous when replacing one by the other (θ re-searched) changes the
//! deviance by less than [`AMBIGUOUS_LR`]: the data cannot tell them apart.

use super::mech::{Context, Mech};
use super::noise::{Filter, Gm, Step, q_upper, smooth_level};
use super::stats::{chi2_sf, chol_solve, dot};

/// Family-wise false-discovery level of the whole diagnosis.
pub const ALPHA: f64 = 1e-3;
/// Deviance difference below which two explanations are taken as equally good.
pub const AMBIGUOUS_LR: f64 = 10.0;
/// Time blocks and folds of the held-out score.
pub const BLOCKS: usize = 40;
/// Folds (block `b` is in fold `b % FOLDS`).
pub const FOLDS: usize = 5;

/// In the selection's cross-validated deviance, a column whose whitened training rows hold
/// less than this share of its whitened sum of squares is not determined by them and takes
/// the fit of all rows. Its coefficient from the training rows alone would carry a variance
/// above 10³ times the whole fit's: a session's level column whitened under a small random
/// walk keeps 2·10⁻⁶ of its energy outside the fold it starts in, and a solve on that gave
/// deviances of ±10⁷ for every candidate (10⁻¹³ at 10⁻⁶: steps located close together in one
/// fold).
pub const CV_MIN_TRAINING_SHARE: f64 = 1e-3;

/// A candidate: one mechanism at one grid θ, and its columns in the bank.
#[derive(Clone, Debug)]
struct Cand {
    mech: Mech,
    theta: Option<f64>,
    cols: Vec<usize>,
    /// Its one coefficient has a physical sign: positive ([`Mech::positive_through_sim`]).
    positive: bool,
}

/// The candidate columns of one accelerometer, each scaled to unit RMS; the first
/// `forced.len()` are the nuisance columns every model carries.
struct Bank {
    cols: Vec<Vec<f64>>,
    cands: Vec<Cand>,
    forced: Vec<usize>,
}

/// Scales `c` to unit RMS (`None` for a zero or non-finite column).
fn unit_rms(c: &[f64]) -> Option<Vec<f64>> {
    let rms = (dot(c, c) / c.len().max(1) as f64).sqrt();
    (rms > 1e-300 && rms.is_finite()).then(|| c.iter().map(|v| v / rms).collect())
}

impl Bank {
    fn new(ctx: &Context) -> Self {
        let mut cols: Vec<Vec<f64>> = ctx.nuisance.iter().filter_map(|c| unit_rms(c)).collect();
        let forced: Vec<usize> = (0..cols.len()).collect();
        let mut cands = Vec::new();
        for m in Mech::ALL {
            if !ctx.available(m) {
                continue;
            }
            let thetas: Vec<Option<f64>> =
                if m.theta().is_some() { ctx.grid(m).into_iter().map(Some).collect() } else { vec![None] };
            for th in thetas {
                let cs = ctx.columns(m, th.unwrap_or(0.0));
                let mut idx = Vec::new();
                for c in cs.iter().filter_map(|c| unit_rms(c)) {
                    cols.push(c);
                    idx.push(cols.len() - 1);
                }
                if !idx.is_empty() {
                    let positive = ctx.s.from_sim && m.positive_through_sim();
                    cands.push(Cand { mech: m, theta: th, cols: idx, positive });
                }
            }
        }
        Bank { cols, cands, forced }
    }

    /// The column indices of a model: the nuisance, then its members'.
    fn cols_of(&self, model: &[usize]) -> Vec<usize> {
        self.forced.iter().copied().chain(model.iter().flat_map(|&c| self.cands[c].cols.iter().copied())).collect()
    }

    /// The columns of a model themselves.
    fn slices_of(&self, model: &[usize]) -> Vec<&[f64]> {
        self.cols_of(model).into_iter().map(|i| self.cols[i].as_slice()).collect()
    }
}

/// The fold of each row (`None`: in no fold).
pub(crate) fn folds_of(n: usize) -> Vec<usize> {
    (0..n).map(|i| (i * BLOCKS / n.max(1)) % FOLDS).collect()
}

/// Gram matrices of the whitened bank columns and `y` (last index).
struct Grams {
    p: usize,
    all: Vec<f64>,
    test: Vec<Vec<f64>>,
    train: Vec<Vec<f64>>,
    n_all: usize,
}

/// The pairs of columns (the bank's, then `y` at `p − 1`) whose Gram entries [`Grams::sse`]
/// reads for a model of the nuisance and at most one candidate: the nuisance and `y` against
/// every column, and each candidate's columns against each other; `a ≤ b`, sorted.
fn candidate_pairs(bank: &Bank, p: usize) -> Vec<(usize, usize)> {
    let y = p - 1;
    let mut pairs: Vec<(usize, usize)> = Vec::new();
    for a in bank.forced.iter().copied().chain(std::iter::once(y)) {
        pairs.extend((0..p).map(|b| (a.min(b), a.max(b))));
    }
    for c in &bank.cands {
        for (u, &a) in c.cols.iter().enumerate() {
            pairs.extend(c.cols[u..].iter().map(|&b| (a.min(b), a.max(b))));
        }
    }
    pairs.sort_unstable();
    pairs.dedup();
    pairs
}

/// Row blocks of the Gram sums: at most [`GRAM_BLOCK`](super::stats::GRAM_BLOCK) rows, each in
/// one fold (`fold` given) — runs of one fold cut from their first row on, as
/// [`gram_blocked`](super::stats::gram_blocked) cuts the ranges it is given, so every sum is made in the same order.
fn gram_chunks(n: usize, fold: Option<&[usize]>) -> Vec<(usize, usize, usize)> {
    let mut out = Vec::new();
    let mut s = 0;
    while s < n {
        let k = fold.map_or(0, |f| f[s]);
        let mut e = s + 1;
        while e < n && fold.is_none_or(|f| f[e] == k) {
            e += 1;
        }
        let mut c0 = s;
        while c0 < e {
            let c1 = (c0 + super::stats::GRAM_BLOCK).min(e);
            out.push((c0, c1, k));
            c0 = c1;
        }
        s = e;
    }
    out
}

impl Grams {
    /// The Gram matrices under the noise model (random-walk intensity `q`, bias instability where
    /// known); with `folds` false only the entries of
    /// all rows that [`Grams::sse`] needs for the nuisance plus one candidate
    /// ([`candidate_pairs`]: about `p` products a row instead of `p²/2`; the others are NaN, and
    /// a model reading them finds no fit). The columns are whitened block by block of rows
    /// beside the products ([`Filter::whiten_rows`]), so no whitened column is stored whole:
    /// the sums are those of whitening first and multiplying after ([`gram_blocked`](super::stats::gram_blocked)), in the
    /// same order.
    fn new(
        t: &[f64],
        r: &[f64],
        (q, gm): (f64, Option<Gm>),
        y: &[f64],
        bank: &Bank,
        fold: &[usize],
        folds: bool,
    ) -> Self {
        use super::stats::GRAM_BLOCK;
        let p = bank.cols.len() + 1;
        let n = y.len();
        let f0 = Filter::new(t, r, q, gm, |_| true);
        let xs: Vec<&[f64]> = bank.cols.iter().map(Vec::as_slice).chain(std::iter::once(y)).collect();
        let mut level = vec![0.0; p * f0.states()];
        let mut w = vec![0.0; p * GRAM_BLOCK];
        let pairs = if folds { Vec::new() } else { candidate_pairs(bank, p) };
        let mut sums = vec![0.0; pairs.len()];
        let mut test: Vec<Vec<f64>> = if folds { vec![vec![0.0; p * p]; FOLDS] } else { Vec::new() };
        for (c0, c1, k) in gram_chunks(n, folds.then_some(fold)) {
            let len = c1 - c0;
            f0.whiten_rows(&xs, c0..c1, &mut level, &mut w, GRAM_BLOCK);
            let col = |a: usize| &w[a * GRAM_BLOCK..a * GRAM_BLOCK + len];
            if folds {
                let g = &mut test[k];
                for a in 0..p {
                    for b in a..p {
                        g[a * p + b] += dot(col(a), col(b));
                    }
                }
            } else {
                for (s, &(a, b)) in sums.iter_mut().zip(&pairs) {
                    *s += dot(col(a), col(b));
                }
            }
        }
        if !folds {
            let mut all = vec![f64::NAN; p * p];
            for (&(a, b), s) in pairs.iter().zip(sums) {
                all[a * p + b] = s;
                all[b * p + a] = s;
            }
            return Grams { p, all, test, train: Vec::new(), n_all: f0.n_used };
        }
        for g in test.iter_mut() {
            for a in 0..p {
                for b in 0..a {
                    g[a * p + b] = g[b * p + a];
                }
            }
        }
        let mut all = vec![0.0; p * p];
        for g in &test {
            for (a, b) in all.iter_mut().zip(g) {
                *a += b;
            }
        }
        // The training rows of fold k are every row but its own: their Gram is the whole
        // one less the fold's (the innovations of the one whitening of all rows, so a
        // training row just after a held-out block still saw that block's level: a small
        // leak that five separate whitenings, six times the work, would avoid).
        let train: Vec<Vec<f64>> = test.iter().map(|g| all.iter().zip(g).map(|(a, b)| a - b).collect()).collect();
        Grams { p, all, test, train, n_all: f0.n_used }
    }

    /// GLS on the columns `idx`: coefficients (of the scaled columns) and SSE.
    fn fit(g: &[f64], p: usize, idx: &[usize]) -> Option<(Vec<f64>, f64)> {
        let y = p - 1;
        let m = idx.len();
        if m == 0 {
            return Some((Vec::new(), g[y * p + y]));
        }
        let mut a = vec![0.0; m * m];
        let mut b = vec![0.0; m];
        for (u, &cu) in idx.iter().enumerate() {
            b[u] = g[cu * p + y];
            for (v, &cv) in idx.iter().enumerate() {
                a[u * m + v] = g[cu * p + cv];
            }
        }
        let (x, _) = chol_solve(&a, &b, m, 1e-9)?;
        let fit: f64 = x.iter().zip(&b).map(|(x, b)| x * b).sum();
        Some((x, (g[y * p + y] - fit).max(0.0)))
    }

    fn sse(&self, idx: &[usize]) -> Option<f64> {
        Self::fit(&self.all, self.p, idx).map(|f| f.1)
    }

    /// Held-out score: Σ over folds of the test rows' whitened SSE with β from the others.
    fn cv(&self, idx: &[usize]) -> Option<f64> {
        let p = self.p;
        let y = p - 1;
        if self.train.is_empty() {
            return None;
        }
        let mut total = 0.0;
        for k in 0..FOLDS {
            // A column the training rows do not determine (a bias step's Heaviside column,
            // whose whitened form lives only just after the step, in the held-out block)
            // takes the fit of all rows, as the held-out figures do. "Not determined" is also a
            // column the training rows hold almost nothing of ([`CV_MIN_TRAINING_SHARE`] of
            // all rows' whitened sum of squares): a solve that passes on it returns noise over
            // ~0.
            let determined =
                idx.iter().all(|&c| self.train[k][c * p + c] > CV_MIN_TRAINING_SHARE * self.all[c * p + c]);
            let on_train = if determined { Self::fit(&self.train[k], p, idx) } else { None };
            let (beta, _) = on_train.or_else(|| Self::fit(&self.all, p, idx))?;
            let g = &self.test[k];
            let mut s = g[y * p + y];
            for (u, &cu) in idx.iter().enumerate() {
                s -= 2.0 * beta[u] * g[cu * p + y];
                for (v, &cv) in idx.iter().enumerate() {
                    s += beta[u] * beta[v] * g[cu * p + cv];
                }
            }
            total += s;
        }
        Some(total)
    }
}

/// One step of the forward search, for the report.
#[derive(Clone, Debug)]
pub struct StepInfo {
    /// The mechanism tried.
    pub mech: Mech,
    /// Its best grid θ.
    pub theta: Option<f64>,
    /// Likelihood-ratio statistic (after the autocorrelation inflation).
    pub lr: f64,
    /// Degrees of freedom.
    pub df: usize,
    /// p-value.
    pub p: f64,
    /// BIC improvement.
    pub dbic: f64,
    /// Held-out improvement in units of the residual variance.
    pub dcv: f64,
    /// Accepted into the model.
    pub accepted: bool,
}

/// A fitted term.
#[derive(Clone, Debug)]
pub struct Term {
    /// The mechanism.
    pub mech: Mech,
    /// Its θ (time constant \[s\] or width [°C]).
    pub theta: Option<f64>,
    /// 95 % profile-likelihood interval of θ.
    pub theta_ci: Option<(f64, f64)>,
    /// Coefficients of the raw (unscaled) columns.
    pub coef: Vec<f64>,
    /// Their standard errors (inflated for autocorrelation).
    pub se: Vec<f64>,
    /// LR statistic for dropping the term from the final model.
    pub lr_drop: f64,
    /// Its p-value.
    pub p_drop: f64,
    /// The term's contribution at every row \[g\].
    pub contribution: Vec<f64>,
    /// Its columns at every row (raw, per unit coefficient).
    pub columns: Vec<Vec<f64>>,
    /// For a warm-up fitted with its fast part, the ratio τ/τ_fast ([`Context::member_columns`]).
    pub fast_ratio: Option<f64>,
}

impl Term {
    /// Whether the term is a warm-up fitted with its fast part ([`Context::member_columns`]).
    pub fn fast_warmup(&self) -> bool {
        self.fast_ratio.is_some()
    }
}

/// The diagnosis of one accelerometer.
#[derive(Clone, Debug)]
pub struct AxisFit {
    /// Accelerometer index.
    pub axis: usize,
    /// Random-walk intensity of the noise model [g²/s].
    pub q: f64,
    /// The bias instability of the noise model, where known ([`Context::gm`]).
    pub gm: Option<Gm>,
    /// Variance inflation for the remaining autocorrelation.
    pub inflation: f64,
    /// The selected terms.
    pub terms: Vec<Term>,
    /// For each selected mechanism, the mechanisms that explain the data equally well, with
    /// the deviance difference on the data (NaN where the rival joined on its separability
    /// alone).
    pub ambiguous: Vec<(Mech, Vec<(Mech, f64)>)>,
    /// For each selected mechanism, every rival's separability on this recording
    /// ([`super::separate::separability`]: the deviance the rival, refitted, cannot absorb of
    /// what the mechanism predicts), ascending.
    pub separability: Vec<(Mech, Vec<(Mech, f64)>)>,
    /// The unit of the deviances: the whitened residual variance times the inflation.
    pub deviance_scale: f64,
    /// The rows the noise model's whitening used (its updates), what the deviances count.
    pub n_used: usize,
    /// The forward search.
    pub trace: Vec<StepInfo>,
    /// The mechanisms that pass the selection's test as the first term, against the nuisance
    /// alone (the forward search's first round, whichever of them it then took): each explains
    /// structure of this accelerometer's data on its own.
    pub passes_alone: Vec<Mech>,
    /// The drift of the final model at every row \[g\]: the smoothed random-walk level of
    /// what the terms leave. Reported and drawn on its own, never subtracted.
    pub drift: Vec<f64>,
    /// RMS of the drift about its mean \[g\].
    pub drift_rms: f64,
    /// Model prediction at every row \[g\].
    pub prediction: Vec<f64>,
    /// RMS \[g\] of the residual with one offset removed, before and after the model (the
    /// terms and the re-fitted nuisance), all rows.
    pub rms: (f64, f64),
    /// The same on held-out blocks (coefficients and offset fitted without them).
    pub heldout_rms: (f64, f64),
    /// The held-out raw residual at every row \[g\] (each row predicted from the folds it is
    /// not in, offset removed), before and after the model: what `heldout_rms` is the RMS of,
    /// and what the verdicts look at on every time scale ([`super::noise::structure_scales`]).
    pub heldout_resid: (Vec<f64>, Vec<f64>),
    /// Per term (as in `terms`): the cut of the raw held-out RMS the term brings \[g\] (the
    /// model without it, or the offset alone where that is lower, minus the model) and that
    /// cut's fold-to-fold standard error. Never more than "before" minus "after".
    pub heldout_gain: Vec<(f64, f64)>,
    /// The die's rise at each power-on a thermal lag carries in this fit
    /// ([`Context::lag_rise_c`]) [°C].
    pub lag_rise_c: f64,
}

/// The raw held-out residual of a model: per fold, coefficients (GLS under the noise model)
/// and offset fitted on the other folds, the fold's rows predicted.
pub struct RawHeldout {
    /// Held-out residual at every row \[g\].
    pub resid: Vec<f64>,
    /// Per fold: sum of squares and rows.
    pub fold_ss: [(f64, usize); FOLDS],
}

impl RawHeldout {
    /// RMS over all rows \[g\].
    pub fn rms(&self) -> f64 {
        let (s, c) = self.fold_ss.iter().fold((0.0, 0usize), |a, f| (a.0 + f.0, a.1 + f.1));
        (s / c.max(1) as f64).sqrt()
    }

    /// What `self` cuts from `without`'s RMS \[g\] and the standard error of that cut from
    /// its spread over the folds.
    pub fn gain_over(&self, without: &RawHeldout) -> (f64, f64) {
        let g = without.rms() - self.rms();
        let d: Vec<f64> = (0..FOLDS)
            .map(|k| {
                let r = |h: &RawHeldout| (h.fold_ss[k].0 / h.fold_ss[k].1.max(1) as f64).sqrt();
                r(without) - r(self)
            })
            .collect();
        let m = d.iter().sum::<f64>() / FOLDS as f64;
        let var = d.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (FOLDS - 1) as f64;
        (g, (var / FOLDS as f64).sqrt())
    }
}

/// Whether the rows outside fold `k` determine column `c` for predicting that fold: they
/// hold more than 10⁻⁶ of its energy, and more than 10⁻⁶ of its spread about their mean. A
/// column they hold (almost) nothing of would get a coefficient of noise over ~0; one they
/// hold nothing of but a constant is the level, which the fit already has free (a play engaged
/// through every other fold of a one-way ramp, moving only in this one, came out at 10³ g).
fn determined_by_training(c: &[f64], fold: &[usize], k: usize) -> bool {
    let train = || c.iter().zip(fold).filter(move |(_, f)| **f != k).map(|(v, _)| *v);
    let (sum, count) = train().fold((0.0, 0usize), |(s, m), v| (s + v, m + 1));
    let mean = sum / count.max(1) as f64;
    let energy = train().map(|v| v * v).sum::<f64>();
    let spread = train().map(|v| (v - mean).powi(2)).sum::<f64>();
    energy > 1e-6 * c.iter().map(|v| v * v).sum::<f64>()
        && spread > 1e-6 * c.iter().map(|v| (v - mean).powi(2)).sum::<f64>()
}

/// [`RawHeldout`] of `y` on the columns `refs` (none: the offset alone) under the noise model
/// (times `t`, white variances `r`, random walk `q`, bias instability `gm` where known).
///
/// `blocks`: when the rows are blocks ([`super::prep::Builder::with_blocks`]), each block's
/// rows and the residual's sum of squares within it: the offset is the rows' mean and the
/// RMS is over the recording's rows.
pub fn raw_heldout(
    t: &[f64],
    r: &[f64],
    (q, gm): (f64, Option<Gm>),
    y: &[f64],
    refs: &[&[f64]],
    fold: &[usize],
    blocks: Option<(&[f64], &[f64])>,
) -> RawHeldout {
    let n = y.len();
    let mut resid = vec![0.0; n];
    let mut fold_ss = [(0.0, 0usize); FOLDS];
    for (k, fs) in fold_ss.iter_mut().enumerate() {
        let held: Vec<&[f64]> = refs.iter().copied().filter(|c| determined_by_training(c, fold, k)).collect();
        let bk = if held.is_empty() {
            Vec::new()
        } else {
            let fk = Filter::new(t, r, q, gm, |i| fold[i] != k);
            match gls(&fk, y, &held) {
                Some(g) => g.0,
                None => {
                    gls(&Filter::new(t, r, q, gm, |_| true), y, &held).map_or_else(|| vec![0.0; held.len()], |g| g.0)
                }
            }
        };
        let refs = &held;
        let ek: Vec<f64> = (0..n).map(|i| y[i] - refs.iter().zip(&bk).map(|(c, b)| c[i] * b).sum::<f64>()).collect();
        if let Some((w, within)) = blocks {
            let (s, c) = (0..n).filter(|&i| fold[i] != k).fold((0.0, 0.0), |(s, c), i| (s + w[i] * ek[i], c + w[i]));
            let off = s / c.max(1.0);
            for i in (0..n).filter(|&i| fold[i] == k) {
                resid[i] = ek[i] - off;
                fs.0 += w[i] * resid[i] * resid[i] + within[i];
                fs.1 += w[i] as usize;
            }
            continue;
        }
        let (s, c) = (0..n).filter(|&i| fold[i] != k).fold((0.0, 0usize), |(s, c), i| (s + ek[i], c + 1));
        let off = s / c.max(1) as f64;
        for i in (0..n).filter(|&i| fold[i] == k) {
            resid[i] = ek[i] - off;
            fs.0 += resid[i] * resid[i];
            fs.1 += 1;
        }
    }
    RawHeldout { resid, fold_ss }
}

/// [`centred_rms`] over the recording's rows when `v` holds block means (`blocks`: each block's
/// rows and the sum of squares within it, [`raw_heldout`]); without blocks, [`centred_rms`].
pub fn centred_rms_rows(v: &[f64], blocks: Option<(&[f64], &[f64])>) -> f64 {
    let Some((w, within)) = blocks else { return centred_rms(v, None) };
    let c: f64 = w.iter().sum();
    if !(c > 0.0) {
        return 0.0;
    }
    let m = v.iter().zip(w).map(|(x, w)| x * w).sum::<f64>() / c;
    ((v.iter().zip(w).zip(within).map(|((x, w), s)| w * (x - m).powi(2) + s).sum::<f64>()) / c).sqrt()
}

/// `v` less its mean over each session (row-weighted by `weight` when the rows are blocks).
pub fn session_centred(v: &[f64], sessions: &[std::ops::Range<usize>], weight: Option<&[f64]>) -> Vec<f64> {
    let mut out = v.to_vec();
    for r in sessions {
        let (s, c) = r.clone().fold((0.0, 0.0), |(s, c), i| {
            let w = weight.map_or(1.0, |w| w[i]);
            (s + w * v[i], c + w)
        });
        let m = if c > 0.0 { s / c } else { 0.0 };
        out[r.clone()].iter_mut().for_each(|x| *x -= m);
    }
    out
}

/// RMS of `v` about its mean (over the rows of `mask`, all when `None`).
pub fn centred_rms(v: &[f64], mask: Option<&[bool]>) -> f64 {
    let inc = |i: usize| mask.is_none_or(|m| m[i]);
    let (s, c) = (0..v.len()).filter(|&i| inc(i)).fold((0.0, 0usize), |(s, c), i| (s + v[i], c + 1));
    if c == 0 {
        return 0.0;
    }
    let m = s / c as f64;
    ((0..v.len()).filter(|&i| inc(i)).map(|i| (v[i] - m).powi(2)).sum::<f64>() / c as f64).sqrt()
}

/// Variance inflation of a sum of the innovations `w` (over the rows where `used`) for their
/// remaining autocorrelation: `1 + 2Σ_k (1 − k/(l+1)) ρ_k`, k ≤ l = min(20, n/10) (Bartlett
/// weights), at least 1; 1 with fewer than 50 rows.
pub(crate) fn inflation(w: &[f64], used: &[bool]) -> f64 {
    let v: Vec<f64> = w.iter().zip(used).filter(|(_, u)| **u).map(|(x, _)| *x).collect();
    let n = v.len();
    if n < 50 {
        return 1.0;
    }
    let mean = v.iter().sum::<f64>() / n as f64;
    let c: Vec<f64> = v.iter().map(|x| x - mean).collect();
    let c0 = dot(&c, &c);
    if !(c0 > 0.0) {
        return 1.0;
    }
    let l = 20usize.min(n / 10);
    let mut s = 1.0;
    for k in 1..=l {
        let rho = dot(&c[k..], &c[..n - k]) / c0;
        s += 2.0 * (1.0 - k as f64 / (l as f64 + 1.0)) * rho;
    }
    s.max(1.0)
}

/// Direct GLS with the whitening filter `f`: coefficients, standard errors per unit variance,
/// SSE and the whitened residual.
/// GLS result: coefficients, standard errors per unit variance, SSE, whitened residual.
type Gls = (Vec<f64>, Vec<f64>, f64, Vec<f64>);

fn gls(f: &Filter, y: &[f64], cols: &[&[f64]]) -> Option<Gls> {
    // All columns whitened in one interleaved pass (the values of whitening each alone).
    let n = cols.iter().map(|c| c.len()).fold(y.len(), usize::min).min(f.step.len());
    if n == 0 {
        return None;
    }
    let xs: Vec<&[f64]> = cols.iter().copied().chain(std::iter::once(y)).collect();
    let mut flat = vec![0.0; xs.len() * n];
    f.whiten_rows(&xs, 0..n, &mut vec![0.0; xs.len() * f.states()], &mut flat, n);
    let (wx, wy) = flat.split_at(cols.len() * n);
    let wx: Vec<&[f64]> = wx.chunks_exact(n).collect();
    let m = wx.len();
    let norms: Vec<f64> = wx.iter().map(|c| dot(c, c).sqrt()).collect();
    if norms.iter().any(|v| !(*v > 0.0)) {
        return None;
    }
    let mut a = vec![0.0; m * m];
    let mut b = vec![0.0; m];
    for u in 0..m {
        b[u] = dot(wx[u], wy) / norms[u];
        for v in 0..m {
            a[u * m + v] = dot(wx[u], wx[v]) / (norms[u] * norms[v]);
        }
    }
    let (x, d) = if m > 0 { chol_solve(&a, &b, m, 1e-10)? } else { (Vec::new(), Vec::new()) };
    let beta: Vec<f64> = x.iter().zip(&norms).map(|(x, n)| x / n).collect();
    let se: Vec<f64> = d.iter().zip(&norms).map(|(d, n)| d.sqrt() / n).collect();
    let mut res = wy.to_vec();
    for (c, bt) in wx.iter().zip(&beta) {
        for (r, v) in res.iter_mut().zip(c.iter()) {
            *r -= bt * v;
        }
    }
    let sse = dot(&res, &res);
    Some((beta, se, sse, res))
}

/// Variance inflation of a model (by its candidates).
type InflOf<'a> = Box<dyn Fn(&[usize]) -> f64 + 'a>;

struct Selector<'a> {
    bank: &'a Bank,
    grams: Grams,
    infl_of: InflOf<'a>,
    alpha: f64,
}

impl Selector<'_> {
    fn cols(&self, model: &[usize]) -> Vec<usize> {
        self.bank.cols_of(model)
    }

    fn df(&self, c: usize) -> usize {
        self.bank.cands[c].cols.len() + usize::from(self.bank.cands[c].theta.is_some())
    }

    /// Best grid candidate of mechanism `m` added to `model`: (cand, sse). A candidate whose
    /// coefficient has a physical sign ([`Cand::positive`]) is offered only where it fits with
    /// that sign.
    fn best_of(&self, model: &[usize], m: Mech) -> Option<(usize, f64)> {
        let mut best: Option<(usize, f64)> = None;
        for (ci, c) in self.bank.cands.iter().enumerate() {
            if c.mech != m {
                continue;
            }
            let mut idx = self.cols(model);
            idx.extend(c.cols.iter().copied());
            let sse = if c.positive {
                Grams::fit(&self.grams.all, self.grams.p, &idx)
                    .and_then(|(x, sse)| (x.last() > Some(&0.0)).then_some(sse))
            } else {
                self.grams.sse(&idx)
            };
            if let Some(sse) = sse
                && best.is_none_or(|b| sse < b.1)
            {
                best = Some((ci, sse));
            }
        }
        best
    }

    fn evaluate(&self, model: &[usize], cand: usize, sse0: f64, sse1: f64, cv0: f64) -> StepInfo {
        let n = self.grams.n_all as f64;
        let mut with = model.to_vec();
        with.push(cand);
        let infl = (self.infl_of)(&with);
        let df = self.df(cand);
        let lr = n * (sse0 / sse1.max(1e-300)).ln() / infl;
        let p = chi2_sf(lr, df as f64);
        let dbic = lr - df as f64 * n.ln();
        let cv1 = self.grams.cv(&self.cols(&with)).unwrap_or(f64::INFINITY);
        let dcv = (cv0 - cv1) / (sse1 / n) / infl;
        let c = &self.bank.cands[cand];
        StepInfo { mech: c.mech, theta: c.theta, lr, df, p, dbic, dcv, accepted: false }
    }

    fn passes(&self, s: &StepInfo) -> bool {
        s.p < self.alpha && s.dbic > 0.0 && s.dcv > s.df as f64
    }

    fn reoptimise(&self, model: &mut [usize]) {
        for k in 0..model.len() {
            let m = self.bank.cands[model[k]].mech;
            if m.theta().is_none() {
                continue;
            }
            let rest: Vec<usize> = model.iter().enumerate().filter(|(j, _)| *j != k).map(|(_, c)| *c).collect();
            if let Some((c, _)) = self.best_of(&rest, m) {
                model[k] = c;
            }
        }
    }

    /// The forward search from `start`, with the backward check after each step; every failed
    /// and accepted step goes to `trace`, and from an empty start, the mechanisms that pass the
    /// first round to `alone`.
    fn run(&self, start: Vec<usize>, trace: &mut Vec<StepInfo>, alone: &mut Vec<Mech>) -> Vec<usize> {
        let mut model = start;
        for round in 0..12 {
            let idx = self.cols(&model);
            let Some(sse0) = self.grams.sse(&idx) else { break };
            let cv0 = self.grams.cv(&idx).unwrap_or(f64::INFINITY);
            let mut best: Option<(usize, StepInfo)> = None;
            for m in Mech::ALL {
                if model.iter().any(|&c| self.bank.cands[c].mech == m) {
                    continue;
                }
                let Some((c, sse1)) = self.best_of(&model, m) else { continue };
                let s = self.evaluate(&model, c, sse0, sse1, cv0);
                let ok = self.passes(&s);
                if ok && round == 0 && model.is_empty() {
                    alone.push(m);
                }
                if ok && best.as_ref().is_none_or(|b| s.dbic > b.1.dbic) {
                    best = Some((c, s.clone()));
                }
                if !ok {
                    trace.push(s);
                }
            }
            let Some((c, mut s)) = best else { break };
            s.accepted = true;
            trace.push(s);
            model.push(c);
            self.reoptimise(&mut model);
            // Backward: drop members that no longer pass.
            loop {
                let mut worst: Option<(usize, f64)> = None;
                for k in 0..model.len() {
                    let rest: Vec<usize> = model.iter().enumerate().filter(|(j, _)| *j != k).map(|(_, c)| *c).collect();
                    let (Some(s_rest), Some(s_all)) =
                        (self.grams.sse(&self.cols(&rest)), self.grams.sse(&self.cols(&model)))
                    else {
                        continue;
                    };
                    let cv_rest = self.grams.cv(&self.cols(&rest)).unwrap_or(f64::INFINITY);
                    let st = self.evaluate(&rest, model[k], s_rest, s_all, cv_rest);
                    if !self.passes(&st) && worst.is_none_or(|w| st.p > w.1) {
                        worst = Some((k, st.p));
                    }
                }
                match worst {
                    Some((k, _)) => {
                        model.remove(k);
                    }
                    None => break,
                }
            }
        }
        model
    }
}

/// The random-walk intensity [g²/s] the selection tests against: the upper end of the 95 %
/// restricted-likelihood interval ([`q_upper`]) with the richest model in (the nuisance and
/// every available mechanism at its best grid θ), as an F-test takes its variance from the
/// full model. Estimated under the null alone, the random walk takes any slow structure for
/// drift (a heating/cooling difference of 10× the noise becomes a few mg/√h) and nothing can
/// be named against it; estimated by its maximum alone, a weak random walk often comes out
/// far too small and is then named as a mechanism.
fn rich_q(bank: &Bank, grams: &Grams, t: &[f64], r: &[f64], gm: Option<Gm>, y: &[f64]) -> f64 {
    let mut rich: Vec<usize> = Vec::new();
    for m in Mech::ALL {
        let mut best: Option<(usize, f64)> = None;
        for (ci, c) in bank.cands.iter().enumerate() {
            if c.mech != m {
                continue;
            }
            let mut idx = bank.cols_of(&[]);
            idx.extend(c.cols.iter().copied());
            if let Some(sse) = grams.sse(&idx)
                && best.is_none_or(|b| sse < b.1)
            {
                best = Some((ci, sse));
            }
        }
        if let Some((c, _)) = best {
            rich.push(c);
        }
    }
    q_upper(t, r, gm, y, &bank.slices_of(&rich))
}

/// Diagnoses one accelerometer. `random_walk`: the random-walk intensity [g²/s] to test
/// against (a sensor specification); `None` estimates it with the richest model (`rich_q`).
pub fn fit_axis(ctx: &Context, n_axes_tested: usize, random_walk: Option<f64>) -> AxisFit {
    let p = ctx.p;
    let (t, r, y) = (&p.t, &p.r_white[ctx.axis], &p.r[ctx.axis]);
    let n = y.len();
    let bank = Bank::new(ctx);
    let fold = folds_of(n);
    let alpha = ALPHA / (Mech::ALL.len() * n_axes_tested.max(1)) as f64;
    let (q, grams) = match random_walk {
        Some(q) => (q, Grams::new(t, r, (q, ctx.gm), y, &bank, &fold, true)),
        None => {
            // θ of the richest model picked by least squares (white noise: the deterministic
            // structure decides), then the random walk estimated with it in.
            let g0 = Grams::new(t, r, (0.0, None), y, &bank, &fold, false);
            let q = rich_q(&bank, &g0, t, r, ctx.gm, y);
            (q, Grams::new(t, r, (q, ctx.gm), y, &bank, &fold, true))
        }
    };
    let filt = Filter::new(t, r, q, ctx.gm, |_| true);
    let used: Vec<bool> = filt.step.iter().map(|s| *s == Step::Update).collect();
    let bank_ref = &bank;
    let infl_of = move |m: &[usize]| match gls(&filt, y, &bank_ref.slices_of(m)) {
        Some((_, _, _, res)) => inflation(&res, &used),
        None => f64::INFINITY,
    };
    let sel = Selector { bank: &bank, grams, infl_of: Box::new(infl_of), alpha };
    let mut trace = Vec::new();
    let mut passes_alone = Vec::new();
    let mut model = sel.run(Vec::new(), &mut trace, &mut passes_alone);
    // Backward pruning on the refined model (θ off the grid): a term that no longer passes
    // was only compensating a grid θ of another.
    let n_used = n.saturating_sub(1).max(2) as f64;
    loop {
        let fit = finish(ctx, &bank, &model, q, &fold, None);
        // A lag, play or self-heating acting through SIM's sensitivity with a negative gain
        // (the temperature reaching the sensor ahead of the thermistor, a die colder than it
        // after power-on) is not that physics: such a term goes first.
        let unphysical = fit
            .terms
            .iter()
            .position(|t| ctx.s.from_sim && t.mech.positive_through_sim() && t.coef.first().is_some_and(|c| *c <= 0.0));
        let weakest = unphysical.or_else(|| {
            fit.terms
                .iter()
                .enumerate()
                .filter(|(_, t)| {
                    let df = t.coef.len() + usize::from(t.theta.is_some());
                    t.p_drop >= alpha || t.lr_drop - df as f64 * n_used.ln() < 0.0
                })
                .max_by(|a, b| a.1.p_drop.total_cmp(&b.1.p_drop))
                .map(|(k, _)| k)
        });
        // The report's own figure decides: a term is kept only if it cuts the raw held-out
        // RMS by more than that cut's fold-to-fold standard error, and the model never leaves
        // "after" above "before". Whitened innovations under the random walk alone would keep
        // a drift-shaped term (a time constant of the record's length) that wins on
        // differences while the levels, the figure the report prints, come out worse.
        let weakest = weakest.or_else(|| {
            let worst = fit
                .heldout_gain
                .iter()
                .enumerate()
                .min_by(|a, b| (a.1.0 - a.1.1).total_cmp(&(b.1.0 - b.1.1)))
                .map(|(k, g)| (k, g.0 - g.1));
            match worst {
                Some((k, margin)) if margin <= 0.0 || fit.heldout_rms.1 >= fit.heldout_rms.0 => Some(k),
                _ => None,
            }
        });
        match weakest {
            Some(k) => {
                model.remove(k);
            }
            None => {
                let all_dev = ambiguity(&bank, &model, &sel.grams, fit.inflation);
                let mut amb: Vec<(Mech, Vec<(Mech, f64)>)> = all_dev
                    .iter()
                    .map(|(m, alts)| (*m, alts.iter().copied().filter(|a| a.1 < AMBIGUOUS_LR).collect::<Vec<_>>()))
                    .filter(|(_, alts)| !alts.is_empty())
                    .collect();
                let beyond = drift_alternatives(ctx, &bank, &model, q, fit.inflation, &mut amb);
                // A temperature form that a drift in time explains clearly better, and that
                // adds nothing once that drift is in, is not a finding: it competes with
                // drift, not with the null. (One that still adds beside the drift stays: the
                // drift then explains something else the model lacks.)
                let drift_wins = amb.iter().find_map(|(m, alts)| {
                    let adds = beyond.iter().any(|(b, d)| b == m && *d >= AMBIGUOUS_LR);
                    (!adds && alts.iter().any(|(a, d)| Mech::ALTERNATIVES.contains(a) && *d <= -AMBIGUOUS_LR))
                        .then(|| fit.terms.iter().position(|t| t.mech == *m))
                        .flatten()
                });
                if let Some(k) = drift_wins {
                    model.remove(k);
                    continue;
                }
                // Joins rival `b` to the group of the selected `m`, with the deviance difference
                // on the data where the search has it.
                let mut join = |m: Mech, b: Mech| {
                    let on_data = all_dev
                        .iter()
                        .find(|(a, _)| *a == m)
                        .and_then(|(_, alts)| alts.iter().find(|x| x.0 == b))
                        .map_or(f64::NAN, |x| x.1);
                    match amb.iter_mut().find(|(a, _)| *a == m) {
                        Some((_, alts)) => {
                            if !alts.iter().any(|x| x.0 == b) {
                                alts.push((b, on_data));
                            }
                        }
                        None => amb.push((m, vec![(b, on_data)])),
                    }
                };
                let sep = separability_of(ctx, &fit);
                let mut by_design: Vec<(Mech, Mech)> = Vec::new();
                for (m, rivals) in &sep {
                    let df = fit
                        .terms
                        .iter()
                        .find(|t| t.mech == *m)
                        .map_or(1, |t| t.coef.len() + usize::from(t.theta.is_some()));
                    let needed = super::separate::separation_needed(naming_threshold(alpha, df), df);
                    for &(b, _) in rivals.iter().filter(|r| r.1 < needed) {
                        join(*m, b);
                        by_design.push((*m, b));
                    }
                }
                // A term that a rival acting through the die's rise after power-on explains
                // about as well on the data is that rival as much as itself, whatever the
                // separability of the term's own prediction says.
                for (m, b, d) in die_rise_on_data(ctx, &fit, &by_design) {
                    if d < AMBIGUOUS_LR {
                        join(m, b);
                    }
                }
                // An additive play in one orientation whose gain has the sign a held
                // temperature gives is also a thermal play on a temperature the thermistor does
                // not follow: one group, whatever the measured separability (which holds the
                // play to SIM's slope at the thermistor's temperature).
                if fit.terms.iter().any(|t| t.mech == Mech::BiasHysteresis && held_temperature_play(ctx, t)) {
                    join(Mech::BiasHysteresis, Mech::ThermalHysteresis);
                }
                // The names, groups and separabilities are decided on the forms the search
                // holds (a warm-up of one exponential); a named warm-up then takes its fast
                // part where the data ask for it, and the figures are that model's.
                let mut fit = match fast_warmup(ctx, &bank, &model, &fold, &fit, alpha) {
                    Some(with) => with,
                    None => fit,
                };
                fit.trace = trace;
                fit.passes_alone = passes_alone;
                fit.ambiguous = amb;
                fit.separability = sep;
                return fit;
            }
        }
    }
}

/// The fit `fit` of `model` with its warm-up given the fast part ([`Context::member_columns`]),
/// where the data ask for it: the second exponential passes the selection's own test (its
/// likelihood ratio beside the model at p < `alpha` and above BIC's ln n) and lowers the raw
/// held-out RMS the report prints. The fast part is tried at each ratio of
/// `mech::WARMUP_FAST_RATIOS`; of the refits that pass, the one with the lowest held-out RMS is
/// kept. `None` without a warm-up or where no ratio passes.
/// A warm-up is rarely one exponential (the electronics and the package settle at their own
/// rates); one exponential fitted to two leaves the first minutes after power-on at several
/// times the noise floor, or takes another term to stand in for the rest.
fn fast_warmup(
    ctx: &Context,
    bank: &Bank,
    model: &[usize],
    fold: &[usize],
    fit: &AxisFit,
    alpha: f64,
) -> Option<AxisFit> {
    if !fit.terms.iter().any(|t| t.mech == Mech::Warmup) {
        return None;
    }
    let nu = fit.n_used as f64;
    // The whitened residual sums of squares, from each fit's deviance unit (their ratio).
    let sse0 = fit.deviance_scale / fit.inflation;
    let mut best: Option<AxisFit> = None;
    for ratio in super::mech::WARMUP_FAST_RATIOS {
        let with = finish(ctx, bank, model, fit.q, fold, Some(ratio));
        if !with.terms.iter().any(Term::fast_warmup) {
            continue;
        }
        let sse1 = with.deviance_scale / with.inflation;
        let lr = nu * (sse0 / sse1.max(1e-300)).ln() / with.inflation;
        let passes = chi2_sf(lr, 1.0) < alpha && lr > nu.ln() && with.heldout_rms.1 < fit.heldout_rms.1;
        if passes && best.as_ref().is_none_or(|b| with.heldout_rms.1 < b.heldout_rms.1) {
            best = Some(with);
        }
    }
    best
}

/// Largest spread (standard deviation) of the accelerometer's own gravity component \[g\] at
/// which its recording counts as one orientation: the scale part of a thermal play is then a
/// constant, and nothing but SIM's slope tells it from an additive play.
pub const ONE_ORIENTATION_SPREAD_G: f64 = 0.05;

/// Share of `|gain · S'(T)|` that must come from rows where the additive play's gain has the
/// sign of SIM's slope for it to be also a held temperature ([`held_temperature_play`]);
/// weighting by the product lets rows where the slope crosses zero, which a play hardly moves,
/// count little.
pub const HELD_SIGN_SHARE: f64 = 0.9;

/// Whether a fitted additive bias play (`bias_hysteresis`, columns `d`, `d·ΔT` with `d` the
/// play's offset over its half-width) is also a thermal play: the accelerometer stays in one
/// orientation ([`ONE_ORIENTATION_SPREAD_G`]) and its gain `c0 + c1·ΔT` has the sign of SIM's
/// slope `S'(T)` on at least [`HELD_SIGN_SHARE`] of `Σ|gain·S'(T)|`, either over the rows where
/// the play is engaged (`|d| ≥ 0.5`) or over the rows where it moves (weighted by `|Δd|`).
/// A thermal play of width `w` holds the temperature at `T + d·w/2` and gives
/// `S(T + d·w/2) − S(T) ≈ S'(T)·d·w/2`, exactly `d·(c0 + c1·ΔT)` with a gain of that sign
/// wherever `S'` is linear in T over the swept range: the
/// additive form with the same sign *is* a play of a temperature the thermistor does not
/// follow (a die running warmer, its own slope), and only a second orientation or a range
/// where the slope bends tells the two apart. The rows where the play moves count on their own
/// because on a leg that stays engaged `d` is constant, so `d·c0` is an offset and `d·c1·ΔT` a
/// slope in temperature that takes whatever else is linear in it: a monotone ramp identifies
/// the gain only where the play engages (seed 73190 of the combined user-profile draw: a play
/// held on the die, gain crossing zero mid-ramp, 83 % of the engaged rows' weight agreeing and
/// 98 % of the moving rows'). An additive play of the other sign (a bias higher while warming
/// on a rising slope) is not what a held temperature makes.
pub fn held_temperature_play(ctx: &Context, term: &Term) -> bool {
    let p = ctx.p;
    let i = ctx.axis;
    let n = p.t.len();
    if n < 2 || term.coef.len() < 2 || !ctx.s.from_sim {
        return false;
    }
    let mean = p.f.iter().map(|f| f[i]).sum::<f64>() / n as f64;
    let var = p.f.iter().map(|f| (f[i] - mean).powi(2)).sum::<f64>() / n as f64;
    if var.sqrt() > ONE_ORIENTATION_SPREAD_G {
        return false;
    }
    let d = &term.columns[0];
    // (weight, agreeing weight) over the engaged rows and over the rows where the play moves.
    let (mut engaged, mut moving) = ((0.0f64, 0.0f64), (0.0f64, 0.0f64));
    for r in 0..n {
        let gain = term.coef[0] + term.coef[1] * (p.temp_s[r] - super::mech::T0_C);
        let both = gain * ctx.s.deriv(p.temp_s[r], &p.f[r]);
        if d[r].abs() >= 0.5 {
            engaged.0 += both.abs();
            engaged.1 += both.max(0.0);
        }
        if r > 0 {
            let step = (d[r] - d[r - 1]).abs();
            moving.0 += step * both.abs();
            moving.1 += step * both.max(0.0);
        }
    }
    let agrees = |(w, a): (f64, f64)| w > 0.0 && a >= HELD_SIGN_SHARE * w;
    agrees(engaged) || agrees(moving)
}

/// The naming threshold of a term of `df` parameters: the likelihood-ratio statistic whose χ²
/// tail is the selection's per-test level `alpha`.
pub fn naming_threshold(alpha: f64, df: usize) -> f64 {
    super::stats::chi2_isf(alpha, df.max(1) as f64)
}

/// For each term of the final model, the separability of every rival ([`super::separate`]),
/// each refitted (θ searched) with the nuisance and the other terms free beside it, to what
/// the term predicts on this recording; ascending by deviance. The rivals are every mechanism
/// whose columns this design holds ([`Context::rival_possible`]: also one the search does not
/// offer because the design makes it another's alias, as a scale-factor tempco in one
/// orientation is a bias tempco), the drift in time, and a second time constant of each other
/// term with one (the term may be only the rest of that one's shape: a second-order lag fitted
/// by first-order terms leaves a remainder that a play or a turn-on term takes).
pub(crate) fn separability_of(ctx: &Context, fit: &AxisFit) -> Vec<(Mech, Vec<(Mech, f64)>)> {
    use super::separate::{Fitted, Refit, predict};
    let mut out = Vec::new();
    let fitted = |t: &Term| Fitted { mech: t.mech, theta: t.theta, coef: t.coef.clone() };
    for (k, term) in fit.terms.iter().enumerate() {
        let a = [fitted(term)];
        let refit = Refit::new(ctx, fit.q, fit.deviance_scale, &predict(ctx, &a), &shared_with(ctx, fit, k));
        let mut rivals = rivals_of(ctx, fit, k, &refit);
        // A turn-on term and a play or temperature form beside it may together be one die lag
        // the model lacks (`Refit::lag_with_rise_free`): both are refitted as that lag at once,
        // the rest of the model free beside it.
        let turn_on = |m: Mech| matches!(m, Mech::Warmup | Mech::SelfHeating);
        let partner = |m: Mech| m.temperature_form() && m != Mech::ThermalLag;
        if !fit.terms.iter().any(|t| t.mech == Mech::ThermalLag) && (turn_on(term.mech) || partner(term.mech)) {
            let pair_lag = fit
                .terms
                .iter()
                .enumerate()
                .filter(|(j, t)| *j != k && if turn_on(term.mech) { partner(t.mech) } else { turn_on(t.mech) })
                .filter_map(|(j, t)| {
                    let eta = predict(ctx, &[fitted(term), fitted(t)]);
                    Refit::new(ctx, fit.q, fit.deviance_scale, &eta, &shared_without(ctx, fit, &[k, j]))
                        .lag_with_rise_free()
                })
                .min_by(f64::total_cmp);
            if let Some(d) = pair_lag {
                match rivals.iter_mut().find(|r| r.0 == Mech::ThermalLag) {
                    Some(r) => r.1 = r.1.min(d),
                    None => rivals.push((Mech::ThermalLag, d)),
                }
                rivals.sort_by(|a, b| a.1.total_cmp(&b.1));
            }
        }
        out.push((term.mech, rivals));
    }
    out
}

/// The columns free beside term `k` of `fit` and its rivals: the nuisance and every other
/// term's columns ([`separability_of`]).
pub(crate) fn shared_with(ctx: &Context, fit: &AxisFit, k: usize) -> Vec<Vec<f64>> {
    shared_without(ctx, fit, &[k])
}

/// The nuisance and the columns of every term of `fit` but those in `left_out`.
fn shared_without(ctx: &Context, fit: &AxisFit, left_out: &[usize]) -> Vec<Vec<f64>> {
    ctx.nuisance
        .iter()
        .cloned()
        .chain(
            fit.terms
                .iter()
                .enumerate()
                .filter(|(j, _)| !left_out.contains(j))
                .flat_map(|(_, t)| t.columns.iter().cloned()),
        )
        .collect()
}

/// Every rival of term `k` of `fit` ([`separability_of`]) refitted to what `refit` holds (the
/// term's prediction, or data), with what `refit` shares: per rival the least whitened residual
/// sum of squares over its forms, in the deviance's unit; ascending.
pub(crate) fn rivals_of(ctx: &Context, fit: &AxisFit, k: usize, refit: &super::separate::Refit) -> Vec<(Mech, f64)> {
    let term = &fit.terms[k];
    let second_copy = |m: Mech| m.theta().is_some() && fit.terms.iter().enumerate().any(|(j, t)| j != k && t.mech == m);
    let mut rivals: Vec<(Mech, f64)> = Mech::ALL
        .iter()
        .chain(Mech::ALTERNATIVES.iter())
        .copied()
        .filter(|&m| m != term.mech && ctx.rival_possible(m))
        .filter(|&m| !fit.terms.iter().any(|t| t.mech == m) || second_copy(m))
        .filter_map(|m| refit.mechanism(m).map(|s| (m, s.deviance)))
        .collect();
    // A warm-up rival also with its fast part, the shape a named warm-up may take
    // ([`fast_warmup`]): what that shape absorbs, a warm-up may be.
    if let Some(r) = rivals.iter_mut().find(|r| r.0 == Mech::Warmup) {
        let grid = ctx.grid(Mech::Warmup);
        for ratio in super::mech::WARMUP_FAST_RATIOS {
            let columns = |tau: f64| ctx.member_columns(Mech::Warmup, tau, Some(ratio));
            if let Some(s) = refit.deviance(&grid, &|tau| ctx.offered(Mech::Warmup, tau), &columns) {
                r.1 = r.1.min(s.deviance);
            }
        }
    }
    if matches!(term.mech, Mech::Warmup | Mech::SelfHeating) {
        let mut add = |m: Mech, d: f64| match rivals.iter_mut().find(|r| r.0 == m) {
            Some(r) => r.1 = r.1.min(d),
            None => rivals.push((m, d)),
        };
        // A turn-on term beside a temperature form may be that form acting through a die
        // that runs warmer than the thermistor after power-on: `∂A/∂T · (1 − e^(−P/τ))`, A
        // the other term's fitted contribution.
        for (j, other) in fit.terms.iter().enumerate() {
            if j == k || !other.mech.temperature_form() {
                continue;
            }
            if let Some(d) = through_self_heating(ctx, refit, other) {
                add(other.mech, d);
            }
        }
        // Or a temperature form the model lacks, acting through a die that self-heats
        // after power-on unseen by the thermistor (a tempco on a soak is a turn-on
        // transient).
        for m in DIE_RISE_FORMS {
            if !fit.terms.iter().any(|t| t.mech == m)
                && let Some(d) = refit.through_die_rise(m)
            {
                add(m, d);
            }
        }
    }
    let mut add = |m: Mech, d: f64| match rivals.iter_mut().find(|r| r.0 == m) {
        Some(r) => r.1 = r.1.min(d),
        None => rivals.push((m, d)),
    };
    // A turn-on term, a play or a temperature form may be a die lag the model lacks, acting
    // on the die's own heating after each power-on as well as on the case's temperature.
    if (term.mech.temperature_form() || matches!(term.mech, Mech::Warmup | Mech::SelfHeating))
        && !fit.terms.iter().any(|t| t.mech == Mech::ThermalLag)
        && let Some(d) = refit.lag_of_die_rise()
    {
        add(Mech::ThermalLag, d);
    }
    // A temperature form may be the die heating after power-on, acting through a
    // sensitivity SIM does not have, `(1 − e^(−P/τ))·(c0 + c1 ΔT + c2 ΔT²)`; or a die
    // running steadily warmer than the thermistor, through SIM's own (`S'(T)`).
    if term.mech.temperature_form() {
        for d in [refit.self_heating_free(), refit.self_heating_settled()].into_iter().flatten() {
            add(Mech::SelfHeating, d);
        }
    }
    // A temperature form or a turn-on term may be a thermal play that never engages: the
    // sensor holds its starting temperature while the thermistor, with the die, moves.
    if (term.mech.temperature_form() || matches!(term.mech, Mech::Warmup | Mech::SelfHeating))
        && !fit.terms.iter().any(|t| t.mech == Mech::ThermalHysteresis)
        && let Some(d) = refit.play_never_engaged()
    {
        add(Mech::ThermalHysteresis, d);
    }
    // A term odd in the specific force may be the die's rise after power-on acting through
    // the scale factor's and cross-sensitivities' tempcos, `(1 − e^(−P/τ))·f_j`; or, long
    // after power-on, the die running steadily warmer than the thermistor through SIM's own
    // slope, which at steady temperatures is a static scale and cross term.
    if ODD_IN_F.contains(&term.mech)
        && let Some(d) = refit.self_heating_of_scale_term()
    {
        add(Mech::SelfHeating, d);
    }
    // A scale-factor or cross-coupling tempco may be, over a soak, the static scale or cross
    // term at the soak's temperature together with the die's rise through the same tempcos:
    // the group holds both.
    if let Some(fixed) = match term.mech {
        Mech::ScaleTemp => Some(Mech::ScaleFactor),
        Mech::CrossCouplingTemp => Some(Mech::CrossAxis),
        _ => None,
    } && let Some(d) = refit.static_scale_with_self_heating()
    {
        add(fixed, d);
        add(Mech::SelfHeating, d);
    }
    // A play may be a tempco SIM lacks acting on a die that lags the thermistor: on one ramp
    // from a hold, the knee where the die starts to trail is a play's engagement. (A lag named
    // is that die lag already, through SIM's sensitivity.)
    if matches!(term.mech, Mech::ThermalHysteresis | Mech::BiasHysteresis) {
        for m in super::separate::TEMPCO_FORMS {
            if let Some(d) = refit.through_die_lag(m) {
                add(m, d);
            }
        }
    }
    // An additive play beside a tempco SIM lacks may be a thermal play acting through that
    // tempco as well as through SIM's sensitivity.
    if term.mech == Mech::BiasHysteresis {
        for (j, other) in fit.terms.iter().enumerate() {
            if j != k
                && let Some(d) = refit.play_through_fitted_tempco(other.mech, &other.coef, &other.contribution)
            {
                add(Mech::ThermalHysteresis, d);
            }
        }
    }
    // Beside a lag, any term may be the rest of a second lag stage.
    for (j, other) in fit.terms.iter().enumerate() {
        if j != k
            && other.mech == Mech::ThermalLag
            && let Some(d) = other.theta.and_then(|tau| refit.second_lag_stage(tau))
        {
            add(Mech::ThermalLag, d);
        }
    }
    // Beside a lag, a turn-on term may be the die's rise the lag misses at each power-on,
    // at another size than the unit's one estimate.
    if matches!(term.mech, Mech::Warmup | Mech::SelfHeating) {
        for (j, other) in fit.terms.iter().enumerate() {
            if j != k
                && other.mech == Mech::ThermalLag
                && let Some(d) = other.theta.and_then(|th| refit.lag_rise_resized(th, &other.coef, &other.contribution))
            {
                add(Mech::ThermalLag, d);
            }
        }
    }
    // Beside a lag or a play, any term may be that lag or play acting on the die's own
    // rise after each power-on, which the thermistor sees only in part.
    for (j, other) in fit.terms.iter().enumerate() {
        if j != k
            && matches!(other.mech, Mech::ThermalLag | Mech::ThermalHysteresis | Mech::BiasHysteresis)
            && let Some(d) = refit.fitted_through_die_rise(other.mech, other.theta, &other.coef, &other.contribution)
        {
            add(other.mech, d);
        }
    }
    // Or the rest of that lag's or play's shape: a gain varying with temperature, or its
    // state restarted at each session instead of carried through the unpowered gaps.
    for (j, other) in fit.terms.iter().enumerate() {
        if j == k || !matches!(other.mech, Mech::ThermalLag | Mech::ThermalHysteresis | Mech::BiasHysteresis) {
            continue;
        }
        for d in [refit.gain_with_temperature(other.mech), refit.other_state_across_sessions(other.mech)]
            .into_iter()
            .flatten()
        {
            add(other.mech, d);
        }
    }
    rivals.sort_by(|x, y| x.1.total_cmp(&y.1));
    rivals
}

/// The temperature forms a turn-on term's rivals build from the die's temperature after
/// power-on ([`super::separate::Refit::through_die_rise`]).
const DIE_RISE_FORMS: [Mech; 5] =
    [Mech::BiasTempOrder, Mech::ScaleTemp, Mech::CrossCouplingTemp, Mech::BiasHysteresis, Mech::ThermalHysteresis];

/// The terms odd in the specific force, which the die's rise after power-on may make through
/// the scale factor's and cross-sensitivities' tempcos, and a die settled warmer than the
/// thermistor through SIM's own slope ([`super::separate::Refit::self_heating_of_scale_term`]).
const ODD_IN_F: [Mech; 5] =
    [Mech::ScaleFactor, Mech::CrossAxis, Mech::NonlinearityK3, Mech::ScaleTemp, Mech::CrossCouplingTemp];

/// The rivals of each term of `fit` that act through the die's rise after power-on, refitted
/// to the recording's residual in the term's place: `(term, rival, D(rival) − D(term))`, the
/// deviance difference on the data with the nuisance and the other terms free (negative: the
/// rival explains more). For a turn-on term (`warmup`, `self_heating`), each temperature form
/// the model lacks built from the die's temperature
/// ([`super::separate::Refit::through_die_rise`]) and each it holds acting through the die's
/// rise (`∂A/∂T · (1 − e^(−P/τ))`, [`through_self_heating`]); for a term odd in the specific
/// force, the rise through the scale factor's and cross-sensitivities' tempcos or the die
/// settled warmer ([`super::separate::Refit::self_heating_of_scale_term`], named
/// `self_heating`). The separability of the term's own prediction holds these rivals to a first-order rise (and a
/// tempco to the thermistor's share of it); the data hold them to nothing but themselves, and
/// a rival that explains them as well is as much the finding as the term. Pairs in `grouped`
/// (already one group by their separability) are not refitted.
fn die_rise_on_data(ctx: &Context, fit: &AxisFit, grouped: &[(Mech, Mech)]) -> Vec<(Mech, Mech, f64)> {
    use super::separate::Refit;
    let y = &ctx.p.r[ctx.axis];
    let mut out = Vec::new();
    for (k, term) in fit.terms.iter().enumerate() {
        let turn_on = matches!(term.mech, Mech::Warmup | Mech::SelfHeating);
        // The rivals still to ask, not grouped with the term already: for a turn-on term each
        // temperature form the model lacks (`None`) and each it holds, acting through the die
        // (`Some(j)`, term `j`'s fitted contribution).
        let forms: Vec<(Mech, Option<usize>)> = if turn_on {
            let lacking =
                DIE_RISE_FORMS.into_iter().filter(|&m| !fit.terms.iter().any(|t| t.mech == m)).map(|m| (m, None));
            let held = fit
                .terms
                .iter()
                .enumerate()
                .filter(|(j, t)| *j != k && t.mech.temperature_form())
                .map(|(j, t)| (t.mech, Some(j)));
            lacking.chain(held).collect()
        } else if ODD_IN_F.contains(&term.mech) {
            vec![(Mech::SelfHeating, None)]
        } else {
            Vec::new()
        };
        let forms: Vec<(Mech, Option<usize>)> =
            forms.into_iter().filter(|&(m, _)| !grouped.contains(&(term.mech, m))).collect();
        if forms.is_empty() {
            continue;
        }
        let refit = Refit::new(ctx, fit.q, fit.deviance_scale, y, &shared_with(ctx, fit, k));
        let Some(own) = refit.deviance(&[], &|_| true, &|_| term.columns.clone()) else { continue };
        let rivals = forms.into_iter().map(|(m, held)| {
            let d = match held {
                Some(j) => through_self_heating(ctx, &refit, &fit.terms[j]),
                None if turn_on => refit.through_die_rise(m),
                None => refit.self_heating_of_scale_term(),
            };
            (m, d)
        });
        for (m, d) in rivals {
            if let Some(d) = d {
                out.push((term.mech, m, d - own.deviance));
            }
        }
    }
    out
}

/// The separability of a turn-on term (what `refit` holds) from the temperature form `other`
/// acting through a self-heated die: the rival column `∂A/∂T · (1 − e^(−P/τ))` (A: `other`'s
/// fitted contribution, its derivative by a difference of 0.1 °C of the smoothed temperature),
/// τ on the turn-on grid.
fn through_self_heating(ctx: &Context, refit: &super::separate::Refit, other: &Term) -> Option<f64> {
    let power = ctx.p.power.as_deref()?;
    let delta = 0.1;
    let shifted: Vec<f64> = ctx.p.temp_s.iter().map(|v| v + delta).collect();
    let cols2 = ctx.columns_at(other.mech, other.theta.unwrap_or(0.0), &shifted);
    let n = ctx.p.t.len();
    let mut slope = vec![0.0; n];
    for (c, b) in cols2.iter().zip(&other.coef) {
        for (s, v) in slope.iter_mut().zip(c) {
            *s += b * v;
        }
    }
    for (s, v) in slope.iter_mut().zip(&other.contribution) {
        *s = (*s - v) / delta;
    }
    let grid = ctx.grid(Mech::Warmup);
    let offered = |th: f64| ctx.offered(Mech::Warmup, th);
    let columns = |tau: f64| vec![(0..n).map(|r| slope[r] * -(-power[r] / tau).exp_m1()).collect()];
    refit.deviance(&grid, &offered, &columns).map(|s| s.deviance)
}

/// For each member of `model`, every mechanism that can replace it (θ re-searched on the grid;
/// a mechanism named elsewhere in the model at another θ of its own) with the deviance change
/// on the data; those below [`AMBIGUOUS_LR`] are ambiguous.
fn ambiguity(bank: &Bank, model: &[usize], grams: &Grams, infl: f64) -> Vec<(Mech, Vec<(Mech, f64)>)> {
    if model.is_empty() {
        return Vec::new();
    }
    let colsidx = |m: &[usize]| bank.cols_of(m);
    let mut ambiguous = Vec::new();
    let sse_full = grams.sse(&colsidx(model));
    for (k, &c) in model.iter().enumerate() {
        let mut alts = Vec::new();
        let rest: Vec<usize> = model.iter().enumerate().filter(|(j, _)| *j != k).map(|(_, c)| *c).collect();
        for m in Mech::ALL {
            // A mechanism already named elsewhere in the model competes through a second θ of
            // its own (the rest of a two-exponential warm-up, a second lag stage): the term may
            // be only the remainder of that one's shape. Its own mechanism does not compete.
            let named_elsewhere = model.iter().enumerate().any(|(j, &mc)| j != k && bank.cands[mc].mech == m);
            if m == bank.cands[c].mech || (named_elsewhere && m.theta().is_none()) {
                continue;
            }
            if !named_elsewhere && model.iter().any(|&mc| bank.cands[mc].mech == m) {
                continue;
            }
            let mut best: Option<f64> = None;
            for (ci, cand) in bank.cands.iter().enumerate() {
                if cand.mech != m || model.contains(&ci) {
                    continue;
                }
                let mut with = rest.clone();
                with.push(ci);
                if let Some(s) = grams.sse(&colsidx(&with))
                    && best.is_none_or(|b| s < b)
                {
                    best = Some(s);
                }
            }
            if let (Some(s_alt), Some(s_full)) = (best, sse_full) {
                let d = grams.n_all as f64 * (s_alt / s_full.max(1e-300)).ln() / infl;
                alts.push((m, d));
            }
        }
        if !alts.is_empty() {
            ambiguous.push((bank.cands[c].mech, alts));
        }
    }
    ambiguous
}

/// A drift in time ([`Mech::Drift`], θ on its grid) in place of each temperature form of
/// `model` (a turn-on term is already a settling, since power-on): added to `amb` where its
/// deviance is within [`AMBIGUOUS_LR`] of the model's (negative: the drift explains more).
/// Direct GLS, only for the few members concerned, so the candidate bank stays as small as the
/// selection needs.
fn drift_alternatives(
    ctx: &Context,
    bank: &Bank,
    model: &[usize],
    q: f64,
    infl: f64,
    amb: &mut Vec<(Mech, Vec<(Mech, f64)>)>,
) -> Vec<(Mech, f64)> {
    let mut beyond = Vec::new();
    if !model.iter().any(|&c| bank.cands[c].mech.temperature_form()) || !ctx.available(Mech::Drift) {
        return beyond;
    }
    let p = ctx.p;
    let (t, r, y) = (&p.t, &p.r_white[ctx.axis], &p.r[ctx.axis]);
    let filt = Filter::new(t, r, q, ctx.gm, |_| true);
    let Some((_, _, sse_full, _)) = gls(&filt, y, &bank.slices_of(model)) else { return beyond };
    let n = filt.n_used as f64;
    let grid = ctx.grid(Mech::Drift);
    // The members' whitened products once per set, only the drift's column per θ.
    let drift_cols: Vec<Vec<Vec<f64>>> = grid.iter().map(|&th| ctx.columns(Mech::Drift, th)).collect();
    let with_drift = |members: &[usize]| {
        let fixed: Vec<Vec<f64>> = bank.slices_of(members).into_iter().map(<[f64]>::to_vec).collect();
        let part = PartialLs::new(&filt, y, &fixed);
        drift_cols.iter().map(|extra| part.sse_plus(&filt, extra)).fold(f64::INFINITY, f64::min)
    };
    let sse_model_drift = with_drift(model);
    for (k, &c) in model.iter().enumerate() {
        let m = bank.cands[c].mech;
        if !m.temperature_form() {
            continue;
        }
        let rest: Vec<usize> = model.iter().enumerate().filter(|(j, _)| *j != k).map(|(_, c)| *c).collect();
        let best = with_drift(&rest);
        if !best.is_finite() {
            continue;
        }
        if sse_model_drift.is_finite() {
            beyond.push((m, n * (best / sse_model_drift.max(1e-300)).ln() / infl));
        }
        let d = n * (best / sse_full.max(1e-300)).ln() / infl;
        if d < AMBIGUOUS_LR {
            match amb.iter_mut().find(|(a, _)| *a == m) {
                Some((_, alts)) => alts.push((Mech::Drift, d)),
                None => amb.push((m, vec![(Mech::Drift, d)])),
            }
        }
    }
    beyond
}

/// Least squares of a whitened `y` on fixed whitened columns plus a few that change (one
/// member's θ searched while the rest of the model stays): the fixed part's products are
/// computed once.
pub(crate) struct PartialLs {
    w: Vec<Vec<f64>>,
    g: Vec<f64>,
    gy: Vec<f64>,
    wy: Vec<f64>,
    yy: f64,
}

impl PartialLs {
    pub(crate) fn new(filt: &Filter, y: &[f64], fixed: &[Vec<f64>]) -> Self {
        let w: Vec<Vec<f64>> = fixed.iter().map(|c| filt.whitened(c)).collect();
        let wy = filt.whitened(y);
        let p = w.len();
        let mut g = vec![0.0; p * p];
        for a in 0..p {
            for b in a..p {
                g[a * p + b] = dot(&w[a], &w[b]);
                g[b * p + a] = g[a * p + b];
            }
        }
        let gy = w.iter().map(|c| dot(c, &wy)).collect();
        let yy = dot(&wy, &wy);
        PartialLs { w, g, gy, wy, yy }
    }

    /// SSE with the raw columns `extra` added (infinite when they are collinear).
    pub(crate) fn sse_plus(&self, filt: &Filter, extra: &[Vec<f64>]) -> f64 {
        match self.solve_plus(filt, extra) {
            Some((x, b, _)) => (self.yy - x.iter().zip(&b).map(|(x, b)| x * b).sum::<f64>()).max(0.0),
            None => f64::INFINITY,
        }
    }

    /// [`PartialLs::sse_plus`] and [`PartialLs::coef_plus`] from one solve, with the extra
    /// columns given already whitened by the filter this was built with (one whitening serves
    /// several fits); `None` when the columns are collinear.
    pub(crate) fn sse_coef_plus_whitened(&self, we: &[Vec<f64>]) -> Option<(f64, Vec<f64>)> {
        let (x, b, d) = self.solve_whitened(we)?;
        let sse = (self.yy - x.iter().zip(&b).map(|(x, b)| x * b).sum::<f64>()).max(0.0);
        Some((sse, x.iter().zip(&d).map(|(x, d)| x / d).collect()))
    }

    /// The generalised-least-squares coefficients of the fixed columns, then of `extra` (`None`
    /// when they are collinear).
    pub(crate) fn coef_plus(&self, filt: &Filter, extra: &[Vec<f64>]) -> Option<Vec<f64>> {
        let (x, _, d) = self.solve_plus(filt, extra)?;
        Some(x.iter().zip(&d).map(|(x, d)| x / d).collect())
    }

    /// The normal equations with `extra` beside the fixed columns, scaled to a unit diagonal,
    /// solved: the scaled solution, right-hand side and the scales.
    fn solve_plus(&self, filt: &Filter, extra: &[Vec<f64>]) -> Option<(Vec<f64>, Vec<f64>, Vec<f64>)> {
        let we: Vec<Vec<f64>> = extra.iter().map(|c| filt.whitened(c)).collect();
        self.solve_whitened(&we)
    }

    /// [`PartialLs::solve_plus`] with the extra columns already whitened.
    fn solve_whitened(&self, we: &[Vec<f64>]) -> Option<(Vec<f64>, Vec<f64>, Vec<f64>)> {
        let (pf, m) = (self.w.len(), self.w.len() + we.len());
        let col = |i: usize| if i < pf { &self.w[i] } else { &we[i - pf] };
        let mut a = vec![0.0; m * m];
        let mut b = vec![0.0; m];
        for u in 0..m {
            b[u] = if u < pf { self.gy[u] } else { dot(col(u), &self.wy) };
            for v in u..m {
                let g = if v < pf { self.g[u * pf + v] } else { dot(col(u), col(v)) };
                a[u * m + v] = g;
                a[v * m + u] = g;
            }
        }
        let d: Vec<f64> = (0..m).map(|u| a[u * m + u].sqrt()).collect();
        if d.iter().any(|v| !(*v > 0.0)) {
            return None;
        }
        for u in 0..m {
            b[u] /= d[u];
            for v in 0..m {
                a[u * m + v] /= d[u] * d[v];
            }
        }
        chol_solve(&a, &b, m, 1e-10).map(|(x, _)| (x, b, d))
    }
}

fn finish(ctx: &Context, bank: &Bank, model: &[usize], q: f64, fold: &[usize], fast: Option<f64>) -> AxisFit {
    let p = ctx.p;
    let axis = ctx.axis;
    let (t, r, y) = (&p.t, &p.r_white[axis], &p.r[axis]);
    let n = y.len();
    let filt = Filter::new(t, r, q, ctx.gm, |_| true);
    let used: Vec<bool> = filt.step.iter().map(|s| *s == Step::Update).collect();
    let nu = filt.n_used as f64;
    // Members with their θ; refine θ by golden section in log θ, coordinate-wise, twice.
    let mut members: Vec<(Mech, Option<f64>)> =
        model.iter().map(|&c| (bank.cands[c].mech, bank.cands[c].theta)).collect();
    let cols_of = |ms: &[(Mech, Option<f64>)]| -> Vec<Vec<f64>> {
        ctx.nuisance
            .iter()
            .cloned()
            .chain(ms.iter().flat_map(|(m, th)| ctx.member_columns(*m, th.unwrap_or(0.0), fast)))
            .collect()
    };
    let sse_of = |ms: &[(Mech, Option<f64>)]| -> f64 {
        let cols = cols_of(ms);
        let refs: Vec<&[f64]> = cols.iter().map(|c| c.as_slice()).collect();
        gls(&filt, y, &refs).map_or(f64::INFINITY, |g| g.2)
    };
    // One pass suffices with one θ; with several, a second lets each adjust to the others.
    let passes = if members.iter().filter(|m| m.1.is_some()).count() > 1 { 2 } else { 1 };
    for _ in 0..passes {
        for k in 0..members.len() {
            let (m, Some(th0)) = members[k] else { continue };
            let grid = ctx.grid(m);
            let step = if grid.len() > 1 { (grid[1] / grid[0]).ln() } else { 0.3 };
            let mut rest = members.clone();
            rest.remove(k);
            let part = PartialLs::new(&filt, y, &cols_of(&rest));
            // Refined only where the mechanism is offered (a turn-on τ whose signature lives
            // in one held-out fold is not: see `Context::offered`).
            let eval = |lt: f64| {
                if ctx.offered(m, lt.exp()) {
                    part.sse_plus(&filt, &ctx.member_columns(m, lt.exp(), fast))
                } else {
                    f64::INFINITY
                }
            };
            // A warm-up given its fast part moves further: the one exponential the search
            // fitted to two lies between their time constants, below the slow one.
            let reach = if m == Mech::Warmup && fast.is_some() { 2.0 * step } else { step };
            let (best, _) = super::stats::golden_min(th0.ln() - reach, th0.ln() + reach, 16, eval);
            if eval(best) <= eval(th0.ln()) {
                members[k].1 = Some(best.exp());
            }
        }
    }
    let cols = cols_of(&members);
    let refs: Vec<&[f64]> = cols.iter().map(|c| c.as_slice()).collect();
    let (beta, se_unit, sse, res) = gls(&filt, y, &refs).unwrap_or_else(|| {
        let wy = filt.whitened(y);
        (vec![0.0; refs.len()], vec![0.0; refs.len()], dot(&wy, &wy), wy)
    });
    let infl = inflation(&res, &used);
    let sigma2 = sse / (nu - beta.len() as f64).max(1.0);
    let deviance_scale = sse / nu.max(1.0) * infl;
    let mut terms = Vec::new();
    let mut off = ctx.nuisance.len();
    // The nuisance (SIM's own terms re-fitted) is part of the prediction, never a term.
    let mut prediction = vec![0.0; n];
    for (c, b) in cols[..off].iter().zip(&beta) {
        for (o, v) in prediction.iter_mut().zip(c) {
            *o += b * v;
        }
    }
    for (k, (m, th)) in members.iter().enumerate() {
        let nc = ctx.member_columns(*m, th.unwrap_or(0.0), fast).len();
        let coef = beta[off..off + nc].to_vec();
        let se: Vec<f64> = se_unit[off..off + nc].iter().map(|s| s * (sigma2 * infl).sqrt()).collect();
        let tcols: Vec<Vec<f64>> = cols[off..off + nc].to_vec();
        let mut contribution = vec![0.0; n];
        for (c, b) in tcols.iter().zip(&coef) {
            for (o, v) in contribution.iter_mut().zip(c) {
                *o += b * v;
            }
        }
        for (o, v) in prediction.iter_mut().zip(&contribution) {
            *o += v;
        }
        let mut rest = members.clone();
        rest.remove(k);
        let sse_rest = sse_of(&rest);
        let lr_drop = nu * (sse_rest / sse.max(1e-300)).ln() / infl;
        let df = nc + usize::from(th.is_some());
        let p_drop = chi2_sf(lr_drop, df as f64);
        // Profile interval of θ: where the deviance rises by 3.84·inflation.
        let theta_ci = th.map(|th| {
            let grid = ctx.grid(*m);
            let (gmin, gmax) = (grid.first().copied().unwrap_or(th) / 10.0, grid.last().copied().unwrap_or(th) * 10.0);
            let mut others = members.clone();
            others.remove(k);
            let part = PartialLs::new(&filt, y, &cols_of(&others));
            let dev =
                |x: f64| nu * (part.sse_plus(&filt, &ctx.member_columns(*m, x, fast)) / sse.max(1e-300)).ln() / infl;
            let bound = |dir: f64| {
                let mut inside = th;
                let mut x = th;
                loop {
                    let nx = if dir > 0.0 { x * 1.25 } else { x / 1.25 };
                    if nx < gmin || nx > gmax {
                        return nx.clamp(gmin, gmax);
                    }
                    if dev(nx) > 3.84 {
                        let (mut lo, mut hi) = (inside.ln(), nx.ln());
                        for _ in 0..8 {
                            let mid = 0.5 * (lo + hi);
                            if dev(mid.exp()) > 3.84 {
                                hi = mid;
                            } else {
                                lo = mid;
                            }
                        }
                        return (0.5 * (lo + hi)).exp();
                    }
                    inside = nx;
                    x = nx;
                }
            };
            (bound(-1.0), bound(1.0))
        });
        let fast_ratio = fast.filter(|_| *m == Mech::Warmup && nc > 1);
        terms.push(Term {
            mech: *m,
            theta: *th,
            theta_ci,
            coef,
            se,
            lr_drop,
            p_drop,
            contribution,
            columns: tcols,
            fast_ratio,
        });
        off += nc;
    }
    // Honest figures: the raw residual with one constant offset removed, before and after
    // the model; held-out rows use coefficients and offset fitted without their fold. The
    // drift (the random-walk level of what the model leaves) is its own figure, never
    // subtracted.
    let blocks = (!ctx.p.weight.is_empty()).then(|| (ctx.p.weight.as_slice(), ctx.p.within[axis].as_slice()));
    // "Before" removes one offset per session (the level restarts at each), nothing else.
    let sessions = ctx.p.sessions();
    let y_c = session_centred(y, &sessions, blocks.map(|b| b.0));
    if members.is_empty() {
        prediction = y.iter().zip(&y_c).map(|(a, b)| a - b).collect();
    }
    let e: Vec<f64> = y.iter().zip(&prediction).map(|(a, b)| a - b).collect();
    let drift = smooth_level(t, r, q, &e);
    let before = centred_rms_rows(&y_c, blocks);
    let after = centred_rms_rows(&e, blocks);
    // The drift is slow: its RMS over the rows is its blocks' weighted RMS.
    let drift_rms = match blocks {
        Some((w, _)) => centred_rms_rows(&drift, Some((w, &vec![0.0; w.len()]))),
        None => centred_rms(&drift, None),
    };
    let session_cols = ctx.p.session_columns();
    let session_refs: Vec<&[f64]> = session_cols.iter().map(Vec::as_slice).collect();
    let hb = raw_heldout(t, r, (q, ctx.gm), y, &session_refs, fold, blocks);
    // With nothing named the model is SIM itself: its own terms re-fitted alone are not a
    // finding, and "after" is "before".
    let ha = if members.is_empty() {
        raw_heldout(t, r, (q, ctx.gm), y, &session_refs, fold, blocks)
    } else {
        raw_heldout(t, r, (q, ctx.gm), y, &refs, fold, blocks)
    };
    // Each term's cut of the raw held-out RMS: the model without it (the others as fitted),
    // or the offset alone ("before") where that predicts better. SIM's own terms re-fitted
    // without the term can predict the held-out folds worse than the offset alone (a cubic in
    // T extrapolated into a fold); a cut measured from there would credit the term with
    // undoing that, and print a cut larger than the "before → after" beside it.
    let mut heldout_gain = Vec::new();
    let mut off = ctx.nuisance.len();
    for (m, th) in &members {
        let nc = ctx.member_columns(*m, th.unwrap_or(0.0), fast).len();
        let without: Vec<&[f64]> = refs[..off].iter().chain(&refs[off + nc..]).copied().collect();
        let hw = raw_heldout(t, r, (q, ctx.gm), y, &without, fold, blocks);
        heldout_gain.push(ha.gain_over(if hb.rms() < hw.rms() { &hb } else { &hw }));
        off += nc;
    }
    AxisFit {
        axis,
        q,
        gm: ctx.gm,
        inflation: infl,
        terms,
        ambiguous: Vec::new(),
        separability: Vec::new(),
        deviance_scale,
        n_used: filt.n_used,
        trace: Vec::new(),
        passes_alone: Vec::new(),
        drift,
        drift_rms,
        prediction,
        rms: (before, after),
        heldout_rms: (hb.rms(), ha.rms()),
        heldout_resid: (hb.resid, ha.resid),
        heldout_gain,
        lag_rise_c: ctx.lag_rise_c,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::mech::max_fold_share;

    /// A pseudo-random white sequence (xorshift), unit variance about.
    fn white(n: usize, seed: u64) -> Vec<f64> {
        let mut s = seed | 1;
        (0..n)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                ((s >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 12f64.sqrt()
            })
            .collect()
    }

    #[test]
    fn a_column_the_other_folds_do_not_hold_takes_no_part_in_a_folds_prediction() {
        // 3 h at 1 Hz; a turn-on of τ = 1 s lives in the first seconds (fold 0 only) and is
        // ~1e-160 elsewhere: fitted from the other folds its coefficient would be noise over
        // nothing (it was 1e135 mg on a 3-hour recording).
        let n = 10_800;
        let t: Vec<f64> = (0..n).map(|i| i as f64).collect();
        let y: Vec<f64> = white(n, 7).iter().map(|v| 1e-5 * v).collect();
        let r = vec![1e-10; n];
        let spike: Vec<f64> = t.iter().map(|p| (-p / 1.0).exp()).collect();
        let fold = folds_of(n);
        let with = raw_heldout(&t, &r, (0.0, None), &y, &[&spike], &fold, None);
        let without = raw_heldout(&t, &r, (0.0, None), &y, &[], &fold, None);
        assert!(with.resid.iter().all(|v| v.is_finite()));
        assert!((with.rms() - without.rms()).abs() < 1e-3 * without.rms(), "{} vs {}", with.rms(), without.rms());
    }

    #[test]
    fn a_column_constant_on_the_other_folds_takes_no_part_in_a_folds_prediction() {
        // 3 h at 1 Hz under a random walk, a bias tempco on a one-way exponential ramp; a
        // play (columns d, d·ΔT) engaging over the first 100 s and engaged after: d moves in
        // fold 0 only and is 1 on every other fold, where the level is already free. Fitted
        // from them its coefficient is not determined: with it, fold 0's held-out RMS came out
        // 1.4 % above the slope's alone here (at q = 1e-10), and at 10³ g on the one-way ramp
        // of the trust tests (tests/diagnose_trust.rs).
        let n = 10_800;
        let t: Vec<f64> = (0..n).map(|i| i as f64).collect();
        let dt_c: Vec<f64> = t.iter().map(|p| 10.0 * (1.0 - (-p / 6830.0).exp())).collect();
        let y: Vec<f64> = white(n, 11).iter().zip(&dt_c).map(|(v, d)| 1e-4 * v + 2e-5 * d).collect();
        let r = vec![1e-8; n];
        let play: Vec<f64> = t.iter().map(|p| (p / 100.0).min(1.0)).collect();
        let play_dt: Vec<f64> = play.iter().zip(&dt_c).map(|(a, b)| a * b).collect();
        let fold = folds_of(n);
        for q in [0.0, 1e-14, 1e-12, 1e-10] {
            let with = raw_heldout(&t, &r, (q, None), &y, &[&play, &play_dt], &fold, None);
            let slope = raw_heldout(&t, &r, (q, None), &y, &[&play_dt], &fold, None);
            assert!(with.resid.iter().all(|v| v.is_finite()));
            let fold0 = |h: &RawHeldout| (h.fold_ss[0].0 / h.fold_ss[0].1 as f64).sqrt();
            assert!(
                (fold0(&with) - fold0(&slope)).abs() < 1e-3 * fold0(&slope),
                "q {q}: {} vs {}",
                fold0(&with),
                fold0(&slope)
            );
        }
    }

    #[test]
    fn a_turn_on_signature_in_one_fold_is_told_from_one_spread_over_the_folds() {
        let n = 10_800;
        let fold = folds_of(n);
        let power_s: Vec<f64> = (0..n).map(|i| i as f64).collect();
        let share = |tau: f64| max_fold_share(power_s.iter().map(|p| (-p / tau).exp()), &fold);
        // A block is 270 s: τ = 1 s lives in block 0; τ = 600 s spreads over the first blocks
        // of every fold.
        assert!(share(1.0) > 0.999, "{}", share(1.0));
        assert!(share(600.0) < 0.8, "{}", share(600.0));
        assert_eq!(max_fold_share(std::iter::repeat_n(1.0, n), &fold), 1.0);
    }
}
