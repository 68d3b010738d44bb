//! The vibration error (VE) of the three navigation accelerometers (the vibration paper's
//! equations, written out in `docs/equations.md`): the nonlinear conversion function V(2), the vibration environments V(3)–V(6),
//! the VE for harmonic V(13) and broadband random V(14) vibration split into its additive and
//! multiplicative components V(15)/V(16), in the paper's printed form and in an exact form, and
//! the run-time vibration configuration (coefficients and flight-phase profiles) the per-sample
//! step in [`pipeline`](crate::pipeline) uses.
//!
//! Submodules: [`window`] (online moments of the measured vibration), [`shake`]
//! (identification on the shake table, V(21)/V(22) and multi-amplitude), [`tables`] (the
//! paper's Tables V1–V3).
//!
//! # Axis mapping
//!
//! Each accelerometer has its input axis IA (projection `a3`), pendulum axis PA (`a2`) and
//! output axis OA (`a1`). On the unit the three accelerometers sit so that the axes are
//! cyclic:
//!
//! | accelerometer | IA (`a3`) | PA (`a2`) | OA (`a1`) |
//! |---|---|---|---|
//! | x | x | y | z |
//! | y | y | z | x |
//! | z | z | x | y |
//!
//! [`AccelAxes::from_unit`] applies this mapping everywhere a unit-frame quantity
//! (static acceleration, vibration amplitude, covariance) meets one accelerometer's model.
//!
//! # Scale and frequency
//!
//! The conversion function is used in acceleration units, V(2): the output is `U/K1` \[g\], so
//! the scale factor `k1` is 1 and the frequency dependence `λ(ω)` is taken as 1 (the paper
//! gives no data for it). A VE in volts is `K1` times the VE here.
//!
//! # Variants
//!
//! [`Variant::Paper`] evaluates V(13)/V(14) as printed (asymmetry coefficients 0.637 and
//! 0.125, `k4 σ⁴`, `5 k5 σ⁴`), which reproduces Tables V4/V5. [`Variant::Exact`] evaluates the
//! true time mean `⟨a_u(a_p + ã)⟩ − a_u(a_p)` through the moments of the vibration
//! ([`VibMoments`], [`exact_terms`]); it matches a time-domain simulation. The differences are
//! listed in `docs/vibration.md`.

pub mod shake;
pub mod tables;
pub mod window;

use crate::float::Float;
use crate::linalg::Vec3;

/// Largest vibration level the model is used at: harmonic amplitude or random σ \[g\] on any
/// axis. Profiles above it are rejected at load time; online estimates above it are clamped
/// and flagged.
pub const MAX_LEVEL_G: f64 = 10.0;
/// Largest static acceleration along IA the VE is evaluated at \[g\]: the AL-15's measuring
/// range, V(17). Larger values are clamped and flagged.
pub const MAX_STATIC_G: f64 = 10.0;
/// Number of flight-phase vibration profiles a configuration can carry.
pub const MAX_PROFILES: usize = 8;
/// The asymmetry coefficient printed in V(13) (and used for Table V4): `0.637·δ_1A·a_B3`.
pub const PAPER_HARMONIC_ASYMMETRY: f64 = 0.637;
/// The asymmetry coefficient that reproduces Table V5's Δ0(1) column from V(14):
/// `0.125·δ_1A·σ` (the printed formula reads `½·λ(ω)·δ_1A·√(S_B Δf)`).
pub const PAPER_RANDOM_ASYMMETRY: f64 = 0.125;

/// One of the unit's axes; names an accelerometer by its input axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Axis {
    /// The x accelerometer / axis.
    X,
    /// The y accelerometer / axis.
    Y,
    /// The z accelerometer / axis.
    Z,
}

impl Axis {
    /// X, Y, Z in order (the order of [`Vec3`]).
    pub const ALL: [Axis; 3] = [Axis::X, Axis::Y, Axis::Z];
}

/// A quantity projected on one accelerometer's own axes (see the module's axis mapping).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AccelAxes<F> {
    /// Along the input axis IA (`a3`).
    pub ia: F,
    /// Along the pendulum axis PA (`a2`).
    pub pa: F,
    /// Along the output axis OA (`a1`).
    pub oa: F,
}

impl<F: Copy> AccelAxes<F> {
    /// The projections of a unit-frame vector on accelerometer `axis`'s IA, PA, OA.
    pub fn from_unit(v: &Vec3<F>, axis: Axis) -> Self {
        match axis {
            Axis::X => AccelAxes { ia: v[0], pa: v[1], oa: v[2] },
            Axis::Y => AccelAxes { ia: v[1], pa: v[2], oa: v[0] },
            Axis::Z => AccelAxes { ia: v[2], pa: v[0], oa: v[1] },
        }
    }
}

