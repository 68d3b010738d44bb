//! `cargo xtask demo`: the whole pipeline on the temperature paper's twin (simulate, calibrate,
//! replay in QEMU, verify in the check positions), then the thermal-dynamics unit; everything in
//! `target/demo/`.

use std::path::Path;
use std::process::Command;
use std::time::Instant;

use crate::process::read;
use crate::qemu::REPLAY_SAMPLE_HZ;
use crate::task::{Result, StepFn, Xtask};
use crate::verify_csv;

/// Output directory of the demo, relative to the repository root; also the replay firmware's
/// and the vector firmware's working directory in QEMU.
pub(crate) const DEMO_DIR: &str = "target/demo";

/// The demo's tilter campaign (calibration and checks) and shaker campaign (same unit).
pub(crate) const DEMO_TILTER: &str = "scenarios/paper-tilter.toml";

pub(crate) const DEMO_SHAKER: &str = "scenarios/paper-unit-shaker.toml";

/// The method of the blob the replay firmware runs (the poly:2 calibration), as `verify`
/// labels it: the host's number the firmware's is compared with.
pub(crate) const DEMO_BLOB_METHOD: &str = "method 1";

/// The VE source of the demo's replay: none. The tilter recording has no vibration, and at its
/// 10 Hz logging rate a 64-sample online block spans 6.4 s, in which a move of the tilter would
/// read as vibration.
pub(crate) const DEMO_VE: &str = "none";

/// A file in the demo directory, as a string argument.
pub(crate) fn demo_path(x: &Xtask, name: &str) -> String {
    x.root.join(DEMO_DIR).join(name).to_string_lossy().into_owned()
}

/// `bins-cal` (release, built by the first call) with these arguments.
pub(crate) fn demo_bins_cal(x: &Xtask, args: &[&str]) -> Command {
    let mut c = x.host_cargo(["run", "--release", "-q", "-p", "bins-cal", "--"]);
    c.args(args);
    c
}

/// The demo's steps after the toolchain: the whole pipeline on the paper's twin. Simulate the
/// temperature paper's tilter campaign and the shake-table plan on the same unit, calibrate
/// with the paper's two-range model and with a quadratic one (with the vibration error, into
/// the blob), replay the tilter recording through the replay firmware in QEMU with that blob
/// (bit for bit against the host), verify both calibrations in the check positions (−10, +20,
/// +45 °C), the firmware's output beside the host's, run the firmware on its test vectors and
/// print the summary; everything in `target/demo/`.
pub(crate) const DEMO_STEPS: [(&str, StepFn); 8] = [
    ("simulate: tilter and shaker campaigns", demo_simulate),
    ("calibrate: two-range (method 2); poly:2 (method 1) + shaker, blob", demo_calibrate),
    ("build firmware", |x| x.build_firmware()),
    ("replay the tilter recording in QEMU, bit for bit against the host", demo_replay),
    ("verify in the check positions (host; firmware's output)", demo_verify),
    ("firmware test vectors in QEMU", demo_vectors),
    ("summary", |x| demo_summary(&x.root.join(DEMO_DIR))),
    (
        "thermal dynamics: die lag and bias play, calibrated from the tilter alone, checked in ramps and holds; replayed in QEMU",
        demo_dynamics,
    ),
];

/// The thermal-dynamics scenario: the paper's unit whose die lags its case and whose bias has
/// a heating/cooling play, tilter and checks during ramps and soaks.
pub(crate) const DEMO_DYNAMICS: &str = "scenarios/dynamics-tilter.toml";

/// Its logging rate \[Hz\]: the replay firmware's pipeline is configured for it, so the dynamics
/// stage advances the recording's own time step (at the default 1 kHz a row would count as
/// 1 ms, and a 180 s lag as 50 h of the recording).
pub(crate) const DEMO_DYNAMICS_SAMPLE_HZ: u32 = 1;

