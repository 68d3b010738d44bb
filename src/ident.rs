//! Identification of the constants from rig data: the six-position formulas T(10), their
//! least-squares generalisation, and the temperature coefficients T(11)/T(12) with least
//! squares for more temperatures than the order. Used by the host tests and the calibration
//! tool; allocation-free like the rest of the core, so it also runs on the target.

use crate::float::Float;
use crate::linalg::{self, Vec3};
use crate::model::Constants;
use crate::temperature::{CoefDelta, MAX_KNOTS, MAX_POLY_ORDER, TempModel};

/// Specific force \[g\] on the unit's axes in the tilter's test positions TP1…TP6 (§2).
pub const TILTER_POSITIONS_G: [Vec3<f64>; 6] =
    [[0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]];

/// Why an identification failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FitError {
    /// Fewer observations than unknowns (`needed`, `got`).
    TooFewPoints {
        /// Observations the fit needs at least.
        needed: usize,
        /// Observations given.
        got: usize,
    },
    /// The observations do not determine the unknowns (coplanar positions, repeated
    /// temperatures, …).
    Singular,
    /// K_ij at T0 is zero but changes with temperature: a relative coefficient γ_ij = ΔK/K is
    /// undefined. Holds the (row, column).
    ZeroReference(usize, usize),
    /// More knots than [`MAX_KNOTS`] or a polynomial order outside 1..=[`MAX_POLY_ORDER`].
    Unsupported,
    /// Input or result not finite.
    NonFinite,
    /// The lengths of paired inputs differ.
    LengthMismatch,
}

impl core::fmt::Display for FitError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            FitError::TooFewPoints { needed, got } => write!(f, "needs at least {needed} observations, got {got}"),
            FitError::Singular => write!(f, "the observations do not determine the unknowns (singular fit)"),
            FitError::ZeroReference(i, j) => {
                write!(f, "K[{i}][{j}] is zero at T0 but varies with temperature: relative coefficient undefined")
            }
            FitError::Unsupported => write!(f, "unsupported model size (knots <= 8, order 1..=4)"),
            FitError::NonFinite => write!(f, "input or result is not finite"),
            FitError::LengthMismatch => write!(f, "paired inputs differ in length"),
        }
    }
}

impl core::error::Error for FitError {}

/// T(10): the 12 constants from the mean signals in TP1…TP6 (`u_v[k]` = signals in TP(k+1)),
/// with g = 1 in g units. Exact for ideal positions.
pub fn six_position<F: Float>(u_v: &[Vec3<F>; 6]) -> Constants<F> {
    let half = F::from_f64(0.5);
    let quarter = F::from_f64(0.25);
    let [u1, u2, u3, u4, u5, u6] = u_v;
    let mut k = [[F::ZERO; 3]; 3];
    for i in 0..3 {
        k[i][0] = (u6[i] - u5[i]) * half;
        k[i][1] = (u4[i] - u2[i]) * half;
        k[i][2] = (u1[i] - u3[i]) * half;
    }
    let u0 = [
        (u1[0] + u2[0] + u3[0] + u4[0]) * quarter,
        (u1[1] + u3[1] + u5[1] + u6[1]) * quarter,
        (u2[2] + u4[2] + u5[2] + u6[2]) * quarter,
    ];
    Constants { k_v_per_g: k, u0_v: u0 }
}

/// Least squares generalisation of T(10): fits `U = K·f + U0` to any number (≥ 4) of
/// observations of known specific force `f_g` and mean signals `u_v`, per accelerometer, on
/// centred data. For the six ideal positions K equals T(10)'s and U0 is the mean over all six.
pub fn fit_constants<F: Float>(f_g: &[Vec3<F>], u_v: &[Vec3<F>]) -> Result<Constants<F>, FitError> {
    if f_g.len() != u_v.len() {
        return Err(FitError::LengthMismatch);
    }
    let n = f_g.len();
    if n < 4 {
        return Err(FitError::TooFewPoints { needed: 4, got: n });
    }
    let inv_n = F::ONE / F::from_f64(n as f64);
    let mut f_mean = [F::ZERO; 3];
    let mut u_mean = [F::ZERO; 3];
    for (f, u) in f_g.iter().zip(u_v) {
        for i in 0..3 {
            f_mean[i] += f[i];
            u_mean[i] += u[i];
        }
    }
    for i in 0..3 {
        f_mean[i] *= inv_n;
        u_mean[i] *= inv_n;
    }
    // Normal equations on centred data: (Σ df dfᵀ) k_i = Σ df du_i.
    let mut ata = [[F::ZERO; 3]; 3];
    let mut atb = [[F::ZERO; 3]; 3];
    for (f, u) in f_g.iter().zip(u_v) {
        let df = linalg::vec_sub(f, &f_mean);
        let du = linalg::vec_sub(u, &u_mean);
        for r in 0..3 {
            for c in 0..3 {
                ata[r][c] += df[r] * df[c];
                atb[r][c] += df[r] * du[c];
            }
        }
    }
    let mut k = [[F::ZERO; 3]; 3];
    let mut u0 = [F::ZERO; 3];
    for i in 0..3 {
        let rhs = [atb[0][i], atb[1][i], atb[2][i]];
        let row = linalg::solve(ata, rhs).ok_or(FitError::Singular)?;
        k[i] = row;
        u0[i] = u_mean[i] - (row[0] * f_mean[0] + row[1] * f_mean[1] + row[2] * f_mean[2]);
    }
    let c = Constants { k_v_per_g: k, u0_v: u0 };
    if c.is_finite() { Ok(c) } else { Err(FitError::NonFinite) }
}