/// The nonlinear conversion function V(2) of one accelerometer, in acceleration units
/// (`k1 = 1`, `λ(ω) = 1`):
///
/// `a_u = a0 + (1 + 0.5·δ_1A·sign a3)·a3 + k2 a3² + k3 a3³ + k4 a3⁴ + k5 a3⁵
///        + m1 a1 + m2 a2 + m31 a3 a1 + m32 a3 a2` \[g\].
///
/// Only `δ_1A`, `k2…k5`, `m31`, `m32` rectify vibration; `a0`, `m1`, `m2` do not enter the VE.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ConversionFunction<F> {
    /// Bias `a0` \[g\].
    pub a0_g: F,
    /// Scale-factor asymmetry `δ_1A` (dimensionless; 15 ppm = 15e-6).
    pub delta_1a: F,
    /// Quadratic nonlinearity `k2` [g/g²].
    pub k2_g_per_g2: F,
    /// Cubic nonlinearity `k3` [g/g³].
    pub k3_g_per_g3: F,
    /// Fourth-order nonlinearity `k4` [g/g⁴].
    pub k4_g_per_g4: F,
    /// Fifth-order nonlinearity `k5` [g/g⁵].
    pub k5_g_per_g5: F,
    /// Additive cross-sensitivity to OA `m1` [g/g].
    pub m1_g_per_g: F,
    /// Additive cross-sensitivity to PA `m2` [g/g].
    pub m2_g_per_g: F,
    /// Multiplicative cross-sensitivity IA·OA `m31` [g/g²].
    pub m31_g_per_g2: F,
    /// Multiplicative cross-sensitivity IA·PA `m32` [g/g²].
    pub m32_g_per_g2: F,
}

impl<F: Float> ConversionFunction<F> {
    /// The coefficients as an array, in field order (a0, δ, k2…k5, m1, m2, m31, m32).
    pub fn to_array(&self) -> [F; 10] {
        [
            self.a0_g,
            self.delta_1a,
            self.k2_g_per_g2,
            self.k3_g_per_g3,
            self.k4_g_per_g4,
            self.k5_g_per_g5,
            self.m1_g_per_g,
            self.m2_g_per_g,
            self.m31_g_per_g2,
            self.m32_g_per_g2,
        ]
    }

    /// The inverse of [`to_array`](Self::to_array).
    pub fn from_array(a: &[F; 10]) -> Self {
        let [
            a0_g,
            delta_1a,
            k2_g_per_g2,
            k3_g_per_g3,
            k4_g_per_g4,
            k5_g_per_g5,
            m1_g_per_g,
            m2_g_per_g,
            m31_g_per_g2,
            m32_g_per_g2,
        ] = *a;
        ConversionFunction {
            a0_g,
            delta_1a,
            k2_g_per_g2,
            k3_g_per_g3,
            k4_g_per_g4,
            k5_g_per_g5,
            m1_g_per_g,
            m2_g_per_g,
            m31_g_per_g2,
            m32_g_per_g2,
        }
    }

    /// True when every coefficient is finite.
    #[inline(never)]
    #[cfg_attr(unstable_target, optimize(size))]
    pub fn is_finite(&self) -> bool {
        self.to_array().iter().all(|x| x.is_finite())
    }

    /// Converts between float types.
    #[cfg_attr(unstable_target, optimize(size))]
    pub fn cast<G: Float>(&self) -> ConversionFunction<G> {
        ConversionFunction::from_array(&self.to_array().map(|x| G::from_f64(x.to_f64())))
    }

    /// The first three derivatives of the conversion function V(2) with respect to the
    /// input-axis acceleration `a3` (`a.ia`) at `a`, without the
    /// asymmetry's jump at zero (at most `δ_1A/2`): slope
    /// `1 + 2k2 a3 + 3k3 a3² + 4k4 a3³ + 5k5 a3⁴ + m31 a1 + m32 a2`, curvature
    /// `2k2 + 6k3 a3 + 12k4 a3² + 20k5 a3³`, third derivative `6k3 + 24k4 a3 + 60k5 a3²`.
    pub fn input_axis_derivatives(&self, a: AccelAxes<F>) -> (F, F, F) {
        let a3 = a.ia;
        let (k2, k3, k4, k5) = (self.k2_g_per_g2, self.k3_g_per_g3, self.k4_g_per_g4, self.k5_g_per_g5);
        let slope = F::ONE
            + (((F::from_f64(5.0) * k5 * a3 + F::from_f64(4.0) * k4) * a3 + F::from_f64(3.0) * k3) * a3
                + F::from_f64(2.0) * k2)
                * a3
            + self.m31_g_per_g2 * a.oa
            + self.m32_g_per_g2 * a.pa;
        let curvature = ((F::from_f64(20.0) * k5 * a3 + F::from_f64(12.0) * k4) * a3 + F::from_f64(6.0) * k3) * a3
            + F::from_f64(2.0) * k2;
        let third = (F::from_f64(60.0) * k5 * a3 + F::from_f64(24.0) * k4) * a3 + F::from_f64(6.0) * k3;
        (slope, curvature, third)
    }

    /// V(2): the accelerometer's output \[g\] for the projections `a` \[g\] on its axes.
    pub fn eval_g(&self, a: AccelAxes<F>) -> F {
        let a3 = a.ia;
        let half = F::from_f64(0.5);
        let poly = ((((self.k5_g_per_g5 * a3 + self.k4_g_per_g4) * a3 + self.k3_g_per_g3) * a3 + self.k2_g_per_g2)
            * a3
            + F::ONE)
            * a3;
        self.a0_g
            + poly
            + half * self.delta_1a * a3.abs()
            + self.m1_g_per_g * a.oa
            + self.m2_g_per_g * a.pa
            + (self.m31_g_per_g2 * a.oa + self.m32_g_per_g2 * a.pa) * a3
    }
}

