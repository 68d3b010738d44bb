//! The noise model of the residual: white measurement noise (variance `r_t` per row, from the
//! differences of consecutive samples within constant-reference segments) plus a random walk
//! of intensity `q` [g²/s] (random walk and bias instability: the slow drift that must be
//! recognised as noise). This is the local-level model; its Kalman filter turns any column
//! into its standardized one-step-ahead innovations, so generalized least squares is ordinary
//! least squares on filtered columns and the likelihood is exact. The level's start is diffuse
//! (the first observed row sets it), so a constant offset between SIM and REAL is always part
//! of the null.
//!
//! Where the sensor's bias instability is known (a specification, [`Gm`], or the noise
//! `bins-cal allan --noise-toml` fits to a quiet recording, [`SensorNoise`]), it is a second
//! state beside the level: a first-order Gauss–Markov bias of variance `σ²` and correlation
//! time `τ`. Below `τ` it wanders like a random walk of intensity `2σ²/τ`; beyond it stays
//! within `σ`, so structure at the hour scale is not taken for drift the way a random walk
//! fitted to the short scales takes it.

/// What the filter does at a row.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Step {
    /// Row not observed (masked out or before the first observed row).
    Skip,
    /// First observed row: sets the level, gives no innovation.
    Init,
    /// A normal update.
    Update,
}

/// Magnitude below which a whitened value is taken as 0 ([`flush`]).
pub const TINY: f64 = 1e-150;

/// `x`, or 0 when `|x| <` [`TINY`]. A decayed column (a turn-on term `e^(−P/τ)` long after
/// power-on) has innovations that shrink through the subnormal range (below 2.2·10⁻³⁰⁸), where
/// every multiplication costs a hundred times a normal one, and the Gram matrices multiply
/// every whitened value with every other column's; with a 260 000-row warm-up case 5 % of the
/// whitened values were subnormal and took half the diagnosis's time. Two values at or above
/// `TINY` multiply to a normal number; what is dropped is below 10⁻¹⁵⁰ against standardized
/// innovations of order 1, far below the last bit of any sum they enter.
#[inline]
pub fn flush(x: f64) -> f64 {
    if x.abs() < TINY { 0.0 } else { x }
}

/// [`flush`] for the filter's level, which each row's update depends on: a branch the
/// processor predicts (the zero is on a cold path), so the test is not in the chain of
/// dependent operations from one row to the next as a branch-free select would be.
#[inline]
fn flush_level(x: f64) -> f64 {
    #[cold]
    #[inline(never)]
    fn zero() -> f64 {
        0.0
    }
    if x.abs() < TINY { zero() } else { x }
}

/// Gains of the local-level filter for one noise setting and one mask; the same for every
/// column, so computed once.
#[derive(Clone, Debug)]
pub struct Filter {
    /// What happens at each row.
    pub step: Vec<Step>,
    /// Kalman gain at each row.
    pub gain: Vec<f64>,
    /// `1/√F` (innovation variance `F`) at each row.
    pub inv_sqrt_f: Vec<f64>,
    /// `Σ ln F` over updated rows.
    pub log_det: f64,
    /// Number of updated rows.
    pub n_used: usize,
    /// With a bias instability: the Kalman gain of its state at each row (empty without).
    pub gain_gm: Vec<f64>,
    /// With a bias instability: its decay `e^(−Δt/τ)` into each row (empty without).
    pub phi: Vec<f64>,
    /// Whether a bias instability is modelled (a second state a column).
    bias_state: bool,
}

/// A first-order Gauss–Markov bias instability: `b' = −b/τ + w`, stationary variance
/// `var_g2` \[g²\], correlation time `tau_s` \[s\] (the sensor's specification).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Gm {
    /// Stationary variance \[g²\].
    pub var_g2: f64,
    /// Correlation time \[s\].
    pub tau_s: f64,
}

impl Gm {
    /// The random-walk intensity [g²/s] it shows at averaging times well below `τ`: `2σ²/τ`.
    pub fn short_q(&self) -> f64 {
        2.0 * self.var_g2 / self.tau_s
    }

    /// One Gauss–Markov bias for the sum of two (the filter holds one): the variance of the
    /// sum (`σ₁² + σ₂²`, what it stays within beyond both times) and the short-time slope of
    /// the sum (`2σ₁²/τ₁ + 2σ₂²/τ₂`, how it wanders below both), so
    /// `τ = (σ₁² + σ₂²)/(σ₁²/τ₁ + σ₂²/τ₂)`. Over any time it wanders at least as far as the
    /// sum (its increment's variance `2σ²(1 − e^(−t/τ))` against the sum's, by Jensen's
    /// inequality: `1 − e^(−x)` is concave), so a test against it is the more cautious one.
    pub fn merged(a: Gm, b: Gm) -> Gm {
        let var_g2 = a.var_g2 + b.var_g2;
        Gm { var_g2, tau_s: var_g2 / (a.var_g2 / a.tau_s + b.var_g2 / b.tau_s) }
    }
}

/// The sensor's noise as a scenario's `[noise]` table gives it, per accelerometer in volts at
/// the scenario's rate: what `bins-cal allan --noise-toml` fits to a quiet recording of the
/// unit (white noise, a random walk, up to two Gauss–Markov biases, the ADC's step), or the
/// table SIM was simulated with.
///
/// The residual is REAL − SIM in g: the file's volts become the residual's through the ratio
/// of the white-noise densities, the residual's (its per-row white variance times the row
/// period) over the file's (its model's Allan variance at one sample times the sample
/// period). That ratio holds the scale factor and the √2 of two recordings that each carry the
/// noise (1 where SIM is noiseless, or predicted by `--calib`), without the diagnosis being
/// told either; it assumes the residual's white noise is the sensor's.
#[derive(Clone, Debug, PartialEq)]
pub struct SensorNoise {
    /// The file it was read from.
    pub file: std::path::PathBuf,
    /// The file's sample period \[s\].
    pub tau0_s: f64,
    /// Per accelerometer, in volts.
    pub axes: [crate::allan::twin::TwinNoise; 3],
}

/// [`SensorNoise`] of one accelerometer in the residual's units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AxisNoise {
    /// Random-walk intensity \[g²/s\].
    pub q: f64,
    /// The Gauss–Markov bias (the two merged where both are slower than a row), if any.
    pub gm: Option<Gm>,
    /// The residual's g per volt of the file: the square root of the density ratio.
    pub g_per_v: f64,
}

