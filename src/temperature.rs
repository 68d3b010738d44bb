//! Temperature models of the 12 constants, T(3) (polynomial) and T(4) (piecewise-linear).
//!
//! Both models answer the same question, "how far have the constants moved at ΔT = T − T0?",
//! as a [`CoefDelta`]: absolute offsets ΔU0 \[V\] and relative scale changes ΔK_ij/K_ij \[1\]
//! (β on the diagonal, γ off it). Both compensation methods of §5 consume only that, so any
//! model works with any method.

use crate::float::Float;
use crate::float::cmp_f64::lt;
use crate::linalg::{Mat3, Vec3};

/// Highest polynomial order supported, T(3).
pub const MAX_POLY_ORDER: usize = 4;
/// Most knots a piecewise-linear model may have, T(4) (7 intervals).
pub const MAX_KNOTS: usize = 8;

/// How far the constants have moved from their values at T0.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct CoefDelta<F> {
    /// ΔU0_i \[V\] (α terms of T(3)/T(4)).
    pub du0_v: Vec3<F>,
    /// ΔK_ij / K_ij(T0) \[1\]: β_ii on the diagonal, γ_ij off it.
    pub rel_k: Mat3<F>,
}

impl<F: Float> CoefDelta<F> {
    /// All zero.
    pub const fn zero() -> Self
    where
        F: Float,
    {
        CoefDelta { du0_v: [F::ZERO; 3], rel_k: [[F::ZERO; 3]; 3] }
    }

    /// Every element as a flat array: `du0_v[0..3]`, then `rel_k` row-major.
    pub fn to_array(&self) -> [F; 12] {
        let mut out = [F::ZERO; 12];
        out[..3].copy_from_slice(&self.du0_v);
        for i in 0..3 {
            out[3 + 3 * i..6 + 3 * i].copy_from_slice(&self.rel_k[i]);
        }
        out
    }

    /// Inverse of [`to_array`](Self::to_array).
    pub fn from_array(a: &[F; 12]) -> Self {
        let mut d = Self::zero();
        d.du0_v.copy_from_slice(&a[..3]);
        for i in 0..3 {
            d.rel_k[i].copy_from_slice(&a[3 + 3 * i..6 + 3 * i]);
        }
        d
    }

    /// `a + s·(b − a)`, element-wise (one fused multiply-add each).
    #[inline(always)]
    fn lerp(a: &Self, b: &Self, s: F) -> Self {
        let mut out = *a;
        for i in 0..3 {
            out.du0_v[i] = s.mul_add(b.du0_v[i] - a.du0_v[i], a.du0_v[i]);
            for j in 0..3 {
                out.rel_k[i][j] = s.mul_add(b.rel_k[i][j] - a.rel_k[i][j], a.rel_k[i][j]);
            }
        }
        out
    }

    /// True when every element is finite.
    pub fn is_finite(&self) -> bool {
        self.du0_v.iter().chain(self.rel_k.iter().flatten()).all(|x| x.is_finite())
    }

    /// Converts between float types.
    #[cfg_attr(unstable_target, optimize(size))]
    pub fn cast<G: Float>(&self) -> CoefDelta<G> {
        let a = self.to_array();
        let mut b = [G::ZERO; 12];
        for (y, x) in b.iter_mut().zip(a.iter()) {
            *y = G::from_f64(x.to_f64());
        }
        CoefDelta::from_array(&b)
    }
}

/// A temperature model of the constants, anchored at T0.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TempModel<F> {
    /// T(3): `Δc(ΔT) = Σ_{n=1..order} c_n·ΔTⁿ`; `coef[n-1]` holds (α_n, β_n, γ_n).
    /// Orders 1 to [`MAX_POLY_ORDER`]; coefficients above `order` are ignored.
    Poly {
        /// Polynomial order k.
        order: u8,
        /// Coefficients of ΔT¹ … ΔT⁴ [V/°Cⁿ for α, 1/°Cⁿ for β, γ].
        coef: [CoefDelta<F>; MAX_POLY_ORDER],
    },
    /// T(4) generalised: linear interpolation of each coefficient change between knots
    /// (strictly increasing temperatures, 2 to [`MAX_KNOTS`]). Outside the knots the end
    /// intervals are extended. The paper's two-range model has knots (Tn, T0, Tv) with a zero
    /// change at T0, so each range is `slope·ΔT` exactly as in T(4)/T(12).
    Pwl {
        /// Number of knots in use.
        n_knots: u8,
        /// Knot temperatures [°C].
        knots_c: [F; MAX_KNOTS],
        /// Change of the constants at each knot, relative to T0.
        at_knot: [CoefDelta<F>; MAX_KNOTS],
    },
}