/// Its truth: die lag \[s\], play [°C], bias play width [°C] (`scenarios/dynamics-tilter.toml`).
pub(crate) const DEMO_DYNAMICS_TRUTH: [(&str, f64); 3] =
    [("lag_tau_s", 180.0), ("hysteresis_width_C", 1.0), ("bias_play_width_C", 4.0)];

/// Simulates the dynamics scenario, calibrates it twice from the recording alone (poly:2 from
/// the soaks; poly:2 with the dynamics identified from every dwell), verifies both in the
/// holds and during the ramps, and prints max |Δg| per phase with and without the dynamics
/// stage and the identified parameters against the scenario's truth. Fails unless the stage
/// cuts the ramps' max |Δg| by 3× or more and τ, h are within 20 % of the truth.
pub(crate) fn demo_dynamics(x: &mut Xtask) -> Result {
    let scenario = x.root.join(DEMO_DYNAMICS).to_string_lossy().into_owned();
    let rec = demo_path(x, "dynamics-tilter.csv");
    x.run(demo_bins_cal(x, &["simulate", &scenario, "-o", &rec, "--seed", "1"]))?;
    let (stat, dynm) = (demo_path(x, "cal-dyn-static.toml"), demo_path(x, "cal-dyn.toml"));
    x.run(demo_bins_cal(x, &["calibrate", "--tilter", &rec, "--model", "poly:2", "-o", &stat]))?;
    x.run(demo_bins_cal(
        x,
        &[
            "calibrate",
            "--tilter",
            &rec,
            "--model",
            "poly:2",
            "--dynamics",
            "identify",
            "-o",
            &dynm,
            "--blob",
            &demo_path(x, "cal-dyn.bin"),
            "--ihex",
            &demo_path(x, "cal-dyn.hex"),
        ],
    ))?;
    // The firmware with the identified dynamics in its blob replays the recording in QEMU; its
    // output must be the host's f32 pipeline bit for bit, and its |g| error is read in the same
    // check dwells as the host's (`verify --replayed`).
    let dir = x.root.join(DEMO_DIR);
    let (blob, hex) = (dir.join("cal-dyn.bin"), dir.join("cal-dyn.hex"));
    let (fw, host) = (dir.join("replay-dyn-qemu.csv"), dir.join("replay-dyn-host.csv"));
    let t = Instant::now();
    x.replay_firmware(Path::new(&rec), &blob, &hex, &fw, &dir, DEMO_VE, DEMO_DYNAMICS_SAMPLE_HZ)?;
    println!("replay firmware with dynamics: {} in {:.1} s wall", fw.display(), t.elapsed().as_secs_f64());
    x.replay_host_identical("dynamics-tilter", Path::new(&rec), &blob, &fw, &host, DEMO_VE, DEMO_DYNAMICS_SAMPLE_HZ)?;
    let fw_arg = fw.to_string_lossy().into_owned();
    for (cal, out, replayed) in [(&stat, "verify-dyn-static", None), (&dynm, "verify-dyn", Some(fw_arg.as_str()))] {
        let mut args = vec!["verify", "--check", &rec, "--calib", cal, "--ramps"];
        if let Some(r) = replayed {
            args.extend(["--replayed", r]);
        }
        let out = demo_path(x, out);
        args.extend(["-o", &out]);
        x.run(demo_bins_cal(x, &args))?;
    }
    // max |Δg| per phase: (phase, method) → max.
    let max_of = |sub: &str, method: &str| -> Result<Vec<(String, f64)>> {
        let mut out: Vec<(String, f64)> = Vec::new();
        for r in verify_csv::read(&dir.join(sub).join("verify.csv"))?.into_iter().filter(|r| r.method == method) {
            match out.iter_mut().find(|o| o.0 == r.phase) {
                Some(o) => o.1 = o.1.max(r.dg_mg.abs()),
                None => out.push((r.phase, r.dg_mg.abs())),
            }
        }
        Ok(out)
    };
    let without = max_of("verify-dyn-static", "method 1")?;
    let with = max_of("verify-dyn", "with dynamics")?;
    let firmware = max_of("verify-dyn", "replayed")?;
    println!("\nthermal dynamics (simulated: {DEMO_DYNAMICS}, seed 1), max |Δg| [mg] over CP1..CP6:");
    println!(
        "| checks | poly:2, method 1, static (soaks) | poly:2, method 1 + dynamics (identified), host f64 | the same, firmware in QEMU (f32) | ratio |"
    );
    println!("|---|---:|---:|---:|---:|");
    let mut bad = Vec::new();
    let mut worst_ramp_ratio = f64::INFINITY;
    for (phase, a) in &without {
        let b = with.iter().find(|w| w.0 == *phase).map_or(f64::NAN, |w| w.1);
        let label = match phase.as_str() {
            "hold" => "in the holds (−10, +20, +45 °C)",
            "heating" => "during heating ramps (1 °C/min)",
            _ => "during cooling ramps (1 °C/min)",
        };
        let f = firmware.iter().find(|w| w.0 == *phase).map_or(f64::NAN, |w| w.1);
        println!("| {label} | {a:.3} | {b:.3} | {f:.3} | {:.0}× |", a / b);
        if !((f - b).abs() <= 0.005) {
            bad.push(format!("{label}: the firmware's max |Δg| {f:.4} mg is not within 5 µg of the host's {b:.4} mg"));
        }
        if phase != "hold" {
            worst_ramp_ratio = worst_ramp_ratio.min(a / b);
        }
    }
    let text = std::fs::read_to_string(&dynm).map_err(|e| format!("{dynm}: {e}"))?;
    for (key, truth) in DEMO_DYNAMICS_TRUTH {
        let got = text
            .lines()
            .find_map(|l| l.strip_prefix(key).and_then(|r| r.trim_start().strip_prefix('=')))
            .and_then(|v| v.trim().parse::<f64>().ok())
            .ok_or_else(|| format!("{dynm}: no `{key}` in [thermal_dynamics]"))?;
        let err = (got - truth) / truth;
        println!("identified {key} = {got:.3} (truth {truth}, {:+.1} %)", 100.0 * err);
        if key != "bias_play_width_C" && err.abs() > 0.2 {
            bad.push(format!("{key} {got:.3} not within 20 % of {truth}"));
        }
    }
    if !(worst_ramp_ratio >= 3.0) {
        bad.push(format!("the dynamics stage cut the ramps' max |Δg| by {worst_ramp_ratio:.1}× only (< 3×)"));
    }
    println!(
        "plots: {} and {}",
        dir.join("verify-dyn-static/verify.png").display(),
        dir.join("verify-dyn/verify.png").display()
    );
    if bad.is_empty() { Ok(()) } else { Err(bad.join("; ")) }
}

