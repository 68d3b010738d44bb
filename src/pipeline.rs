//! The per-sample step with vibration-error subtraction: temperature compensation by
//! [`Calibration::compensate`], then the predicted VE of each accelerometer (§7) subtracted
//! from its axis. The configuration ([`Pipeline`]: calibration and VE model) is immutable;
//! the running state ([`PipelineState`]: the online moment window, the temperature terms of
//! the last reading) is separate and mutable.
//!
//! # Where the vibration comes from
//!
//! [`VibrationSource`] selects, per sample, what the VE is computed for:
//!
//! - `None`: nothing is subtracted.
//! - `Profile(i)`: flight-phase profile `i` of the configuration (Tables V2/V3-like), with the
//!   configuration's [`Variant`](crate::vibration::Variant). The compensated sample is a mean
//!   over the vibration, `y = a_p + VE(a_p)` per axis; `a_p` is solved for
//!   ([`solve_static_g`](crate::vibration::solve_static_g), at most four Newton steps)
//!   and `VE(a_p)` subtracted, so `y − VE = a_p`.
//! - `Online`: the moments of the last complete block of `W` compensated samples
//!   ([`MomentWindow`]), for a system that samples fast enough to see the vibration, referred
//!   back to the acceleration by the gain of each conversion function at the block mean
//!   ([`output_gains`](VibrationConfig::output_gains); the AL-15 at 6 g magnifies the
//!   vibration by 2.5 %, which would overstate the VE by 5 %); the exact moment form is used
//!   and `a_p` is solved from the block mean the same way. One block of `W` samples in
//!   [`ONLINE_BLOCK_EVERY`] = 4 enters the window: after a completed block the next `3W`
//!   samples are left out, so the window's sums and the VE cost a quarter of what every block
//!   would, and an estimate is refreshed every `4W` samples (256 ms with the firmware's 64
//!   samples at 1 kHz; at most `5W + 4` samples old, against `2W + 4` from every block;
//!   flight-phase vibration changes over seconds). Each estimate is one block's, as it was.
//!   The VE depends on the block alone, so it is computed once per estimated block, spread
//!   over four steps so that no step carries all of it (the moments on the step after the
//!   one that completes the block, which adds the last samples to the block's sums; one
//!   accelerometer's VE on each of the next three), and subtracted from every sample from
//!   then until the next estimate is ready. The window is fed only while `Online` is selected
//!   and emptied by any other source, so after switching to `Online` the first estimate comes
//!   four steps after the first complete block (flagged not ready until then).
//!
//! # Policies
//!
//! - No estimate (no complete block's VE yet, unknown profile): nothing subtracted, flagged
//!   [`Status::VIBRATION_ESTIMATE_NOT_READY`].
//! - Static acceleration beyond ±[`MAX_STATIC_G`](crate::vibration::MAX_STATIC_G) on an
//!   axis, or an online σ beyond [`MAX_LEVEL_G`]: clamped to the limit for the VE, flagged
//!   [`Status::VIBRATION_OUT_OF_RANGE`]. Profiles beyond the limit are rejected at load.
//! - Invalid calibration (output in volts) or a non-finite input: nothing subtracted and the
//!   sample is kept out of the window.
//!
//! # Thermal dynamics
//!
//! A pipeline built [`with_dynamics`](Pipeline::with_dynamics) runs the thermal dynamics
//! ([`dynamics`](crate::dynamics)) on each reading first: the temperature model is evaluated
//! at the effective temperature rounded to a multiple of [`TEMP_EFF_STEP_C`] (so that the
//! cached terms are reused while it moves less than the step; the host tests bound what the
//! rounding costs), and the bias play is subtracted from the compensated sample before the
//! window and the VE. Without dynamics the step is the one before they existed, bit for bit.
//!
//! Allocation-free, panic-free and bounded time: one compensation (its temperature terms
//! reused while the temperature reading does not change, [`TempCache`]), one window update
//! (O(1)), and per step at most three VE solutions of five evaluations each (a profile), or
//! one share of an online block's VE (its moments, or one accelerometer's solution).

use crate::compensate::{Calibration, Sample, Status, TempCache};
use crate::dynamics::{DynamicsState, FixedRate};
use crate::float::Float;
use crate::linalg::Vec3;
use crate::vibration::window::{MomentWindow, Pushed, WindowMoments};
use crate::vibration::{Axis, MAX_LEVEL_G, VibrationConfig};

