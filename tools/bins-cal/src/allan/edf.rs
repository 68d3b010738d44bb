//! Equivalent degrees of freedom of the overlapping Allan and Hadamard variances for a
//! power-law noise (Greenhall & Riley 2003, "Uncertainty of stability variances based on finite
//! differences", 35th PTTI; the algorithm of their section 4 with Tables 1–3), and the χ²
//! confidence interval they give (NIST SP 1065, eq. 45).
//!
//! The estimate `σ̂²` of a variance whose estimator behaves as `σ²·χ²_ν/ν` lies in
//! `[ν σ̂²/χ²_ν(1 − p/2), ν σ̂²/χ²_ν(p/2)]` with probability `1 − p`. Greenhall and Riley give `ν`
//! for phase differences of order `d` (2 for the Allan, 3 for the Hadamard variance) of a
//! power-law noise `S_y(f) ∝ f^α` from the noise's generalized autocovariance: an exact sum
//! for few terms, a two-coefficient table for many.

/// `s_w(t)` of the phase noise of type `α` (their eq. 7): the generalized autocovariance up
/// to a constant.
fn sw(t: f64, alpha: i32) -> f64 {
    let lg = |t: f64, k: i32| if t == 0.0 { 0.0 } else { t.powi(k) * t.abs().ln() };
    match alpha {
        2 => -t.abs(),
        1 => lg(t, 2),
        0 => t.abs().powi(3),
        -1 => lg(t, 4),
        -2 => t.abs().powi(5),
        -3 => lg(t, 6),
        _ => t.abs().powi(7),
    }
}

/// `s_x(t)` (eq. 8): the filter factor `F` (`m` for the unmodified variances; ∞ is the limit).
fn sx(t: f64, f: f64, alpha: i32) -> f64 {
    if f.is_infinite() {
        return sw(t, alpha + 2);
    }
    f * f * (2.0 * sw(t, alpha) - sw(t - 1.0 / f, alpha) - sw(t + 1.0 / f, alpha))
}

/// `s_z(t)` (eq. 9): the `d`-th difference's autocovariance.
fn sz(t: f64, f: f64, alpha: i32, d: usize) -> f64 {
    let x = |k: f64| sx(t + k, f, alpha);
    match d {
        1 => 2.0 * x(0.0) - x(-1.0) - x(1.0),
        2 => 6.0 * x(0.0) - 4.0 * x(-1.0) - 4.0 * x(1.0) + x(-2.0) + x(2.0),
        _ => 20.0 * x(0.0) - 15.0 * x(-1.0) - 15.0 * x(1.0) + 6.0 * x(-2.0) + 6.0 * x(2.0) - x(-3.0) - x(3.0),
    }
}

/// The basic sum (eq. 10).
fn basic_sum(j: f64, m_terms: f64, s: f64, f: f64, alpha: i32, d: usize) -> f64 {
    let mut sum = sz(0.0, f, alpha, d).powi(2) + (1.0 - j / m_terms) * sz(j / s, f, alpha, d).powi(2);
    for k in 1..(j as usize) {
        let k = k as f64;
        sum += 2.0 * (1.0 - k / m_terms) * sz(k / s, f, alpha, d).powi(2);
    }
    sum
}

/// Table 2 (unmodified variances): `(a0, a1)` for `α` 2 … −4 and `d` 1 … 3.
fn table2(alpha: i32, d: usize) -> Option<(f64, f64)> {
    const T: [[(f64, f64); 3]; 7] = [
        [(3.0 / 2.0, 1.0 / 2.0), (35.0 / 18.0, 1.0), (231.0 / 100.0, 3.0 / 2.0)],
        [(78.6, 25.2), (790.0, 410.0), (9950.0, 6520.0)],
        [(2.0 / 3.0, 1.0 / 6.0), (2.0 / 3.0, 1.0 / 3.0), (7.0 / 9.0, 1.0 / 2.0)],
        [(f64::NAN, f64::NAN), (0.852, 0.375), (0.997, 0.617)],
        [(f64::NAN, f64::NAN), (1.079, 0.368), (1.033, 0.607)],
        [(f64::NAN, f64::NAN), (f64::NAN, f64::NAN), (1.053, 0.553)],
        [(f64::NAN, f64::NAN), (f64::NAN, f64::NAN), (1.302, 0.535)],
    ];
    let v = T.get((2 - alpha) as usize)?.get(d.checked_sub(1)?)?;
    v.0.is_finite().then_some(*v)
}

/// Table 3 (`α = 1`, unmodified): `(b0, b1)` for `d` 1 … 3.
fn table3(d: usize) -> (f64, f64) {
    [(6.0, 4.0), (15.23, 12.0), (47.8, 40.0)][d.clamp(1, 3) - 1]
}

