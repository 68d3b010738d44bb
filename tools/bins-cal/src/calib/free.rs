//! Calibration without a tilter: static intervals found in the signals alone, and the
//! orientation-free fit of the constants to `|f| = 1 g` over all of them (the multi-position
//! method of imu_tk); the labelled fit with each hold's tilt fitted jointly with the
//! constants.
//!
//! **Static intervals** ([`find_static`]): the variance of each signal over a centred window
//! (`static_window_s`), summed over the three axes, is compared with the same sum over the
//! initial still period (`init_s`, which must be still); rows below `static_threshold` times
//! that are static, and every run of static rows lasting at least `min_static_s` is an
//! interval. The window's half-width at each end of a run keeps the turns out.
//!
//! **Free fit** ([`fit_free`]): in each interval the unit is still, so its mean signal `ū`
//! satisfies `|K⁻¹(ū − U0)| = 1` (T(1) solved for `f`, with `|f| = 1 g`). A rotation `R` of the
//! unit frame (`K → K·Rᵀ`) leaves every `|f|` unchanged, so only 9 of the 12 constants are
//! determined. The gauge is fixed as imu_tk fixes it: the correction `A = K⁻¹` is upper
//! triangular (imu_tk's `T·K` with `T` upper triangular), hence so is `K`: `K_yx = K_zx =
//! K_zy = 0`. The frame's z axis is then the z accelerometer's input axis and its y axis lies
//! in the plane of the y and z input axes. Levenberg–Marquardt (the `levenberg-marquardt`
//! crate) minimises `Σ (|A(ū_k − U0)| − 1)²` over `U0` and the 6 elements of `A`; the standard
//! errors are `σ·√diag((JᵀJ)⁻¹)` with `σ` the residual standard error.
//!
//! The results are given as the 9 frame-independent parameters ([`FrameFree`]): per axis the
//! scale factor `s_i = ±|K_i|` \[V/g\] (`K_i` the i-th row of K, the accelerometer's input
//! axis times its scale factor; the sign of `K_ii`) and the bias `U0_i/s_i` \[g\], and per
//! pair the non-orthogonality: 90° minus the angle between the input axes `K_i/s_i`
//! \[rad\].
//!
//! `|f|` cannot tell the sign of an axis: the signs of `K_ii` are an input (`--free-signs`,
//! `+++` by default; the paper's unit, whose signals fall as the specific force rises, takes
//! `---`). They also fix the frame's handedness, which no rotation changes. Their standard
//! errors come from the parameters' covariance through the derivatives of these functions.
//!
//! **Labelled holds that are not level** ([`fit_tilted`]): each hold `k` with label `l_k`
//! is modelled as `ū_k = U0 + K·f_k` with `f_k = (l_k + θ₁e₁ + θ₂e₂)/√(1 + θ₁² + θ₂²)` (`e₁`,
//! `e₂` perpendicular to `l_k`), the 12 constants and the 2 tilts of every hold fitted
//! together; the residuals are weighted by the holds' standard errors and each tilt by the
//! rig's tolerance (a prior `θ ~ N(0, tol²)`), which fixes the rotation gauge (the frame that
//! makes the tilts smallest) and the directions the holds do not determine.

use super::segments::{Options, RunRow, Segment, temp_rate_c_per_min};
use crate::progress::Pass;
use crate::recording::Row;
use anyhow::{anyhow, bail};
use bins_comp::Constants;
use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{DMatrix, DVector, Dyn, Owned};
use std::collections::VecDeque;
use std::path::Path;

/// How static intervals are found.
#[derive(Clone, Copy, Debug, clap::Args)]
pub struct StaticOptions {
    /// Free fit: the initial still period whose signal variance is the reference \[s\].
    #[arg(long, default_value_t = 2.0, value_parser = crate::numarg::duration_s)]
    pub init_s: f64,
    /// Free fit: a row is static when the signals' variance over the window is at most this
    /// multiple of the initial period's.
    #[arg(long, default_value_t = 6.0, value_parser = crate::numarg::positive)]
    pub static_threshold: f64,
    /// Free fit: the window of the variance \[s\].
    #[arg(long, default_value_t = 1.0, value_parser = crate::numarg::duration_s)]
    pub static_window_s: f64,
    /// Free fit: the shortest static interval used \[s\].
    #[arg(long, default_value_t = 1.5, value_parser = crate::numarg::duration_s)]
    pub min_static_s: f64,
}

impl Default for StaticOptions {
    fn default() -> Self {
        StaticOptions { init_s: 2.0, static_threshold: 6.0, static_window_s: 1.0, min_static_s: 1.5 }
    }
}

