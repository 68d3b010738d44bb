//! Bias steps: a jump of the residual's level at one time (stress release in the package, a
//! connector or mount shifting), located in time with its size and standard error.
//!
//! This module owns the step mechanism: the innovation-outlier test against the diagnosis's
//! noise model (the local-level model of [`super::noise`]: white noise plus a random walk), the
//! search for several steps, their joint fit with the selected mechanisms and the threshold.
//!
//! **The test.** Under the local-level model a step of size `s` at row `k` enters the
//! standardised one-step-ahead innovations as a decaying pulse: `s·c_{k,j}` at rows `j ≥ k`,
//! `c_{k,j} = F_j^{−½}·Π_{i=k}^{j−1}(1 − K_i)` (`F` the innovation variance, `K` the Kalman
//! gain): the filter's level catches up with the new level at the rate of the gain. The
//! generalised-least-squares statistic of a Heaviside column at row `k`, given the rest of the
//! model, is the matched filter `z_k = Σ_j c_{k,j} w_j / √(Σ_j c_{k,j}²)` of the model's
//! standardised innovations `w`; one backward pass gives it at every row
//! (`N_k = F_k^{−½} w_k + (1 − K_k) N_{k+1}`, the same for the denominator). Slow structure the
//! model does not explain (a thermal term it lacks, drift) is followed by the filter's level and
//! moves `z` by little, and only over long stretches; `z` is standardised by its own robust
//! spread (1.4826 × the median absolute deviation over the rows), so a residual whose slow
//! structure widens every `z` does not make steps of it. A step is accepted when `|z|` exceeds
//! the two-sided normal quantile of `α / (rows × accelerometers)`: the rows tested are corrected
//! for ([`threshold`]).
//!
//! **Several steps.** The largest `|z|` is accepted first; its Heaviside column joins the model,
//! the random walk is re-estimated with it in (a step that is not modelled inflates the random
//! walk) and the scan repeats, up to [`MAX_STEPS`], no two steps closer than [`MIN_GAP_ROWS`]
//! rows (a one-row spike is not two steps). Then every step is tested again with all the others
//! in the model (the same test); the weakest failing one is dropped until all pass.
//!
//! **Never absorbed.** The located steps are Heaviside columns fitted jointly with the selected
//! mechanisms (the pipeline in [`super::diagnose_with`] passes them to the selection as columns
//! every model carries, then fits their sizes with the final model: [`fit_sizes`]), so neither
//! the random walk nor a thermal term takes a step's share.

use super::noise::{Filter, Gm, Step, estimate_q};
use super::stats::{chi2_sf, chol_solve, dot, median};

/// At most this many steps per accelerometer.
pub const MAX_STEPS: usize = 8;
/// Two steps are at least this many rows apart, and this many rows from either end.
pub const MIN_GAP_ROWS: usize = 10;
/// Rows either side of a step in its local test ([`level_shift_t`]).
pub const LOCAL_ROWS: usize = 60;

/// One located bias step.
#[derive(Clone, Debug, PartialEq)]
pub struct BiasStep {
    /// Row of the first sample at the new level.
    pub row: usize,
    /// Its time \[s\].
    pub time_s: f64,
    /// Size (new level − old level) \[g\], fitted jointly with the model.
    pub size_g: f64,
    /// Its standard error \[g\] (noise model, inflated for the remaining autocorrelation).
    pub se_g: f64,
    /// The robustly standardised scan statistic at the step with the other steps in the model.
    pub z: f64,
}

