//! Identification of the VE on a shake table, §8: from the change of the mean output `ΔU`
//! that vibration causes in known positions, (a) the VE terms Δ0(1..3), δ(1..3) at the tested
//! level by least squares on V(21) (equal to V(22) on the paper's ten-position plan), and (b)
//! from plans at several amplitudes, the rectifying coefficients δ_1A, k2…k5, m31, m32 of the
//! conversion function by linear least squares on the exact moment expressions
//! ([`exact_terms`]), which then predict the VE at any level.
//!
//! Least squares is solved by Givens rotations into a fixed-size triangular factor (no normal
//! equations, no allocation), on columns scaled to unit maximum.

use super::{AccelAxes, ConversionFunction, VeTerms, VibMoments, exact_terms, harmonic_abs_excess_g};
use crate::float::Float;

/// One shake-table measurement of one accelerometer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShakePosition<F> {
    /// Static acceleration along IA in this position \[g\] (`g·cos φ_k` on the tilting table).
    pub a_p3_g: F,
    /// Peak amplitude of the (harmonic) table vibration on the accelerometer's axes \[g\].
    pub amp_g: AccelAxes<F>,
    /// `ΔU = ⟨U^B⟩ − U`: mean output with vibration minus without \[V\], V(20).
    pub du_v: F,
}

/// Why an identification failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VibFitError {
    /// Fewer positions than unknowns (`needed`, `got`).
    TooFewPoints {
        /// Positions the fit needs at least.
        needed: usize,
        /// Positions given.
        got: usize,
    },
    /// The positions do not determine the unknowns (too few distinct static accelerations or
    /// amplitudes).
    Singular,
    /// An input or the result is not finite.
    NonFinite,
    /// The scale factor `K1` is zero.
    ZeroScaleFactor,
    /// [`fit_ve_terms`] needs every position at the same IA amplitude (within 1 %), or an IA
    /// amplitude is zero.
    MixedAmplitudes,
}

impl core::fmt::Display for VibFitError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            VibFitError::TooFewPoints { needed, got } => write!(f, "needs at least {needed} positions, got {got}"),
            VibFitError::Singular => write!(f, "the positions do not determine the unknowns (singular fit)"),
            VibFitError::NonFinite => write!(f, "input or result is not finite"),
            VibFitError::ZeroScaleFactor => write!(f, "scale factor K1 is zero"),
            VibFitError::MixedAmplitudes => {
                write!(f, "positions differ in IA vibration amplitude (or it is zero): one level per fit")
            }
        }
    }
}

impl core::error::Error for VibFitError {}

/// The static IA acceleration \[g\] (g = 1) and the vibration amplitudes on the accelerometer's
/// axes of the paper's ten test positions at table amplitude `a_b_g`, §8: TP1…TP8 tilt IA by
/// φ_k = (k−1)·45° from the vertical with vibration `a_b` along IA; TP9 (TP10) vibrate along
/// the IA–OA (IA–PA) diagonal with amplitude `√2·a_b`, IA horizontal, so both axes see `a_b`.
pub fn ten_position_plan<F: Float>(a_b_g: F) -> [(F, AccelAxes<F>); 10] {
    let s = F::from_f64(core::f64::consts::FRAC_1_SQRT_2);
    let z = F::ZERO;
    let cos_phi = [F::ONE, s, z, -s, -F::ONE, -s, z, s];
    let along_ia = AccelAxes { ia: a_b_g, pa: z, oa: z };
    let mut out = [(z, along_ia); 10];
    for (o, c) in out.iter_mut().zip(cos_phi) {
        o.0 = c;
    }
    out[8] = (z, AccelAxes { ia: a_b_g, pa: z, oa: a_b_g });
    out[9] = (z, AccelAxes { ia: a_b_g, pa: a_b_g, oa: z });
    out
}

/// Linear least squares by Givens rotations: the rows are folded one at a time into an
/// upper-triangular `R` and `Qᵀy`, so the memory is fixed (N × N) whatever the row count.
#[derive(Clone, Copy, Debug)]
struct Givens<F, const N: usize> {
    r: [[F; N]; N],
    qty: [F; N],
    rows: usize,
    ss_resid: F,
}

impl<F: Float, const N: usize> Givens<F, N> {
    fn new() -> Self {
        Givens { r: [[F::ZERO; N]; N], qty: [F::ZERO; N], rows: 0, ss_resid: F::ZERO }
    }

    fn add_row(&mut self, mut x: [F; N], mut y: F) {
        for k in 0..N {
            let xk = x[k];
            if xk == F::ZERO {
                continue;
            }
            let rkk = self.r[k][k];
            let h = (rkk * rkk + xk * xk).sqrt();
            let (c, s) = (rkk / h, xk / h);
            self.r[k][k] = h;
            for j in k + 1..N {
                let t = self.r[k][j];
                self.r[k][j] = c * t + s * x[j];
                x[j] = c * x[j] - s * t;
            }
            let t = self.qty[k];
            self.qty[k] = c * t + s * y;
            y = c * y - s * t;
        }
        self.ss_resid += y * y;
        self.rows += 1;
    }

