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

use crate::float::cmp_f64::{eq, le, lt};
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
    /// the conditioning test. Kept out of line: the boot code of the firmware calls it from
    /// two places and needs one copy of it, not one per caller.
    #[inline(never)]
    #[cfg_attr(unstable_target, optimize(size))]
    pub fn validate(&self) -> Result<(), CalibrationError> {
        let p = self;
        let constants = p.constants;
        if !constants.is_finite() {
            return Err(CalibrationError::NonFiniteConstants);
        }
        // Invertibility is decided in `f32`, like K(T) over the range below.
        let c = constants.cast::<f32>();
        if c.inverse().is_none() {
            return Err(CalibrationError::SingularK);
        }
        let k = &constants.k_v_per_g;
        if eq(k[0][0], 0.0) || eq(k[1][1], 0.0) || eq(k[2][2], 0.0) {
            return Err(CalibrationError::ZeroScaleFactor);
        }
        p.model.check().map_err(CalibrationError::TempModel)?;
        let (lo, hi) = p.temp_range_c;
        if !(lo.is_finite() && hi.is_finite() && p.t0_c.is_finite() && lt(lo, hi) && le(lo, p.t0_c) && le(p.t0_c, hi)) {
            return Err(CalibrationError::BadRange);
        }
        let (model, t0_c) = (p.model.cast::<f32>(), f32::from_f64(p.t0_c));
        // The grid in `f32` (the target has no `f64` arithmetic), the fraction i/64 as a
        // running sum of 1/64 (exact).
        let (lo32, hi32) = (f32::from_f64(lo), f32::from_f64(hi));
        let mut frac = 0.0f32;
        for _ in 0..=RANGE_CHECK_POINTS {
            check_k_at(&c, &model, t0_c, lo32 + (hi32 - lo32) * frac)?;
            frac += 1.0 / RANGE_CHECK_POINTS as f32;
        }
        if let TempModel::Pwl { n_knots, knots_c, .. } = &p.model {
            for &kn in knots_c.iter().take(*n_knots as usize) {
                if lt(lo, kn) && lt(kn, hi) {
                    check_k_at(&c, &model, t0_c, f32::from_f64(kn))?;
                }
            }
        }
        Ok(())
    }

    /// The constants at `temp_c` by T(3)/T(4), in `f64`:
    /// `K_ij(T) = K_ij·(1 + ΔK_ij/K_ij)`, `U0(T) = U0 + ΔU0`.
    pub fn constants_at(&self, temp_c: f64) -> Constants<f64> {
        apply_delta(&self.constants, &self.model.delta(temp_c, self.t0_c))
    }
}