/// The `|z|` a step must exceed: the two-sided normal quantile of `alpha / (rows × axes)`.
pub fn threshold(alpha: f64, rows: usize, axes: usize) -> f64 {
    let a = alpha / (rows.max(1) * axes.max(1)) as f64;
    let (mut lo, mut hi) = (0.0f64, 40.0f64);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if chi2_sf(mid * mid, 1.0) > a {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi
}

/// The Heaviside column of a step at `row`: 0 before it, 1 from it on.
pub fn heaviside(n: usize, row: usize) -> Vec<f64> {
    (0..n).map(|i| if i >= row { 1.0 } else { 0.0 }).collect()
}

/// The matched-filter statistic of a step at every row (module docs) from the standardised
/// innovations `w` of the model's residual under the filter `f`: the GLS `t` of a Heaviside
/// column given the model, in units of the innovations' standard deviation. 0 where no step
/// can be tested (the first observed row: a step there is the offset).
pub fn scan(f: &Filter, w: &[f64]) -> Vec<f64> {
    let n = w.len().min(f.step.len());
    let mut z = vec![0.0; n];
    let (mut num, mut den) = (0.0, 0.0);
    for k in (0..n).rev() {
        match f.step[k] {
            Step::Update => {
                let (g, s) = (1.0 - f.gain[k], f.inv_sqrt_f[k]);
                num = s * w[k] + g * num;
                den = s * s + g * g * den;
                z[k] = if den > 0.0 { num / den.sqrt() } else { 0.0 };
            }
            Step::Init => (num, den) = (0.0, 0.0),
            Step::Skip => {}
        }
    }
    z
}

/// The robust spread of `z` over the updated rows: 1.4826 × the median absolute deviation.
fn robust_scale(f: &Filter, z: &[f64]) -> f64 {
    let v: Vec<f64> = z.iter().zip(&f.step).filter(|(_, s)| **s == Step::Update).map(|(z, _)| *z).collect();
    if v.is_empty() {
        return 1.0;
    }
    let m = median(&v);
    let dev: Vec<f64> = v.iter().map(|x| (x - m).abs()).collect();
    let s = 1.4826 * median(&dev);
    if s > 0.0 && s.is_finite() { s } else { 1.0 }
}

/// Generalised least squares of `y` on `cols` under the filter `f`: coefficients, their
/// standard errors per unit innovation variance, and the standardised innovations of the
/// residual. Columns collinear with earlier ones get a zero coefficient and standard error.
fn gls(f: &Filter, y: &[f64], cols: &[&[f64]]) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let wy = f.whitened(y);
    let wx: Vec<Vec<f64>> = cols.iter().map(|c| f.whitened(c)).collect();
    let norms: Vec<f64> = wx.iter().map(|c| dot(c, c).sqrt()).collect();
    // Greedy: keep a column when it is not collinear with those kept.
    let mut keep: Vec<usize> = Vec::new();
    let mut sol: (Vec<f64>, Vec<f64>) = (Vec::new(), Vec::new());
    for j in 0..wx.len() {
        if !(norms[j] > 0.0) {
            continue;
        }
        let mut trial = keep.clone();
        trial.push(j);
        let m = trial.len();
        let mut a = vec![0.0; m * m];
        let mut b = vec![0.0; m];
        for (u, &cu) in trial.iter().enumerate() {
            b[u] = dot(&wx[cu], &wy) / norms[cu];
            for (v, &cv) in trial.iter().enumerate() {
                a[u * m + v] = dot(&wx[cu], &wx[cv]) / (norms[cu] * norms[cv]);
            }
        }
        if let Some(s) = chol_solve(&a, &b, m, 1e-10) {
            keep = trial;
            sol = s;
        }
    }
    let mut beta = vec![0.0; cols.len()];
    let mut se = vec![0.0; cols.len()];
    let mut res = wy;
    for (u, &c) in keep.iter().enumerate() {
        beta[c] = sol.0[u] / norms[c];
        se[c] = sol.1[u].sqrt() / norms[c];
        for (r, v) in res.iter_mut().zip(&wx[c]) {
            *r -= beta[c] * v;
        }
    }
    (beta, se, res)
}

/// The scan with the model `cols` and the steps at `rows` in: the filter at random-walk
/// intensity `q` (estimated with everything in when `None`), the robustly standardised `z`, and
/// the raw residual of that fit (what the model and those steps leave).
fn scan_with(t: &[f64], r: &[f64], y: &[f64], cols: &[&[f64]], rows: &[usize], q: Option<f64>) -> (Vec<f64>, Vec<f64>) {
    let hs: Vec<Vec<f64>> = rows.iter().map(|&k| heaviside(y.len(), k)).collect();
    let all: Vec<&[f64]> = cols.iter().copied().chain(hs.iter().map(Vec::as_slice)).collect();
    let q = q.unwrap_or_else(|| estimate_q(t, r, None, y, &all));
    let f = Filter::new(t, r, q, None, |_| true);
    let (beta, _, w) = gls(&f, y, &all);
    let z = scan(&f, &w);
    let s = robust_scale(&f, &z);
    let mut e = y.to_vec();
    for (c, b) in all.iter().zip(&beta) {
        for (v, x) in e.iter_mut().zip(c.iter()) {
            *v -= b * x;
        }
    }
    (z.into_iter().map(|v| v / s).collect(), e)
}

