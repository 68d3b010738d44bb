//! The simulator against independent references: the paper's tables through the six-position
//! formulas, the core's closed-form exact VE, the noise parameters, bit-identical seeds, and
//! scenario errors that name file, key and reason and leave no output.

use bins_cal::recording::{Reader, Row};
use bins_cal::sim::{Simulation, rectify, scenario};
use bins_comp::ident::six_position;
use bins_comp::vibration::{self, Axis, Variant, Vibration, tables::AL15};
use bins_comp::{Constants, paper};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

#[allow(dead_code)] // the CLI helpers other test files use
mod common;
use common::csv_text::Csv;

fn load(dir: &Path, name: &str, text: &str) -> Simulation {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    scenario::load(&p).unwrap_or_else(|e| panic!("{e}"))
}

/// (pos, chamber_C [m°C], vib_kind, largest vibration level [µg], static force [µg]).
type Key = (String, i64, String, i64, [i64; 3]);

/// Simulates to a file, reads it back, and averages the signals of the rows with a known
/// reference per [`Key`].
#[allow(clippy::type_complexity)]
fn segment_means(sim: &Simulation, dir: &Path, seed: u64) -> BTreeMap<Key, ([f64; 3], usize, Row)> {
    let out = dir.join(format!("rec-{seed}.csv"));
    sim.write("test.toml", seed, &out, false).unwrap();
    let mut r = Reader::open(&out).unwrap();
    let mut row = Row::default();
    let mut acc: BTreeMap<Key, ([f64; 3], usize, Row)> = BTreeMap::new();
    while r.read_row(&mut row).unwrap() {
        let (Some(_), Some(pos)) = (row.reference_f_g(), &row.pos) else { continue };
        let level = row.vib_g.iter().map(|v| v.unwrap_or(0.0).abs()).fold(0.0, f64::max);
        let f = row.reference_f_g().unwrap_or_default();
        let key = (
            pos.clone(),
            (row.chamber_c.unwrap_or(0.0) * 1000.0).round() as i64,
            row.vib_kind.map_or("?", |k| k.as_str()).to_string(),
            (level * 1e6).round() as i64,
            f.map(|x| (x * 1e6).round() as i64),
        );
        let e = acc.entry(key).or_insert(([0.0; 3], 0, row.clone()));
        for i in 0..3 {
            e.0[i] += row.u_v[i];
        }
        e.1 += 1;
    }
    for v in acc.values_mut() {
        v.0 = v.0.map(|s| s / v.1 as f64);
    }
    acc
}

fn tp_means(m: &BTreeMap<Key, ([f64; 3], usize, Row)>, chamber_c: f64) -> [[f64; 3]; 6] {
    std::array::from_fn(|k| {
        let key = (
            format!("TP{}", k + 1),
            (chamber_c * 1000.0).round() as i64,
            "none".to_string(),
            0,
            bins_comp::ident::TILTER_POSITIONS_G[k].map(|x| (x * 1e6).round() as i64),
        );
        m.get(&key).unwrap_or_else(|| panic!("no {key:?}")).0
    })
}

fn assert_constants_close(c: &Constants<f64>, r: &Constants<f64>, tol: f64, what: &str) {
    for i in 0..3 {
        assert!((c.u0_v[i] - r.u0_v[i]).abs() <= tol, "{what}: U0[{i}] {} vs {}", c.u0_v[i], r.u0_v[i]);
        for j in 0..3 {
            let (a, b) = (c.k_v_per_g[i][j], r.k_v_per_g[i][j]);
            assert!((a - b).abs() <= tol, "{what}: K[{i}][{j}] {a} vs {b}");
        }
    }
}

