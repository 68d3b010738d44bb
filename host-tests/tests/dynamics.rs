//! Thermal dynamics (`bins_comp::dynamics`) against independent references: the closed-form
//! step response of the lag, hand-computed traces of the two play operators, the closed form
//! of the self-heating, the non-finite policy, and the pipeline's cached temperature terms
//! (effective temperature rounded to 1/256 °C, `f32`) against the `f64` pipeline evaluating
//! the model at the exact effective temperature on every sample.

use bins_comp::dynamics::{DynamicsError, DynamicsState, ThermalDynamics};
use bins_comp::vibration::VibrationConfig;
use bins_comp::{Calibration, Form, Method, Pipeline, PipelineState, Status, VibrationSource, paper};

const DT: f64 = 1.0e-3;

fn off() -> ThermalDynamics<f64> {
    ThermalDynamics::none()
}

#[test]
fn lag_follows_the_closed_form_step_response() {
    let tau = 10.0;
    let d = ThermalDynamics { lag_tau_s: tau, ..off() };
    let fixed = d.at_rate(DT).unwrap();
    let fixed32 = d.cast::<f32>().at_rate(DT as f32).unwrap();
    let (mut st, mut st32, mut st_gen) = (DynamicsState::new(), DynamicsState::new(), DynamicsState::new());
    // At power-on the reading is 20 °C: no transient.
    assert_eq!(fixed.step(&mut st, 20.0).temp_eff_c, 20.0);
    assert_eq!(fixed32.step(&mut st32, 20.0).temp_eff_c, 20.0);
    assert_eq!(d.step(&mut st_gen, 20.0, DT, 0.0).temp_eff_c, 20.0);
    let (mut worst, mut worst32, mut worst_gen) = (0.0f64, 0.0f64, 0.0f64);
    for n in 1..=100_000 {
        // The reading steps to 30 °C at sample 1; after n samples x = 30 − 10·e^(−n·Δt/τ).
        let want = 30.0 - 10.0 * (-(n as f64) * DT / tau).exp();
        worst = worst.max((fixed.step(&mut st, 30.0).temp_eff_c - want).abs());
        worst32 = worst32.max((fixed32.step(&mut st32, 30.0).temp_eff_c as f64 - want).abs());
        worst_gen = worst_gen.max((d.step(&mut st_gen, 30.0, DT, n as f64 * DT).temp_eff_c - want).abs());
    }
    println!(
        "lag step response, worst error: f64 {worst:.2e} °C, f32 {worst32:.2e} °C, per-call gains {worst_gen:.2e} °C"
    );
    assert!(worst < 1e-11, "{worst}");
    assert!(worst_gen < 1e-11, "{worst_gen}");
    // f32: the output's own rounding (spacing 1.9e-6 at 30 °C) and the gain's, not an
    // accumulation over 10⁵ samples (a plain f32 sum would drift by ~1e-3 °C here).
    assert!(worst32 < 4e-6, "{worst32}");
}

#[test]
fn hysteresis_play_matches_a_hand_computed_trace() {
    // Width 1 °C, no lag: e ← clamp(e, x − 0.5, x + 0.5).
    let d = ThermalDynamics { hysteresis_width_c: 1.0, ..off() }.at_rate(DT).unwrap();
    let readings = [20.0, 20.3, 20.8, 21.0, 20.7, 20.4, 19.9, 19.0];
    let want = [20.0, 20.0, 20.3, 20.5, 20.5, 20.5, 20.4, 19.5];
    let mut st = DynamicsState::new();
    for (r, w) in readings.iter().zip(want) {
        let e = d.step(&mut st, *r);
        assert!((e.temp_eff_c - w).abs() < 1e-12, "reading {r}: {} != {w}", e.temp_eff_c);
        assert_eq!(e.bias_play, 0.0);
    }
}