/// The level shift at `row` against a change of slope there: least squares of `e` over the
/// rows `lo..hi` on `1, u, H, u·H` (`u = t − t_row`, `H` the step), the shift's `t` statistic
/// with the variance of the local fit's residual. A turn of a ramp or the start of a slow
/// transient is a change of slope and leaves the shift near 0; a step is a shift.
pub fn level_shift_t(t: &[f64], e: &[f64], row: usize, lo: usize, hi: usize) -> f64 {
    if hi < lo + 8 || row <= lo || row >= hi {
        return 0.0;
    }
    let x = |i: usize| {
        let (u, h) = (t[i] - t[row], if i >= row { 1.0 } else { 0.0 });
        [1.0, u, h, u * h]
    };
    let (mut a, mut b, mut yy) = ([0.0; 16], [0.0; 4], 0.0);
    for i in lo..hi {
        let xi = x(i);
        for u in 0..4 {
            b[u] += xi[u] * e[i];
            for v in 0..4 {
                a[u * 4 + v] += xi[u] * xi[v];
            }
        }
        yy += e[i] * e[i];
    }
    let d: Vec<f64> = (0..4).map(|u| a[u * 4 + u].sqrt()).collect();
    if d.iter().any(|v| !(*v > 0.0)) {
        return 0.0;
    }
    let an: Vec<f64> = (0..16).map(|k| a[k] / (d[k / 4] * d[k % 4])).collect();
    let bn: Vec<f64> = (0..4).map(|u| b[u] / d[u]).collect();
    let Some((sol, diag)) = chol_solve(&an, &bn, 4, 1e-12) else { return 0.0 };
    let sse = (yy - sol.iter().zip(&bn).map(|(s, b)| s * b).sum::<f64>()).max(0.0);
    let sigma2 = sse / (hi - lo - 4) as f64;
    let se = (sigma2 * diag[2]).sqrt() / d[2];
    if se > 0.0 { sol[2] / d[2] / se } else { 0.0 }
}

/// The window of the local test of a step at `row`: [`LOCAL_ROWS`] rows either side, cut at
/// the neighbouring steps `others` and the ends of the record.
fn window(row: usize, others: &[usize], n: usize) -> (usize, usize) {
    let lo = others.iter().copied().filter(|&s| s < row).max().unwrap_or(0).max(row.saturating_sub(LOCAL_ROWS));
    let hi = others.iter().copied().filter(|&s| s > row).min().unwrap_or(n).min(row + LOCAL_ROWS);
    (lo, hi)
}

/// Locates the bias steps of `y` (times `t`, white variances `r`) against the noise model with
/// the columns `cols` fitted jointly (module docs): rows of the accepted steps, in time order,
/// with their scan statistics. `q`: the random-walk intensity [g²/s], or `None` to estimate it
/// (maximum likelihood) with the model and the steps found so far in. `alpha` over `axes`
/// accelerometers: the scan's threshold is [`threshold`] over the rows, the local test's over
/// the [`MAX_STEPS`] candidates an accelerometer can have.
pub fn locate(
    t: &[f64],
    r: &[f64],
    y: &[f64],
    cols: &[&[f64]],
    q: Option<f64>,
    alpha: f64,
    axes: usize,
) -> Vec<(usize, f64)> {
    let n = y.len();
    if n < 3 * MIN_GAP_ROWS {
        return Vec::new();
    }
    let (z_min, t_min) = (threshold(alpha, n, axes), threshold(alpha, MAX_STEPS, axes));
    let mut rows: Vec<usize> = Vec::new();
    let mut rejected: Vec<usize> = Vec::new();
    for _ in 0..2 * MAX_STEPS {
        if rows.len() == MAX_STEPS {
            break;
        }
        let (z, e) = scan_with(t, r, y, cols, &rows, q);
        let free = |k: usize| rows.iter().chain(&rejected).all(|&s| s.abs_diff(k) >= MIN_GAP_ROWS);
        let best =
            (MIN_GAP_ROWS..n - MIN_GAP_ROWS).filter(|&k| free(k)).max_by(|&a, &b| z[a].abs().total_cmp(&z[b].abs()));
        match best {
            Some(k) if z[k].abs() > z_min => {
                let (lo, hi) = window(k, &rows, n);
                if level_shift_t(t, &e, k, lo, hi).abs() > t_min {
                    rows.push(k);
                } else {
                    rejected.push(k);
                }
            }
            _ => break,
        }
    }
    // Every step again with all the others in: drop the weakest failing one until all pass.
    loop {
        let stats: Vec<(f64, f64)> = (0..rows.len())
            .map(|j| {
                let others: Vec<usize> = rows.iter().enumerate().filter(|(i, _)| *i != j).map(|(_, k)| *k).collect();
                let (z, e) = scan_with(t, r, y, cols, &others, q);
                let (lo, hi) = window(rows[j], &others, n);
                (z[rows[j]], level_shift_t(t, &e, rows[j], lo, hi))
            })
            .collect();
        let fails = |j: usize| stats[j].0.abs() <= z_min || stats[j].1.abs() <= t_min;
        let weakest =
            (0..rows.len()).filter(|&j| fails(j)).min_by(|&a, &b| stats[a].0.abs().total_cmp(&stats[b].0.abs()));
        match weakest {
            Some(j) => {
                rows.remove(j);
            }
            None => {
                let mut out: Vec<(usize, f64)> = rows.into_iter().zip(stats.into_iter().map(|s| s.0)).collect();
                out.sort_by_key(|s| s.0);
                return out;
            }
        }
    }
}

