//! Thermal dynamics between the thermistor and the sensing elements: the temperature the
//! constants follow is not the thermistor's reading.
//!
//! The temperature paper's models T(3)/T(4) take the unit's temperature as one number that
//! the constants follow at once. A real unit's thermistor sits beside the accelerometers, not
//! in them: the die lags the reading during a ramp, it may reach a different temperature when
//! heated than when cooled to the same reading, the electronics warm it after power-on, and
//! the bias itself may keep a memory of the direction of the last change. These stages go
//! beyond the papers; they model what `bins-cal diagnose` names (`thermal_lag`,
//! `thermal_hysteresis`, `self_heating`, `bias_hysteresis`) so that a calibration carrying
//! them compensates in flight what the diagnosis found (`docs/compensation.md`, "Thermal
//! dynamics").
//!
//! Per sample, with the thermistor reading `T_th` and the sample period `Δt`:
//!
//! - lag: `x ← x + (T_th − x)·(1 − e^(−Δt/τ))`, the exact discretisation of
//!   `τ·dx/dt = T_th − x` for a reading held over the period;
//! - hysteresis: the play (backlash) operator of width `h` on the lagged temperature,
//!   `e ← clamp(e, x − h/2, x + h/2)`;
//! - self-heating: `s = ΔT_sh·(1 − e^(−t_on/τ_sh))`, `t_on` the time since power-on;
//! - effective temperature: `T_eff = e + s`, what the temperature model T(3)/T(4) is
//!   evaluated at;
//! - bias hysteresis: a play of width `h_b` on `T_eff`, `p ← clamp(p, T_eff − h_b/2,
//!   T_eff + h_b/2)`, and the fraction `d = (p − T_eff)/(h_b/2) ∈ [−1, 1]` (−1 after heating,
//!   +1 after cooling, by at least `h_b`); the bias `b_i = bias_play_g[i]·d` \[g\] is
//!   subtracted from the compensated output.
//!
//! The first finite reading sets the lag and both plays to itself: no transient at power-on.
//! Every stage is off when its parameter is 0 ([`ThermalDynamics::none`]).
//!
//! Two ways to run it: [`ThermalDynamics::step`] with any period and the time since
//! power-on (host tools; the gains and the self-heating term are computed in the call), and
//! [`FixedRate`] ([`ThermalDynamics::at_rate`]), the same stages run once every
//! N = [`UPDATE_EVERY`] samples with the gains of N periods precomputed, their output held in
//! between: the lag by `x ← x + (T_th − x)·(1 − e^(−N·Δt/τ))`, N per-sample steps exactly for
//! a reading held over them (a TMP117 gives a new reading every 16 samples at 1 kHz), and the
//! self-heating term by `s ← s + (ΔT_sh − s)·(1 − e^(−N·Δt/τ_sh))`, which after k updates is
//! `ΔT_sh·(1 − e^(−k·N·Δt/τ_sh))` (the closed form at `t_on = k·N·Δt`, time counted from the
//! first finite reading): within `|ΔT_sh|·(N − 1)·Δt/τ_sh` of the closed form at the sample's
//! own time (7.5·10⁻⁵ °C for 1.5 °C, τ_sh = 300 s at 1 kHz), with no exponential and, on 15
//! samples of 16, no arithmetic. The sampling interrupt uses [`FixedRate`];
//! [`FixedRate::every_sample`] runs the stages on every sample (the tests' reference), and
//! [`FixedRate::step`] bounds the difference.
//!
//! Precision: the lagged temperature is kept as a double-word (hi + lo, Fast2Sum). Its
//! increment per update is small (2.7·10⁻⁴ of the gap at N·Δt = 16 ms, τ = 60 s; 1.7·10⁻⁵
//! per sample) beside the `f32` spacing of the temperature (3.8·10⁻⁶ °C at 50 °C), so a plain
//! `f32` sum would lose part of each increment. The self-heating term is a double-word too
//! (the high part is used).
//!
//! A reading that is not a temperature (NaN, ±∞, or beyond ±[`MAX_READING_C`]): the state is
//! not touched (the next good reading continues from it), and the reading is passed through
//! as the effective temperature, so the calibration's policy applies (a non-finite one is
//! compensated at T0 and flagged `NONFINITE_INPUT | TEMP_CLAMPED`, a huge one clamped to the
//! calibrated range and flagged `TEMP_CLAMPED`, see [`compensate`](crate::compensate)); no bias
//! play is subtracted. So the state is always finite.