#[test]
fn bias_play_fraction_matches_a_hand_computed_trace() {
    // Width 1 °C on T_eff (= the reading here): p ← clamp(p, T − 0.5, T + 0.5),
    // d = (p − T)/0.5.
    let d = ThermalDynamics { bias_play_width_c: 1.0, bias_play_g: [1e-5, -2e-5, 3e-5], ..off() }.at_rate(DT).unwrap();
    let readings = [20.0, 20.3, 20.8, 21.0, 20.7, 20.4, 19.9];
    let want = [0.0, -0.6, -1.0, -1.0, -0.4, 0.2, 1.0];
    let mut st = DynamicsState::new();
    for (r, w) in readings.iter().zip(want) {
        let e = d.step(&mut st, *r);
        assert_eq!(e.temp_eff_c, *r);
        assert!((e.bias_play - w).abs() < 1e-12, "reading {r}: {} != {w}", e.bias_play);
    }
}

#[test]
fn self_heating_recursion_equals_its_closed_form() {
    let (dt_sh, tau_sh) = (1.5, 30.0);
    let d = ThermalDynamics { self_heating_c: dt_sh, self_heating_tau_s: tau_sh, ..off() };
    let closed = |t: f64| 25.0 + dt_sh * (1.0 - (-t / tau_sh).exp());
    let fixed = d.at_rate(DT).unwrap();
    let fixed32 = d.cast::<f32>().at_rate(DT as f32).unwrap();
    let every = fixed.heating_every() as usize;
    assert_eq!(every, bins_comp::dynamics::HEATING_EVERY as usize);
    // Advanced on every sample (the reference of the hold).
    let (every_sample, every_sample32) = (fixed.heating_every_sample(), fixed32.heating_every_sample());
    let (mut st, mut st32, mut su, mut su32) =
        (DynamicsState::new(), DynamicsState::new(), DynamicsState::new(), DynamicsState::new());
    let (mut worst, mut worst32, mut worst_u, mut worst_u32, mut worst_hold) = (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for n in 0..400_000usize {
        let want = closed(n as f64 * DT);
        let general = d.step(&mut DynamicsState::new(), 25.0, DT, n as f64 * DT).temp_eff_c;
        assert!((general - want).abs() < 1e-13, "n = {n}: {general} != {want}");
        worst_u = worst_u.max((every_sample.step(&mut su, 25.0).temp_eff_c - want).abs());
        worst_u32 = worst_u32.max((every_sample32.step(&mut su32, 25.0).temp_eff_c as f64 - want).abs());
        // Held: step n uses the closed form at the first multiple of N from n on.
        let held = closed(n.div_ceil(every) as f64 * every as f64 * DT);
        let t = fixed.step(&mut st, 25.0).temp_eff_c;
        worst = worst.max((t - held).abs());
        worst32 = worst32.max((fixed32.step(&mut st32, 25.0).temp_eff_c as f64 - held).abs());
        worst_hold = worst_hold.max((t - want).abs());
    }
    // The hold's bound: |ΔT_sh|·(N − 1)·Δt/τ_sh.
    let bound = dt_sh * (every - 1) as f64 * DT / tau_sh;
    println!(
        "self-heating recursion vs closed form: f64 {worst_u:.2e} °C, f32 {worst_u32:.2e} °C; held every {every} samples, vs the held closed form: f64 {worst:.2e} °C, f32 {worst32:.2e} °C; the hold {worst_hold:.3e} °C (bound {bound:.3e} °C)"
    );
    assert!(worst_u < 1e-11, "{worst_u}");
    assert!(worst_u32 < 4e-6, "{worst_u32}");
    assert!(worst < 1e-11, "{worst}");
    assert!(worst32 < 4e-6, "{worst32}");
    assert!(worst_hold <= bound, "{worst_hold} > {bound}");
    assert!(worst_hold > 0.5 * bound, "{worst_hold}: the hold is not exercised");
}

#[test]
fn non_finite_readings_leave_the_state_and_pass_through() {
    let d = ThermalDynamics {
        lag_tau_s: 5.0,
        hysteresis_width_c: 0.2,
        bias_play_width_c: 0.4,
        bias_play_g: [1e-5; 3],
        ..off()
    }
    .at_rate(DT)
    .unwrap();
    let mut st = DynamicsState::new();
    // Not initialised by a non-finite first reading.
    let e = d.step(&mut st, f64::NAN);
    assert!(e.temp_eff_c.is_nan() && e.bias_play == 0.0 && !st.is_initialised());
    for _ in 0..1000 {
        d.step(&mut st, 20.0 + 1.0);
    }
    let before = st;
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let e = d.step(&mut st, bad);
        assert!(!e.temp_eff_c.is_finite());
        assert_eq!(e.bias_play, 0.0);
        // The lag and the plays untouched (the self-heating's clock runs on).
        assert_eq!((st.lagged_c(), st.play_outputs_c()), (before.lagged_c(), before.play_outputs_c()));
    }
    // A finite reading beyond ±1000 °C is not a temperature either: passed through, the
    // state untouched.
    for huge in [1e30, -1000.5, 3.0e38] {
        let e = d.step(&mut st, huge);
        assert_eq!((e.temp_eff_c, e.bias_play), (huge, 0.0));
        assert_eq!(st.lagged_c(), before.lagged_c());
    }
    assert!(d.step(&mut st, 1000.0).temp_eff_c.is_finite());
    let mut st = before;
    let mut reference = before;
    let (mut a, mut b) = (0.0, 0.0);
    for _ in 0..100_000 {
        a = d.step(&mut st, 21.0).temp_eff_c;
        b = d.step(&mut reference, 21.0).temp_eff_c;
    }
    assert!((a - 21.0).abs() < 0.11 && (b - 21.0).abs() < 0.11, "{a} {b}");
}