impl SensorNoise {
    /// Reads the `[noise]` table and the rate of a scenario file (errors name the file and the
    /// key). Every accelerometer needs white noise or an ADC step (the residual's level is
    /// matched to it).
    pub fn read(path: &std::path::Path) -> Result<Self, super::DiagnoseError> {
        use crate::sim::scenario::ScenarioFile;
        let err = |e: crate::sim::scenario::ScenarioError| super::DiagnoseError(format!("--noise {e}"));
        let sim = ScenarioFile::read(path).map_err(err)?.build(path).map_err(err)?;
        let n = &sim.noise;
        let axes = std::array::from_fn(|i| crate::allan::twin::TwinNoise {
            white: n.white_v[i],
            random_walk: n.random_walk_v_per_sqrt_s[i],
            gm: [(n.bias_instability_v[i], n.bias_tau_s[i]), (n.bias_instability2_v[i], n.bias_tau2_s[i])],
            adc_step: n.adc_lsb_v,
        });
        let noise = SensorNoise { file: path.to_path_buf(), tau0_s: 1.0 / sim.rate_hz, axes };
        for (i, a) in noise.axes.iter().enumerate() {
            if !(a.avar(1.0, noise.tau0_s) > 0.0) {
                return Err(super::DiagnoseError(format!(
                    "--noise {}: noise.white_V[{i}]: the accelerometer has no noise at one sample (white, Gauss–Markov or ADC step); its random walk is scaled to the residual by that level",
                    path.display()
                )));
            }
        }
        Ok(noise)
    }

    /// The noise of accelerometer `axis` in a residual of white-noise density
    /// `white_g2_s` \[g²·s\] (per-row variance × row period) whose rows are `row_s` apart: a
    /// Gauss–Markov bias faster than a row is white there (in the residual's white level
    /// already) and is left out.
    pub fn for_axis(&self, axis: usize, white_g2_s: f64, row_s: f64) -> AxisNoise {
        let a = &self.axes[axis];
        let k2 = white_g2_s / (a.avar(1.0, self.tau0_s) * self.tau0_s);
        let gms =
            a.gm.iter().filter(|&&(s, t)| s > 0.0 && t >= row_s).map(|&(s, t)| Gm { var_g2: k2 * s * s, tau_s: t });
        AxisNoise { q: k2 * a.random_walk * a.random_walk, gm: gms.reduce(Gm::merged), g_per_v: k2.sqrt() }
    }
}

/// The filter's covariance recursion, one observed row at a time: the same for every column,
/// so [`Filter`] runs it once and stores its gains. Carried from one block of rows to the next,
/// it lets a long recording be whitened a block at a time ([`Filter::refill`]).
#[derive(Clone, Copy, Debug)]
struct Recursion {
    q: f64,
    gm: Option<Gm>,
    /// Covariance `[a b; b c]` of (bias instability, level); only `c` without one.
    a: f64,
    b: f64,
    c: f64,
    last_t: f64,
    init: bool,
}

/// One row's gains from [`Recursion::update`].
struct Gains {
    level: f64,
    bias: f64,
    phi: f64,
    f: f64,
}

impl Recursion {
    fn new(q: f64, gm: Option<Gm>) -> Self {
        Recursion { q, gm, a: 0.0, b: 0.0, c: 0.0, last_t: 0.0, init: false }
    }

    /// The first observed row, at `t` with white variance `r`: the level is set (diffuse);
    /// with a bias instability, the bias starts at its stationary prior, so the two start
    /// correlated: covariance `[σ², −σ²; −σ², σ² + r]` of (bias, level).
    fn start(&mut self, t: f64, r: f64) {
        self.init = true;
        self.last_t = t;
        match self.gm {
            Some(gm) => (self.a, self.b, self.c) = (gm.var_g2, -gm.var_g2, gm.var_g2 + r),
            None => self.c = r,
        }
    }

    /// A normal update at `t` with white variance `r`.
    fn update(&mut self, t: f64, r: f64) -> Gains {
        let dt = (t - self.last_t).max(0.0);
        self.last_t = t;
        let Some(gm) = self.gm else {
            let pp = self.c + self.q * dt;
            let f = pp + r;
            let k = pp / f;
            self.c = (1.0 - k) * pp;
            return Gains { level: k, bias: 0.0, phi: 0.0, f };
        };
        let s2 = gm.var_g2;
        let ph = (-dt / gm.tau_s).exp();
        let (pa, pb, pc) = (ph * ph * self.a + s2 * (1.0 - ph * ph), ph * self.b, self.c + self.q * dt);
        let f = pa + 2.0 * pb + pc + r;
        let (kg, kl) = ((pa + pb) / f, (pb + pc) / f);
        (self.a, self.b, self.c) = (pa - (pa + pb) * kg, pb - (pa + pb) * kl, pc - (pb + pc) * kl);
        Gains { level: kl, bias: kg, phi: ph, f }
    }
}

impl Filter {
    /// Builds the filter for times `t` \[s\], white variances `r`, random-walk intensity `q` and
    /// the bias instability `gm` if known; rows with `observed(i) == false` are skipped (the
    /// level only diffuses over them, the bias instability decays).
    pub fn new(t: &[f64], r: &[f64], q: f64, gm: Option<Gm>, observed: impl Fn(usize) -> bool) -> Self {
        let mut f = Self::with_rows(t.len(), gm.is_some());
        f.refill(&mut Recursion::new(q, gm), t, r, observed);
        f
    }

    /// A filter of `n` rows, all skipped, with room for a bias instability's gains if `gm`.
    fn with_rows(n: usize, gm: bool) -> Self {
        let gm_rows = if gm { n } else { 0 };
        Filter {
            step: vec![Step::Skip; n],
            gain: vec![0.0; n],
            inv_sqrt_f: vec![0.0; n],
            log_det: 0.0,
            n_used: 0,
            gain_gm: vec![0.0; gm_rows],
            phi: vec![0.0; gm_rows],
            bias_state: gm,
        }
    }