/// The change of the constants from `c0` (at T0) to `c`: ΔU0 \[V\] and ΔK_ij/K_ij(T0) — the
/// right-hand sides of T(11)/T(12) (with the division by K_cal that T(3) implies).
pub fn coef_delta<F: Float>(c0: &Constants<F>, c: &Constants<F>) -> Result<CoefDelta<F>, FitError> {
    let mut d = CoefDelta::zero();
    for i in 0..3 {
        d.du0_v[i] = c.u0_v[i] - c0.u0_v[i];
        for j in 0..3 {
            let k0 = c0.k_v_per_g[i][j];
            let dk = c.k_v_per_g[i][j] - k0;
            d.rel_k[i][j] = if k0 != F::ZERO {
                dk / k0
            } else if dk == F::ZERO {
                F::ZERO
            } else {
                return Err(FitError::ZeroReference(i, j));
            };
        }
    }
    if d.is_finite() { Ok(d) } else { Err(FitError::NonFinite) }
}

/// T(4)/T(12) generalised: the piecewise-linear model whose knots are the calibration
/// temperatures of `points` plus T0 (change zero there). With points at Tn < T0 < Tv this is
/// the paper's two-range model; its slopes are those of T(12). `points` need not be sorted;
/// a point at T0 is ignored (T0's constants are `c0`).
pub fn pwl_from_constants<F: Float>(
    t0_c: F,
    c0: &Constants<F>,
    points: &[(F, Constants<F>)],
) -> Result<TempModel<F>, FitError> {
    let mut knots_c = [F::ZERO; MAX_KNOTS];
    let mut at_knot = [CoefDelta::zero(); MAX_KNOTS];
    knots_c[0] = t0_c;
    let mut n = 1;
    for (t, c) in points {
        if !t.is_finite() {
            return Err(FitError::NonFinite);
        }
        if *t == t0_c {
            continue;
        }
        if n == MAX_KNOTS {
            return Err(FitError::Unsupported);
        }
        // Insertion into the sorted knot list; a repeated temperature is ambiguous.
        let mut pos = n;
        while pos > 0 {
            let (Some(&k), Some(&d)) = (knots_c.get(pos - 1), at_knot.get(pos - 1)) else { break };
            if !(k > *t) {
                break;
            }
            if let (Some(ks), Some(ds)) = (knots_c.get_mut(pos), at_knot.get_mut(pos)) {
                *ks = k;
                *ds = d;
            }
            pos -= 1;
        }
        if pos > 0 && knots_c.get(pos - 1) == Some(t) {
            return Err(FitError::Singular);
        }
        let delta = coef_delta(c0, c)?;
        if let (Some(ks), Some(ds)) = (knots_c.get_mut(pos), at_knot.get_mut(pos)) {
            *ks = *t;
            *ds = delta;
        }
        n += 1;
    }
    if n < 2 {
        return Err(FitError::TooFewPoints { needed: 1, got: 0 });
    }
    Ok(TempModel::Pwl { n_knots: n as u8, knots_c, at_knot })
}

/// The slope of every coefficient on each side of T0 in a two-range piecewise model: T3's
/// columns (α [V/°C], β and γ [1/°C]) for the interval ending at T0 (`low`) and the one
/// starting there (`high`). `None` unless T0 is an interior knot.
pub fn pwl_slopes_at_t0<F: Float>(model: &TempModel<F>, t0_c: F) -> Option<(CoefDelta<F>, CoefDelta<F>)> {
    let TempModel::Pwl { n_knots, knots_c, at_knot } = model else { return None };
    let n = *n_knots as usize;
    let i0 = knots_c.iter().take(n).position(|&k| k == t0_c)?;
    if i0 == 0 || i0 + 1 >= n {
        return None;
    }
    let slope = |a: &CoefDelta<F>, b: &CoefDelta<F>, dt: F| {
        let (x, y) = (a.to_array(), b.to_array());
        let mut s = [F::ZERO; 12];
        for k in 0..12 {
            s[k] = (y[k] - x[k]) / dt;
        }
        CoefDelta::from_array(&s)
    };
    let low = slope(&at_knot[i0 - 1], &at_knot[i0], knots_c[i0] - knots_c[i0 - 1]);
    let high = slope(&at_knot[i0], &at_knot[i0 + 1], knots_c[i0 + 1] - knots_c[i0]);
    Some((low, high))
}