#[test]
fn validation_names_the_parameter() {
    let ok = ThermalDynamics {
        lag_tau_s: 60.0,
        hysteresis_width_c: 0.3,
        self_heating_c: -1.0,
        self_heating_tau_s: 120.0,
        bias_play_width_c: 0.5,
        bias_play_g: [2e-5, -1e-5, 0.0],
    };
    assert_eq!(ok.validate(), Ok(()));
    assert!(off().is_none() && !ok.is_none());
    let cases: [(ThermalDynamics<f64>, DynamicsError, &str); 8] = [
        (ThermalDynamics { lag_tau_s: -1.0, ..ok }, DynamicsError::LagTau, "lag_tau_s"),
        (ThermalDynamics { hysteresis_width_c: f64::NAN, ..ok }, DynamicsError::HysteresisWidth, "hysteresis_width_C"),
        (ThermalDynamics { self_heating_c: 51.0, ..ok }, DynamicsError::SelfHeating, "self_heating_C"),
        (
            ThermalDynamics { self_heating_tau_s: f64::INFINITY, ..ok },
            DynamicsError::SelfHeatingTau,
            "self_heating_tau_s",
        ),
        (ThermalDynamics { bias_play_width_c: -0.1, ..ok }, DynamicsError::BiasPlayWidth, "bias_play_width_C"),
        (ThermalDynamics { bias_play_g: [0.0, 0.2, 0.0], ..ok }, DynamicsError::BiasPlayG(1), "bias_play_mg[1]"),
        (ThermalDynamics { bias_play_width_c: 0.0, ..ok }, DynamicsError::BiasPlayWithoutWidth, "bias_play_mg"),
        (ThermalDynamics { lag_tau_s: 2e5, ..ok }, DynamicsError::LagTau, "lag_tau_s"),
    ];
    for (d, err, key) in cases {
        assert_eq!(d.validate(), Err(err));
        assert!(err.to_string().starts_with(key), "{err}");
        assert_eq!(d.at_rate(DT).err(), Some(err));
    }
    assert_eq!(ok.at_rate(0.0).err(), Some(DynamicsError::SamplePeriod));
    assert_eq!(ok.at_rate(f64::NAN).err(), Some(DynamicsError::SamplePeriod));
}

/// Parameters of a unit whose die lags by a minute, with every stage on.
fn unit_dynamics() -> ThermalDynamics<f64> {
    ThermalDynamics {
        lag_tau_s: 60.0,
        hysteresis_width_c: 0.3,
        self_heating_c: 1.5,
        self_heating_tau_s: 300.0,
        bias_play_width_c: 0.5,
        bias_play_g: [20e-6, -15e-6, 10e-6],
    }
}