/// Which formulas the VE is computed with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Variant {
    /// V(13)/V(14) as printed: asymmetry `0.637·δ·a_B3` (harmonic) and `0.125·δ·σ` (random,
    /// the coefficient that reproduces Table V5), random `k4 σ⁴` and `5 k5 σ⁴`. Reproduces
    /// Tables V4/V5.
    Paper,
    /// The true time mean of V(2) under the vibration ([`exact_terms`]): exact asymmetry
    /// `0.5·δ·(⟨|a_p3 + ã3|⟩ − |a_p3|)`, Gaussian moments `⟨ã⁴⟩ = 3σ⁴`, every cross term.
    Exact,
}

/// The VE of one accelerometer split as in V(15)/V(16):
/// `Δa_B = Δ0(1) + Δ0(2) + Δ0(3) + δ(1)·a_p3 + δ(2)·a_p3² + δ(3)·a_p3³` (V(23)).
///
/// In [`Variant::Exact`] the asymmetry part of Δ0(1) depends on `a_p3` (it vanishes once the
/// vibration no longer carries `a3` through zero), so the split holds for the `a_p3` the terms
/// were computed at.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct VeTerms<F> {
    /// Δ0(1): asymmetry and even nonlinearity \[g\].
    pub d0_1_g: F,
    /// Δ0(2): multiplicative cross-sensitivity IA·OA \[g\].
    pub d0_2_g: F,
    /// Δ0(3): multiplicative cross-sensitivity IA·PA \[g\].
    pub d0_3_g: F,
    /// δ(1) [g/g].
    pub delta1_g_per_g: F,
    /// δ(2) [g/g²].
    pub delta2_g_per_g2: F,
    /// δ(3) [g/g³].
    pub delta3_g_per_g3: F,
}

impl<F: Float> VeTerms<F> {
    /// The additive component Δ0(1) + Δ0(2) + Δ0(3) \[g\].
    pub fn additive_g(&self) -> F {
        self.d0_1_g + self.d0_2_g + self.d0_3_g
    }
    /// The multiplicative component `δ(1)·a_p3 + δ(2)·a_p3² + δ(3)·a_p3³` \[g\].
    pub fn multiplicative_g(&self, a_p3_g: F) -> F {
        ((self.delta3_g_per_g3 * a_p3_g + self.delta2_g_per_g2) * a_p3_g + self.delta1_g_per_g) * a_p3_g
    }
    /// The whole VE at `a_p3_g`, V(23) \[g\].
    pub fn total_g(&self, a_p3_g: F) -> F {
        self.additive_g() + self.multiplicative_g(a_p3_g)
    }
    /// The terms as an array: Δ0(1), Δ0(2), Δ0(3), δ(1), δ(2), δ(3).
    pub fn to_array(&self) -> [F; 6] {
        [self.d0_1_g, self.d0_2_g, self.d0_3_g, self.delta1_g_per_g, self.delta2_g_per_g2, self.delta3_g_per_g3]
    }
}

/// Vibration of the base in the unit's frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Vibration<F> {
    /// No vibration.
    None,
    /// Harmonic vibration V(3): `a_i(t) = a_pi + amp_g[i]·sin ωt`, all axes in phase (a
    /// negative amplitude is the antiphase component). The frequency does not enter the VE
    /// (`λ(ω) = 1`); it documents the profile.
    Harmonic {
        /// Peak amplitude per axis x, y, z \[g\], signed.
        amp_g: Vec3<F>,
        /// Frequency \[Hz\].
        freq_hz: F,
    },
    /// Broadband random vibration V(4)–V(6): zero-mean stationary Gaussian, flat spectral
    /// density over the band, components fully correlated (the recording format's
    /// convention), so `⟨ã_i ã_j⟩ = σ_i σ_j`.
    Random {
        /// RMS per axis x, y, z \[g\], σ = √(S_B·Δf) V(6).
        sigma_g: Vec3<F>,
        /// Band (f_low, f_up) \[Hz\].
        band_hz: (F, F),
    },
}

impl<F: Float> Vibration<F> {
    /// Random vibration from a flat spectral density per axis [g²/Hz] over a band \[Hz\]:
    /// `σ² = S_B·Δf`, V(6). A negative density or an inverted band gives σ = 0.
    pub fn random_from_psd(psd_g2_per_hz: Vec3<F>, band_hz: (F, F)) -> Self {
        let df = (band_hz.1 - band_hz.0).max(F::ZERO);
        Vibration::Random { sigma_g: psd_g2_per_hz.map(|s| (s.max(F::ZERO) * df).sqrt()), band_hz }
    }

    /// The largest amplitude or σ over the axes \[g\] (0 for none).
    pub fn level_g(&self) -> F {
        match self {
            Vibration::None => F::ZERO,
            Vibration::Harmonic { amp_g: v, .. } | Vibration::Random { sigma_g: v, .. } => {
                v[0].abs().max(v[1].abs()).max(v[2].abs())
            }
        }
    }

