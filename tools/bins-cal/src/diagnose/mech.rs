//! The library of named physical mechanisms. Each is a parametric term built from the
//! reference columns, the temperature and time, linear in its coefficients and, for the
//! thermal and turn-on terms, nonlinear in one time constant or width `θ` (searched on a grid,
//! then refined).
//!
//! Nonlinearity and vibration terms are the conversion function V(2) with one coefficient set
//! to 1, evaluated statically and rectified under the row's vibration through the core's exact
//! VE ([`bins_comp::vibration::ve_terms`]), so the same coefficient explains the static and the
//! vibration part (one implementation of each formula).
//!
//! The thermal terms use the simulation's own temperature sensitivity `S_i(T, f)` (fitted to
//! SIM's departure from its linear model): a sensor whose constants follow an effective
//! temperature `T_e` instead of the thermistor's `T` differs from SIM by `S_i(T_e) − S_i(T)`.
//! When SIM has no temperature dependence the term falls back to `T_e − T` with a free
//! coefficient [g/°C].

use super::noise::ls_sse;
use super::prep::Prepared;
use bins_comp::vibration::{Axis, ConversionFunction, Variant, Vibration, ve_terms};

/// Points a decade of the θ grids (refined off the grid by golden section in the fit).
pub const GRID_PER_DECADE: f64 = 3.0;

/// Reference temperature of the polynomial terms [°C] (the paper's normal conditions).
pub const T0_C: f64 = 20.0;

/// A turn-on term is offered at a time constant τ only when `e^(−P/τ)` changes over the
/// recording's `power_s` by at least this much: a warm-up `A·e^(−P/τ)` by this share of its
/// level on the first row (the recording shows the term's shape, not a constant, nor a slow
/// ramp at a τ far beyond the recording: a drift under another name); a self-heating
/// `S'·(1 − e^(−P/τ))` by this share of its rise (where `e^(−P/τ)` has died out the column is
/// SIM's sensitivity times a constant, a static term under another name).
pub const TURN_ON_MIN_RANGE: f64 = 0.25;

/// A warm-up is offered at τ only when `e^(−P/τ)` on the recording's first row is at least
/// this share of its level at power-on: the recording starts within 4.6 τ of power-on, what it
/// shows is the warm-up's tail, and its size at power-on is at most 100× what the recording
/// shows (a record started 25 min after power-on shows a warm-up of 5 min at e^(−5), 1/150
/// of its size at power-on: not offered).
pub const TURN_ON_MIN_TAIL: f64 = 0.01;

/// A turn-on term is offered at τ only when at most this share of the centred energy of
/// `e^(−P/τ)` falls in one held-out fold ([`super::fit::FOLDS`]): a signature that lives
/// in one fold (a τ of seconds after power-on in an hour-long record) cannot be checked on
/// data left out of its fit, and fitted from the other folds it is not determined at all.
pub const TURN_ON_MAX_FOLD_SHARE: f64 = 0.98;

/// The ratios τ/τ_fast tried for a warm-up fitted with its fast part,
/// `A·e^(−P/τ) + B·e^(−R·P/τ)` ([`Context::member_columns`]): a fast part from half the main
/// time constant to a fourteenth of it.
pub const WARMUP_FAST_RATIOS: [f64; 6] = [2.0, 3.0, 4.0, 6.0, 9.0, 14.0];

/// A mechanism.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Mech {
    /// The sensor's effective temperature lags the thermistor (first-order lag, τ).
    ThermalLag,
    /// Rate-independent heating/cooling difference (play of width h) of the temperature the
    /// constants follow: through SIM's temperature sensitivity.
    ThermalHysteresis,
    /// Additive heating/cooling difference of the bias: a play of width h, its output
    /// `(play_h(T) − T)/(h/2)` ∈ [−1, 1] times an amplitude linear in T, independent of SIM's
    /// temperature sensitivity.
    BiasHysteresis,
    /// The die heats after power-on, unseen by the thermistor: `S'(T)·ΔT_sh·(1 − e^(−P/τ))`.
    SelfHeating,
    /// Turn-on transient of the bias: `A·e^(−P/τ)`.
    Warmup,
    /// Bias vs temperature beyond the simulated model: `b1 ΔT + b2 ΔT² + b3 ΔT³`.
    BiasTempOrder,
    /// Scale-factor temperature dependence missing: `f_i (s1 ΔT + s2 ΔT²)`.
    ScaleTemp,
    /// Temperature dependence of the cross-sensitivities missing: `f_j ΔT`, `f_j ΔT²`, j ≠ i.
    CrossCouplingTemp,
    /// Static cross-axis sensitivity / misalignment: `f_j`, j ≠ i.
    CrossAxis,
    /// Scale-factor error: `f_i`.
    ScaleFactor,
    /// Scale-factor asymmetry δ_1A of V(2): `0.5·δ·|a3|`, rectified under vibration.
    SfAsymmetry,
    /// Quadratic nonlinearity k2: `a3²`, rectified `k2·⟨ã3²⟩` under vibration.
    NonlinearityK2,
    /// Cubic nonlinearity k3: `a3³`, `3·⟨ã3²⟩·a_p3` under vibration.
    NonlinearityK3,
    /// Multiplicative cross-coupling m31, m32: `a3 a1`, `a3 a2`, `⟨ã3 ã1⟩`, `⟨ã3 ã2⟩`.
    VibrationCross,
    /// A settling or drift in time, `e^(−(t − t₀)/τ)` (t₀ the first row): never named on its
    /// own (slow drift is noise, [`super::noise`]), only the alternative a temperature form
    /// must beat ([`Mech::ALTERNATIVES`]).
    Drift,
}

impl Mech {
    /// Every mechanism, in report order.
    pub const ALL: [Mech; 14] = [
        Mech::ThermalLag,
        Mech::ThermalHysteresis,
        Mech::BiasHysteresis,
        Mech::SelfHeating,
        Mech::Warmup,
        Mech::BiasTempOrder,
        Mech::ScaleTemp,
        Mech::CrossCouplingTemp,
        Mech::CrossAxis,
        Mech::ScaleFactor,
        Mech::SfAsymmetry,
        Mech::NonlinearityK2,
        Mech::NonlinearityK3,
        Mech::VibrationCross,
    ];

    /// Forms that are never named but are offered as the alternative explanation of what a
    /// named mechanism fits: a temperature term and a drift in time are confounded when the
    /// temperature changes one way only.
    pub const ALTERNATIVES: [Mech; 1] = [Mech::Drift];

    /// Whether `self` is a temperature form (a drift in time is its alternative).
    pub fn temperature_form(self) -> bool {
        matches!(
            self,
            Mech::ThermalLag
                | Mech::ThermalHysteresis
                | Mech::BiasHysteresis
                | Mech::BiasTempOrder
                | Mech::ScaleTemp
                | Mech::CrossCouplingTemp
        )
    }

    /// Whether `self` is a bias that follows the unit's thermal history: the die's temperature
    /// through a lag, a play or its own heating, the time since power-on, a second bias form in
    /// temperature, or a drift in time. Where the model leaves an accelerometer above its floor,
    /// two of them there stand in for each other and are reported as one group
    /// ([`super::report::THERMAL_JOIN_RATIO`]).
    pub fn thermal_history(self) -> bool {
        matches!(
            self,
            Mech::ThermalLag
                | Mech::ThermalHysteresis
                | Mech::BiasHysteresis
                | Mech::SelfHeating
                | Mech::Warmup
                | Mech::BiasTempOrder
                | Mech::Drift
        )
    }