const IDEAL_TILTER: &str = r#"
[recording]
rate_Hz = 10.0
[unit]
preset = "paper"
fit = "poly"
order = 2
[thermal]
rate_C_per_min = inf
[[step]]
kind = "tilter"
dwell_s = 3.0
move_s = 1.0
[[step]]
kind = "soak"
chamber_C = -40.0
dwell_s = 10.0
[[step]]
kind = "tilter"
dwell_s = 3.0
move_s = 1.0
[[step]]
kind = "soak"
chamber_C = 70.0
dwell_s = 10.0
[[step]]
kind = "tilter"
dwell_s = 3.0
move_s = 1.0
"#;

#[test]
fn ideal_tilter_gives_back_the_paper_tables() {
    // Noise off, lags off: the six-position formulas T(10) on the recorded segment means give
    // Tables T1/T2 at each calibration temperature (the truth's quadratic passes through them).
    let dir = tempfile::tempdir().unwrap();
    let sim = load(dir.path(), "ideal.toml", IDEAL_TILTER);
    let m = segment_means(&sim, dir.path(), 1);
    for (t, table) in paper::TABLE_TEMPS_C.iter().zip(paper::TABLE_CONSTANTS.iter()) {
        let c = six_position(&tp_means(&m, *t));
        assert_constants_close(&c, table, 1e-9, &format!("{t} °C"));
    }
    // Each hold is 3 s at 10 Hz: 30 rows, none lost to the moves.
    assert!(m.values().all(|v| v.1 == 30), "{:?}", m.values().map(|v| v.1).collect::<Vec<_>>());
}

#[test]
fn measured_constants_at_several_temperatures_are_the_truth_at_those_temperatures() {
    // Explicit constants at T0 and two more temperatures, piecewise-linear between them.
    let text = r#"
[recording]
rate_Hz = 5.0
[unit]
t0_C = 25.0
k_V_per_g = [[1.0, 0.01, -0.02], [0.005, -0.9, 0.003], [0.0, 0.004, 1.1]]
u0_V = [0.01, -0.02, 0.03]
fit = "pwl"
[[unit.at]]
temp_C = 0.0
k_V_per_g = [[1.001, 0.0102, -0.0199], [0.0051, -0.9003, 0.0031], [0.0, 0.0041, 1.1004]]
u0_V = [0.012, -0.021, 0.028]
[[unit.at]]
temp_C = 60.0
k_V_per_g = [[0.998, 0.0097, -0.0203], [0.0049, -0.8995, 0.0029], [0.0, 0.0039, 1.0991]]
u0_V = [0.007, -0.018, 0.033]
[thermal]
start_C = 0.0
rate_C_per_min = inf
[[step]]
kind = "tilter"
dwell_s = 2.0
[[step]]
kind = "soak"
chamber_C = 60.0
dwell_s = 5.0
[[step]]
kind = "tilter"
dwell_s = 2.0
"#;
    let dir = tempfile::tempdir().unwrap();
    let sim = load(dir.path(), "at.toml", text);
    let m = segment_means(&sim, dir.path(), 1);
    let c0 = six_position(&tp_means(&m, 0.0));
    let c60 = six_position(&tp_means(&m, 60.0));
    let r0 = Constants {
        k_v_per_g: [[1.001, 0.0102, -0.0199], [0.0051, -0.9003, 0.0031], [0.0, 0.0041, 1.1004]],
        u0_v: [0.012, -0.021, 0.028],
    };
    let r60 = Constants {
        k_v_per_g: [[0.998, 0.0097, -0.0203], [0.0049, -0.8995, 0.0029], [0.0, 0.0039, 1.0991]],
        u0_v: [0.007, -0.018, 0.033],
    };
    assert_constants_close(&c0, &r0, 1e-9, "0 °C");
    assert_constants_close(&c60, &r60, 1e-9, "60 °C");
}