/// Sizes and standard errors of the steps at `found` (rows with their statistics), fitted
/// jointly with the model columns `cols` under the selection's noise model (random-walk
/// intensity `q`, the bias instability `gm` where known): GLS, the standard errors scaled by the residual's variance per degree of
/// freedom and its autocorrelation inflation.
pub fn fit_sizes(
    t: &[f64],
    r: &[f64],
    y: &[f64],
    cols: &[&[f64]],
    (q, gm): (f64, Option<Gm>),
    found: &[(usize, f64)],
) -> Vec<BiasStep> {
    if found.is_empty() {
        return Vec::new();
    }
    let hs: Vec<Vec<f64>> = found.iter().map(|&(k, _)| heaviside(y.len(), k)).collect();
    let all: Vec<&[f64]> = cols.iter().copied().chain(hs.iter().map(Vec::as_slice)).collect();
    let f = Filter::new(t, r, q, gm, |_| true);
    let (beta, se, w) = gls(&f, y, &all);
    let dof = (f.n_used as f64 - all.len() as f64).max(1.0);
    let used: Vec<bool> = f.step.iter().map(|s| *s == Step::Update).collect();
    let sigma2 = dot(&w, &w) / dof * super::fit::inflation(&w, &used);
    let off = cols.len();
    found
        .iter()
        .enumerate()
        .map(|(j, &(row, z))| BiasStep {
            row,
            time_s: t[row],
            size_g: beta[off + j],
            se_g: se[off + j] * sigma2.sqrt(),
            z,
        })
        .collect()
}

/// Temperature turns taken as reversals by [`at_reversals`]: the temperature moves at least this
/// far [°C] away from an extreme on both sides of it.
pub const REVERSAL_C: f64 = 0.5;
/// A step within this long \[s\] of a reversal is at it ([`at_reversals`]).
pub const REVERSAL_WINDOW_S: f64 = 300.0;

/// The temperature's reversals, `(time [s], a maximum)`: the extremes of the smoothed
/// temperature `temp` between which it moves by at least [`REVERSAL_C`] (a zigzag: an extreme is
/// confirmed once the temperature has come [`REVERSAL_C`] back from it).
pub fn reversals(t: &[f64], temp: &[f64]) -> Vec<(f64, bool)> {
    let mut out = Vec::new();
    let Some(&first) = temp.first() else { return out };
    // Direction not yet known (0), rising (1) or falling (−1); the extreme of the current leg.
    let (mut dir, mut ext, mut ext_t, mut lo, mut hi) = (0i8, first, t[0], (first, t[0]), (first, t[0]));
    for (&ti, &x) in t.iter().zip(temp) {
        match dir {
            0 => {
                if x < lo.0 {
                    lo = (x, ti);
                }
                if x > hi.0 {
                    hi = (x, ti);
                }
                if x - lo.0 >= REVERSAL_C {
                    (dir, ext, ext_t) = (1, x, ti);
                } else if hi.0 - x >= REVERSAL_C {
                    (dir, ext, ext_t) = (-1, x, ti);
                }
            }
            1 if x > ext => (ext, ext_t) = (x, ti),
            1 if ext - x >= REVERSAL_C => {
                out.push((ext_t, true));
                (dir, ext, ext_t) = (-1, x, ti);
            }
            -1 if x < ext => (ext, ext_t) = (x, ti),
            -1 if x - ext >= REVERSAL_C => {
                out.push((ext_t, false));
                (dir, ext, ext_t) = (1, x, ti);
            }
            _ => {}
        }
    }
    out
}