/// What the VE of a sample is computed for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VibrationSource {
    /// No vibration compensation.
    None,
    /// The configuration's flight-phase profile with this index.
    Profile(u8),
    /// The online moment window.
    Online,
}

impl VibrationSource {
    /// The source named `name`: `none`, `online`, or `profile:N` with N a decimal profile index
    /// (0 to 255; whether the configuration has that profile is decided per sample, see
    /// [`Pipeline::step`]). `None` for anything else. A `const fn`, so that a firmware image can
    /// take its source from a build-time setting.
    pub const fn parse(name: &str) -> Option<Self> {
        let b = name.as_bytes();
        if eq(b, b"none") {
            return Some(VibrationSource::None);
        }
        if eq(b, b"online") {
            return Some(VibrationSource::Online);
        }
        let prefix = b"profile:";
        if b.len() <= prefix.len() || b.len() > prefix.len() + 3 {
            return None;
        }
        let (head, digits) = b.split_at(prefix.len());
        if !eq(head, prefix) {
            return None;
        }
        let mut n: u32 = 0;
        let mut i = 0;
        while i < digits.len() {
            let d = digits[i];
            if !d.is_ascii_digit() {
                return None;
            }
            n = n * 10 + (d - b'0') as u32;
            i += 1;
        }
        if n > u8::MAX as u32 {
            return None;
        }
        Some(VibrationSource::Profile(n as u8))
    }
}

/// `a == b`, in a `const fn`.
const fn eq(a: &[u8], b: &[u8]) -> bool {
    if a.len() != b.len() {
        return false;
    }
    let mut i = 0;
    while i < a.len() {
        if a[i] != b[i] {
            return false;
        }
        i += 1;
    }
    true
}

/// The step of the cache's key for an effective temperature [°C]: with thermal dynamics the
/// temperature terms are computed at the effective temperature rounded to a multiple of
/// 1/256 °C (±2 m°C, half the TMP117's resolution), so that the terms are reused while it
/// stays within one step (see [`Pipeline::with_dynamics`]).
pub const TEMP_EFF_STEP_C: f64 = 1.0 / 256.0;

/// The online VE is estimated from one block of `W` samples in this many: after a completed
/// block the next `(ONLINE_BLOCK_EVERY − 1)·W` samples are left out of the window (module
/// docs, "Where the vibration comes from").
pub const ONLINE_BLOCK_EVERY: usize = 4;

/// The configuration of the per-sample step: calibration, VE model and thermal dynamics.
/// Immutable after boot.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pipeline<F> {
    cal: Calibration<F>,
    vib: VibrationConfig<F>,
    /// The thermal dynamics at the sampling period (`None`: the temperature model is
    /// evaluated at the reading, as without dynamics).
    dynamics: Option<FixedRate<F>>,
    /// `1.5·2^p·step` (p the mantissa bits): `(T + c) − c` rounds T to a multiple of the
    /// step; 0 evaluates at the exact effective temperature.
    round_c: F,
}

/// The running state of the per-sample step: the online moment window over blocks of `W`
/// samples, the VE of the last block, and the temperature terms of the last reading.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PipelineState<F, const W: usize> {
    /// Moments of the compensated samples, by blocks of `W`.
    pub window: MomentWindow<F, W>,
    /// The online VE \[g\] of the last complete block (zero before the first block's VE is
    /// complete); always finite.
    online_ve_g: Vec3<F>,
    /// The flags of the online VE: [`Status::VIBRATION_ESTIMATE_NOT_READY`] before the first
    /// block's VE is complete, [`Status::VIBRATION_OUT_OF_RANGE`] when it was clamped.
    online_status: Status,
    /// The online VE's work on the block that completed last, one piece per step: 0 none
    /// left; 1 its moments; 2, 3, 4 the x, y, z accelerometer's VE.
    ve_work: u8,
    /// That block's VE in progress.
    next_ve: NextVe<F>,
    /// Samples the online source leaves out of the window before its next block (set to
    /// `(ONLINE_BLOCK_EVERY − 1)·W` by a completed block).
    skip: u32,
    /// The online source has fed the window or set a VE since the last reset.
    online_used: bool,
    /// Temperature terms of the last reading.
    temps: TempCache<F>,
    /// The thermal dynamics' state (untouched without dynamics).
    pub dynamics: DynamicsState<F>,
}

