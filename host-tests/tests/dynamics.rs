//! Thermal dynamics (`bins_comp::dynamics`) against independent references: the closed-form
//! step response of the lag, hand-computed traces of the two play operators, the closed form
//! of the self-heating, the non-finite policy, the stages run every N samples and held against
//! the same stages on every sample (within their stated bound), and the pipeline's cached
//! temperature terms (effective temperature held over N samples and rounded to 1/256 °C,
//! `f32`) against the `f64` pipeline evaluating the model at the exact effective temperature
//! on every sample.

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
    let every = fixed.every() as usize;
    assert_eq!(every, bins_comp::dynamics::UPDATE_EVERY as usize);
    let per_sample = fixed.every_sample();
    let (mut st, mut st32, mut st_gen, mut st_1) =
        (DynamicsState::new(), DynamicsState::new(), DynamicsState::new(), DynamicsState::new());
    // At power-on the reading is 20 °C: no transient.
    assert_eq!(fixed.step(&mut st, 20.0).temp_eff_c, 20.0);
    assert_eq!(fixed32.step(&mut st32, 20.0).temp_eff_c, 20.0);
    assert_eq!(d.step(&mut st_gen, 20.0, DT, 0.0).temp_eff_c, 20.0);
    assert_eq!(per_sample.step(&mut st_1, 20.0).temp_eff_c, 20.0);
    let (mut worst, mut worst32, mut worst_gen, mut worst_1) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    let closed = |n: usize| 30.0 - 10.0 * (-(n as f64) * DT / tau).exp();
    for n in 1..=100_000 {
        // The reading steps to 30 °C at sample 1; after n samples x = 30 − 10·e^(−n·Δt/τ).
        let want = closed(n);
        // Held: the update at the last multiple of N up to n, N periods of the held reading.
        let held = closed(n / every * every);
        worst = worst.max((fixed.step(&mut st, 30.0).temp_eff_c - held).abs());
        worst32 = worst32.max((fixed32.step(&mut st32, 30.0).temp_eff_c as f64 - held).abs());
        worst_gen = worst_gen.max((d.step(&mut st_gen, 30.0, DT, n as f64 * DT).temp_eff_c - want).abs());
        worst_1 = worst_1.max((per_sample.step(&mut st_1, 30.0).temp_eff_c - want).abs());
    }
    println!(
        "lag step response, worst error: held every {every} samples f64 {worst:.2e} °C, f32 {worst32:.2e} °C; every sample {worst_1:.2e} °C; per-call gains {worst_gen:.2e} °C"
    );
    assert!(worst < 1e-11, "{worst}");
    assert!(worst_1 < 1e-11, "{worst_1}");
    assert!(worst_gen < 1e-11, "{worst_gen}");
    // f32: the output's own rounding (spacing 1.9e-6 at 30 °C) and the gain's, not an
    // accumulation over 10⁵ samples (a plain f32 sum would drift by ~1e-3 °C here).
    assert!(worst32 < 4e-6, "{worst32}");
}