    /// Whether `self` belongs to the unit's thermal path rather than to one accelerometer: the
    /// die's lag behind the case, its play, an additive play of the same width, the die's
    /// heating after power-on, the settling since power-on. Their θ (τ, width) is the unit's,
    /// as the compensation core's dynamics stage carries them (one τ, one width, amplitudes
    /// per accelerometer); only their sizes differ between accelerometers. A second bias form
    /// in temperature and a drift in time are each accelerometer's own.
    pub fn thermal_path(self) -> bool {
        matches!(
            self,
            Mech::ThermalLag | Mech::ThermalHysteresis | Mech::BiasHysteresis | Mech::SelfHeating | Mech::Warmup
        )
    }

    /// Whether the mechanism's one coefficient, acting through SIM's sensitivity, is positive
    /// by its physics: a lag's or a play's gain (the sensing element sees a delayed or held
    /// temperature, not one ahead of the thermistor) and a self-heating's rise (the die heats
    /// itself after power-on).
    pub fn positive_through_sim(self) -> bool {
        matches!(self, Mech::ThermalLag | Mech::ThermalHysteresis | Mech::SelfHeating)
    }

    /// The report id.
    pub fn id(self) -> &'static str {
        match self {
            Mech::ThermalLag => "thermal_lag",
            Mech::ThermalHysteresis => "thermal_hysteresis",
            Mech::BiasHysteresis => "bias_hysteresis",
            Mech::SelfHeating => "self_heating",
            Mech::Warmup => "warmup",
            Mech::BiasTempOrder => "bias_temp_order",
            Mech::ScaleTemp => "scale_temp",
            Mech::CrossCouplingTemp => "cross_coupling_temp",
            Mech::CrossAxis => "cross_axis",
            Mech::ScaleFactor => "scale_factor",
            Mech::SfAsymmetry => "sf_asymmetry",
            Mech::NonlinearityK2 => "nonlinearity_k2",
            Mech::NonlinearityK3 => "nonlinearity_k3",
            Mech::VibrationCross => "vibration_cross",
            Mech::Drift => "drift",
        }
    }

    /// The mechanism with report id `id`.
    pub fn from_id(id: &str) -> Option<Mech> {
        Mech::ALL.into_iter().chain(Mech::ALTERNATIVES).find(|m| m.id() == id)
    }

    /// Name and unit of the nonlinear parameter θ, if any.
    pub fn theta(self) -> Option<&'static str> {
        match self {
            Mech::ThermalLag | Mech::SelfHeating | Mech::Warmup | Mech::Drift => Some("tau_s"),
            Mech::ThermalHysteresis | Mech::BiasHysteresis => Some("width_C"),
            _ => None,
        }
    }

    /// One line on what the term is.
    pub fn explanation(self) -> &'static str {
        match self {
            Mech::ThermalLag => {
                "the sensor's effective temperature lags the thermistor (first-order lag τ): the error follows the ramp rate and decays during holds"
            }
            Mech::ThermalHysteresis => {
                "rate-independent heating/cooling difference (play of width h): the constants follow the temperature through a backlash"
            }
            Mech::BiasHysteresis => {
                "additive bias hysteresis: heating and cooling legs differ by ±(a0 + a1 ΔT) through a play of width h, independent of the temperature sensitivity"
            }
            Mech::SelfHeating => {
                "the die warms after power-on by ΔT_sh with time constant τ, unseen by the thermistor: error = dS/dT·ΔT_sh·(1 − e^(−P/τ))"
            }
            Mech::Warmup => "turn-on transient of the bias A·e^(−P/τ), independent of the temperature sensitivity",
            Mech::BiasTempOrder => {
                "bias vs temperature of higher order than simulated: b1 ΔT + b2 ΔT² + b3 ΔT³ (ΔT = T − 20 °C)"
            }
            Mech::ScaleTemp => "scale-factor temperature dependence missing: f_i·(s1 ΔT + s2 ΔT²)",
            Mech::CrossCouplingTemp => {
                "temperature dependence of the cross-sensitivities missing: f_j·(c1 ΔT + c2 ΔT²), j ≠ i"
            }
            Mech::CrossAxis => "static cross-axis sensitivity / misalignment: f_j, j ≠ i",
            Mech::ScaleFactor => "scale factor differs from the simulated one: f_i",
            Mech::SfAsymmetry => {
                "scale-factor asymmetry δ_1A of V(2): 0.5·δ·|a3| statically, 0.5·δ·⟨|a_p3 + ã3|⟩ under vibration"
            }
            Mech::NonlinearityK2 => {
                "quadratic nonlinearity k2 of V(2): k2·a3² statically and k2·⟨ã3²⟩ rectified under vibration"
            }
            Mech::NonlinearityK3 => {
                "cubic nonlinearity k3 of V(2): k3·a3³ statically and 3·k3·⟨ã3²⟩·a_p3 under vibration"
            }
            Mech::VibrationCross => {
                "multiplicative cross-coupling m31, m32 of V(2): a3·a1, a3·a2 statically and ⟨ã3 ã1⟩, ⟨ã3 ã2⟩ under vibration"
            }
            Mech::Drift => "a settling or drift of the bias in time, A·e^(−(t − t₀)/τ), independent of the temperature",
        }
    }
}

/// The test that separates two mechanisms the data could not.
pub fn separating_test(a: Mech, b: Mech) -> String {
    use Mech::*;
    let (a, b) = if a <= b { (a, b) } else { (b, a) };
    match (a, b) {
        (Warmup, Drift) | (SelfHeating, Drift) => "a second power-on (power cycle): a turn-on term restarts with power_s, a drift in time does not".into(),
        (_, Drift) => "a temperature reversal (heat, then cool back through the same temperatures, or the reverse): a temperature term follows the temperature back, a drift in time does not".into(),
        (ThermalHysteresis, BiasHysteresis) => "positions or temperature ranges where the temperature sensitivity differs (e.g. +1 g and −1 g on an axis whose scale factor has a tempco): thermal hysteresis follows dS/dT, an additive bias play does not".into(),
        (ThermalLag, BiasHysteresis) => "two ramp rates with holds at the ends of the ramps: a lag's error scales with the rate and decays during a hold, an additive play does neither".into(),
        (BiasHysteresis, BiasTempOrder) => "holds at several temperatures, reached by heating and by cooling: the bias curve is the same both ways, a play is not".into(),
        (ThermalLag, ThermalHysteresis) => "two ramp rates with holds at the ends of the ramps: a lag's error scales with the rate and decays during a hold, hysteresis does neither".into(),
        (SfAsymmetry, NonlinearityK2) => "tilted positions (e.g. ±0.5 g, ±0.7 g along the axis): asymmetry grows as |f|, k2 as f²; or vibration at two amplitudes".into(),
        (SelfHeating, Warmup) => "power the unit on twice, in opposite positions (±1 g) or at two chamber temperatures: self-heating follows the local temperature sensitivity dS/dT, a warm-up transient does not".into(),
        (ThermalLag, BiasTempOrder) | (ThermalHysteresis, BiasTempOrder) => "holds at several temperatures, reached by heating and by cooling: the bias curve is the same both ways, lag and hysteresis are not".into(),
        (NonlinearityK2, NonlinearityK3) | (SfAsymmetry, NonlinearityK3) => "positions with the axis at +1 g and at −1 g (static and under vibration): odd terms change sign, even ones do not".into(),
        (ScaleTemp, BiasTempOrder) => "both orientations (+1 g and −1 g) at each temperature: the scale-factor term changes sign with f, the bias term does not".into(),
        (CrossAxis, CrossCouplingTemp) | (ScaleFactor, ScaleTemp) => "the same positions at several temperatures: the temperature term changes with T, the static one does not".into(),
        (Warmup, _) | (_, Warmup) | (SelfHeating, _) | (_, SelfHeating) => "a second power-on (power cycle) under different conditions: the turn-on term restarts with power_s".into(),
        _ => format!("a test in which the regressors differ: {} ({}) and {} ({})", a.id(), a.explanation(), b.id(), b.explanation()),
    }
}

