//! The calibration file (TOML): the checked-in sample is the paper's unit, TOML → blob → TOML
//! is lossless for random valid calibrations of both model kinds and every method, with and
//! without a vibration-error model, and malformed files are rejected naming the key.

use bins_cal::calfile::{CalFileError, CalibrationFile};
use bins_comp::blob::{self, CalDate, Meta};
use bins_comp::dynamics::ThermalDynamics;
use bins_comp::temperature::{MAX_KNOTS, MAX_POLY_ORDER};
use bins_comp::vibration::tables;
use bins_comp::{
    CalibrationParams, CoefDelta, Constants, ConversionFunction, Form, Method, TempModel, Variant, Vibration,
    VibrationParams, paper,
};
use proptest::prelude::*;
use std::path::PathBuf;

fn sample_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../calibrations/paper-two-range.toml")
}

/// The paper's unit as the sample file describes it.
fn sample_params() -> CalibrationParams {
    paper::params(paper::two_range_model().unwrap(), Method::OutputCorrection(Form::Simplified))
}

const SAMPLE_META: Meta<'static> = Meta { serial: "PAPER-T1T2", date: None, tool_version: "bins-cal 0.1.0" };

/// Every f64 of the parameters as bits, plus the model's shape.
fn bits(p: &CalibrationParams) -> Vec<u64> {
    let mut v: Vec<f64> = vec![p.t0_c, p.temp_range_c.0, p.temp_range_c.1];
    v.extend(p.constants.k_v_per_g.iter().flatten());
    v.extend(p.constants.u0_v);
    let set = |c: &CoefDelta<f64>| c.to_array().to_vec();
    match &p.model {
        TempModel::Poly { order, coef } => {
            v.push(*order as f64);
            coef.iter().for_each(|c| v.extend(set(c)));
        }
        TempModel::Pwl { n_knots, knots_c, at_knot } => {
            v.push(100.0 + *n_knots as f64);
            v.extend(knots_c);
            at_knot.iter().for_each(|c| v.extend(set(c)));
        }
    }
    v.iter().map(|x| x.to_bits()).collect()
}

/// With `BINS_CAL_BLESS=1` the sample file is (re)written from `bins_comp::paper`; otherwise
/// it must describe exactly that calibration and be exactly the tool's rendering of it.
#[test]
fn sample_file_is_the_papers_unit() {
    // The paper's unit with the AL-15 vibration model and the seven flight profiles (what the
    // replay test of `cargo xtask test` runs with).
    let vib = bins_comp::vectors::vibration_params(bins_comp::Variant::Exact);
    let expected_text = CalibrationFile::from_parts(&sample_params(), Some(&vib), &SAMPLE_META).to_toml();
    if std::env::var_os("BINS_CAL_BLESS").is_some() {
        std::fs::write(sample_path(), &expected_text).unwrap();
    }
    let text = std::fs::read_to_string(sample_path()).unwrap();
    let file = CalibrationFile::from_toml(&text).unwrap();
    let (params, meta) = file.to_params().unwrap();
    assert_eq!(bits(&params), bits(&sample_params()));
    assert_eq!(meta.as_meta(), SAMPLE_META);
    assert_eq!(file.to_vibration().unwrap(), Some(vib));
    assert_eq!(text, expected_text, "the sample is the tool's own rendering (re-bless if the format changed)");
    // Spot check against the paper's printed tables, independently of the conversion code.
    assert!(text.contains("-0.55060863"), "K_xx of Table T1");
    assert!(text.contains("0.01639328"), "K_xz of Table T2");
    assert!(text.contains("t0_C = 20.0"));
    assert!(text.contains("temp_range_C = [-40.0, 70.0]"));
    let blob = file.to_blob().unwrap();
    assert_eq!(blob::parse(&blob).unwrap().params, sample_params());
}

#[test]
fn missing_tool_version_is_filled_in_by_the_encoder() {
    let mut file = CalibrationFile::from_params(&sample_params(), &SAMPLE_META);
    file.tool_version = None;
    let back = CalibrationFile::from_blob(&file.to_blob().unwrap()).unwrap();
    assert_eq!(back.tool_version.as_deref(), Some(bins_cal::TOOL_VERSION));
}

