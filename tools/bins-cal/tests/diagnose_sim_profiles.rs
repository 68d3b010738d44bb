//! The diagnosis on user profiles made with the project's simulator (`bins_cal::sim`), not by
//! the blind generator: the paper's unit with a die that self-heats after each power-on and a
//! thermistor partly on the die, in SIM and REAL alike; REAL with some of a warm-up, a die lag
//! behind the case (90–240 s) and a thermal play (0.2–0.6 °C) that SIM lacks. The profiles are
//! the kinds users run: one power-on hot then cooling; two sessions joined with an hour
//! unpowered between; a die lag alone, powered on cold then heating (sometimes reversing); and
//! all three mechanisms together (lag 300 s, a play, a warm-up of 900 s) on any of those.
//!
//! Each case is scored as the blind draws are (docs/diagnosis-blind.md): every mechanism in
//! REAL named exactly or inside a group that holds it; a **definite false name** (an effect that
//! is none of them, or a group that holds none); and every accelerometer's held-out RMS after
//! against before and against 1.25× its floor.
//!
//! ```sh
//! SIMPROF_SEED=1 SIMPROF_CASES=24 cargo test -p bins-cal --release --test diagnose_sim_profiles -- --ignored --nocapture
//! ```
//!
//! With `SIMPROF_SPEC=1` the draw gives the diagnosis the noise as a datasheet would (the
//! residual's random walk and bias instability) instead of estimating a random walk from
//! each record; with `SIMPROF_SPEC=allan`, the noise `bins-cal allan --noise-toml` fits to a
//! quiet recording of the unit at the case's rate (`--noise`), as a user would get it.

use bins_cal::diagnose::noise::SensorNoise;
use bins_cal::diagnose::{Options, diagnose, diagnose_with};
use bins_cal::recording::Row;
use bins_cal::sim::scenario::ScenarioFile;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::Path;

/// The mechanisms REAL may have that SIM lacks, by the diagnosis's ids.
const WARMUP: &str = "warmup";
const LAG: &str = "thermal_lag";
const PLAY: &str = "thermal_hysteresis";

/// The residual's random walk [mg/√h] of the scenarios' noise (`random_walk_V_per_sqrt_s`
/// 2·10⁻⁸ at 1 V/g, in SIM and REAL: √2 · 0.0012).
const SPEC_RANDOM_WALK_MG_PER_SQRT_H: f64 = 0.0017;

/// The residual's bias instability [mg] and its correlation time [s] of the scenarios' noise
/// (`bias_instability_V` 3·10⁻⁶ at 1 V/g, `bias_tau_s` 300, in SIM and REAL: √2 · 0.003 mg).
const SPEC_BIAS_INSTABILITY: (f64, f64) = (0.00424, 300.0);

/// The diagnosis's options with the residual's noise as a datasheet gives it.
fn datasheet_noise() -> Options {
    Options {
        random_walk_mg_per_sqrt_h: Some(SPEC_RANDOM_WALK_MG_PER_SQRT_H),
        bias_instability: Some(SPEC_BIAS_INSTABILITY),
        ..Options::default()
    }
}

/// One drawn case: REAL's and SIM's scenarios, what REAL has, and the draw as text.
struct Draw {
    rate_hz: f64,
    real: String,
    sim: String,
    truth: Vec<&'static str>,
    text: String,
}

/// The scenario text of a unit with `warmup_v` (per axis), `die_tau_s` and `play_c`, the
/// thermal path and noise of `scenarios/three-hour-real.toml`, and `steps`.
fn scenario(rate_hz: f64, start_c: f64, warmup: ([f64; 3], f64), die_tau_s: f64, play_c: f64, steps: &str) -> String {
    format!(
        "description = \"user profile\"\n\
         [recording]\nrate_Hz = {rate_hz}\npower_on_s = 0.0\n\
         [unit]\npreset = \"paper\"\nfit = \"poly\"\norder = 2\nwarmup_V = [{:e}, {:e}, {:e}]\nwarmup_tau_s = {}\n\
         [thermal]\nstart_C = {start_c}\nrate_C_per_min = 1.0\ncase_tau_s = 600.0\ndie_tau_s = {die_tau_s}\n\
         self_heating_C = 1.5\nthermistor_at = 0.3\nthermistor_tau_s = 20.0\nhysteresis_C = {play_c}\n\
         [noise]\nwhite_V = 1.0e-5\nrandom_walk_V_per_sqrt_s = 2.0e-8\nbias_instability_V = 3.0e-6\nbias_tau_s = 300.0\n\
         adc_lsb_V = 1.0e-7\ntemp_noise_C = 0.005\ntemp_resolution_C = 0.01\n{steps}",
        warmup.0[0], warmup.0[1], warmup.0[2], warmup.1
    )
}

