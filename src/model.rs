//! The metrological model of the triaxial unit, T(1): `U = K·a + U0`, `a = N·(U − U0)` with
//! `N = K⁻¹`, and its 12 "passport" constants.

use crate::float::Float;
use crate::linalg::{self, Mat3, Vec3};

/// The 12 constants of T(1) at one temperature.
///
/// `k_v_per_g[i][j]` is the signal of accelerometer i per g of specific force along axis j:
/// scale factors on the diagonal, cross-sensitivities off it. `u0_v` are the zero offsets.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Constants<F> {
    /// K [V/g], row-major.
    pub k_v_per_g: Mat3<F>,
    /// U0 \[V\].
    pub u0_v: Vec3<F>,
}

impl<F: Float> Constants<F> {
    /// The signals the unit outputs for the specific force `f_g` (forward model of T(1)).
    pub fn signals_v(&self, f_g: &Vec3<F>) -> Vec3<F> {
        let kf = linalg::mat_vec(&self.k_v_per_g, f_g);
        [kf[0] + self.u0_v[0], kf[1] + self.u0_v[1], kf[2] + self.u0_v[2]]
    }

    /// `N = K⁻¹`, or `None` when K is singular or ill-conditioned
    /// (see [`linalg::MIN_HADAMARD_RATIO`]).
    pub fn inverse(&self) -> Option<Mat3<F>> {
        linalg::inverse_checked(&self.k_v_per_g, F::from_f64(linalg::MIN_HADAMARD_RATIO))
    }

    /// True when all 12 numbers are finite.
    pub fn is_finite(&self) -> bool {
        self.k_v_per_g.iter().flatten().all(|x| x.is_finite()) && self.u0_v.iter().all(|x| x.is_finite())
    }

    /// Converts between float types.
    #[cfg_attr(unstable_target, optimize(size))]
    pub fn cast<G: Float>(&self) -> Constants<G> {
        Constants { k_v_per_g: linalg::cast_mat(&self.k_v_per_g), u0_v: linalg::cast_vec(&self.u0_v) }
    }
}