    /// The vibration seen by accelerometer `axis`, on its own axes.
    pub fn on_accel(&self, axis: Axis) -> AccelVibration<F> {
        match self {
            Vibration::None => AccelVibration::None,
            Vibration::Harmonic { amp_g, .. } => AccelVibration::Harmonic(AccelAxes::from_unit(amp_g, axis)),
            Vibration::Random { sigma_g, .. } => AccelVibration::Random(AccelAxes::from_unit(sigma_g, axis)),
        }
    }

    /// Converts between float types.
    #[cfg_attr(unstable_target, optimize(size))]
    pub fn cast<G: Float>(&self) -> Vibration<G> {
        let c = |v: &Vec3<F>| v.map(|x| G::from_f64(x.to_f64()));
        match self {
            Vibration::None => Vibration::None,
            Vibration::Harmonic { amp_g, freq_hz } => {
                Vibration::Harmonic { amp_g: c(amp_g), freq_hz: G::from_f64(freq_hz.to_f64()) }
            }
            Vibration::Random { sigma_g, band_hz } => Vibration::Random {
                sigma_g: c(sigma_g),
                band_hz: (G::from_f64(band_hz.0.to_f64()), G::from_f64(band_hz.1.to_f64())),
            },
        }
    }

    /// True when every number is finite, amplitudes/σ are within [`MAX_LEVEL_G`], σ ≥ 0,
    /// the frequency ≥ 0 and the band is ordered and non-negative.
    #[inline(never)]
    #[cfg_attr(unstable_target, optimize(size))]
    pub fn is_valid(&self) -> bool {
        let lim = F::from_f64(MAX_LEVEL_G);
        let ok3 = |v: &Vec3<F>| v.iter().all(|x| x.is_finite() && !(x.abs() > lim));
        match self {
            Vibration::None => true,
            Vibration::Harmonic { amp_g, freq_hz } => ok3(amp_g) && freq_hz.is_finite() && !(*freq_hz < F::ZERO),
            Vibration::Random { sigma_g, band_hz } => {
                ok3(sigma_g)
                    && sigma_g.iter().all(|s| !(*s < F::ZERO))
                    && band_hz.0.is_finite()
                    && band_hz.1.is_finite()
                    && !(band_hz.0 < F::ZERO)
                    && band_hz.0 < band_hz.1
            }
        }
    }
}

/// The vibration seen by one accelerometer, on its own axes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AccelVibration<F> {
    /// No vibration.
    None,
    /// Harmonic, in phase: peak amplitudes `a_B3` (IA), `a_B2` (PA), `a_B1` (OA) \[g\], V(3).
    Harmonic(AccelAxes<F>),
    /// Random Gaussian, fully correlated: σ per axis \[g\], V(4).
    Random(AccelAxes<F>),
}

/// Moments of the vibration `ã` (the part of the acceleration beyond its static value) that
/// the exact VE needs: central moments of the IA component and its covariances with OA and
/// PA. The fifth moment is taken as zero (symmetric vibration).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct VibMoments<F> {
    /// `⟨ã3²⟩` \[g²\].
    pub m2_g2: F,
    /// `⟨ã3³⟩` \[g³\] (zero for harmonic and Gaussian vibration).
    pub m3_g3: F,
    /// `⟨ã3⁴⟩` \[g⁴\].
    pub m4_g4: F,
    /// `⟨ã3 ã1⟩` (IA·OA) \[g²\].
    pub cov_oa_g2: F,
    /// `⟨ã3 ã2⟩` (IA·PA) \[g²\].
    pub cov_pa_g2: F,
}

impl<F: Float> VibMoments<F> {
    /// Harmonic, in phase: `⟨sin²⟩ = 1/2`, `⟨sin⁴⟩ = 3/8`, so `m2 = a_B3²/2`,
    /// `m4 = 3a_B3⁴/8`, `⟨ã3 ã1⟩ = a_B3 a_B1 / 2`.
    pub fn harmonic(amp: AccelAxes<F>) -> Self {
        let half = F::from_f64(0.5);
        let a2 = amp.ia * amp.ia;
        VibMoments {
            m2_g2: half * a2,
            m3_g3: F::ZERO,
            m4_g4: F::from_f64(0.375) * a2 * a2,
            cov_oa_g2: half * amp.ia * amp.oa,
            cov_pa_g2: half * amp.ia * amp.pa,
        }
    }

    /// Gaussian, fully correlated: `m2 = σ3²`, `m4 = 3σ3⁴`, `⟨ã3 ã1⟩ = σ3 σ1`.
    pub fn gaussian(sigma: AccelAxes<F>) -> Self {
        let s2 = sigma.ia * sigma.ia;
        VibMoments {
            m2_g2: s2,
            m3_g3: F::ZERO,
            m4_g4: F::from_f64(3.0) * s2 * s2,
            cov_oa_g2: sigma.ia * sigma.oa,
            cov_pa_g2: sigma.ia * sigma.pa,
        }
    }
}

/// Exact mean rectification of `|a3|` under harmonic vibration:
/// `⟨|a_p + a_B sin ωt|⟩ − |a_p|` \[g\].
///
/// With `r = |a_p|/|a_B|`: `(2/π)·|a_B|·(√(1 − r²) − r·acos r)` for `r < 1`, zero for `r ≥ 1`
/// (the signal no longer crosses zero). At `a_p = 0` it is `(2/π)·|a_B| = 0.637·|a_B|`.
pub fn harmonic_abs_excess_g<F: Float>(a_p_g: F, amp_g: F) -> F {
    let b = amp_g.abs();
    let p = a_p_g.abs();
    if !(p < b) {
        return F::ZERO;
    }
    let r = p / b;
    let root = ((F::ONE - r) * (F::ONE + r)).sqrt();
    let v = F::from_f64(core::f64::consts::FRAC_2_PI) * b * (root - r * r.acos());
    v.max(F::ZERO)
}

