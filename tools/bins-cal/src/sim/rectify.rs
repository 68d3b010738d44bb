//! Rectified means: the time mean of an accelerometer's conversion function V(2) over the
//! vibration, by quadrature of the core's [`ConversionFunction::eval_g`] (not by the closed
//! forms of V(13)/V(14), which the tests compare against).
//!
//! - Harmonic vibration `a(θ) = a_p + a_B·sin θ` (all axes in phase): the mean over one
//!   period, composite Gauss–Legendre on panels whose ends include the zeros of the IA
//!   component (where `|a3|` has its kink), so each panel's integrand is smooth.
//! - Broadband random vibration, Gaussian and fully correlated (`ã = σ·ξ`, ξ standard normal):
//!   the expectation over ξ, composite Gauss–Legendre on `[−12, 12]` against the normal
//!   density, again split at the kink `ξ* = −a_p3/σ3`. (Gauss–Hermite would integrate the
//!   polynomial part exactly but converges slowly across the `|a3|` kink; the split panels
//!   do both to rounding.)
//!
//! The simulator adds `K_ii(T)·⟨N_i⟩` to each signal, where `N_i` is V(2) without its linear
//! part (`a0 + a3 + m1 a1 + m2 a2`, which T(1)'s constants already carry).

use bins_comp::vibration::{AccelAxes, Axis, ConversionFunction, Vibration};

/// Gauss–Legendre nodes and weights on [−1, 1] (16 points), computed once by Newton's method
/// on the Legendre polynomial.
fn gauss_legendre_16() -> &'static ([f64; 16], [f64; 16]) {
    static GL: std::sync::OnceLock<([f64; 16], [f64; 16])> = std::sync::OnceLock::new();
    GL.get_or_init(|| {
        const N: usize = 16;
        let mut x = [0.0; N];
        let mut w = [0.0; N];
        for i in 0..N {
            let mut z = (std::f64::consts::PI * (i as f64 + 0.75) / (N as f64 + 0.5)).cos();
            let mut dp = 0.0;
            for _ in 0..100 {
                let (mut p0, mut p1) = (1.0, z);
                for k in 2..=N {
                    let p2 = ((2 * k - 1) as f64 * z * p1 - (k - 1) as f64 * p0) / k as f64;
                    p0 = p1;
                    p1 = p2;
                }
                dp = N as f64 * (z * p1 - p0) / (z * z - 1.0);
                let dz = p1 / dp;
                z -= dz;
                if dz.abs() < 1e-16 {
                    break;
                }
            }
            x[i] = z;
            w[i] = 2.0 / ((1.0 - z * z) * dp * dp);
        }
        (x, w)
    })
}

/// `∫ f` over `[a, b]` split at the sorted `breaks` (those inside) and into panels no wider
/// than `max_panel`, 16-point Gauss–Legendre on each.
fn integrate(a: f64, b: f64, breaks: &[f64], max_panel: f64, mut f: impl FnMut(f64) -> f64) -> f64 {
    let (x, w) = gauss_legendre_16();
    let mut ends = vec![a];
    ends.extend(breaks.iter().copied().filter(|&t| t > a && t < b));
    ends.push(b);
    ends.sort_by(f64::total_cmp);
    let mut sum = 0.0;
    for pair in ends.windows(2) {
        let (lo, hi) = (pair[0], pair[1]);
        let n = ((hi - lo) / max_panel).ceil().max(1.0) as usize;
        let h = (hi - lo) / n as f64;
        for p in 0..n {
            let (c, r) = (lo + (p as f64 + 0.5) * h, 0.5 * h);
            let mut s = 0.0;
            for k in 0..16 {
                s += w[k] * f(c + r * x[k]);
            }
            sum += r * s;
        }
    }
    sum
}

/// V(2) without its linear part: `a_u − (a0 + a3 + m1 a1 + m2 a2)` \[g\], through the core's
/// [`ConversionFunction::eval_g`].
pub fn nonlinear_g(cf: &ConversionFunction<f64>, a: AccelAxes<f64>) -> f64 {
    cf.eval_g(a) - (cf.a0_g + a.ia + cf.m1_g_per_g * a.oa + cf.m2_g_per_g * a.pa)
}

fn add(p: AccelAxes<f64>, v: AccelAxes<f64>, s: f64) -> AccelAxes<f64> {
    AccelAxes { ia: p.ia + s * v.ia, pa: p.pa + s * v.pa, oa: p.oa + s * v.oa }
}