/// A move of the chamber to `to_c` at `rate` °C/min from `from_c`, then a hold of `hold_s`.
fn ramp(from_c: f64, to_c: f64, rate: f64, hold_s: f64) -> String {
    let move_s = (to_c - from_c).abs() / rate * 60.0;
    format!("[[step]]\nkind = \"soak\"\nchamber_C = {to_c}\nrate_C_per_min = {rate}\ndwell_s = {}\n", move_s + hold_s)
}

fn draw(seed: u64) -> Draw {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x513F_0F11);
    let kind = ["hot then cooling", "two sessions", "lag alone", "all three"][rng.random_range(0..4)];
    let rate_hz = [1.0, 2.0, 5.0][rng.random_range(0..3)];
    let rate = rng.random_range(0.2..1.0);
    let hold_s = if rng.random_bool(0.5) { 0.0 } else { rng.random_range(600.0..2400.0) };
    let (start_c, steps) = match kind {
        "lag alone" => {
            let cold = rng.random_range(-20.0..0.0);
            let warm = rng.random_range(30.0..50.0);
            let mut s = ramp(cold, warm, rate, hold_s);
            if rng.random_bool(0.3) {
                s += &ramp(warm, warm - rng.random_range(10.0..25.0), rate, 0.0);
            }
            (cold, s)
        }
        "two sessions" => {
            let a = rng.random_range(-10.0..50.0);
            let b = rng.random_range(-10.0..50.0);
            let c = rng.random_range(-10.0..50.0);
            let mut s = ramp(a, b, rate, hold_s);
            s += &format!("[[step]]\nkind = \"power\"\noff_s = 3600.0\nchamber_C = {c}\nrate_C_per_min = 1.0\n");
            s += &ramp(c, a, rate, 0.0);
            (a, s)
        }
        _ => {
            let hot = rng.random_range(35.0..60.0);
            let cool = rng.random_range(-10.0..15.0);
            (hot, ramp(hot, cool, rate, hold_s))
        }
    };
    let mut truth = Vec::new();
    let sign = |rng: &mut ChaCha8Rng| if rng.random_bool(0.5) { 1.0 } else { -1.0 };
    let (mut warmup, mut die_tau_s, mut play_c) = (([0.0; 3], 600.0), 1.0, 0.0);
    let all = kind == "all three";
    if all || (kind != "lag alone" && rng.random_bool(0.6)) {
        let w: [f64; 3] = std::array::from_fn(|_| sign(&mut rng) * rng.random_range(0.5e-4..2.5e-4));
        warmup = (w, if all { 900.0 } else { rng.random_range(300.0..1200.0) });
        truth.push(WARMUP);
    }
    if all || kind == "lag alone" || rng.random_bool(0.6) {
        die_tau_s = if all { 300.0 } else { rng.random_range(90.0..240.0) };
        truth.push(LAG);
    }
    if all || (kind != "lag alone" && rng.random_bool(0.6)) {
        play_c = rng.random_range(0.2..0.6);
        truth.push(PLAY);
    }
    let real = scenario(rate_hz, start_c, warmup, die_tau_s, play_c, &steps);
    let sim = scenario(rate_hz, start_c, ([0.0; 3], 600.0), 1.0, 0.0, &steps);
    let text = format!(
        "{kind:<16} {rate_hz:>3.0} Hz {rate:.2} °C/min start {start_c:>5.1} °C | warm-up {:?} τ {:.0} s, die lag {die_tau_s:.0} s, play {play_c:.2} °C",
        warmup.0.map(|v| (v * 1e6).round()),
        warmup.1
    );
    Draw { rate_hz, real, sim, truth, text }
}