/// Whether the steps located on one accelerometer (time \[s\], size) look like a heating/cooling
/// difference rather than steps: at least three, each within [`REVERSAL_WINDOW_S`] of a
/// temperature reversal ([`reversals`]), at maxima and at minima both, those at maxima of one
/// sign and those at minima of the other. A bias play narrower than the thermometer resolves
/// switches within a sample at each reversal, and the step search takes it as steps
/// (docs/diagnosis.md, "Limits"); the report says so in a note.
pub fn at_reversals(steps: &[(f64, f64)], turns: &[(f64, bool)]) -> bool {
    if steps.len() < 3 {
        return false;
    }
    // The kind of reversal each step is at (the nearest within the window); none if one is at
    // no reversal.
    let kinds: Option<Vec<bool>> = steps
        .iter()
        .map(|(ts, _)| {
            turns
                .iter()
                .filter(|(tr, _)| (ts - tr).abs() <= REVERSAL_WINDOW_S)
                .min_by(|a, b| (ts - a.0).abs().total_cmp(&(ts - b.0).abs()))
                .map(|&(_, max)| max)
        })
        .collect();
    let Some(kinds) = kinds else { return false };
    // The sign every step at a maximum has; those at a minimum have the other.
    let Some(up) = steps.iter().zip(&kinds).find(|(_, max)| **max).map(|(s, _)| s.1 > 0.0) else {
        return false;
    };
    kinds.contains(&false) && steps.iter().zip(&kinds).all(|(s, &max)| (s.1 > 0.0) == (up == max))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reversals_are_the_extremes_between_moves_of_half_a_degree() {
        // Up 2 °C, down 3 °C, up 1 °C, with a 0.2 °C wiggle on the way down (not a reversal).
        let t: Vec<f64> = (0..700).map(|k| k as f64).collect();
        let temp: Vec<f64> = t
            .iter()
            .map(|&x| {
                if x <= 200.0 {
                    20.0 + 0.01 * x
                } else if x <= 500.0 {
                    let w = if (300.0..=320.0).contains(&x) { 0.01 * (x - 300.0) } else { 0.0 };
                    22.0 - 0.01 * (x - 200.0) + w
                } else {
                    19.0 + 0.005 * (x - 500.0)
                }
            })
            .collect();
        assert_eq!(reversals(&t, &temp), vec![(200.0, true), (500.0, false)]);
        // Steps of one sign at the maxima and the other at the minima are a heating/cooling
        // difference (one reversal may lack its step); of one sign throughout, at one kind of
        // reversal only, fewer than three, or one far from any reversal, they are not.
        let turns = [(200.0, true), (500.0, false), (900.0, true), (1200.0, false)];
        assert!(at_reversals(&[(230.0, -1.0), (520.0, 1.0), (1230.0, 1.0)], &turns));
        assert!(!at_reversals(&[(230.0, -1.0), (520.0, -1.0), (1230.0, -1.0)], &turns));
        assert!(!at_reversals(&[(230.0, -1.0), (920.0, -1.0), (210.0, -1.0)], &turns));
        assert!(!at_reversals(&[(230.0, -1.0), (520.0, 1.0)], &turns));
        assert!(!at_reversals(&[(230.0, -1.0), (520.0, 1.0), (3000.0, -1.0)], &turns));
    }

    #[test]
    fn the_scan_is_the_gls_t_of_a_heaviside_column() {
        // On a short series with irregular white variances and a random walk: the backward
        // recursion equals the whitened Heaviside column's normalised product, row by row.
        let n = 200;
        let t: Vec<f64> = (0..n).map(|i| i as f64 * 0.5).collect();
        let r: Vec<f64> = (0..n).map(|i| 1e-6 * (1.0 + 0.3 * ((i * 7) % 5) as f64)).collect();
        let y: Vec<f64> = (0..n).map(|i| 1e-3 * (((i * 7919) % 31) as f64 / 31.0 - 0.5)).collect();
        let f = Filter::new(&t, &r, 1e-8, None, |_| true);
        let w = f.whitened(&y);
        let z = scan(&f, &w);
        for k in [1, 17, 100, 199] {
            let h = f.whitened(&heaviside(n, k));
            let direct = dot(&h, &w) / dot(&h, &h).sqrt();
            assert!((z[k] - direct).abs() < 1e-9 * (1.0 + direct.abs()), "row {k}: {} vs {direct}", z[k]);
        }
        assert_eq!(z[0], 0.0);
    }

    #[test]
    fn threshold_is_the_bonferroni_normal_quantile() {
        // Two-sided 5 % is 1.95996; 1e-3 / (10 000 × 3) is 5.52 (normal tables).
        assert!((threshold(0.05, 1, 1) - 1.959_964).abs() < 1e-4);
        let z = threshold(1e-3, 10_000, 3);
        assert!((chi2_sf(z * z, 1.0) - 1e-3 / 30_000.0).abs() < 1e-10, "{z}");
        assert!(z > 5.4 && z < 5.6, "{z}");
    }
}