/// The thermistor's reading over a chamber cycle: 2 min at −40 °C, a 5 °C/min ramp to +60 °C,
/// 2 min there, and back down; quantised to the TMP117's 1/128 °C and read every 16 samples.
fn chamber_reading(n: usize) -> f64 {
    let t = (n / 16 * 16) as f64 * DT;
    let rate = 5.0 / 60.0;
    let (dwell, ramp) = (120.0, 100.0 / rate);
    let case = if t < dwell {
        -40.0
    } else if t < dwell + ramp {
        -40.0 + rate * (t - dwell)
    } else if t < 2.0 * dwell + ramp {
        60.0
    } else {
        (60.0 - rate * (t - 2.0 * dwell - ramp)).max(-40.0)
    };
    (case * 128.0).round() / 128.0
}

#[test]
fn cached_terms_at_the_rounded_effective_temperature_stay_within_2_ug_of_the_exact_f64() {
    let samples = ((4.0 * 120.0 + 2.0 * 1200.0) / DT) as usize;
    let orientations =
        [[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]];
    let dynamics = unit_dynamics();
    for method in [Method::CoefficientCorrection, Method::OutputCorrection(Form::Simplified)] {
        let model = paper::two_range_model().unwrap();
        let cal64: Calibration<f64> = paper::calibration(model, method).unwrap();
        let cal32: Calibration<f32> = paper::calibration(model, method).unwrap();
        let reference = Pipeline::new(cal64, VibrationConfig::none())
            .with_dynamics(dynamics.at_rate(DT).unwrap())
            .exact_effective_temperature();
        let rounded64 = Pipeline::new(cal64, VibrationConfig::none()).with_dynamics(dynamics.at_rate(DT).unwrap());
        let mut st_r: PipelineState<f64, 64> = PipelineState::new();
        let mut worst_rounding = 0.0f64;
        let target =
            Pipeline::new(cal32, VibrationConfig::none()).with_dynamics(dynamics.cast().at_rate(DT as f32).unwrap());
        let mut st64: PipelineState<f64, 64> = PipelineState::new();
        let mut st32: PipelineState<f32, 64> = PipelineState::new();
        let (mut worst, mut worst_at) = (0.0f64, 0usize);
        for n in 0..samples {
            let reading = chamber_reading(n);
            // ±1 g along each axis in turn, 10 s each, signals of the unit at the reading.
            let a = orientations[(n / 10_000) % 6];
            let c = paper::params(model, method).constants_at(reading);
            let u: [f64; 3] =
                std::array::from_fn(|i| (0..3).map(|j| c.k_v_per_g[i][j] * a[j]).sum::<f64>() + c.u0_v[i]);
            let r64 = reference.step(&mut st64, u, reading, VibrationSource::None);
            let r32 = target.step(&mut st32, u.map(|x| x as f32), reading as f32, VibrationSource::None);
            let r = rounded64.step(&mut st_r, u, reading, VibrationSource::None);
            worst_rounding = (0..3).map(|i| (r.accel_g[i] - r64.accel_g[i]).abs()).fold(worst_rounding, f64::max);
            assert_eq!(r64.status, Status::OK);
            assert_eq!(r32.status, Status::OK);
            let e = (0..3).map(|i| (r32.accel_g[i] as f64 - r64.accel_g[i]).abs()).fold(0.0, f64::max);
            if e > worst {
                worst = e;
                worst_at = n;
            }
        }
        println!(
            "{method:?}: {} samples, −40…+60 °C at 5 °C/min, ±1 g: worst |f32 rounded − f64 exact| = {:.3} µg at sample {worst_at} ({:.2} °C); the rounding alone (f64): {:.3} µg",
            samples,
            worst * 1e6,
            chamber_reading(worst_at),
            worst_rounding * 1e6
        );
        // The rounding alone is the model's slope at 1 g times at most 1/512 °C (the offsets
        // alone move by 220 µg/°C below T0 for this unit: 0.43 µg), plus the self-heating's
        // hold, at most 1.5 °C·15 ms/300 s = 7.5·10⁻⁵ °C (0.02 µg).
        assert!(worst_rounding <= 0.6e-6, "{method:?}: {worst_rounding}");
        assert!(worst <= 2e-6, "{method:?}: {worst}");
    }
}