/// SIM's temperature sensitivity of one accelerometer:
/// `S(T, f) = Σ_{p=1..3} ΔTᵖ·(c_p0 + Σ_j c_pj f_j)` \[g\], or `ΔT` itself (free form).
#[derive(Clone, Debug, PartialEq)]
pub struct Sensitivity {
    /// True when fitted to SIM; false: the free form `S = ΔT` [°C].
    pub from_sim: bool,
    /// `c[p−1][0]` constant, `c[p−1][1 + j]` times `f_j`.
    pub c: [[f64; 4]; 3],
}

impl Sensitivity {
    fn free() -> Self {
        let mut c = [[0.0; 4]; 3];
        c[0][0] = 1.0;
        Sensitivity { from_sim: false, c }
    }

    /// `S(T, f)`.
    pub fn eval(&self, temp_c: f64, f: &[f64; 3]) -> f64 {
        let dt = temp_c - T0_C;
        let mut acc = 0.0;
        for p in (0..3).rev() {
            let k = self.c[p][0] + self.c[p][1] * f[0] + self.c[p][2] * f[1] + self.c[p][3] * f[2];
            acc = (acc + k) * dt;
        }
        acc
    }

    /// `∂S/∂T`.
    pub fn deriv(&self, temp_c: f64, f: &[f64; 3]) -> f64 {
        let dt = temp_c - T0_C;
        let k = |p: usize| self.c[p][0] + self.c[p][1] * f[0] + self.c[p][2] * f[1] + self.c[p][3] * f[2];
        k(0) + 2.0 * k(1) * dt + 3.0 * k(2) * dt * dt
    }
}

/// One accelerometer's V(2) term with a single unit coefficient: static value plus the exact
/// VE under the row's vibration [g per unit coefficient].
fn v2_column(p: &Prepared, axis: usize, cf: &ConversionFunction<f64>) -> Vec<f64> {
    let ax = Axis::ALL[axis];
    (0..p.t.len())
        .map(|k| {
            let a = bins_comp::vibration::AccelAxes::from_unit(&p.f[k], ax);
            let stat = cf.eval_g(a) - a.ia;
            let ve = match p.vib[k] {
                Vibration::None => 0.0,
                ref v => ve_terms(cf, Variant::Exact, &v.on_accel(ax), a.ia).total_g(a.ia),
            };
            stat + ve
        })
        .collect()
}

fn unit_cf(set: impl FnOnce(&mut ConversionFunction<f64>)) -> ConversionFunction<f64> {
    let mut cf = ConversionFunction::default();
    set(&mut cf);
    cf
}

/// The V(2) unit columns of accelerometer `axis`: asymmetry, k2, k3, m31, m32.
pub fn v2_columns(p: &Prepared, axis: usize) -> [Vec<f64>; 5] {
    [
        v2_column(p, axis, &unit_cf(|c| c.delta_1a = 1.0)),
        v2_column(p, axis, &unit_cf(|c| c.k2_g_per_g2 = 1.0)),
        v2_column(p, axis, &unit_cf(|c| c.k3_g_per_g3 = 1.0)),
        v2_column(p, axis, &unit_cf(|c| c.m31_g_per_g2 = 1.0)),
        v2_column(p, axis, &unit_cf(|c| c.m32_g_per_g2 = 1.0)),
    ]
}

/// SIM's temperature sensitivity is fitted as a straight line over a span of `temp_C` below
/// this, a quadratic below 2.5 times it, a cubic beyond [°C] ([`fit_sensitivity`]).
pub const SENSITIVITY_LINEAR_SPAN_C: f64 = 6.0;

/// Fits SIM's temperature sensitivity of accelerometer `axis` (ordinary least squares of
/// `sim_g` on `[1, f] ⊗ [1, ΔT, ΔT², ΔT³]` plus the V(2) columns, ΔT from SIM's own smoothed
/// `temp_C`, [`Prepared::sim_temp_s`]). Falls back to the free form
/// when SIM's temperature terms are not significant (F-test, p < 1e-6) or the temperature
/// does not vary.
///
/// The polynomial's order follows the span SIM's temperature covers
/// ([`SENSITIVITY_LINEAR_SPAN_C`]): over a few degrees SIM's output against its thermistor is
/// not one curve (the die runs ahead of the thermistor after power-on and on ramps), and a
/// cubic fitted to that loop bends its slope at the span's ends. Against the user-profile
/// generator's own unit (200 profiles, docs/measurements.md; fitted against the thermistor's
/// reading, before [`die_rise`]), the slope's worst relative error over the span has a median
/// of 0.027 and a 90th percentile of 0.107 (a cubic throughout: 0.027, 0.124); soaks of about a
/// degree stay poor either way (0.3–1.4: their slope is the die's self-heating, which the
/// thermistor sees only in part). Where SIM shows its die's rise ([`die_rise`]), `sim_temp_s`
/// is the die's temperature and the loop is gone.
pub fn fit_sensitivity(p: &Prepared, axis: usize) -> Sensitivity {
    let temp = &p.sim_temp_s;
    let Some(design) = SimDesign::new(p, axis, temp) else { return Sensitivity::free() };
    design.fit(p, axis, temp, None).map_or_else(Sensitivity::free, |f| f.s)
}

/// The regression of SIM's departure `sim_g` on its temperature sensitivity
/// ([`fit_sensitivity`]): the columns that do not depend on the temperature (`[1, f]` and the
/// V(2) columns), the polynomial's order and scale from the span of SIM's temperature.
struct SimDesign {
    base: Vec<Vec<f64>>,
    /// SIM's residual sum of squares on the base columns alone \[g²\].
    sse_base: f64,
    order: usize,
    scale: f64,
}

/// A fit of SIM's sensitivity at some temperature ([`SimDesign::fit`]).
struct SimFit {
    s: Sensitivity,
    /// Residual sum of squares \[g²\].
    sse: f64,
    /// The extra column's coefficient (0 without one).
    extra_coef: f64,
}

impl SimDesign {
    /// `None` when SIM's temperature spans half a degree or less, or under 50 rows.
    fn new(p: &Prepared, axis: usize, temp: &[f64]) -> Option<Self> {
        let n = p.t.len();
        let (tmin, tmax) = temp.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
        if !(tmax - tmin > 0.5) || n < 50 {
            return None;
        }
        let span = tmax - tmin;
        let mut base: Vec<Vec<f64>> =
            (0..4).map(|j| (0..n).map(|k| if j == 0 { 1.0 } else { p.f[k][j - 1] }).collect()).collect();
        base.extend(v2_columns(p, axis));
        let order = if span < SENSITIVITY_LINEAR_SPAN_C {
            1
        } else if span < 2.5 * SENSITIVITY_LINEAR_SPAN_C {
            2
        } else {
            3
        };
        let (sse_base, _) = ls_sse(&p.sim_g[axis], &base);
        Some(SimDesign { base, sse_base, order, scale: 0.5 * span.max(1.0) })
    }