fn rows(text: &str, seed: u64) -> Vec<Row> {
    ScenarioFile::parse(text, Path::new("case.toml")).unwrap().build(Path::new("case.toml")).unwrap().all_rows(seed)
}

/// The ids named that are none of `truth`: effects of another mechanism, and groups that hold
/// none of them.
fn false_names(r: &bins_cal::diagnose::report::Report, truth: &[&str]) -> Vec<String> {
    let mut out: Vec<String> =
        r.effects.iter().filter(|e| !truth.contains(&e.id.as_str())).map(|e| e.id.clone()).collect();
    for g in &r.ambiguous {
        if !g.ids.iter().any(|i| truth.contains(&i.as_str())) {
            out.push(g.ids.join("|"));
        }
    }
    out
}

/// The accelerometers the report says the estimated random walk hides structure on, as one
/// string ("xz").
fn hidden_by_random_walk(r: &bins_cal::diagnose::report::Report) -> String {
    r.notes
        .iter()
        .filter(|n| n.contains("random walk estimated from this record"))
        .filter_map(|n| n.strip_prefix("accelerometer ").and_then(|n| n.get(..1)))
        .collect()
}

/// A die lag alone after the only power-on, cold, then one ramp up and a hold (the unit heats
/// 1.5 °C at power-on, the thermistor 30 % of the way from case to die; REAL's die follows the
/// case and its own heating 119 s behind, SIM's at once):
/// after the power-on the lag is a turn-on transient that a warm-up, a self-heating or a play
/// the rise engages also makes, so the lag must be inside every group the report gives, and no
/// accelerometer left worse held-out. The rise the thermistor misses, `(1 − 0.3)·1.5 = 1.05 °C`,
/// is measured (on the grid of [`bins_cal::diagnose::mech::MISSED_RISE_GRID_C`], 1.0 or 1.45),
/// and with it the lag takes every accelerometer to within 1.25× its floor (2.5× without).
#[test]
fn a_die_lag_after_one_cold_power_on_is_inside_its_group() {
    let steps = ramp(-16.6, 47.0, 0.89, 1990.0);
    let real = rows(&scenario(2.0, -16.6, ([0.0; 3], 600.0), 119.0, 0.0, &steps), 180);
    let sim = rows(&scenario(2.0, -16.6, ([0.0; 3], 600.0), 1.0, 0.0, &steps), 181);
    let d = diagnose(&sim, &real, Path::new("sim.csv"), Path::new("real.csv")).unwrap();
    let rise_c = d.prepared.lag_rise_c;
    assert!((0.65..=1.5).contains(&rise_c), "missed rise {rise_c} °C, the unit's 1.05 °C");
    let r = d.report;
    println!(
        "effects {:?}, groups {:?}, held-out {:?} → {:?} mg, floor {:?} mg",
        r.effects.iter().map(|e| (&e.id, &e.axes)).collect::<Vec<_>>(),
        r.ambiguous.iter().map(|g| (&g.ids, &g.axes)).collect::<Vec<_>>(),
        r.heldout_rms_before_mg,
        r.heldout_rms_after_mg,
        r.noise_floor_mg
    );
    assert!(!r.effects.is_empty() || !r.ambiguous.is_empty(), "the lag's structure is found");
    assert_eq!(false_names(&r, &[LAG]), Vec::<String>::new());
    for a in ["x", "y", "z"] {
        assert!(r.heldout_rms_after_mg[a] <= r.heldout_rms_before_mg[a], "{a}");
        assert!(r.heldout_rms_after_mg[a] <= 1.25 * r.noise_floor_mg[a], "{a}");
    }
}