/// Binomial coefficient (small arguments).
fn binom(n: usize, k: usize) -> f64 {
    (0..k).fold(1.0, |acc, i| acc * (n - i) as f64 / (i + 1) as f64)
}

/// The largest basic sum evaluated term by term (`J_max`).
const J_MAX: f64 = 100.0;

/// Equivalent degrees of freedom of the unmodified variance of difference order `d`
/// (2 Allan, 3 Hadamard) at cluster size `m`, from `n_phase` phase points, overlapping
/// (stride 1) or not (stride `m`), for noise type `α`; `None` when the variance does not
/// converge for that noise (`α + 2d ≤ 1`) or there is no term.
pub fn greenhall(alpha: i32, d: usize, m: f64, n_phase: f64, overlapping: bool) -> Option<f64> {
    if !(-4..=2).contains(&alpha) || alpha + 2 * d as i32 <= 1 || !(1..=3).contains(&d) || !(m >= 1.0) {
        return None;
    }
    let f = m;
    let s = if overlapping { m } else { 1.0 };
    let l = m / f + m * d as f64;
    if n_phase < l {
        return None;
    }
    let m_terms = 1.0 + (s * (n_phase - l) / m).floor();
    let j = m_terms.min((d + 1) as f64 * s);
    let r = m_terms / s;
    let inv = if alpha <= 0 {
        if j <= J_MAX {
            let mp = if m * (d + 1) as f64 <= J_MAX { m } else { f64::INFINITY };
            basic_sum(j, m_terms, s, mp, alpha, d) / (sz(0.0, mp, alpha, d).powi(2) * m_terms)
        } else if r > (d + 1) as f64 {
            let (a0, a1) = table2(alpha, d)?;
            (a0 - a1 / r) / r
        } else {
            let mp = J_MAX / r;
            basic_sum(J_MAX, J_MAX, mp, f64::INFINITY, alpha, d) / (sz(0.0, f64::INFINITY, alpha, d).powi(2) * J_MAX)
        }
    } else if alpha == 1 {
        let (b0, b1) = table3(d);
        if j <= J_MAX {
            basic_sum(j, m_terms, s, m, 1, d) / (sz(0.0, m, 1, d).powi(2) * m_terms)
        } else if r > (d + 1) as f64 {
            let (a0, a1) = table2(1, d)?;
            (a0 - a1 / r) / ((b0 + b1 * m.ln()).powi(2) * r)
        } else {
            let mp = J_MAX / r;
            basic_sum(J_MAX, J_MAX, mp, mp, 1, d) / ((b0 + b1 * m.ln()).powi(2) * J_MAX)
        }
    } else {
        // α = 2: few terms by the exact sum, else the closed form.
        if r.ceil() <= d as f64 {
            basic_sum(j, m_terms, s, m, 2, d) / (sz(0.0, m, 2, d).powi(2) * m_terms)
        } else {
            let a0 = binom(4 * d, 2 * d) / binom(2 * d, d).powi(2);
            (a0 - d as f64 / 2.0 / r) / m_terms
        }
    };
    (inv > 0.0 && inv.is_finite()).then(|| 1.0 / inv)
}

/// `P(χ²_ν ≤ x)`.
fn chi2_cdf(x: f64, nu: f64) -> f64 {
    1.0 - crate::diagnose::stats::chi2_sf(x, nu)
}

/// The `p` quantile of χ² with `ν` degrees of freedom (`0 < p < 1`, `ν > 0`): bisection in
/// `ln x` on the regularized incomplete gamma function, to 1e-12 relative.
pub fn chi2_quantile(p: f64, nu: f64) -> f64 {
    // Bracket around the Wilson–Hilferty approximation.
    let (mut lo, mut hi) = (1e-300f64.ln(), (nu + 50.0 * (2.0 * nu).sqrt() + 100.0).ln());
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if chi2_cdf(mid.exp(), nu) < p {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo < 1e-13 {
            break;
        }
    }
    (0.5 * (lo + hi)).exp()
}

/// The confidence interval `(lower, upper)` of a deviation `dev` estimated with `ν` degrees
/// of freedom, at confidence `level` (e.g. 0.95).
pub fn interval(dev: f64, nu: f64, level: f64) -> (f64, f64) {
    let tail = 0.5 * (1.0 - level);
    let var = dev * dev;
    let lower = nu * var / chi2_quantile(1.0 - tail, nu);
    let upper = nu * var / chi2_quantile(tail, nu);
    (lower.sqrt(), upper.sqrt())
}