    /// Ordinary least squares of `sim_g` on the base columns, the polynomial in `temp` and
    /// `extra` (one column, or none). `None` when the temperature terms are not significant
    /// (F-test, p < 1e-6) or give less than 1 µg over the range: SIM does not depend on the
    /// temperature.
    fn fit(&self, p: &Prepared, axis: usize, temp: &[f64], extra: Option<&[f64]>) -> Option<SimFit> {
        let n = p.t.len();
        let dtn: Vec<f64> = temp.iter().map(|t| (t - T0_C) / self.scale).collect();
        let base = |j: usize, k: usize| if j == 0 { 1.0 } else { p.f[k][j - 1] };
        let mut cols = self.base.clone();
        let n_nuis = cols.len();
        let mut tags = Vec::new();
        for pw in 1..=self.order {
            for j in 0..4 {
                cols.push((0..n).map(|k| base(j, k) * dtn[k].powi(pw as i32)).collect());
                tags.push((pw, j));
            }
        }
        if let Some(e) = extra {
            cols.push(e.to_vec());
        }
        let y = &p.sim_g[axis];
        let (sse1, beta) = ls_sse(y, &cols);
        let sse0 = self.sse_base;
        let df = (cols.len() - n_nuis) as f64;
        let fstat = ((sse0 - sse1) / df) / (sse1 / (n as f64 - cols.len() as f64)).max(1e-300);
        let significant =
            sse0 > 0.0 && (sse1 <= 1e-20 * sse0 || fstat > 40.0 || super::stats::chi2_sf(fstat * df, df) < 1e-6);
        if !significant {
            return None;
        }
        let mut c = [[0.0; 4]; 3];
        for (b, &(pw, j)) in beta[n_nuis..].iter().zip(&tags) {
            c[pw - 1][j] = b / self.scale.powi(pw as i32);
        }
        let s = Sensitivity { from_sim: true, c };
        // Negligible sensitivity (below 1 µg over the range): free form.
        let range = (0..n).map(|k| s.eval(temp[k], &p.f[k]).abs()).fold(0.0, f64::max);
        if !(range >= 1e-6) {
            return None;
        }
        let extra_coef = if extra.is_some() { beta.last().copied().unwrap_or(0.0) } else { 0.0 };
        Some(SimFit { s, sse: sse1, extra_coef })
    }
}

/// The die's rise over the thermistor after each power-on, as SIM shows it ([`die_rise`]).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct DieRise {
    /// The rise once settled, `A` [°C].
    pub amp_c: f64,
    /// Its time constant `τ` \[s\].
    pub tau_s: f64,
    /// What SIM's sensitivity leaves of SIM's departure at the die's temperature, as a share
    /// of what it leaves at the thermistor's (sums of squares, geometric mean over the
    /// accelerometers whose SIM depends on the temperature).
    pub sim_left_share: f64,
}

impl DieRise {
    /// `A·(1 − e^(−P/τ))` at the power-on times `power_s` [°C].
    pub fn offset_c(&self, power_s: &[f64]) -> Vec<f64> {
        power_s.iter().map(|p| -self.amp_c * (-p / self.tau_s).exp_m1()).collect()
    }
}

/// The temperature of a die that rises `rho` over `temp` after each power-on with time constant
/// `tau`: `T + ρ·(1 − e^(−P/τ))` at the power-on times `power` [°C].
pub fn die_temperature(temp: &[f64], power: &[f64], rho: f64, tau: f64) -> Vec<f64> {
    temp.iter().zip(power).map(|(t, p)| t - rho * (-p / tau).exp_m1()).collect()
}

/// The rises tried for the die's rise a thermal lag carries ([`missed_die_rise`]) [°C].
pub const MISSED_RISE_GRID_C: [f64; 7] = [0.15, 0.3, 0.6, 1.0, 1.5, 2.2, 3.0];

/// The die's rise at each power-on that the thermistor misses, as REAL's thermal lag shows it
/// (ρ, [°C]), or `None` where there is none to see; `ctxs` are the accelerometers' contexts
/// (their [`Context::lag_rise_c`] is left at 0). SIM's die heats at once after power-on, and
/// SIM's sensitivity, fitted against SIM's reading, holds that heating; REAL's die starts cold
/// and reaches it only through its lag, while the thermistor, mostly on the case, reads a part
/// of it. Behind REAL's reading `T` the die is then `lag_τ(T) − ρ·e^(−P/τ)`: with a thermistor
/// a share `a` of the way to a die of lag τ₀ that heats by `H`, exactly `τ = (1 − a)·τ₀` and
/// `ρ = (1 − a)·H` (docs/diagnosis.md, section 3).
///
/// ρ is the unit's, one for all accelerometers, and the die it describes is the one SIM's
/// sensitivity acts on, so the lag's gain is 1: each accelerometer's residual is fitted with its
/// nuisance, a free warm-up `A·e^(−P/τ_w)` (τ_w on every other point of the turn-on grid, or
/// none, counted as two parameters by BIC) and the lag at gain 1 for each τ of its grid and each
/// ρ of [`MISSED_RISE_GRID_C`] (and 0), under the random walk its static runs show at averaging
/// times up to a minute; ρ minimises the deviance summed over the accelerometers. The warm-up
/// beside keeps the rise from standing in for a turn-on transient of another time constant or
/// of sizes SIM's sensitivity does not give (a rise acts on each accelerometer as `ρ·S'(T)`).
/// Taken when it cuts the deviance of the lag without it by more than a χ²₁ at the
/// diagnosis's level ([`super::fit::ALPHA`] over mechanisms × accelerometers). `None` without
/// `power_s`, with no lag possible, where no power-on falls in the record, or where SIM does
/// not depend on the temperature (a lag's gain is then free).
pub fn missed_die_rise(p: &Prepared, ctxs: &mut [Context]) -> Option<f64> {
    let power = p.power.as_deref()?;
    if !ctxs.first()?.available(Mech::ThermalLag) {
        return None;
    }
    let grid = ctxs[0].grid(Mech::ThermalLag);
    // A rise is seen only after a power-on in the record.
    let longest = grid.last().copied()?;
    if power.iter().all(|pw| (-pw / longest).exp() < 1e-3) {
        return None;
    }
    let rises: Vec<f64> = std::iter::once(0.0).chain(MISSED_RISE_GRID_C).collect();
    let runs = p.static_runs();
    let n = p.t.len() as f64;
    let mut total = vec![0.0; rises.len()];
    // Only through SIM's own sensitivity is the lag's gain 1.
    for (axis, ctx) in ctxs.iter_mut().enumerate().filter(|(_, c)| c.s.from_sim) {
        let segs: Vec<&[f64]> = runs.iter().map(|&(a, b)| &p.r[axis][a..b]).collect();
        let q = super::noise::short_tau_q(&segs, p.dt).map_or(0.0, |(q, _)| q.max(0.0));
        let filt = super::noise::Filter::new(&p.t, &p.r_white[axis], q, None, |_| true);
        // The nuisance with no warm-up, then with one at each τ_w, and what each costs.
        let beside: Vec<(super::fit::PartialLs, f64, f64)> = std::iter::once(None)
            .chain(ctx.grid(Mech::Warmup).into_iter().step_by(2).map(Some))
            .filter_map(|tau_w| {
                let mut fixed = ctx.nuisance.clone();
                if let Some(tw) = tau_w {
                    fixed.push(power.iter().map(|pw| (-pw / tw).exp()).collect());
                }
                let part = super::fit::PartialLs::new(&filt, &p.r[axis], &fixed);
                let (s0, _) = part.sse_coef_plus_whitened(&[])?;
                Some((part, s0, if tau_w.is_some() { 2.0 * n.ln() } else { 0.0 }))
            })
            .collect();
        for (k, &rho) in rises.iter().enumerate() {
            ctx.lag_rise_c = rho;
            let mut best = beside.iter().map(|b| n * b.1.max(1e-300).ln() + b.2).fold(f64::INFINITY, f64::min);
            for &tau in &grid {
                // The lag through SIM's sensitivity is one column.
                let Some(column) = ctx.columns(Mech::ThermalLag, tau).into_iter().next() else { continue };
                let lag = [filt.whitened(&column)];
                for (part, s0, penalty) in &beside {
                    let Some((s_min, coef)) = part.sse_coef_plus_whitened(&lag) else { continue };
                    let b = coef.last().copied().unwrap_or(0.0);
                    if b.abs() > 1e-9 {
                        // At gain 1 what the lag leaves grows from its best as (b − 1)².
                        let sse = s_min + (b - 1.0).powi(2) * (s0 - s_min).max(0.0) / (b * b);
                        best = best.min(n * sse.max(1e-300).ln() + penalty);
                    }
                }
            }
            total[k] += best;
        }
    }
    for ctx in ctxs.iter_mut() {
        ctx.lag_rise_c = 0.0;
    }
    let k = (0..rises.len()).min_by(|&a, &b| total[a].total_cmp(&total[b]))?;
    let needed = super::stats::chi2_isf(super::fit::ALPHA / (Mech::ALL.len() * 3) as f64, 1.0);
    (k > 0 && total[0] - total[k] > needed).then_some(rises[k])
}