/// The same profile with a warm-up in REAL and no die lag: a turn-on transient whose sizes
/// are not `ρ·S'(T)` is not taken for a rise the lag misses, and every answer holds the
/// warm-up (no definite false name).
#[test]
fn a_warm_up_after_one_cold_power_on_is_no_missed_rise() {
    let steps = ramp(-16.6, 47.0, 0.89, 1990.0);
    let real = rows(&scenario(2.0, -16.6, ([1.5e-4, -2.0e-4, 1.0e-4], 600.0), 1.0, 0.0, &steps), 182);
    let sim = rows(&scenario(2.0, -16.6, ([0.0; 3], 600.0), 1.0, 0.0, &steps), 183);
    let d = diagnose(&sim, &real, Path::new("sim.csv"), Path::new("real.csv")).unwrap();
    println!(
        "rise {} °C, effects {:?}, groups {:?}",
        d.prepared.lag_rise_c,
        d.report.effects.iter().map(|e| (&e.id, &e.axes)).collect::<Vec<_>>(),
        d.report.ambiguous.iter().map(|g| (&g.ids, &g.axes)).collect::<Vec<_>>()
    );
    assert_eq!(d.prepared.lag_rise_c, 0.0);
    assert_eq!(false_names(&d.report, &[WARMUP]), Vec::<String>::new());
}

/// All three mechanisms after one hot power-on, then one cooling with no hold (case 79 of the
/// draw: +36 → 0 °C at 0.43 °C/min, 83 min). On x the warm-up (−0.15 mV) and the lag's missed
/// heating have opposite signs and leave a nearly straight residual, 2.5× the floor held-out,
/// that the random walk estimated from the record can make: nothing is named on x, and the
/// report says why and what tests it sharper. Given the noise as a datasheet gives it (the
/// scenarios' bias instability saturates where that random walk keeps wandering), the lag
/// takes x to within 1.25× its floor and the report has no such line.
#[test]
fn structure_the_estimated_random_walk_hides_is_said_and_the_datasheet_noise_names_it() {
    let case = draw(79);
    let (sim, real) = (rows(&case.sim, 159), rows(&case.real, 158));
    let ratio = |r: &bins_cal::diagnose::report::Report, a: &str| r.heldout_rms_after_mg[a] / r.noise_floor_mg[a];
    let d = diagnose(&sim, &real, Path::new("sim.csv"), Path::new("real.csv")).unwrap().report;
    println!("estimated: x {:.2}× its floor, notes on {:?}", ratio(&d, "x"), hidden_by_random_walk(&d));
    assert!(ratio(&d, "x") > 1.25, "x is left above its floor against the estimated random walk");
    assert_eq!(hidden_by_random_walk(&d), "x");
    assert_eq!(false_names(&d, &[WARMUP, LAG, PLAY]), Vec::<String>::new());
    let g = diagnose_with(&sim, &real, Path::new("sim.csv"), Path::new("real.csv"), &datasheet_noise()).unwrap().report;
    println!("datasheet: x {:.2}× its floor, notes on {:?}", ratio(&g, "x"), hidden_by_random_walk(&g));
    assert!(ratio(&g, "x") <= 1.25);
    assert!(hidden_by_random_walk(&g).is_empty());
    assert_eq!(false_names(&g, &[WARMUP, LAG, PLAY]), Vec::<String>::new());
}

/// Case 17 of the draw (a die lag of 199 s alone, one ramp from −18 °C after a cold power-on)
/// given the datasheet's noise: the die's missed rise is estimated at 1.5 °C for the unit's
/// 1.05 °C, and a warm-up at about the lag's time constant took the difference on x and y, named
/// beside the lag. That warm-up is the lag's rise at another size as much as a term of its own:
/// grouped with the lag, nothing false, every accelerometer within 1.25× its floor.
#[test]
fn a_warm_up_beside_a_lag_is_grouped_with_the_lags_rise_resized() {
    let d = draw(17);
    assert_eq!(d.truth, [LAG]);
    let (sim, real) = (rows(&d.sim, 35), rows(&d.real, 34));
    let r = diagnose_with(&sim, &real, Path::new("sim.csv"), Path::new("real.csv"), &datasheet_noise()).unwrap().report;
    println!("effects {:?}", r.effects.iter().map(|e| (&e.id, &e.axes)).collect::<Vec<_>>());
    assert_eq!(false_names(&r, &d.truth), Vec::<String>::new());
    assert!(r.effects.iter().all(|e| e.id != WARMUP), "no warm-up named beside the lag");
    for a in ["x", "y", "z"] {
        assert!(r.heldout_rms_after_mg[a] <= 1.25 * r.noise_floor_mg[a], "{a}");
    }
}