use crate::float::{self, Float};
use crate::linalg::Vec3;

/// Largest magnitude of a reading that enters the state [°C]; a larger one is passed through
/// without touching the state, as a non-finite one is (the calibration clamps it to its
/// range).
pub const MAX_READING_C: f64 = 1000.0;
/// Largest time constant (lag, self-heating) accepted \[s\].
pub const MAX_TAU_S: f64 = 1.0e5;
/// Largest width of a play (hysteresis, bias hysteresis) and largest |ΔT_sh| accepted [°C].
pub const MAX_WIDTH_C: f64 = 50.0;
/// Largest |bias_play_g| accepted per axis \[g\] (100 mg).
pub const MAX_BIAS_PLAY_G: f64 = 0.1;

/// The range of parameter `n` in the order of [`ThermalDynamics::to_array`], in its units
/// (s, °C, g): time constants within [0, [`MAX_TAU_S`]], play widths within [0,
/// [`MAX_WIDTH_C`]], ΔT_sh within ±[`MAX_WIDTH_C`], the bias play's gains within
/// ±[`MAX_BIAS_PLAY_G`].
pub const fn limits(n: u8) -> (f64, f64) {
    match n {
        0 | 3 => (0.0, MAX_TAU_S),
        1 | 4 => (0.0, MAX_WIDTH_C),
        2 => (-MAX_WIDTH_C, MAX_WIDTH_C),
        _ => (-MAX_BIAS_PLAY_G, MAX_BIAS_PLAY_G),
    }
}

/// Parameters of the thermal dynamics; every stage optional (0 = off).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ThermalDynamics<F> {
    /// τ of the first-order lag of the die behind the thermistor reading \[s\] (0: no lag).
    pub lag_tau_s: F,
    /// Width h of the play operator on the lagged temperature [°C] (0: no hysteresis).
    pub hysteresis_width_c: F,
    /// ΔT_sh: how much warmer the die settles than the thermistor after power-on [°C] (may be
    /// negative; 0: no self-heating).
    pub self_heating_c: F,
    /// τ_sh of the self-heating \[s\] (0 with ΔT_sh ≠ 0: a constant offset from power-on).
    pub self_heating_tau_s: F,
    /// Width h_b of the bias play on the effective temperature [°C] (0: no bias hysteresis).
    pub bias_play_width_c: F,
    /// Bias per unit of the play fraction d, per axis \[g\]: `b_i = bias_play_g[i]·d` is
    /// subtracted from the output. Must be zero when `bias_play_width_c` is.
    pub bias_play_g: Vec3<F>,
}

/// Why a set of thermal-dynamics parameters was rejected. Each names the parameter.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DynamicsError {
    /// `lag_tau_s` not finite or outside [0, [`MAX_TAU_S`]].
    LagTau,
    /// `hysteresis_width_c` not finite or outside [0, [`MAX_WIDTH_C`]].
    HysteresisWidth,
    /// `self_heating_c` not finite or beyond ±[`MAX_WIDTH_C`].
    SelfHeating,
    /// `self_heating_tau_s` not finite or outside [0, [`MAX_TAU_S`]].
    SelfHeatingTau,
    /// `bias_play_width_c` not finite or outside [0, [`MAX_WIDTH_C`]].
    BiasPlayWidth,
    /// `bias_play_g[axis]` not finite or beyond ±[`MAX_BIAS_PLAY_G`].
    BiasPlayG(u8),
    /// `bias_play_g` nonzero with `bias_play_width_c` = 0 (the fraction d is undefined).
    BiasPlayWithoutWidth,
    /// The sample period is not finite and positive.
    SamplePeriod,
}