/// A die rise is taken when at the die's temperature SIM's sensitivity leaves at most this
/// share of what it leaves at the thermistor's ([`die_rise`]).
pub const DIE_RISE_MAX_LEFT: f64 = 0.5;

/// A die rise is taken only when at least this share of its column's spread (`S'(T)·(1 −
/// e^(−P/τ))`, information-weighted over the accelerometers) is its own, not the polynomial's
/// in the temperature ([`die_rise`]). On a soak the thermistor's reading is itself the rise's
/// shape: user-profile single draw 65094 (a soak) kept 0.23 % of it and its rise came out at
/// 0.89 °C for the generator's 0.10 °C; over 200 profiles (seed base 85001) three more rises
/// fell below this line, two of them 36 % and 129 % off.
pub const DIE_RISE_MIN_OWN: f64 = 0.005;

/// The die's rise over the thermistor after each power-on that SIM shows: SIM is the unit's
/// model at its die's temperature, so when SIM's output is not one function of the
/// thermistor's reading but is one of `T + A·(1 − e^(−P/τ))`, the die runs that much ahead of
/// the thermistor after each power-on, and REAL's die does the same. `A` and `τ` are fitted
/// to SIM's departure on all accelerometers at once (τ on the turn-on grid, refined by golden
/// section, minimising the summed log of what SIM's sensitivity leaves; `A` by linearising
/// SIM's sensitivity about the temperature, twice, each accelerometer's estimate weighted by
/// its information, so an accelerometer SIM's polynomial does not fit well counts little) and the rise is
/// taken when at the die's temperature SIM's sensitivity leaves at most
/// [`DIE_RISE_MAX_LEFT`] of what it leaves at the thermistor's and the rise's column is not
/// the polynomial's ([`DIE_RISE_MIN_OWN`]). `None` without `power_s`,
/// when SIM does not depend on the temperature, or when the rise explains less: a SIM driven
/// by the thermistor's own reading (or a soak, where the rise is the temperature's own shape
/// and the polynomial absorbs it) has none.
pub fn die_rise(p: &Prepared) -> Option<DieRise> {
    let power = p.power.as_deref()?;
    let temp = &p.sim_temp_s;
    let (pmin, pmax) = power.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
    let mut axes = Vec::new();
    for axis in 0..3 {
        let Some(design) = SimDesign::new(p, axis, temp) else { continue };
        let Some(fit) = design.fit(p, axis, temp, None) else { continue };
        if fit.sse > 0.0 {
            axes.push((axis, design, fit));
        }
    }
    if axes.is_empty() {
        return None;
    }
    let at = |amp: f64, tau: f64| die_temperature(temp, power, amp, tau);
    // Linearised about the temperature `base` (the die at `amp0`): each accelerometer's
    // amplitude `a_i` with its information `E_i / SSE_i` (`E_i` what the column adds beyond the
    // polynomial, per unit amplitude squared), the common amplitude weighted by it, and the
    // sum over accelerometers of the log of what SIM's sensitivity then leaves, relative to
    // what it leaves at the thermistor's temperature.
    let linearised = |amp0: f64, tau: f64| -> Option<(f64, f64, f64)> {
        let base = at(amp0, tau);
        let g: Vec<f64> = power.iter().map(|p| -(-p / tau).exp_m1()).collect();
        let (mut num, mut den, mut own, mut parts) = (0.0, 0.0, 0.0, Vec::new());
        for (axis, design, fit0) in &axes {
            let without = design.fit(p, *axis, &base, None)?;
            let col: Vec<f64> = (0..p.t.len()).map(|k| without.s.deriv(base[k], &p.f[k]) * g[k]).collect();
            let with = design.fit(p, *axis, &base, Some(&col))?;
            let a = with.extra_coef;
            let energy = if a != 0.0 { ((without.sse - with.sse) / (a * a)).max(0.0) } else { 0.0 };
            let info = energy / with.sse.max(1e-30 * fit0.sse);
            let mean = col.iter().sum::<f64>() / col.len() as f64;
            let spread = col.iter().map(|v| (v - mean).powi(2)).sum::<f64>();
            num += info * a;
            den += info;
            own += info * if spread > 0.0 { energy / spread } else { 0.0 };
            parts.push((with.sse, a, energy, fit0.sse));
        }
        if !(den > 0.0) {
            return None;
        }
        let da = num / den;
        let j = parts.iter().map(|(sse, a, e, sse0)| ((sse + (da - a).powi(2) * e) / sse0).ln()).sum::<f64>();
        Some((amp0 + da, j, own / den))
    };
    let lo = (3.0 * p.dt).max(1.0);
    let hi = 0.5 * pmax;
    if !(hi > lo) {
        return None;
    }
    let varies = |tau: f64| (-pmin / tau).exp() - (-pmax / tau).exp() >= TURN_ON_MIN_RANGE;
    let steps = ((hi / lo).log10() * GRID_PER_DECADE).ceil().max(1.0) as usize;
    let grid: Vec<f64> =
        (0..=steps).map(|k| lo * (hi / lo).powf(k as f64 / steps as f64)).filter(|&t| varies(t)).collect();
    let score = |tau: f64| linearised(0.0, tau).map_or(f64::INFINITY, |(_, j, _)| j);
    let scores: Vec<f64> = grid.iter().map(|&t| score(t)).collect();
    let best = (0..grid.len()).filter(|&k| scores[k].is_finite()).min_by(|&a, &b| scores[a].total_cmp(&scores[b]))?;
    // Golden section in ln τ between the best point's neighbours.
    let (ln_tau, f) = super::stats::golden_min(
        grid[best.saturating_sub(1)].ln(),
        grid[(best + 1).min(grid.len() - 1)].ln(),
        12,
        |x| score(x.exp()),
    );
    let tau = if f < scores[best] { ln_tau.exp() } else { grid[best] };
    // The amplitude, linearised twice (the second time about the die found the first).
    let (amp1, _, own) = linearised(0.0, tau)?;
    let (amp, _, _) = linearised(amp1, tau)?;
    if !(own >= DIE_RISE_MIN_OWN && amp.is_finite() && amp.abs() <= 20.0) {
        return None;
    }
    // Exact sums of squares at the thermistor's temperature and at the die's.
    let die = at(amp, tau);
    let mut ln_left = 0.0;
    for (axis, design, fit0) in &axes {
        ln_left += design.fit(p, *axis, &die, None).map_or(f64::INFINITY, |f| (f.sse / fit0.sse).ln());
    }
    let left = (ln_left / axes.len() as f64).exp();
    (left <= DIE_RISE_MAX_LEFT).then_some(DieRise { amp_c: amp, tau_s: tau, sim_left_share: left })
}