#[test]
fn constants_follow_the_die_and_the_column_is_the_thermistor() {
    // Self-heating puts the die 5 °C above the case; the thermistor sits on the case. At
    // equilibrium the temperature column reads the chamber, the constants are those at +5 °C.
    let text = r#"
[recording]
rate_Hz = 10.0
power_on_s = 1.0e6
[unit]
preset = "paper"
[thermal]
start_C = 20.0
die_tau_s = 10.0
self_heating_C = 5.0
thermistor_at = 0.0
[[step]]
kind = "tilter"
dwell_s = 2.0
"#;
    let dir = tempfile::tempdir().unwrap();
    let sim = load(dir.path(), "die.toml", text);
    let m = segment_means(&sim, dir.path(), 1);
    assert!(m.values().all(|v| v.2.temp_c == 20.0));
    let c = six_position(&tp_means(&m, 20.0));
    let truth = bins_comp::CalibrationParams {
        constants: paper::TABLE_CONSTANTS[0],
        t0_c: paper::T0_C,
        model: paper::quadratic_truth().unwrap(),
        method: bins_comp::Method::Uncorrected,
        temp_range_c: paper::TEMP_RANGE_C,
    };
    assert_constants_close(&c, &truth.constants_at(25.0), 1e-9, "die at 25 °C");
    // And differs visibly from the constants at the thermistor's 20 °C.
    let diff = (c.u0_v[0] - paper::TABLE_CONSTANTS[0].u0_v[0]).abs();
    assert!(diff > 1e-4, "{diff}");
}

#[test]
fn thermistor_lags_the_chamber_step_exponentially() {
    // Chamber jumps 20 → 30 °C; case τ = 50 s, thermistor on the case without its own lag:
    // temp_C = 30 − 10·e^(−t/τ) (the exact discretisation, to the resolution 0.01 °C).
    let text = r#"
[recording]
rate_Hz = 1.0
[unit]
preset = "paper"
[thermal]
start_C = 20.0
rate_C_per_min = inf
case_tau_s = 50.0
[noise]
temp_resolution_C = 0.01
[[step]]
kind = "soak"
chamber_C = 30.0
dwell_s = 200.0
"#;
    let dir = tempfile::tempdir().unwrap();
    let sim = load(dir.path(), "lag.toml", text);
    let mut rows = sim.rows(1);
    let mut row = Row::default();
    let mut n = 0;
    while rows.next_row(&mut row) {
        let expect = 30.0 - 10.0 * (-row.t_s / 50.0).exp();
        assert!((row.temp_c - expect).abs() <= 0.005 + 1e-9, "t = {}: {} vs {expect}", row.t_s, row.temp_c);
        n += 1;
    }
    assert_eq!(n, 200);
}

#[test]
fn noise_has_the_scenario_statistics_and_the_adc_step() {
    let text = r#"
[recording]
rate_Hz = 100.0
[unit]
preset = "paper"
[noise]
white_V = [1.0e-4, 2.0e-4, 5.0e-5]
adc_lsb_V = 1.0e-6
[[step]]
kind = "hold"
position = "TP1"
dwell_s = 200.0
"#;
    let dir = tempfile::tempdir().unwrap();
    let sim = load(dir.path(), "noise.toml", text);
    let mut rows = sim.rows(3);
    let mut row = Row::default();
    let (mut s1, mut s2, mut n) = ([0.0; 3], [0.0; 3], 0.0);
    let ideal = paper::TABLE_CONSTANTS[0].signals_v(&[0.0, 0.0, 1.0]);
    while rows.next_row(&mut row) {
        for i in 0..3 {
            let x = row.u_v[i] - ideal[i];
            s1[i] += x;
            s2[i] += x * x;
            // On the ADC grid.
            let q = row.u_v[i] * 1e6;
            assert!((q - q.round()).abs() < 1e-6, "{}", row.u_v[i]);
        }
        n += 1.0;
    }
    assert_eq!(n, 20000.0);
    for (i, want) in [1.0e-4, 2.0e-4, 5.0e-5].iter().enumerate() {
        let mean = s1[i] / n;
        let sd = (s2[i] / n - mean * mean).sqrt();
        // 20 000 samples: the sd is within 2 % (5 σ of its sampling error plus the ADC step).
        assert!((sd / want - 1.0).abs() < 0.025, "axis {i}: sd {sd} vs {want}");
        assert!(mean.abs() < 5.0 * want / n.sqrt(), "axis {i}: mean {mean}");
    }
}