impl<F: Float, const W: usize> Default for PipelineState<F, W> {
    fn default() -> Self {
        Self::new()
    }
}

impl<F: Float, const W: usize> PipelineState<F, W> {
    /// The state at power-on: empty window, nothing cached.
    pub const fn new() -> Self {
        PipelineState {
            window: MomentWindow::new(),
            online_ve_g: [F::ZERO; 3],
            online_status: Status::VIBRATION_ESTIMATE_NOT_READY,
            ve_work: 0,
            next_ve: NextVe::ZERO,
            skip: 0,
            online_used: false,
            temps: TempCache::new(),
            dynamics: DynamicsState::new(),
        }
    }

    /// The online estimate forgotten: empty window, no VE. Out of line: it runs when the
    /// source changes from the online one, not per sample.
    #[cold]
    #[inline(never)]
    fn reset_online(&mut self) {
        self.window.reset();
        self.online_ve_g = [F::ZERO; 3];
        self.online_status = Status::VIBRATION_ESTIMATE_NOT_READY;
        self.ve_work = 0;
        self.skip = 0;
        self.online_used = false;
    }
}

/// A completed block's VE in progress: its moments (referred to the acceleration and
/// clamped), the VE of the accelerometers done so far and whether any was clamped.
#[derive(Clone, Copy, Debug, PartialEq)]
struct NextVe<F> {
    moments: WindowMoments<F>,
    ve_g: Vec3<F>,
    clamped: bool,
}

impl<F: Float> NextVe<F> {
    const ZERO: Self = NextVe {
        moments: WindowMoments {
            mean_g: [F::ZERO; 3],
            var_g2: [F::ZERO; 3],
            m3_g3: [F::ZERO; 3],
            m4_g4: [F::ZERO; 3],
            cov_g2: [F::ZERO; 3],
            abs_excess_g: [F::ZERO; 3],
        },
        ve_g: [F::ZERO; 3],
        clamped: false,
    };
}

impl<F: Float> Pipeline<F> {
    /// Joins a calibration and a VE configuration.
    pub fn new(cal: Calibration<F>, vib: VibrationConfig<F>) -> Self {
        Pipeline { cal, vib, dynamics: None, round_c: F::ZERO }
    }

    /// The same pipeline with thermal dynamics at a fixed sampling period
    /// ([`ThermalDynamics::at_rate`](crate::dynamics::ThermalDynamics::at_rate)); dynamics
    /// with every stage off are not applied. Each step then evaluates the temperature model at
    /// the effective temperature rounded to a multiple of [`TEMP_EFF_STEP_C`] (the cache keeps
    /// the terms while the rounded value does not change) and subtracts the bias play.
    pub fn with_dynamics(mut self, dynamics: FixedRate<F>) -> Self {
        if dynamics.params().is_none() {
            self.dynamics = None;
            self.round_c = F::ZERO;
        } else {
            self.dynamics = Some(dynamics);
            self.round_c = F::from_f64(1.5) / F::EPSILON * F::from_f64(TEMP_EFF_STEP_C);
        }
        self
    }

    /// The same pipeline evaluating the temperature model at the exact effective temperature
    /// on every sample (no rounding to [`TEMP_EFF_STEP_C`], the stages run on every sample,
    /// [`FixedRate::every_sample`]): the reference the rounded, held one is tested against.
    pub fn exact_effective_temperature(mut self) -> Self {
        self.round_c = F::ZERO;
        self.dynamics = self.dynamics.map(|d| d.every_sample());
        self
    }

    /// The thermal dynamics in use.
    pub fn dynamics(&self) -> Option<&FixedRate<F>> {
        self.dynamics.as_ref()
    }

    /// The stand-in when no valid calibration exists (a missing or rejected blob):
    /// [`Calibration::uncalibrated`] with no VE model. Every sample it produces is flagged
    /// `INVALID_CALIBRATION`.
    pub fn uncalibrated() -> Self {
        Pipeline::new(Calibration::uncalibrated(), VibrationConfig::none())
    }