    /// Back substitution; `None` when a diagonal element is negligible (rank deficiency).
    fn solve(&self) -> Option<[F; N]> {
        let mut dmax = F::ZERO;
        for k in 0..N {
            dmax = dmax.max(self.r[k][k].abs());
        }
        let tol = dmax * F::EPSILON * F::from_f64(1024.0);
        let mut x = [F::ZERO; N];
        for k in (0..N).rev() {
            let d = self.r[k][k];
            if !(d.abs() > tol) {
                return None;
            }
            let mut s = self.qty[k];
            for j in k + 1..N {
                s -= self.r[k][j] * x[j];
            }
            x[k] = s / d;
        }
        if x.iter().all(|v| v.is_finite()) { Some(x) } else { None }
    }
}

/// Fits `ΔU/K1 = Σ_j θ_j·basis_j` over the positions for the N unknowns θ. Columns that are
/// identically zero are left out (reported inactive, θ = 0); the others are scaled to unit
/// maximum and compacted to the front of each row. Returns θ, the active mask and the
/// residual standard error.
fn fit_columns<F: Float, const N: usize>(
    positions: &[ShakePosition<F>],
    k1_v_per_g: F,
    basis: impl Fn(&ShakePosition<F>) -> [F; N],
) -> Result<([F; N], [bool; N], F), VibFitError> {
    if k1_v_per_g == F::ZERO {
        return Err(VibFitError::ZeroScaleFactor);
    }
    if !k1_v_per_g.is_finite() {
        return Err(VibFitError::NonFinite);
    }
    // Pass 1: column scales and which columns are active.
    let mut scale = [F::ZERO; N];
    for p in positions {
        let b = basis(p);
        if !(p.du_v.is_finite() && b.iter().all(|v| v.is_finite())) {
            return Err(VibFitError::NonFinite);
        }
        for (s, v) in scale.iter_mut().zip(b) {
            *s = s.max(v.abs());
        }
    }
    let active = scale.map(|s| s > F::ZERO);
    let n_active = active.iter().filter(|&&a| a).count();
    if positions.len() < n_active.max(1) {
        return Err(VibFitError::TooFewPoints { needed: n_active.max(1), got: positions.len() });
    }
    // Pass 2: rows, compacted to the active columns (inactive ones stay zero, and a zero
    // column of R is replaced by the identity so it solves to zero).
    let mut ls = Givens::<F, N>::new();
    for p in positions {
        let b = basis(p);
        let mut row = [F::ZERO; N];
        let mut c = 0;
        for j in 0..N {
            if active[j] {
                if let Some(slot) = row.get_mut(c) {
                    *slot = b[j] / scale[j];
                }
                c += 1;
            }
        }
        ls.add_row(row, p.du_v / k1_v_per_g);
    }
    for k in n_active..N {
        if let Some(d) = ls.r.get_mut(k).and_then(|rk| rk.get_mut(k)) {
            *d = F::ONE;
        }
    }
    let compact = ls.solve().ok_or(VibFitError::Singular)?;
    let mut theta = [F::ZERO; N];
    let mut c = 0;
    for j in 0..N {
        if active[j] {
            if let Some(v) = compact.get(c) {
                theta[j] = *v / scale[j];
            }
            c += 1;
        }
    }
    if !theta.iter().all(|v| v.is_finite()) {
        return Err(VibFitError::NonFinite);
    }
    // The residual's degrees of freedom count only the active columns.
    let dof = ls.rows.saturating_sub(n_active);
    let sigma = if dof > 0 { (ls.ss_resid / F::from_f64(dof as f64)).sqrt() } else { F::ZERO };
    Ok((theta, active, sigma))
}

/// Result of [`fit_ve_terms`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VeTermsFit<F> {
    /// Δ0(1..3), δ(1..3) at the tested level.
    pub terms: VeTerms<F>,
    /// The IA amplitude of the plan \[g\] (mean over the positions).
    pub amp_g: F,
    /// False when no position vibrates along OA (PA): Δ0(2) (Δ0(3)) is then not determined
    /// and reported as zero.
    pub cross_determined: [bool; 2],
    /// Residual standard error of the fit \[g\] (zero without redundant positions).
    pub residual_sigma_g: F,
}

impl<F: Float> VeTermsFit<F> {
    /// V(23): the VE \[g\] at static IA acceleration `a_g` for the tested level; the cross
    /// terms scale with the transverse amplitudes `oa_g`, `pa_g` relative to the plan's (so
    /// the paper's TP9/TP10 level, `a_b` on the transverse axis, gives Δ0(2) + Δ0(3)).
    pub fn predict_g(&self, a_g: F, oa_g: F, pa_g: F) -> F {
        let t = &self.terms;
        let r = F::ONE / self.amp_g;
        t.d0_1_g + t.d0_2_g * oa_g * r + t.d0_3_g * pa_g * r + t.multiplicative_g(a_g)
    }
}

