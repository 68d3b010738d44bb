//! The unit's thermal model: chamber air → case → sensor die, each a first-order lag, the die
//! heated by the unit's own dissipation while it is powered, and the thermistor, which sits
//! between case and die and has its own lag. The constants follow the die temperature
//! (through an optional hysteresis); the `temp_C` column is the thermistor's reading.
//!
//! Each lag `τ·dx/dt = u − x` is advanced exactly for an input held over the step:
//! `x ← x + (u − x)·(1 − e^(−Δt/τ))`; `τ = 0` means no lag (`x = u`). The die's input over a
//! step is the case plus the self-heating when the unit is powered at the step's start, the
//! case alone when it is off.

/// Thermal parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ThermalParams {
    /// Chamber air temperature at the start [°C].
    pub start_c: f64,
    /// Chamber ramp rate [°C/s] (infinite: jumps to the set point).
    pub rate_c_per_s: f64,
    /// Time constant air → case \[s\].
    pub case_tau_s: f64,
    /// Time constant case → die \[s\].
    pub die_tau_s: f64,
    /// Die temperature above the case in steady state once powered [°C].
    pub self_heating_c: f64,
    /// Where the thermistor sits: 0 = on the case, 1 = at the die.
    pub thermistor_at: f64,
    /// The thermistor's own time constant \[s\].
    pub thermistor_tau_s: f64,
    /// Width of the backlash (play) hysteresis between die temperature and the temperature
    /// the constants follow [°C]; 0 = none.
    pub hysteresis_c: f64,
}

impl Default for ThermalParams {
    fn default() -> Self {
        ThermalParams {
            start_c: 20.0,
            rate_c_per_s: f64::INFINITY,
            case_tau_s: 0.0,
            die_tau_s: 0.0,
            self_heating_c: 0.0,
            thermistor_at: 0.0,
            thermistor_tau_s: 0.0,
            hysteresis_c: 0.0,
        }
    }
}

/// The thermal state, advanced one sample at a time.
#[derive(Clone, Debug)]
pub struct Thermal {
    p: ThermalParams,
    k_case: f64,
    k_die: f64,
    k_th: f64,
    dt: f64,
    /// Chamber set point [°C].
    pub target_c: f64,
    /// Rate at which the chamber moves to the set point [°C/s] (infinite: jumps).
    pub rate_c_per_s: f64,
    /// Whether the unit is powered (its die heated) over the next step.
    pub powered: bool,
    /// Chamber air [°C].
    pub chamber_c: f64,
    /// Case [°C].
    pub case_c: f64,
    /// Die [°C].
    pub die_c: f64,
    /// Thermistor (true, before its noise) [°C].
    pub thermistor_c: f64,
    /// The temperature the constants follow (die through the hysteresis) [°C].
    pub effective_c: f64,
}

fn lag_gain(dt: f64, tau: f64) -> f64 {
    if tau > 0.0 { -(-dt / tau).exp_m1() } else { 1.0 }
}

impl Thermal {
    /// Starts in equilibrium with the chamber at `p.start_c`, powered for `power_s` seconds
    /// (the die's self-heating has reached `1 − e^(−power_s/τ_die)` of its final value).
    pub fn new(p: ThermalParams, dt: f64, power_s: f64) -> Self {
        let heat = if p.die_tau_s > 0.0 { -(-power_s / p.die_tau_s).exp_m1() } else { 1.0 };
        let die = p.start_c + p.self_heating_c * heat;
        let th = p.start_c + p.thermistor_at * (die - p.start_c);
        Thermal {
            p,
            k_case: lag_gain(dt, p.case_tau_s),
            k_die: lag_gain(dt, p.die_tau_s),
            k_th: lag_gain(dt, p.thermistor_tau_s),
            dt,
            target_c: p.start_c,
            rate_c_per_s: p.rate_c_per_s,
            powered: true,
            chamber_c: p.start_c,
            case_c: p.start_c,
            die_c: die,
            thermistor_c: th,
            effective_c: die,
        }
    }

    /// Advances one sample period.
    pub fn step(&mut self) {
        let max_step = self.rate_c_per_s * self.dt;
        let d = self.target_c - self.chamber_c;
        self.chamber_c = if d.abs() <= max_step { self.target_c } else { self.chamber_c + max_step.copysign(d) };
        self.case_c += (self.chamber_c - self.case_c) * self.k_case;
        let heating_c = if self.powered { self.p.self_heating_c } else { 0.0 };
        self.die_c += (self.case_c + heating_c - self.die_c) * self.k_die;
        let at = self.case_c + self.p.thermistor_at * (self.die_c - self.case_c);
        self.thermistor_c += (at - self.thermistor_c) * self.k_th;
        let h = 0.5 * self.p.hysteresis_c;
        self.effective_c = self.effective_c.clamp(self.die_c - h, self.die_c + h);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lags_follow_a_step_exponentially() {
        let p = ThermalParams {
            start_c: 20.0,
            case_tau_s: 100.0,
            thermistor_at: 0.0,
            thermistor_tau_s: 0.0,
            ..ThermalParams::default()
        };
        let mut t = Thermal::new(p, 0.5, 0.0);
        t.target_c = 70.0;
        for _ in 0..200 {
            t.step();
        }
        // After 100 s = τ: 1 − 1/e of the step.
        let expect = 20.0 + 50.0 * (1.0 - (-1.0f64).exp());
        assert!((t.case_c - expect).abs() < 1e-9, "{}", t.case_c);
        assert_eq!(t.die_c, t.case_c);
        assert_eq!(t.thermistor_c, t.case_c);
    }

    #[test]
    fn self_heating_decays_while_off_and_returns_when_on() {
        let p = ThermalParams { die_tau_s: 100.0, self_heating_c: 5.0, ..ThermalParams::default() };
        let mut t = Thermal::new(p, 1.0, 1e9);
        assert_eq!(t.die_c, 25.0);
        t.powered = false;
        for _ in 0..100 {
            t.step();
        }
        // One τ off: e^(−1) of the heating left.
        assert!((t.die_c - (20.0 + 5.0 * (-1.0f64).exp())).abs() < 1e-9, "{}", t.die_c);
        t.powered = true;
        for _ in 0..100 {
            t.step();
        }
        let want = 25.0 - 5.0 * (1.0 - (-1.0f64).exp()) * (-1.0f64).exp();
        assert!((t.die_c - want).abs() < 1e-9, "{} vs {want}", t.die_c);
    }

    #[test]
    fn chamber_ramps_at_its_rate_and_hysteresis_is_a_play() {
        let p = ThermalParams { rate_c_per_s: 1.0 / 60.0, hysteresis_c: 2.0, ..ThermalParams::default() };
        let mut t = Thermal::new(p, 1.0, 1e9);
        t.target_c = 30.0;
        for _ in 0..300 {
            t.step();
        }
        assert!((t.chamber_c - 25.0).abs() < 1e-9);
        // Rising: the constants' temperature trails the die by half the play.
        assert!((t.effective_c - 24.0).abs() < 1e-9);
        t.target_c = 0.0;
        for _ in 0..60 {
            t.step();
        }
        // Reversed by 1 °C: inside the play, no change.
        assert!((t.die_c - 24.0).abs() < 1e-9 && (t.effective_c - 24.0).abs() < 1e-9);
    }
}
