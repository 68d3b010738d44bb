//! Concealed-effect cases for the proof suite: a small generator of SIM/REAL pairs written in
//! terms of the core's formulas (T(1) constants through the core's temperature model T(3),
//! the conversion function V(2) through the core's `eval_g`) with the vibration rectified by
//! direct averaging over the vibration (phase grid for sine, quadrature against the normal
//! density for random), independent of the closed-form VE the diagnosis uses.
//!
//! SIM is the unit as simulated (constants follow the thermistor's temperature, no noise);
//! REAL adds the case's concealed effects and the noise (white, random walk, optionally a
//! Gauss–Markov bias instability). Each case states what an exact diagnosis finds.

use super::mech::{Mech, T0_C};
use crate::recording::Row;
use bins_comp::model::Constants;
use bins_comp::temperature::{CoefDelta, TempModel};
use bins_comp::vibration::{AccelAxes, Axis, ConversionFunction, Vibration};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// One position of the rig program.
#[derive(Clone, Debug)]
pub struct Hold {
    /// Duration \[s\].
    pub dur_s: f64,
    /// Static specific force \[g\].
    pub f_g: [f64; 3],
    /// Vibration.
    pub vib: Vibration<f64>,
    /// Label.
    pub pos: String,
}

/// The test: rig program (repeated), chamber profile, power-on times.
#[derive(Clone, Debug)]
pub struct Plan {
    /// Sample period \[s\].
    pub dt_s: f64,
    /// Rows.
    pub rows: usize,
    /// Rig program, repeated until the end.
    pub holds: Vec<Hold>,
    /// Chamber (= unit case) temperature knots `(t_s, °C)`, linear between, held outside.
    pub chamber: Vec<(f64, f64)>,
    /// Times the unit is powered on \[s\]; the first should be ≤ 0.
    pub power_on_s: Vec<f64>,
}

/// REAL's noise.
#[derive(Clone, Copy, Debug)]
pub struct Noise {
    /// White noise per sample \[g\].
    pub white_g: f64,
    /// Random walk [g/√s].
    pub rw_g_per_sqrt_s: f64,
    /// Gauss–Markov bias instability: σ \[g\] and correlation time \[s\].
    pub gm: Option<(f64, f64)>,
    /// Thermistor noise [°C].
    pub temp_c: f64,
}

impl Default for Noise {
    fn default() -> Self {
        Noise { white_g: 20e-6, rw_g_per_sqrt_s: 0.2e-6, gm: None, temp_c: 0.005 }
    }
}

/// A concealed effect in REAL (coefficients in g units; axis = accelerometer index).
#[derive(Clone, Copy, Debug)]
pub enum Effect {
    /// The constants follow the temperature lagged by τ \[s\].
    ThermalLag(f64),
    /// The constants follow the temperature through a play of width [°C].
    Hysteresis(f64),
    /// The die runs `rise` °C above the case after power-on, time constant τ: (rise, τ).
    SelfHeating(f64, f64),
    /// Bias transient `amp·e^(−P/τ)` on one axis: (axis, amp \[g\], τ \[s\]).
    Warmup(usize, f64, f64),
    /// Extra bias `b1 ΔT + b2 ΔT² + b3 ΔT³` [g/°Cⁿ].
    BiasTemp(usize, [f64; 3]),
    /// Extra scale `s1 ΔT` [1/°C].
    ScaleTemp(usize, f64),
    /// Extra cross-sensitivity to axis j: `c ΔT` [1/°C].
    CrossTemp(usize, usize, f64),
    /// Extra cross-sensitivity to axis j [g/g].
    CrossAxis(usize, usize, f64),
    /// V(2) asymmetry δ_1A.
    Asymmetry(usize, f64),
    /// V(2) k2 [g/g²].
    K2(usize, f64),
    /// V(2) k3 [g/g³].
    K3(usize, f64),
    /// V(2) m31, m32 [g/g²].
    VibCross(usize, f64, f64),
}

