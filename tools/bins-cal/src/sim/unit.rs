//! The truth model of one unit: what its signals are for a given specific force, vibration,
//! temperature and time since power-on, before and after noise.
//!
//! `U_i = Σ_j K_ij(T)·f_j + U0_i(T) + K_ii(T)·(⟨N_i(f + ã)⟩ + b_i·d) + w_i(t_p) + b_i(t) + n_i`
//!
//! - `K(T)`, `U0(T)`: the core's [`CalibrationParams::constants_at`] at the temperature the
//!   constants follow (die through hysteresis), forward model T(1) by
//!   [`Constants::signals_v`](bins_comp::Constants::signals_v);
//! - `⟨N_i⟩`: the rectified mean of V(2)'s nonlinear part ([`super::rectify`]);
//! - `K_ii(T)·b_i·d`: the additive bias play ([`BiasPlay`]), a heating/cooling difference of
//!   the bias independent of the temperature sensitivity;
//! - `w_i`: the warm-up transient after power-on, `A_i·e^(−t_p/τ)`;
//! - `b_i`: bias random walk plus bias instability (one or two first-order Gauss–Markov
//!   terms, each with its own correlation time per axis);
//! - `n_i`: white noise per sample, then ADC quantisation.

use bins_comp::CalibrationParams;
use bins_comp::vibration::ConversionFunction;
use rand::Rng;
use rand_distr::StandardNormal;

/// Noise and quantisation of the signals and the thermistor. All zero = noise off.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct NoiseParams {
    /// White noise per sample, RMS \[V\], per axis.
    pub white_v: [f64; 3],
    /// Bias random walk [V/√s], per axis.
    pub random_walk_v_per_sqrt_s: [f64; 3],
    /// Bias instability: stationary RMS of a first-order Gauss–Markov bias \[V\], per axis.
    pub bias_instability_v: [f64; 3],
    /// Its correlation time \[s\], per axis.
    pub bias_tau_s: [f64; 3],
    /// A second Gauss–Markov bias: stationary RMS \[V\], per axis (0 = none). With the first,
    /// white noise and the random walk it follows a real unit's Allan curve, which one
    /// Gauss–Markov term seldom does (`docs/noise.md`).
    pub bias_instability2_v: [f64; 3],
    /// Its correlation time \[s\], per axis.
    pub bias_tau2_s: [f64; 3],
    /// ADC step \[V\]; 0 = no quantisation.
    pub adc_lsb_v: f64,
    /// Thermistor white noise per sample, RMS [°C].
    pub temp_noise_c: f64,
    /// Thermistor resolution [°C]; 0 = none.
    pub temp_resolution_c: f64,
    /// Thermistor offset [°C].
    pub temp_offset_c: f64,
    /// Whether the logger's sample mean carries the fluctuation of the vibration over one
    /// sample period (random: the boxcar-averaged band noise; sine: the part of a period not
    /// completed in the sample) on top of the rectified mean.
    pub vibration_sampling: bool,
}

/// The unit: constants and their temperature model, conversion functions, warm-up.
#[derive(Clone, Debug, PartialEq)]
pub struct UnitModel {
    /// Constants at T0 and their temperature model (method and range unused).
    pub params: CalibrationParams,
    /// V(2) of the x, y, z accelerometers, in g units (its linear part is T(1)'s and is not
    /// added again).
    pub cf: [ConversionFunction<f64>; 3],
    /// Warm-up transient amplitude at power-on \[V\], per axis.
    pub warmup_v: [f64; 3],
    /// Warm-up time constant \[s\].
    pub warmup_tau_s: f64,
    /// Additive bias play: amplitude per axis \[g\] (0 = none).
    pub bias_play_g: [f64; 3],
    /// Its play width [°C].
    pub bias_play_width_c: f64,
}

/// The additive bias play of the unit: a play (backlash) of width `h_b` on the temperature the
/// constants follow, whose output `d = (play(T) − T)/(h_b/2)` ∈ [−1, 1] is −1 while heating,
/// +1 while cooling (beyond the play) and in between after a reversal; the bias on axis `i` is
/// `K_ii·b_i·d`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BiasPlay {
    width_c: f64,
    state_c: f64,
}