/// Exact mean rectification of `|a3|` under Gaussian vibration:
/// `⟨|a_p + ã|⟩ − |a_p| = σ·√(2/π)·exp(−a_p²/2σ²) − |a_p|·erfc(|a_p|/(σ√2))` \[g\]
/// (written without the cancellation of `E|X| − |a_p|`). At `a_p = 0` it is `σ·√(2/π)`.
pub fn gaussian_abs_excess_g<F: Float>(a_p_g: F, sigma_g: F) -> F {
    let s = sigma_g.abs();
    if !(s > F::ZERO) {
        return F::ZERO;
    }
    let p = a_p_g.abs();
    let z = p / (s * F::from_f64(core::f64::consts::SQRT_2));
    let sqrt_2_over_pi = F::from_f64(0.797_884_560_802_865_4);
    let v = s * sqrt_2_over_pi * (-(z * z)).exp() - p * z.erfc();
    v.max(F::ZERO)
}

/// The exact VE terms from the moments of the vibration: the time mean of V(2),
/// `⟨a_u(a_p + ã)⟩ − a_u(a_p)`, expanded term by term (`m` = [`VibMoments`],
/// `abs_excess_g` = `⟨|a_p3 + ã3|⟩ − |a_p3|`):
///
/// - Δ0(1) = 0.5·δ_1A·abs_excess + k2 m2 + k3 m3 + k4 m4
/// - Δ0(2) = m31 ⟨ã3 ã1⟩, Δ0(3) = m32 ⟨ã3 ã2⟩
/// - δ(1) = 3 k3 m2 + 4 k4 m3 + 5 k5 m4
/// - δ(2) = 6 k4 m2 + 10 k5 m3
/// - δ(3) = 10 k5 m2
///
/// With the harmonic moments this is V(13) with the exact asymmetry term; with the Gaussian
/// moments it is V(14) with `3 k4 σ⁴`, `15 k5 σ⁴` and the exact asymmetry term.
pub fn exact_terms<F: Float>(cf: &ConversionFunction<F>, m: &VibMoments<F>, abs_excess_g: F) -> VeTerms<F> {
    let (k2, k3, k4, k5) = (cf.k2_g_per_g2, cf.k3_g_per_g3, cf.k4_g_per_g4, cf.k5_g_per_g5);
    VeTerms {
        d0_1_g: F::from_f64(0.5) * cf.delta_1a * abs_excess_g + k2 * m.m2_g2 + k3 * m.m3_g3 + k4 * m.m4_g4,
        d0_2_g: cf.m31_g_per_g2 * m.cov_oa_g2,
        d0_3_g: cf.m32_g_per_g2 * m.cov_pa_g2,
        delta1_g_per_g: F::from_f64(3.0) * k3 * m.m2_g2
            + F::from_f64(4.0) * k4 * m.m3_g3
            + F::from_f64(5.0) * k5 * m.m4_g4,
        delta2_g_per_g2: F::from_f64(6.0) * k4 * m.m2_g2 + F::from_f64(10.0) * k5 * m.m3_g3,
        delta3_g_per_g3: F::from_f64(10.0) * k5 * m.m2_g2,
    }
}

/// V(13) as printed (harmonic): Δ0(1) = 0.637 δ a_B3 + 0.5 k2 a_B3² + 0.375 k4 a_B3⁴,
/// Δ0(2) = 0.5 m31 a_B3 a_B1, Δ0(3) = 0.5 m32 a_B3 a_B2, δ(1) = 1.5 k3 a_B3² + 1.875 k5 a_B3⁴,
/// δ(2) = 3 k4 a_B3², δ(3) = 5 k5 a_B3² (V(15)/V(16)).
pub fn paper_harmonic_terms<F: Float>(cf: &ConversionFunction<F>, amp: AccelAxes<F>) -> VeTerms<F> {
    let half = F::from_f64(0.5);
    let a = amp.ia;
    let a2 = a * a;
    VeTerms {
        d0_1_g: F::from_f64(PAPER_HARMONIC_ASYMMETRY) * cf.delta_1a * a.abs()
            + half * cf.k2_g_per_g2 * a2
            + F::from_f64(0.375) * cf.k4_g_per_g4 * a2 * a2,
        d0_2_g: half * cf.m31_g_per_g2 * a * amp.oa,
        d0_3_g: half * cf.m32_g_per_g2 * a * amp.pa,
        delta1_g_per_g: F::from_f64(1.5) * cf.k3_g_per_g3 * a2 + F::from_f64(1.875) * cf.k5_g_per_g5 * a2 * a2,
        delta2_g_per_g2: F::from_f64(3.0) * cf.k4_g_per_g4 * a2,
        delta3_g_per_g3: F::from_f64(5.0) * cf.k5_g_per_g5 * a2,
    }
}