/// The static intervals of a recording, as [`Segment`]s labelled `S1`, `S2`, … in time order
/// (`f_g` is NaN: the orientation is not known; `rows` is empty, `n_rows` counts them).
/// Intervals shorter than `min_static_s` are not returned; an interval whose temperature is
/// not settled (`seg.max_rate_c_per_min`) is returned rejected. Errors name the file:
/// unreadable, shorter than the initial period, an initial period without variance.
///
/// Two passes over the file, each with a progress bar: the first counts the rows and takes
/// the initial period's variance and the mean sample period (which sets the window), the
/// second slides the window. What is held: the window's rows and the rows of the static run
/// being read (the longest static run, not the file).
pub fn find_static(path: &Path, opt: &StaticOptions, seg: &Options) -> anyhow::Result<Vec<Segment>> {
    let mut survey = Survey::new(opt.init_s);
    let mut row = Row::default();
    let mut pass = Pass::open(path, "noise level").map_err(|e| anyhow!("{e}"))?;
    while pass.read_row(&mut row).map_err(|e| anyhow!("{e}"))? {
        survey.push(&(row.t_s, row.u_v, row.temp_c));
    }
    let mut window = survey.window(path, opt, seg)?;
    let mut pass = Pass::open(path, "static intervals").map_err(|e| anyhow!("{e}"))?;
    while pass.read_row(&mut row).map_err(|e| anyhow!("{e}"))? {
        window.push((row.t_s, row.u_v, row.temp_c));
    }
    Ok(window.finish())
}

/// [`find_static`] on rows already read: (`t_s`, `u_v`, `temp_c`).
pub fn static_intervals(
    path: &Path,
    rows: &[RunRow],
    opt: &StaticOptions,
    seg: &Options,
) -> anyhow::Result<Vec<Segment>> {
    let mut survey = Survey::new(opt.init_s);
    for r in rows {
        survey.push(r);
    }
    let mut window = survey.window(path, opt, seg)?;
    for r in rows {
        window.push(*r);
    }
    Ok(window.finish())
}

/// The first pass: the row count, the first and last time, and the sums of `u` and `u²` per
/// axis over the initial still period (the rows before `t_first + init_s`).
struct Survey {
    init_s: f64,
    n: usize,
    t_first: f64,
    t_last: f64,
    n_init: usize,
    in_init: bool,
    s1: [f64; 3],
    s2: [f64; 3],
}

impl Survey {
    fn new(init_s: f64) -> Survey {
        Survey { init_s, n: 0, t_first: 0.0, t_last: 0.0, n_init: 0, in_init: true, s1: [0.0; 3], s2: [0.0; 3] }
    }

    fn push(&mut self, r: &RunRow) {
        if self.n == 0 {
            self.t_first = r.0;
        }
        self.n += 1;
        self.t_last = r.0;
        self.in_init &= r.0 < self.t_first + self.init_s;
        if self.in_init {
            self.n_init += 1;
            for i in 0..3 {
                self.s1[i] += r.1[i];
                self.s2[i] += r.1[i] * r.1[i];
            }
        }
    }

    /// The second pass's state; errors name the file: no rows, too short, a still period
    /// without variance.
    fn window<'a>(&self, path: &'a Path, opt: &StaticOptions, seg: &'a Options) -> anyhow::Result<Window<'a>> {
        let n = self.n;
        if n == 0 {
            bail!("{}: no rows", path.display());
        }
        if self.n_init < 10 || self.t_last < self.t_first + opt.init_s {
            bail!(
                "{}: the recording is shorter than the initial still period (--init-s {} s) or has fewer than 10 rows in it",
                path.display(),
                opt.init_s
            );
        }
        let v_init = var_of(&[[0.0; 3], [0.0; 3]], &[self.s1, self.s2], self.n_init);
        if !(v_init > 0.0) {
            bail!(
                "{}: the signals do not vary at all in the initial still period ({} s): no noise level to compare with",
                path.display(),
                opt.init_s
            );
        }
        // Centred window of ±half rows (by time: the mean sample period).
        let dt = (self.t_last - self.t_first) / (n - 1).max(1) as f64;
        let half = ((0.5 * opt.static_window_s / dt).round() as usize).max(1);
        Ok(Window {
            path,
            seg,
            min_static_s: opt.min_static_s,
            limit: opt.static_threshold * v_init,
            n,
            half,
            prefix: VecDeque::from([[[0.0; 3]; 2]]),
            prefix_first: 0,
            ahead: VecDeque::new(),
            read: 0,
            decided: 0,
            run: Vec::new(),
            out: Vec::new(),
        })
    }
}

/// The variance of the signals summed over the axes between two prefix sums `a` and `b`
/// (`[Σu, Σu²]` per axis) `m` rows apart.
fn var_of(a: &[[f64; 3]; 2], b: &[[f64; 3]; 2], m: usize) -> f64 {
    let m = m as f64;
    (0..3).map(|i| ((b[1][i] - a[1][i]) - (b[0][i] - a[0][i]).powi(2) / m) / m).sum::<f64>().max(0.0)
}