#[test]
fn hysteresis_play_matches_a_hand_computed_trace() {
    // Width 1 °C, no lag: e ← clamp(e, x − 0.5, x + 0.5).
    let d = ThermalDynamics { hysteresis_width_c: 1.0, ..off() }.at_rate(DT).unwrap().every_sample();
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
    let d = ThermalDynamics { bias_play_width_c: 1.0, bias_play_g: [1e-5, -2e-5, 3e-5], ..off() }
        .at_rate(DT)
        .unwrap()
        .every_sample();
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
    let every = fixed.every() as usize;
    // Advanced on every sample (the reference of the hold).
    let (every_sample, every_sample32) = (fixed.every_sample(), fixed32.every_sample());
    let (mut st, mut st32, mut su, mut su32) =
        (DynamicsState::new(), DynamicsState::new(), DynamicsState::new(), DynamicsState::new());
    let (mut worst, mut worst32, mut worst_u, mut worst_u32, mut worst_hold) = (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for n in 0..400_000usize {
        let want = closed(n as f64 * DT);
        let general = d.step(&mut DynamicsState::new(), 25.0, DT, n as f64 * DT).temp_eff_c;
        assert!((general - want).abs() < 1e-13, "n = {n}: {general} != {want}");
        worst_u = worst_u.max((every_sample.step(&mut su, 25.0).temp_eff_c - want).abs());
        worst_u32 = worst_u32.max((every_sample32.step(&mut su32, 25.0).temp_eff_c as f64 - want).abs());
        // Held: step n uses the closed form at the last multiple of N up to n.
        let held = closed((n / every * every) as f64 * DT);
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

/// A reading [°C] by sample index.
type Reading = fn(usize) -> f64;

/// The largest spread (max − min) of `v` over any N consecutive samples.
fn spread_over(v: &[f64], n: usize) -> f64 {
    v.windows(n)
        .map(|w| w.iter().fold(f64::MIN, |a, &b| a.max(b)) - w.iter().fold(f64::MAX, |a, &b| a.min(b)))
        .fold(0.0, f64::max)
}

#[test]
fn the_held_stages_stay_within_their_bound_of_the_stages_on_every_sample() {
    // f64: the stages run every N samples with the gains of N periods, their output held,
    // against the same stages on every sample, for readings that change out of step with the
    // updates (the chamber cycle's TMP117 reading shifted by 7 samples; a 10 °C step on
    // sample 5; a 1 Hz ±0.5 °C wobble held 16 samples at a time), with and without the lag.
    // The bound (`FixedRate::step`): D_u + D_x + D_T + |ΔT_sh|·(N − 1)·Δt/τ_sh, each D the
    // largest change over N − 1 samples of the reading, of the per-sample lagged temperature
    // and of the per-sample T_eff; the bias play's fraction within (|ΔT_eff| + |Δp|)/(h_b/2),
    // the play's output p within the bound + D_T.
    let samples = ((4.0 * 120.0 + 2.0 * 1200.0) / DT) as usize;
    let readings: [(&str, Reading); 3] = [
        ("chamber cycle, shifted by 7 samples", |n| chamber_reading(n + 7)),
        ("10 °C step on sample 5", |n| if n < 5 { 20.0 } else { 30.0 }),
        ("1 Hz ±0.5 °C wobble", |n| 25.0 + 0.5 * ((n / 16 * 16 + 3) as f64 * DT * std::f64::consts::TAU).sin()),
    ];
    for lag_tau_s in [60.0, 0.0] {
        let dynamics = ThermalDynamics { lag_tau_s, ..unit_dynamics() };
        let held = dynamics.at_rate(DT).unwrap();
        let every = held.every() as usize;
        let per_sample = held.every_sample();
        for (name, reading) in &readings {
            let n_run = if name.starts_with("chamber") { samples } else { 200_000 };
            let (mut st_h, mut st_1) = (DynamicsState::new(), DynamicsState::new());
            let (mut u, mut x, mut t) = (Vec::new(), Vec::new(), Vec::new());
            let (mut d_t, mut d_d, mut d_p) = (Vec::new(), Vec::new(), Vec::new());
            for n in 0..n_run {
                let r = reading(n);
                let h = held.step(&mut st_h, r);
                let e = per_sample.step(&mut st_1, r);
                u.push(r);
                x.push(st_1.lagged_c());
                t.push(e.temp_eff_c);
                d_t.push((h.temp_eff_c - e.temp_eff_c).abs());
                d_d.push((h.bias_play - e.bias_play).abs());
                d_p.push((st_h.play_outputs_c().1 - st_1.play_outputs_c().1).abs());
            }
            let (du, dx, dtt) = (spread_over(&u, every), spread_over(&x, every), spread_over(&t, every));
            let sh = dynamics.self_heating_c.abs() * (every - 1) as f64 * DT / dynamics.self_heating_tau_s;
            let bound = du + dx + dtt + sh;
            let worst = d_t.iter().fold(0.0f64, |a, &b| a.max(b));
            let worst_p = d_p.iter().fold(0.0f64, |a, &b| a.max(b));
            let worst_d = d_d.iter().fold(0.0f64, |a, &b| a.max(b));
            let bound_d = (bound + bound + dtt) / (0.5 * dynamics.bias_play_width_c);
            println!(
                "τ = {lag_tau_s} s, {name}: |T_eff held − every sample| ≤ {:.3} m°C (bound {:.3}: D_u {:.3}, D_x {:.3}, D_T {:.3}, self-heating {:.3}); bias play's p {:.3} m°C, fraction {:.2e} (bound {:.2e})",
                worst * 1e3,
                bound * 1e3,
                du * 1e3,
                dx * 1e3,
                dtt * 1e3,
                sh * 1e3,
                worst_p * 1e3,
                worst_d,
                bound_d
            );
            assert!(worst <= bound, "τ = {lag_tau_s}, {name}: {worst} > {bound}");
            assert!(worst_p <= bound + dtt, "τ = {lag_tau_s}, {name}: p {worst_p} > {}", bound + dtt);
            assert!(worst_d <= bound_d, "τ = {lag_tau_s}, {name}: d {worst_d} > {bound_d}");
            // The hold is exercised: the outputs differ.
            assert!(worst > 0.0, "τ = {lag_tau_s}, {name}");
        }
    }
}

#[test]
fn cached_terms_at_the_rounded_held_effective_temperature_stay_within_2_ug_of_the_exact_f64() {
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
            "{method:?}: {} samples, −40…+60 °C at 5 °C/min, ±1 g: worst |f32 rounded − f64 exact| = {:.3} µg at sample {worst_at} ({:.2} °C); the rounding and the hold alone (f64): {:.3} µg",
            samples,
            worst * 1e6,
            chamber_reading(worst_at),
            worst_rounding * 1e6
        );
        // The rounding and the hold alone: the model's slope at 1 g times at most 1/512 °C
        // (the rounding) plus the per-sample T_eff's change over the 15 samples the stages'
        // output is held, 1.26 m°C on the 5 °C/min ramp (the test above): 3.2 m°C; the offsets
        // alone move by 220 µg/°C below T0 for this unit (0.71 µg); plus the self-heating's
        // hold, at most 1.5 °C·15 ms/300 s = 7.5·10⁻⁵ °C (0.02 µg).
        assert!(worst_rounding <= 1.0e-6, "{method:?}: {worst_rounding}");
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
    let stage = dynamics.at_rate(DT).unwrap().every_sample();
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