#[test]
fn warmup_transient_decays_with_its_time_constant() {
    let text = r#"
[recording]
rate_Hz = 2.0
[unit]
preset = "paper"
warmup_V = [1.0e-3, 0.0, -2.0e-3]
warmup_tau_s = 30.0
[[step]]
kind = "hold"
position = "TP1"
dwell_s = 100.0
"#;
    let dir = tempfile::tempdir().unwrap();
    let sim = load(dir.path(), "warm.toml", text);
    let ideal = paper::TABLE_CONSTANTS[0].signals_v(&[0.0, 0.0, 1.0]);
    let mut rows = sim.rows(1);
    let mut row = Row::default();
    while rows.next_row(&mut row) {
        let w = (-row.t_s / 30.0).exp();
        assert!((row.u_v[0] - ideal[0] - 1e-3 * w).abs() < 1e-15);
        assert!((row.u_v[2] - ideal[2] + 2e-3 * w).abs() < 1e-15);
        assert_eq!(row.power_s, Some(row.t_s));
    }
}

#[test]
fn quadrature_equals_the_cores_exact_closed_forms() {
    // The simulator's rectified means (quadrature of V(2)) minus V(2)'s static value are the
    // VE; the core's exact formulas (moments, exact |a3| terms) must agree to rounding, for
    // static IA accelerations inside and outside the vibration amplitude.
    for &(a_p3, level) in &[(0.0, 0.42), (0.3, 1.0), (-0.7, 1.5), (1.0, 0.5), (-9.0, 3.0), (2.0, 4.0)] {
        for axis in Axis::ALL {
            let mut f = [0.2, -0.4, 0.1];
            let mut amp = [0.8 * level, 0.6 * level, -0.5 * level];
            // Put a_p3 and the level on this accelerometer's IA.
            let ia = axis as usize;
            f[ia] = a_p3;
            amp[ia] = level;
            let cfs = [AL15; 3];
            for vib in [
                Vibration::Harmonic { amp_g: amp, freq_hz: 16.0 },
                Vibration::Random { sigma_g: amp, band_hz: (20.0, 80.0) },
            ] {
                let rect = rectify::rectified_g(&cfs, &f, &vib)[ia];
                let stat = rectify::rectified_g(&cfs, &f, &Vibration::None)[ia];
                let ve = rect - stat;
                let exact = vibration::ve_terms(&AL15, Variant::Exact, &vib.on_accel(axis), a_p3).total_g(a_p3);
                assert!(
                    (ve - exact).abs() <= 1e-9 * exact.abs() + 1e-15,
                    "{axis:?} a_p3 {a_p3} {vib:?}: quadrature {ve} vs exact {exact}"
                );
            }
        }
    }
}

const SHAKER: &str = r#"
[recording]
rate_Hz = 100.0
[unit]
preset = "al15"
[noise]
vibration_sampling = SAMPLING
[[step]]
kind = "shake"
accelerometer = "x"
vibration = "sine"
freq_Hz = 16.0
levels_g = [0.42, 2.0]
quiet_s = 2.0
shake_s = 2.5
move_s = 1.0
[[step]]
kind = "shake"
accelerometer = "y"
vibration = "random"
band_Hz = [20.0, 80.0]
levels_g = [1.0]
quiet_s = 2.0
shake_s = 2.0
move_s = 1.0
"#;