/// The second pass: a row is static when the variance over the centred window of ±`half` rows
/// (cut at the ends of the recording) is at most `limit`; runs of static rows become
/// intervals. Holds the prefix sums and rows of the window, and the current static run.
struct Window<'a> {
    path: &'a Path,
    seg: &'a Options,
    min_static_s: f64,
    limit: f64,
    n: usize,
    half: usize,
    /// Prefix sums `[Σu, Σu²]` of rows `prefix_first..` (entry j: the sums over rows `< j`).
    prefix: VecDeque<[[f64; 3]; 2]>,
    prefix_first: usize,
    /// Rows read whose window is not complete yet.
    ahead: VecDeque<RunRow>,
    read: usize,
    decided: usize,
    run: Vec<RunRow>,
    out: Vec<Segment>,
}

impl Window<'_> {
    fn push(&mut self, r: RunRow) {
        let last = self.prefix[self.prefix.len() - 1];
        let mut next = last;
        for i in 0..3 {
            next[0][i] = last[0][i] + r.1[i];
            next[1][i] = last[1][i] + r.1[i] * r.1[i];
        }
        self.prefix.push_back(next);
        self.ahead.push_back(r);
        self.read += 1;
        if self.read > self.half {
            self.decide((self.decided + self.half + 1).min(self.n));
        }
    }

    /// Decides the oldest row waiting, whose window ends before row `b`.
    fn decide(&mut self, b: usize) {
        let k = self.decided;
        let a = k.saturating_sub(self.half);
        let pa = self.prefix[a - self.prefix_first];
        let pb = self.prefix[b - self.prefix_first];
        let still = var_of(&pa, &pb, b - a) <= self.limit;
        let Some(row) = self.ahead.pop_front() else { return };
        if still {
            self.run.push(row);
        } else {
            self.close_run();
        }
        self.decided += 1;
        let keep_from = self.decided.saturating_sub(self.half);
        while self.prefix_first < keep_from {
            self.prefix.pop_front();
            self.prefix_first += 1;
        }
    }

    fn close_run(&mut self) {
        let run = std::mem::take(&mut self.run);
        let Some(last) = run.last() else { return };
        if last.0 - run[0].0 < self.min_static_s || run.len() < 3 {
            return;
        }
        self.out.push(interval(self.path, self.out.len() + 1, &run, self.seg));
    }

    fn finish(mut self) -> Vec<Segment> {
        while self.decided < self.read {
            self.decide(self.read);
        }
        self.close_run();
        self.out
    }
}

fn interval(path: &Path, number: usize, run: &[RunRow], seg: &Options) -> Segment {
    let n = run.len() as f64;
    let mut mean = [0.0; 3];
    let mut temp = 0.0;
    for (_, u, tc) in run {
        for i in 0..3 {
            mean[i] += u[i] / n;
        }
        temp += tc / n;
    }
    let mut var = [0.0; 3];
    for (_, u, _) in run {
        for i in 0..3 {
            var[i] += (u[i] - mean[i]).powi(2) / n;
        }
    }
    let rate = temp_rate_c_per_min(run, temp);
    let rejected =
        (!(rate.abs() <= seg.max_rate_c_per_min)).then(|| format!("temperature not settled ({rate:+.2} °C/min)"));
    Segment {
        file: path.to_path_buf(),
        pos: format!("S{number:02}"),
        f_g: [f64::NAN; 3],
        t_s: (run[0].0, run[run.len() - 1].0),
        rows: Vec::new(),
        n_rows: run.len(),
        mean_u_v: mean,
        std_u_v: var.map(f64::sqrt),
        temp_c: temp,
        rate_c_per_min: rate,
        rejected,
    }
}

/// The 9 frame-independent parameters of a set of constants (or their standard errors).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameFree {
    /// Bias `U0_i/|K_i|` \[g\] (x, y, z).
    pub bias_g: [f64; 3],
    /// Scale factor `|K_i|` with the sign of `K_ii` \[V/g\] (x, y, z).
    pub scale_v_per_g: [f64; 3],
    /// Non-orthogonality, 90° minus the angle between input axes \[rad\] (xy, xz, yz).
    pub nonorth_rad: [f64; 3],
}

/// The axis pairs of [`FrameFree::nonorth_rad`].
pub const PAIRS: [(usize, usize); 3] = [(0, 1), (0, 2), (1, 2)];
const AXES: [&str; 3] = ["x", "y", "z"];

