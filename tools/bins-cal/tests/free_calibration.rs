//! Calibration without a tilter (`calib::free`, `calibrate --free`/`--tilt`): against the
//! simulator's truth on hand-placed recordings, and on the real imucal six-position recording
//! against its independent reference and between the two fits.

mod common;

use bins_cal::calib::free::{self, FrameFree, FreeParams, StaticOptions};
use bins_cal::calib::segments::{self, Options};
use bins_cal::calib::tilter::fit_temperature;
use bins_cal::recording::Row;
use bins_cal::sim::rig::{Motion, Written};
use bins_cal::sim::scenario::ScenarioFile;
use bins_comp::Constants;
use std::path::Path;

fn seg_options() -> Options {
    Options { settle_s: 1.0, max_std_v: 0.01, max_rate_c_per_min: 0.5, temp_tol_c: 3.0 }
}

/// A hand-placed recording (`holds` random orientations drawn from `seed`, noise from `seed`) of the
/// paper's unit at 100 Hz: its rows and the truth at the recording's temperature.
fn hand_recording(seed: u64, holds: usize) -> (Vec<segments::RunRow>, Constants<f64>) {
    let text = std::fs::read_to_string(common::repo("scenarios/hand-40.toml")).expect("scenario");
    let text = text.replace("holds = 40", &format!("holds = {holds}")).replace("seed = 1", &format!("seed = {seed}"));
    let file = Path::new("hand.toml");
    let sim = ScenarioFile::parse(&text, file).expect("parses").build(file).expect("builds");
    let mut rowgen = sim.rows(seed);
    let mut row = Row::default();
    let mut rows = Vec::new();
    while rowgen.next_row(&mut row) {
        assert!(row.reference_f_g().is_none() && row.pos.is_none(), "a hand-placed recording has no reference");
        rows.push((row.t_s, row.u_v, row.temp_c));
    }
    let temp = rows.iter().map(|r| r.2).sum::<f64>() / rows.len() as f64;
    (rows, sim.unit.params.constants_at(temp))
}

#[test]
fn free_fit_recovers_the_truth_of_simulated_hand_placements() {
    let names = FrameFree::names();
    for seed in 1..=5 {
        let (rows, truth) = hand_recording(seed, 36);
        let intervals = free::static_intervals(Path::new("hand.csv"), &rows, &StaticOptions::default(), &seg_options())
            .expect("intervals");
        // The still start and every orientation.
        assert_eq!(intervals.len(), 37, "seed {seed}: {} intervals", intervals.len());
        let u: Vec<[f64; 3]> = intervals.iter().map(|s| s.mean_u_v).collect();
        let fit = free::fit_free(&u, FreeParams::Full, [-1.0; 3]).expect("fit");
        let (t, e, se) = (FrameFree::of(&truth).to_array(), fit.params.to_array(), fit.se.to_array());
        let mut line = format!("seed {seed}:");
        for p in 0..9 {
            let err = e[p] - t[p];
            let (tol, shown) = match p {
                0..3 => (1e-4, err * 1e3),                     // 0.1 mg
                3..6 => (1e-4 * t[p].abs(), err / t[p] * 1e6), // 100 ppm
                _ => (2e-4, err * 1e3),                        // 0.2 mrad
            };
            line += &format!(" {} {shown:+.4}", names[p]);
            line += &format!(" ({:+.1}σ)", err / se[p]);
            assert!(err.abs() <= tol, "seed {seed}: {} off by {shown:+.4} (mg, ppm or mrad)", names[p]);
            // The standard errors are those of the intervals' scatter; the simulated bias
            // instability (3 µV, τ = 300 s) is a near-constant offset over the 3-minute recording
            // that no fit of one recording can tell from U0: it is added to the bias's.
            let drift = if p < 3 { 3e-6 / t[p + 3].abs() } else { 0.0 };
            let cover = 3.0 * se[p].hypot(drift);
            assert!(err.abs() <= cover, "seed {seed}: {} error {err:e} beyond 3 standard errors {cover:e}", names[p]);
        }
        println!("{line}");
        // The fitted constants explain every interval: |f| = 1 g within 5 standard deviations.
        assert!(fit.residual_g.iter().all(|r| r.abs() < 5.0 * fit.sigma_g), "{:?}", fit.residual_g);
    }
}

