//! The per-sample step: raw signals and the unit's temperature in, compensated acceleration
//! and a status word out. Owns the two compensation methods of §5 and the status policy.
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

use crate::float::Float;
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
    /// T(5) (polynomial) / T(6) (piecewise-linear): all four terms of the bracket.
    Full,
    /// T(7) / T(8): scale-factor and offset terms only, cross-sensitivity terms dropped.
    Simplified,
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
    /// Specific force along the unit's x, y, z axes [g].
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
    /// K(T) becomes singular somewhere inside the valid range.
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
            CalibrationError::SingularInRange => write!(f, "K(T) becomes singular inside the valid temperature range"),
        }
    }
}

impl core::error::Error for CalibrationError {}

/// Number of temperatures, besides the knots and the range ends, at which a loaded
/// calibration's K(T) is checked for invertibility.
const RANGE_CHECK_POINTS: usize = 64;

/// A validated calibration: everything the per-sample step needs, immutable after boot.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Calibration<F> {
    t0_c: F,
    constants: Constants<F>,
    /// N = K⁻¹ at T0.
    n_g_per_v: Mat3<F>,
    /// 1/K_ii at T0.
    inv_diag: Vec3<F>,
    model: TempModel<F>,
    method: Method,
    temp_min_c: F,
    temp_max_c: F,
    valid: bool,
}

impl<F: Float> Calibration<F> {
    /// Validates and precomputes. Fails on non-finite or singular constants, a malformed
    /// temperature model, a bad range, or a K(T) that becomes singular inside the range.
    pub fn new(
        constants: Constants<F>,
        t0_c: F,
        model: TempModel<F>,
        method: Method,
        temp_range_c: (F, F),
    ) -> Result<Self, CalibrationError> {
        if !constants.is_finite() {
            return Err(CalibrationError::NonFiniteConstants);
        }
        let n = constants.inverse().ok_or(CalibrationError::SingularK)?;
        let k = &constants.k_v_per_g;
        if k[0][0] == F::ZERO || k[1][1] == F::ZERO || k[2][2] == F::ZERO {
            return Err(CalibrationError::ZeroScaleFactor);
        }
        model.check().map_err(CalibrationError::TempModel)?;
        let (lo, hi) = temp_range_c;
        if !(lo.is_finite() && hi.is_finite() && lo < hi && lo <= t0_c && t0_c <= hi) {
            return Err(CalibrationError::BadRange);
        }
        let cal = Calibration {
            t0_c,
            constants,
            n_g_per_v: n,
            inv_diag: [F::ONE / k[0][0], F::ONE / k[1][1], F::ONE / k[2][2]],
            model,
            method,
            temp_min_c: lo,
            temp_max_c: hi,
            valid: true,
        };
        // K(T) must stay invertible over the whole range: check the ends, the knots and a
        // grid, so the run-time fallback is never expected to trigger.
        let check = |t: F| -> Result<(), CalibrationError> {
            let kt = cal.constants_at(t);
            if kt.inverse().is_none() { Err(CalibrationError::SingularInRange) } else { Ok(()) }
        };
        for i in 0..=RANGE_CHECK_POINTS {
            check(lo + (hi - lo) * F::of(i as f64 / RANGE_CHECK_POINTS as f64))?;
        }
        if let TempModel::Pwl { n_knots, knots_c, .. } = &model {
            for &kn in knots_c.iter().take(*n_knots as usize) {
                if kn > lo && kn < hi {
                    check(kn)?;
                }
            }
        }
        Ok(cal)
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
            inv_diag: [F::ONE; 3],
            model: TempModel::Poly { order: 1, coef: [CoefDelta::zero(); 4] },
            method: Method::Uncorrected,
            temp_min_c: F::of(-1.0e30),
            temp_max_c: F::of(1.0e30),
            valid: false,
        }
    }

    /// The same calibration compensating with another method.
    pub fn with_method(mut self, method: Method) -> Self {
        self.method = method;
        self
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
        let d = self.model.delta(temp_c, self.t0_c);
        let mut c = self.constants;
        for i in 0..3 {
            c.u0_v[i] += d.du0_v[i];
            for j in 0..3 {
                c.k_v_per_g[i][j] = c.k_v_per_g[i][j] * (F::ONE + d.rel_k[i][j]);
            }
        }
        c
    }

    /// The output correction Δa_T of T(5)/T(6) (full) or T(7)/T(8) (simplified) for signals
    /// `u_v` and coefficient changes `d`: the amount to **add** to `N·(U − U0)` (see the
    /// module's note on the sign). With `v = U − U0`, per axis i:
    ///
    /// `Δa_i = −v_i/K_ii·β_ii − α_i/K_ii` (simplified), plus in the full form
    /// `− Σ_{j≠i} v_j·K_ij·γ_ij/(K_ii·K_jj) + Σ_{j≠i} K_ij·α_j/(K_ii·K_jj)`.
    #[inline(always)]
    pub fn output_correction(&self, v: &Vec3<F>, d: &CoefDelta<F>, form: Form) -> Vec3<F> {
        let k = &self.constants.k_v_per_g;
        let r = &self.inv_diag;
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

    /// The per-sample step: signals `u_v` [V] and the unit's temperature `temp_c` [°C] to
    /// specific force [g] and status. Allocation-free, panic-free, bounded time; the output is
    /// always finite (see the module's policies).
    #[inline]
    pub fn compensate(&self, u_v: Vec3<F>, temp_c: F) -> Sample<F> {
        let mut status = Status::OK;
        if !self.valid {
            status.insert(Status::INVALID_CALIBRATION);
        }
        let mut u = u_v;
        for i in 0..3 {
            if !u[i].is_finite() {
                u[i] = self.constants.u0_v[i];
                status.insert(Status::NONFINITE_INPUT);
            }
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

        let mut a = match self.method {
            Method::Uncorrected => {
                linalg::mat_vec(&self.n_g_per_v, &linalg::vec_sub(&u, &self.constants.u0_v))
            }
            Method::CoefficientCorrection => {
                let c = self.constants_at(t);
                let v = linalg::vec_sub(&u, &c.u0_v);
                match c.inverse() {
                    Some(n_t) => linalg::mat_vec(&n_t, &v),
                    None => {
                        status.insert(Status::SINGULAR_AT_TEMP);
                        linalg::mat_vec(&self.n_g_per_v, &v)
                    }
                }
            }
            Method::OutputCorrection(form) => {
                let v = linalg::vec_sub(&u, &self.constants.u0_v);
                let a0 = linalg::mat_vec(&self.n_g_per_v, &v);
                let d = self.model.delta(t, self.t0_c);
                let c = self.output_correction(&v, &d, form);
                [a0[0] + c[0], a0[1] + c[1], a0[2] + c[2]]
            }
        };
        if !(a[0].is_finite() && a[1].is_finite() && a[2].is_finite()) {
            a = [F::ZERO; 3];
            status.insert(Status::NONFINITE_INPUT);
        }
        Sample { accel_g: a, status }
    }

    /// Converts between float types (the constants are rounded, not re-validated; use on a
    /// calibration already validated in the wider type, then validate with
    /// [`Calibration::new`] if the narrow type could fail).
    pub fn cast<G: Float>(&self) -> Result<Calibration<G>, CalibrationError> {
        if !self.valid {
            return Ok(Calibration::uncalibrated());
        }
        Calibration::new(
            self.constants.cast(),
            G::of(self.t0_c.to_f64()),
            self.model.cast(),
            self.method,
            (G::of(self.temp_min_c.to_f64()), G::of(self.temp_max_c.to_f64())),
        )
    }
}