/// V(21) by least squares: the VE terms at one vibration level from any set of positions at
/// the same IA amplitude. Each position contributes
/// `ΔU/K1 = Δ0(1) + Δ0(2)·a_B1/a_B3 + Δ0(3)·a_B2/a_B3 + δ(1)·a_p3 + δ(2)·a_p3² + δ(3)·a_p3³`
/// (the paper's TP9/TP10 have `a_B1 = a_B3` resp. `a_B2 = a_B3`). On the ten-position plan
/// with consistent data this is exactly V(22); with more or noisy positions it is the least
/// squares estimate. Needs at least 4 distinct `a_p3` for δ(1..3).
pub fn fit_ve_terms<F: Float>(positions: &[ShakePosition<F>], k1_v_per_g: F) -> Result<VeTermsFit<F>, VibFitError> {
    let Some(first) = positions.first() else {
        return Err(VibFitError::TooFewPoints { needed: 4, got: 0 });
    };
    let amp = first.amp_g.ia;
    let mut sum_amp = F::ZERO;
    for p in positions {
        let a = p.amp_g.ia;
        if !a.is_finite() || !amp.is_finite() {
            return Err(VibFitError::NonFinite);
        }
        if !(a.abs() > F::ZERO) || !((a - amp).abs() <= F::from_f64(0.01) * amp.abs()) {
            return Err(VibFitError::MixedAmplitudes);
        }
        sum_amp += a;
    }
    let basis = |p: &ShakePosition<F>| {
        let x = p.a_p3_g;
        let r = F::ONE / p.amp_g.ia;
        [F::ONE, x, x * x, x * x * x, p.amp_g.oa * r, p.amp_g.pa * r]
    };
    let (th, active, sigma) = fit_columns::<F, 6>(positions, k1_v_per_g, basis)?;
    if !(active[1] && active[2] && active[3]) {
        return Err(VibFitError::Singular);
    }
    Ok(VeTermsFit {
        terms: VeTerms {
            d0_1_g: th[0],
            d0_2_g: th[4],
            d0_3_g: th[5],
            delta1_g_per_g: th[1],
            delta2_g_per_g2: th[2],
            delta3_g_per_g3: th[3],
        },
        amp_g: sum_amp / F::from_f64(positions.len() as f64),
        cross_determined: [active[4], active[5]],
        residual_sigma_g: sigma,
    })
}

/// Result of [`fit_conversion_function`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CfFit<F> {
    /// δ_1A, k2…k5, m31, m32 as identified; `a0`, `m1`, `m2` do not rectify, cannot be seen
    /// in ΔU and are zero.
    pub cf: ConversionFunction<F>,
    /// Which of δ_1A, k2, k3, k4, k5, m31, m32 the positions determine (an undetermined one,
    /// e.g. m31 without OA vibration, is zero).
    pub determined: [bool; 7],
    /// Residual standard error of the fit \[g\].
    pub residual_sigma_g: F,
}

/// The rectifying coefficients of the conversion function from shake-table positions at
/// several amplitudes: linear least squares in (δ_1A, k2, k3, k4, k5, m31, m32) with, per
/// position, `ΔU/K1 = Σ coefficient × (its exact harmonic VE term at that position's a_p3 and
/// amplitudes)` — the columns are [`exact_terms`] evaluated with a unit coefficient, so the
/// fit and the prediction share one formula. One amplitude already separates k3 from k5 and
/// k2 from k4 (through the a_p3-dependence of δ(1..3)), but δ_1A from k2 only through the
/// a_p3-dependence of the exact asymmetry term, weakly; plans at several amplitudes separate
/// them through the different powers of a_B.
pub fn fit_conversion_function<F: Float>(
    positions: &[ShakePosition<F>],
    k1_v_per_g: F,
) -> Result<CfFit<F>, VibFitError> {
    let basis = |p: &ShakePosition<F>| {
        let m = VibMoments::harmonic(p.amp_g);
        let abs_excess = harmonic_abs_excess_g(p.a_p3_g, p.amp_g.ia);
        let mut out = [F::ZERO; 7];
        // Field positions of δ_1A, k2…k5, m31, m32 in ConversionFunction::to_array.
        for (o, idx) in out.iter_mut().zip([1usize, 2, 3, 4, 5, 8, 9]) {
            let mut unit = [F::ZERO; 10];
            if let Some(u) = unit.get_mut(idx) {
                *u = F::ONE;
            }
            let cf = ConversionFunction::from_array(&unit);
            *o = exact_terms(&cf, &m, abs_excess).total_g(p.a_p3_g);
        }
        out
    };
    let (th, determined, sigma) = fit_columns::<F, 7>(positions, k1_v_per_g, basis)?;
    let cf = ConversionFunction {
        a0_g: F::ZERO,
        delta_1a: th[0],
        k2_g_per_g2: th[1],
        k3_g_per_g3: th[2],
        k4_g_per_g4: th[3],
        k5_g_per_g5: th[4],
        m1_g_per_g: F::ZERO,
        m2_g_per_g: F::ZERO,
        m31_g_per_g2: th[5],
        m32_g_per_g2: th[6],
    };
    Ok(CfFit { cf, determined, residual_sigma_g: sigma })
}