#[test]
fn a_warm_up_and_a_play_that_are_one_lag_are_grouped_with_it() {
    // Case 109: a die lag of 127 s alone, one ramp at 0.23 °C/min from a cold power-on, with
    // the noise `bins-cal allan --noise-toml` fits to a quiet recording. x was modelled as a
    // 2.2 °C thermal play and a warm-up with a fast part at 148 s, and the warm-up was named:
    // the play takes the lag's offset along the ramp, the warm-up the transient the thermistor
    // misses at power-on. Refitted together as one lag with its missed rise free
    // (`Refit::lag_with_rise_free`), they are grouped with the lag.
    let d = draw(109);
    assert_eq!(d.truth, [LAG]);
    let dir = tempfile::tempdir().unwrap();
    let noise = SensorNoise::read(&noise_of_quiet_recording(dir.path(), d.rate_hz)).unwrap();
    let (sim, real) = (rows(&d.sim, 219), rows(&d.real, 218));
    let options = Options { sensor_noise: Some(noise), ..Options::default() };
    let r = diagnose_with(&sim, &real, Path::new("sim.csv"), Path::new("real.csv"), &options).unwrap().report;
    println!("effects {:?}", r.effects.iter().map(|e| (&e.id, &e.axes)).collect::<Vec<_>>());
    assert_eq!(false_names(&r, &d.truth), Vec::<String>::new());
    assert!(r.effects.iter().all(|e| e.id != WARMUP), "no warm-up named for the lag's missed rise");
    assert!(
        r.ambiguous.iter().any(|g| g.axes.iter().any(|a| a == "x") && g.ids.iter().any(|i| i == LAG)),
        "x's group holds the lag: {:?}",
        r.ambiguous
    );
}