#[test]
fn extreme_but_valid_floats_round_trip() {
    let mut p = sample_params();
    if let TempModel::Pwl { at_knot, .. } = &mut p.model {
        at_knot[0].rel_k[0][1] = 5e-324; // smallest subnormal
        at_knot[0].rel_k[1][0] = -0.0;
        at_knot[2].du0_v[2] = 1.0e-300;
        at_knot[2].rel_k[2][2] = 0.1 + 0.2; // not the shortest decimal of a "round" number
    }
    p.constants.u0_v[0] = -0.0;
    let text = CalibrationFile::from_params(&p, &SAMPLE_META).to_toml();
    let blob = CalibrationFile::from_toml(&text).unwrap().to_blob().unwrap();
    let back = CalibrationFile::from_blob(&blob).unwrap();
    assert_eq!(back.to_toml(), text);
    assert_eq!(bits(&back.to_params().unwrap().0), bits(&p));
}

fn error_of(text: &str) -> String {
    match CalibrationFile::from_toml(text).and_then(|f| f.to_blob()) {
        Ok(_) => panic!("accepted:\n{text}"),
        Err(e) => e.to_string(),
    }
}

fn sample_text() -> String {
    CalibrationFile::from_params(&sample_params(), &SAMPLE_META).to_toml()
}

/// Every edited text differs from `original` and is refused with a one-line error naming its key.
fn assert_rejected_naming(original: &str, cases: &[(String, &str)]) {
    for (text, key) in cases {
        assert_ne!(text, original, "edit applies for {key}");
        let e = error_of(text);
        assert!(e.contains(key), "error {e:?} should name {key:?}");
        assert!(!e.contains('\n'), "one line: {e:?}");
    }
}

#[test]
fn malformed_files_are_rejected_naming_the_key() {
    let s = sample_text();
    let cases: [(String, &str); 12] = [
        (s.replace("t0_C = 20.0\n", ""), "t0_C"),
        (s.replace("t0_C = 20.0", "t0_C = 20.0\nt0_K = 293.15"), "t0_K"),
        (s.replace("t0_C = 20.0", "t0_C = \"twenty\""), "line"),
        (s.replace("form = \"simplified\"\n", ""), "method.form"),
        (s.replace("kind = \"output-correction\"", "kind = \"coefficient-correction\""), "method.form"),
        (s.replace("form = \"simplified\"", "form = \"approximate\""), "approximate"),
        (s.replace("kind = \"pwl\"", "kind = \"poly\""), "temperature_model.knot"),
        (s.replace("t0_C = 20.0", "t0_C = 80.0"), "temp_range_C"),
        (
            s.replace("serial = \"PAPER-T1T2\"", "serial = \"PAPER-T1T2\"\ncalibration_date = 2024-01-15T10:00:00"),
            "calibration_date",
        ),
        (s.replace("serial = \"PAPER-T1T2\"", "serial = \"\""), "serial"),
        (s.replace("serial = \"PAPER-T1T2\"", "serial = \"PAPER-T1T2-ÄÖÜ\""), "serial"),
        (s.replace("t_C = 70.0", "t_C = 10.0"), "temperature_model.knot[2].t_C"),
    ];
    assert_rejected_naming(&s, &cases);
    // A physically impossible value names the key and its limit, not a blob offset.
    let k01 = sample_params().constants.k_v_per_g[0][1];
    let e = error_of(&s.replace(&format!("{k01}"), "0.3"));
    assert!(e.starts_with("k_V_per_g[0][1] out of range"), "{e}");
    assert!(!e.contains("byte"), "{e}");
}

#[test]
fn term_powers_must_be_in_order() {
    let quad = paper::params(paper::quadratic_truth().unwrap(), Method::CoefficientCorrection);
    let text = CalibrationFile::from_params(&quad, &Meta::default()).to_toml();
    assert!(text.contains("power = 2"));
    let e = CalibrationFile::from_toml(&text.replace("power = 2", "power = 3")).unwrap().to_params().unwrap_err();
    assert_eq!(
        e,
        CalFileError::Key {
            key: "temperature_model.term[1].power".into(),
            message: "3, expected 2 (terms in order of power)".into()
        }
    );
}