    /// Rows `0..t.len()` (at most the filter's length) set from the recursion `rec`, continued
    /// over `t`, `r`; `log_det` and `n_used` add the updated rows. Called on consecutive blocks
    /// of a recording with one recursion, the block filters whiten as one filter of all rows.
    fn refill(&mut self, rec: &mut Recursion, t: &[f64], r: &[f64], observed: impl Fn(usize) -> bool) {
        for i in 0..t.len().min(r.len()).min(self.step.len()) {
            self.step[i] = Step::Skip;
            if !observed(i) {
                continue;
            }
            if !rec.init {
                rec.start(t[i], r[i]);
                self.step[i] = Step::Init;
                continue;
            }
            let g = rec.update(t[i], r[i]);
            self.step[i] = Step::Update;
            self.gain[i] = g.level;
            self.inv_sqrt_f[i] = 1.0 / g.f.sqrt();
            if self.bias_state {
                self.gain_gm[i] = g.bias;
                self.phi[i] = g.phi;
            }
            self.log_det += g.f.ln();
            self.n_used += 1;
        }
    }

    /// Filter states a column carries: 1 (the level), 2 with a bias instability. The `level`
    /// of [`Filter::whiten_rows`] holds this many values a column.
    pub fn states(&self) -> usize {
        if self.bias_state { 2 } else { 1 }
    }

    /// The standardized innovations of column `x` into `out` (0 where not updated). Values
    /// below [`TINY`] in magnitude, of the innovations and of the filter's level, are taken
    /// as 0 ([`flush`]).
    pub fn whiten(&self, x: &[f64], out: &mut [f64]) {
        if self.states() > 1 {
            let n = x.len().min(out.len());
            self.whiten_rows(&[x], 0..n, &mut [0.0; 2], out, n);
            return;
        }
        let mut mu = 0.0;
        for i in 0..x.len().min(out.len()) {
            match self.step[i] {
                Step::Skip => out[i] = 0.0,
                Step::Init => {
                    mu = flush(x[i]);
                    out[i] = 0.0;
                }
                Step::Update => {
                    let v = x[i] - mu;
                    out[i] = flush(v * self.inv_sqrt_f[i]);
                    mu = flush_level(mu + self.gain[i] * v);
                }
            }
        }
    }

    /// [`Filter::whiten`] of every column of `xs`, rows `rows` only, continuing from the states
    /// `level` ([`Filter::states`] per column, updated: the levels, then the bias
    /// instabilities): column `c`'s values go to `out[c·stride ..]`.
    /// Called on consecutive ranges from row 0, it gives the values of one whitening of all
    /// rows. The columns are interleaved row by row: each column's recursion is a chain of
    /// dependent operations, and interleaving lets the chains of different columns overlap.
    pub fn whiten_rows(
        &self,
        xs: &[&[f64]],
        rows: std::ops::Range<usize>,
        level: &mut [f64],
        out: &mut [f64],
        stride: usize,
    ) {
        let m = xs.len().min(level.len() / self.states());
        let start = rows.start;
        if self.states() > 1 {
            let (level, bias) = level.split_at_mut(m);
            for i in rows {
                let o = i - start;
                match self.step[i] {
                    Step::Skip => (0..m).for_each(|c| out[c * stride + o] = 0.0),
                    Step::Init => {
                        for c in 0..m {
                            level[c] = flush(xs[c][i]);
                            bias[c] = 0.0;
                            out[c * stride + o] = 0.0;
                        }
                    }
                    Step::Update => {
                        let (g, s, kg, ph) = (self.gain[i], self.inv_sqrt_f[i], self.gain_gm[i], self.phi[i]);
                        for c in 0..m {
                            let b = bias[c] * ph;
                            let v = xs[c][i] - level[c] - b;
                            out[c * stride + o] = flush(v * s);
                            level[c] = flush_level(level[c] + g * v);
                            bias[c] = flush_level(b + kg * v);
                        }
                    }
                }
            }
            return;
        }
        // Four columns at a time: enough independent chains to overlap, few enough streams of
        // memory for the prefetcher.
        for c0 in (0..m).step_by(4) {
            let c1 = (c0 + 4).min(m);
            for i in rows.clone() {
                let o = i - start;
                match self.step[i] {
                    Step::Skip => (c0..c1).for_each(|c| out[c * stride + o] = 0.0),
                    Step::Init => {
                        for c in c0..c1 {
                            level[c] = flush(xs[c][i]);
                            out[c * stride + o] = 0.0;
                        }
                    }
                    Step::Update => {
                        let (g, s) = (self.gain[i], self.inv_sqrt_f[i]);
                        for c in c0..c1 {
                            let v = xs[c][i] - level[c];
                            out[c * stride + o] = flush(v * s);
                            level[c] = flush_level(level[c] + g * v);
                        }
                    }
                }
            }
        }
    }

    /// Whitened copy of `x`.
    pub fn whitened(&self, x: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; x.len()];
        self.whiten(x, &mut out);
        out
    }
}

/// The smoothed level (fixed-interval RTS smoother) of `x` under the local-level model: the
/// drift estimate. Rows that are not observed take the level of the nearest observed row
/// before them.
pub fn smooth_level(t: &[f64], r: &[f64], q: f64, x: &[f64]) -> Vec<f64> {
    let n = x.len();
    if n == 0 {
        return Vec::new();
    }
    let mut mf = vec![0.0; n];
    let mut pf = vec![0.0; n];
    let mut pp = vec![0.0; n];
    mf[0] = x[0];
    pf[0] = r[0];
    pp[0] = r[0];
    for i in 1..n {
        let pred = pf[i - 1] + q * (t[i] - t[i - 1]).max(0.0);
        let f = pred + r[i];
        let k = pred / f;
        mf[i] = mf[i - 1] + k * (x[i] - mf[i - 1]);
        pf[i] = (1.0 - k) * pred;
        pp[i] = pred;
    }
    let mut ms = mf.clone();
    for i in (0..n - 1).rev() {
        let c = if pp[i + 1] > 0.0 { pf[i] / pp[i + 1] } else { 0.0 };
        ms[i] = mf[i] + c * (ms[i + 1] - mf[i]);
    }
    ms
}

/// Restricted (REML) profile log-likelihood of `y = X·β + level + white` for random-walk
/// intensity `q`, the white variances known up to a common scale (profiled):
/// `−½((n − p) ln(SSE/(n − p)) + Σ ln F + ln det(X̃ᵀX̃))`, `X̃` the whitened columns.
///
/// The restricted form counts what the regressors absorb, so `q` is not biased low by a rich
/// model (the plain profile likelihood is, by the variance the regressors take).
/// Returns `(ll, sse, n_used, β)`.
pub fn profile_ll(
    t: &[f64],
    r: &[f64],
    q: f64,
    gm: Option<Gm>,
    y: &[f64],
    xs: &[&[f64]],
) -> (f64, f64, usize, Vec<f64>) {
    let (gram, log_det, n_used) = whitened_gram(t, r, q, gm, y, xs);
    let (sse, beta, log_det_x, p) = ls_from_gram(&gram, xs.len());
    let n = n_used.max(1) as f64;
    let m = (n - p as f64).max(1.0);
    let ll = -0.5 * (m * (sse.max(1e-300) / m).ln() + log_det + log_det_x + m);
    (ll, sse, n_used, beta)
}