/// What an exact diagnosis reports.
#[derive(Clone, Debug, Default)]
pub struct Expected {
    /// Effects and their accelerometers.
    pub effects: Vec<(Mech, Vec<usize>)>,
    /// Ambiguous groups (sorted ids) and their accelerometers.
    pub ambiguous: Vec<(Vec<Mech>, Vec<usize>)>,
    /// True parameters: mechanism, accelerometer, report name, value.
    pub params: Vec<(Mech, usize, &'static str, f64)>,
}

/// A case of the suite.
#[derive(Clone, Debug)]
pub struct Case {
    /// Name.
    pub name: &'static str,
    /// What is concealed and how.
    pub description: &'static str,
    /// The test.
    pub plan: Plan,
    /// REAL's noise.
    pub noise: Noise,
    /// REAL's concealed effects.
    pub effects: Vec<Effect>,
    /// Seed.
    pub seed: u64,
    /// What an exact diagnosis reports.
    pub expected: Expected,
}

/// The simulated unit: the paper's constants at +20 °C (Tables T1/T2), a second-order
/// temperature model, the AL-15 conversion function on every axis.
pub fn base_unit() -> (Constants<f64>, TempModel<f64>, ConversionFunction<f64>) {
    let k = [
        [-0.55060863, -0.00051742, 0.01639328],
        [-0.01322881, -0.54854890, -0.00066841],
        [-0.01466957, -0.00035441, -0.54859224],
    ];
    let u0 = [0.00449084, -0.00442299, -0.00347099];
    let c1 = CoefDelta {
        du0_v: [-1.0e-4, -0.8e-4, 0.7e-4],
        rel_k: [[3.0e-5, 4e-4, 2e-4], [6e-4, 2.5e-5, -1e-3], [3e-4, 1e-3, 4.0e-5]],
    };
    let c2 =
        CoefDelta { du0_v: [1.5e-6, -1.2e-6, 1.0e-6], rel_k: [[2e-7, 0.0, 0.0], [0.0, 1e-7, 0.0], [0.0, 0.0, 3e-7]] };
    let tm = TempModel::Poly { order: 2, coef: [c1, c2, CoefDelta::zero(), CoefDelta::zero()] };
    let cf = ConversionFunction {
        a0_g: 0.0,
        delta_1a: 15e-6,
        k2_g_per_g2: 105e-6,
        k3_g_per_g3: 87e-6,
        k4_g_per_g4: 10e-6,
        k5_g_per_g5: 0.9e-6,
        m1_g_per_g: 0.0,
        m2_g_per_g: 0.0,
        m31_g_per_g2: 11.6e-6,
        m32_g_per_g2: 11.6e-6,
    };
    (Constants { k_v_per_g: k, u0_v: u0 }, tm, cf)
}

/// V(2) without its linear part, through the core's `eval_g`.
fn nonlinear(cf: &ConversionFunction<f64>, a: AccelAxes<f64>) -> f64 {
    cf.eval_g(a) - (cf.a0_g + a.ia + cf.m1_g_per_g * a.oa + cf.m2_g_per_g * a.pa)
}

/// Time mean of the nonlinear part under the vibration, by direct averaging: 256 phases for
/// sine, trapezoid quadrature on ±9σ (6001 nodes) against the normal density for random.
pub fn rectified(cf: &ConversionFunction<f64>, f: &[f64; 3], vib: &Vibration<f64>, axis: Axis) -> f64 {
    let ap = AccelAxes::from_unit(f, axis);
    let at = |v: &[f64; 3], s: f64| {
        let x = [f[0] + s * v[0], f[1] + s * v[1], f[2] + s * v[2]];
        nonlinear(cf, AccelAxes::from_unit(&x, axis))
    };
    match vib {
        Vibration::None => nonlinear(cf, ap),
        Vibration::Harmonic { amp_g, .. } => {
            let n = 256;
            (0..n).map(|k| at(amp_g, (std::f64::consts::TAU * (k as f64 + 0.37) / n as f64).sin())).sum::<f64>()
                / n as f64
        }
        Vibration::Random { sigma_g, .. } => {
            let n = 6000;
            let h = 18.0 / n as f64;
            let mut s = 0.0;
            for k in 0..=n {
                let x = -9.0 + k as f64 * h;
                let w = if k == 0 || k == n { 0.5 } else { 1.0 };
                s += w * (-0.5 * x * x).exp() * at(sigma_g, x);
            }
            s * h / (2.0 * std::f64::consts::PI).sqrt()
        }
    }
}

/// First-order lag of a piecewise-linear input, integrated with 20 Euler sub-steps per sample
/// (written independently of the diagnosis's exact discretisation).
fn lag_euler(t: &[f64], x: &[f64], tau: f64) -> Vec<f64> {
    let mut y = x.first().copied().unwrap_or(0.0);
    let mut out = Vec::with_capacity(x.len());
    for k in 0..x.len() {
        if k > 0 {
            let h = (t[k] - t[k - 1]) / 20.0;
            for s in 0..20 {
                let u = x[k - 1] + (x[k] - x[k - 1]) * (s as f64 + 0.5) / 20.0;
                y += h * (u - y) / tau;
            }
        }
        out.push(y);
    }
    out
}

/// Backlash of width `h`: the output moves only when the input pushes it from outside ±h/2.
fn backlash(x: &[f64], h: f64) -> Vec<f64> {
    let mut y = x.first().copied().unwrap_or(0.0);
    x.iter()
        .map(|&v| {
            if v > y + 0.5 * h {
                y = v - 0.5 * h;
            } else if v < y - 0.5 * h {
                y = v + 0.5 * h;
            }
            y
        })
        .collect()
}

fn interp(knots: &[(f64, f64)], t: f64) -> f64 {
    match knots.iter().position(|k| k.0 > t) {
        None => knots.last().map_or(T0_C, |k| k.1),
        Some(0) => knots[0].1,
        Some(i) => {
            let (a, b) = (knots[i - 1], knots[i]);
            a.1 + (b.1 - a.1) * (t - a.0) / (b.0 - a.0)
        }
    }
}

/// Generates the case's SIM and REAL recordings.
pub fn generate(case: &Case) -> (Vec<Row>, Vec<Row>) {
    let (c0, tm, cf_sim) = base_unit();
    let plan = &case.plan;
    let n = plan.rows;
    let mut rng = ChaCha8Rng::seed_from_u64(case.seed);
    let nrm = Normal::new(0.0, 1.0).unwrap_or_else(|_| unreachable!());
    let t: Vec<f64> = (0..n).map(|k| k as f64 * plan.dt_s).collect();
    let temp_true: Vec<f64> = t.iter().map(|&x| interp(&plan.chamber, x)).collect();
    let power: Vec<f64> = t
        .iter()
        .map(|&x| {
            let on = plan.power_on_s.iter().copied().filter(|&p| p <= x).fold(f64::NEG_INFINITY, f64::max);
            if on.is_finite() { x - on } else { 0.0 }
        })
        .collect();
    // REAL's effective temperature.
    let mut temp_eff = temp_true.clone();
    let mut cf_real = [cf_sim; 3];
    for e in &case.effects {
        match *e {
            Effect::ThermalLag(tau) => temp_eff = lag_euler(&t, &temp_eff, tau),
            Effect::Hysteresis(h) => temp_eff = backlash(&temp_eff, h),
            Effect::Asymmetry(i, d) => cf_real[i].delta_1a += d,
            Effect::K2(i, k) => cf_real[i].k2_g_per_g2 += k,
            Effect::K3(i, k) => cf_real[i].k3_g_per_g3 += k,
            Effect::VibCross(i, a, b) => {
                cf_real[i].m31_g_per_g2 += a;
                cf_real[i].m32_g_per_g2 += b;
            }
            _ => {}
        }
    }
    for e in &case.effects {
        if let Effect::SelfHeating(rise, tau) = *e {
            for (te, p) in temp_eff.iter_mut().zip(&power) {
                *te += rise * -(-p / tau).exp_m1();
            }
        }
    }
    // Rig program.
    let cycle: f64 = plan.holds.iter().map(|h| h.dur_s).sum();
    let hold_at = |x: f64| {
        let mut s = x % cycle;
        for (i, h) in plan.holds.iter().enumerate() {
            if s < h.dur_s {
                return i;
            }
            s -= h.dur_s;
        }
        plan.holds.len() - 1
    };
    let rect = |cf: &[ConversionFunction<f64>; 3]| -> Vec<[f64; 3]> {
        plan.holds.iter().map(|h| [0, 1, 2].map(|i| rectified(&cf[i], &h.f_g, &h.vib, Axis::ALL[i]))).collect()
    };
    let rect_sim = rect(&[cf_sim; 3]);
    let rect_real = rect(&cf_real);
    let consts_at = |temp: f64, extra: &dyn Fn(&mut Constants<f64>)| {
        let d = tm.delta(temp, T0_C);
        let mut c = c0;
        for i in 0..3 {
            c.u0_v[i] += d.du0_v[i];
            for j in 0..3 {
                c.k_v_per_g[i][j] *= 1.0 + d.rel_k[i][j];
            }
        }
        extra(&mut c);
        c
    };
    let mut rw = [0.0; 3];
    let mut gm = [0.0; 3];
    let mut sim = Vec::with_capacity(n);
    let mut real = Vec::with_capacity(n);
    for k in 0..n {
        let h = hold_at(t[k]);
        let hold = &plan.holds[h];
        let f = hold.f_g;
        let cs = consts_at(temp_true[k], &|_| {});
        let dtr = temp_true[k] - T0_C;
        let cr = consts_at(temp_eff[k], &|c: &mut Constants<f64>| {
            for e in &case.effects {
                match *e {
                    Effect::ScaleTemp(i, s) => c.k_v_per_g[i][i] += c0.k_v_per_g[i][i] * s * dtr,
                    Effect::CrossTemp(i, j, s) => c.k_v_per_g[i][j] += c0.k_v_per_g[i][i] * s * dtr,
                    Effect::CrossAxis(i, j, m) => c.k_v_per_g[i][j] += c0.k_v_per_g[i][i] * m,
                    _ => {}
                }
            }
        });
        let us = cs.signals_v(&f);
        let ur = cr.signals_v(&f);
        let mut row_s = Row { line: k as u64 + 2, t_s: t[k], pos: Some(hold.pos.clone()), ..Row::default() };
        row_s.f_g = f.map(Some);
        row_s.set_vibration(&hold.vib);
        if !plan.power_on_s.is_empty() {
            row_s.power_s = Some(power[k]);
        }
        let mut row_r = row_s.clone();
        let temp_read = temp_true[k] + case.noise.temp_c * nrm.sample(&mut rng);
        row_s.temp_c = temp_read;
        row_r.temp_c = temp_read;
        for i in 0..3 {
            let kii = c0.k_v_per_g[i][i];
            let mut extra_g = 0.0;
            for e in &case.effects {
                match *e {
                    Effect::Warmup(a, amp, tau) if a == i => extra_g += amp * (-power[k] / tau).exp(),
                    Effect::BiasTemp(a, b) if a == i => extra_g += ((b[2] * dtr + b[1]) * dtr + b[0]) * dtr,
                    _ => {}
                }
            }
            let nz = &case.noise;
            rw[i] += nz.rw_g_per_sqrt_s * plan.dt_s.sqrt() * nrm.sample(&mut rng);
            if let Some((s, tau)) = nz.gm {
                let a = (-plan.dt_s / tau).exp();
                gm[i] = a * gm[i] + s * (1.0 - a * a).sqrt() * nrm.sample(&mut rng);
            }
            let noise_g = nz.white_g * nrm.sample(&mut rng) + rw[i] + gm[i];
            row_s.u_v[i] = us[i] + kii * rect_sim[h][i];
            row_r.u_v[i] = ur[i] + kii * (rect_real[h][i] + extra_g + noise_g);
        }
        sim.push(row_s);
        real.push(row_r);
    }
    (sim, real)
}

fn pos(name: &str, f: [f64; 3], dur: f64) -> Hold {
    Hold { dur_s: dur, f_g: f, vib: Vibration::None, pos: name.into() }
}

fn tilter6(dur: f64) -> Vec<Hold> {
    vec![
        pos("TP1", [0.0, 0.0, 1.0], dur),
        pos("TP2", [0.0, -1.0, 0.0], dur),
        pos("TP3", [0.0, 0.0, -1.0], dur),
        pos("TP4", [0.0, 1.0, 0.0], dur),
        pos("TP5", [-1.0, 0.0, 0.0], dur),
        pos("TP6", [1.0, 0.0, 0.0], dur),
    ]
}

fn tilted(dur: f64) -> Vec<Hold> {
    let (a, b) = (0.5, 0.866_025_403_784_438_6);
    let c = std::f64::consts::FRAC_1_SQRT_2;
    let mut v = tilter6(dur);
    v.extend([
        pos("CP1", [a, 0.0, b], dur),
        pos("CP2", [-c, c, 0.0], dur),
        pos("CP3", [0.0, -a, -b], dur),
        pos("CP4", [b, -a, 0.0], dur),
        pos("CP5", [-a, 0.0, b], dur),
        pos("CP6", [c, 0.0, -c], dur),
        pos("CP7", [0.0, b, a], dur),
        pos("CP8", [-b, 0.0, -a], dur),
    ]);
    v
}

fn sine(amp: [f64; 3]) -> Vibration<f64> {
    Vibration::Harmonic { amp_g: amp, freq_hz: 80.0 }
}

fn random(sigma: [f64; 3]) -> Vibration<f64> {
    Vibration::Random { sigma_g: sigma, band_hz: (20.0, 640.0) }
}

fn with_vib(mut holds: Vec<Hold>, every: usize, vib: &[Vibration<f64>]) -> Vec<Hold> {
    let mut out = Vec::new();
    let mut vi = 0;
    for (i, h) in holds.drain(..).enumerate() {
        out.push(h.clone());
        if i % every == every - 1 {
            let mut v = h.clone();
            v.vib = vib[vi % vib.len()];
            v.pos = format!("{}-vib", h.pos);
            vi += 1;
            out.push(v);
        }
    }
    out
}

/// Chamber profile from a start and `(target °C, rate °C/min, hold s)` legs.
fn chamber(start: f64, legs: &[(f64, f64, f64)]) -> Vec<(f64, f64)> {
    let mut k = vec![(0.0, start)];
    let (mut t, mut c) = (0.0, start);
    for &(to, rate, hold) in legs {
        t += (to - c).abs() / (rate / 60.0);
        c = to;
        k.push((t, c));
        t += hold;
        k.push((t, c));
    }
    k
}

/// Two ramp rates (0.5 and 2 °C/min) with holds, cycled over about 6.7 h.
fn two_rates() -> Vec<(f64, f64)> {
    chamber(
        20.0,
        &[
            (50.0, 0.5, 1200.0),
            (0.0, 2.0, 1200.0),
            (50.0, 2.0, 900.0),
            (20.0, 0.5, 1200.0),
            (-10.0, 2.0, 900.0),
            (20.0, 0.5, 600.0),
        ],
    )
}

/// One rate, no holds: a triangle 10 ↔ 50 °C at 1 °C/min.
fn triangle() -> Vec<(f64, f64)> {
    let mut legs = Vec::new();
    for _ in 0..6 {
        legs.push((50.0, 1.0, 0.0));
        legs.push((10.0, 1.0, 0.0));
    }
    chamber(30.0, &legs)
}

/// Slow chamber drift around 20 °C (± 3 °C, 4 h period).
fn drift() -> Vec<(f64, f64)> {
    (0..=48)
        .map(|k| (k as f64 * 600.0, 20.0 + 3.0 * (k as f64 * 600.0 / 14_400.0 * std::f64::consts::TAU).sin()))
        .collect()
}

const ROWS: usize = 24_000;

fn plan(holds: Vec<Hold>, chamber: Vec<(f64, f64)>, power_on_s: Vec<f64>) -> Plan {
    Plan { dt_s: 1.0, rows: ROWS, holds, chamber, power_on_s }
}

fn expect(effects: &[(Mech, &[usize])], params: &[(Mech, usize, &'static str, f64)]) -> Expected {
    Expected {
        effects: effects.iter().map(|(m, a)| (*m, a.to_vec())).collect(),
        ambiguous: Vec::new(),
        params: params.to_vec(),
    }
}

fn ambiguous(ids: &[Mech], axes: &[usize]) -> Expected {
    let mut ids = ids.to_vec();
    ids.sort_by_key(|m| m.id());
    Expected { effects: Vec::new(), ambiguous: vec![(ids, axes.to_vec())], params: Vec::new() }
}

/// The proof suite.
pub fn suite() -> Vec<Case> {
    use Mech::*;
    let xyz: &[usize] = &[0, 1, 2];
    let vibs = [sine([0.0, 0.0, 0.9]), random([0.0, 0.0, 0.45]), sine([0.0, 0.0, 0.6])];
    let std_holds = || with_vib(tilter6(60.0), 3, &vibs);
    let rw_noise = Noise { white_g: 20e-6, rw_g_per_sqrt_s: 2e-6, gm: Some((20e-6, 600.0)), temp_c: 0.005 };
    vec![
        Case {
            name: "null_white",
            description: "no effect, white noise only; thermal cycling at two rates, tilter positions, vibration",
            plan: plan(std_holds(), two_rates(), vec![0.0]),
            noise: Noise { rw_g_per_sqrt_s: 0.0, ..Noise::default() },
            effects: vec![],
            seed: 101,
            expected: Expected::default(),
        },
        Case {
            name: "null_random_walk",
            description: "no effect; strong random walk (2 µg/√s) plus a Gauss–Markov bias instability (20 µg, 600 s) that slow thermal and warm-up terms could absorb",
            plan: plan(std_holds(), two_rates(), vec![0.0]),
            noise: rw_noise,
            effects: vec![],
            seed: 102,
            expected: Expected::default(),
        },
        Case {
            name: "thermal_lag",
            description: "die lags the thermistor by τ = 180 s; separable from hysteresis through two ramp rates and holds",
            plan: plan(tilter6(60.0), two_rates(), vec![]),
            noise: Noise::default(),
            effects: vec![Effect::ThermalLag(180.0)],
            seed: 103,
            expected: expect(
                &[(ThermalLag, xyz)],
                &[
                    (ThermalLag, 0, "tau_s", 180.0),
                    (ThermalLag, 1, "tau_s", 180.0),
                    (ThermalLag, 2, "tau_s", 180.0),
                    (ThermalLag, 0, "gain", 1.0),
                ],
            ),
        },
        Case {
            name: "thermal_hysteresis",
            description: "constants follow the temperature through a 1.5 °C play; two ramp rates and holds",
            plan: plan(tilter6(60.0), two_rates(), vec![]),
            noise: Noise::default(),
            effects: vec![Effect::Hysteresis(1.5)],
            seed: 104,
            expected: expect(
                &[(ThermalHysteresis, xyz)],
                &[
                    (ThermalHysteresis, 0, "width_C", 1.5),
                    (ThermalHysteresis, 1, "width_C", 1.5),
                    (ThermalHysteresis, 2, "width_C", 1.5),
                ],
            ),
        },
        Case {
            name: "lag_vs_hysteresis_one_rate",
            description: "a short lag (τ = 8 s) under a triangle at one rate without holds: indistinguishable from hysteresis",
            plan: plan(tilter6(60.0), triangle(), vec![]),
            noise: Noise { white_g: 50e-6, ..Noise::default() },
            effects: vec![Effect::ThermalLag(8.0)],
            seed: 105,
            expected: ambiguous(&[ThermalLag, ThermalHysteresis], xyz),
        },
        Case {
            name: "asymmetry_tilted",
            description: "scale-factor asymmetry 300 ppm on x; tilted positions separate |f| from f²; chamber drifts",
            plan: plan(tilted(60.0), drift(), vec![]),
            noise: Noise::default(),
            effects: vec![Effect::Asymmetry(0, 300e-6)],
            seed: 106,
            expected: expect(&[(SfAsymmetry, &[0])], &[(SfAsymmetry, 0, "delta_1a_ppm", 300.0)]),
        },
        Case {
            name: "asymmetry_vs_k2_level",
            description: "the same asymmetry with only 0/±1 g positions and no vibration: |f| = f², indistinguishable from k2",
            plan: plan(tilter6(60.0), drift(), vec![]),
            noise: Noise::default(),
            effects: vec![Effect::Asymmetry(0, 300e-6)],
            seed: 107,
            expected: ambiguous(&[SfAsymmetry, NonlinearityK2], &[0]),
        },
        Case {
            name: "k2_vibration_only",
            description: "k2 = 200 µg/g² on z with z always at ±1 g (the static part is a bias); only vibration along z reveals it, while the chamber drifts",
            plan: plan(
                with_vib(vec![pos("TP1", [0.0, 0.0, 1.0], 60.0), pos("TP3", [0.0, 0.0, -1.0], 60.0)], 1, &vibs),
                drift(),
                vec![],
            ),
            noise: Noise::default(),
            effects: vec![Effect::K2(2, 200e-6)],
            seed: 108,
            expected: expect(&[(NonlinearityK2, &[2])], &[(NonlinearityK2, 2, "k2_ug_per_g2", 200.0)]),
        },
        Case {
            name: "k3_tilted_vibration",
            description: "k3 = 150 µg/g³ on y: tilted positions and vibration along y (3σ²·f term)",
            plan: plan(with_vib(tilted(60.0), 2, &[sine([0.0, 0.8, 0.0]), random([0.0, 0.5, 0.0])]), drift(), vec![]),
            noise: Noise::default(),
            effects: vec![Effect::K3(1, 150e-6)],
            seed: 109,
            expected: expect(&[(NonlinearityK3, &[1])], &[(NonlinearityK3, 1, "k3_ug_per_g3", 150.0)]),
        },
        Case {
            name: "vibration_cross",
            description: "m31 = 400 µg/g² on x (IA·OA = x·z): vibration along x and z together, tilted positions",
            plan: plan(with_vib(tilted(60.0), 2, &[sine([0.7, 0.0, 0.7]), sine([0.5, 0.0, -0.5])]), drift(), vec![]),
            noise: Noise::default(),
            effects: vec![Effect::VibCross(0, 400e-6, 0.0)],
            seed: 110,
            expected: expect(&[(VibrationCross, &[0])], &[(VibrationCross, 0, "m31_ug_per_g2", 400.0)]),
        },
        Case {
            name: "cross_axis",
            description: "misalignment of y towards z (+250 ppm) and x (−150 ppm) under a moderate random walk",
            plan: plan(tilter6(60.0), drift(), vec![]),
            noise: Noise { rw_g_per_sqrt_s: 1e-6, ..Noise::default() },
            effects: vec![Effect::CrossAxis(1, 2, 250e-6), Effect::CrossAxis(1, 0, -150e-6)],
            seed: 111,
            expected: expect(
                &[(CrossAxis, &[1])],
                &[(CrossAxis, 1, "m_yz_ppm", 250.0), (CrossAxis, 1, "m_yx_ppm", -150.0)],
            ),
        },
        Case {
            name: "scale_temp",
            description: "scale factor of z changes by 25 ppm/°C more than simulated; two-rate thermal cycling",
            plan: plan(tilter6(60.0), two_rates(), vec![]),
            noise: Noise::default(),
            effects: vec![Effect::ScaleTemp(2, 25e-6)],
            seed: 112,
            expected: expect(&[(ScaleTemp, &[2])], &[(ScaleTemp, 2, "s1_ppm_per_C", 25.0)]),
        },
        Case {
            name: "cross_coupling_temp_noisy",
            description: "cross-sensitivity x←y changes by 15 ppm/°C, under heavy white noise and random walk",
            plan: plan(tilter6(60.0), two_rates(), vec![]),
            noise: Noise { white_g: 60e-6, rw_g_per_sqrt_s: 1.5e-6, gm: None, temp_c: 0.01 },
            effects: vec![Effect::CrossTemp(0, 1, 15e-6)],
            seed: 113,
            expected: expect(&[(CrossCouplingTemp, &[0])], &[(CrossCouplingTemp, 0, "c_xy_ppm_per_C", 15.0)]),
        },
        Case {
            name: "bias_temp_order",
            description: "a quadratic bias term (0.5 µg/°C²) on y the simulation lacks, during two-rate ramps and holds",
            plan: plan(tilter6(60.0), two_rates(), vec![]),
            noise: Noise::default(),
            effects: vec![Effect::BiasTemp(1, [0.0, 0.5e-6, 0.0])],
            seed: 114,
            expected: expect(&[(BiasTempOrder, &[1])], &[(BiasTempOrder, 1, "b2_mg_per_C2", 0.5e-3)]),
        },
        Case {
            name: "warmup",
            description: "turn-on transients on x (0.3 mg) and z (−0.2 mg), τ = 600 s; two power-ons at 20 and 50 °C separate them from self-heating",
            plan: plan(
                tilter6(60.0),
                chamber(20.0, &[(20.0, 1.0, 6000.0), (50.0, 1.0, 8000.0), (20.0, 1.0, 8000.0)]),
                vec![0.0, 10_000.0],
            ),
            noise: Noise::default(),
            effects: vec![Effect::Warmup(0, 0.3e-3, 600.0), Effect::Warmup(2, -0.2e-3, 600.0)],
            seed: 115,
            expected: expect(
                &[(Warmup, &[0, 2])],
                &[(Warmup, 0, "tau_s", 600.0), (Warmup, 0, "amp_mg", 0.3), (Warmup, 2, "amp_mg", -0.2)],
            ),
        },
        Case {
            name: "warmup_vs_self_heating",
            description: "the die self-heats by 1.5 °C (τ = 1500 s) after the only power-on, at the record's start, at constant chamber temperature in one position (z up): indistinguishable from a warm-up transient, from a drift in time, and from any temperature coefficient acting through the die's rise (bias, its play, and on each axis the coefficient gravity lets act: the cross-coupling on x and y, the scale factor on z), and on z from a die lag that delays an instant rise of the die by τ",
            plan: plan(vec![pos("TP1", [0.0, 0.0, 1.0], 60.0)], vec![(0.0, 20.0)], vec![0.0]),
            noise: Noise::default(),
            effects: vec![Effect::SelfHeating(1.5, 1500.0)],
            seed: 116,
            expected: {
                let through_die = [BiasHysteresis, BiasTempOrder, Drift, SelfHeating, ThermalHysteresis, Warmup];
                let mut xy = ambiguous(&[&through_die[..], &[CrossCouplingTemp]].concat(), &[0, 1]);
                let z = ambiguous(&[&through_die[..], &[ScaleTemp, ThermalLag]].concat(), &[2]);
                xy.ambiguous.extend(z.ambiguous);
                xy
            },
        },
        Case {
            name: "lag_plus_asymmetry",
            description: "two mechanisms: thermal lag τ = 120 s on every axis and asymmetry 300 ppm on y; tilted positions, two-rate cycling",
            plan: plan(tilted(60.0), two_rates(), vec![]),
            noise: Noise::default(),
            effects: vec![Effect::ThermalLag(120.0), Effect::Asymmetry(1, 300e-6)],
            seed: 117,
            expected: expect(
                &[(ThermalLag, xyz), (SfAsymmetry, &[1])],
                &[(ThermalLag, 0, "tau_s", 120.0), (SfAsymmetry, 1, "delta_1a_ppm", 300.0)],
            ),
        },
    ]
}

/// How one case was diagnosed.
#[derive(Clone, Debug)]
pub struct Score {
    /// Case name.
    pub name: &'static str,
    /// Effects and ambiguous groups exactly as expected.
    pub exact: bool,
    /// Expected `(id, axis)` not found (effects and ambiguous groups).
    pub missing: Vec<String>,
    /// Found `(id, axis)` not expected.
    pub extra: Vec<String>,
    /// Worst relative parameter error (0 when the case has no parameter).
    pub worst_param_error: f64,
    /// Each parameter: name, truth, estimate.
    pub params: Vec<(String, f64, f64)>,
    /// Per accelerometer: held-out RMS before, after, noise floor \[mg\].
    pub rms: [(f64, f64, f64); 3],
    /// Held-out RMS down to the noise model's level (within 25 % of the white floor and the
    /// drift combined) or ≥ 3× smaller on every accelerometer with an expected effect.
    pub rms_ok: bool,
}

/// Scores a diagnosis against the case's expectation.
pub fn score(case: &Case, report: &super::report::Report) -> Score {
    use std::collections::BTreeSet;
    let ax = ["x", "y", "z"];
    let mut want: BTreeSet<String> = BTreeSet::new();
    for (m, axes) in &case.expected.effects {
        for a in axes {
            want.insert(format!("{}/{}", m.id(), ax[*a]));
        }
    }
    for (ms, axes) in &case.expected.ambiguous {
        let ids: Vec<&str> = ms.iter().map(|m| m.id()).collect();
        for a in axes {
            want.insert(format!("ambiguous[{}]/{}", ids.join("+"), ax[*a]));
        }
    }
    let mut got: BTreeSet<String> = BTreeSet::new();
    for e in &report.effects {
        for a in &e.axes {
            got.insert(format!("{}/{}", e.id, a));
        }
    }
    for g in &report.ambiguous {
        for a in &g.axes {
            got.insert(format!("ambiguous[{}]/{}", g.ids.join("+"), a));
        }
    }
    let missing: Vec<String> = want.difference(&got).cloned().collect();
    let extra: Vec<String> = got.difference(&want).cloned().collect();
    let mut params = Vec::new();
    let mut worst: f64 = 0.0;
    for (m, a, name, truth) in &case.expected.params {
        let est = report
            .effects
            .iter()
            .find(|e| e.id == m.id())
            .and_then(|e| e.params.get(ax[*a]))
            .and_then(|p| p.get(*name))
            .copied()
            .unwrap_or(f64::NAN);
        let err = ((est - truth) / truth).abs();
        worst = if err.is_nan() { f64::INFINITY } else { worst.max(err) };
        params.push((format!("{}/{}/{}", m.id(), ax[*a], name), *truth, est));
    }
    let mut rms = [(0.0, 0.0, 0.0); 3];
    let mut rms_ok = true;
    let affected: BTreeSet<usize> = case
        .expected
        .effects
        .iter()
        .flat_map(|e| e.1.iter().copied())
        .chain(case.expected.ambiguous.iter().flat_map(|e| e.1.iter().copied()))
        .collect();
    for i in 0..3 {
        let g = |m: &super::report::PerAxis<f64>| m.get(ax[i]).copied().unwrap_or(f64::NAN);
        rms[i] = (g(&report.heldout_rms_before_mg), g(&report.heldout_rms_after_mg), g(&report.noise_floor_mg));
        if affected.contains(&i) {
            // The level the noise model expects of what is left: the white floor and the drift
            // at the random walk the mechanisms were tested against.
            let (b, a, fl) = rms[i];
            let level = fl.hypot(g(&report.drift_rms_mg));
            rms_ok &= a <= 1.25 * level || b >= 3.0 * a;
        }
    }
    Score {
        name: case.name,
        exact: missing.is_empty() && extra.is_empty(),
        missing,
        extra,
        worst_param_error: worst,
        params,
        rms,
        rms_ok,
    }
}