// ---- property: TOML → blob → TOML is lossless ----------------------------------------------

fn all_methods() -> Vec<Method> {
    vec![
        Method::Uncorrected,
        Method::CoefficientCorrection,
        Method::OutputCorrection(Form::Full),
        Method::OutputCorrection(Form::Simplified),
        Method::OutputCorrection(Form::Linearized),
    ]
}

/// Coefficients whose effect stays small for |ΔT| ≤ 100 °C.
fn arb_coef(power: i32) -> impl Strategy<Value = CoefDelta<f64>> {
    let s = 0.05 / 100f64.powi(power);
    prop::array::uniform12(-1.0f64..1.0).prop_map(move |a| CoefDelta::from_array(&a.map(|x| x * s)))
}

fn arb_model(lo: f64, hi: f64) -> impl Strategy<Value = TempModel<f64>> {
    let poly =
        (1..=MAX_POLY_ORDER, (arb_coef(1), arb_coef(2), arb_coef(3), arb_coef(4))).prop_map(|(order, (a, b, c, d))| {
            let mut coef = [a, b, c, d];
            coef[order..].fill(CoefDelta::zero());
            TempModel::Poly { order: order as u8, coef }
        });
    let pwl = (2..=MAX_KNOTS).prop_flat_map(move |n| {
        (prop::collection::vec(-0.3f64..0.3, n), prop::collection::vec(arb_coef(0), n)).prop_map(move |(jit, sets)| {
            let mut knots_c = [0.0; MAX_KNOTS];
            let mut at_knot = [CoefDelta::zero(); MAX_KNOTS];
            let step = (hi - lo) / (n - 1) as f64;
            for i in 0..n {
                // Jittered about the even grid but inside what a blob holds ([-100, 200] °C):
                // the first knot of a wide range jittered outward once fell at -102 °C.
                knots_c[i] = (lo + step * (i as f64 + jit[i])).clamp(-100.0, 200.0);
                at_knot[i] = sets[i];
            }
            TempModel::Pwl { n_knots: n as u8, knots_c, at_knot }
        })
    });
    prop_oneof![poly, pwl]
}

