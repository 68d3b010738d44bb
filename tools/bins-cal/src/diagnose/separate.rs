//! Separability of two explanations on a design: the deviance a rival cannot absorb of what
//! another explanation predicts (the T-criterion of Atkinson & Fedorov, 1975).
//!
//! An explanation A (a set of fitted mechanisms) predicts `η_A` on a design (the rows,
//! temperatures, power-ons and positions of a recording, or of a test not yet run). A rival B is
//! refitted to `η_A` — its coefficients by generalised least squares under the noise model, its
//! θ searched on its grid and refined — with the columns both explanations share (the nuisance
//! and the other members) free beside it. What B cannot absorb, in the whitened metric and in
//! units of the residual variance (times the autocorrelation inflation), is the expected
//! likelihood-ratio statistic of A against B were A true: the deviance the design lets the data
//! show between them. Below the naming threshold, data drawn from A would seldom name A over B,
//! and the two are one ambiguous group whatever one recording's ranking says. Holding B at
//! fixed values instead of refitting it overstates the separation.
//!
//! The design is a [`Context`] (built from a [`super::prep::Prepared`]), so a design other than
//! the recording's can be passed.

use super::fit::PartialLs;
use super::mech::{Context, Mech};
use super::noise::Filter;

/// One fitted member of an explanation: the mechanism, its θ and the coefficients of its raw
/// columns ([`Context::columns`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Fitted {
    /// The mechanism.
    pub mech: Mech,
    /// Its time constant \[s\] or width [°C].
    pub theta: Option<f64>,
    /// Coefficients of its columns.
    pub coef: Vec<f64>,
}

/// What a rival absorbs of an explanation's prediction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Separation {
    /// The deviance the rival cannot absorb (expected likelihood-ratio statistic of the
    /// explanation against the refitted rival).
    pub deviance: f64,
    /// The rival's θ at its best (for mechanisms with one).
    pub rival_theta: Option<f64>,
}

/// The prediction of `members` on the design `ctx` \[g\].
pub fn predict(ctx: &Context, members: &[Fitted]) -> Vec<f64> {
    let n = ctx.p.t.len();
    let mut eta = vec![0.0; n];
    for m in members {
        let cols = ctx.columns(m.mech, m.theta.unwrap_or(0.0));
        for (c, b) in cols.iter().zip(&m.coef) {
            for (e, v) in eta.iter_mut().zip(c) {
                *e += b * v;
            }
        }
    }
    eta
}

/// The deviance the rival `rival` (one mechanism, θ searched on its grid where it has one)
/// cannot absorb of what `a` predicts on the design `ctx`, with the columns `shared` free in
/// both explanations, under the noise model of random-walk intensity `q` [g²/s]; `scale` is the
/// residual variance of the whitened innovations times the autocorrelation inflation (the
/// deviance's unit: [`super::fit::AxisFit::deviance_scale`]). `None` when the rival has no
/// column on this design.
pub fn separability(
    ctx: &Context,
    q: f64,
    scale: f64,
    a: &[Fitted],
    rival: Mech,
    shared: &[Vec<f64>],
) -> Option<Separation> {
    let grid: Vec<f64> = if rival.theta().is_some() {
        ctx.grid(rival).into_iter().filter(|&th| ctx.offered(rival, th)).collect()
    } else {
        Vec::new()
    };
    let offered = |th: f64| ctx.offered(rival, th);
    separability_of_columns(ctx, q, scale, a, shared, &grid, &offered, &|th| ctx.columns(rival, th))
}