impl core::fmt::Display for DynamicsError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let s = match self {
            DynamicsError::LagTau => "lag_tau_s: not finite or outside [0, 1e5] s",
            DynamicsError::HysteresisWidth => "hysteresis_width_C: not finite or outside [0, 50] °C",
            DynamicsError::SelfHeating => "self_heating_C: not finite or beyond ±50 °C",
            DynamicsError::SelfHeatingTau => "self_heating_tau_s: not finite or outside [0, 1e5] s",
            DynamicsError::BiasPlayWidth => "bias_play_width_C: not finite or outside [0, 50] °C",
            DynamicsError::BiasPlayG(0) => "bias_play_mg[0] (x): not finite or beyond ±100 mg",
            DynamicsError::BiasPlayG(1) => "bias_play_mg[1] (y): not finite or beyond ±100 mg",
            DynamicsError::BiasPlayG(_) => "bias_play_mg[2] (z): not finite or beyond ±100 mg",
            DynamicsError::BiasPlayWithoutWidth => "bias_play_mg: nonzero with bias_play_width_C = 0",
            DynamicsError::SamplePeriod => "sample period: not finite and positive",
        };
        f.write_str(s)
    }
}

impl core::error::Error for DynamicsError {}

/// The running state of the thermal dynamics. Starts uninitialised: the first finite reading
/// sets it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DynamicsState<F> {
    /// The lagged temperature, high and low part (hi + lo) [°C].
    lag: (F, F),
    /// The hysteresis play's output [°C].
    play: F,
    /// The bias play's output [°C].
    bias_play: F,
    /// The self-heating term of [`FixedRate`], high and low part [°C] (advanced every N steps
    /// from power-on).
    heating: (F, F),
    /// Steps of [`FixedRate`] until its next update.
    countdown: u32,
    /// [`FixedRate`]'s output at its last update, held until the next.
    held: Effective<F>,
    /// A finite reading has set the lag and the plays.
    initialised: bool,
}

impl<F: Float> DynamicsState<F> {
    /// The state at power-on.
    pub const fn new() -> Self {
        DynamicsState {
            lag: (F::ZERO, F::ZERO),
            play: F::ZERO,
            bias_play: F::ZERO,
            heating: (F::ZERO, F::ZERO),
            countdown: 0,
            held: Effective { temp_eff_c: F::ZERO, bias_play: F::ZERO },
            initialised: false,
        }
    }

    /// The lagged temperature x [°C] (0 before the first finite reading).
    pub fn lagged_c(&self) -> F {
        self.lag.0 + self.lag.1
    }

    /// The outputs of the hysteresis play and of the bias play [°C] (0 before the first finite
    /// reading).
    pub fn play_outputs_c(&self) -> (F, F) {
        (self.play, self.bias_play)
    }

    /// True once a finite reading has set the state.
    pub fn is_initialised(&self) -> bool {
        self.initialised
    }
}

/// The output of one step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Effective<F> {
    /// The effective temperature T_eff [°C] at which the temperature model is evaluated
    /// (the reading itself, non-finite, when the reading is).
    pub temp_eff_c: F,
    /// The bias play's fraction d ∈ [−1, 1] (0 without bias hysteresis or for a non-finite
    /// reading).
    pub bias_play: F,
}

/// `1 − e^(−x)` for `x ≥ 0` without an exponential: x is halved k times to below 0.01, where
/// a Taylor series is exact to the rounding (its first omitted term is x⁷/5040, below
/// 2·10⁻¹⁶ relative), and the result is squared back, `1 − e^(−2y) = g·(2 − g)` with
/// `g = 1 − e^(−y)`, which does not cancel and does not amplify relative errors. No `exp` is
/// linked for it (the target computes its gains once, at boot). 1 from x = 40 on (e⁻⁴⁰ is
/// below half an `f64` ulp of 1), so at most 12 halvings; 0 for x ≤ 0 or NaN.
#[inline(never)]
#[cfg_attr(unstable_target, optimize(size))]
pub fn one_minus_exp_neg<F: Float>(x: F) -> F {
    if !(x > F::ZERO) {
        return F::ZERO;
    }
    if x >= F::from_f64(40.0) {
        return F::ONE;
    }
    let (mut y, mut k) = (x, 0u32);
    while y >= F::from_f64(0.01) && k < 16 {
        y *= F::from_f64(0.5);
        k += 1;
    }
    // y·(1 − y/2·(1 − y/3·(1 − y/4·(1 − y/5·(1 − y/6)))))
    // Written out: a loop over the divisors would convert each from `f64` at run time (a
    // soft-float call on the target); as literals they are FPU immediates.
    let mut acc = F::ONE - y / F::from_f64(6.0);
    acc = F::ONE - y / F::from_f64(5.0) * acc;
    acc = F::ONE - y / F::from_f64(4.0) * acc;
    acc = F::ONE - y / F::from_f64(3.0) * acc;
    acc = F::ONE - y / F::from_f64(2.0) * acc;
    let mut g = y * acc;
    for _ in 0..k {
        g = g * (F::from_f64(2.0) - g);
    }
    if g > F::ONE { F::ONE } else { g }
}