pub(crate) fn demo_simulate(x: &mut Xtask) -> Result {
    let dir = x.root.join(DEMO_DIR);
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    for (scenario, rec) in [(DEMO_TILTER, "paper-tilter.csv"), (DEMO_SHAKER, "paper-shaker.csv")] {
        let scenario = x.root.join(scenario).to_string_lossy().into_owned();
        x.run(demo_bins_cal(x, &["simulate", &scenario, "-o", &demo_path(x, rec), "--seed", "1"]))?;
    }
    Ok(())
}

pub(crate) fn demo_calibrate(x: &mut Xtask) -> Result {
    let (rec, shaker) = (demo_path(x, "paper-tilter.csv"), demo_path(x, "paper-shaker.csv"));
    // The paper's model: two ranges through −40/+20/+70 °C; then the quadratic (T(11)) with
    // the vibration error from the shaker, written into the blob the firmware runs.
    let pwl = demo_path(x, "cal-pwl.toml");
    x.run(demo_bins_cal(x, &["calibrate", "--tilter", &rec, "--model", "pwl", "--method", "2", "-o", &pwl]))?;
    let (toml, bin, hex) =
        (demo_path(x, "cal-poly2.toml"), demo_path(x, "cal-poly2.bin"), demo_path(x, "cal-poly2.hex"));
    x.run(demo_bins_cal(
        x,
        &[
            "calibrate",
            "--tilter",
            &rec,
            "--shaker",
            &shaker,
            "--model",
            "poly:2",
            "--method",
            "1",
            "-o",
            &toml,
            "--blob",
            &bin,
            "--ihex",
            &hex,
        ],
    ))
}