/// [`separability`] of a rival given by its columns at θ (`columns(θ)`), θ searched on `grid`
/// where `offered` (a rival without θ: `grid` empty, `columns` called once with 0).
#[allow(clippy::too_many_arguments)]
pub fn separability_of_columns(
    ctx: &Context,
    q: f64,
    scale: f64,
    a: &[Fitted],
    shared: &[Vec<f64>],
    grid: &[f64],
    offered: &dyn Fn(f64) -> bool,
    columns: &dyn Fn(f64) -> Vec<Vec<f64>>,
) -> Option<Separation> {
    let p = ctx.p;
    let filt = Filter::new(&p.t, &p.r_white[ctx.axis], q, |_| true);
    let eta = predict(ctx, a);
    let part = PartialLs::new(&filt, &eta, shared);
    let scale = scale.max(1e-300);
    let sse_at = |theta: f64| -> f64 {
        let cols = columns(theta);
        if cols.iter().all(|c| c.iter().all(|v| *v == 0.0)) {
            return f64::INFINITY;
        }
        let sse = part.sse_plus(&filt, &cols);
        if sse.is_finite() || cols.len() < 2 {
            return sse;
        }
        // Columns this design makes collinear (a cross-sensitivity tempco's `f_j ΔT` and
        // `f_k ΔT` in one orientation): the best of the subsets that are not.
        (1u32..(1 << cols.len()) - 1)
            .map(|mask| {
                let sub: Vec<Vec<f64>> =
                    cols.iter().enumerate().filter(|(j, _)| mask >> j & 1 == 1).map(|(_, c)| c.clone()).collect();
                part.sse_plus(&filt, &sub)
            })
            .fold(f64::INFINITY, f64::min)
    };
    if grid.is_empty() {
        let sse = sse_at(0.0);
        return sse.is_finite().then_some(Separation { deviance: sse / scale, rival_theta: None });
    }
    let mut best: Option<(f64, f64)> = None;
    for &th in grid {
        let s = sse_at(th);
        if s.is_finite() && best.is_none_or(|b| s < b.1) {
            best = Some((th, s));
        }
    }
    let (th0, s0) = best?;
    // Golden section in ln θ over one grid step either side, within the grid's span (a play
    // wider than the grid's is one that never engages over the temperatures swept: a polynomial
    // in T under another name, not a rival play).
    let step = if grid.len() > 1 { (grid[1] / grid[0]).ln() } else { 0.3 };
    let (g_lo, g_hi) = (grid[0].ln(), grid[grid.len() - 1].ln());
    let eval = |lt: f64| if offered(lt.exp()) { sse_at(lt.exp()) } else { f64::INFINITY };
    let phi = 0.618_033_988_749_894_9;
    let (mut lo, mut hi) = ((th0.ln() - step).max(g_lo), (th0.ln() + step).min(g_hi));
    let (mut c, mut d) = (hi - phi * (hi - lo), lo + phi * (hi - lo));
    let (mut fc, mut fd) = (eval(c), eval(d));
    for _ in 0..12 {
        if fc < fd {
            hi = d;
            d = c;
            fd = fc;
            c = hi - phi * (hi - lo);
            fc = eval(c);
        } else {
            lo = c;
            c = d;
            fc = fd;
            d = lo + phi * (hi - lo);
            fd = eval(d);
        }
    }
    let (th, s) = if fc.min(fd) < s0 { if fc < fd { (c.exp(), fc) } else { (d.exp(), fd) } } else { (th0, s0) };
    Some(Separation { deviance: s / scale, rival_theta: Some(th) })
}

/// The separation a name needs from a rival: the expected deviance `T` at which data drawn from
/// the named explanation exceed the naming threshold `thr` with 95 % probability (the
/// likelihood-ratio statistic is then about a noncentral χ² of `df` degrees of freedom and
/// noncentrality `T`: mean `df + T`, variance `2(df + 2T)`). Below it a recording of this design
/// names the wrong one of the two too often, and they are one group.
pub fn separation_needed(thr: f64, df: usize) -> f64 {
    let k = df.max(1) as f64;
    let power_ok = |t: f64| k + t - 1.645 * (2.0 * (k + 2.0 * t)).sqrt() >= thr;
    let (mut lo, mut hi) = (0.0, thr.max(1.0) * 4.0 + 100.0);
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if power_ok(mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    hi
}