fn check_shaker_ve(sampling: bool) {
    // The recorded ΔU = ⟨U^B⟩ − U per position, over K1, against the core's exact VE at that
    // position's static acceleration and vibration: within 0.5 %.
    let dir = tempfile::tempdir().unwrap();
    let sim = load(dir.path(), "shaker.toml", &SHAKER.replace("SAMPLING", &sampling.to_string()));
    let m = segment_means(&sim, dir.path(), 1);
    let k1 = vibration::tables::AL15_K1_V_PER_G;
    let mut checked = 0;
    for ((pos, ch, kind, _, f_key), (u, _, row)) in &m {
        if kind == "none" || (sampling && kind == "random") {
            continue;
        }
        let quiet = &m[&(pos.clone(), *ch, "none".to_string(), 0, *f_key)];
        let vib = row.vibration().unwrap();
        let f = row.reference_f_g().unwrap();
        for axis in Axis::ALL {
            let i = axis as usize;
            let du = (u[i] - quiet.0[i]) / k1;
            let a_p3 = f[i];
            let exact = vibration::ve_terms(&AL15, Variant::Exact, &vib.on_accel(axis), a_p3).total_g(a_p3);
            assert!(
                (du - exact).abs() <= 0.005 * exact.abs() + 1e-12,
                "{pos} {kind} {axis:?}: simulated {du} vs exact {exact}"
            );
            if exact.abs() > 1e-6 {
                checked += 1;
            }
        }
    }
    assert!(checked >= 20, "{checked}");
}

#[test]
fn shaker_rectified_means_equal_the_cores_exact_ve() {
    check_shaker_ve(false);
}

#[test]
fn sine_sampling_fluctuation_averages_out_over_whole_periods() {
    check_shaker_ve(true);
}

fn bin() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_bins-cal"))
}

fn scenario_path(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios").join(name)
}

#[test]
fn a_seed_reproduces_the_file_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let run = |seed: &str, out: &str| {
        let o = Command::new(bin())
            .args(["simulate", "--quiet", "--seed", seed, "-o"])
            .arg(dir.path().join(out))
            .arg(scenario_path("paper-shaker.toml"))
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        std::fs::read(dir.path().join(out)).unwrap()
    };
    let a = run("42", "a.csv");
    let b = run("42", "b.csv");
    let c = run("43", "c.csv");
    assert!(a.len() > 1_000_000);
    assert!(a == b, "same seed, different files");
    assert!(a != c, "different seeds, same file");
    // Only the noise differs: same rows, same header.
    assert_eq!(a.iter().filter(|&&x| x == b'\n').count(), c.iter().filter(|&&x| x == b'\n').count());
}