/// The Gram matrix of the whitened columns `[xs…, y]` (row-major, `(p+1)²`), the filter's
/// `Σ ln F` and its number of updated rows, for every row observed: the filter and the
/// whitening run block by block of rows beside the Gram's products, so no whitened column is
/// ever stored whole (the likelihood is evaluated many times over hundreds of thousands of
/// rows; storing them cost more than the arithmetic). The blocks are
/// [`GRAM_BLOCK`](super::stats::GRAM_BLOCK) rows, as in [`gram_blocked`](super::stats::gram_blocked),
/// so the sums are the same as whitening first and multiplying after.
fn whitened_gram(t: &[f64], r: &[f64], q: f64, gm: Option<Gm>, y: &[f64], xs: &[&[f64]]) -> (Vec<f64>, f64, usize) {
    use super::stats::GRAM_BLOCK;
    let cols: Vec<&[f64]> = xs.iter().copied().chain(std::iter::once(y)).collect();
    let m = cols.len();
    let n = cols.iter().map(|c| c.len()).min().unwrap_or(0).min(t.len()).min(r.len());
    let mut g = vec![0.0; m * m];
    if n == 0 {
        return (g, 0.0, 0);
    }
    // The filter's gains a block at a time: memory bounded by the block, not the recording.
    let mut f = Filter::with_rows(GRAM_BLOCK, gm.is_some());
    let mut rec = Recursion::new(q, gm);
    let mut state = vec![0.0; f.states() * m];
    let mut w = vec![0.0; m * GRAM_BLOCK];
    let mut block: Vec<&[f64]> = Vec::with_capacity(m);
    for c0 in (0..n).step_by(GRAM_BLOCK) {
        let c1 = (c0 + GRAM_BLOCK).min(n);
        f.refill(&mut rec, &t[c0..c1], &r[c0..c1], |_| true);
        block.clear();
        block.extend(cols.iter().map(|c| &c[c0..c1]));
        f.whiten_rows(&block, 0..c1 - c0, &mut state, &mut w, GRAM_BLOCK);
        add_products(&mut g, &w, m, c1 - c0);
    }
    symmetrise(&mut g, m);
    (g, f.log_det, f.n_used)
}

/// Adds the products of the `m` whitened columns in `w` (each [`GRAM_BLOCK`](super::stats::GRAM_BLOCK)
/// long, `len` rows used) to the upper triangle of the Gram matrix `g` (`m × m`).
fn add_products(g: &mut [f64], w: &[f64], m: usize, len: usize) {
    use super::stats::{GRAM_BLOCK, dot};
    for a in 0..m {
        let wa = &w[a * GRAM_BLOCK..a * GRAM_BLOCK + len];
        for b in a..m {
            g[a * m + b] += dot(wa, &w[b * GRAM_BLOCK..b * GRAM_BLOCK + len]);
        }
    }
}

/// Copies the upper triangle of `g` (`m × m`) to the lower.
fn symmetrise(g: &mut [f64], m: usize) {
    for a in 0..m {
        for b in 0..a {
            g[a * m + b] = g[b * m + a];
        }
    }
}

/// Least squares of `y` on the columns `xs` (already whitened): residual sum of squares and
/// coefficients. Columns that are collinear with earlier ones get a zero coefficient.
pub fn ls_sse(y: &[f64], xs: &[Vec<f64>]) -> (f64, Vec<f64>) {
    let (sse, beta, _, _) = ls_fit(y, xs);
    (sse, beta)
}

/// [`ls_sse`] plus `ln det` of the kept columns' Gram matrix and their number.
fn ls_fit(y: &[f64], xs: &[Vec<f64>]) -> (f64, Vec<f64>, f64, usize) {
    let mut cols: Vec<&[f64]> = xs.iter().map(Vec::as_slice).collect();
    cols.push(y);
    ls_from_gram(&super::stats::gram_blocked(&cols, None), xs.len())
}

/// Least squares from the Gram matrix `raw` of `[x_1 … x_p, y]` (row-major, `(p+1)²`):
/// residual sum of squares, coefficients, `ln det` of the kept columns' Gram matrix and their
/// number. Greedy: a column is kept when it is not collinear with those kept, judged on the
/// Gram matrix of the normalised columns.
fn ls_from_gram(raw: &[f64], p: usize) -> (f64, Vec<f64>, f64, usize) {
    use super::stats::{chol_logdet, chol_solve};
    let yy = raw[p * (p + 1) + p];
    if p == 0 {
        return (yy, Vec::new(), 0.0, 0);
    }
    let norms: Vec<f64> = (0..p).map(|u| raw[u * (p + 1) + u].sqrt()).collect();
    let mut full = vec![0.0; p * p];
    let mut xy = vec![0.0; p];
    for u in 0..p {
        if !(norms[u] > 0.0) {
            continue;
        }
        xy[u] = raw[u * (p + 1) + p] / norms[u];
        for v in 0..p {
            if norms[v] > 0.0 {
                full[u * p + v] = raw[u * (p + 1) + v] / (norms[u] * norms[v]);
            }
        }
    }
    let mut keep: Vec<usize> = Vec::new();
    let mut sol = (Vec::new(), Vec::new());
    let mut gram = Vec::new();
    for j in 0..p {
        if !(norms[j] > 0.0) {
            continue;
        }
        let mut trial = keep.clone();
        trial.push(j);
        let m = trial.len();
        let a: Vec<f64> =
            trial.iter().flat_map(|&cu| trial.iter().map(move |&cv| (cu, cv))).map(|(u, v)| full[u * p + v]).collect();
        let b: Vec<f64> = trial.iter().map(|&c| xy[c]).collect();
        if let Some(s) = chol_solve(&a, &b, m, 1e-10) {
            keep = trial;
            sol = s;
            gram = a;
        }
    }
    let mut beta = vec![0.0; p];
    let mut fit = 0.0;
    for (u, &c) in keep.iter().enumerate() {
        beta[c] = sol.0[u] / norms[c];
        fit += sol.0[u] * xy[c];
    }
    let log_det =
        chol_logdet(&gram, keep.len()).unwrap_or(0.0) + keep.iter().map(|&c| 2.0 * norms[c].ln()).sum::<f64>();
    ((yy - fit).max(0.0), beta, log_det, keep.len())
}

