//! The per-sample step: raw signals and the unit's temperature in, compensated acceleration
//! and a status word out. Owns the two compensation methods of §5 and the status policy.
//! The equations T(2), T(5)…T(8) it evaluates are written out in `docs/equations.md`.
//!
//! # Sign convention (§4 erratum)
//!
//! T(2)/T(5) as printed give `a(constants at T) − a(constants at T0)`: the amount that must be
//! **added** to the acceleration computed with the T0 constants. The paper's correction
//! `â_k = â − Δa_T` is right only if `Δa_T` denotes the error `â − a_true`, which is the
//! negative of T(5). This crate defines the correction as T(5) itself and adds it:
//! `a = N·(U − U0) + Δa_T`. The host tests check that method 2 agrees with method 1 (which
//! needs no linearisation) to first order; with the opposite sign the error would double.
//!
//! # Policies
//!
//! - Temperature outside the calibrated range: clamped to the nearest edge, flagged
//!   [`Status::TEMP_CLAMPED`].
//! - Non-finite temperature: compensated at T0 (no correction), flagged
//!   [`Status::NONFINITE_INPUT`] and [`Status::TEMP_CLAMPED`].
//! - Non-finite signal of one accelerometer: that signal is replaced by its zero offset (the
//!   axis then contributes no acceleration), flagged [`Status::NONFINITE_INPUT`].
//! - A result that is still not finite (signals so large that the product overflows): the
//!   output is zero, flagged [`Status::NONFINITE_INPUT`].
//! - K(T) singular at the current temperature (method 1; load-time checks make this
//!   practically unreachable): the T0 inverse is used, flagged [`Status::SINGULAR_AT_TEMP`].

use crate::float::{self, Float};
use crate::linalg::{self, Mat3, Vec3};
use crate::model::Constants;
use crate::temperature::{CoefDelta, TempModel, TempModelError};

/// Status bits of one compensated sample. Zero means "compensated, nothing to report".
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Status(pub u32);

impl Status {
    /// Nothing to report.
    pub const OK: Status = Status(0);
    /// Temperature outside the calibrated range: clamped to the edge.
    pub const TEMP_CLAMPED: Status = Status(1 << 0);
    /// A signal or the temperature was NaN/∞, or the result overflowed.
    pub const NONFINITE_INPUT: Status = Status(1 << 1);
    /// No valid calibration: the output is the uncompensated signal (see
    /// [`uncalibrated`](Calibration::uncalibrated)).
    pub const INVALID_CALIBRATION: Status = Status(1 << 2);
    /// K(T) was not invertible at this temperature; the T0 inverse was used.
    pub const SINGULAR_AT_TEMP: Status = Status(1 << 3);
    /// No vibration-error estimate was available, so none was subtracted: the online
    /// estimate has no complete block yet, or the selected vibration profile does not exist (see
    /// [`pipeline`](crate::pipeline)).
    pub const VIBRATION_ESTIMATE_NOT_READY: Status = Status(1 << 4);
    /// The vibration level (σ or amplitude above 10 g) or the static acceleration along an
    /// input axis (above 10 g, V(17)) was outside the VE model's range: clamped to it.
    pub const VIBRATION_OUT_OF_RANGE: Status = Status(1 << 5);
    /// The sampling interrupt lost data since the previous result: a sample was not taken in
    /// its slot (input not ready, or the interrupt ran past its deadline), or a result was
    /// dropped because the consumer's queue was full (see [`replay`](crate::replay)).
    pub const OVERRUN: Status = Status(1 << 6);
    /// An input of this sample was not freshly measured: a sensor driver failed, and the
    /// signals were held or NaN, or the temperature poll failed or the temperature is stale
    /// (see [`drivers`](crate::drivers)).
    pub const SENSOR_FAULT: Status = Status(1 << 8);

    /// True when every bit of `other` is set.
    pub const fn contains(self, other: Status) -> bool {
        self.0 & other.0 == other.0
    }
    /// Sets the bits of `other`.
    pub fn insert(&mut self, other: Status) {
        self.0 |= other.0;
    }
}