#[test]
fn shipped_scenarios_build_and_read_back() {
    for name in ["paper-tilter.toml", "paper-shaker.toml", "flight.toml"] {
        let sim = scenario::load(&scenario_path(name)).unwrap_or_else(|e| panic!("{e}"));
        assert!(sim.n_rows() > 10_000, "{name}");
    }
    // The benchmark day: exactly 24 h at 100 Hz.
    let day = scenario::load(&scenario_path("day-100hz.toml")).unwrap();
    assert_eq!(day.n_rows(), 8_640_000);
    // The flight: all Table V2/V3 profiles appear with their levels in the reference columns.
    let sim = scenario::load(&scenario_path("flight.toml")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("flight.csv");
    sim.write("flight.toml", 5, &out, false).unwrap();
    let (profiles, n) = vibration::tables::flight_profiles();
    let mut seen = vec![false; n as usize];
    for row in Reader::open(&out).unwrap() {
        let row = row.unwrap();
        if let Some(v) = row.vibration() {
            for (k, p) in profiles.iter().take(n as usize).enumerate() {
                let close = match (p, &v) {
                    (Vibration::Harmonic { amp_g: a, freq_hz: f }, Vibration::Harmonic { amp_g: b, freq_hz: g }) => {
                        a == b && (f - g).abs() < 1e-12
                    }
                    (Vibration::Random { sigma_g: a, band_hz: x }, Vibration::Random { sigma_g: b, band_hz: y }) => {
                        a == b && (x.0 - y.0).abs() < 1e-9 && (x.1 - y.1).abs() < 1e-9
                    }
                    _ => false,
                };
                seen[k] |= close;
            }
        }
    }
    assert!(seen.iter().all(|&s| s), "{seen:?}");
}

/// Runs the CLI on a bad scenario; returns its stderr after checking the exit status and that
/// neither the output nor a temporary file was left.
fn bad(text: &str) -> String {
    let dir = tempfile::tempdir().unwrap();
    let scen = dir.path().join("bad.toml");
    std::fs::write(&scen, text).unwrap();
    let out = dir.path().join("out.csv");
    let o = Command::new(bin()).args(["simulate", "--quiet", "-o"]).arg(&out).arg(&scen).output().unwrap();
    assert_eq!(o.status.code(), Some(1), "{text}");
    let files: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(files, [std::ffi::OsString::from("bad.toml")], "left behind: {files:?}");
    let err = String::from_utf8(o.stderr).unwrap();
    assert!(err.contains("bad.toml"), "no file name: {err}");
    err
}

const GOOD: &str = "[recording]\nrate_Hz = 10.0\n[unit]\npreset = \"paper\"\n";

#[test]
fn bad_scenarios_name_file_key_and_reason_and_leave_nothing() {
    let e = bad(&format!("{GOOD}colour = \"red\"\n[[step]]\nkind = \"tilter\"\ndwell_s = 1.0\n"));
    assert!(e.contains("unit") && e.contains("unknown field `colour`"), "{e}");
    let e = bad(&format!("{GOOD}[[step]]\nkind = \"tilter\"\ndwell_s = 1.0\nspeed = 3\n"));
    assert!(e.contains("step[0]") && e.contains("unknown field `speed`"), "{e}");
    let e = bad(&format!("{GOOD}[[step]]\nkind = \"tilter\"\n"));
    assert!(e.contains("step[0]") && e.contains("missing field `dwell_s`"), "{e}");
    let e = bad(&format!("{GOOD}[[step]]\nkind = \"tilter\"\ndwell_s = -5.0\n"));
    assert!(e.contains("step[0].dwell_s: must be > 0, got -5"), "{e}");
    let e = bad(&format!(
        "{GOOD}[[step]]\nkind = \"tilter\"\ndwell_s = 1.0\n[[step]]\nkind = \"check\"\ntheta_deg = 45.0\ndwell_s = 1.0\n"
    ));
    assert!(e.contains("step[1].theta_deg: must be in [0, 45)"), "{e}");
    let e = bad(&format!("{GOOD}[[step]]\nkind = \"spin\"\ndwell_s = 1.0\n"));
    assert!(e.contains("step[0]") && e.contains("unknown variant `spin`"), "{e}");
    let e = bad(&format!("{GOOD}[[step]]\nkind = \"tilter\"\ndwell_s = 1.0\npositions = [1, 7]\n"));
    assert!(e.contains("step[0].positions[1]: position 7 does not exist"), "{e}");
    let e = bad("[recording]\nrate_Hz = 0.0\n[unit]\npreset = \"paper\"\n[[step]]\nkind = \"tilter\"\ndwell_s = 1.0\n");
    assert!(e.contains("recording.rate_Hz: must be > 0"), "{e}");
    let e = bad(&format!(
        "{GOOD}[[step]]\nkind = \"shake\"\naccelerometer = \"x\"\nvibration = \"sine\"\nlevels_g = [1.0]\nquiet_s = 1.0\nshake_s = 1.0\n"
    ));
    assert!(e.contains("step[0].freq_Hz: required for sine"), "{e}");
    let e = bad(&format!("{GOOD}[thermal]\nthermistor_at = 2.0\n[[step]]\nkind = \"tilter\"\ndwell_s = 1.0\n"));
    assert!(e.contains("thermal.thermistor_at: must be in [0, 1]"), "{e}");
    let e = bad("[recording]\nrate_Hz = 10.0\n[unit]\npreset = \"paper\"\n[[step]]\nkind = tilter\n");
    assert!(e.contains("bad.toml:6"), "syntax error without its line: {e}");
    let e = bad(&format!(
        "{GOOD}[[step]]\nkind = \"hold\"\nposition = \"TP1\"\ndwell_s = 1.0\nvibration = {{ kind = \"sine\", amp_g = [20.0, 0.0, 0.0], freq_Hz = 10.0 }}\n"
    ));
    assert!(e.contains("step[0].vibration: not a valid vibration"), "{e}");
}

#[test]
fn an_unwritable_output_names_the_file() {
    let o = Command::new(bin())
        .args(["simulate", "--quiet", "-o", "/nonexistent-dir/out.csv"])
        .arg(scenario_path("flight.toml"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("/nonexistent-dir/out.csv"));
}

#[test]
fn an_output_dropped_before_commit_leaves_nothing() {
    use std::io::Write;
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("rec.csv");
    {
        let mut f = bins_cal::fsio::AtomicFile::create(&out).unwrap();
        f.writer().write_all(b"t_s,ux_V\n").unwrap();
        // An error on the way: dropped without commit.
    }
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    let mut f = bins_cal::fsio::AtomicFile::create(&out).unwrap();
    f.writer().write_all(b"done\n").unwrap();
    f.commit().unwrap();
    assert_eq!(std::fs::read(&out).unwrap(), b"done\n");
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}

#[test]
fn al15_preset_is_the_data_file() {
    // data/al15-coefficients.csv (Table V1) against the preset's T(1) constants and V(2).
    let table = Csv::read(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/al15-coefficients.csv"));
    let get = |name: &str| table.num(&table.rows[0], name);
    let (a0, k1) = (get("a0_mg") * 1e-3, get("K1_V_per_g"));
    let (m1, m2) = (get("m1_mg_per_g") * 1e-3, get("m2_mg_per_g") * 1e-3);
    let c = scenario::al15_constants();
    for i in 0..3 {
        assert!((c.k_v_per_g[i][i] - k1).abs() < 1e-15);
        assert!((c.u0_v[i] - k1 * a0).abs() < 1e-15);
        // OA of x is z, of y is x, of z is y; PA is the other one.
        let (oa, pa) = ((i + 2) % 3, (i + 1) % 3);
        assert!((c.k_v_per_g[i][oa] - k1 * m1).abs() < 1e-15);
        assert!((c.k_v_per_g[i][pa] - k1 * m2).abs() < 1e-15);
    }
    let dir = tempfile::tempdir().unwrap();
    let sim = load(
        dir.path(),
        "al.toml",
        "[recording]\nrate_Hz = 1.0\n[unit]\npreset = \"al15\"\n[[step]]\nkind = \"hold\"\nposition = \"TP1\"\ndwell_s = 1.0\n",
    );
    let cf = sim.unit.cf[1];
    let want = [
        get("delta_1A_ppm") * 1e-6,
        get("k2_ug_per_g2") * 1e-6,
        get("k3_ug_per_g3") * 1e-6,
        get("k4_ug_per_g4") * 1e-6,
        get("k5_ug_per_g5") * 1e-6,
        get("m31_ug_per_g2") * 1e-6,
        get("m32_ug_per_g2") * 1e-6,
    ];
    let got =
        [cf.delta_1a, cf.k2_g_per_g2, cf.k3_g_per_g3, cf.k4_g_per_g4, cf.k5_g_per_g5, cf.m31_g_per_g2, cf.m32_g_per_g2];
    for (g, w) in got.iter().zip(want) {
        assert!((g - w).abs() <= 1e-12 * w.abs(), "{g} vs {w}");
    }
}

#[test]
fn a_set_point_inside_one_sample_period_is_not_lost() {
    let text = r#"
[recording]
rate_Hz = 10.0
[unit]
preset = "paper"
[thermal]
rate_C_per_min = inf
[[step]]
kind = "hold"
position = "TP1"
dwell_s = 1.01
[[step]]
kind = "soak"
chamber_C = -40.0
dwell_s = 0.05     # 1.01 … 1.06 s: between the rows at 1.0 and 1.1 s
[[step]]
kind = "hold"
position = "TP2"
dwell_s = 1.0
"#;
    let dir = tempfile::tempdir().unwrap();
    let sim = load(dir.path(), "short.toml", text);
    let mut rows = sim.rows(1);
    let mut row = Row::default();
    let mut last = Row::default();
    while rows.next_row(&mut row) {
        last = row.clone();
    }
    assert_eq!((last.chamber_c, last.temp_c, last.pos.as_deref()), (Some(-40.0), -40.0, Some("TP2")));
}

/// FNV-1a (64 bit) of a file's bytes.
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3))
}