/// First-order lag of the temperature with time constant `tau`, exact for an input that is
/// linear between samples (first-order hold); starts in equilibrium. Over a recording of
/// several sessions it runs on through the joins: the unpowered unit's parts go on following
/// the chamber, taken to have gone straight from the last reading to the next
/// (docs/recording-format.md, "Sessions").
pub fn lagged(t: &[f64], temp: &[f64], tau: f64) -> Vec<f64> {
    let mut out = Vec::with_capacity(temp.len());
    let mut x = temp.first().copied().unwrap_or(0.0);
    // e^(−h/τ) of the last step length (the same for every step of a regular recording).
    let (mut last_h, mut last_e) = (f64::NAN, 0.0);
    for k in 0..temp.len() {
        if k > 0 {
            let h = (t[k] - t[k - 1]).max(0.0);
            if h > 0.0 {
                // u(s) = u0 + g·s: x(h) = u1 − gτ + (x − u0 + gτ)·e^(−h/τ).
                let g = (temp[k] - temp[k - 1]) / h;
                if h != last_h {
                    (last_h, last_e) = (h, (-h / tau).exp());
                }
                let e = last_e;
                x = temp[k] - g * tau + (x - temp[k - 1] + g * tau) * e;
            }
        }
        out.push(x);
    }
    out
}

/// The bias polynomial's columns `ΔTᵉ` for the orders `e` given, `ΔT = T − 20 °C` from the
/// temperature `temp` (one value a row).
pub fn bias_powers(temp: &[f64], orders: &[i32]) -> Vec<Vec<f64>> {
    orders.iter().map(|&e| temp.iter().map(|t| (t - T0_C).powi(e)).collect()).collect()
}

/// Play (backlash) operator of width `h`, starting at the first temperature. Over a recording
/// of several sessions it runs on through the joins: a play is a position, which the unpowered
/// time does not relax, and the temperature between two sessions is taken to have gone straight
/// from the last reading to the next (docs/recording-format.md, "Sessions").
pub fn play(temp: &[f64], h: f64) -> Vec<f64> {
    let mut e = temp.first().copied().unwrap_or(0.0);
    temp.iter()
        .map(|&x| {
            e = e.clamp(x - 0.5 * h, x + 0.5 * h);
            e
        })
        .collect()
}

/// The state of a lag or play `m` of time constant or width `theta` over `temp` at the times
/// `t`: the lagged temperature ([`lagged`]) for a thermal lag, the play's position ([`play`])
/// for a thermal or an additive bias play; `temp` itself for any other mechanism.
pub fn state_of(m: Mech, t: &[f64], temp: &[f64], theta: f64) -> Vec<f64> {
    match m {
        Mech::ThermalLag => lagged(t, temp, theta),
        Mech::ThermalHysteresis | Mech::BiasHysteresis => play(temp, theta),
        _ => temp.to_vec(),
    }
}

/// `f` applied to each session's rows ([`Prepared::sessions`]) and the results joined: a lag or
/// play started afresh at each session, the rival
/// ([`super::separate::Refit::other_state_across_sessions`]) of the state the library carries
/// through the unrecorded time ([`lagged`], [`play`]).
pub fn by_session(p: &Prepared, f: impl Fn(std::ops::Range<usize>) -> Vec<f64>) -> Vec<f64> {
    let sessions = p.sessions();
    if sessions.len() == 1 {
        return f(0..p.t.len());
    }
    let mut out = Vec::with_capacity(p.t.len());
    for r in sessions {
        out.extend(f(r));
    }
    out
}

/// The largest share of the centred energy of the column `c` (one value per row) that falls
/// in one held-out fold (`fold[i]`: row `i`'s fold); 1 for a constant column.
pub fn max_fold_share(c: impl Iterator<Item = f64> + Clone, fold: &[usize]) -> f64 {
    let (s, n) = c.clone().fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    let mean = s / n.max(1) as f64;
    let mut e = [0.0; super::fit::FOLDS];
    for (v, &k) in c.zip(fold) {
        e[k] += (v - mean) * (v - mean);
    }
    let total: f64 = e.iter().sum();
    if !(total > 0.0) {
        return 1.0;
    }
    e.iter().fold(0.0, |a: f64, &b| a.max(b)) / total
}

/// The shortest τ \[s\] at which `e^(−P/τ)` has at most [`TURN_ON_MAX_FOLD_SHARE`] of its
/// centred energy in one held-out fold, by bisection in log τ (the share falls as τ grows and
/// the signature spreads over more blocks); ∞ without `power_s` or when no τ up to 100× the
/// longest `power_s` qualifies.
fn turn_on_min_tau_s(p: &Prepared) -> f64 {
    let Some(pw) = p.power.as_deref() else { return f64::INFINITY };
    let pmax = pw.iter().fold(0.0, |a: f64, &b| a.max(b));
    let fold = super::fit::folds_of(pw.len());
    let ok = |tau: f64| max_fold_share(pw.iter().map(|v| (-v / tau).exp()), &fold) <= TURN_ON_MAX_FOLD_SHARE;
    let (mut lo, mut hi) = ((0.1 * p.dt).max(1e-6).ln(), (100.0 * pmax).max(1.0).ln());
    if !ok(hi.exp()) {
        return f64::INFINITY;
    }
    if ok(lo.exp()) {
        return lo.exp();
    }
    for _ in 0..30 {
        let mid = 0.5 * (lo + hi);
        if ok(mid.exp()) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    hi.exp()
}

/// What the columns of a mechanism are built from, per accelerometer.
pub struct Context<'a> {
    /// The data.
    pub p: &'a Prepared,
    /// Accelerometer index.
    pub axis: usize,
    /// SIM's temperature sensitivity.
    pub s: Sensitivity,
    /// V(2) unit columns: asymmetry, k2, k3, m31, m32.
    pub v2: [Vec<f64>; 5],
    /// Temperature range [°C].
    pub temp_range: f64,
    /// `S(T, f)` at every row.
    pub s_now: Vec<f64>,
    /// SIM's own temperature terms, re-fitted in every model (empty unless SIM was fitted to
    /// this very recording: see [`sim_fitted_forms`]).
    pub nuisance: Vec<Vec<f64>>,
    /// The powers of ΔT whose bias term is in [`Context::nuisance`] (those orders are then
    /// not "of higher order than simulated").
    pub nuisance_orders: Vec<i32>,
    /// What the nuisance is, for the report.
    pub nuisance_names: Vec<String>,
    /// The recording's `power_s` range \[s\] (`(∞, −∞)` without `power_s`).
    pub power_range_s: (f64, f64),
    /// The shortest turn-on τ \[s\] whose `e^(−P/τ)` has at most [`TURN_ON_MAX_FOLD_SHARE`] of
    /// its centred energy in one held-out fold (∞ when none has): see [`Context::offered`].
    pub turn_on_min_tau_s: f64,
    /// The sensor's bias instability beside the random walk in the noise model, where it is
    /// known ([`super::Options::bias_instability`]); `None`: white + random walk alone.
    pub gm: Option<super::noise::Gm>,
    /// The die's rise at each power-on that the thermistor misses, as a thermal lag carries it
    /// ([`missed_die_rise`], [`Prepared::lag_rise_c`]) [°C]; 0: none.
    pub lag_rise_c: f64,
}