impl core::ops::BitOr for Status {
    type Output = Status;
    fn bitor(self, rhs: Status) -> Status {
        Status(self.0 | rhs.0)
    }
}

/// Which form of the output correction method 2 uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Form {
    /// T(5) (polynomial) / T(6) (piecewise-linear) as printed: all four terms of the
    /// bracket. It replaces N by diag(1/K_ii) in the scale term, so besides second-order
    /// terms it differs from method 1 by (cross-sensitivity ratio)·ΔK·a, ≈ 1 mg at 10 g for
    /// the paper's unit at −40 °C.
    Full,
    /// T(7) / T(8): scale-factor and offset terms only, cross-sensitivity terms dropped.
    Simplified,
    /// T(2) without the diagonal approximation: `Δa_T = −N·(ΔK·â + ΔU0)`,
    /// `â = N·(U − U0)`. The exact first-order expansion of method 1 (a project addition to
    /// the paper's forms; it differs from method 1 only by second-order terms).
    Linearized,
}

/// How the temperature is compensated (§5).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// No temperature correction: `a = N·(U − U0)` with the T0 constants. The baseline the
    /// paper's check compares against.
    Uncorrected,
    /// Method 1, coefficient correction: `a = K(T)⁻¹·(U − U0(T))`, exact within the model.
    CoefficientCorrection,
    /// Method 2, output correction: `a = N·(U − U0) + Δa_T` with Δa_T from T(5)…T(8).
    OutputCorrection(Form),
}

/// One compensated sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample<F> {
    /// Specific force along the unit's x, y, z axes \[g\].
    pub accel_g: Vec3<F>,
    /// What happened on the way.
    pub status: Status,
}

/// Why a calibration was rejected when it was loaded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CalibrationError {
    /// A constant at T0 is NaN or infinite.
    NonFiniteConstants,
    /// K at T0 is singular or ill-conditioned (Hadamard ratio below the limit).
    SingularK,
    /// A scale factor K_ii is zero (method 2 divides by it).
    ZeroScaleFactor,
    /// The temperature model is malformed.
    TempModel(TempModelError),
    /// The valid temperature range is empty, not finite, or does not contain T0.
    BadRange,
    /// K(T) becomes singular somewhere inside the valid range, or a scale factor leaves
    /// [1/2, 2]× its T0 value there.
    SingularInRange,
}

impl core::fmt::Display for CalibrationError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            CalibrationError::NonFiniteConstants => write!(f, "a constant at T0 is not finite"),
            CalibrationError::SingularK => write!(f, "K at T0 is singular or ill-conditioned"),
            CalibrationError::ZeroScaleFactor => write!(f, "a scale factor K_ii is zero"),
            CalibrationError::TempModel(e) => write!(f, "temperature model: {e}"),
            CalibrationError::BadRange => write!(f, "valid temperature range is empty, not finite, or excludes T0"),
            CalibrationError::SingularInRange => {
                write!(f, "K(T) becomes singular or implausible inside the valid temperature range")
            }
        }
    }
}

impl core::error::Error for CalibrationError {}

/// Number of temperatures, besides the knots and the range ends, at which a loaded
/// calibration's K(T) is checked.
const RANGE_CHECK_POINTS: usize = 64;

/// Largest plausible change of a scale factor over the calibrated range: K_ii(T)/K_ii(T0)
/// must stay within [1/2, 2]. A model outside that has been extrapolated beyond reason (or
/// drives a scale factor through zero, which no conditioning test on K alone can see, since
/// scaling a row does not change its conditioning).
const MAX_SCALE_RATIO: f64 = 2.0;

/// Everything that defines a calibration, in `f64`: what the blob and the calibration file
/// hold. [`Calibration::new`] validates it and precomputes the per-sample quantities in the
/// working precision.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CalibrationParams {
    /// The 12 constants at T0.
    pub constants: Constants<f64>,
    /// T0 [°C].
    pub t0_c: f64,
    /// Temperature model of the constants.
    pub model: TempModel<f64>,
    /// Compensation method.
    pub method: Method,
    /// Calibrated temperature range [°C]: (min, max).
    pub temp_range_c: (f64, f64),
}