/// T(11) and its least-squares generalisation: the polynomial model of order `order` (1…4),
/// anchored at T0 (no constant term), fitted to the constants at the temperatures of
/// `points`. With exactly `order` temperatures besides T0 it is T(11)'s exact solution;
/// with more, least squares. ΔT is scaled to [−1, 1] inside the fit for conditioning.
pub fn poly_from_constants<F: Float>(
    t0_c: F,
    c0: &Constants<F>,
    points: &[(F, Constants<F>)],
    order: usize,
) -> Result<TempModel<F>, FitError> {
    if order == 0 || order > MAX_POLY_ORDER {
        return Err(FitError::Unsupported);
    }
    let mut scale = F::ZERO;
    let mut used = 0;
    for (t, _) in points {
        if !t.is_finite() {
            return Err(FitError::NonFinite);
        }
        if *t != t0_c {
            used += 1;
            scale = scale.max((*t - t0_c).abs());
        }
    }
    if used < order {
        return Err(FitError::TooFewPoints { needed: order, got: used });
    }
    // Normal equations shared by all 12 coefficients: Σ x xᵀ with x = (s, s², …), s = ΔT/scale.
    let mut ata = [[F::ZERO; MAX_POLY_ORDER]; MAX_POLY_ORDER];
    let mut atb = [[F::ZERO; 12]; MAX_POLY_ORDER];
    for (t, c) in points {
        if *t == t0_c {
            continue;
        }
        let s = (*t - t0_c) / scale;
        let mut x = [F::ZERO; MAX_POLY_ORDER];
        let mut p = F::ONE;
        for xn in x.iter_mut().take(order) {
            p *= s;
            *xn = p;
        }
        let y = coef_delta(c0, c)?.to_array();
        for r in 0..order {
            for q in 0..order {
                ata[r][q] += x[r] * x[q];
            }
            for k in 0..12 {
                atb[r][k] += x[r] * y[k];
            }
        }
    }
    // The order×order system solved in the MAX_POLY_ORDER arrays: an identity in the unused
    // corner (`linalg::solve`; the tolerance is unchanged, as ata[0][0] = Σ s² ≥ 1: the
    // farthest point has |s| = 1).
    for r in order..MAX_POLY_ORDER {
        ata[r][r] = F::ONE;
    }
    let mut coef = [CoefDelta::zero(); MAX_POLY_ORDER];
    let mut arrays = [[F::ZERO; 12]; MAX_POLY_ORDER];
    for k in 0..12 {
        let mut rhs = [F::ZERO; MAX_POLY_ORDER];
        for r in 0..order {
            rhs[r] = atb[r][k];
        }
        let sol = linalg::solve(ata, rhs).ok_or(FitError::Singular)?;
        // Undo the scaling: c_n = ĉ_n / scaleⁿ.
        let mut p = F::ONE;
        for n in 0..order {
            p *= scale;
            arrays[n][k] = sol[n] / p;
        }
    }
    for n in 0..order {
        coef[n] = CoefDelta::from_array(&arrays[n]);
    }
    Ok(TempModel::Poly { order: order as u8, coef })
}

/// Specific force \[g\] in the tilted check positions CP1…CP6 of §6 (T(13)), for a tilt `θ`.
///
/// The paper's Figure 3 (the positions' drawing) did not survive in its text, so the project
/// defines them: CPm starts from TPm, whose axis `a` is vertical, and tilts both horizontal
/// axes `b`, `c` by θ out of the horizon plane, so that `f_b = sin θ`,
/// `f_c = ±sin θ` (alternating with m) and `f_a = ±√(1 − 2 sin²θ)` (the sign of TPm). Every
/// axis then sees a large component, which is what makes the check sensitive to the
/// cross-sensitivities. Requires θ < 45°.
pub fn check_positions_g(theta_deg: f64) -> [Vec3<f64>; 6] {
    let s = libm::sin(theta_deg * core::f64::consts::PI / 180.0);
    let main = libm::sqrt((1.0 - 2.0 * s * s).max(0.0));
    let mut out = [[0.0; 3]; 6];
    for (m, tp) in TILTER_POSITIONS_G.iter().enumerate() {
        let a = tp.iter().position(|&x| x != 0.0).unwrap_or(0);
        let (b, c) = ((a + 1) % 3, (a + 2) % 3);
        out[m][a] = tp[a] * main;
        out[m][b] = s;
        out[m][c] = if m % 2 == 0 { s } else { -s };
    }
    out
}