#[test]
fn too_few_intervals_and_one_plane_are_named() {
    let (rows, _) = hand_recording(1, 8);
    let intervals = free::static_intervals(Path::new("hand.csv"), &rows, &StaticOptions::default(), &seg_options())
        .expect("intervals");
    let u: Vec<[f64; 3]> = intervals.iter().map(|s| s.mean_u_v).collect();
    let e = free::fit_free(&u, FreeParams::Full, [-1.0; 3]).expect_err("9 intervals");
    assert!(e.to_string().contains("9 static interval(s)") && e.to_string().contains("at least 12"), "{e}");
    // Orientations in the x–y plane only (z never vertical): z's bias and scale factor are
    // not separated.
    let truth = bins_comp::paper::TABLE_CONSTANTS[1];
    let u: Vec<[f64; 3]> = (0..20)
        .map(|k| {
            let a = k as f64 * 0.7;
            let f = [a.cos(), a.sin(), 0.0];
            // 10 µV of scatter between the intervals.
            std::array::from_fn(|i| {
                truth.u0_v[i]
                    + (0..3).map(|j| truth.k_v_per_g[i][j] * f[j]).sum::<f64>()
                    + 1e-5 * ((k * 7 + i * 3) % 5) as f64
                    - 2e-5
            })
        })
        .collect();
    let e = free::fit_free(&u, FreeParams::Full, [-1.0; 3]).expect_err("one plane").to_string();
    assert!(e.contains("do not span enough directions") && e.contains("nonorth_xz_mrad"), "{e}");
}

/// imucal's reference calibration (data/real/README.md), in the model U = U0 + K·f.
fn imucal_reference() -> Constants<f64> {
    Constants {
        k_v_per_g: [[0.996608, -0.014782, -0.007457], [0.008598, 1.002399, 0.001848], [0.013643, 0.002050, 1.023302]],
        u0_v: [0.054752, -0.062814, 0.040659],
    }
}

#[test]
fn imucal_free_and_tilt_refined_fits_agree_and_show_the_unlevel_holds() {
    let path = common::repo("data/real/imucal-session.csv");
    let opt = seg_options();
    // The free fit over the static intervals found in the signals (13: the six holds, the
    // still start and the repeated orientations after them).
    let intervals = free::find_static(&path, &StaticOptions::default(), &opt).expect("intervals");
    assert!(intervals.len() >= 12, "{} intervals", intervals.len());
    let u: Vec<[f64; 3]> = intervals.iter().map(|s| s.mean_u_v).collect();
    // Six orientations along the axes do not determine the non-orthogonality…
    let e = free::fit_free(&u, FreeParams::Full, [1.0; 3]).expect_err("near the axes only").to_string();
    assert!(e.contains("nonorth_xy_mrad") && e.contains("--free-params bias-scale"), "{e}");
    // …the biases and scale factors they do.
    let free_fit = free::fit_free(&u, FreeParams::BiasScale, [1.0; 3]).expect("bias-scale fit");
    // The labelled holds with their tilts.
    let all = segments::find(&path, &opt).expect("holds");
    let groups = segments::by_temperature(&all, opt.temp_tol_c);
    assert_eq!(groups.len(), 1);
    let (t, segs) = groups.into_iter().next().expect("one temperature");
    let labelled = fit_temperature(t, segs, "imucal").expect("T(10)");
    let labels: Vec<[f64; 3]> = labelled.segments.iter().map(|s| s.f_g).collect();
    let means: Vec<[f64; 3]> = labelled.segments.iter().map(|s| s.mean_u_v).collect();
    let se: Vec<[f64; 3]> =
        labelled.segments.iter().map(|s| s.std_u_v.map(|x| x / (s.rows.len() as f64).sqrt())).collect();
    let tilt = free::fit_tilted(&labels, &means, &se, &labelled.constants, 10e-3).expect("tilt fit");
    let names = FrameFree::names();
    let (a, sa) = (free_fit.params.to_array(), free_fit.se.to_array());
    let (b, sb) = (tilt.params.to_array(), tilt.se.to_array());
    let r = FrameFree::of(&imucal_reference()).to_array();
    for p in 0..9 {
        println!(
            "{:<18} free {:+.6} ± {:.6}  tilt {:+.6} ± {:.6}  imucal {:+.6}",
            names[p], a[p], sa[p], b[p], sb[p], r[p]
        );
        // Within their standard errors of each other (the free fit assumes orthogonal axes:
        // the tilt fit's non-orthogonality is within its standard error of 0).
        assert!(
            (a[p] - b[p]).abs() <= sa[p] + sb[p],
            "{}: free {} ± {} vs tilt {} ± {}",
            names[p],
            a[p],
            sa[p],
            b[p],
            sb[p]
        );
    }
    // The scale factors agree with imucal's reference within 300 ppm; the biases within
    // 0.3 mg (the reference's own estimator moves them by up to 2 mg: data/real/README.md).
    for p in 0..3 {
        assert!(
            (a[p] - r[p]).abs() < 3e-4 && (b[p] - r[p]).abs() < 3e-4,
            "{}: {} {} vs {}",
            names[p],
            a[p],
            b[p],
            r[p]
        );
        let q = p + 3;
        assert!(((a[q] - r[q]) / r[q]).abs() < 3e-4 && ((b[q] - r[q]) / r[q]).abs() < 3e-4, "{}", names[q]);
    }
    // The holds were not level: every one is tilted, by 1 to 10 mrad.
    for (s, t) in labelled.segments.iter().zip(&tilt.tilt_rad) {
        println!("{} tilt {:.3} mrad", s.pos, t * 1e3);
        assert!((1e-3..10e-3).contains(t), "{}: {t}", s.pos);
    }
    // After the tilts the holds are explained to their noise (T(10) leaves up to 2 mg).
    assert!(labelled.residual_g.iter().flatten().any(|r| r.abs() > 1e-3));
    assert!(tilt.residual_g.iter().flatten().all(|r| r.abs() < 1e-5), "{:?}", tilt.residual_g);
}