impl CalibrationParams {
    /// The same parameters compensating with another method.
    pub fn with_method(mut self, method: Method) -> Self {
        self.method = method;
        self
    }

    /// Every check a calibration must pass before it is used: finite, invertible constants
    /// with nonzero scale factors, a well-formed temperature model, a finite range that holds
    /// T0, and a K(T) that stays invertible (with each scale factor within [1/2, 2]× its T0
    /// value) at the range's ends, its knots and a grid of 64 steps, so
    /// the run-time fallback is never expected to trigger.
    ///
    /// One implementation for every working precision, run once at load time (by
    /// [`Calibration::new`] and the blob parser). Finiteness is checked in `f64`; the
    /// conditioning of K and K(T) over the range in `f32`, the precision the firmware runs
    /// in, with the same T(3)/T(4) code as the per-sample step: host and target give a blob
    /// the same verdict, and the target needs no `f64` copy of the temperature model or of
    /// the conditioning test.
    pub fn validate(&self) -> Result<(), CalibrationError> {
        self.checked_inverse().map(|_| ())
    }

    /// [`validate`](Self::validate), returning N = K⁻¹ at T0 (`f64`), which the check
    /// computes anyway and [`Calibration::new`] needs. Kept out of line: the boot code of the
    /// firmware calls it from two places and needs one copy of it, not one per caller.
    #[inline(never)]
    #[cfg_attr(unstable_target, optimize(size))]
    fn checked_inverse(&self) -> Result<Mat3<f64>, CalibrationError> {
        let p = self;
        let constants = p.constants;
        if !constants.is_finite() {
            return Err(CalibrationError::NonFiniteConstants);
        }
        // Invertibility is decided in `f32`, like K(T) over the range below; N itself is
        // computed in `f64`, where the precomputation needs it.
        let c = constants.cast::<f32>();
        if c.inverse().is_none() {
            return Err(CalibrationError::SingularK);
        }
        let n = linalg::inverse_unchecked(&constants.k_v_per_g).ok_or(CalibrationError::SingularK)?;
        let k = &constants.k_v_per_g;
        if k[0][0] == 0.0 || k[1][1] == 0.0 || k[2][2] == 0.0 {
            return Err(CalibrationError::ZeroScaleFactor);
        }
        p.model.check().map_err(CalibrationError::TempModel)?;
        let (lo, hi) = p.temp_range_c;
        if !(lo.is_finite() && hi.is_finite() && p.t0_c.is_finite() && lo < hi && lo <= p.t0_c && p.t0_c <= hi) {
            return Err(CalibrationError::BadRange);
        }
        let (model, t0_c) = (p.model.cast::<f32>(), f32::from_f64(p.t0_c));
        // The fraction i/64 as a running sum of 1/64 (exact), not a conversion of i: the
        // target then needs no integer-to-f64 conversion.
        let mut frac = 0.0;
        for _ in 0..=RANGE_CHECK_POINTS {
            let t = lo + (hi - lo) * frac;
            check_k_at(&c, &model, t0_c, f32::from_f64(t))?;
            frac += 1.0 / RANGE_CHECK_POINTS as f64;
        }
        if let TempModel::Pwl { n_knots, knots_c, .. } = &p.model {
            for &kn in knots_c.iter().take(*n_knots as usize) {
                if kn > lo && kn < hi {
                    check_k_at(&c, &model, t0_c, f32::from_f64(kn))?;
                }
            }
        }
        Ok(n)
    }

    /// The constants at `temp_c` by T(3)/T(4), in `f64`:
    /// `K_ij(T) = K_ij·(1 + ΔK_ij/K_ij)`, `U0(T) = U0 + ΔU0`.
    pub fn constants_at(&self, temp_c: f64) -> Constants<f64> {
        apply_delta(&self.constants, &self.model.delta(temp_c, self.t0_c))
    }
}