/// The gain `1 − e^(−Δt/τ)` of an exactly discretised first-order lag (1 for τ = 0).
#[inline]
fn lag_gain<F: Float>(dt_s: F, tau_s: F) -> F {
    if tau_s > F::ZERO { one_minus_exp_neg(dt_s / tau_s) } else { F::ONE }
}

/// `x` clamped to `[lo, hi]` (`lo ≤ hi`), by comparisons (no library call).
#[inline(always)]
fn clamp<F: Float>(x: F, lo: F, hi: F) -> F {
    if x < lo {
        lo
    } else if x > hi {
        hi
    } else {
        x
    }
}

impl<F: Float> ThermalDynamics<F> {
    /// Every stage off.
    pub const fn none() -> Self {
        ThermalDynamics {
            lag_tau_s: F::ZERO,
            hysteresis_width_c: F::ZERO,
            self_heating_c: F::ZERO,
            self_heating_tau_s: F::ZERO,
            bias_play_width_c: F::ZERO,
            bias_play_g: [F::ZERO; 3],
        }
    }

    /// True when every stage is off: the effective temperature is the reading and no bias is
    /// subtracted.
    pub fn is_none(&self) -> bool {
        // One comparison: a sum of magnitudes is 0 only when each is (and NaN when one is).
        let [bx, by, bz] = self.bias_play_g;
        (self.lag_tau_s.abs()
            + self.hysteresis_width_c.abs()
            + self.self_heating_c.abs()
            + self.bias_play_width_c.abs()
            + bx.abs()
            + by.abs()
            + bz.abs())
            == F::ZERO
    }

    /// Checks every parameter: finite, within its physical limit ([`limits`]), and the bias
    /// play's gains zero without a play width. The error names the parameter.
    #[inline(never)]
    #[cfg_attr(unstable_target, optimize(size))]
    pub fn validate(&self) -> Result<(), DynamicsError> {
        for (n, &x) in self.to_array().iter().enumerate() {
            let (lo, hi) = limits(n as u8);
            if !(x.is_finite() && x >= F::from_f64(lo) && x <= F::from_f64(hi)) {
                return Err(match n {
                    0 => DynamicsError::LagTau,
                    1 => DynamicsError::HysteresisWidth,
                    2 => DynamicsError::SelfHeating,
                    3 => DynamicsError::SelfHeatingTau,
                    4 => DynamicsError::BiasPlayWidth,
                    _ => DynamicsError::BiasPlayG(n as u8 - 5),
                });
            }
        }
        if self.bias_play_width_c == F::ZERO && self.bias_play_g.iter().any(|&b| b != F::ZERO) {
            return Err(DynamicsError::BiasPlayWithoutWidth);
        }
        Ok(())
    }

    /// The parameters in the blob section's order: `lag_tau_s`, `hysteresis_width_c`,
    /// `self_heating_c`, `self_heating_tau_s`, `bias_play_width_c`, `bias_play_g` x, y, z.
    pub fn to_array(&self) -> [F; 8] {
        let [bx, by, bz] = self.bias_play_g;
        [
            self.lag_tau_s,
            self.hysteresis_width_c,
            self.self_heating_c,
            self.self_heating_tau_s,
            self.bias_play_width_c,
            bx,
            by,
            bz,
        ]
    }

    /// Inverse of [`to_array`](Self::to_array).
    pub fn from_array(a: &[F; 8]) -> Self {
        let [lag_tau_s, hysteresis_width_c, self_heating_c, self_heating_tau_s, bias_play_width_c, bx, by, bz] = *a;
        ThermalDynamics {
            lag_tau_s,
            hysteresis_width_c,
            self_heating_c,
            self_heating_tau_s,
            bias_play_width_c,
            bias_play_g: [bx, by, bz],
        }
    }