/// SIM's own calibration forms `b_j(f)·ΔTᵖ` (`b` = 1, f_x, f_y, f_z; p = 1…3; ΔT from the
/// raw `temp_C`, as a calibration uses it) that REAL − SIM is orthogonal to: |corr|·√n below
/// 0.01, where an independent residual gives about 1. Two or more such forms mean SIM is a
/// least-squares calibration of this very recording: its coefficients absorbed whatever the
/// residual had along them, so a mechanism that is tested without re-fitting them is tested
/// against a residual with a hole in it (and "bias of higher order than simulated" would only
/// be the calibration re-adjusting itself). Returns the independent forms (collinear
/// duplicates dropped) with their names and bias orders; empty when SIM is an independent
/// prediction.
pub fn sim_fitted_forms(p: &Prepared, axis: usize) -> (Vec<Vec<f64>>, Vec<String>, Vec<i32>) {
    let n = p.t.len();
    let y = &p.r[axis];
    if n < 50 {
        return Default::default();
    }
    let centred = |v: &[f64]| -> Vec<f64> {
        let m = v.iter().sum::<f64>() / n as f64;
        v.iter().map(|x| x - m).collect()
    };
    let yc = centred(y);
    let yy = yc.iter().map(|v| v * v).sum::<f64>();
    if !(yy > 0.0) {
        return Default::default();
    }
    let names = ["", "·f_x", "·f_y", "·f_z"];
    let (mut cols, mut labels, mut orders): (Vec<Vec<f64>>, Vec<String>, Vec<i32>) = Default::default();
    let mut kept_centred: Vec<Vec<f64>> = Vec::new();
    for pw in 1..=3i32 {
        for j in 0..4 {
            let c: Vec<f64> = (0..n)
                .map(|k| {
                    let b = if j == 0 { 1.0 } else { p.f[k][j - 1] };
                    b * (p.temp[k] - T0_C).powi(pw)
                })
                .collect();
            let cc = centred(&c);
            let c2 = cc.iter().map(|v| v * v).sum::<f64>();
            if !(c2 > 1e-12 * n as f64) {
                continue;
            }
            let z = cc.iter().zip(&yc).map(|(a, b)| a * b).sum::<f64>() / (c2 * yy).sqrt() * (n as f64).sqrt();
            if !(z.abs() < 0.01) {
                continue;
            }
            // Not a duplicate of a form already kept (one orientation: f_z·ΔT = −ΔT).
            let (sse, _) = ls_sse(&cc, &kept_centred);
            if !(sse > 1e-8 * c2) {
                continue;
            }
            kept_centred.push(cc);
            cols.push(c);
            labels.push(format!("ΔT^{pw}{}", names[j]));
            if j == 0 {
                orders.push(pw);
            }
        }
    }
    if cols.len() < 2 {
        return Default::default();
    }
    (cols, labels, orders)
}