/// K(T) at `temp_c` (T(3)/T(4) from the constants `c` at T0) is invertible and each scale
/// factor within [1/2, 2]× its T0 value ([`MAX_SCALE_RATIO`]).
#[cfg_attr(unstable_target, optimize(size))]
fn check_k_at<F: Float>(c: &Constants<F>, model: &TempModel<F>, t0_c: F, temp_c: F) -> Result<(), CalibrationError> {
    let kt = apply_delta(c, &model.delta(temp_c, t0_c));
    let k = &c.k_v_per_g;
    let ratio = F::from_f64(MAX_SCALE_RATIO);
    let plausible = (0..3).all(|i| (F::ONE / ratio..=ratio).contains(&(kt.k_v_per_g[i][i] / k[i][i])));
    if kt.inverse().is_none() || !plausible { Err(CalibrationError::SingularInRange) } else { Ok(()) }
}

/// The constants moved by `d`.
fn apply_delta<F: Float>(c: &Constants<F>, d: &CoefDelta<F>) -> Constants<F> {
    let mut out = *c;
    for i in 0..3 {
        out.u0_v[i] += d.du0_v[i];
        for j in 0..3 {
            out.k_v_per_g[i][j] += c.k_v_per_g[i][j] * d.rel_k[i][j];
        }
    }
    out
}

/// A validated calibration: everything the per-sample step needs, immutable after boot.
///
/// Precision: N = K⁻¹ is computed in `f64` at load time and its diagonal kept as a
/// double-word (hi + lo) pair, and `N·(U − U0)` is evaluated with error-free transformations
/// on the diagonal (TwoSum, Veltkamp/Dekker TwoProduct). All temperature-dependent parts are
/// small corrections to that product. In `f32` the result is then within about one rounding
/// of the output (≈0.5 µg at 10 g) of the `f64` reference, instead of the several µg a plain
/// `f32` inverse and product would lose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Calibration<F> {
    params: CalibrationParams,
    t0_c: F,
    constants: Constants<F>,
    /// N = K⁻¹ at T0, rounded (diagonal = hi part).
    n_g_per_v: Mat3<F>,
    /// Veltkamp split of the diagonal's hi part.
    n_diag_split: [(F, F); 3],
    /// Low part of the diagonal: N_ii − hi.
    n_diag_lo: Vec3<F>,
    /// 1/K_ii at T0 ([`float::recip`] in `f64`, rounded).
    inv_diag: Vec3<F>,
    model: TempModel<F>,
    method: Method,
    temp_min_c: F,
    temp_max_c: F,
    valid: bool,
    /// A hash of `params` (0 for [`uncalibrated`](Self::uncalibrated)): what [`TempCache`]
    /// keys on, so that terms of one calibration are never applied with another.
    fingerprint: u64,
}

/// A 64-bit hash of everything that defines a calibration (FNV-1a-style over the bits of
/// each number). Equal parameters give equal hashes; two different calibrations collide
/// with probability about 2⁻⁶⁴.
#[inline(never)]
#[cfg_attr(unstable_target, optimize(size))]
fn fingerprint(p: &CalibrationParams) -> u64 {
    let c = &p.constants;
    let method = match p.method {
        Method::Uncorrected => 1,
        Method::CoefficientCorrection => 2,
        Method::OutputCorrection(Form::Full) => 3,
        Method::OutputCorrection(Form::Simplified) => 4,
        Method::OutputCorrection(Form::Linearized) => 5,
    };
    let mut h = mix(FNV_OFFSET, &[method]);
    for i in 0..3 {
        h = mix_f64(h, &c.k_v_per_g[i]);
    }
    h = mix_f64(h, &c.u0_v);
    h = mix_f64(h, &[p.t0_c, p.temp_range_c.0, p.temp_range_c.1]);
    match &p.model {
        TempModel::Poly { order, coef } => {
            h = mix(h, &[0x100 + *order as u64]);
            for d in coef {
                h = mix_f64(h, &d.to_array());
            }
        }
        TempModel::Pwl { n_knots, knots_c, at_knot } => {
            h = mix(h, &[0x200 + *n_knots as u64]);
            h = mix_f64(h, knots_c);
            for d in at_knot {
                h = mix_f64(h, &d.to_array());
            }
        }
    }
    h
}

/// FNV-1a's offset basis.
const FNV_OFFSET: u64 = 0xcbf2_9ce4_8422_2325;