    /// Converts between float types.
    #[inline(never)]
    #[cfg_attr(unstable_target, optimize(size))]
    pub fn cast<G: Float>(&self) -> ThermalDynamics<G> {
        ThermalDynamics::from_array(&self.to_array().map(|x| G::from_f64(x.to_f64())))
    }

    /// The self-heating term `ΔT_sh·(1 − e^(−t_on/τ_sh))` at `t_on_s` seconds after power-on
    /// (ΔT_sh for τ_sh = 0, and from t_on > 40·τ_sh on, where the exponential is below 10⁻¹⁷).
    pub fn self_heating_at(&self, t_on_s: F) -> F {
        let (dt, tau) = (self.self_heating_c, self.self_heating_tau_s);
        if dt == F::ZERO {
            return F::ZERO;
        }
        if tau <= F::ZERO || t_on_s > F::from_f64(40.0) * tau {
            return dt;
        }
        dt * one_minus_exp_neg(t_on_s.max(F::ZERO) / tau)
    }

    /// One sample: thermistor reading `temp_c` [°C], sample period `dt_s` \[s\] (the time since
    /// the previous reading) and time since power-on `t_on_s` \[s\] to the effective
    /// temperature and the bias-play fraction (module docs). The gains are computed in the call
    /// ([`one_minus_exp_neg`], twice); at a fixed period [`FixedRate::step`] is the cheaper
    /// equivalent.
    /// A non-finite or negative `dt_s` is taken as 0 (the lag holds).
    pub fn step(&self, st: &mut DynamicsState<F>, temp_c: F, dt_s: F, t_on_s: F) -> Effective<F> {
        let dt = if dt_s.is_finite() && dt_s > F::ZERO { dt_s } else { F::ZERO };
        let t_on = if t_on_s.is_finite() { t_on_s } else { F::ZERO };
        let k = Constants {
            lag_gain: lag_gain(dt, self.lag_tau_s),
            half_width_c: self.hysteresis_width_c * F::from_f64(0.5),
            bias_half_width_c: self.bias_play_width_c * F::from_f64(0.5),
            inv_bias_half_width: inv_half(self.bias_play_width_c),
        };
        let heating = self.self_heating_at(t_on);
        k.advance(st, temp_c, heating, k.lag_gain < F::ONE)
    }

    /// The stages at one fixed sample period `dt_s` \[s\], their per-sample constants
    /// precomputed. Fails on invalid parameters ([`validate`](Self::validate)) or a period
    /// that is not finite and positive.
    #[inline(never)]
    #[cfg_attr(unstable_target, optimize(size))]
    pub fn at_rate(&self, dt_s: F) -> Result<FixedRate<F>, DynamicsError> {
        self.validate()?;
        self.at_rate_validated(dt_s)
    }

    /// [`at_rate`](Self::at_rate) for parameters that have passed
    /// [`validate`](Self::validate) (in any precision: rounding keeps a parameter within its
    /// rounded limits), e.g. the blob parser's. Checks the period only.
    #[inline(never)]
    #[cfg_attr(unstable_target, optimize(size))]
    pub fn at_rate_validated(&self, dt_s: F) -> Result<FixedRate<F>, DynamicsError> {
        if !(dt_s.is_finite() && dt_s > F::ZERO) {
            return Err(DynamicsError::SamplePeriod);
        }
        let n = F::from_f64(UPDATE_EVERY as f64) * dt_s;
        let lag = lag_gain(n, self.lag_tau_s);
        Ok(FixedRate {
            k: Constants {
                lag_gain: lag,
                half_width_c: self.hysteresis_width_c * F::from_f64(0.5),
                bias_half_width_c: self.bias_play_width_c * F::from_f64(0.5),
                inv_bias_half_width: inv_half(self.bias_play_width_c),
            },
            lag: (lag < F::ONE) as u32,
            heating_gain: lag_gain(n, self.self_heating_tau_s),
            every: UPDATE_EVERY,
            params: *self,
            dt_s,
        })
    }
}

/// How often [`FixedRate`] runs the stages \[samples\]: once every N = 16 samples, with the
/// gains of N periods, and the effective temperature and the bias-play fraction held in
/// between (the TMP117 at its fastest conversion cycle gives a new reading every 15.5 ms, 16
/// samples at 1 kHz). The held output is the per-sample stages' at the update's time for a
/// reading held over the N periods before it (see [`FixedRate::step`] for the bound).
pub const UPDATE_EVERY: u32 = 16;