/// V(14) as printed (random, σ² = S_B·Δf): Δ0(1) = 0.125 δ σ + k2 σ² + k4 σ⁴,
/// Δ0(2) = m31 σ²_31, Δ0(3) = m32 σ²_32 (fully correlated: σ²_31 = σ3 σ1),
/// δ(1) = 3 k3 σ² + 5 k5 σ⁴, δ(2) = 6 k4 σ², δ(3) = 10 k5 σ².
pub fn paper_random_terms<F: Float>(cf: &ConversionFunction<F>, sigma: AccelAxes<F>) -> VeTerms<F> {
    let s = sigma.ia;
    let s2 = s * s;
    VeTerms {
        d0_1_g: F::from_f64(PAPER_RANDOM_ASYMMETRY) * cf.delta_1a * s.abs()
            + cf.k2_g_per_g2 * s2
            + cf.k4_g_per_g4 * s2 * s2,
        d0_2_g: cf.m31_g_per_g2 * s * sigma.oa,
        d0_3_g: cf.m32_g_per_g2 * s * sigma.pa,
        delta1_g_per_g: F::from_f64(3.0) * cf.k3_g_per_g3 * s2 + F::from_f64(5.0) * cf.k5_g_per_g5 * s2 * s2,
        delta2_g_per_g2: F::from_f64(6.0) * cf.k4_g_per_g4 * s2,
        delta3_g_per_g3: F::from_f64(10.0) * cf.k5_g_per_g5 * s2,
    }
}

/// The VE terms of one accelerometer with conversion function `cf` under `vib`, at the static
/// acceleration `a_p3_g` along its IA (used only by the exact asymmetry term).
pub fn ve_terms<F: Float>(
    cf: &ConversionFunction<F>,
    variant: Variant,
    vib: &AccelVibration<F>,
    a_p3_g: F,
) -> VeTerms<F> {
    match (variant, vib) {
        (_, AccelVibration::None) => VeTerms::default(),
        (Variant::Paper, AccelVibration::Harmonic(amp)) => paper_harmonic_terms(cf, *amp),
        (Variant::Paper, AccelVibration::Random(sigma)) => paper_random_terms(cf, *sigma),
        (Variant::Exact, AccelVibration::Harmonic(amp)) => {
            exact_terms(cf, &VibMoments::harmonic(*amp), harmonic_abs_excess_g(a_p3_g, amp.ia))
        }
        (Variant::Exact, AccelVibration::Random(sigma)) => {
            exact_terms(cf, &VibMoments::gaussian(*sigma), gaussian_abs_excess_g(a_p3_g, sigma.ia))
        }
    }
}

/// Why a vibration configuration was rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VibrationConfigError {
    /// A conversion-function coefficient of this accelerometer (0 = x, 1 = y, 2 = z) is not
    /// finite.
    NonFiniteCoefficients(usize),
    /// More than [`MAX_PROFILES`] profiles.
    TooManyProfiles,
    /// This profile has a non-finite number, a negative σ or frequency, a bad band, or a level
    /// above [`MAX_LEVEL_G`].
    BadProfile(usize),
}

impl core::fmt::Display for VibrationConfigError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            VibrationConfigError::NonFiniteCoefficients(i) => {
                write!(f, "conversion function of accelerometer {i} has a non-finite coefficient")
            }
            VibrationConfigError::TooManyProfiles => write!(f, "more than {MAX_PROFILES} vibration profiles"),
            VibrationConfigError::BadProfile(i) => {
                write!(f, "vibration profile {i} is not finite, negative, or above {MAX_LEVEL_G} g")
            }
        }
    }
}

impl core::error::Error for VibrationConfigError {}

/// Everything that defines the VE compensation, in `f64`: what the calibration file and blob
/// hold. [`VibrationConfig::new`] validates it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VibrationParams {
    /// Conversion function of the x, y, z accelerometer.
    pub cf: [ConversionFunction<f64>; 3],
    /// Formulas used for the profiles (the online estimate always uses the exact moments).
    pub variant: Variant,
    /// Number of valid entries of `profiles`.
    pub n_profiles: u8,
    /// Flight-phase vibration profiles, selected at run time by index.
    pub profiles: [Vibration<f64>; MAX_PROFILES],
}

impl VibrationParams {
    /// Coefficients and variant, no profiles yet.
    pub fn new(cf: [ConversionFunction<f64>; 3], variant: Variant) -> Self {
        VibrationParams { cf, variant, n_profiles: 0, profiles: [Vibration::None; MAX_PROFILES] }
    }

    /// Every check a VE configuration must pass before it is used: finite coefficients, at
    /// most [`MAX_PROFILES`] profiles, each valid ([`Vibration::is_valid`]). One `f64`
    /// implementation for every working precision, kept out of line (see
    /// [`CalibrationParams::validate`](crate::CalibrationParams::validate)).
    #[inline(never)]
    #[cfg_attr(unstable_target, optimize(size))]
    pub fn validate(&self) -> Result<(), VibrationConfigError> {
        for (i, cf) in self.cf.iter().enumerate() {
            if !cf.is_finite() {
                return Err(VibrationConfigError::NonFiniteCoefficients(i));
            }
        }
        let n = self.n_profiles as usize;
        if n > MAX_PROFILES {
            return Err(VibrationConfigError::TooManyProfiles);
        }
        for (i, v) in self.profiles.iter().enumerate().take(n) {
            if !v.is_valid() {
                return Err(VibrationConfigError::BadProfile(i));
            }
        }
        Ok(())
    }