impl FrameFree {
    /// The parameters of constants `c` (any rotation gauge).
    pub fn of(c: &Constants<f64>) -> Self {
        let k = &c.k_v_per_g;
        let norm = |i: usize| {
            let n = (k[i][0] * k[i][0] + k[i][1] * k[i][1] + k[i][2] * k[i][2]).sqrt();
            if k[i][i] < 0.0 { -n } else { n }
        };
        let s = [norm(0), norm(1), norm(2)];
        let mut out = FrameFree { scale_v_per_g: s, ..Default::default() };
        for i in 0..3 {
            out.bias_g[i] = c.u0_v[i] / s[i];
        }
        for (p, &(i, j)) in PAIRS.iter().enumerate() {
            let dot = (0..3).map(|m| k[i][m] * k[j][m]).sum::<f64>() / (s[i] * s[j]);
            out.nonorth_rad[p] = dot.clamp(-1.0, 1.0).asin();
        }
        out
    }

    /// As an array: biases, scale factors, non-orthogonalities.
    pub fn to_array(&self) -> [f64; 9] {
        let mut a = [0.0; 9];
        a[..3].copy_from_slice(&self.bias_g);
        a[3..6].copy_from_slice(&self.scale_v_per_g);
        a[6..].copy_from_slice(&self.nonorth_rad);
        a
    }

    /// From [`to_array`](Self::to_array)'s order.
    pub fn from_array(a: &[f64; 9]) -> Self {
        FrameFree { bias_g: [a[0], a[1], a[2]], scale_v_per_g: [a[3], a[4], a[5]], nonorth_rad: [a[6], a[7], a[8]] }
    }

    /// The parameters' names with their printed units, in [`to_array`](Self::to_array)'s order.
    pub fn names() -> [String; 9] {
        std::array::from_fn(|p| match p {
            0..3 => format!("bias_{}_mg", AXES[p]),
            3..6 => format!("scale_{}_V_per_g", AXES[p - 3]),
            _ => {
                let (i, j) = PAIRS[p - 6];
                format!("nonorth_{}{}_mrad", AXES[i], AXES[j])
            }
        })
    }
}

/// Which parameters the free fit estimates.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum FreeParams {
    /// Biases, scale factors and non-orthogonalities (9).
    Full,
    /// Biases and scale factors (6); the input axes are taken as orthogonal. For recordings
    /// whose holds all lie near the axes (six positions), which do not determine the
    /// non-orthogonality.
    BiasScale,
}

/// A parameter's standard error above which the intervals do not determine it: bias 1 mg,
/// scale factor 1000 ppm (relative), non-orthogonality 2 mrad.
pub const NOT_DETERMINED_SE: [f64; 3] = [1e-3, 1e-3, 2e-3];

/// The smallest residual standard error the free fit's standard errors assume \[g\]: no
/// recording measures `|f|` better than 1 µg.
pub const SIGMA_FLOOR_G: f64 = 1e-6;

/// The result of the free fit.
#[derive(Clone, Debug)]
pub struct FreeFit {
    /// The constants in the upper-triangular gauge (`K_yx = K_zx = K_zy = 0`).
    pub constants: Constants<f64>,
    /// The frame-independent parameters.
    pub params: FrameFree,
    /// Their standard errors (0 for a parameter not fitted).
    pub se: FrameFree,
    /// Per interval, `|K⁻¹(ū − U0)| − 1` \[g\].
    pub residual_g: Vec<f64>,
    /// Residual standard error \[g\].
    pub sigma_g: f64,
    /// Which parameters were fitted.
    pub which: FreeParams,
}

/// A least squares problem for `levenberg-marquardt` with a central-difference Jacobian.
struct Problem<F: Fn(&DVector<f64>) -> DVector<f64>> {
    x: DVector<f64>,
    step: DVector<f64>,
    f: F,
}

impl<F: Fn(&DVector<f64>) -> DVector<f64>> LeastSquaresProblem<f64, Dyn, Dyn> for Problem<F> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        self.x.copy_from(x);
    }

    fn params(&self) -> DVector<f64> {
        self.x.clone()
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        let r = (self.f)(&self.x);
        r.iter().all(|v| v.is_finite()).then_some(r)
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        Some(jacobian(&self.f, &self.x, &self.step))
    }
}

fn jacobian(f: &impl Fn(&DVector<f64>) -> DVector<f64>, x: &DVector<f64>, step: &DVector<f64>) -> DMatrix<f64> {
    let m = f(x).len();
    let mut j = DMatrix::zeros(m, x.len());
    let mut xp = x.clone();
    for c in 0..x.len() {
        let h = step[c];
        xp[c] = x[c] + h;
        let rp = f(&xp);
        xp[c] = x[c] - h;
        let rm = f(&xp);
        xp[c] = x[c];
        j.set_column(c, &((rp - rm) / (2.0 * h)));
    }
    j
}

/// The solver's answer: the solution, `(JᵀJ)⁻¹` there (None if singular) and, when it did not
/// converge, why.
type Solution = (DVector<f64>, Option<DMatrix<f64>>, Option<String>);