/// `x ← x + (target − x)·gain` on a double-word `x` = (hi, lo): the low part is carried
/// into the increment and the sum's rounding error becomes the new low part, so an
/// increment far below the spacing of `hi` is not lost.
///
/// The error is Fast2Sum's (three operations, not TwoSum's six), exact when the increment
/// `b` is no larger than `hi` (or `hi` = 0). For the self-heating term (from 0 towards ΔT_sh)
/// that always holds: after k steps `s = ΔT_sh·(1 − rᵏ)` and the next increment is
/// `ΔT_sh·(1 − r)·rᵏ`, r = 1 − gain, and `rᵏ·(2 − r) ≤ r·(2 − r) ≤ 1`. For the lag it fails
/// only while |x| is below one increment, `gain·|target − x|` (crossing 0 °C): on at most two
/// samples per crossing the low part then loses at most one rounding of the increment, about
/// 2⁻²⁴·gain·|target − x| in `f32` (≈ 10⁻¹⁰ °C for a 100 °C gap at τ = 60 s, 1 kHz).
#[inline(always)]
fn follow<F: Float>(x: &mut (F, F), target: F, gain: F) {
    let (hi, lo) = *x;
    let step = (target - hi - lo) * gain;
    *x = float::fast_two_sum(hi, step + lo);
}

/// `2/h` (0 for h = 0).
fn inv_half<F: Float>(h: F) -> F {
    if h > F::ZERO { F::from_f64(2.0) / h } else { F::ZERO }
}

/// The per-sample constants of the lag and the two plays.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Constants<F> {
    /// `1 − e^(−Δt/τ)` (1: no lag).
    lag_gain: F,
    /// h/2 [°C].
    half_width_c: F,
    /// h_b/2 [°C].
    bias_half_width_c: F,
    /// 2/h_b (0: no bias play) [1/°C].
    inv_bias_half_width: F,
}

impl<F: Float> Constants<F> {
    /// The lag (when `lag`, i.e. its gain is below 1), the hysteresis play, the self-heating
    /// term `heating_c` added, the bias play.
    #[inline(always)]
    fn advance(&self, st: &mut DynamicsState<F>, temp_c: F, heating_c: F, lag: bool) -> Effective<F> {
        // Not a temperature (NaN, ±∞, beyond ±1000 °C): passed through, the state untouched.
        // One comparison, false for NaN too.
        if !(temp_c.abs() <= F::from_f64(MAX_READING_C)) {
            return Effective { temp_eff_c: temp_c, bias_play: F::ZERO };
        }
        let u = temp_c;
        let x = if !st.initialised {
            st.lag = (u, F::ZERO);
            st.play = u;
            st.bias_play = u + heating_c;
            st.initialised = true;
            u
        } else if lag {
            follow(&mut st.lag, u, self.lag_gain);
            st.lag.0 + st.lag.1
        } else {
            // Without the lag x is the reading (its low part stays 0 from the first reading).
            st.lag.0 = u;
            u
        };
        let h = self.half_width_c;
        st.play = clamp(st.play, x - h, x + h);
        let t_eff = st.play + heating_c;
        let hb = self.bias_half_width_c;
        st.bias_play = clamp(st.bias_play, t_eff - hb, t_eff + hb);
        Effective { temp_eff_c: t_eff, bias_play: (st.bias_play - t_eff) * self.inv_bias_half_width }
    }
}

/// [`ThermalDynamics`] at one fixed sample period: the gains of N = [`UPDATE_EVERY`] periods
/// precomputed, the stages run once every N samples and their output held in between (module
/// docs). Per sample a countdown and a comparison; no exponential.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FixedRate<F> {
    /// The lag's, the plays' and the bias play's constants, the lag's gain of N periods.
    k: Constants<F>,
    /// The lag is on (its gain below 1): 1, else 0 (a word: the `Option` around the stages
    /// keeps its own tag).
    lag: u32,
    /// `1 − e^(−N·Δt/τ_sh)` (1 for τ_sh = 0).
    heating_gain: F,
    /// N: the stages run every N samples ([`UPDATE_EVERY`]; 1 for the per-sample reference).
    every: u32,
    params: ThermalDynamics<F>,
    dt_s: F,
}