    /// The calibration.
    pub fn calibration(&self) -> &Calibration<F> {
        &self.cal
    }

    /// The VE configuration.
    pub fn vibration(&self) -> &VibrationConfig<F> {
        &self.vib
    }

    /// The per-sample step: signals `u_v` \[V\] and temperature `temp_c` [°C] to specific
    /// force \[g\] with the VE for `source` subtracted, and status.
    ///
    /// # Example
    ///
    /// Without a VE model the step is the calibration's [`compensate`](Calibration::compensate),
    /// bit for bit; the state is the caller's (the sampling interrupt holds both).
    ///
    /// ```
    /// use bins_comp::compensate::Method;
    /// use bins_comp::paper;
    /// use bins_comp::pipeline::{Pipeline, PipelineState, VibrationSource};
    /// use bins_comp::vibration::VibrationConfig;
    ///
    /// let cal = paper::calibration::<f32>(paper::two_range_model()?, Method::CoefficientCorrection)?;
    /// let pipeline = Pipeline::new(cal, VibrationConfig::none());
    /// let mut state = PipelineState::<f32, 64>::new();
    /// let u_v = paper::TABLE_CONSTANTS[0].signals_v(&[0.6, -0.8, 0.0]).map(|u| u as f32);
    ///
    /// for _ in 0..3 {
    ///     let sample = pipeline.step(&mut state, u_v, 20.0, VibrationSource::None);
    ///     assert_eq!(sample, cal.compensate(u_v, 20.0));
    ///     assert!((sample.accel_g[0] - 0.6).abs() < 2e-6 && (sample.accel_g[1] + 0.8).abs() < 2e-6);
    /// }
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    #[inline]
    pub fn step<const W: usize>(
        &self,
        state: &mut PipelineState<F, W>,
        u_v: Vec3<F>,
        temp_c: F,
        source: VibrationSource,
    ) -> Sample<F> {
        self.step_with_ve(state, u_v, temp_c, source).0
    }

    /// The online VE's share of a step (`state.ve_work`, see [`PipelineState`]): on the step
    /// after a block completes, its moments, referred to the acceleration and clamped; on each
    /// of the next three, one accelerometer's VE, and after the third the block's VE replaces
    /// the one subtracted. Four steps per block, so it is kept out of the per-sample code and
    /// optimised for size.
    #[inline(never)]
    #[cfg_attr(unstable_target, optimize(size))]
    fn online_ve_work<const W: usize>(&self, state: &mut PipelineState<F, W>) {
        let n = &mut state.next_ve;
        match state.ve_work {
            1 => match state.window.moments() {
                Some(mut m) => {
                    m.unscale(&self.vib.output_gains(&m));
                    n.clamped = m.clamp_sigma(F::from_f64(MAX_LEVEL_G));
                    n.moments = m;
                    state.ve_work = 2;
                }
                None => state.ve_work = 0,
            },
            w => {
                let i = (w as usize).wrapping_sub(2);
                if let (Some(&axis), Some(slot)) = (Axis::ALL.get(i), n.ve_g.get_mut(i)) {
                    let (e, c) = self.vib.correction_from_moments_on_g(&n.moments, &n.moments.mean_g, axis);
                    *slot = e;
                    n.clamped |= c;
                }
                if w >= 4 {
                    // Finite: each axis's VE is `solve_static_g`'s.
                    state.online_ve_g = n.ve_g;
                    state.online_status = if n.clamped { Status::VIBRATION_OUT_OF_RANGE } else { Status::OK };
                    state.ve_work = 0;
                } else {
                    state.ve_work = w + 1;
                }
            }
        }
    }