fn arb_params() -> impl Strategy<Value = CalibrationParams> {
    (-20.0f64..40.0, 1.0f64..60.0, 1.0f64..60.0).prop_flat_map(|(t0_c, below, above)| {
        let (lo, hi) = (t0_c - below, t0_c + above);
        (
            prop::array::uniform3(prop_oneof![0.05f64..5.0, -5.0f64..-0.05]),
            prop::array::uniform6(-0.02f64..0.02),
            prop::array::uniform3(-0.5f64..0.5),
            arb_model(lo, hi),
            prop::sample::select(all_methods()),
        )
            .prop_map(move |(diag, cross, u0_v, model, method)| {
                let mut k = [[0.0; 3]; 3];
                let mut c = cross.iter();
                for i in 0..3 {
                    for j in 0..3 {
                        k[i][j] = if i == j { diag[i] } else { c.next().unwrap() * diag[i].abs() };
                    }
                }
                CalibrationParams {
                    constants: Constants { k_v_per_g: k, u0_v },
                    t0_c,
                    model,
                    method,
                    temp_range_c: (lo, hi),
                }
            })
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn toml_blob_toml_is_lossless(
        p in arb_params(),
        serial in prop::option::of("[ -~]{1,32}"),
        tool in "[ -~]{1,32}",
        date in prop::option::of((1970u16..=9999, 1u8..=12, 1u8..=28)),
    ) {
        let date = date.map(|(year, month, day)| CalDate { year, month, day });
        let meta = Meta { serial: serial.as_deref().unwrap_or(""), date, tool_version: &tool };
        let text = CalibrationFile::from_params(&p, &meta).to_toml();
        let file = CalibrationFile::from_toml(&text).expect("own output parses");
        let (back, back_meta) = file.to_params().expect("structurally valid");
        prop_assert_eq!(bits(&back), bits(&p));
        prop_assert_eq!(back_meta.as_meta(), meta);
        let blob = file.to_blob().expect("valid calibration encodes");
        let again = CalibrationFile::from_blob(&blob).expect("blob parses");
        prop_assert_eq!(again.to_toml(), text);
        prop_assert_eq!(again, file);
    }
}

// ---- the vibration-error model ------------------------------------------------------------

fn vib_sample() -> VibrationParams {
    let mut v = VibrationParams::new([tables::AL15, ConversionFunction::default(), tables::AL15], Variant::Exact);
    let (profiles, n) = tables::flight_profiles();
    for p in &profiles[..n as usize] {
        v.push_profile(*p).unwrap();
    }
    v.push_profile(Vibration::None).unwrap();
    v
}

fn vib_text() -> String {
    CalibrationFile::from_parts(&sample_params(), Some(&vib_sample()), &SAMPLE_META).to_toml()
}

#[test]
fn vibration_model_round_trips_through_toml_and_blob() {
    let text = vib_text();
    assert!(text.contains("[vibration]\nvariant = \"exact\""), "{text}");
    assert!(text.contains("[vibration.x]") && text.contains("k2_g_per_g2 = 0.000105"), "{text}");
    assert!(text.contains("[[vibration.profile]]\nkind = \"sine\""), "{text}");
    assert!(text.contains("kind = \"random\"") && text.contains("band_Hz = [320.0, 640.0]"), "{text}");
    let file = CalibrationFile::from_toml(&text).unwrap();
    assert_eq!(file.to_vibration().unwrap(), Some(vib_sample()));
    let bytes = file.to_blob().unwrap();
    let parsed = blob::parse(&bytes).unwrap();
    assert_eq!(parsed.vibration, Some(vib_sample()));
    let back = CalibrationFile::from_blob(&bytes).unwrap();
    assert_eq!(back, file);
    assert_eq!(back.to_toml(), text);
    // Without `[vibration]`: no VE model, no vibration section.
    let plain = CalibrationFile::from_toml(&sample_text()).unwrap();
    assert_eq!(plain.to_vibration().unwrap(), None);
    assert_eq!(blob::parse(&plain.to_blob().unwrap()).unwrap().vibration, None);
}

#[test]
fn vibration_tables_may_omit_axes_and_coefficients() {
    let s = sample_text()
        + "\n[vibration]\nvariant = \"paper\"\n\n[vibration.y]\nk2_g_per_g2 = 1e-4\nm31_g_per_g2 = 2e-5\n";
    let v = CalibrationFile::from_toml(&s).unwrap().to_vibration().unwrap().unwrap();
    assert_eq!(v.variant, Variant::Paper);
    assert_eq!(v.cf[0], ConversionFunction::default());
    assert_eq!(v.cf[1], ConversionFunction { k2_g_per_g2: 1e-4, m31_g_per_g2: 2e-5, ..Default::default() });
    assert_eq!(v.n_profiles, 0);
}

#[test]
fn malformed_vibration_keys_are_rejected_naming_the_key() {
    let s = vib_text();
    let nine = s.clone() + &"\n[[vibration.profile]]\nkind = \"none\"\n".repeat(2);
    let cases: [(String, &str); 9] = [
        (s.replace("variant = \"exact\"", "variant = \"approximate\""), "approximate"),
        (s.replace("variant = \"exact\"\n", ""), "variant"),
        (s.replace("k3_g_per_g3 = 0.000087", "k3_g_per_g3 = 0.000087\nk6_g_per_g6 = 1.0"), "k6_g_per_g6"),
        (s.replacen("kind = \"sine\"", "kind = \"square\"", 1), "square"),
        (s.replacen("freq_Hz", "frequency_Hz", 1), "frequency_Hz"),
        (nine, "vibration.profile"),
        (s.replacen("k2_g_per_g2 = 0.000105", "k2_g_per_g2 = 0.05", 1), "vibration.x.k2_g_per_g2"),
        (s.replace("band_Hz = [320.0, 640.0]", "band_Hz = [320.0, 300.0]"), "vibration.profile[6].band_Hz[1]"),
        (s.replacen("delta_1a = 0.000015", "delta_1a = nan", 1), "vibration.x.delta_1a"),
    ];
    assert_rejected_naming(&s, &cases);
    for (text, _) in &cases {
        assert!(!error_of(text).contains("byte"), "{}", error_of(text));
    }
}

fn arb_vibration() -> impl Strategy<Value = VibrationParams> {
    let profile = prop_oneof![
        Just(Vibration::None),
        (prop::array::uniform3(-10.0f64..=10.0), 0.0f64..1e4)
            .prop_map(|(amp_g, freq_hz)| Vibration::Harmonic { amp_g, freq_hz }),
        (prop::array::uniform3(0.0f64..=10.0), 0.0f64..1e4, 1.0f64..1e4)
            .prop_map(|(sigma_g, lo, w)| Vibration::Random { sigma_g, band_hz: (lo, lo + w) }),
    ];
    (prop::array::uniform3(prop::array::uniform10(-1.0f64..1.0)), any::<bool>(), prop::collection::vec(profile, 0..=8))
        .prop_map(|(cf, paper, profiles)| {
            let cf = cf.map(|a| {
                let mut out = [0.0; 10];
                for (n, x) in a.iter().enumerate() {
                    out[n] = x * blob::coefficient_limit(n as u8);
                }
                ConversionFunction::from_array(&out)
            });
            let mut v = VibrationParams::new(cf, if paper { Variant::Paper } else { Variant::Exact });
            for p in profiles {
                v.push_profile(p).unwrap();
            }
            v
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]

    #[test]
    fn toml_blob_toml_with_vibration_is_lossless(p in arb_params(), v in arb_vibration()) {
        let text = CalibrationFile::from_parts(&p, Some(&v), &SAMPLE_META).to_toml();
        let file = CalibrationFile::from_toml(&text).expect("own output parses");
        prop_assert_eq!(file.to_vibration().expect("structurally valid"), Some(v));
        let blob = file.to_blob().expect("valid calibration encodes");
        let again = CalibrationFile::from_blob(&blob).expect("blob parses");
        prop_assert_eq!(again.to_toml(), text);
        prop_assert_eq!(again, file);
    }
}

// ---- thermal dynamics -----------------------------------------------------------------------

fn dynamics_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../calibrations/paper-two-range-dynamics.toml")
}

#[test]
fn thermal_dynamics_table_round_trips_in_mg_and_reaches_the_core_in_g() {
    let file = CalibrationFile::read(&dynamics_path()).unwrap();
    let d = file.dynamics().unwrap().expect("the file has [thermal_dynamics]");
    // Written independently of the conversion: the file's mg as g.
    let want = ThermalDynamics {
        lag_tau_s: 2.0,
        hysteresis_width_c: 0.05,
        self_heating_c: 0.5,
        self_heating_tau_s: 3.0,
        bias_play_width_c: 0.1,
        bias_play_g: [0.02e-3, -0.015e-3, 0.01e-3],
    };
    for (a, b) in d.to_array().iter().zip(want.to_array()) {
        assert!((a - b).abs() <= 1e-18 + 1e-15 * b.abs(), "{a} != {b}");
    }
    // The blob carries the section; file → blob → file is lossless, text included.
    let bytes = file.check().unwrap();
    assert_eq!(blob::parse(&bytes).unwrap().dynamics, Some(d));
    let back = CalibrationFile::from_blob(&bytes).unwrap();
    assert_eq!(back.thermal_dynamics, file.thermal_dynamics);
    let text = back.to_toml();
    assert!(text.contains("[thermal_dynamics]\nlag_tau_s = 2.0\nhysteresis_width_C = 0.05\n"), "{text}");
    assert!(text.contains("bias_play_mg = [0.02, -0.015, 0.01]"), "{text}");
    assert_eq!(CalibrationFile::from_toml(&text).unwrap(), back);
    // Without the table: no dynamics, no section.
    let plain = CalibrationFile::from_toml(&sample_text()).unwrap();
    assert_eq!(plain.dynamics().unwrap(), None);
    assert_eq!(blob::parse(&plain.to_blob().unwrap()).unwrap().dynamics, None);
}

#[test]
fn thermal_dynamics_keys_may_be_omitted() {
    let s = sample_text() + "\n[thermal_dynamics]\nlag_tau_s = 150.0\n";
    let d = CalibrationFile::from_toml(&s).unwrap().dynamics().unwrap().unwrap();
    assert_eq!(d, ThermalDynamics { lag_tau_s: 150.0, ..ThermalDynamics::none() });
}

#[test]
fn malformed_thermal_dynamics_are_rejected_naming_the_key() {
    let s = CalibrationFile::read(&dynamics_path()).unwrap().to_toml();
    let cases: [(String, &str); 9] = [
        (s.replace("lag_tau_s = 2.0", "lag_tau_s = -2.0"), "thermal_dynamics.lag_tau_s out of range"),
        (s.replace("hysteresis_width_C = 0.05", "hysteresis_width_C = 60.0"), "thermal_dynamics.hysteresis_width_C"),
        (s.replace("self_heating_C = 0.5", "self_heating_C = nan"), "thermal_dynamics.self_heating_C"),
        (s.replace("self_heating_tau_s = 3.0", "self_heating_tau_s = 1e6"), "thermal_dynamics.self_heating_tau_s"),
        (s.replace("bias_play_width_C = 0.1", "bias_play_width_C = -0.1"), "thermal_dynamics.bias_play_width_C"),
        (s.replace("[0.02, -0.015, 0.01]", "[0.02, -150.0, 0.01]"), "thermal_dynamics.bias_play_mg[1]"),
        (s.replace("bias_play_width_C = 0.1", "bias_play_width_C = 0.0"), "thermal_dynamics.bias_play_mg[0]"),
        (s.replace("lag_tau_s = 2.0", "lag_tau_min = 2.0"), "lag_tau_min"),
        (s.replace("lag_tau_s = 2.0", "lag_tau_s = \"slow\""), "lag_tau_s"),
    ];
    assert_rejected_naming(&s, &cases);
    for (text, _) in &cases {
        assert!(!error_of(text).contains("byte"), "{}", error_of(text));
    }
    let e = error_of(&s.replace("[0.02, -0.015, 0.01]", "[0.02, -150.0, 0.01]"));
    assert!(e.contains("[-100, 100] mg"), "the limit in the file's unit: {e}");
}

fn round_trip_mg(mg: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    let s = sample_text()
        + &format!(
            "\n[thermal_dynamics]\nbias_play_width_C = 0.2\nbias_play_mg = [{:?}, {:?}, {:?}]\n",
            mg[0], mg[1], mg[2]
        );
    let file = CalibrationFile::from_toml(&s).unwrap();
    let g = file.dynamics().unwrap().unwrap().bias_play_g;
    let back = CalibrationFile::from_blob(&file.check().unwrap()).unwrap();
    let g_back = back.dynamics().unwrap().unwrap().bias_play_g;
    assert_eq!(g.map(f64::to_bits), g_back.map(f64::to_bits), "g changed: {mg:?}");
    (back.thermal_dynamics.unwrap().bias_play_mg, g)
}

proptest! {
    /// The bias the core uses (g) survives file → blob → file → blob bit for bit. The mg
    /// written back is the one nearest g·1000 that gives the same g: the file's own value
    /// when it has up to 12 significant digits, else within an ulp of it (two mg values
    /// can give the same g).
    #[test]
    fn bias_play_round_trips(mg in prop::array::uniform3(-100.0f64..=100.0), n in prop::array::uniform3(-100_000_000i64..=100_000_000)) {
        let (back, _) = round_trip_mg(mg);
        for (a, b) in back.iter().zip(mg) {
            prop_assert!((a.to_bits() as i64 - b.to_bits() as i64).abs() <= 1, "{a:?} vs {b:?}");
        }
        let decimal = n.map(|k| k as f64 / 1e6);
        let (back, _) = round_trip_mg(decimal);
        prop_assert_eq!(back.map(f64::to_bits), decimal.map(f64::to_bits));
    }
}
