//! Small numerical helpers of the diagnosis: a Cholesky solver and log-determinant for the
//! few-column least-squares problems (normal equations of columns scaled to unit norm), Gram
//! matrices in row blocks, the χ² tail probability, the noncentral χ² distribution, the
//! overlapping Allan deviation and Hadamard variance (of [`crate::allan`]).

/// The Cholesky factor `L` (row-major, lower) of a symmetric positive-definite `A` (`p×p`);
/// `None` when a pivot is not above `rel_tol` times its diagonal element or that element is
/// not positive (the columns are collinear on this data).
fn chol_factor(a: &[f64], p: usize, rel_tol: f64) -> Option<Vec<f64>> {
    let mut l = vec![0.0; p * p];
    for i in 0..p {
        for j in 0..=i {
            let mut s = a[i * p + j];
            for k in 0..j {
                s -= l[i * p + k] * l[j * p + k];
            }
            if i == j {
                let d = a[i * p + i];
                if !(s > rel_tol * d.abs()) || !(d > 0.0) {
                    return None;
                }
                l[i * p + i] = s.sqrt();
            } else {
                l[i * p + j] = s / l[j * p + j];
            }
        }
    }
    Some(l)
}

/// `ln det A` of a symmetric positive-definite `A` (`p×p`, row-major) by Cholesky; `None`
/// when it is not positive definite.
pub fn chol_logdet(a: &[f64], p: usize) -> Option<f64> {
    let l = chol_factor(a, p, 0.0)?;
    Some((0..p).map(|i| 2.0 * l[i * p + i].ln()).sum())
}

/// Solves `A·x = b` for a symmetric positive-definite `A` (`p×p`, row-major) by Cholesky.
/// Returns `None` when a pivot falls below `rel_tol` times its diagonal element (the columns
/// are collinear on this data). Also returns the diagonal of `A⁻¹` (for standard errors).
pub fn chol_solve(a: &[f64], b: &[f64], p: usize, rel_tol: f64) -> Option<(Vec<f64>, Vec<f64>)> {
    let l = chol_factor(a, p, rel_tol)?;
    let fwd = |rhs: &[f64]| {
        let mut y = rhs.to_vec();
        for i in 0..p {
            let mut s = y[i];
            for k in 0..i {
                s -= l[i * p + k] * y[k];
            }
            y[i] = s / l[i * p + i];
        }
        y
    };
    let back = |y: &[f64]| {
        let mut x = y.to_vec();
        for i in (0..p).rev() {
            let mut s = x[i];
            for k in i + 1..p {
                s -= l[k * p + i] * x[k];
            }
            x[i] = s / l[i * p + i];
        }
        x
    };
    let x = back(&fwd(b));
    // diag(A⁻¹) = diag(L⁻ᵀ·L⁻¹): column sums of the squares of L⁻¹.
    let mut linv = vec![0.0; p * p];
    for j in 0..p {
        let mut e = vec![0.0; p];
        e[j] = 1.0;
        let y = fwd(&e);
        for i in 0..p {
            linv[i * p + j] = y[i];
        }
    }
    let mut diag = vec![0.0; p];
    for (j, d) in diag.iter_mut().enumerate() {
        for i in 0..p {
            *d += linv[i * p + j] * linv[i * p + j];
        }
    }
    Some((x, diag))
}