    /// [`step`](Self::step), also returning the VE \[g\] that was subtracted from each axis.
    pub fn step_with_ve<const W: usize>(
        &self,
        state: &mut PipelineState<F, W>,
        u_v: Vec3<F>,
        temp_c: F,
        source: VibrationSource,
    ) -> (Sample<F>, Vec3<F>) {
        // The temperature the model is evaluated at: the reading, or with thermal dynamics the
        // effective temperature rounded to a multiple of the step (|T_eff| ≤ 1050 °C is far
        // below the constant 1.5·2^p·step, so the sum's rounding is the rounding to the step; a
        // non-finite T_eff stays non-finite and the calibration's policy applies). One call of
        // the cache and of `apply` for both, so that they stay inlined in the step.
        let (temp_c, play) = match &self.dynamics {
            None => (temp_c, None),
            Some(d) => {
                let e = d.step(&mut state.dynamics, temp_c);
                ((e.temp_eff_c + self.round_c) - self.round_c, Some((d.bias_play_g(), e.bias_play)))
            }
        };
        let mut s = self.cal.apply(u_v, state.temps.get(&self.cal, temp_c));
        // Without dynamics one test, not two.
        if let Some((bias_g, d)) = play
            && usable(&s)
        {
            for (a, b) in s.accel_g.iter_mut().zip(bias_g) {
                *a = (-*b).mul_add(d, *a);
            }
        }
        self.subtract_ve(state, s, source)
    }

    /// The VE stage of [`step`](Self::step): the VE for `source` subtracted from the
    /// compensated sample `s` (the window fed with it, for the online source), the VE's flags
    /// set; returns the sample and the VE \[g\] subtracted from each axis. Nothing is
    /// subtracted from a sample of an invalid calibration or with a non-finite input, and it
    /// does not enter the window. Public so that the benchmark can time it alone.
    #[inline]
    pub fn subtract_ve<const W: usize>(
        &self,
        state: &mut PipelineState<F, W>,
        mut s: Sample<F>,
        source: VibrationSource,
    ) -> (Sample<F>, Vec3<F>) {
        let ve = match source {
            VibrationSource::Online => {
                if !usable(&s) {
                    return (s, [F::ZERO; 3]);
                }
                // One piece of the online VE per step, so that no step carries a whole
                // block's (nor a block's last sums and its moments together): the moments on
                // the step after a block completes, then one accelerometer's VE on each of the
                // next three.
                if state.ve_work != 0 {
                    self.online_ve_work(state);
                }
                state.online_used = true;
                // One block in ONLINE_BLOCK_EVERY enters the window: the samples after a
                // completed block are left out until the next block's first. The sample is
                // finite (`usable`).
                if state.skip != 0 {
                    state.skip -= 1;
                } else if state.window.push_finite(&s.accel_g) == Pushed::BlockDone {
                    state.ve_work = 1;
                    state.skip = ((ONLINE_BLOCK_EVERY - 1) * W) as u32;
                }
                s.status.insert(state.online_status);
                state.online_ve_g
            }
            // The window serves the online source only: a block must not span a time when it
            // was not selected.
            VibrationSource::None => {
                if state.online_used {
                    state.reset_online();
                }
                return (s, [F::ZERO; 3]);
            }
            VibrationSource::Profile(i) => {
                if state.online_used {
                    state.reset_online();
                }
                if !usable(&s) {
                    return (s, [F::ZERO; 3]);
                }
                let (e, flags) = self.profile_ve(i, s.accel_g);
                s.status.insert(flags);
                e
            }
        };
        for (a, e) in s.accel_g.iter_mut().zip(ve) {
            *a -= e;
        }
        (s, ve)
    }
}

impl<F: Float> Pipeline<F> {
    /// The VE \[g\] of flight profile `i` for the compensated output `accel_g` and the flags
    /// it sets. Out of line: its locals (four Newton steps per axis) would otherwise enlarge
    /// the step's frame for every source, and a call is negligible beside its cost. The
    /// output by value, so that the step's sample stays in registers.
    #[inline(never)]
    fn profile_ve(&self, i: u8, accel_g: Vec3<F>) -> (Vec3<F>, Status) {
        let Some(v) = self.vib.profile(i as usize) else {
            return ([F::ZERO; 3], Status::VIBRATION_ESTIMATE_NOT_READY);
        };
        // Finite: each axis's VE is `solve_static_g`'s.
        let (e, clamped) = self.vib.correction_for_output_g(v, &accel_g);
        (e, if clamped { Status::VIBRATION_OUT_OF_RANGE } else { Status::OK })
    }
}

/// A sample the bias play and the VE apply to: a valid calibration and finite inputs (an
/// invalid calibration flags every sample).
#[inline(always)]
fn usable<F>(s: &Sample<F>) -> bool {
    s.status.0 & (Status::INVALID_CALIBRATION.0 | Status::NONFINITE_INPUT.0) == 0
}