    /// Appends a profile; returns its index, or `TooManyProfiles` when the table is full.
    pub fn push_profile(&mut self, v: Vibration<f64>) -> Result<u8, VibrationConfigError> {
        let i = self.n_profiles as usize;
        let slot = self.profiles.get_mut(i).ok_or(VibrationConfigError::TooManyProfiles)?;
        *slot = v;
        self.n_profiles += 1;
        Ok(i as u8)
    }
}

/// A validated VE configuration in the working precision, immutable after boot.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VibrationConfig<F> {
    cf: [ConversionFunction<F>; 3],
    variant: Variant,
    n_profiles: u8,
    profiles: [Vibration<F>; MAX_PROFILES],
}

impl<F: Float> VibrationConfig<F> {
    /// Validates `p` ([`VibrationParams::validate`]) and casts it to the working precision.
    pub fn new(p: &VibrationParams) -> Result<Self, VibrationConfigError> {
        p.validate()?;
        Ok(Self::from_validated(p))
    }

    /// `p` cast to the working precision, without [`VibrationParams::validate`]: for
    /// parameters already checked value by value, as the blob parser does (its checks imply
    /// `validate`'s; a property test in the host tests holds them so). The image that loads
    /// a blob then needs no second, `f64` copy of the checks.
    #[inline(never)]
    #[cfg_attr(unstable_target, optimize(size))]
    pub fn from_validated(p: &VibrationParams) -> Self {
        let mut profiles = [Vibration::None; MAX_PROFILES];
        for (src, dst) in p.profiles.iter().zip(profiles.iter_mut()).take(p.n_profiles as usize) {
            *dst = src.cast();
        }
        VibrationConfig { cf: p.cf.map(|c| c.cast()), variant: p.variant, n_profiles: p.n_profiles, profiles }
    }

    /// No VE model: every coefficient zero, no profiles; predicts zero.
    pub fn none() -> Self {
        VibrationConfig {
            cf: [ConversionFunction::default(); 3],
            variant: Variant::Exact,
            n_profiles: 0,
            profiles: [Vibration::None; MAX_PROFILES],
        }
    }

    /// The conversion functions of the x, y, z accelerometers.
    pub fn conversion_functions(&self) -> &[ConversionFunction<F>; 3] {
        &self.cf
    }
    /// The variant used for profiles.
    pub fn variant(&self) -> Variant {
        self.variant
    }
    /// Number of profiles.
    pub fn n_profiles(&self) -> usize {
        self.n_profiles as usize
    }
    /// Profile `index`, or `None` past the end.
    pub fn profile(&self, index: usize) -> Option<&Vibration<F>> {
        if index < self.n_profiles as usize { self.profiles.get(index) } else { None }
    }

    /// The VE \[g\] of each accelerometer (unit order x, y, z) under `vib` at the static
    /// acceleration `a_p_g` (only each accelerometer's IA component is used).
    pub fn predict_g(&self, vib: &Vibration<F>, a_p_g: &Vec3<F>) -> Vec3<F> {
        let mut out = [F::ZERO; 3];
        for ((o, cf), axis) in out.iter_mut().zip(self.cf.iter()).zip(Axis::ALL) {
            let a_p3 = AccelAxes::from_unit(a_p_g, axis).ia;
            *o = ve_terms(cf, self.variant, &vib.on_accel(axis), a_p3).total_g(a_p3);
        }
        out
    }

    /// The VE \[g\] to subtract from each axis of a compensated output `y_g` that was measured
    /// under `vib`: the output is `a_p + VE(a_p)` per axis, so `a_p` is found from `y` by
    /// [`solve_static_g`] and the VE is evaluated there (evaluating it at `y` instead would
    /// leave an error of `VE·dVE/da`, 0.14 g for Table V5's worst band at 10 g). Also returns
    /// true when a solution had to be clamped to ±[`MAX_STATIC_G`].
    pub fn correction_for_output_g(&self, vib: &Vibration<F>, y_g: &Vec3<F>) -> (Vec3<F>, bool) {
        let mut out = [F::ZERO; 3];
        let mut clamped = false;
        for ((o, cf), axis) in out.iter_mut().zip(self.cf.iter()).zip(Axis::ALL) {
            let v = vib.on_accel(axis);
            let y = AccelAxes::from_unit(y_g, axis).ia;
            let (ve, c) = solve_static_g(y, |a| ve_terms(cf, self.variant, &v, a));
            *o = ve;
            clamped |= c;
        }
        (out, clamped)
    }