#[test]
fn calibrate_reports_the_unlevel_holds_and_calibrates_empty_references_freely() {
    let dir = tempfile::tempdir().expect("tmp");
    let d = common::repo("data/real/imucal-session.csv");
    let d = d.to_str().expect("utf-8");
    let out = dir.path().join("tilt.toml");
    let o = common::run(&["calibrate", "--tilter", d, "--tilt", "--tilt-tol-mrad", "3", "-o", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("dwells against their labels"), "{text}");
    let tilted: Vec<&str> = text.lines().filter(|l| l.contains("beyond the rig tolerance")).collect();
    let warned = String::from_utf8_lossy(&o.stderr);
    // The holds tilted by more than 3 mrad are in the table and warned of, naming the file.
    assert!(!tilted.is_empty(), "{text}");
    assert_eq!(
        warned.lines().filter(|l| l.contains("warning") && l.contains("imucal-session.csv")).count(),
        tilted.len()
    );
    // Empty reference columns: the free fit, automatically, with a note saying why.
    let csv = std::fs::read_to_string(common::repo("data/real/imucal-session.csv")).expect("csv");
    // Every cell after the five required columns emptied.
    let mut rec = common::csv_text::Csv::parse(&csv);
    for r in &mut rec.rows {
        r.iter_mut().skip(5).for_each(String::clear);
    }
    let empty = rec.to_text();
    let p = dir.path().join("empty.csv");
    std::fs::write(&p, empty).expect("write");
    let out = dir.path().join("free.toml");
    let text = common::ok(&[
        "calibrate",
        "--tilter",
        p.to_str().unwrap(),
        "--free-params",
        "bias-scale",
        "--tilt",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(
        text.contains("the reference columns are empty in every row") && text.contains("free fit at 20.00"),
        "{text}"
    );
    // `--tilt` needs labelled references: ignored, and said so, not silently.
    assert!(text.contains("--tilt ignored"), "{text}");
    assert!(out.exists());
    // Absent reference columns: the same, and the note says so.
    let absent = ["fx_g", "fy_g", "fz_g"].iter().fold(csv.clone(), |t, c| common::without_column(&t, c));
    let p2 = dir.path().join("absent.csv");
    std::fs::write(&p2, absent).expect("write");
    let text = common::ok(&[
        "calibrate",
        "--tilter",
        p2.to_str().unwrap(),
        "--free-params",
        "bias-scale",
        "-o",
        dir.path().join("free2.toml").to_str().unwrap(),
    ]);
    assert!(text.contains("has no reference columns") && text.contains("free fit at 20.00"), "{text}");
    // The labelled path on it says the columns are empty, not absent.
    let e = common::err(&[
        "verify",
        "--check",
        p.to_str().unwrap(),
        "--calib",
        dir.path().join("free.toml").to_str().unwrap(),
        "-o",
        dir.path().join("v.csv").to_str().unwrap(),
    ]);
    assert!(e.contains("present but empty"), "{e}");
}

#[test]
fn hand_placements_at_three_temperatures_give_the_temperature_model() {
    let dir = tempfile::tempdir().expect("tmp");
    let scen = dir.path().join("hand-3t.toml");
    std::fs::write(
        &scen,
        r#"
[recording]
rate_Hz = 20.0

[unit]
preset = "paper"
fit = "poly"
order = 2

[thermal]
start_C = 20.0
rate_C_per_min = 30.0
case_tau_s = 4.0
die_tau_s = 2.0
thermistor_at = 0.5
thermistor_tau_s = 1.0

[noise]
white_V = 3.0e-5
bias_instability_V = 1.0e-6
bias_tau_s = 300.0
adc_lsb_V = 1.0e-7
temp_noise_C = 0.005
temp_resolution_C = 0.01

[[step]]
kind = "hand"
holds = 20
init_s = 5.0
dwell_s = 3.0
move_s = 2.0
seed = 1

[[step]]
kind = "hand"
chamber_C = -40.0
holds = 20
init_s = 180.0
dwell_s = 3.0
move_s = 2.0
seed = 2

[[step]]
kind = "hand"
chamber_C = 70.0
holds = 20
init_s = 300.0
dwell_s = 3.0
move_s = 2.0
seed = 3
"#,
    )
    .expect("write");
    let rec = dir.path().join("hand-3t.csv");
    let cal = dir.path().join("hand-3t-cal.toml");
    let (rec_s, cal_s) = (rec.to_str().unwrap(), cal.to_str().unwrap());
    common::ok(&["simulate", scen.to_str().unwrap(), "-o", rec_s, "--seed", "4"]);
    let out = common::ok(&["calibrate", "--tilter", rec_s, "--free-signs=---", "--model", "poly:2", "-o", cal_s]);
    assert_eq!(out.lines().filter(|l| l.starts_with("free fit at")).count(), 3, "{out}");
    let (params, _) = bins_cal::calfile::CalibrationFile::read(&cal).unwrap().to_params().unwrap();
    let names = FrameFree::names();
    // The model through the three temperatures against the unit's true constants there.
    for (k, t) in bins_comp::paper::TABLE_TEMPS_C.iter().enumerate() {
        let got = FrameFree::of(&params.constants_at(*t)).to_array();
        let want = FrameFree::of(&bins_comp::paper::TABLE_CONSTANTS[k]).to_array();
        for p in 0..9 {
            let tol = match p {
                0..3 => 1e-4,
                3..6 => 1e-4 * want[p].abs(),
                _ => 2e-4,
            };
            assert!((got[p] - want[p]).abs() <= tol, "{} at {t} °C: {} vs {}", names[p], got[p], want[p]);
        }
    }
}

/// A tilter run of the paper's unit with its holds tilted by up to `tilt_deg` from their
/// labels (which the reference cells say): the true tilts, the T(10) and the tilt fits, and
/// the truth's frame-free parameters.
fn tilter_run(tilt_deg: f64) -> (Vec<f64>, FrameFree, free::TiltFit, FrameFree) {
    let dir = tempfile::tempdir().expect("tmp");
    let text = format!(
        r#"
[recording]
rate_Hz = 20.0

[unit]
preset = "paper"
fit = "poly"
order = 2

[noise]
white_V = 3.0e-5
adc_lsb_V = 1.0e-7

[[step]]
kind = "tilter"
dwell_s = 10.0
move_s = 2.0
tilt_deg = {tilt_deg}
tilt_seed = 7
"#
    );
    let file = dir.path().join("unlevel.toml");
    std::fs::write(&file, text).expect("write");
    let sim = bins_cal::sim::scenario::load(&file).expect("scenario");
    let truth_tilt: Vec<f64> = sim
        .segments
        .iter()
        .filter(|s| s.label.is_some())
        .map(|s| match (s.motion, s.written) {
            (Motion::Hold(f), Written::Nominal(l)) => (f[0] * l[0] + f[1] * l[1] + f[2] * l[2]).clamp(-1.0, 1.0).acos(),
            _ => 0.0,
        })
        .collect();
    assert_eq!(truth_tilt.len(), 6);
    let rec = dir.path().join("unlevel.csv");
    sim.write("unlevel.toml", 1, &rec, false).expect("simulate");
    let opt = seg_options();
    let all = segments::find(&rec, &opt).expect("holds");
    let (t, segs) = segments::by_temperature(&all, opt.temp_tol_c).into_iter().next().expect("one temperature");
    let labelled = fit_temperature(t, segs, "unlevel").expect("T(10)");
    // The reference cells say the labels.
    assert!(labelled.segments.iter().all(|s| bins_comp::ident::TILTER_POSITIONS_G.contains(&s.f_g)));
    let labels: Vec<[f64; 3]> = labelled.segments.iter().map(|s| s.f_g).collect();
    let means: Vec<[f64; 3]> = labelled.segments.iter().map(|s| s.mean_u_v).collect();
    let se: Vec<[f64; 3]> =
        labelled.segments.iter().map(|s| s.std_u_v.map(|x| x / (s.rows.len() as f64).sqrt())).collect();
    let tilt = free::fit_tilted(&labels, &means, &se, &labelled.constants, 10e-3).expect("tilt fit");
    let truth = FrameFree::of(&sim.unit.params.constants_at(t));
    (truth_tilt, FrameFree::of(&labelled.constants), tilt, truth)
}

#[test]
fn unlevel_tilter_holds_are_found_and_their_tilt_fitted() {
    let rss = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    // Level holds: the fit finds no tilt.
    let (true_tilt, _, tilt, _) = tilter_run(0.0);
    assert!(rss(&true_tilt) == 0.0);
    assert!(tilt.tilt_rad.iter().all(|t| *t < 0.1e-3), "{:?}", tilt.tilt_rad);
    // Holds up to 0.5° off: T(10) turns the tilts into bias errors, the tilt fit does not.
    let (true_tilt, t10, tilt, truth) = tilter_run(0.5);
    let names = FrameFree::names();
    let (t10, fit, truth) = (t10.to_array(), tilt.params.to_array(), truth.to_array());
    for p in 0..3 {
        println!("{} truth {:+.6} T(10) {:+.6} tilt {:+.6}", names[p], truth[p], t10[p], fit[p]);
        assert!((fit[p] - truth[p]).abs() < 0.05e-3, "{}: {} vs {}", names[p], fit[p], truth[p]);
    }
    assert!((0..3).any(|p| (t10[p] - truth[p]).abs() > 0.2e-3), "T(10) {t10:?} truth {truth:?}");
    // The fitted tilts are the smallest that explain the holds: never more than the true
    // ones (with the noise), and they show that the holds were not level.
    println!("true tilts {true_tilt:?}, fitted {:?}", tilt.tilt_rad);
    assert!(rss(&tilt.tilt_rad) <= rss(&true_tilt) * 1.02 + 0.05e-3);
    assert!(tilt.tilt_rad.iter().any(|t| *t > 1e-3), "{:?}", tilt.tilt_rad);
}

#[test]
fn too_few_intervals_is_one_line_naming_the_file() {
    let dir = tempfile::tempdir().expect("tmp");
    let text = std::fs::read_to_string(common::repo("scenarios/hand-40.toml")).expect("scenario");
    let scen = dir.path().join("hand-8.toml");
    std::fs::write(&scen, text.replace("holds = 40", "holds = 8")).expect("write");
    let rec = dir.path().join("hand-8.csv");
    common::ok(&["simulate", scen.to_str().unwrap(), "-o", rec.to_str().unwrap(), "--seed", "2"]);
    let out = dir.path().join("cal.toml");
    let e = common::err(&["calibrate", "--tilter", rec.to_str().unwrap(), "-o", out.to_str().unwrap()]);
    assert!(e.contains("hand-8.csv") && e.contains("9 static interval(s)") && e.contains("at least 12"), "{e}");
    assert!(!out.exists());
}