impl<F: Float> FixedRate<F> {
    /// The parameters.
    pub fn params(&self) -> &ThermalDynamics<F> {
        &self.params
    }

    /// The sample period \[s\].
    pub fn dt_s(&self) -> F {
        self.dt_s
    }

    /// The bias per unit of the play fraction \[g\].
    pub fn bias_play_g(&self) -> &Vec3<F> {
        &self.params.bias_play_g
    }

    /// N: the stages run every N samples and their output is held in between
    /// ([`UPDATE_EVERY`]).
    pub fn every(&self) -> u32 {
        self.every
    }

    /// The same stages run on every sample (N = 1, the gains of one period): the reference
    /// the held ones are tested against.
    pub fn every_sample(mut self) -> Self {
        self.every = 1;
        self.k.lag_gain = lag_gain(self.dt_s, self.params.lag_tau_s);
        self.lag = (self.k.lag_gain < F::ONE) as u32;
        self.heating_gain = lag_gain(self.dt_s, self.params.self_heating_tau_s);
        self
    }

    /// One sample (period `dt_s`): the thermistor reading [°C] to the effective temperature
    /// and the bias-play fraction.
    ///
    /// The stages run on the first finite reading and then every N samples
    /// ([`every`](Self::every)): the lag by its gain over N periods, `1 − e^(−N·Δt/τ)`, which
    /// is N per-sample steps exactly for a reading held over them; the plays on the lagged
    /// temperature and on `T_eff`; the self-heating term at the update's time `k·N·Δt`,
    /// advanced by N periods after it. The output is held until the next update. A reading
    /// that is not a temperature is passed through on its own sample (the calibration's policy
    /// applies) and leaves the state untouched; the countdown runs on, and an update that
    /// falls on such a reading waits for the next good one.
    ///
    /// Against the stages run on every sample ([`every_sample`](Self::every_sample)), the held
    /// `T_eff` at sample n (last update at m ≤ n, n − m < N) differs by at most
    /// `D_u + D_x + D_T + |ΔT_sh|·(N − 1)·Δt/τ_sh`: `D_u` the largest change of the reading
    /// over N − 1 samples (the update uses the reading at m for the N periods before it; the
    /// lag and the plays do not enlarge a difference of their input), `D_x` the per-sample
    /// lagged temperature's largest change over N − 1 samples (the play sees it at the
    /// updates only), `D_T` the per-sample `T_eff`'s (the hold). For the TMP117 read every 16
    /// samples, a 5 °C/min chamber ramp and τ = 60 s, all of it stays below 3 m°C (host tests,
    /// `dynamics.rs`). The per-sample cost is a countdown, a comparison and two loads; the
    /// update is out of line.
    #[inline]
    pub fn step(&self, st: &mut DynamicsState<F>, temp_c: F) -> Effective<F> {
        let u = temp_c;
        // Not a temperature (NaN, ±∞, beyond ±1000 °C): passed through, the state untouched.
        // One comparison, false for NaN too.
        let good = u.abs() <= F::from_f64(MAX_READING_C);
        if st.countdown != 0 {
            st.countdown -= 1;
            if good {
                return st.held;
            }
        } else if good {
            return self.update(st, u);
        }
        Effective { temp_eff_c: u, bias_play: F::ZERO }
    }

    /// The stages over the N periods up to a good reading `u` (the first one sets them), the
    /// self-heating term at this time, then advanced by N periods; the output held.
    #[inline(never)]
    fn update(&self, st: &mut DynamicsState<F>, u: F) -> Effective<F> {
        // The term at this update's time k·N·Δt (k updates since the first reading).
        let heating = st.heating.0;
        let e = self.k.advance(st, u, heating, self.lag != 0);
        // s ← s + (ΔT_sh − s)·g_N: after k updates ΔT_sh·(1 − (1 − g_N)ᵏ) = ΔT_sh·(1 − e^(−kNΔt/τ_sh)).
        follow(&mut st.heating, self.params.self_heating_c, self.heating_gain);
        st.held = e;
        st.countdown = self.every.saturating_sub(1);
        e
    }
}