impl<'a> Context<'a> {
    /// Builds the context of accelerometer `axis`.
    pub fn new(p: &'a Prepared, axis: usize) -> Self {
        let s = fit_sensitivity(p, axis);
        let (tmin, tmax) = p.temp_s.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
        let s_now = (0..p.t.len()).map(|k| s.eval(p.temp_s[k], &p.f[k])).collect();
        let (mut nuisance, nuisance_names, nuisance_orders) = sim_fitted_forms(p, axis);
        // A level of its own for every session after the first (the noise model's level
        // restarts there); not SIM's terms, so not named among them.
        nuisance.extend(p.session_columns());
        Context {
            p,
            axis,
            v2: v2_columns(p, axis),
            s,
            temp_range: tmax - tmin,
            s_now,
            nuisance,
            nuisance_orders,
            nuisance_names,
            power_range_s: p
                .power
                .as_deref()
                .unwrap_or(&[])
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v))),
            turn_on_min_tau_s: turn_on_min_tau_s(p),
            gm: None,
            lag_rise_c: p.lag_rise_c,
        }
    }

    /// Whether the mechanism can be tried on this data at all.
    pub fn available(&self, m: Mech) -> bool {
        let thermal = self.temp_range > 0.5;
        // A term in f_j is indistinguishable from a bias term when f_j never changes.
        let varies = |j: usize| self.p.f.iter().any(|f| (f[j] - self.p.f[0][j]).abs() > 1e-6);
        let (i, j, k) = (self.axis, (self.axis + 1) % 3, (self.axis + 2) % 3);
        match m {
            Mech::ThermalLag | Mech::ThermalHysteresis | Mech::BiasHysteresis => thermal,
            Mech::BiasTempOrder => thermal && self.nuisance_orders.len() < 3,
            Mech::ScaleTemp => thermal && varies(i),
            Mech::CrossCouplingTemp => thermal && (varies(j) || varies(k)),
            Mech::CrossAxis => varies(j) || varies(k),
            Mech::ScaleFactor => varies(i),
            Mech::SelfHeating | Mech::Warmup => self.p.power.is_some() && !self.grid(m).is_empty(),
            Mech::Drift => self.p.t.len() >= 50,
            // Rectification needs vibration: on static rows `a3·a1` is a product of the
            // reference alone, which the static terms and the temperature forms already span.
            Mech::VibrationCross => self.p.vib.iter().any(|v| !matches!(v, Vibration::None)),
            _ => true,
        }
    }

    /// Whether the mechanism's columns exist on this design, to be tried as a rival
    /// ([`super::separate`]): every mechanism the search offers, and those it does not offer
    /// because this design makes them another's alias (a term in `f_j` that never changes, a
    /// thermal term over less than the search's temperature range); not a turn-on term without
    /// `power_s`, nor a vibration term on rows without vibration.
    pub fn rival_possible(&self, m: Mech) -> bool {
        match m {
            Mech::SelfHeating | Mech::Warmup | Mech::VibrationCross | Mech::Drift => self.available(m),
            _ => true,
        }
    }

    /// The grid of θ for a nonlinear mechanism (empty for linear ones), log-spaced,
    /// [`GRID_PER_DECADE`] points a decade. A turn-on term keeps only the time constants whose
    /// signature varies over the recording ([`TURN_ON_MIN_RANGE`]): far from power-on
    /// `1 − e^(−P/τ)` is constant (a short τ) or a slow ramp in time (a τ far beyond the
    /// recording), and the term would only be a constant or a drift under another name.
    pub fn grid(&self, m: Mech) -> Vec<f64> {
        let g = self.grid_span(m);
        match m {
            Mech::SelfHeating | Mech::Warmup => g.into_iter().filter(|&tau| self.offered(m, tau)).collect(),
            _ => g,
        }
    }

    /// Whether mechanism `m` is offered at `theta`: a turn-on term (`warmup`, `self_heating`)
    /// only where `e^(−P/τ)` on the first row is at least [`TURN_ON_MIN_TAIL`], changes over
    /// the recording by at least [`TURN_ON_MIN_RANGE`] (of that level for a warm-up, of the
    /// rise for a self-heating), and has at most [`TURN_ON_MAX_FOLD_SHARE`] of its centred
    /// energy in one held-out fold; every other mechanism at every θ.
    pub fn offered(&self, m: Mech, theta: f64) -> bool {
        if !matches!(m, Mech::SelfHeating | Mech::Warmup) {
            return true;
        }
        let (pmin, pmax) = self.power_range_s;
        let (first, last) = ((-pmin / theta).exp(), (-pmax / theta).exp());
        // A self-heating's column `S'·(1 − e^(−P/τ))` is SIM's sensitivity times a constant
        // where `e^(−P/τ)` has died out: only its change counts, as a share of the rise.
        let level = if m == Mech::Warmup { first } else { 1.0 };
        first >= TURN_ON_MIN_TAIL && first - last >= TURN_ON_MIN_RANGE * level && theta >= self.turn_on_min_tau_s
    }

    /// The shortest time constant a lag or turn-on grid holds \[s\]: three samples, and 1 s.
    pub fn shortest_tau_s(&self) -> f64 {
        (3.0 * self.p.dt).max(1.0)
    }

    fn grid_span(&self, m: Mech) -> Vec<f64> {
        let p = self.p;
        let dur = p.t.last().copied().unwrap_or(0.0) - p.t.first().copied().unwrap_or(0.0);
        let (lo, hi) = match m {
            Mech::ThermalLag => (self.shortest_tau_s(), 0.25 * dur),
            Mech::ThermalHysteresis | Mech::BiasHysteresis => (0.02, 0.5 * self.temp_range),
            Mech::Drift => (dur / 30.0, 3.0 * dur),
            Mech::SelfHeating | Mech::Warmup => {
                let pmax = p.power.as_ref().map_or(0.0, |v| v.iter().fold(0.0, |a: f64, &b| a.max(b)));
                (self.shortest_tau_s(), 0.5 * pmax)
            }
            _ => return Vec::new(),
        };
        if !(hi > lo) {
            return Vec::new();
        }
        let n = ((hi / lo).log10() * GRID_PER_DECADE).ceil().max(1.0) as usize;
        (0..=n).map(|k| lo * (hi / lo).powf(k as f64 / n as f64)).collect()
    }

    /// The columns of mechanism `m` at `theta` (ignored for linear mechanisms).
    pub fn columns(&self, m: Mech, theta: f64) -> Vec<Vec<f64>> {
        self.columns_at(m, theta, &self.p.temp_s)
    }

    /// The columns of a fitted member: [`Context::columns`], and for a warm-up fitted with its
    /// fast part (`fast`: the ratio R, one of [`WARMUP_FAST_RATIOS`]) the second exponential
    /// `e^(−R·P/τ)` beside `e^(−P/τ)`, where `τ/R` is at least the turn-on grid's shortest
    /// time constant (`shortest_tau_s`: three samples, and 1 s). The fast part is not held to the turn-on rules
    /// of [`Context::offered`]: beside the slow part it is kept only where it lowers the raw
    /// held-out RMS, which a column whose signature lives in one held-out fold cannot do. The
    /// search and the names use one exponential; a named warm-up's shape is then given its
    /// fast part where the data ask for it ([`super::fit::fit_axis`]).
    pub fn member_columns(&self, m: Mech, theta: f64, fast: Option<f64>) -> Vec<Vec<f64>> {
        let mut cols = self.columns(m, theta);
        let Some(ratio) = fast else { return cols };
        let fast_tau = theta / ratio;
        if m == Mech::Warmup && fast_tau >= self.shortest_tau_s() {
            let pw = self.p.power.as_deref().unwrap_or(&[]);
            cols.push(pw.iter().map(|v| (-v / fast_tau).exp()).collect());
        }
        cols
    }

    /// The columns of a lag or play `m` (width or time constant `theta`) whose state, the
    /// effective temperature `te`, is given beside the temperature `temp` it follows (one value
    /// a row each): `S(Tₑ, f) − S(T, f)` through SIM's sensitivity for a thermal lag or play
    /// (docs/diagnosis.md, section 3), and for the additive bias play its displacement
    /// `d = (Tₑ − T)/(w/2)` and `d·ΔT`. [`Context::columns_at`] gives the state the library
    /// carries; the rival restarted at each session
    /// ([`super::separate::Refit::other_state_across_sessions`]) gives its own. Empty for any
    /// other mechanism.
    pub fn state_columns(&self, m: Mech, theta: f64, te: &[f64], temp: &[f64]) -> Vec<Vec<f64>> {
        let p = self.p;
        let n = p.t.len();
        let s_now = |r: usize| {
            if std::ptr::eq(temp, p.temp_s.as_slice()) { self.s_now[r] } else { self.s.eval(temp[r], &p.f[r]) }
        };
        match m {
            Mech::ThermalLag | Mech::ThermalHysteresis => {
                vec![(0..n).map(|r| self.s.eval(te[r], &p.f[r]) - s_now(r)).collect()]
            }
            Mech::BiasHysteresis => {
                let d: Vec<f64> = (0..n).map(|r| (te[r] - temp[r]) / (0.5 * theta)).collect();
                vec![d.clone(), (0..n).map(|r| d[r] * (temp[r] - T0_C)).collect()]
            }
            _ => Vec::new(),
        }
    }

    /// The state `te` of a lag or play `m` ([`state_of`]) with, for a thermal lag of time
    /// constant `theta`, the die's rise at each power-on that the thermistor misses
    /// ([`Context::lag_rise_c`], ρ): `te − ρ·e^(−P/τ)`. REAL's die, started cold at a power-on,
    /// reaches the heating SIM's die has at once (and SIM's sensitivity, fitted against SIM's
    /// reading, holds) only through the lag; the thermistor reads a part of it. `te` as given
    /// for a play, without `power_s`, or where ρ is 0.
    pub fn with_missed_rise(&self, m: Mech, theta: f64, mut te: Vec<f64>) -> Vec<f64> {
        if m == Mech::ThermalLag
            && self.lag_rise_c > 0.0
            && let Some(power) = self.p.power.as_deref()
        {
            for (x, pw) in te.iter_mut().zip(power) {
                *x -= self.lag_rise_c * (-pw / theta).exp();
            }
        }
        te
    }

    /// [`Context::columns`] with the temperature the thermal and temperature terms are built
    /// from given (one value a row; [`Context::columns`] gives the smoothed `temp_C`): a rival
    /// acting on a die warmer than the thermistor ([`super::separate`]).
    pub fn columns_at(&self, m: Mech, theta: f64, temp: &[f64]) -> Vec<Vec<f64>> {
        let p = self.p;
        let n = p.t.len();
        let i = self.axis;
        let (j, k) = ((i + 1) % 3, (i + 2) % 3);
        let dtc = |r: usize| temp[r] - T0_C;
        match m {
            Mech::ThermalLag | Mech::ThermalHysteresis | Mech::BiasHysteresis => {
                let te = self.with_missed_rise(m, theta, state_of(m, &p.t, temp, theta));
                self.state_columns(m, theta, &te, temp)
            }
            Mech::SelfHeating => {
                let pw = p.power.as_deref().unwrap_or(&[]);
                vec![(0..n).map(|r| self.s.deriv(temp[r], &p.f[r]) * -(-pw[r] / theta).exp_m1()).collect()]
            }
            Mech::Warmup => {
                let pw = p.power.as_deref().unwrap_or(&[]);
                vec![(0..n).map(|r| (-pw[r] / theta).exp()).collect()]
            }
            Mech::BiasTempOrder => {
                let orders: Vec<i32> = (1..=3).filter(|e| !self.nuisance_orders.contains(e)).collect();
                bias_powers(temp, &orders)
            }
            Mech::ScaleTemp => (1..=2).map(|e| (0..n).map(|r| p.f[r][i] * dtc(r).powi(e)).collect()).collect(),
            Mech::CrossCouplingTemp => [(j, 1), (k, 1), (j, 2), (k, 2)]
                .iter()
                .map(|&(c, e)| (0..n).map(|r| p.f[r][c] * dtc(r).powi(e)).collect())
                .collect(),
            Mech::CrossAxis => [j, k].iter().map(|&c| (0..n).map(|r| p.f[r][c]).collect()).collect(),
            Mech::ScaleFactor => vec![(0..n).map(|r| p.f[r][i]).collect()],
            Mech::SfAsymmetry => vec![self.v2[0].clone()],
            Mech::NonlinearityK2 => vec![self.v2[1].clone()],
            Mech::NonlinearityK3 => vec![self.v2[2].clone()],
            Mech::VibrationCross => vec![self.v2[3].clone(), self.v2[4].clone()],
            Mech::Drift => {
                let t0 = p.t.first().copied().unwrap_or(0.0);
                vec![p.t.iter().map(|t| (-(t - t0) / theta).exp()).collect()]
            }
        }
    }
}