/// `h` with the words `w` mixed in (FNV-1a-style, a word at a time).
#[inline(never)]
#[cfg_attr(unstable_target, optimize(size))]
fn mix(mut h: u64, w: &[u64]) -> u64 {
    for &x in w {
        h = (h ^ x).wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// `h` with the bits of the numbers `xs` mixed in.
#[inline(never)]
#[cfg_attr(unstable_target, optimize(size))]
fn mix_f64(mut h: u64, xs: &[f64]) -> u64 {
    for x in xs {
        h = mix(h, &[x.to_bits()]);
    }
    h
}

impl<F: Float> Calibration<F> {
    /// Validates `p` ([`CalibrationParams::validate`]) and precomputes. Fails on non-finite
    /// or singular constants, a malformed temperature model, a bad range, or a K(T) that
    /// becomes singular (or a scale factor that leaves [1/2, 2]× its T0 value) inside the
    /// range.
    #[inline(never)]
    #[cfg_attr(unstable_target, optimize(size))]
    pub fn new(p: &CalibrationParams) -> Result<Self, CalibrationError> {
        let n = p.checked_inverse()?;
        let constants = p.constants;
        let k = &constants.k_v_per_g;
        let (lo, hi) = p.temp_range_c;
        let n_f: Mat3<F> = linalg::cast_mat(&n);
        let lo_at = |i: usize| F::from_f64(n[i][i] - n_f[i][i].to_f64());
        let n_diag_lo = [lo_at(0), lo_at(1), lo_at(2)];
        Ok(Calibration {
            params: *p,
            t0_c: F::from_f64(p.t0_c),
            constants: constants.cast(),
            n_g_per_v: n_f,
            n_diag_split: [float::split(n_f[0][0]), float::split(n_f[1][1]), float::split(n_f[2][2])],
            n_diag_lo,
            inv_diag: [0, 1, 2].map(|i| F::from_f64(float::recip(k[i][i]))),
            model: p.model.cast(),
            method: p.method,
            temp_min_c: F::from_f64(lo),
            temp_max_c: F::from_f64(hi),
            valid: true,
            fingerprint: fingerprint(p),
        })
    }

    /// The stand-in used when no valid calibration exists: identity K, zero offsets, no
    /// temperature model. Every sample it produces carries [`Status::INVALID_CALIBRATION`]
    /// and its output is the raw signal in volts, unscaled.
    pub fn uncalibrated() -> Self {
        let one = [[F::ONE, F::ZERO, F::ZERO], [F::ZERO, F::ONE, F::ZERO], [F::ZERO, F::ZERO, F::ONE]];
        let one64 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        Calibration {
            params: CalibrationParams {
                constants: Constants { k_v_per_g: one64, u0_v: [0.0; 3] },
                t0_c: 0.0,
                model: TempModel::Poly { order: 1, coef: [CoefDelta::zero(); 4] },
                method: Method::Uncorrected,
                temp_range_c: (-1.0e30, 1.0e30),
            },
            t0_c: F::ZERO,
            constants: Constants { k_v_per_g: one, u0_v: [F::ZERO; 3] },
            n_g_per_v: one,
            n_diag_split: [float::split(F::ONE); 3],
            n_diag_lo: [F::ZERO; 3],
            inv_diag: [F::ONE; 3],
            model: TempModel::Poly { order: 1, coef: [CoefDelta::zero(); 4] },
            method: Method::Uncorrected,
            temp_min_c: F::from_f64(-1.0e30),
            temp_max_c: F::from_f64(1.0e30),
            valid: false,
            fingerprint: 0,
        }
    }

    /// The parameters this calibration was built from.
    pub fn params(&self) -> &CalibrationParams {
        &self.params
    }

    /// The compensation method in use.
    pub fn method(&self) -> Method {
        self.method
    }
    /// T0 [°C].
    pub fn t0_c(&self) -> F {
        self.t0_c
    }
    /// The constants at T0.
    pub fn constants(&self) -> &Constants<F> {
        &self.constants
    }
    /// The temperature model.
    pub fn model(&self) -> &TempModel<F> {
        &self.model
    }
    /// The calibrated temperature range [°C].
    pub fn temp_range_c(&self) -> (F, F) {
        (self.temp_min_c, self.temp_max_c)
    }
    /// False for [`uncalibrated`](Self::uncalibrated).
    pub fn is_valid(&self) -> bool {
        self.valid
    }

    /// The constants at `temp_c` by T(3)/T(4): `K_ij(T) = K_ij·(1 + ΔK_ij/K_ij)`,
    /// `U0(T) = U0 + ΔU0`.
    pub fn constants_at(&self, temp_c: F) -> Constants<F> {
        apply_delta(&self.constants, &self.model.delta(temp_c, self.t0_c))
    }

    /// `N·(U − U0')` with N at T0 and any offsets `u0_v`, accurate to about one rounding of
    /// the result (see the type's note on precision).
    #[inline(always)]
    fn apply_n(&self, u_v: &Vec3<F>, u0_v: &Vec3<F>) -> Vec3<F> {
        let v = [0, 1, 2].map(|i| float::two_sum(u_v[i], -u0_v[i]));
        let n = &self.n_g_per_v;
        let mut a = [F::ZERO; 3];
        for i in 0..3 {
            let (p, pe) = float::two_prod_split(v[i].0, self.n_diag_split[i]);
            let mut small = pe + n[i][i] * v[i].1 + self.n_diag_lo[i] * v[i].0;
            for j in 0..3 {
                if j != i {
                    small += n[i][j] * (v[j].0 + v[j].1);
                }
            }
            a[i] = p + small;
        }
        a
    }

    /// Method 1's correction matrix at a temperature: with X = N·ΔK(T),
    /// `K(T)⁻¹ = (I + X)⁻¹·N`, so `a = a₀ + M·a₀` with `M = −(I + X)⁻¹·X` and
    /// `a₀ = N·(U − U0(T))`. M is small (|X| ≲ 10⁻²), so its rounding errors are negligible
    /// beside a₀'s. `None` when K(T) is not invertible.
    #[inline(always)]
    fn method1_matrix(&self, d: &CoefDelta<F>) -> Option<Mat3<F>> {
        let k = &self.constants.k_v_per_g;
        let mut dk = [[F::ZERO; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                dk[i][j] = k[i][j] * d.rel_k[i][j];
            }
        }
        let x = linalg::mat_mul(&self.n_g_per_v, &dk);
        let mut y = x;
        for (i, row) in y.iter_mut().enumerate() {
            row[i] += F::ONE;
        }
        let inv = linalg::inverse_checked(&y, F::from_f64(linalg::MIN_HADAMARD_RATIO))?;
        let mut m = linalg::mat_mul(&inv, &x);
        for row in m.iter_mut() {
            for v in row.iter_mut() {
                *v = -*v;
            }
        }
        Some(m)
    }

    /// The output correction Δa_T of T(5)/T(6) (full) or T(7)/T(8) (simplified) for signals
    /// `u_v` and coefficient changes `d`: the amount to **add** to `N·(U − U0)` (see the
    /// module's note on the sign). With `v = U − U0`, per axis i:
    ///
    /// `Δa_i = −v_i/K_ii·β_ii − α_i/K_ii` (simplified), plus in the full form
    /// `− Σ_{j≠i} v_j·K_ij·γ_ij/(K_ii·K_jj) + Σ_{j≠i} K_ij·α_j/(K_ii·K_jj)`.
    ///
    /// [`Form::Linearized`] is `−N·(ΔK·â + ΔU0)` with `â = N·v`.
    #[inline(always)]
    pub fn output_correction(&self, v: &Vec3<F>, d: &CoefDelta<F>, form: Form) -> Vec3<F> {
        let k = &self.constants.k_v_per_g;
        let r = &self.inv_diag;
        if form == Form::Linearized {
            let n = &self.n_g_per_v;
            let a_hat = linalg::mat_vec(n, v);
            let mut w = d.du0_v;
            for (i, wi) in w.iter_mut().enumerate() {
                for j in 0..3 {
                    *wi += k[i][j] * d.rel_k[i][j] * a_hat[j];
                }
            }
            let c = linalg::mat_vec(n, &w);
            return [-c[0], -c[1], -c[2]];
        }
        let mut out = [F::ZERO; 3];
        for i in 0..3 {
            let mut c = -(v[i] * d.rel_k[i][i] + d.du0_v[i]) * r[i];
            if form == Form::Full {
                for j in 0..3 {
                    if j != i {
                        c += k[i][j] * r[i] * r[j] * (d.du0_v[j] - v[j] * d.rel_k[i][j]);
                    }
                }
            }
            out[i] = c;
        }
        out
    }

    /// The per-sample step: signals `u_v` \[V\] and the unit's temperature `temp_c` [°C] to
    /// specific force \[g\] and status. Allocation-free, panic-free, bounded time; the output is
    /// always finite (see the module's policies). Equal, bit for bit, to
    /// [`apply`](Self::apply) of [`at_temperature`](Self::at_temperature).
    ///
    /// # Example
    ///
    /// The paper's unit with its two-range model (T(4)/T(12)) and method 1, in `f32`: lying
    /// in TP1 (1 g along z) at +70 °C, where its constants are those of Tables T1/T2.
    ///
    /// ```
    /// use bins_comp::compensate::{Calibration, Method, Status};
    /// use bins_comp::paper;
    ///
    /// let params = paper::params(paper::two_range_model()?, Method::CoefficientCorrection);
    /// let cal = Calibration::<f32>::new(&params)?;
    /// let u_v = paper::TABLE_CONSTANTS[2].signals_v(&[0.0, 0.0, 1.0]).map(|u| u as f32);
    ///
    /// let sample = cal.compensate(u_v, 70.0);
    /// assert_eq!(sample.status, Status::OK);
    /// let [x, y, z] = sample.accel_g;
    /// assert!(x.abs() < 2e-6 && y.abs() < 2e-6 && (z - 1.0).abs() < 2e-6, "{x} {y} {z}");
    ///
    /// // The T0 constants alone are off by milli-g at +70 °C (U0_y moved by 2 mV).
    /// let t0_only = Calibration::<f32>::new(&params.with_method(Method::Uncorrected))?;
    /// assert!(t0_only.compensate(u_v, 70.0).accel_g[1].abs() > 1e-3);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    #[inline]
    pub fn compensate(&self, u_v: Vec3<F>, temp_c: F) -> Sample<F> {
        self.apply(u_v, &self.at_temperature(temp_c))
    }

    /// The temperature-dependent half of the step: everything [`apply`](Self::apply) needs
    /// that depends on `temp_c` alone (the clamped temperature's flags; method 1's
    /// `U0(T)` and correction matrix M; method 2's coefficient changes). A pure function of
    /// `temp_c`, so a caller may keep it while the temperature reading does not change
    /// ([`TempCache`]) without changing any result.
    #[inline]
    pub fn at_temperature(&self, temp_c: F) -> AtTemperature<F> {
        let mut status = Status::OK;
        if !self.valid {
            status.insert(Status::INVALID_CALIBRATION);
        }
        let t = if !temp_c.is_finite() {
            status.insert(Status::NONFINITE_INPUT | Status::TEMP_CLAMPED);
            self.t0_c
        } else if temp_c < self.temp_min_c {
            status.insert(Status::TEMP_CLAMPED);
            self.temp_min_c
        } else if temp_c > self.temp_max_c {
            status.insert(Status::TEMP_CLAMPED);
            self.temp_max_c
        } else {
            temp_c
        };
        let terms = match self.method {
            Method::Uncorrected => TempTerms::None,
            Method::CoefficientCorrection => {
                let d = self.model.delta(t, self.t0_c);
                let u0 = &self.constants.u0_v;
                let u0_t = [u0[0] + d.du0_v[0], u0[1] + d.du0_v[1], u0[2] + d.du0_v[2]];
                let m = self.method1_matrix(&d);
                if m.is_none() {
                    status.insert(Status::SINGULAR_AT_TEMP);
                }
                TempTerms::Method1 { u0_t, m }
            }
            Method::OutputCorrection(form) => TempTerms::Method2 { d: self.model.delta(t, self.t0_c), form },
        };
        AtTemperature { status, terms }
    }

    /// The signal-dependent half of the step: signals `u_v` \[V\] to specific force \[g\] with
    /// the temperature terms `at` of [`at_temperature`](Self::at_temperature) (T(1) with
    /// method 1 or 2 of §5).
    #[inline]
    pub fn apply(&self, u_v: Vec3<F>, at: &AtTemperature<F>) -> Sample<F> {
        let mut status = at.status;
        let mut u = u_v;
        for i in 0..3 {
            if !u[i].is_finite() {
                u[i] = self.constants.u0_v[i];
                status.insert(Status::NONFINITE_INPUT);
            }
        }
        // One N·(U − U0) for every method (method 1 with U0(T)), then the method's correction.
        let u0 = match &at.terms {
            TempTerms::Method1 { u0_t, .. } => u0_t,
            TempTerms::None | TempTerms::Method2 { .. } => &self.constants.u0_v,
        };
        let a0 = self.apply_n(&u, u0);
        let correction = match &at.terms {
            TempTerms::None | TempTerms::Method1 { m: None, .. } => None,
            TempTerms::Method1 { m: Some(m), .. } => Some(linalg::mat_vec(m, &a0)),
            TempTerms::Method2 { d, form } => Some(self.output_correction(&linalg::vec_sub(&u, u0), d, *form)),
        };
        let mut a = match correction {
            Some(c) => [a0[0] + c[0], a0[1] + c[1], a0[2] + c[2]],
            None => a0,
        };
        if !(a[0].is_finite() && a[1].is_finite() && a[2].is_finite()) {
            a = [F::ZERO; 3];
            status.insert(Status::NONFINITE_INPUT);
        }
        Sample { accel_g: a, status }
    }
}

/// What the step needs at one temperature, by method.
#[derive(Clone, Copy, Debug, PartialEq)]
enum TempTerms<F> {
    /// No temperature correction.
    None,
    /// Method 1: `U0(T)` \[V\] and M (`None` when K(T) is singular: the T0 inverse is used).
    Method1 { u0_t: Vec3<F>, m: Option<Mat3<F>> },
    /// Method 2: the coefficient changes of T(3)/T(4) and the form of the correction.
    Method2 { d: CoefDelta<F>, form: Form },
}

/// The temperature-dependent half of the per-sample step
/// ([`Calibration::at_temperature`]): the temperature's status flags and the method's terms.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AtTemperature<F> {
    status: Status,
    terms: TempTerms<F>,
}

impl<F: Float> AtTemperature<F> {
    /// The flags the temperature contributes (clamped, non-finite, singular K(T), invalid
    /// calibration).
    pub fn status(&self) -> Status {
        self.status
    }
}

/// The temperature terms of the last temperature reading, kept while the reading does not
/// change. A temperature sensor converts far more slowly than the accelerometers are sampled
/// (the TMP117's shortest cycle is 15.5 ms, 16 samples at 1 kHz), so most samples reuse the
/// terms and skip the temperature model and method 1's 3×3 inverse. Results are the same,
/// bit for bit, as without the cache.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TempCache<F> {
    /// The calibration's fingerprint and the reading the terms were computed for (`None`:
    /// nothing cached yet).
    key: Option<(u64, F)>,
    at: AtTemperature<F>,
}

impl<F: Float> Default for TempCache<F> {
    fn default() -> Self {
        Self::new()
    }
}

impl<F: Float> TempCache<F> {
    /// Empty: the first lookup computes.
    pub const fn new() -> Self {
        TempCache { key: None, at: AtTemperature { status: Status::OK, terms: TempTerms::None } }
    }

    /// The terms of `cal` at `temp_c`, recomputed only when `temp_c` differs from the last
    /// reading or `cal` from the last calibration (by fingerprint); a non-finite reading is
    /// never reused.
    #[inline]
    pub fn get(&mut self, cal: &Calibration<F>, temp_c: F) -> &AtTemperature<F> {
        let key = Some((cal.fingerprint, temp_c));
        if self.key != key {
            self.at = cal.at_temperature(temp_c);
            self.key = key;
        }
        &self.at
    }

    /// Forgets the cached terms.
    pub fn invalidate(&mut self) {
        self.key = None;
    }
}