#[test]
fn the_effective_temperature_drives_the_model_and_the_bias_play_is_subtracted() {
    // f64, exact: the pipeline's output with dynamics equals the plain calibration at the
    // effective temperature minus bias_play_g·d (rounded once: a fused multiply-add),
    // computed here from the stage alone.
    let dynamics = unit_dynamics();
    let model = paper::two_range_model().unwrap();
    let cal: Calibration<f64> = paper::calibration(model, Method::CoefficientCorrection).unwrap();
    let p = Pipeline::new(cal, VibrationConfig::none())
        .with_dynamics(dynamics.at_rate(DT).unwrap())
        .exact_effective_temperature();
    let stage = dynamics.at_rate(DT).unwrap().heating_every_sample();
    let mut st: PipelineState<f64, 64> = PipelineState::new();
    let mut ds = DynamicsState::new();
    let mut saw_play = false;
    for n in 0..400_000 {
        let reading = 20.0 + 10.0 * ((n as f64) * DT / 40.0).sin();
        let u = [0.01, -0.55, 0.02];
        let s = p.step(&mut st, u, reading, VibrationSource::None);
        let e = stage.step(&mut ds, reading);
        let plain = cal.compensate(u, e.temp_eff_c);
        saw_play |= e.bias_play.abs() == 1.0;
        for i in 0..3 {
            assert_eq!(s.accel_g[i], (-dynamics.bias_play_g[i]).mul_add(e.bias_play, plain.accel_g[i]));
        }
    }
    assert!(saw_play);
}

#[test]
fn a_non_finite_reading_is_compensated_at_t0_and_flagged_with_or_without_dynamics() {
    let model = paper::two_range_model().unwrap();
    let cal: Calibration<f32> = paper::calibration(model, Method::CoefficientCorrection).unwrap();
    let plain = Pipeline::new(cal, VibrationConfig::none());
    let dynamic = plain.with_dynamics(unit_dynamics().cast().at_rate(DT as f32).unwrap());
    let (mut a, mut b): (PipelineState<f32, 64>, PipelineState<f32, 64>) = (PipelineState::new(), PipelineState::new());
    let u = [0.01, -0.55, 0.02];
    for _ in 0..100 {
        dynamic.step(&mut b, u, 30.0, VibrationSource::None);
    }
    let before = b.dynamics;
    let x = plain.step(&mut a, u, f32::NAN, VibrationSource::None);
    let y = dynamic.step(&mut b, u, f32::NAN, VibrationSource::None);
    assert_eq!(x, y);
    assert!(y.status.contains(Status::NONFINITE_INPUT | Status::TEMP_CLAMPED));
    assert!(y.accel_g.iter().all(|v| v.is_finite()));
    assert_eq!(b.dynamics.lagged_c(), before.lagged_c());
    // Without dynamics (every stage off) the pipeline is the plain one, bit for bit.
    let none = plain.with_dynamics(ThermalDynamics::none().at_rate(DT as f32).unwrap());
    assert!(none.dynamics().is_none());
    let (mut c, mut d): (PipelineState<f32, 64>, PipelineState<f32, 64>) = (PipelineState::new(), PipelineState::new());
    for n in 0..5000 {
        let t = -40.0 + 0.02 * n as f32;
        assert_eq!(plain.step(&mut c, u, t, VibrationSource::Online), none.step(&mut d, u, t, VibrationSource::Online));
    }
}

#[test]
fn the_exponential_free_gain_equals_expm1() {
    use bins_comp::dynamics::one_minus_exp_neg;
    let (mut worst64, mut worst32) = (0.0f64, 0.0f64);
    let mut x = 1e-12f64;
    while x < 60.0 {
        let want = -(-x).exp_m1();
        worst64 = worst64.max((one_minus_exp_neg(x) - want).abs() / want);
        worst32 = worst32.max((one_minus_exp_neg(x as f32) as f64 - want).abs() / want);
        x *= 1.07;
    }
    println!("1 − e^(−x): worst relative error f64 {worst64:.2e}, f32 {worst32:.2e}");
    assert!(worst64 < 4e-15, "{worst64}");
    assert!(worst32 < 1e-6, "{worst32}");
    assert_eq!(one_minus_exp_neg(0.0f64), 0.0);
    assert_eq!(one_minus_exp_neg(f64::NAN), 0.0);
    assert_eq!(one_minus_exp_neg(1e30f64), 1.0);
}