/// N = K⁻¹ in the working precision with its diagonal as a double-word pair: N (diagonal =
/// hi part) and the diagonal's low part, from K in `f64` without `f64` arithmetic (the target
/// has none). K is split into hi + lo pairs ([`Float::split_f64`]); N₀, the inverse of K's hi
/// part, is refined by one Newton step `N = N₀ + N₀·R` with the residual `R = I − K·N₀`
/// computed from both parts by fused multiply-adds (R ~ 10⁻⁷ against the ~1 of each product
/// it is the difference of, so its rounding is ~10⁻¹⁰ of N): N within ~10⁻⁹ of K⁻¹,
/// relative. `None` when K's hi part is singular.
#[inline(never)]
#[cfg_attr(unstable_target, optimize(size))]
fn inverse_hi_lo<F: Float>(k: &Mat3<f64>) -> Option<(Mat3<F>, Vec3<F>)> {
    let split = k.map(|row| row.map(F::split_f64));
    let k_hi = split.map(|row| row.map(|(h, _)| h));
    let n0 = linalg::inverse_unchecked(&k_hi)?;
    let mut r = [[F::ZERO; 3]; 3];
    for (i, (row, k_row)) in r.iter_mut().zip(&split).enumerate() {
        for (j, cell) in row.iter_mut().enumerate() {
            // The largest product first (K_ii·N₀_ij: the one near 1 on the diagonal).
            let mut acc = if i == j { F::ONE } else { F::ZERO };
            let n = |m: usize| n0.get(m).and_then(|row| row.get(j)).copied().unwrap_or(F::ZERO);
            for m in [i, (i + 1) % 3, (i + 2) % 3] {
                if let Some(&(k_hi, _)) = k_row.get(m) {
                    acc = (-k_hi).mul_add(n(m), acc);
                }
            }
            for (m, &(_, k_lo)) in k_row.iter().enumerate() {
                acc = (-k_lo).mul_add(n(m), acc);
            }
            *cell = acc;
        }
    }
    let corr = linalg::mat_mul_fused(&n0, &r);
    let mut n = n0;
    for (i, (row, c_row)) in n.iter_mut().zip(&corr).enumerate() {
        for (j, (x, c)) in row.iter_mut().zip(c_row).enumerate() {
            if i != j {
                *x += *c;
            }
        }
    }
    Some((n, [corr[0][0], corr[1][1], corr[2][2]]))
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
/// Every method is an affine map of the signals at a given temperature, `a = A(T)·U − c(T)`
/// (method 1: `A = K(T)⁻¹`, `c = A·U0(T)`; method 2: T(5)…T(8) are linear in `U − U0`; see
/// [`at_temperature`](Self::at_temperature)). A and c are computed once per temperature
/// reading, so the per-sample work is one 3×3 product and an offset.
///
/// Precision: N = K⁻¹ is computed at load time to about twice the working precision (from K
/// in `f64`, without `f64` arithmetic: `inverse_hi_lo`) and its diagonal kept as a
/// double-word (hi + lo) pair; A is N plus a small temperature-dependent part, which joins the
/// low part of the diagonal. Per sample every other term is small beside the dominant product
/// `hi·U_i`, which is added to their sum in one fused multiply-add (the product exact, one
/// rounding). In `f32` the result is then within about one rounding of the output (≈0.5 µg at
/// 10 g) of the `f64` reference, instead of the several µg a plain `f32` inverse and product
/// would lose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Calibration<F> {
    t0_c: F,
    constants: Constants<F>,
    /// N = K⁻¹ at T0, rounded (diagonal = hi part).
    n_g_per_v: Mat3<F>,
    /// The map at T0 (no temperature correction): N with its diagonal's low part (N_ii − hi)
    /// in place of the diagonal, and `−N·U0` \[g\] (see [`AtTemperature`]).
    lin0: Mat3<F>,
    neg_offset0_g: Vec3<F>,
    /// 1/K_ii at T0 ([`float::recip`] in `f64`, rounded).
    inv_diag: Vec3<F>,
    model: TempModel<F>,
    /// The model of method 1's (and the linearised form's) terms: each set's ΔU0 kept, its
    /// ΔK/K replaced by `X_c = N·(K ∘ c)`. X(T) = N·ΔK(T) is linear in the sets, so a new
    /// reading evaluates it directly, without forming ΔK(T) and the product (N with its
    /// diagonal's hi part, as in [`at_temperature`](Self::at_temperature)).
    model_x: TempModel<F>,
    method: Method,
    temp_min_c: F,
    temp_max_c: F,
    valid: bool,
    /// A hash of the [`CalibrationParams`] it was built from (0 for
    /// [`uncalibrated`](Self::uncalibrated)): what [`TempCache`]
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
        p.validate()?;
        let constants = p.constants;
        let (lo, hi) = p.temp_range_c;
        let (n, n_diag_lo) = inverse_hi_lo(&constants.k_v_per_g).ok_or(CalibrationError::SingularK)?;
        let constants_f: Constants<F> = constants.cast();
        let k = &constants_f.k_v_per_g;
        let mut lin0 = n;
        for (i, row) in lin0.iter_mut().enumerate() {
            if let (Some(x), Some(&lo)) = (row.get_mut(i), n_diag_lo.get(i)) {
                *x = lo;
            }
        }
        let model: TempModel<F> = p.model.cast();
        let model_x =
            model.map_sets(|c| CoefDelta { du0_v: c.du0_v, rel_k: linalg::mat_mul_fused(&n, &delta_k(k, c)) });
        Ok(Calibration {
            t0_c: F::from_f64(p.t0_c),
            constants: constants_f,
            n_g_per_v: n,
            lin0,
            neg_offset0_g: neg_offset(&n, &lin0, &constants_f.u0_v, &[F::ZERO; 3]),
            inv_diag: [0, 1, 2].map(|i| float::recip(k[i][i])),
            model,
            model_x,
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
        Calibration {
            t0_c: F::ZERO,
            constants: Constants { k_v_per_g: one, u0_v: [F::ZERO; 3] },
            n_g_per_v: one,
            lin0: [[F::ZERO; 3]; 3],
            neg_offset0_g: [F::ZERO; 3],
            inv_diag: [F::ONE; 3],
            model: TempModel::Poly { order: 1, coef: [CoefDelta::zero(); 4] },
            model_x: TempModel::Poly { order: 1, coef: [CoefDelta::zero(); 4] },
            method: Method::Uncorrected,
            temp_min_c: F::from_f64(-1.0e30),
            temp_max_c: F::from_f64(1.0e30),
            valid: false,
            fingerprint: 0,
        }
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

    /// The affine map `A·U − c` of [`AtTemperature`] applied to the signals `u`: per axis the
    /// small terms (the diagonal's low part, the off-diagonal terms, the offset) as one fused
    /// sum, then the dominant `hi_i·U_i` (hi = N_ii rounded) added to it in one fused
    /// multiply-add: the product exact, one rounding of the result. Non-finite when a signal
    /// is (its own axis at least).
    #[inline(always)]
    fn affine(&self, u: &Vec3<F>, at: &AtTemperature<F>) -> Vec3<F> {
        let n = &self.n_g_per_v;
        let l = &at.lin;
        let c = &at.neg_offset_g;
        let row = |i: usize, j: usize, k: usize| {
            let small = l[i][k].mul_add(u[k], l[i][j].mul_add(u[j], l[i][i].mul_add(u[i], c[i])));
            n[i][i].mul_add(u[i], small)
        };
        [row(0, 1, 2), row(1, 2, 0), row(2, 0, 1)]
    }

    /// The status and temperature [°C] the model is evaluated at: the reading, or clamped to
    /// the calibrated range, or T0 for a non-finite reading (see the module's policies).
    #[inline(always)]
    fn clamped(&self, temp_c: F) -> (F, Status) {
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
        (t, status)
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

    /// The temperature-dependent half of the step: the affine map `a = A·U − c` every method
    /// reduces to at `temp_c` (clamped to the range, with its flags), with
    ///
    /// - no correction: `A = N`, `c = N·U0`;
    /// - method 1: `A = K(T)⁻¹`, `c = A·U0(T)`. With `X = N·ΔK(T)`,
    ///   `K(T)⁻¹ = (I + X)⁻¹·N = N − (I + X)⁻¹·X·N`: the correction to N is small
    ///   (|X| ≲ 10⁻²), so its rounding errors are negligible beside N's. K(T) not invertible
    ///   (the Hadamard test of [`linalg::inverse_checked`] on I + X): N, flagged
    ///   [`Status::SINGULAR_AT_TEMP`];
    /// - method 2: `a = N·(U − U0) + Δa_T` with Δa_T of T(5)…T(8) linear in `v = U − U0`:
    ///   per axis i, `Δa_i = −v_i/K_ii·β_ii − α_i/K_ii` (simplified, T(7)/T(8)), plus in the
    ///   full form T(5)/T(6) `− Σ_{j≠i} v_j·K_ij·γ_ij/(K_ii·K_jj) + Σ_{j≠i} K_ij·α_j/(K_ii·K_jj)`;
    ///   linearised, `Δa_T = −N·(ΔK·N·v + ΔU0)`. So `A = N + D`, `c = A·U0 − b` with D the
    ///   terms in v and b the others (see the module's note on the sign).
    ///
    /// A pure function of `temp_c`, so a caller may keep it while the temperature reading does
    /// not change ([`TempCache`]) without changing any result.
    #[inline]
    pub fn at_temperature(&self, temp_c: F) -> AtTemperature<F> {
        let (t, status) = self.clamped(temp_c);
        // The map at T0 (no correction), and the method's temperature terms added to it.
        let mut at = AtTemperature { status, lin: self.lin0, neg_offset_g: self.neg_offset0_g };
        if self.method == Method::Uncorrected {
            return at;
        }
        // Method 1 and the linearised form: ΔU0 and X = N·ΔK from their own model.
        let uses_x = matches!(self.method, Method::CoefficientCorrection | Method::OutputCorrection(Form::Linearized));
        let d = if uses_x { &self.model_x } else { &self.model }.delta(t, self.t0_c);
        let n = &self.n_g_per_v;
        let k = &self.constants.k_v_per_g;
        match self.method {
            Method::Uncorrected => {}
            Method::CoefficientCorrection => {
                let u0 = linalg::vec_add(&self.constants.u0_v, &d.du0_v);
                let x = &d.rel_k;
                match identity_minus_inverse(x, F::from_f64(linalg::MIN_HADAMARD_RATIO)) {
                    Some(m) => at.lin = linalg::mat_mul_sub(&m, n, &at.lin),
                    None => at.status.insert(Status::SINGULAR_AT_TEMP),
                }
                at.neg_offset_g = neg_offset(n, &at.lin, &u0, &[F::ZERO; 3]);
            }
            Method::OutputCorrection(Form::Linearized) => {
                // A = N + D with D = −X·N, X = N·ΔK; −c = −c₀ + b − D·U0 with b = −N·ΔU0 and
                // D·U0 = X·c₀.
                let x = &d.rel_k;
                let nd = linalg::mat_vec_fused(n, &d.du0_v);
                at.lin = linalg::mat_sub(&at.lin, &linalg::mat_mul_fused(x, n));
                let xc = linalg::mat_vec_fused(x, &self.neg_offset0_g);
                for i in 0..3 {
                    at.neg_offset_g[i] -= nd[i] + xc[i];
                }
            }
            Method::OutputCorrection(form) => {
                // A = N + D, −c = −c₀ + b − D·U0: per axis i, D_ii = −β_ii/K_ii and
                // b_i = −α_i/K_ii, and in the full form D_ij = −γ_ij·K_ij/(K_ii·K_jj),
                // b_i += α_j·K_ij/(K_ii·K_jj) (j ≠ i).
                let r = &self.inv_diag;
                let u0 = &self.constants.u0_v;
                for i in 0..3 {
                    let dii = -(d.rel_k[i][i] * r[i]);
                    at.lin[i][i] += dii;
                    let mut neg = (-dii).mul_add(u0[i], at.neg_offset_g[i] - d.du0_v[i] * r[i]);
                    if form == Form::Full {
                        for j in 0..3 {
                            if j != i {
                                let q = k[i][j] * r[i] * r[j];
                                let dij = -(q * d.rel_k[i][j]);
                                at.lin[i][j] += dij;
                                neg = q.mul_add(d.du0_v[j], (-dij).mul_add(u0[j], neg));
                            }
                        }
                    }
                    at.neg_offset_g[i] = neg;
                }
            }
        }
        at
    }

    /// The signal-dependent half of the step: signals `u_v` \[V\] to specific force \[g\] with
    /// the affine map `at` of [`at_temperature`](Self::at_temperature) (T(1) with method 1 or
    /// 2 of §5). A non-finite result takes the module's policies: its non-finite signals
    /// replaced and the map applied again, or, when every signal is finite (an overflow),
    /// zero, flagged.
    #[inline]
    #[allow(clippy::eq_op, reason = "`x − x` is 0 for a finite x and NaN otherwise: the finiteness test")]
    pub fn apply(&self, u_v: Vec3<F>, at: &AtTemperature<F>) -> Sample<F> {
        let mut u = u_v;
        let mut status = at.status;
        // A second pass only after a non-finite signal was replaced (the module's policies).
        for _ in 0..2 {
            let a = self.affine(&u, at);
            // One test for the three: the sum is finite when each is (or it overflowed, and
            // the test of each number says so).
            let sum = a[0] + a[1] + a[2];
            if sum - sum == F::ZERO || all_finite(&a) {
                return Sample { accel_g: a, status };
            }
            let mut replaced = u;
            if !self.replace_nonfinite(&mut replaced) {
                // Every signal finite: the result overflowed.
                break;
            }
            u = replaced;
            status.insert(Status::NONFINITE_INPUT);
        }
        status.insert(Status::NONFINITE_INPUT);
        Sample { accel_g: [F::ZERO; 3], status }
    }

    /// Replaces each non-finite signal by its zero offset at T0; false when every signal was
    /// finite. Out of line: only a sample with a non-finite result comes here.
    #[cold]
    #[inline(never)]
    fn replace_nonfinite(&self, u: &mut Vec3<F>) -> bool {
        let mut any = false;
        for (x, u0) in u.iter_mut().zip(self.constants.u0_v) {
            if !x.is_finite() {
                *x = u0;
                any = true;
            }
        }
        any
    }
}

/// True when the three numbers are finite: `x − x` is 0 for a finite x and NaN otherwise.
#[inline(always)]
#[allow(clippy::eq_op, reason = "`x − x` is the test")]
fn all_finite<F: Float>(a: &Vec3<F>) -> bool {
    (a[0] - a[0]) + (a[1] - a[1]) + (a[2] - a[2]) == F::ZERO
}

/// `b − A·U0'` for the map whose linear part is `lin` plus N's diagonal hi part (`n`'s
/// diagonal): the small terms first, the hi part last.
#[inline(always)]
fn neg_offset<F: Float>(n: &Mat3<F>, lin: &Mat3<F>, u0: &Vec3<F>, b: &Vec3<F>) -> Vec3<F> {
    let row = |i: usize, j: usize, k: usize| {
        let small = (-lin[i][k]).mul_add(u0[k], (-lin[i][j]).mul_add(u0[j], (-lin[i][i]).mul_add(u0[i], b[i])));
        (-n[i][i]).mul_add(u0[i], small)
    };
    [row(0, 1, 2), row(1, 2, 0), row(2, 0, 1)]
}

/// `I − (I + X)⁻¹` for a small X (method 1's correction, `K(T)⁻¹ = (I − M)·N`), from the
/// cofactors C of `Y = I + X`: `M = (det Y·I − adj Y)/det Y` with `det Y − C_ii = Σ_j X_ij·C_ij`
/// (the expansion of det Y along row i less C_ii): every numerator a sum of products of small
/// numbers, so M keeps `f32`'s relative precision although Y's elements are near 1 or 0.
/// `None` when Y fails [`linalg::inverse_checked`]'s test (not finite, or its Hadamard ratio
/// below `min_ratio`).
#[inline(always)]
fn identity_minus_inverse<F: Float>(x: &Mat3<F>, min_ratio: F) -> Option<Mat3<F>> {
    let one = |i: usize| F::ONE + x[i][i];
    let (y00, y11, y22) = (one(0), one(1), one(2));
    // Cofactors C_ij of Y.
    let c00 = y11.mul_add(y22, -(x[1][2] * x[2][1]));
    let c01 = x[1][2].mul_add(x[2][0], -(x[1][0] * y22));
    let c02 = x[1][0].mul_add(x[2][1], -(y11 * x[2][0]));
    let c10 = x[0][2].mul_add(x[2][1], -(x[0][1] * y22));
    let c11 = y00.mul_add(y22, -(x[0][2] * x[2][0]));
    let c12 = x[0][1].mul_add(x[2][0], -(y00 * x[2][1]));
    let c20 = x[0][1].mul_add(x[1][2], -(x[0][2] * y11));
    let c21 = x[0][2].mul_add(x[1][0], -(y00 * x[1][2]));
    let c22 = y00.mul_add(y11, -(x[0][1] * x[1][0]));
    // det Y − C_ii, row by row.
    let n0 = x[0][2].mul_add(c02, x[0][1].mul_add(c01, x[0][0] * c00));
    let n1 = x[1][2].mul_add(c12, x[1][1].mul_add(c11, x[1][0] * c10));
    let n2 = x[2][2].mul_add(c22, x[2][1].mul_add(c21, x[2][0] * c20));
    let det = c00 + n0;
    let norm2 = |a: F, b: F, c: F| c.mul_add(c, b.mul_add(b, a * a));
    let p =
        norm2(y00, x[0][1], x[0][2]).sqrt() * norm2(x[1][0], y11, x[1][2]).sqrt() * norm2(x[2][0], x[2][1], y22).sqrt();
    // `!(x >= y)` is also true for NaN, so a non-finite X is rejected here too.
    if !(det.abs() >= min_ratio * p) || !(p > F::ZERO) || !det.is_finite() || !p.is_finite() {
        return None;
    }
    let r = F::ONE / det;
    Some([[n0 * r, -(c10 * r), -(c20 * r)], [-(c01 * r), n1 * r, -(c21 * r)], [-(c02 * r), -(c12 * r), n2 * r]])
}

/// ΔK(T) = K ∘ (ΔK/K): the elementwise product of the constants at T0 and the relative
/// changes of T(3)/T(4).
#[inline(always)]
fn delta_k<F: Float>(k: &Mat3<F>, d: &CoefDelta<F>) -> Mat3<F> {
    let mut dk = [[F::ZERO; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            dk[i][j] = k[i][j] * d.rel_k[i][j];
        }
    }
    dk
}

/// The temperature-dependent half of the per-sample step ([`Calibration::at_temperature`]):
/// the temperature's status flags and the affine map `a = A·U − c` of the method at that
/// temperature.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AtTemperature<F> {
    status: Status,
    /// A without the hi part of N's diagonal (off the diagonal: A_ij; on it: A_ii − hi_i, the
    /// low part of N_ii plus the method's change) \[g/V\].
    lin: Mat3<F>,
    /// −c \[g\] (negated: the per-sample sum starts from it).
    neg_offset_g: Vec3<F>,
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
    /// The reading the terms were computed for (NaN: nothing cached yet; a NaN reading never
    /// equals it, so it is never reused).
    key_c: F,
    /// The fingerprint of the calibration they were computed with.
    key_fingerprint: u64,
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
        TempCache {
            key_c: F::NAN,
            key_fingerprint: 0,
            at: AtTemperature { status: Status::OK, lin: [[F::ZERO; 3]; 3], neg_offset_g: [F::ZERO; 3] },
        }
    }

    /// The terms of `cal` at `temp_c`, recomputed only when `temp_c` differs from the last
    /// reading or `cal` from the last calibration (by fingerprint); a NaN reading is never
    /// reused.
    #[inline]
    pub fn get(&mut self, cal: &Calibration<F>, temp_c: F) -> &AtTemperature<F> {
        if !(temp_c == self.key_c) || self.key_fingerprint != cal.fingerprint {
            self.refresh(cal, temp_c);
        }
        &self.at
    }

    /// The terms recomputed: once per temperature reading, so out of line (the per-sample
    /// path keeps its registers).
    #[inline(never)]
    fn refresh(&mut self, cal: &Calibration<F>, temp_c: F) {
        self.at = cal.at_temperature(temp_c);
        self.key_c = temp_c;
        self.key_fingerprint = cal.fingerprint;
    }

    /// Forgets the cached terms.
    pub fn invalidate(&mut self) {
        self.key_c = F::NAN;
    }
}