/// Restricted-maximum-likelihood random-walk intensity `q` [g²/s] with the columns `xs` in
/// the model: a scan one point a decade relative to the median white variance per second
/// (1e-9 … 10, and 0), the best point refined by steps of ½ and ¼ decade, and a parabola
/// through the last three (16 likelihood evaluations).
pub fn estimate_q(t: &[f64], r: &[f64], gm: Option<Gm>, y: &[f64], xs: &[&[f64]]) -> f64 {
    estimate_q_ll(t, r, gm, y, xs).0
}

/// [`estimate_q`] and the restricted log-likelihood at the estimate.
fn estimate_q_ll(t: &[f64], r: &[f64], gm: Option<Gm>, y: &[f64], xs: &[&[f64]]) -> (f64, f64) {
    let rmed = super::stats::median(r).max(1e-300);
    let ll = |lq: f64| profile_ll(t, r, rmed * 10f64.powf(lq), gm, y, xs).0;
    let (mut best_lq, mut best_ll) = (f64::NAN, f64::NEG_INFINITY);
    for k in -9..=1 {
        let v = ll(k as f64);
        if v > best_ll {
            (best_lq, best_ll) = (k as f64, v);
        }
    }
    let ll0 = profile_ll(t, r, 0.0, gm, y, xs).0;
    if ll0 >= best_ll {
        return (0.0, ll0);
    }
    let mut around = (f64::NEG_INFINITY, best_ll, f64::NEG_INFINITY);
    for step in [0.5, 0.25] {
        let (lo, hi) = (ll(best_lq - step), ll(best_lq + step));
        if lo > best_ll && lo >= hi {
            (best_lq, best_ll) = (best_lq - step, lo);
            around = (f64::NEG_INFINITY, lo, f64::NEG_INFINITY);
        } else if hi > best_ll {
            (best_lq, best_ll) = (best_lq + step, hi);
            around = (f64::NEG_INFINITY, hi, f64::NEG_INFINITY);
        } else {
            around = (lo, best_ll, hi);
        }
    }
    // Parabola in log q through the last step's three points.
    let (a, b, c) = around;
    let den = a - 2.0 * b + c;
    let off = if den < 0.0 && a.is_finite() && c.is_finite() { (0.5 * (a - c) / den).clamp(-1.0, 1.0) } else { 0.0 };
    // The parabola's vertex: its height is the maximum (no further evaluation needed).
    let peak = if off != 0.0 { b + 0.5 * (c - a) * off + 0.5 * den * off * off } else { b };
    (rmed * 10f64.powf(best_lq + 0.25 * off), peak.max(b))
}

/// The upper end of the 95 % restricted-likelihood interval of `q` (where the log-likelihood
/// has fallen by 1.92 from its maximum), with the columns `xs` in: the random walk that
/// mechanisms are tested against. A weak random walk is poorly determined by one record (its
/// estimate is often far below the truth, or 0), and a mechanism tested against too small a
/// drift is named for what is drift; against the upper end it is named only when the data
/// exclude the drift as its explanation.
pub fn q_upper(t: &[f64], r: &[f64], gm: Option<Gm>, y: &[f64], xs: &[&[f64]]) -> f64 {
    let rmed = super::stats::median(r).max(1e-300);
    let (q_hat, ll_max) = estimate_q_ll(t, r, gm, y, xs);
    let ll = |q: f64| profile_ll(t, r, q, gm, y, xs).0;
    // Walk up in quarter decades from the estimate (or from 1e-9·rmed when it is 0).
    let mut lq = if q_hat > 0.0 { (q_hat / rmed).log10() } else { -9.0 };
    let (mut prev_lq, mut prev_drop) = (lq, if q_hat > 0.0 { 0.0 } else { ll_max - ll(rmed * 1e-9) });
    if prev_drop > 1.92 {
        return q_hat;
    }
    while lq < 2.0 {
        lq += 0.25;
        let drop = ll_max - ll(rmed * 10f64.powf(lq));
        if drop > 1.92 {
            let f = ((1.92 - prev_drop) / (drop - prev_drop)).clamp(0.0, 1.0);
            return rmed * 10f64.powf(prev_lq + f * (lq - prev_lq));
        }
        (prev_lq, prev_drop) = (lq, drop);
    }
    rmed * 100.0
}