impl BiasPlay {
    /// Width `width_c` [°C] (0: none), starting centred on `temp_c` (d = 0).
    pub fn new(width_c: f64, temp_c: f64) -> Self {
        BiasPlay { width_c, state_c: temp_c }
    }

    /// Advances the play to the temperature `temp_c`; returns `d`.
    pub fn step(&mut self, temp_c: f64) -> f64 {
        if !(self.width_c > 0.0) {
            return 0.0;
        }
        let h = 0.5 * self.width_c;
        self.state_c = self.state_c.clamp(temp_c - h, temp_c + h);
        (self.state_c - temp_c) / h
    }
}

/// A quantiser that prints short: for a step whose inverse is an integer (1e-7 V, 0.01 °C)
/// it divides by that integer, so the result is the double nearest to a short decimal.
#[derive(Clone, Copy, Debug)]
pub struct Quantiser {
    step: f64,
    inv: Option<f64>,
}

impl Quantiser {
    /// A quantiser with step `step` (0 = identity).
    pub fn new(step: f64) -> Self {
        let inv = if step > 0.0 {
            let i = (1.0 / step).round();
            (i >= 1.0 && ((1.0 / step) - i).abs() <= 1e-9 * i).then_some(i)
        } else {
            None
        };
        Quantiser { step, inv }
    }

    /// `x` rounded to the step.
    #[inline]
    pub fn apply(&self, x: f64) -> f64 {
        match self.inv {
            Some(inv) => (x * inv).round() / inv,
            None if self.step > 0.0 => (x / self.step).round() * self.step,
            None => x,
        }
    }
}

/// The random state of the unit's noise.
#[derive(Clone, Debug)]
pub struct NoiseState {
    p: NoiseParams,
    rw: [f64; 3],
    gm: [f64; 3],
    rw_step: [f64; 3],
    gm_decay: [f64; 3],
    gm_drive: [f64; 3],
    gm2: [f64; 3],
    gm2_decay: [f64; 3],
    gm2_drive: [f64; 3],
    adc: Quantiser,
    temp_q: Quantiser,
}

impl NoiseState {
    /// Zero biases; the Gauss–Markov biases start from their stationary distributions at the
    /// first draw.
    pub fn new(p: NoiseParams, dt: f64) -> Self {
        let decay = |tau: [f64; 3]| tau.map(|t| if t > 0.0 { (-dt / t).exp() } else { 0.0 });
        let drive =
            |sigma: [f64; 3], decay: [f64; 3]| std::array::from_fn(|i| sigma[i] * (1.0 - decay[i] * decay[i]).sqrt());
        let (gm_decay, gm2_decay) = (decay(p.bias_tau_s), decay(p.bias_tau2_s));
        NoiseState {
            p,
            rw: [0.0; 3],
            gm: [0.0; 3],
            rw_step: p.random_walk_v_per_sqrt_s.map(|q| q * dt.sqrt()),
            gm_decay,
            gm_drive: drive(p.bias_instability_v, gm_decay),
            gm2: [0.0; 3],
            gm2_decay,
            gm2_drive: drive(p.bias_instability2_v, gm2_decay),
            adc: Quantiser::new(p.adc_lsb_v),
            temp_q: Quantiser::new(p.temp_resolution_c),
        }
    }

    /// Initialises the Gauss–Markov biases from their stationary distributions (the second
    /// term's draws after the first's, so a scenario without it draws as before).
    pub fn start<R: Rng>(&mut self, rng: &mut R) {
        for i in 0..3 {
            if self.p.bias_instability_v[i] > 0.0 {
                let z: f64 = rng.sample(StandardNormal);
                self.gm[i] = self.p.bias_instability_v[i] * z;
            }
        }
        for i in 0..3 {
            if self.p.bias_instability2_v[i] > 0.0 {
                let z: f64 = rng.sample(StandardNormal);
                self.gm2[i] = self.p.bias_instability2_v[i] * z;
            }
        }
    }