pub(crate) fn demo_replay(x: &mut Xtask) -> Result {
    let dir = x.root.join(DEMO_DIR);
    let (rec, blob, hex) = (dir.join("paper-tilter.csv"), dir.join("cal-poly2.bin"), dir.join("cal-poly2.hex"));
    let (fw, host) = (dir.join("replay-qemu.csv"), dir.join("replay-host.csv"));
    let t = Instant::now();
    x.replay_firmware(&rec, &blob, &hex, &fw, &dir, DEMO_VE, REPLAY_SAMPLE_HZ)?;
    println!("replay firmware: {} in {:.1} s wall", fw.display(), t.elapsed().as_secs_f64());
    x.replay_host_identical("paper-tilter", &rec, &blob, &fw, &host, DEMO_VE, REPLAY_SAMPLE_HZ)
}

pub(crate) fn demo_verify(x: &mut Xtask) -> Result {
    let rec = demo_path(x, "paper-tilter.csv");
    let (pwl, poly) = (demo_path(x, "cal-pwl.toml"), demo_path(x, "cal-poly2.toml"));
    x.run(demo_bins_cal(x, &["verify", "--check", &rec, "--calib", &pwl, "-o", &demo_path(x, "verify-pwl")]))?;
    let (fw, out) = (demo_path(x, "replay-qemu.csv"), demo_path(x, "verify-poly2"));
    x.run(demo_bins_cal(x, &["verify", "--check", &rec, "--calib", &poly, "--replayed", &fw, "-o", &out]))
}

/// The firmware in QEMU on its test vectors (the demo set) and their report.
pub(crate) fn demo_vectors(x: &mut Xtask) -> Result {
    let dir = x.root.join(DEMO_DIR);
    let input = dir.join("target/fw-vectors/in.bin");
    let output = dir.join("target/fw-vectors/out.bin");
    let (inp, out) = (input.to_string_lossy().into_owned(), output.to_string_lossy().into_owned());
    x.run(x.host_cargo(["run", "--release", "-q", "-p", "host-tests", "--bin", "gen-vectors", "--", "--demo", &inp]))?;
    x.run_qemu_in(&x.elf("firmware"), &dir)?;
    x.run(x.host_cargo(["run", "--release", "-q", "-p", "host-tests", "--bin", "demo-report", "--", &inp, &out]))
}