/// Minimises `Σ r(x)²` from `x0` (Levenberg–Marquardt).
fn solve(f: impl Fn(&DVector<f64>) -> DVector<f64>, x0: DVector<f64>, step: DVector<f64>) -> Solution {
    let problem = Problem { x: x0, step, f };
    let (p, report) = LevenbergMarquardt::new().with_patience(200).minimize(problem);
    let failed = (!report.termination.was_successful())
        .then(|| format!("the least squares fit did not converge ({:?})", report.termination));
    let j = jacobian(&p.f, &p.x, &p.step);
    let cov = (j.transpose() * &j).try_inverse();
    (p.x, cov, failed)
}

/// `|A(u − b)|` \[g\], T(1) solved for `f`: `A = K⁻¹` upper triangular, given as
/// `[a_xx, a_xy, a_xz, a_yy, a_yz, a_zz]`, `b = U0` \[V\].
fn magnitude_g(a: &[f64], b: &[f64], u: &[f64; 3]) -> f64 {
    let v = [u[0] - b[0], u[1] - b[1], u[2] - b[2]];
    let f = [a[0] * v[0] + a[1] * v[1] + a[2] * v[2], a[3] * v[1] + a[4] * v[2], a[5] * v[2]];
    (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt()
}

/// The constants of `U0 = b` and the upper-triangular `A = K⁻¹`.
fn constants_of(a: &[f64], b: &[f64]) -> Constants<f64> {
    let am = nalgebra::Matrix3::new(a[0], a[1], a[2], 0.0, a[3], a[4], 0.0, 0.0, a[5]);
    let k = am.try_inverse().unwrap_or_else(nalgebra::Matrix3::zeros);
    Constants { k_v_per_g: std::array::from_fn(|i| std::array::from_fn(|j| k[(i, j)])), u0_v: [b[0], b[1], b[2]] }
}

/// Why the free fit failed.
#[derive(Debug, thiserror::Error)]
pub enum FreeError {
    /// Fewer intervals than the fit needs.
    #[error("{got} static interval(s): the free fit of {params} parameters needs at least {needed}")]
    TooFew {
        /// Found.
        got: usize,
        /// Needed.
        needed: usize,
        /// Parameters fitted.
        params: usize,
    },
    /// Parameters whose standard error exceeds [`NOT_DETERMINED_SE`].
    #[error(
        "the intervals do not span enough directions to determine {0}; hold the unit in more orientations between the axes{hint}",
        hint = if *.1 { ", or fit the biases and scale factors only (--free-params bias-scale)" } else { "" }
    )]
    NotDetermined(String, bool),
    /// The solver did not converge.
    #[error("{0}")]
    Solver(String),
}

/// The free fit over the intervals' mean signals `u_v` \[V\] (see the module doc); `signs`:
/// the signs of `K_ii` (±1).
pub fn fit_free(u_v: &[[f64; 3]], which: FreeParams, signs: [f64; 3]) -> Result<FreeFit, FreeError> {
    fit_inner(u_v, which, signs, true)
}

