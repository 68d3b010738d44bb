//! The IEEE noise terms read off an Allan curve (IEEE Std 952-1997 annex C, Std 1293-1998
//! annex C): the Allan variance of a sum of independent noises is the sum of theirs,
//!
//! `σ²(τ) = 3Q²/τ² + N²/τ + (2 ln 2/π)·B² + K²τ/3 + R²τ²/2`,
//!
//! quantisation `Q` (slope −1 of the deviation), white noise `N` (velocity random walk for an
//! accelerometer, slope −½), bias instability `B` (the flat floor of flicker noise, 0.664·B),
//! acceleration random walk `K` (+½) and ramp `R` (+1). The five coefficients are fitted by
//! non-negative weighted least squares to the measured variances, each point weighted by the
//! inverse of its variance `2σ⁴/ν` (ν its degrees of freedom) with `σ²` the model's own value
//! (three reweightings from the measured one), every subset of terms tried and the best
//! non-negative solution kept. A term the curve does not show is 0.

/// `2 ln 2 / π`: the flicker floor's Allan variance over `B²`.
pub const FLICKER_FLOOR: f64 = 2.0 * std::f64::consts::LN_2 / std::f64::consts::PI;

/// The fitted terms in the channel's unit `u` (V, g or °C) and seconds.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Terms {
    /// Quantisation `Q` [u·s].
    pub q: f64,
    /// White noise `N` [u/√Hz = u·√s].
    pub n: f64,
    /// Bias instability `B` \[u\].
    pub b: f64,
    /// Random walk `K` [u/√s].
    pub k: f64,
    /// Ramp `R` [u/s].
    pub r: f64,
}

impl Terms {
    /// The model's Allan variance at `tau` \[s\].
    pub fn avar(&self, tau: f64) -> f64 {
        self.parts(tau).iter().sum()
    }

    /// Each term's Allan variance at `tau`: Q, N, B, K, R.
    pub fn parts(&self, tau: f64) -> [f64; 5] {
        let (b, c) = (basis(tau), self.coefs());
        std::array::from_fn(|i| b[i] * c[i])
    }

    fn coefs(&self) -> [f64; 5] {
        [
            3.0 * self.q * self.q,
            self.n * self.n,
            FLICKER_FLOOR * self.b * self.b,
            self.k * self.k / 3.0,
            self.r * self.r / 2.0,
        ]
    }

    fn from_coefs(c: [f64; 5]) -> Self {
        Terms {
            q: (c[0] / 3.0).max(0.0).sqrt(),
            n: c[1].max(0.0).sqrt(),
            b: (c[2] / FLICKER_FLOOR).max(0.0).sqrt(),
            k: (3.0 * c[3]).max(0.0).sqrt(),
            r: (2.0 * c[4]).max(0.0).sqrt(),
        }
    }
}

/// The basis of the variance: `τ⁻², τ⁻¹, 1, τ, τ²`.
fn basis(tau: f64) -> [f64; 5] {
    [1.0 / (tau * tau), 1.0 / tau, 1.0, tau, tau * tau]
}

/// Non-negative weighted least squares of `y` on the columns `x` (rows × p), every subset of
/// the columns tried: the solution with all coefficients ≥ 0 and the smallest weighted sum of
/// squares. Columns are scaled to unit weighted norm before solving.
pub fn nnls_subsets(x: &[Vec<f64>], y: &[f64], w: &[f64]) -> Vec<f64> {
    let p = x.first().map_or(0, Vec::len);
    let rows = y.len();
    let norm: Vec<f64> =
        (0..p).map(|j| (0..rows).map(|i| w[i] * x[i][j] * x[i][j]).sum::<f64>().sqrt().max(1e-300)).collect();
    let mut best = (f64::INFINITY, vec![0.0; p]);
    for mask in 0u32..(1 << p) {
        let cols: Vec<usize> = (0..p).filter(|j| mask & (1 << j) != 0).collect();
        let k = cols.len();
        let mut a = vec![0.0; k * k];
        let mut b = vec![0.0; k];
        for i in 0..rows {
            for (u, &cu) in cols.iter().enumerate() {
                let xu = x[i][cu] / norm[cu];
                b[u] += w[i] * xu * y[i];
                for (v, &cv) in cols.iter().enumerate() {
                    a[u * k + v] += w[i] * xu * x[i][cv] / norm[cv];
                }
            }
        }
        let Some(sol) = solve(&mut a, &mut b, k) else { continue };
        if sol.iter().any(|&c| !(c >= 0.0)) {
            continue;
        }
        let mut coef = vec![0.0; p];
        for (u, &c) in cols.iter().enumerate() {
            coef[c] = sol[u] / norm[c];
        }
        let sse: f64 = (0..rows).map(|i| w[i] * (y[i] - (0..p).map(|j| x[i][j] * coef[j]).sum::<f64>()).powi(2)).sum();
        if sse < best.0 {
            best = (sse, coef);
        }
    }
    best.1
}

/// Gaussian elimination with partial pivoting; `None` when singular.
fn solve(a: &mut [f64], b: &mut [f64], k: usize) -> Option<Vec<f64>> {
    for c in 0..k {
        let piv = (c..k).max_by(|&i, &j| a[i * k + c].abs().total_cmp(&a[j * k + c].abs()))?;
        if !(a[piv * k + c].abs() > 1e-12) {
            return None;
        }
        if piv != c {
            for j in 0..k {
                a.swap(c * k + j, piv * k + j);
            }
            b.swap(c, piv);
        }
        for i in c + 1..k {
            let f = a[i * k + c] / a[c * k + c];
            for j in c..k {
                a[i * k + j] -= f * a[c * k + j];
            }
            b[i] -= f * b[c];
        }
    }
    let mut x = vec![0.0; k];
    for i in (0..k).rev() {
        let s: f64 = (i + 1..k).map(|j| a[i * k + j] * x[j]).sum();
        x[i] = (b[i] - s) / a[i * k + i];
    }
    Some(x)
}

/// Fits the terms to the points `(τ [s], Allan variance, ν)`; points without degrees of
/// freedom weigh as one.
pub fn fit(points: &[(f64, f64, f64)]) -> Terms {
    let pts: Vec<&(f64, f64, f64)> = points.iter().filter(|p| p.0 > 0.0 && p.1 > 0.0).collect();
    if pts.is_empty() {
        return Terms::default();
    }
    let x: Vec<Vec<f64>> = pts.iter().map(|p| basis(p.0).to_vec()).collect();
    let y: Vec<f64> = pts.iter().map(|p| p.1).collect();
    let nu = |p: &(f64, f64, f64)| if p.2.is_finite() && p.2 > 0.0 { p.2 } else { 1.0 };
    let mut w: Vec<f64> = pts.iter().map(|p| nu(p) / (2.0 * p.1 * p.1)).collect();
    let mut terms = Terms::default();
    for _ in 0..4 {
        let c = nnls_subsets(&x, &y, &w);
        terms = Terms::from_coefs([c[0], c[1], c[2], c[3], c[4]]);
        w = pts.iter().map(|p| nu(p) / (2.0 * terms.avar(p.0).max(1e-3 * p.1).powi(2))).collect();
    }
    terms
}