/// `⟨N(a_p + a_B sin θ)⟩` over one period \[g\] (harmonic, in phase).
pub fn harmonic_mean_g(cf: &ConversionFunction<f64>, a_p: AccelAxes<f64>, amp: AccelAxes<f64>) -> f64 {
    use std::f64::consts::{PI, TAU};
    let mut breaks = Vec::new();
    if amp.ia != 0.0 && a_p.ia.abs() < amp.ia.abs() {
        let t1 = (-a_p.ia / amp.ia).asin();
        breaks.push(t1.rem_euclid(TAU));
        breaks.push((PI - t1).rem_euclid(TAU));
    }
    integrate(0.0, TAU, &breaks, TAU / 8.0, |t| nonlinear_g(cf, add(a_p, amp, t.sin()))) / TAU
}

/// `E[N(a_p + σ ξ)]` over a standard normal ξ \[g\] (Gaussian, fully correlated axes).
pub fn gaussian_mean_g(cf: &ConversionFunction<f64>, a_p: AccelAxes<f64>, sigma: AccelAxes<f64>) -> f64 {
    const L: f64 = 12.0;
    let norm = 1.0 / (2.0 * std::f64::consts::PI).sqrt();
    let mut breaks = Vec::new();
    if sigma.ia != 0.0 {
        breaks.push(-a_p.ia / sigma.ia);
    }
    integrate(-L, L, &breaks, 1.0, |x| norm * (-0.5 * x * x).exp() * nonlinear_g(cf, add(a_p, sigma, x)))
}

/// The rectified mean `⟨N_i⟩` \[g\] of each accelerometer (unit order x, y, z) at the static
/// specific force `f_g` under `vib`. Without vibration it is `N_i(f)`.
pub fn rectified_g(cfs: &[ConversionFunction<f64>; 3], f_g: &[f64; 3], vib: &Vibration<f64>) -> [f64; 3] {
    let mut out = [0.0; 3];
    for ((o, cf), axis) in out.iter_mut().zip(cfs).zip(Axis::ALL) {
        let a_p = AccelAxes::from_unit(f_g, axis);
        *o = match vib {
            Vibration::None => nonlinear_g(cf, a_p),
            Vibration::Harmonic { amp_g, .. } => harmonic_mean_g(cf, a_p, AccelAxes::from_unit(amp_g, axis)),
            Vibration::Random { sigma_g, .. } => gaussian_mean_g(cf, a_p, AccelAxes::from_unit(sigma_g, axis)),
        };
    }
    out
}

/// Variance of the logger's sample mean of a unit-variance flat-spectrum process over the band
/// `(f1, f2)` \[Hz\] for a sample period `dt` \[s\]: `(1/Δf)·∫ sinc²(π f dt) df` (the boxcar
/// average's power response). Used for the sampling fluctuation of random vibration.
pub fn boxcar_variance(band_hz: (f64, f64), dt: f64) -> f64 {
    let (f1, f2) = band_hz;
    if !(f2 > f1) {
        return 0.0;
    }
    let sinc2 = |f: f64| {
        let x = std::f64::consts::PI * f * dt;
        if x.abs() < 1e-8 { 1.0 } else { (x.sin() / x).powi(2) }
    };
    let panel = (0.25 / dt).min(f2 - f1);
    integrate(f1, f2, &[], panel, sinc2) / (f2 - f1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gauss_legendre_integrates_polynomials_exactly() {
        // ∫_0^2 x^31 dx = 2^32/32 (degree 31 = 2·16 − 1 is the rule's limit).
        let v = integrate(0.0, 2.0, &[], 2.0, |x| x.powi(31));
        assert!((v / (2f64.powi(32) / 32.0) - 1.0).abs() < 1e-14, "{v}");
        // ∫_{-1}^{1} |x| = 1 with the kink as a break.
        assert!((integrate(-1.0, 1.0, &[0.0], 2.0, f64::abs) - 1.0).abs() < 1e-15);
    }

    #[test]
    fn boxcar_variance_against_a_midpoint_sum() {
        // A band far below the sample rate is not averaged at all.
        assert!((boxcar_variance((0.0, 1e-3), 0.01) - 1.0).abs() < 1e-6);
        // Otherwise: a brute-force midpoint sum of sinc² over the band.
        for &(f1, f2, dt) in &[(320.0, 640.0, 0.01), (20.0, 80.0, 0.01), (5.0, 45.0, 0.1)] {
            let n = 200_000;
            let h = (f2 - f1) / n as f64;
            let mut s = 0.0;
            for k in 0..n {
                let x = std::f64::consts::PI * (f1 + (k as f64 + 0.5) * h) * dt;
                s += (x.sin() / x).powi(2);
            }
            let want = s * h / (f2 - f1);
            let v = boxcar_variance((f1, f2), dt);
            assert!((v / want - 1.0).abs() < 1e-6, "{v} vs {want}");
        }
    }
}