fn fit_inner(u_v: &[[f64; 3]], which: FreeParams, signs: [f64; 3], check: bool) -> Result<FreeFit, FreeError> {
    let n_par = match which {
        FreeParams::Full => 9,
        FreeParams::BiasScale => 6,
    };
    let needed = n_par + 3;
    if u_v.len() < needed {
        return Err(FreeError::TooFew { got: u_v.len(), needed, params: n_par });
    }
    // Start: no bias, orthogonal axes with the mean magnitude as the scale factor.
    let mag = u_v.iter().map(|u| (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt()).sum::<f64>() / u_v.len() as f64;
    let a0 = 1.0 / mag.max(f64::MIN_POSITIVE);
    // Parameters: b (3), then A's elements (6 full, 3 diagonal).
    let expand = |x: &DVector<f64>| -> ([f64; 3], [f64; 6]) {
        let b = [x[0], x[1], x[2]];
        let a = match which {
            FreeParams::Full => [x[3], x[4], x[5], x[6], x[7], x[8]],
            FreeParams::BiasScale => [x[3], 0.0, 0.0, x[4], 0.0, x[5]],
        };
        (b, a)
    };
    let resid = |x: &DVector<f64>| -> DVector<f64> {
        let (b, a) = expand(x);
        DVector::from_iterator(u_v.len(), u_v.iter().map(|u| magnitude_g(&a, &b, u) - 1.0))
    };
    let mut x0 = DVector::zeros(n_par);
    let mut step = DVector::from_element(n_par, 1e-6 * mag);
    let diag: &[usize] = if which == FreeParams::Full { &[3, 6, 8] } else { &[3, 4, 5] };
    for &d in diag {
        x0[d] = a0;
    }
    for c in 3..n_par {
        step[c] = 1e-6 * a0;
    }
    if which == FreeParams::Full {
        // Start from the biases and scale factors (not checked: their standard errors include
        // the non-orthogonality they leave out).
        let bs = fit_inner(u_v, FreeParams::BiasScale, [1.0; 3], false)?;
        let a = &bs.constants.k_v_per_g;
        x0 = DVector::from_row_slice(&[
            bs.constants.u0_v[0],
            bs.constants.u0_v[1],
            bs.constants.u0_v[2],
            1.0 / a[0][0],
            0.0,
            0.0,
            1.0 / a[1][1],
            0.0,
            1.0 / a[2][2],
        ]);
    }
    let (x, cov, failed) = solve(resid, x0, step.clone());
    let r = resid(&x);
    let dof = (u_v.len() - n_par) as f64;
    let sigma = (r.norm_squared() / dof).sqrt();
    // A perfect fit would give zero standard errors even to undetermined parameters.
    let sigma_se = sigma.max(SIGMA_FLOOR_G);
    // The signs: flip K's columns (a reflection of the frame, K upper triangular still) so
    // that K_ii has the sign asked for; |f| is unchanged.
    let (b, mut a) = expand(&x);
    let mut x = x;
    let flip: Vec<bool> = (0..3).map(|i| [a[0], a[3], a[5]][i] * signs[i] < 0.0).collect();
    // A = K⁻¹: flipping K's column j flips A's row j.
    let rows: [&[usize]; 3] = [&[0, 1, 2], &[3, 4], &[5]];
    for j in 0..3 {
        if flip[j] {
            for &e in rows[j] {
                a[e] = -a[e];
            }
        }
    }
    // The parameter vector and its covariance follow: `d` = −1 where an element flipped.
    let slots: &[(usize, usize)] = match which {
        FreeParams::Full => &[(0, 3), (1, 4), (2, 5), (3, 6), (4, 7), (5, 8)],
        FreeParams::BiasScale => &[(0, 3), (3, 4), (5, 5)],
    };
    let mut d = DVector::from_element(n_par, 1.0);
    for &(e, slot) in slots {
        if x[slot] != a[e] {
            d[slot] = -1.0;
        }
        x[slot] = a[e];
    }
    let cov = cov.map(|c| DMatrix::from_diagonal(&d) * c * DMatrix::from_diagonal(&d));
    let constants = constants_of(&a, &b);
    let params = FrameFree::of(&constants);
    let se = match cov {
        Some(cov) => derived_se(&x, &step, &(cov * sigma_se * sigma_se), |x| {
            let (b, a) = expand(x);
            FrameFree::of(&constants_of(&a, &b))
        }),
        None => FrameFree::from_array(&[f64::INFINITY; 9]),
    };
    let mut se = se;
    if which == FreeParams::BiasScale {
        se.nonorth_rad = [0.0; 3];
    }
    // An undetermined parameter also stops the solver: name it first.
    if check {
        check_determined(&params, &se, which)?;
    }
    if let Some(e) = failed.filter(|_| check) {
        return Err(FreeError::Solver(e));
    }
    Ok(FreeFit { constants, params, se, residual_g: r.iter().copied().collect(), sigma_g: sigma, which })
}

/// Standard errors of `g(x)` from the covariance of `x` (derivatives by central differences).
fn derived_se(
    x: &DVector<f64>,
    step: &DVector<f64>,
    cov: &DMatrix<f64>,
    g: impl Fn(&DVector<f64>) -> FrameFree,
) -> FrameFree {
    let gv = |x: &DVector<f64>| DVector::from_row_slice(&g(x).to_array());
    let d = jacobian(&gv, x, step);
    let c = &d * cov * d.transpose();
    FrameFree::from_array(&std::array::from_fn(|p| c[(p, p)].max(0.0).sqrt()))
}

fn check_determined(params: &FrameFree, se: &FrameFree, which: FreeParams) -> Result<(), FreeError> {
    let names = FrameFree::names();
    let (v, s) = (params.to_array(), se.to_array());
    let mut bad = Vec::new();
    for p in 0..9 {
        let (limit, rel, unit, scale) = match p {
            0..3 => (NOT_DETERMINED_SE[0], s[p], "mg", 1e3),
            3..6 => (NOT_DETERMINED_SE[1], s[p] / v[p].abs(), "ppm", 1e6),
            _ => (NOT_DETERMINED_SE[2], s[p], "mrad", 1e3),
        };
        if !(rel <= limit) {
            bad.push(format!("{} (standard error {:.3} {unit} > {} {unit})", names[p], rel * scale, limit * scale));
        }
    }
    if bad.is_empty() {
        Ok(())
    } else {
        // Undetermined non-orthogonality also leaves the scale factors it correlates with
        // undetermined: name the cause.
        let nonorth: Vec<String> = bad.iter().filter(|b| b.starts_with("nonorth")).cloned().collect();
        if which == FreeParams::Full && !nonorth.is_empty() {
            Err(FreeError::NotDetermined(nonorth.join(", "), true))
        } else {
            Err(FreeError::NotDetermined(bad.join(", "), false))
        }
    }
}

/// The result of the labelled fit with each hold's tilt.
#[derive(Clone, Debug)]
pub struct TiltFit {
    /// The 12 constants (the frame that makes the tilts smallest).
    pub constants: Constants<f64>,
    /// The frame-independent parameters.
    pub params: FrameFree,
    /// Their standard errors (posterior: the holds' noise and the tilt prior).
    pub se: FrameFree,
    /// Per hold, the angle between the fitted direction and the label \[rad\].
    pub tilt_rad: Vec<f64>,
    /// Per hold, the fitted direction of the specific force (unit vector).
    pub f_g: Vec<[f64; 3]>,
    /// Per hold, `ū − (U0 + K·f)` divided by `K_ii` \[g\].
    pub residual_g: Vec<[f64; 3]>,
}

fn perpendiculars(l: &[f64; 3]) -> ([f64; 3], [f64; 3]) {
    let n = (l[0] * l[0] + l[1] * l[1] + l[2] * l[2]).sqrt();
    let l = l.map(|x| x / n);
    let k = if l[0].abs() < 0.9 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] };
    let d = l[0] * k[0] + l[1] * k[1] + l[2] * k[2];
    let e1: [f64; 3] = std::array::from_fn(|i| k[i] - d * l[i]);
    let n1 = (e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2]).sqrt();
    let e1 = e1.map(|x| x / n1);
    let e2 = [l[1] * e1[2] - l[2] * e1[1], l[2] * e1[0] - l[0] * e1[2], l[0] * e1[1] - l[1] * e1[0]];
    (e1, e2)
}