/// The random walk [g²/s] seen at short averaging times, up to a minute, where the
/// temperature barely moves: least squares of the Hadamard variance of `segs` (equally spaced
/// at `dt` \[s\]) on `σ²·dt/τ + q·τ/6`, each point weighted by its variance `2·H²/n`
/// (`n` independent terms). Returns the estimate and its one-sided 97.5 % upper bound, or
/// `None` when fewer than three averaging times have 8 independent terms.
pub fn short_tau_q(segs: &[&[f64]], dt: f64) -> Option<(f64, f64)> {
    let longest = segs.iter().map(|s| s.len()).max().unwrap_or(0);
    let mut ms = Vec::new();
    let mut m = 1usize;
    while 3 * m < longest && m as f64 * dt <= 60.0 {
        ms.push(m);
        m *= 2;
    }
    let pts: Vec<(f64, f64, f64)> = super::stats::hadamard_var(segs, &ms)
        .into_iter()
        .filter_map(|(m, h, n)| {
            let n_indep = n as f64 / m as f64;
            (n_indep >= 8.0 && h > 0.0).then_some((m as f64 * dt, h, n_indep))
        })
        .collect();
    if pts.len() < 3 {
        return None;
    }
    // Weighted least squares h = a·(1/τ) + b·(τ/6).
    let (mut s11, mut s12, mut s22, mut b1, mut b2) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for &(tau, h, n) in &pts {
        let w = n / (2.0 * h * h);
        let (x1, x2) = (1.0 / tau, tau / 6.0);
        s11 += w * x1 * x1;
        s12 += w * x1 * x2;
        s22 += w * x2 * x2;
        b1 += w * x1 * h;
        b2 += w * x2 * h;
    }
    let det = s11 * s22 - s12 * s12;
    if !(det > 0.0) {
        return None;
    }
    let q = (s11 * b2 - s12 * b1) / det;
    let se = (s11 / det).sqrt();
    Some((q.max(0.0), (q + 1.96 * se).max(0.0)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// Innovations of unit variance (within 5 %) and no lag-1 correlation (within 0.03).
    fn assert_white(w: &[f64]) {
        let m = w.len() as f64;
        let var = super::super::stats::dot(w, w) / m;
        let lag1 = super::super::stats::dot(&w[1..], &w[..w.len() - 1]) / m / var;
        assert!((var - 1.0).abs() < 0.05, "{var}");
        assert!(lag1.abs() < 0.03, "{lag1}");
    }

    #[test]
    fn whitened_random_walk_plus_white_is_white_and_q_is_recovered() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let nrm = Normal::new(0.0, 1.0).unwrap();
        let n = 20_000;
        let (sw, q): (f64, f64) = (1e-4, 1e-10);
        let t: Vec<f64> = (0..n).map(|i| i as f64).collect();
        let mut lvl = 0.0;
        let y: Vec<f64> = (0..n)
            .map(|_| {
                lvl += q.sqrt() * nrm.sample(&mut rng);
                lvl + sw * nrm.sample(&mut rng)
            })
            .collect();
        let r = vec![sw * sw; n];
        let qh = estimate_q(&t, &r, None, &y, &[]);
        assert!(qh > q / 2.0 && qh < q * 2.0, "{qh}");
        let f = Filter::new(&t, &r, qh, None, |_| true);
        assert_white(&f.whitened(&y));
    }

    #[test]
    fn a_bias_instability_given_whitens_to_white_and_is_not_taken_for_a_random_walk() {
        // White noise, a Gauss–Markov bias (σ 1e-5, τ 200 s) and a weak random walk, one row a
        // second for 5.6 h: with the bias instability in the model the innovations are white
        // and the random walk estimate stays near its own intensity; without it the random walk
        // takes the bias instability's short-scale share 2σ²/τ = 1e-12.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let nrm = Normal::new(0.0, 1.0).unwrap();
        let n = 20_000;
        let (sw, q, gm): (f64, f64, Gm) = (1e-5, 1e-14, Gm { var_g2: 1e-10, tau_s: 200.0 });
        let phi = (-1.0 / gm.tau_s).exp();
        let t: Vec<f64> = (0..n).map(|i| i as f64).collect();
        let (mut lvl, mut b) = (0.0, gm.var_g2.sqrt() * nrm.sample(&mut rng));
        let y: Vec<f64> = (0..n)
            .map(|_| {
                lvl += q.sqrt() * nrm.sample(&mut rng);
                b = phi * b + (gm.var_g2 * (1.0 - phi * phi)).sqrt() * nrm.sample(&mut rng);
                lvl + b + sw * nrm.sample(&mut rng)
            })
            .collect();
        let r = vec![sw * sw; n];
        let (with, without) = (estimate_q(&t, &r, Some(gm), &y, &[]), estimate_q(&t, &r, None, &y, &[]));
        assert!(with < 5.0 * q, "with the bias instability: q {with:e}");
        assert!(without > 0.3 * gm.short_q(), "without it: q {without:e}");
        let f = Filter::new(&t, &r, with, Some(gm), |_| true);
        assert_white(&f.whitened(&y));
    }

    #[test]
    fn a_decayed_column_whitens_without_subnormal_values() {
        // A turn-on term e^(−P/τ) long after power-on passes through the subnormal range
        // (P/τ from 708 to 745); its innovations under a random walk shrink with it. None may
        // be subnormal (each costs a hundred normal multiplications in every Gram product), and
        // the products the Gram matrices are made of stay those of the exact innovations.
        let n = 100_000;
        let t: Vec<f64> = (0..n).map(|i| i as f64).collect();
        let r = vec![1e-10; n];
        let x: Vec<f64> = t.iter().map(|v| (-v / 100.0).exp()).collect();
        let y: Vec<f64> = (0..n).map(|i| 1e-5 * (((i * 7919) % 101) as f64 / 50.0 - 1.0) + 3e-4 * x[i]).collect();
        let f = Filter::new(&t, &r, 1e-14, None, |_| true);
        let (wx, wy) = (f.whitened(&x), f.whitened(&y));
        assert!(x.iter().any(|v| v.is_subnormal()), "the column reaches the subnormal range");
        let sub = wx.iter().filter(|v| v.is_subnormal()).count();
        assert_eq!(sub, 0, "{sub} subnormal innovations");
        // The innovations without the flush, as the filter's recursion defines them.
        let (mut mu, mut exact) = (x[0], vec![0.0; n]);
        for i in 1..n {
            let v = x[i] - mu;
            exact[i] = v * f.inv_sqrt_f[i];
            mu += f.gain[i] * v;
        }
        let (d, d_exact) = (super::super::stats::dot(&wx, &wy), super::super::stats::dot(&exact, &wy));
        assert!((d - d_exact).abs() <= 1e-14 * d_exact.abs(), "{d} vs {d_exact}");
        let (g, g_exact) = (super::super::stats::dot(&wx, &wx), super::super::stats::dot(&exact, &exact));
        assert!((g - g_exact).abs() <= 1e-14 * g_exact, "{g} vs {g_exact}");
    }

    #[test]
    fn whitening_in_row_blocks_equals_whitening_each_column_whole() {
        // Five columns (more than one group of four), rows masked out at the start and in
        // the middle, blocks of uneven length: the same values to the last bit.
        let n = 1000;
        let t: Vec<f64> = (0..n).map(|i| i as f64 * 0.5).collect();
        let r: Vec<f64> = (0..n).map(|i| 1e-8 * (1.0 + 0.3 * (i as f64 * 0.02).cos())).collect();
        // With a bias instability too (two states a column).
        for gm in [None, Some(Gm { var_g2: 1e-8, tau_s: 40.0 })] {
            let f = Filter::new(&t, &r, 1e-9, gm, |i| i >= 3 && !(400..410).contains(&i));
            let cols: Vec<Vec<f64>> =
                (0..5).map(|c| t.iter().map(|v| (v * 0.01 * (c + 1) as f64).sin() + c as f64).collect()).collect();
            let xs: Vec<&[f64]> = cols.iter().map(Vec::as_slice).collect();
            let stride = 300;
            let (mut level, mut out) = (vec![0.0; 5 * f.states()], vec![0.0; 5 * stride]);
            let mut blocks = vec![vec![0.0; n]; 5];
            for (a, b) in [(0, 7), (7, 300), (300, 404), (404, 700), (700, 1000)] {
                f.whiten_rows(&xs, a..b, &mut level, &mut out, stride);
                for c in 0..5 {
                    blocks[c][a..b].copy_from_slice(&out[c * stride..c * stride + b - a]);
                }
            }
            for c in 0..5 {
                assert_eq!(blocks[c], f.whitened(&cols[c]), "{gm:?}: column {c}");
            }
        }
    }

    #[test]
    fn blocked_likelihood_equals_whitening_first() {
        // Over several blocks, with irregular times and a column collinear with another: the
        // block-by-block Gram gives the likelihood of whitening every column whole.
        let n = 1000;
        let t: Vec<f64> = (0..n).map(|i| i as f64 * 0.5 + if i % 7 == 0 { 0.3 } else { 0.0 }).collect();
        let r: Vec<f64> = (0..n).map(|i| 1e-8 * (1.0 + 0.5 * (i as f64 * 0.01).sin())).collect();
        let x1: Vec<f64> = t.iter().map(|v| (v * 0.01).sin()).collect();
        let x2: Vec<f64> = t.iter().map(|v| (v * 0.003).cos() * 1e-3).collect();
        let x3: Vec<f64> = x1.iter().map(|v| -2.0 * v).collect();
        let y: Vec<f64> = (0..n).map(|i| 2e-4 * x1[i] + 0.3 * x2[i] + 1e-4 * ((i * 7919) % 13) as f64).collect();
        let gm = Gm { var_g2: 1e-8, tau_s: 40.0 };
        for (q, gm) in [(0.0, None), (1e-10, None), (1e-6, None), (1e-10, Some(gm)), (0.0, Some(gm))] {
            let (ll, sse, n_used, beta) = profile_ll(&t, &r, q, gm, &y, &[&x1, &x2, &x3]);
            let f = Filter::new(&t, &r, q, gm, |_| true);
            let (sse_ref, beta_ref, log_det_x, p) =
                ls_fit(&f.whitened(&y), &[f.whitened(&x1), f.whitened(&x2), f.whitened(&x3)]);
            let m = f.n_used as f64 - p as f64;
            let ll_ref = -0.5 * (m * (sse_ref / m).ln() + f.log_det + log_det_x + m);
            assert_eq!((n_used, p), (f.n_used, 2));
            assert!((ll - ll_ref).abs() < 1e-9 * ll_ref.abs(), "q {q}: {ll} vs {ll_ref}");
            assert!((sse - sse_ref).abs() < 1e-9 * sse_ref, "q {q}: {sse} vs {sse_ref}");
            for (b, b_ref) in beta.iter().zip(&beta_ref) {
                assert!((b - b_ref).abs() <= 1e-9 * b_ref.abs().max(1e-12), "q {q}: {beta:?} vs {beta_ref:?}");
            }
        }
    }

    #[test]
    fn ls_recovers_coefficients_and_skips_collinear_columns() {
        let x1: Vec<f64> = (0..100).map(|i| (i as f64 * 0.1).sin()).collect();
        let x2: Vec<f64> = (0..100).map(|i| (i as f64 * 0.37).cos()).collect();
        let x3: Vec<f64> = x1.iter().map(|v| 2.0 * v).collect();
        let y: Vec<f64> = x1.iter().zip(&x2).map(|(a, b)| 3.0 * a - 0.5 * b).collect();
        let (sse, b) = ls_sse(&y, &[x1, x2, x3]);
        let yy: f64 = y.iter().map(|v| v * v).sum();
        assert!(sse < 1e-12 * yy, "{sse}");
        assert!((b[0] - 3.0).abs() < 1e-10 && (b[1] + 0.5).abs() < 1e-10 && b[2] == 0.0);
    }

    /// Two Gauss–Markov biases taken as one keep the sum's variance and short-time slope, and
    /// the one wanders at least as far as the sum over every time (the caution the test needs).
    #[test]
    fn two_gauss_markov_biases_merge_into_one_that_wanders_at_least_as_far() {
        let (a, b) = (Gm { var_g2: 4e-12, tau_s: 30.0 }, Gm { var_g2: 9e-12, tau_s: 2000.0 });
        let m = Gm::merged(a, b);
        assert!((m.var_g2 - 13e-12).abs() < 1e-24);
        assert!((m.short_q() - (a.short_q() + b.short_q())).abs() < 1e-12 * m.short_q());
        assert!(m.tau_s > a.tau_s && m.tau_s < b.tau_s, "{}", m.tau_s);
        // The variance of the bias's change over t: 2σ²(1 − e^(−t/τ)).
        let wander = |g: Gm, t: f64| -2.0 * g.var_g2 * (-t / g.tau_s).exp_m1();
        for t in [0.1, 1.0, 10.0, 60.0, 300.0, 1000.0, 5000.0, 1e5] {
            let sum = wander(a, t) + wander(b, t);
            assert!(wander(m, t) >= sum * (1.0 - 1e-12), "t = {t} s: {} < {sum}", wander(m, t));
        }
    }

    /// A noise file's volts become the residual's g through the ratio of the white densities:
    /// the unit at 1 V/g logged at 10 Hz, the residual at 1 Hz of two recordings that each
    /// carry the noise (twice the density): the random walk's and the bias's variances double;
    /// a bias faster than the residual's row is left out, two slower ones become one.
    #[test]
    fn a_noise_file_is_scaled_to_the_residual_by_the_white_densities() {
        use crate::allan::twin::TwinNoise;
        let slow = TwinNoise { white: 1e-5, random_walk: 2e-8, gm: [(3e-6, 300.0), (0.0, 0.0)], adc_step: 0.0 };
        let fast = TwinNoise { gm: [(3e-6, 300.0), (2e-6, 0.5)], ..slow };
        let two = TwinNoise { gm: [(3e-6, 300.0), (2e-6, 40.0)], ..slow };
        let n = SensorNoise { file: "n.toml".into(), tau0_s: 0.1, axes: [slow, fast, two] };
        // The file's density: white² × τ₀ (its random walk and slow bias add < 10⁻⁴ at one sample).
        let density_g2_s = 2.0 * 1e-10 * 0.1;
        let x = n.for_axis(0, density_g2_s, 1.0);
        assert!((x.g_per_v - 2f64.sqrt()).abs() < 1e-4 * 2f64.sqrt(), "{}", x.g_per_v);
        assert!((x.q / (2.0 * 4e-16) - 1.0).abs() < 2e-4, "{}", x.q);
        let gm = x.gm.unwrap();
        assert!((gm.var_g2 / (2.0 * 9e-12) - 1.0).abs() < 2e-4 && gm.tau_s == 300.0, "{gm:?}");
        // The 0.5 s bias is white at 1 s rows: only the 300 s one is kept.
        let y = n.for_axis(1, density_g2_s, 1.0);
        assert_eq!(y.gm.unwrap().tau_s, 300.0);
        // Both slower than a row: one bias with both variances.
        let z = n.for_axis(2, density_g2_s, 1.0);
        let k2 = z.g_per_v * z.g_per_v;
        assert!((z.gm.unwrap().var_g2 - k2 * (9e-12 + 4e-12)).abs() < 1e-9 * k2 * 13e-12);
        assert!(z.gm.unwrap().tau_s > 40.0 && z.gm.unwrap().tau_s < 300.0);
    }

    /// `--noise` reads a scenario's `[noise]` table and rate; a file without noise at one sample
    /// on an accelerometer, or not a scenario, is refused with the file and the key named.
    #[test]
    fn a_noise_file_is_read_and_checked() {
        let dir = tempfile::tempdir().unwrap();
        let scenario = |noise: &str| {
            format!(
                "description = \"quiet\"\n[recording]\nrate_Hz = 10.0\n[unit]\npreset = \"paper\"\n[thermal]\nstart_C = 20.0\n\
                 [noise]\n{noise}\n[[step]]\nkind = \"soak\"\nchamber_C = 20.0\ndwell_s = 100.0\n"
            )
        };
        let path = dir.path().join("n.toml");
        std::fs::write(&path, scenario("white_V = [1e-5, 2e-5, 3e-5]\nbias_instability_V = 3e-6\nbias_tau_s = 300.0"))
            .unwrap();
        let n = SensorNoise::read(&path).unwrap();
        assert_eq!(n.tau0_s, 0.1);
        assert_eq!(n.axes[1].white, 2e-5);
        assert_eq!(n.axes[2].gm[0], (3e-6, 300.0));
        std::fs::write(&path, scenario("white_V = [1e-5, 0.0, 3e-5]")).unwrap();
        let e = SensorNoise::read(&path).unwrap_err().0;
        assert!(e.contains("n.toml") && e.contains("noise.white_V[1]"), "{e}");
        std::fs::write(&path, scenario("white_V = 1e-5\nbias_tau_s = 300.0\nwhite_v = 1.0")).unwrap();
        let e = SensorNoise::read(&path).unwrap_err().0;
        assert!(e.contains("n.toml") && e.contains("white_v"), "{e}");
    }
}

/// One averaging time of the verdict: the spread of block means of the held-out residual
/// against what the measured short-τ noise predicts for them.
#[derive(Clone, Debug, PartialEq)]
pub struct ScalePoint {
    /// Averaging time \[s\] (block of `rows` rows).
    pub tau_s: f64,
    /// Rows per block.
    pub rows: usize,
    /// Blocks.
    pub blocks: usize,
    /// Standard deviation of the block means of the residual before the model \[g\].
    pub before: f64,
    /// The same after the model \[g\].
    pub after: f64,
    /// What the noise alone gives for it \[g\].
    pub noise: f64,
    /// The level above which the spread is structure (one-sided, about 2·10⁻⁴ per scale for
    /// Gaussian noise) \[g\].
    pub limit: f64,
}

/// Upper quantile of χ²ₖ/k at z standard normal deviations (Wilson–Hilferty).
fn chi2_ratio_upper(k: f64, z: f64) -> f64 {
    let a = 2.0 / (9.0 * k);
    (1.0 - a + z * a.sqrt()).powi(3).max(0.0)
}

/// Standard normal deviate of [`ScalePoint::limit`].
pub const SCALE_Z: f64 = 3.5;

/// The residual's structure at every time scale from the first row count at or above 1 s
/// (`m0` rows) up to a tenth of the record, doubling: the standard deviation of the means of
/// consecutive blocks of the held-out residual `before` / `after`, against the noise the
/// measured short-τ level predicts there. The noise: the per-row white variances `r` (from
/// sample-to-sample differences) scaled by `kappa`, the ratio of the Allan variance measured
/// at `m0` rows to what those variances give there — so coloured noise that sample-to-sample
/// differences understate is counted at its measured level — and averaged as white noise:
/// `κ·Σ r_i / m²` for a block of `m` rows. Slow structure (drift, a mechanism the model lacks)
/// stands out at the scales where it lives even when it is far below the per-sample noise.
pub fn structure_scales(before: &[f64], after: &[f64], r: &[f64], kappa: f64, m0: usize, dt: f64) -> Vec<ScalePoint> {
    let n = before.len().min(after.len()).min(r.len());
    let mut out = Vec::new();
    let mut m = m0.max(1);
    while n / m >= 10 {
        let k = n / m;
        let sd = |e: &[f64]| {
            let means: Vec<f64> = (0..k).map(|b| e[b * m..(b + 1) * m].iter().sum::<f64>() / m as f64).collect();
            let mu = means.iter().sum::<f64>() / k as f64;
            (means.iter().map(|x| (x - mu).powi(2)).sum::<f64>() / (k - 1) as f64).sqrt()
        };
        let var_noise = kappa * r[..k * m].iter().sum::<f64>() / (k * m) as f64 / m as f64;
        let noise = var_noise.max(0.0).sqrt();
        out.push(ScalePoint {
            tau_s: m as f64 * dt,
            rows: m,
            blocks: k,
            before: sd(before),
            after: sd(after),
            noise,
            limit: noise * chi2_ratio_upper((k - 1) as f64, SCALE_Z).sqrt(),
        });
        m *= 2;
    }
    out
}

/// The structure above the noise in `points` (`after`: of the residual after the model,
/// else before): its size `√(sd² − noise²)` \[g\] and averaging time \[s\] at the scale where
/// it stands out most (the largest sd / limit), `None` when no scale exceeds its limit.
pub fn structure(points: &[ScalePoint], after: bool) -> Option<(f64, f64)> {
    points
        .iter()
        .map(|p| (p, if after { p.after } else { p.before }))
        .filter(|(p, v)| *v > p.limit)
        .max_by(|a, b| (a.1 / a.0.limit).total_cmp(&(b.1 / b.0.limit)))
        .map(|(p, v)| ((v * v - p.noise * p.noise).max(0.0).sqrt(), p.tau_s))
}