    /// Adds one sample's noise to `u` and quantises it.
    #[inline]
    pub fn apply_signals<R: Rng>(&mut self, rng: &mut R, u: &mut [f64; 3]) {
        for i in 0..3 {
            if self.rw_step[i] > 0.0 {
                let z: f64 = rng.sample(StandardNormal);
                self.rw[i] += self.rw_step[i] * z;
            }
            if self.gm_drive[i] > 0.0 {
                let z: f64 = rng.sample(StandardNormal);
                self.gm[i] = self.gm_decay[i] * self.gm[i] + self.gm_drive[i] * z;
            }
            let mut v = u[i] + self.rw[i] + self.gm[i];
            if self.gm2_drive[i] > 0.0 {
                let z: f64 = rng.sample(StandardNormal);
                self.gm2[i] = self.gm2_decay[i] * self.gm2[i] + self.gm2_drive[i] * z;
                v += self.gm2[i];
            }
            if self.p.white_v[i] > 0.0 {
                let z: f64 = rng.sample(StandardNormal);
                v += self.p.white_v[i] * z;
            }
            u[i] = self.adc.apply(v);
        }
    }

    /// The thermistor's reading for its true temperature.
    #[inline]
    pub fn apply_temp<R: Rng>(&mut self, rng: &mut R, t: f64) -> f64 {
        let mut v = t + self.p.temp_offset_c;
        if self.p.temp_noise_c > 0.0 {
            let z: f64 = rng.sample(StandardNormal);
            v += self.p.temp_noise_c * z;
        }
        self.temp_q.apply(v)
    }

    /// Whether vibration sampling fluctuations are on.
    pub fn vibration_sampling(&self) -> bool {
        self.p.vibration_sampling
    }
}

impl UnitModel {
    /// The noise-free signals \[V\] at the constants' temperature `temp_c` for the static
    /// specific force `f_g` plus the sample's mean vibration `vib_mean_g` (zero unless the
    /// sampling fluctuation is on), with the rectified means `rect_g` \[g\], `power_s` since
    /// power-on and the bias play's output `bias_d` ([`BiasPlay::step`]).
    #[inline]
    pub fn signals_v(
        &self,
        temp_c: f64,
        f_g: &[f64; 3],
        vib_mean_g: &[f64; 3],
        rect_g: &[f64; 3],
        power_s: f64,
        bias_d: f64,
    ) -> [f64; 3] {
        let c = self.params.constants_at(temp_c);
        let f = [f_g[0] + vib_mean_g[0], f_g[1] + vib_mean_g[1], f_g[2] + vib_mean_g[2]];
        let mut u = c.signals_v(&f);
        let w = if self.warmup_tau_s > 0.0 { (-power_s / self.warmup_tau_s).exp() } else { 0.0 };
        for i in 0..3 {
            u[i] += c.k_v_per_g[i][i] * (rect_g[i] + self.bias_play_g[i] * bias_d) + self.warmup_v[i] * w;
        }
        u
    }
}

#[cfg(test)]
mod tests {
    use super::BiasPlay;

    #[test]
    fn bias_play_follows_a_hand_computed_trace() {
        // Width 1 °C (half-width 0.5), starting at 20 °C: heat to 21, reverse to 20.2, heat to 20.6.
        let mut p = BiasPlay::new(1.0, 20.0);
        let trace = [
            (20.0, 0.0),   // centred
            (20.25, -0.5), // state 20 stays (within 19.75..20.75): (20 − 20.25)/0.5
            (20.5, -1.0),  // state at the lower edge 20.0
            (21.0, -1.0),  // dragged: state 20.5
            (20.7, -0.4),  // reversed, inside the play: state 20.5, (20.5 − 20.7)/0.5
            (20.2, 0.6),   // state 20.5: (20.5 − 20.2)/0.5
            (19.8, 1.0),   // dragged down: state 20.3
            (20.6, -0.6),  // reversed again: state 20.3 within 20.1..21.1, (20.3 − 20.6)/0.5
        ];
        for (k, (t, d)) in trace.iter().enumerate() {
            let got = p.step(*t);
            assert!((got - d).abs() < 1e-12, "step {k} at {t} °C: d = {got}, expected {d}");
        }
        let mut none = BiasPlay::new(0.0, 20.0);
        assert_eq!(none.step(30.0), 0.0);
    }
}