fn tilted(l: &[f64; 3], e: &([f64; 3], [f64; 3]), t1: f64, t2: f64) -> [f64; 3] {
    let n = (1.0 + t1 * t1 + t2 * t2).sqrt();
    let ln = (l[0] * l[0] + l[1] * l[1] + l[2] * l[2]).sqrt();
    std::array::from_fn(|i| (l[i] / ln + t1 * e.0[i] + t2 * e.1[i]) / n)
}

/// The labelled fit with each hold's tilt (see the module doc): labels `l_k` \[g\], mean
/// signals `u_v` and their standard errors `se_u_v` \[V\] (floored at 1 µV), the constants to
/// start from, the rig's tilt tolerance \[rad\] (the prior's σ).
pub fn fit_tilted(
    labels: &[[f64; 3]],
    u_v: &[[f64; 3]],
    se_u_v: &[[f64; 3]],
    start: &Constants<f64>,
    tol_rad: f64,
) -> anyhow::Result<TiltFit> {
    let n = labels.len();
    if n < 4 {
        bail!("{n} labelled hold(s): the fit with tilts needs at least 4");
    }
    if !(tol_rad > 0.0) {
        bail!("the rig's tilt tolerance must be positive, got {tol_rad} rad");
    }
    let perp: Vec<_> = labels.iter().map(perpendiculars).collect();
    let w: Vec<[f64; 3]> = se_u_v.iter().map(|s| s.map(|x| 1.0 / x.max(1e-6))).collect();
    let unpack = |x: &DVector<f64>| -> Constants<f64> {
        Constants {
            k_v_per_g: std::array::from_fn(|i| std::array::from_fn(|j| x[3 + 3 * i + j])),
            u0_v: [x[0], x[1], x[2]],
        }
    };
    let resid = |x: &DVector<f64>| -> DVector<f64> {
        let c = unpack(x);
        let mut r = DVector::zeros(5 * n);
        for k in 0..n {
            let f = tilted(&labels[k], &perp[k], x[12 + 2 * k], x[13 + 2 * k]);
            for i in 0..3 {
                let model = c.u0_v[i] + (0..3).map(|j| c.k_v_per_g[i][j] * f[j]).sum::<f64>();
                r[3 * k + i] = (u_v[k][i] - model) * w[k][i];
            }
            r[3 * n + 2 * k] = x[12 + 2 * k] / tol_rad;
            r[3 * n + 2 * k + 1] = x[13 + 2 * k] / tol_rad;
        }
        r
    };
    let n_par = 12 + 2 * n;
    let mut x0 = DVector::zeros(n_par);
    let scale = (0..3).map(|i| start.k_v_per_g[i][i].abs()).fold(0.0, f64::max).max(1e-9);
    let mut step = DVector::from_element(n_par, 1e-7 * scale);
    for i in 0..3 {
        x0[i] = start.u0_v[i];
        for j in 0..3 {
            x0[3 + 3 * i + j] = start.k_v_per_g[i][j];
        }
    }
    for c in 12..n_par {
        step[c] = 1e-7;
    }
    let (x, cov, failed) = solve(resid, x0, step.clone());
    if let Some(e) = failed {
        bail!("{e}");
    }
    let cov = cov.ok_or_else(|| anyhow!("the holds do not determine the constants (singular fit)"))?;
    let constants = unpack(&x);
    let params = FrameFree::of(&constants);
    let se = derived_se(&x, &step, &cov, |x| FrameFree::of(&unpack(x)));
    let mut tilt_rad = Vec::with_capacity(n);
    let mut f_g = Vec::with_capacity(n);
    let mut residual_g = Vec::with_capacity(n);
    for k in 0..n {
        let (t1, t2) = (x[12 + 2 * k], x[13 + 2 * k]);
        tilt_rad.push(t1.hypot(t2).atan());
        let f = tilted(&labels[k], &perp[k], t1, t2);
        f_g.push(f);
        residual_g.push(std::array::from_fn(|i| {
            let model = constants.u0_v[i] + (0..3).map(|j| constants.k_v_per_g[i][j] * f[j]).sum::<f64>();
            (u_v[k][i] - model) / constants.k_v_per_g[i][i]
        }));
    }
    Ok(TiltFit { constants, params, se, tilt_rad, f_g, residual_g })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn truth() -> Constants<f64> {
        Constants {
            k_v_per_g: [[1.01, 0.002, -0.001], [0.0015, 0.99, 0.003], [-0.002, 0.001, 1.02]],
            u0_v: [0.02, -0.01, 0.005],
        }
    }

    fn signals(c: &Constants<f64>, f: &[f64; 3]) -> [f64; 3] {
        std::array::from_fn(|i| c.u0_v[i] + (0..3).map(|j| c.k_v_per_g[i][j] * f[j]).sum::<f64>())
    }

    #[test]
    fn noiseless_free_fit_recovers_the_frame_free_parameters() {
        let c = truth();
        // A spiral of directions over the sphere.
        let u: Vec<[f64; 3]> = (0..24)
            .map(|k| {
                let z = -1.0 + (2.0 * k as f64 + 1.0) / 24.0;
                let phi = k as f64 * 2.399963;
                let r = (1.0 - z * z).sqrt();
                signals(&c, &[r * phi.cos(), r * phi.sin(), z])
            })
            .collect();
        let fit = fit_free(&u, FreeParams::Full, [1.0; 3]).expect("fit");
        let (t, e) = (FrameFree::of(&c).to_array(), fit.params.to_array());
        for p in 0..9 {
            assert!((t[p] - e[p]).abs() < 1e-9, "{}: {} vs {}", FrameFree::names()[p], e[p], t[p]);
        }
        let k = fit.constants.k_v_per_g;
        assert_eq!((k[1][0], k[2][0], k[2][1]), (0.0, 0.0, 0.0));
    }

    #[test]
    fn the_signs_asked_for_give_the_truth_of_a_unit_with_negative_scale_factors() {
        let mut c = truth();
        for row in c.k_v_per_g.iter_mut() {
            for v in row.iter_mut() {
                *v = -*v;
            }
        }
        let u: Vec<[f64; 3]> = (0..20)
            .map(|k| {
                let z = -1.0 + (2.0 * k as f64 + 1.0) / 20.0;
                let phi = k as f64 * 2.399963;
                let r = (1.0 - z * z).sqrt();
                signals(&c, &[r * phi.cos(), r * phi.sin(), z])
            })
            .collect();
        let fit = fit_free(&u, FreeParams::Full, [-1.0; 3]).expect("fit");
        let (t, e) = (FrameFree::of(&c).to_array(), fit.params.to_array());
        for p in 0..9 {
            assert!((t[p] - e[p]).abs() < 1e-9, "{}: {} vs {}", FrameFree::names()[p], e[p], t[p]);
        }
        // The fitted constants give back unit specific forces.
        let k = nalgebra::Matrix3::from_fn(|i, j| fit.constants.k_v_per_g[i][j]).try_inverse().expect("K");
        for uk in &u {
            let v = nalgebra::Vector3::from_fn(|i, _| uk[i] - fit.constants.u0_v[i]);
            assert!(((k * v).norm() - 1.0).abs() < 1e-9);
        }
    }

    #[test]
    fn six_axis_positions_do_not_determine_the_non_orthogonality() {
        let c = truth();
        let dirs = bins_comp::ident::TILTER_POSITIONS_G;
        let u: Vec<[f64; 3]> =
            (0..12).map(|k| signals(&c, &dirs[k % 6]).map(|x| x + 1e-5 * ((k * 7 % 5) as f64 - 2.0))).collect();
        let e = fit_free(&u, FreeParams::Full, [1.0; 3]).expect_err("undetermined");
        let msg = e.to_string();
        assert!(msg.contains("nonorth_xy_mrad") && msg.contains("--free-params bias-scale"), "{msg}");
        let fit = fit_free(&u, FreeParams::BiasScale, [1.0; 3]).expect("bias and scale");
        assert!((fit.params.bias_g[0] - FrameFree::of(&c).bias_g[0]).abs() < 1e-4);
    }
}