/// Runs `bins-cal` with `args`; its standard output (a failure stops the test with its errors).
fn bins_cal(args: &[&std::ffi::OsStr]) -> String {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_bins-cal")).args(args).output().unwrap();
    assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// What a user does for the unit's own noise: a quiet recording of the scenarios' unit (four
/// hours still at 20 °C at `rate_hz`, seed 7) into `dir`, and `bins-cal allan --noise-toml` of
/// it; the noise file's path.
fn noise_of_quiet_recording(dir: &Path, rate_hz: f64) -> std::path::PathBuf {
    let quiet = "[[step]]\nkind = \"soak\"\nchamber_C = 20.0\ndwell_s = 14400.0\n";
    let (toml, csv) = (dir.join(format!("quiet-{rate_hz}.toml")), dir.join(format!("quiet-{rate_hz}.csv")));
    let noise = dir.join(format!("noise-{rate_hz}.toml"));
    std::fs::write(&toml, scenario(rate_hz, 20.0, ([0.0; 3], 600.0), 1.0, 0.0, quiet)).unwrap();
    bins_cal(&["simulate".as_ref(), toml.as_os_str(), "-o".as_ref(), csv.as_os_str(), "--seed".as_ref(), "7".as_ref()]);
    let channels = "ux_V,uy_V,uz_V".as_ref();
    bins_cal(&[
        "allan".as_ref(),
        csv.as_os_str(),
        "--channels".as_ref(),
        channels,
        "--noise-toml".as_ref(),
        noise.as_os_str(),
    ]);
    noise
}

/// Case 79 (above) as a user closes that loop: a quiet recording of the unit (four hours at
/// 20 °C, the same noise), `bins-cal allan --noise-toml` of it, and `diagnose --noise` with
/// that file. The noise the Allan fit finds (its own estimate, not the scenario's numbers) is
/// scaled to the residual by the white levels (√2: SIM and REAL each carry it), and the
/// diagnosis does what the datasheet's figures make it do: x within 1.25× its floor, no
/// random-walk note, nothing false.
#[test]
fn the_noise_allan_fits_to_a_quiet_recording_is_the_sharper_test() {
    let dir = tempfile::tempdir().unwrap();
    let at = |f: &str| dir.path().join(f);
    let case = draw(79);
    for (name, text, seed) in [("real", &case.real, "158"), ("sim", &case.sim, "159")] {
        let (toml, csv) = (at(&format!("{name}.toml")), at(&format!("{name}.csv")));
        std::fs::write(&toml, text).unwrap();
        bins_cal(&[
            "simulate".as_ref(),
            toml.as_os_str(),
            "-o".as_ref(),
            csv.as_os_str(),
            "--seed".as_ref(),
            seed.as_ref(),
        ]);
    }
    let (noise, report) = (noise_of_quiet_recording(dir.path(), 2.0), at("report.json"));
    let (s, r) = (at("sim.csv"), at("real.csv"));
    let args: [&std::ffi::OsStr; 9] = [
        "diagnose".as_ref(),
        "--sim".as_ref(),
        s.as_os_str(),
        "--real".as_ref(),
        r.as_os_str(),
        "--report".as_ref(),
        report.as_os_str(),
        "--noise".as_ref(),
        noise.as_os_str(),
    ];
    let stdout = bins_cal(&args);
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    let ratio = |a: &str| v["heldout_rms_after_mg"][a].as_f64().unwrap() / v["noise_floor_mg"][a].as_f64().unwrap();
    println!("x {:.2}×, y {:.2}×, z {:.2}× their floors\n{stdout}", ratio("x"), ratio("y"), ratio("z"));
    assert!(ratio("x") <= 1.25, "x {:.2}× its floor", ratio("x"));
    assert_eq!(v["random_walk_source"], noise.display().to_string());
    let notes: Vec<&str> = v["notes"].as_array().unwrap().iter().filter_map(|n| n.as_str()).collect();
    assert!(!notes.iter().any(|n| n.contains("random walk estimated from this record")), "{notes:?}");
    // The white levels' ratio over the scale factor: √2, both recordings noisy.
    let scaled = notes.iter().find(|n| n.contains("scaled to the residual")).expect("the scaling is said");
    let ratios: Vec<f64> = scaled
        .split("white levels: ")
        .nth(1)
        .and_then(|t| t.split(" times").next())
        .map(|t| t.split(" / ").map(|x| x.parse().unwrap()).collect())
        .unwrap();
    assert!(ratios.len() == 3 && ratios.iter().all(|k| (k / 2f64.sqrt() - 1.0).abs() < 0.05), "{ratios:?}");
    assert!(!notes.iter().any(|n| n.contains("neither near 1 nor near √2")), "{notes:?}");
    // A file whose white noise on y is a hundredth of the unit's: the scaling is said not to fit.
    let text = std::fs::read_to_string(&noise).unwrap();
    let white = text.lines().find(|l| l.starts_with("white_V")).unwrap();
    std::fs::write(&noise, text.replace(white, "white_V = [1e-5, 1e-7, 1e-5]")).unwrap();
    bins_cal(&args);
    let w: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    let odd: Vec<&str> = w["notes"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|n| n.as_str())
        .filter(|n| n.contains("neither near 1 nor near √2"))
        .collect();
    assert!(odd.len() == 1 && odd[0].starts_with("accelerometer y:"), "{odd:?}");
    let truth = [WARMUP, LAG, PLAY];
    for e in v["effects"].as_array().unwrap() {
        assert!(truth.contains(&e["id"].as_str().unwrap()), "false effect {e}");
    }
    for g in v["ambiguous"].as_array().unwrap() {
        assert!(g["ids"].as_array().unwrap().iter().any(|i| truth.contains(&i.as_str().unwrap())), "false group {g}");
    }
}

#[test]
#[ignore = "a draw of simulator-made user profiles: minutes; run on demand"]
fn simulator_user_profiles() {
    let base: u64 = std::env::var("SIMPROF_SEED").ok().and_then(|v| v.parse().ok()).unwrap_or(1);
    let n: u64 = std::env::var("SIMPROF_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(24);
    // SIMPROF_SPEC=1: the noise as a datasheet gives it (the residual's, √2 times the unit's
    // random walk and bias instability at the nominal 1 V/g), not estimated from the record;
    // SIMPROF_SPEC=allan: the noise `bins-cal allan --noise-toml` fits to a quiet recording of
    // the unit at the case's rate (`--noise`).
    let spec = std::env::var("SIMPROF_SPEC").unwrap_or_default();
    let quiet_dir = tempfile::tempdir().unwrap();
    let mut allan_noise: Vec<(f64, SensorNoise)> = Vec::new();
    let mut options_for = |rate_hz: f64| match spec.as_str() {
        "1" => datasheet_noise(),
        "allan" => {
            if !allan_noise.iter().any(|(r, _)| *r == rate_hz) {
                let file = noise_of_quiet_recording(quiet_dir.path(), rate_hz);
                allan_noise.push((rate_hz, SensorNoise::read(&file).unwrap()));
            }
            let noise = allan_noise.iter().find(|(r, _)| *r == rate_hz).map(|(_, n)| n.clone());
            Options { sensor_noise: noise, ..Options::default() }
        }
        _ => Options::default(),
    };
    let (mut false_cases, mut members, mut named, mut worse, mut full, mut cases) = (0, 0, 0, 0, 0, 0);
    for seed in base..base + n {
        let d = draw(seed);
        let (sim, real) = (rows(&d.sim, 2 * seed + 1), rows(&d.real, 2 * seed));
        let options = options_for(d.rate_hz);
        let (r, rise_c) = match diagnose_with(&sim, &real, Path::new("sim.csv"), Path::new("real.csv"), &options) {
            Ok(x) => (x.report, x.prepared.lag_rise_c),
            Err(e) => {
                println!("case {seed}: {e}");
                continue;
            }
        };
        if std::env::var("SIMPROF_REPORT").is_ok_and(|v| v == "1") {
            println!("{}\n{}", d.real, serde_json::to_string_pretty(&r).unwrap_or_default());
        }
        cases += 1;
        let false_ids = false_names(&r, &d.truth);
        let hit: Vec<bool> = d
            .truth
            .iter()
            .map(|m| r.effects.iter().any(|e| e.id == *m) || r.ambiguous.iter().any(|g| g.ids.iter().any(|i| i == m)))
            .collect();
        members += d.truth.len();
        named += hit.iter().filter(|h| **h).count();
        false_cases += usize::from(!false_ids.is_empty());
        let ratio: Vec<String> = ["x", "y", "z"]
            .iter()
            .map(|a| format!("{:.2}", r.heldout_rms_after_mg[*a] / r.noise_floor_mg[*a]))
            .collect();
        let w = ["x", "y", "z"].iter().filter(|a| r.heldout_rms_after_mg[**a] > r.heldout_rms_before_mg[**a]).count();
        worse += w;
        let within = ["x", "y", "z"].iter().all(|a| r.heldout_rms_after_mg[*a] <= 1.25 * r.noise_floor_mg[*a]);
        full += usize::from(within && hit.iter().all(|h| *h));
        println!(
            "case {seed:>4} {} | truth {:?} hit {:?} | eff [{}] amb [{}] false {:?} | after/floor {} worse {w} ({} rows) missed rise {rise_c:.2} °C; the random walk hides structure on [{}]",
            d.text,
            d.truth,
            hit,
            r.effects.iter().map(|e| format!("{}:{}", e.id, e.axes.join(""))).collect::<Vec<_>>().join(" "),
            r.ambiguous
                .iter()
                .map(|g| format!("{}:{}", g.ids.join("|"), g.axes.join("")))
                .collect::<Vec<_>>()
                .join(" "),
            false_ids,
            ratio.join("/"),
            r.rows,
            hidden_by_random_walk(&r)
        );
    }
    println!(
        "{cases} cases: definite false name in {false_cases}; members named or inside a group {named}/{members}; axes worse held-out {worse}/{}; every member named and every axis within 1.25x {full}",
        3 * cases
    );
}