impl<F: Float> TempModel<F> {
    /// The change of the constants at `temp_c` (T0 = `t0_c`). Bounded time: at most
    /// [`MAX_POLY_ORDER`] power-form steps or a [`MAX_KNOTS`]-step interval search.
    ///
    /// The caller ensures a valid model (see [`TempModel::check`]); an out-of-range order or
    /// knot count is clamped so that this function cannot index out of bounds.
    #[inline]
    pub fn delta(&self, temp_c: F, t0_c: F) -> CoefDelta<F> {
        match self {
            TempModel::Poly { order, coef } => {
                let n = (*order as usize).min(MAX_POLY_ORDER);
                let dt = temp_c - t0_c;
                // Power form: c1·ΔT + c2·ΔT² + …, each term one fused multiply-add into the
                // sum it joins, so the twelve sums stay where they are from one set to the next
                // (Horner's rule moves each partial result once per set on the target).
                let mut acc = [F::ZERO; 12];
                let mut power = dt;
                for c in coef.iter().take(n) {
                    for (a, c) in acc.iter_mut().zip(c.to_array()) {
                        *a = c.mul_add(power, *a);
                    }
                    power *= dt;
                }
                CoefDelta::from_array(&acc)
            }
            TempModel::Pwl { n_knots, knots_c, at_knot } => {
                let n = (*n_knots as usize).clamp(2, MAX_KNOTS);
                // Interval l such that knots[l] <= T < knots[l+1], end intervals extended.
                let mut l = 0;
                while l + 2 < n && knots_c.get(l + 1).is_some_and(|&k| temp_c >= k) {
                    l += 1;
                }
                // `l + 1 < n <= MAX_KNOTS`, so the `get`s below always succeed; written with
                // `get` so that no bounds-check panic is linked into the per-sample path.
                match (knots_c.get(l), knots_c.get(l + 1), at_knot.get(l), at_knot.get(l + 1)) {
                    (Some(&k0), Some(&k1), Some(c0), Some(c1)) => {
                        let span = k1 - k0;
                        let s = if span > F::ZERO { (temp_c - k0) / span } else { F::ZERO };
                        CoefDelta::lerp(c0, c1, s)
                    }
                    _ => CoefDelta::zero(),
                }
            }
        }
    }

    /// Validates the model's shape and values.
    pub fn check(&self) -> Result<(), TempModelError> {
        // The coefficient sets and knots in use: one finiteness test for both kinds.
        let (sets, knots): (&[CoefDelta<F>], &[F]) = match self {
            TempModel::Poly { order, coef } => {
                let n = *order as usize;
                if n == 0 || n > MAX_POLY_ORDER {
                    return Err(TempModelError::UnsupportedOrder(*order));
                }
                (coef.get(..n).unwrap_or(&[]), &[])
            }
            TempModel::Pwl { n_knots, knots_c, at_knot } => {
                let n = *n_knots as usize;
                if !(2..=MAX_KNOTS).contains(&n) {
                    return Err(TempModelError::KnotCount(*n_knots));
                }
                (at_knot.get(..n).unwrap_or(&[]), knots_c.get(..n).unwrap_or(&[]))
            }
        };
        if !sets.iter().all(CoefDelta::is_finite) || !knots.iter().all(|k| k.is_finite()) {
            return Err(TempModelError::NonFinite);
        }
        // Compared by the bits (exact: `to_f64` widens), no soft-float `f64` comparison.
        if knots.windows(2).any(|w| matches!(w, [a, b] if !lt(a.to_f64(), b.to_f64()))) {
            return Err(TempModelError::KnotsNotIncreasing);
        }
        Ok(())
    }

    /// The same model with each coefficient set (each term's, or each knot's) mapped by `f`:
    /// for a quantity linear in the sets, its own model (the knots kept).
    #[cfg_attr(unstable_target, optimize(size))]
    pub fn map_sets(&self, f: impl Fn(&CoefDelta<F>) -> CoefDelta<F>) -> Self {
        let mut out = *self;
        let sets: &mut [CoefDelta<F>] = match &mut out {
            TempModel::Poly { coef, .. } => coef,
            TempModel::Pwl { at_knot, .. } => at_knot,
        };
        for c in sets {
            *c = f(c);
        }
        out
    }

    /// Converts between float types.
    #[cfg_attr(unstable_target, optimize(size))]
    pub fn cast<G: Float>(&self) -> TempModel<G> {
        match self {
            TempModel::Poly { order, coef } => TempModel::Poly {
                order: *order,
                coef: [coef[0].cast(), coef[1].cast(), coef[2].cast(), coef[3].cast()],
            },
            TempModel::Pwl { n_knots, knots_c, at_knot } => {
                let mut k = [G::ZERO; MAX_KNOTS];
                let mut a = [CoefDelta::zero(); MAX_KNOTS];
                for i in 0..MAX_KNOTS {
                    k[i] = G::from_f64(knots_c[i].to_f64());
                    a[i] = at_knot[i].cast();
                }
                TempModel::Pwl { n_knots: *n_knots, knots_c: k, at_knot: a }
            }
        }
    }
}

/// Why a temperature model was rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TempModelError {
    /// Polynomial order outside 1..=4.
    UnsupportedOrder(u8),
    /// Knot count outside 2..=8.
    KnotCount(u8),
    /// Knot temperatures not strictly increasing.
    KnotsNotIncreasing,
    /// A coefficient or knot is NaN or infinite.
    NonFinite,
}

impl core::fmt::Display for TempModelError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            TempModelError::UnsupportedOrder(n) => write!(f, "polynomial order {n} unsupported (1..=4)"),
            TempModelError::KnotCount(n) => write!(f, "{n} knots unsupported (2..=8)"),
            TempModelError::KnotsNotIncreasing => write!(f, "knot temperatures are not strictly increasing"),
            TempModelError::NonFinite => write!(f, "a temperature coefficient is not finite"),
        }
    }
}

impl core::error::Error for TempModelError {}