/// max |Δg| \[mg\] per check temperature and method, from the two `verify.csv` files; the
/// poly:2 file also has the firmware's output (`replayed`), set under the host's number it
/// reproduces, and the replay's bit-identity is checked once more.
pub(crate) fn demo_summary(dir: &Path) -> Result {
    let fw_label = format!("{DEMO_BLOB_METHOD}: replay firmware in QEMU (blob)");
    let mut rows: Vec<(String, String, f64, f64)> = Vec::new(); // (model, method, temp, max)
    // (temp, pos, host, firmware) [mg], to compare dwell by dwell.
    let mut pairs: Vec<(f64, String, f64, f64)> = Vec::new();
    for (model, sub) in [("two-range (paper)", "verify-pwl"), ("poly:2", "verify-poly2")] {
        for row in verify_csv::read(&dir.join(sub).join("verify.csv"))? {
            let (t, pos, m, v) = (row.temp_c, &row.pos, &row.method, row.dg_mg);
            let poly = model.starts_with("poly");
            if poly && *m == "T0 constants" {
                continue;
            }
            let fw = *m == "replayed";
            if poly && (fw || *m == DEMO_BLOB_METHOD) {
                let k = match pairs.iter().position(|p| p.0 == t && p.1 == *pos) {
                    Some(k) => k,
                    None => {
                        pairs.push((t, pos.to_string(), f64::NAN, f64::NAN));
                        pairs.len() - 1
                    }
                };
                if fw {
                    pairs[k].3 = v;
                } else {
                    pairs[k].2 = v;
                }
            }
            let label = if *m == "T0 constants" { "–".to_string() } else { model.to_string() };
            let method = if fw { fw_label.clone() } else { m.to_string() };
            match rows.iter_mut().find(|r| r.0 == label && r.1 == method && (r.2 - t).abs() < 0.5) {
                Some(r) => r.3 = r.3.max(v.abs()),
                None => rows.push((label, method, t, v.abs())),
            }
        }
    }
    let mut temps: Vec<f64> = rows.iter().map(|r| r.2).collect();
    temps.sort_by(f64::total_cmp);
    temps.dedup();
    // One line per (model, method) in file order, the firmware's under the host's.
    let mut lines: Vec<(String, String)> = Vec::new();
    for r in &rows {
        if !lines.contains(&(r.0.clone(), r.1.clone())) {
            lines.push((r.0.clone(), r.1.clone()));
        }
    }
    if let Some(k) = lines.iter().position(|l| l.1 == fw_label) {
        let fw = lines.remove(k);
        let host = lines.iter().position(|l| l.0 == fw.0 && l.1 == DEMO_BLOB_METHOD).map_or(lines.len(), |h| h + 1);
        lines.insert(host, fw);
    }
    println!("\nmax |Δg| [mg] in the check positions CP1..CP6 (tolerance ±0.3 mg at T0, ±1 mg over the range):");
    print!("| model | method |");
    for t in &temps {
        print!(" {} °C |", format!("{t:+.1}").replace('-', "−"));
    }
    println!();
    println!("|---|---|{}", "---:|".repeat(temps.len()));
    for (model, method) in &lines {
        print!("| {model} | {method} |");
        for t in &temps {
            let v = rows.iter().find(|q| q.0 == *model && q.1 == *method && q.2 == *t).map_or(f64::NAN, |q| q.3);
            print!(" {v:.3} |");
        }
        println!();
    }
    let verify = dir.join("verify-poly2/verify.csv");
    if pairs.is_empty() || pairs.iter().any(|p| p.2.is_nan() || p.3.is_nan()) {
        return Err(format!(
            "{}: not every check dwell has a host {DEMO_BLOB_METHOD} and a `replayed` value",
            verify.display()
        ));
    }
    let worst = pairs.iter().map(|p| (p.3 - p.2).abs()).fold(0.0f64, f64::max);
    let (fw, host) = (dir.join("replay-qemu.csv"), dir.join("replay-host.csv"));
    let replayed = read(&fw)?;
    if replayed != read(&host)? {
        return Err(format!("{} and {} differ", fw.display(), host.display()));
    }
    let n = replayed.iter().filter(|&&c| c == b'\n').count().saturating_sub(1);
    println!(
        "replay firmware in QEMU (VE source {DEMO_VE}) = bins-cal replay on the host, bit for bit ({n} rows, {}); its \
         |g| error minus the host's {DEMO_BLOB_METHOD} (f64, no VE) in the {} check dwells: at most {:.3} µg",
        fw.display(),
        pairs.len(),
        worst * 1e3
    );
    println!(
        "plots: {} and {}",
        dir.join("verify-pwl/verify.png").display(),
        dir.join("verify-poly2/verify.png").display()
    );
    Ok(())
}

impl Xtask {
    pub(crate) fn demo(&mut self) -> bool {
        let started = Instant::now();
        let mut ok = self.step(1, "toolchain", Xtask::setup_toolchain);
        for (i, (name, f)) in DEMO_STEPS.iter().enumerate() {
            ok = ok && self.step(i + 2, name, *f);
        }
        self.summary(started);
        ok
    }
}