#[test]
fn scenarios_written_before_the_per_axis_and_second_noise_terms_simulate_as_before() {
    // The files the simulator wrote for these scenarios (seed 7) before `bias_tau_s` took a
    // value per axis and the second Gauss–Markov term came: their length and FNV-1a hash.
    let dir = tempfile::tempdir().unwrap();
    for (name, len, hash) in [
        ("test-tilter-3t.toml", 478_458, 0xae26_ae55_df16_d7cd_u64),
        ("hand-40.toml", 1_313_792, 0xaaf3_6262_ffa2_1d48),
        ("diagnose-ramps.toml", 1_040_486, 0xef78_9995_65c1_6902),
    ] {
        let out = dir.path().join("out.csv");
        let o = Command::new(bin())
            .args(["simulate", "--quiet", "--seed", "7", "-o"])
            .arg(&out)
            .arg(scenario_path(name))
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let bytes = std::fs::read(&out).unwrap();
        assert_eq!((bytes.len(), fnv1a(&bytes)), (len, hash), "{name}");
    }
    // One correlation time for all axes and the same three times; no second term and a second
    // term of 0: the same rows.
    let base = "[recording]\nrate_Hz = 50.0\n[unit]\npreset = \"paper\"\n[noise]\nwhite_V = 1.0e-5\nrandom_walk_V_per_sqrt_s = 1.0e-7\nbias_instability_V = [3.0e-6, 2.0e-6, 1.0e-6]\nadc_lsb_V = 1.0e-7\n";
    let step = "[[step]]\nkind = \"hold\"\nposition = \"TP1\"\ndwell_s = 40.0\n";
    let rows_of = |extra: &str| {
        let sim = load(dir.path(), "v.toml", &format!("{base}{extra}{step}"));
        let mut g = sim.rows(9);
        let (mut row, mut v) = (Row::default(), Vec::new());
        while g.next_row(&mut row) {
            v.push(row.clone());
        }
        v
    };
    let one = rows_of("bias_tau_s = 30.0\n");
    assert_eq!(one.len(), 2000);
    assert_eq!(one, rows_of("bias_tau_s = [30.0, 30.0, 30.0]\n"));
    assert_eq!(one, rows_of("bias_tau_s = 30.0\nbias_instability2_V = 0.0\nbias_tau2_s = 5.0\n"));
    assert_ne!(one, rows_of("bias_tau_s = [30.0, 30.0, 10.0]\n"));
    assert_ne!(one, rows_of("bias_tau_s = 30.0\nbias_instability2_V = [0.0, 0.0, 1.0e-6]\nbias_tau2_s = 5.0\n"));
    // A second term needs its time where it is given.
    let e = bad(&format!(
        "{base}bias_tau_s = 30.0\nbias_instability2_V = [0.0, 1.0e-6, 0.0]\nbias_tau2_s = [1.0, 0.0, 1.0]\n{step}"
    ));
    assert!(e.contains("bias_tau2_s[1]"), "{e}");
}