    /// The gain by which each axis's output magnifies a vibration along that axis, from the
    /// measured output moments `m` (about the window mean): with the conversion function's
    /// slope `s`, curvature `c` and third derivative `d` at the mean, the output's vibration is
    /// `s·ã + c·ã²/2 + d·ã³/6`, whose least-squares gain on `ã` is
    /// `s + (c/2)·m3/m2 + (d/6)·m4/m2` (moments of `ã`, first estimated as the output's over
    /// `s^k`). The first-order factor `s` alone would leave 0.4 % of the VE for the AL-15 at
    /// 6 g with 2 g amplitude. Used with [`window::WindowMoments::unscale`]; a gain outside
    /// [1/2, 2] (no real accelerometer) is replaced by 1.
    pub fn output_gains(&self, m: &window::WindowMoments<F>) -> Vec3<F> {
        let mut out = [F::ONE; 3];
        for ((o, cf), axis) in out.iter_mut().zip(self.cf.iter()).zip(Axis::ALL) {
            let (s, c, d) = cf.input_axis_derivatives(AccelAxes::from_unit(&m.mean_g, axis));
            let (mom, _) = m.on_accel(axis);
            let mut g = s;
            if s > F::from_f64(0.5) && mom.m2_g2 > F::ZERO {
                let r = F::ONE / s;
                let m2 = mom.m2_g2 * r * r;
                let m3 = mom.m3_g3 * r * r * r;
                let m4 = mom.m4_g4 * r * r * r * r;
                g = s + (F::from_f64(0.5) * c * m3 + F::from_f64(1.0 / 6.0) * d * m4) / m2;
            }
            *o = if g > F::from_f64(0.5) && g < F::from_f64(2.0) { g } else { F::ONE };
        }
        out
    }

    /// [`correction_for_output_g`](Self::correction_for_output_g) for measured window moments
    /// (the exact moment form, see
    /// [`predict_from_moments_g`](Self::predict_from_moments_g)), with `y_g` the window mean,
    /// for one accelerometer (`axis`; the online estimate solves one per step): its VE \[g\]
    /// and whether its solution was clamped.
    pub fn correction_from_moments_on_g(&self, m: &window::WindowMoments<F>, y_g: &Vec3<F>, axis: Axis) -> (F, bool) {
        let cf = match axis {
            Axis::X => &self.cf[0],
            Axis::Y => &self.cf[1],
            Axis::Z => &self.cf[2],
        };
        let (mom, abs_excess) = m.on_accel(axis);
        let terms = exact_terms(cf, &mom, abs_excess);
        let y = AccelAxes::from_unit(y_g, axis).ia;
        solve_static_g(y, |_| terms)
    }

    /// The exact VE \[g\] of each accelerometer from measured window moments
    /// ([`window::WindowMoments`]): the moment form of [`exact_terms`] with the measured
    /// `⟨|a3|⟩ − |⟨a3⟩|` as the asymmetry input, at the static acceleration `a_p_g`.
    pub fn predict_from_moments_g(&self, m: &window::WindowMoments<F>, a_p_g: &Vec3<F>) -> Vec3<F> {
        let mut out = [F::ZERO; 3];
        for ((o, cf), axis) in out.iter_mut().zip(self.cf.iter()).zip(Axis::ALL) {
            let a_p3 = AccelAxes::from_unit(a_p_g, axis).ia;
            let (mom, abs_excess) = m.on_accel(axis);
            *o = exact_terms(cf, &mom, abs_excess).total_g(a_p3);
        }
        out
    }
}

/// Newton iterations of [`solve_static_g`]: the VE is a cubic in `a_p3` with
/// `|dVE/da| ≤ 0.2` over the model's range for the paper's unit, so 4 steps from `a = y`
/// reach the solution to rounding.
const NEWTON_STEPS: usize = 4;

/// Solves `a + VE(a) = y` for the static IA acceleration `a` (clamped to ±[`MAX_STATIC_G`])
/// by at most four (`NEWTON_STEPS`) Newton steps (fewer once a step leaves `a` unchanged: the rest
/// would repeat it) with `dVE/da = δ(1) + 2δ(2)a + 3δ(3)a²` (the exact
/// asymmetry's slope, below `δ_1A`, is left out); `terms(a)` gives the VE terms at `a`.
/// Returns `VE(a)` \[g\] and whether the solution was clamped. Bounded time, no panic; a
/// non-finite `y` gives zero.
pub fn solve_static_g<F: Float>(y_g: F, terms: impl Fn(F) -> VeTerms<F>) -> (F, bool) {
    if !y_g.is_finite() {
        return (F::ZERO, false);
    }
    let lim = F::from_f64(MAX_STATIC_G);
    let clamp = |a: F| a.max(-lim).min(lim);
    let mut a = clamp(y_g);
    let mut t = terms(a);
    for _ in 0..NEWTON_STEPS {
        let f = a + t.total_g(a) - y_g;
        let three = F::from_f64(3.0);
        let slope =
            F::ONE + t.delta1_g_per_g + (F::from_f64(2.0) * t.delta2_g_per_g2 + three * t.delta3_g_per_g3 * a) * a;
        // A model that is not monotone here (never for a real accelerometer) falls back to a
        // fixed-point step.
        let slope = if slope > F::from_f64(0.5) { slope } else { F::ONE };
        let next = clamp(a - f / slope);
        if next == a {
            // Converged: the remaining steps would repeat this one from the same `a` (and
            // `terms(a)`), so the result is the same bits as after all of them.
            break;
        }
        a = next;
        t = terms(a);
    }
    let ve = t.total_g(a);
    let clamped = !(a.abs() < lim) && !((y_g - ve).abs() <= lim);
    if ve.is_finite() { (ve, clamped) } else { (F::ZERO, clamped) }
}