/// `ln Γ(x)` for `x > 0` (Lanczos, 15 digits).
fn ln_gamma(x: f64) -> f64 {
    const G: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        return (std::f64::consts::PI / (std::f64::consts::PI * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut a = G[0];
    let t = x + 7.5;
    for (i, g) in G.iter().enumerate().skip(1) {
        a += g / (x + i as f64);
    }
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// Regularized upper incomplete gamma `Q(s, x)`.
fn gamma_q(s: f64, x: f64) -> f64 {
    if !(x > 0.0) {
        return 1.0;
    }
    let lg = ln_gamma(s);
    if x < s + 1.0 {
        // Series for P.
        let (mut sum, mut term, mut n) = (1.0 / s, 1.0 / s, s);
        for _ in 0..10_000 {
            n += 1.0;
            term *= x / n;
            sum += term;
            if term.abs() < sum.abs() * 1e-16 {
                break;
            }
        }
        (1.0 - sum * (-x + s * x.ln() - lg).exp()).max(0.0)
    } else {
        // Continued fraction for Q (Lentz).
        let tiny = 1e-300;
        let mut b = x + 1.0 - s;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..10_000 {
            let an = -(i as f64) * (i as f64 - s);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let del = d * c;
            h *= del;
            if (del - 1.0).abs() < 1e-16 {
                break;
            }
        }
        ((-x + s * x.ln() - lg).exp() * h).clamp(0.0, 1.0)
    }
}

/// `P(χ²_k > x)`.
pub fn chi2_sf(x: f64, k: f64) -> f64 {
    gamma_q(0.5 * k, 0.5 * x)
}

/// The `x` with `P(χ²_k > x) = p` (bisection on [`chi2_sf`], to 10⁻⁹ relative).
pub fn chi2_isf(p: f64, k: f64) -> f64 {
    let (mut lo, mut hi) = (0.0, k.max(1.0));
    while chi2_sf(hi, k) > p && hi < 1e6 {
        hi *= 2.0;
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if chi2_sf(mid, k) > p {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo <= 1e-9 * hi {
            break;
        }
    }
    0.5 * (lo + hi)
}

/// `P(X ≤ x)` for `X` a noncentral χ² of `k` degrees of freedom and noncentrality `lambda`
/// (the sum of `k` squared unit normals whose means' squares sum to `lambda`): the Poisson
/// mixture `Σⱼ e^(−λ/2) (λ/2)ʲ/j! · P(χ²_{k+2j} ≤ x)`, summed outward from its largest
/// weight until the weights fall below 10⁻¹⁷ of the total. The central χ² probabilities come
/// from one incomplete gamma function at the largest weight and the recurrence
/// `P(χ²_{2a+2} ≤ x) = P(χ²_{2a} ≤ x) − (x/2)^a e^(−x/2)/Γ(a+1)` outward from it.
pub fn ncx2_cdf(x: f64, k: f64, lambda: f64) -> f64 {
    if !(x > 0.0) {
        return 0.0;
    }
    if !(lambda > 0.0) {
        return 1.0 - chi2_sf(x, k);
    }
    let (h, y) = (0.5 * lambda, 0.5 * x);
    let j0 = h.floor();
    let weight = |j: f64| (-h + j * h.ln() - ln_gamma(j + 1.0)).exp();
    // (x/2)^a e^(−x/2) / Γ(a+1): the step of the recurrence from a to a + 1.
    let step = |a: f64| (a * y.ln() - y - ln_gamma(a + 1.0)).exp();
    let a0 = 0.5 * k + j0;
    let p0 = 1.0 - gamma_q(a0, y);
    let (mut sum, mut wsum) = (weight(j0) * p0, weight(j0));
    let (mut j, mut p) = (j0 - 1.0, p0);
    while j >= 0.0 {
        p = (p + step(0.5 * k + j)).min(1.0);
        let w = weight(j);
        sum += w * p;
        wsum += w;
        if w < 1e-17 * wsum {
            break;
        }
        j -= 1.0;
    }
    let (mut j, mut p) = (j0 + 1.0, p0);
    loop {
        p = (p - step(0.5 * k + j - 1.0)).max(0.0);
        let w = weight(j);
        sum += w * p;
        wsum += w;
        if w < 1e-17 * wsum {
            break;
        }
        j += 1.0;
    }
    sum.clamp(0.0, 1.0)
}

/// The `x` with `P(X ≤ x) = p` for the noncentral χ² of [`ncx2_cdf`] ([`quantile_of`]).
pub fn ncx2_quantile(p: f64, k: f64, lambda: f64) -> f64 {
    let lambda = lambda.max(0.0);
    quantile_of(&|x| ncx2_cdf(x, k, lambda), p, k + lambda + 10.0 * (2.0 * (k + 2.0 * lambda)).sqrt() + 10.0)
}

/// The `x ≥ 0` with `cdf(x) = p` for a distribution on `[0, ∞)`: the bracket `[0, hi]` doubled
/// until it holds `p` (up to 10¹²), then bisection to 10⁻¹⁰ relative.
pub fn quantile_of(cdf: &dyn Fn(f64) -> f64, p: f64, hi: f64) -> f64 {
    let (mut lo, mut hi) = (0.0, hi.max(1e-12));
    while cdf(hi) < p && hi < 1e12 {
        hi *= 2.0;
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if cdf(mid) < p {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo <= 1e-10 * hi {
            break;
        }
    }
    0.5 * (lo + hi)
}

/// Overlapping Allan deviation at cluster sizes `ms` (samples), pooled over `segments` (each a
/// run of equally spaced samples). Returns `(m, adev, n_terms)` for every `m` with at least
/// two terms in a segment ([`crate::allan::pooled`]).
pub fn allan_dev(segments: &[&[f64]], ms: &[usize]) -> Vec<(usize, f64, usize)> {
    crate::allan::pooled(crate::allan::Kind::Allan, segments, ms)
        .into_iter()
        .map(|(m, v, n)| (m, v.sqrt(), n))
        .collect()
}

/// Overlapping Hadamard variance at cluster sizes `ms`, pooled over `segments`:
/// `⅙⟨(ȳ_{k+2} − 2ȳ_{k+1} + ȳ_k)²⟩` of the cluster means. Blind to a constant slope (a
/// temperature ramp's share of the residual), `σ²/m` for white noise of variance `σ²` and
/// `q·τ/6` for a random walk of intensity `q`. Returns `(m, hvar, n_terms)`
/// ([`crate::allan::pooled`]).
pub fn hadamard_var(segments: &[&[f64]], ms: &[usize]) -> Vec<(usize, f64, usize)> {
    crate::allan::pooled(crate::allan::Kind::Hadamard, segments, ms)
}

/// Rows per block of [`gram_blocked`]: the block of every column stays in cache while all
/// pairs are multiplied (the columns themselves are far larger than the cache).
pub const GRAM_BLOCK: usize = 256;

/// `Σ w_a·w_b` over the rows of `rows` (all rows when `None`), every pair `a ≤ b`, computed
/// block by block of rows; the full symmetric matrix, row-major.
pub fn gram_blocked<C: AsRef<[f64]>>(w: &[C], rows: Option<&[(usize, usize)]>) -> Vec<f64> {
    let p = w.len();
    let n = w.first().map_or(0, |c| c.as_ref().len());
    let all = [(0, n)];
    let rows = rows.unwrap_or(&all);
    let mut g = vec![0.0; p * p];
    for &(s, e) in rows {
        let mut c0 = s;
        while c0 < e {
            let c1 = (c0 + GRAM_BLOCK).min(e);
            for a in 0..p {
                let wa = &w[a].as_ref()[c0..c1];
                for b in a..p {
                    g[a * p + b] += dot(wa, &w[b].as_ref()[c0..c1]);
                }
            }
            c0 = c1;
        }
    }
    for a in 0..p {
        for b in 0..a {
            g[a * p + b] = g[b * p + a];
        }
    }
    g
}

/// Dot product with four accumulators (vectorises).
#[inline]
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut acc = [0.0f64; 4];
    let chunks = n / 4;
    for c in 0..chunks {
        let i = 4 * c;
        acc[0] += a[i] * b[i];
        acc[1] += a[i + 1] * b[i + 1];
        acc[2] += a[i + 2] * b[i + 2];
        acc[3] += a[i + 3] * b[i + 3];
    }
    let mut s = (acc[0] + acc[1]) + (acc[2] + acc[3]);
    for i in 4 * chunks..n {
        s += a[i] * b[i];
    }
    s
}

/// Median of a slice (copies); NaN for an empty slice.
pub fn median(v: &[f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut w = v.to_vec();
    w.sort_by(f64::total_cmp);
    let n = w.len();
    if n % 2 == 1 { w[n / 2] } else { 0.5 * (w[n / 2 - 1] + w[n / 2]) }
}

/// The minimum of `f` on `[lo, hi]` by `steps` golden-section steps: the better of the last two
/// interior points and its value (`f` assumed unimodal there; the ends are not evaluated).
pub fn golden_min(lo: f64, hi: f64, steps: usize, f: impl Fn(f64) -> f64) -> (f64, f64) {
    let phi = 0.618_033_988_749_894_9;
    let (mut lo, mut hi) = (lo, hi);
    let (mut c, mut d) = (hi - phi * (hi - lo), lo + phi * (hi - lo));
    let (mut fc, mut fd) = (f(c), f(d));
    for _ in 0..steps {
        if fc < fd {
            hi = d;
            d = c;
            fd = fc;
            c = hi - phi * (hi - lo);
            fc = f(c);
        } else {
            lo = c;
            c = d;
            fc = fd;
            d = lo + phi * (hi - lo);
            fd = f(d);
        }
    }
    if fc < fd { (c, fc) } else { (d, fd) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chi2_tail_matches_known_values() {
        // χ²₁: P(>3.841459) = 0.05; χ²₂: P(>x) = exp(−x/2); χ²₁₀: P(>23.209251) = 0.01.
        assert!((chi2_sf(3.841_458_820_694_124, 1.0) - 0.05).abs() < 1e-10);
        for x in [0.1, 1.0, 7.0, 40.0] {
            assert!((chi2_sf(x, 2.0) / (-x / 2.0f64).exp() - 1.0).abs() < 1e-10);
        }
        assert!((chi2_sf(23.209_251_158_954_356, 10.0) - 0.01).abs() < 1e-10);
    }

    /// `Φ(z)` by Simpson's rule on the normal density (an independent route to the df = 1 case).
    fn phi_cdf(z: f64) -> f64 {
        let n = 4000;
        let h = z / n as f64;
        let f = |u: f64| (-0.5 * u * u).exp() / (2.0 * std::f64::consts::PI).sqrt();
        let mut s = f(0.0) + f(z);
        for i in 1..n {
            s += if i % 2 == 1 { 4.0 } else { 2.0 } * f(i as f64 * h);
        }
        0.5 + s * h / 3.0
    }

    #[test]
    fn noncentral_chi2_with_one_degree_is_a_shifted_normal_squared() {
        // X = (Z + √λ)²: P(X ≤ x) = Φ(√x − √λ) − Φ(−√x − √λ).
        for lambda in [0.5, 4.0, 30.0, 400.0] {
            let m = f64::sqrt(lambda);
            for x in [0.2f64, 1.0, 5.0, 25.0, 80.0, 350.0, 500.0] {
                let want = phi_cdf(x.sqrt() - m) - phi_cdf(-x.sqrt() - m);
                let got = ncx2_cdf(x, 1.0, lambda);
                assert!((got - want).abs() < 1e-9, "λ {lambda}, x {x}: {got} vs {want}");
            }
            for p in [0.05, 0.5, 0.95] {
                let q = ncx2_quantile(p, 1.0, lambda);
                let at = phi_cdf(q.sqrt() - m) - phi_cdf(-q.sqrt() - m);
                assert!((at - p).abs() < 1e-8, "λ {lambda}, p {p}: quantile {q} has cdf {at}");
            }
        }
        // λ = 0 is the central χ².
        for k in [1.0, 3.0, 7.0] {
            let q = ncx2_quantile(0.95, k, 0.0);
            assert!((q / chi2_isf(0.05, k) - 1.0).abs() < 1e-8, "k {k}: {q}");
        }
    }

    #[test]
    fn noncentral_chi2_quantiles_match_monte_carlo() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let n = 200_000;
        for (k, lambda) in [(4usize, 9.0), (2, 150.0), (6, 2500.0)] {
            // Means spread unevenly over the k components, their squares summing to λ.
            let w: Vec<f64> = (1..=k).map(|i| i as f64).collect();
            let ws: f64 = w.iter().sum();
            let mu: Vec<f64> = w.iter().map(|v| (lambda * v / ws).sqrt()).collect();
            let (q05, q95) = (ncx2_quantile(0.05, k as f64, lambda), ncx2_quantile(0.95, k as f64, lambda));
            let (mut below, mut above, mut mean) = (0usize, 0usize, 0.0);
            for _ in 0..n {
                let x: f64 = mu
                    .iter()
                    .map(|m| {
                        let z: f64 = StandardNormal.sample(&mut rng);
                        (z + m).powi(2)
                    })
                    .sum();
                below += usize::from(x < q05);
                above += usize::from(x > q95);
                mean += x / n as f64;
            }
            // Binomial standard error of a 5 % fraction over 200 000 draws: 0.00049.
            let (fb, fa) = (below as f64 / n as f64, above as f64 / n as f64);
            assert!((fb - 0.05).abs() < 0.0025 && (fa - 0.05).abs() < 0.0025, "k {k}, λ {lambda}: {fb} {fa}");
            let sd = (2.0 * (k as f64 + 2.0 * lambda) / n as f64).sqrt();
            assert!((mean - (k as f64 + lambda)).abs() < 5.0 * sd, "k {k}, λ {lambda}: mean {mean}");
        }
    }

    #[test]
    fn cholesky_solves_and_inverts() {
        let a = [4.0, 2.0, 0.6, 2.0, 5.0, 1.0, 0.6, 1.0, 3.0];
        let x_true = [1.0, -2.0, 0.5];
        let b: Vec<f64> = (0..3).map(|i| (0..3).map(|j| a[i * 3 + j] * x_true[j]).sum()).collect();
        let (x, d) = chol_solve(&a, &b, 3, 1e-12).unwrap();
        for i in 0..3 {
            assert!((x[i] - x_true[i]).abs() < 1e-12);
        }
        // diag(A⁻¹) by cofactors.
        let det = 4.0 * (15.0 - 1.0) - 2.0 * (6.0 - 0.6) + 0.6 * (2.0 - 3.0);
        assert!((d[0] - 14.0 / det).abs() < 1e-12);
        assert!((d[1] - (12.0 - 0.36) / det).abs() < 1e-12);
        assert!((d[2] - 16.0 / det).abs() < 1e-12);
        assert!(chol_solve(&[1.0, 1.0, 1.0, 1.0], &[1.0, 1.0], 2, 1e-9).is_none());
    }

    #[test]
    fn allan_of_white_noise_is_sigma_over_sqrt_m() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let n = Normal::new(0.0, 2.0).unwrap();
        let x: Vec<f64> = (0..200_000).map(|_| n.sample(&mut rng)).collect();
        let a = allan_dev(&[&x], &[1, 16]);
        assert!((a[0].1 / 2.0 - 1.0).abs() < 0.01, "{:?}", a);
        assert!((a[1].1 / (2.0 / 4.0) - 1.0).abs() < 0.03, "{:?}", a);
    }
}
