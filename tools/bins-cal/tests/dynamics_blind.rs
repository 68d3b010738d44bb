//! Blind check of `bins-cal calibrate --dynamics identify` (docs/dynamics.md): units drawn by a
//! generator that shares no code with `calib::dynamics`, the simulator or the core
//! (`dynamics_gen`), each calibrated from its calibration recording by the real binary — once
//! static (poly:2 from the soaks), once with the dynamics identified — and both checked by
//! `verify --ramps` on the unit's separate check recording.
//!
//! `dynamics_blind` (ignored by default): `cargo test -p bins-cal --release --test
//! dynamics_blind -- --ignored --nocapture`. `DYN_BLIND_UNITS` units with dynamics (default 40)
//! and `DYN_BLIND_NULLS` without (default 20) from seed `DYN_BLIND_SEED` (default 1); a
//! scorecard on stdout, `dynamics_blind.csv` and `dynamics_blind.png` in `DYN_BLIND_OUT`
//! (default `target/dynamics-blind`); `DYN_BLIND_THREADS` (default 2). `DYN_BLIND_ONLY=seed,…`
//! runs those units only and prints their draws and the calibration's log.
//!
//! `dynamics_blind_few` (always run): two units with dynamics and a null unit.

#[allow(dead_code)] // the helpers other test files use
mod common;
mod dynamics_gen;

use dynamics_gen::Unit;
use std::path::{Path, PathBuf};
use std::process::Command;

/// What one unit gave.
#[derive(Clone, Debug)]
struct Outcome {
    unit: Unit,
    null: bool,
    /// The identified table (None: nothing written).
    got: Option<bins_cal::calfile::DynamicsSpec>,
    /// max |Δg| [mg] in the check recording's ramps and holds: static, with the dynamics.
    ramps_mg: (f64, f64),
    holds_mg: (f64, f64),
    /// The calibration's log (stdout).
    log: String,
}

impl Outcome {
    fn tau_ok(&self) -> bool {
        self.got.as_ref().is_some_and(|g| (g.lag_tau_s - self.unit.tau_s).abs() <= 0.2 * self.unit.tau_s)
    }
    /// h_b within 20 % where the unit has a bias play (true where it has none).
    fn hb_ok(&self) -> bool {
        self.unit.hb_c == 0.0
            || self.got.as_ref().is_some_and(|g| (g.bias_play_width_c - self.unit.hb_c).abs() <= 0.2 * self.unit.hb_c)
    }
    fn ramps_ok(&self) -> bool {
        self.ramps_mg.0 >= 3.0 * self.ramps_mg.1
    }
    fn holds_ok(&self) -> bool {
        self.holds_mg.1 <= 1.1 * self.holds_mg.0
    }
    fn pass(&self) -> bool {
        if self.null { self.got.is_none() } else { self.tau_ok() && self.hb_ok() && self.ramps_ok() && self.holds_ok() }
    }
}

fn run(args: &[&str]) -> String {
    let o = Command::new(env!("CARGO_BIN_EXE_bins-cal")).args(args).output().expect("bins-cal runs");
    assert!(o.status.success(), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// max |Δg| [mg] of `method` over the ramps (heating, cooling) and the holds of a verify.csv.
fn max_dg(csv: &Path, method: &str) -> (f64, f64) {
    let v = common::csv_text::Csv::read(csv);
    let (mut ramps, mut holds) = (0.0f64, 0.0f64);
    for r in v.rows.iter().filter(|r| v.cell(r, "method") == method) {
        let dg_mg = v.num(r, "dg_mg");
        if v.cell(r, "phase") == "hold" {
            holds = holds.max(dg_mg.abs());
        } else {
            ramps = ramps.max(dg_mg.abs());
        }
    }
    (ramps, holds)
}

/// Generates, calibrates (static and dynamic) and verifies one unit in `dir`.
fn run_unit(unit: &Unit, null: bool, dir: &Path) -> Outcome {
    std::fs::create_dir_all(dir).unwrap();
    let p = |n: &str| dir.join(n).to_string_lossy().into_owned();
    let (cal, chk) = dynamics_gen::recordings(unit);
    std::fs::write(p("cal.csv"), cal).unwrap();
    std::fs::write(p("chk.csv"), chk).unwrap();
    let common = ["calibrate", "--tilter", &p("cal.csv"), "--model", "poly:2", "--max-rate-c-per-min", "0.2"];
    run(&[&common[..], &["-o", &p("static.toml")]].concat());
    let log = run(&[&common[..], &["--dynamics", "identify", "-o", &p("dyn.toml")]].concat());
    let got = bins_cal::calfile::CalibrationFile::read(Path::new(&p("dyn.toml"))).unwrap().thermal_dynamics;
    run(&["verify", "--check", &p("chk.csv"), "--calib", &p("static.toml"), "--ramps", "-o", &p("v-static")]);
    run(&["verify", "--check", &p("chk.csv"), "--calib", &p("dyn.toml"), "--ramps", "-o", &p("v-dyn")]);
    let s = max_dg(&dir.join("v-static/verify.csv"), "method 1");
    let d = max_dg(&dir.join("v-dyn/verify.csv"), if got.is_some() { "with dynamics" } else { "method 1" });
    Outcome { unit: unit.clone(), null, got, ramps_mg: (s.0, d.0), holds_mg: (s.1, d.1), log }
}

/// Runs the units on `threads` threads under `out`.
fn run_all(units: &[(Unit, bool)], threads: usize, out: &Path) -> Vec<Outcome> {
    let next = std::sync::atomic::AtomicUsize::new(0);
    let results = std::sync::Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..threads.max(1) {
            s.spawn(|| {
                loop {
                    let k = next.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                    let Some((u, null)) = units.get(k) else { break };
                    let dir = out.join(format!("{}-{}", if *null { "null" } else { "unit" }, u.seed));
                    let o = run_unit(u, *null, &dir);
                    let _ = std::fs::remove_dir_all(&dir);
                    eprintln!("{}", line(&o));
                    results.lock().unwrap().push((k, o));
                }
            });
        }
    });
    let mut r = results.into_inner().unwrap();
    r.sort_by_key(|x| x.0);
    r.into_iter().map(|x| x.1).collect()
}

fn line(o: &Outcome) -> String {
    let u = &o.unit;
    let g = o.got.as_ref();
    format!(
        "{} {:>4}: τ {:>6.1} → {:>6.1} s, h {:>5.2} → {:>5.2} °C, h_b {:>5.2} → {:>5.2} °C; ramps {:>6.3} → {:>6.3} mg ({:>5.1}×), holds {:>6.3} → {:>6.3} mg{} {}",
        if o.null { "null" } else { "unit" },
        u.seed,
        u.tau_s,
        g.map_or(0.0, |g| g.lag_tau_s),
        u.h_c,
        g.map_or(0.0, |g| g.hysteresis_width_c),
        u.hb_c,
        g.map_or(0.0, |g| g.bias_play_width_c),
        o.ramps_mg.0,
        o.ramps_mg.1,
        o.ramps_mg.0 / o.ramps_mg.1,
        o.holds_mg.0,
        o.holds_mg.1,
        if u.reversal { ", reversal" } else { "" },
        if o.pass() { "ok" } else { "FAIL" }
    )
}

fn pct(n: usize, of: usize) -> String {
    format!("{n}/{of} ({:.0} %)", 100.0 * n as f64 / of.max(1) as f64)
}

/// The scorecard's lines.
fn scorecard(r: &[Outcome]) -> Vec<String> {
    let units: Vec<&Outcome> = r.iter().filter(|o| !o.null).collect();
    let nulls: Vec<&Outcome> = r.iter().filter(|o| o.null).collect();
    let with_hb = units.iter().filter(|o| o.unit.hb_c > 0.0).count();
    vec![
        format!("units with dynamics: {}", units.len()),
        format!("  τ within 20 %: {}", pct(units.iter().filter(|o| o.tau_ok()).count(), units.len())),
        format!(
            "  h_b within 20 % (units with a bias play): {}",
            pct(units.iter().filter(|o| o.unit.hb_c > 0.0 && o.hb_ok()).count(), with_hb)
        ),
        format!("  ramps' max |Δg| cut ≥ 3×: {}", pct(units.iter().filter(|o| o.ramps_ok()).count(), units.len())),
        format!("  holds' max |Δg| ≤ 1.1× static: {}", pct(units.iter().filter(|o| o.holds_ok()).count(), units.len())),
        format!("  all four: {}", pct(units.iter().filter(|o| o.pass()).count(), units.len())),
        format!("null units writing no table: {}", pct(nulls.iter().filter(|o| o.pass()).count(), nulls.len())),
    ]
}

fn write_csv(r: &[Outcome], path: &Path) {
    let mut s = String::from(
        "seed,null,reversal,tau_s,tau_got_s,h_C,h_got_C,hb_C,hb_got_C,rw_ug_per_sqrt_s,ramps_static_mg,ramps_dyn_mg,holds_static_mg,holds_dyn_mg,pass\n",
    );
    for o in r {
        let u = &o.unit;
        let g = o.got.as_ref();
        s.push_str(&format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
            u.seed,
            o.null,
            u.reversal,
            u.tau_s,
            g.map_or(0.0, |g| g.lag_tau_s),
            u.h_c,
            g.map_or(0.0, |g| g.hysteresis_width_c),
            u.hb_c,
            g.map_or(0.0, |g| g.bias_play_width_c),
            u.rw_g_per_sqrt_s * 1e6,
            o.ramps_mg.0,
            o.ramps_mg.1,
            o.holds_mg.0,
            o.holds_mg.1,
            o.pass()
        ));
    }
    std::fs::write(path, s).unwrap();
}

/// Three panels: identified τ against the truth, identified h_b against the truth, and the
/// ramps' max |Δg| of the static calibration against the one with the dynamics.
fn plot(r: &[Outcome], path: &Path) {
    use plotters::prelude::*;
    use plotters::style::{FontStyle, register_font};
    static FONT: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");
    let _ = register_font("sans-serif", FontStyle::Normal, FONT);
    let units: Vec<&Outcome> = r.iter().filter(|o| !o.null).collect();
    let root = BitMapBackend::new(path, (1500, 500)).into_drawing_area();
    root.fill(&WHITE).unwrap();
    let areas = root.split_evenly((1, 3));
    let panel = |area: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
                 title: &str,
                 xl: &str,
                 yl: &str,
                 range: (f64, f64),
                 pts: Vec<(f64, f64, bool)>,
                 factor: f64| {
        let mut ch = ChartBuilder::on(area)
            .caption(title, ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(55)
            .build_cartesian_2d((range.0..range.1).log_scale(), (range.0..range.1).log_scale())
            .unwrap();
        ch.configure_mesh().x_desc(xl).y_desc(yl).draw().unwrap();
        ch.draw_series(LineSeries::new([(range.0, range.0), (range.1, range.1)], BLACK.stroke_width(1))).unwrap();
        // ±factor for a tolerance (factor > 1), one line for a bound (factor < 1).
        let lines = if factor > 1.0 { vec![factor, 1.0 / factor] } else { vec![factor] };
        for f in lines {
            ch.draw_series(LineSeries::new([(range.0, range.0 * f), (range.1, range.1 * f)], BLACK.mix(0.3))).unwrap();
        }
        ch.draw_series(pts.into_iter().map(|(x, y, ok)| {
            Circle::new((x, y.clamp(range.0, range.1)), 4, if ok { BLUE.filled() } else { RED.filled() })
        }))
        .unwrap();
    };
    let g = |o: &Outcome, f: &dyn Fn(&bins_cal::calfile::DynamicsSpec) -> f64| o.got.as_ref().map_or(0.0, f);
    panel(
        &areas[0],
        "lag τ [s] (lines: ±20 %)",
        "truth",
        "identified",
        (10.0, 2000.0),
        units.iter().map(|o| (o.unit.tau_s, g(o, &|d| d.lag_tau_s), o.tau_ok())).collect(),
        1.2,
    );
    panel(
        &areas[1],
        "bias play h_b [°C] (lines: ±20 %)",
        "truth",
        "identified",
        (0.2, 30.0),
        units
            .iter()
            .filter(|o| o.unit.hb_c > 0.0)
            .map(|o| (o.unit.hb_c, g(o, &|d| d.bias_play_width_c), o.hb_ok()))
            .collect(),
        1.2,
    );
    panel(
        &areas[2],
        "check ramps: max |Δg| [mg] (line: 3× cut)",
        "static poly:2",
        "with the identified dynamics",
        (0.005, 20.0),
        units.iter().map(|o| (o.ramps_mg.0, o.ramps_mg.1, o.ramps_ok())).collect(),
        1.0 / 3.0,
    );
    root.present().unwrap();
}

fn env_num<T: std::str::FromStr>(name: &str, default: T) -> T {
    std::env::var(name).ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

#[test]
#[ignore = "60 units, two calibrations and two verifications each: run in release with --ignored"]
fn dynamics_blind() {
    let threads = env_num("DYN_BLIND_THREADS", 2usize);
    let out =
        std::env::var("DYN_BLIND_OUT").map(PathBuf::from).unwrap_or_else(|_| common::repo("target/dynamics-blind"));
    std::fs::create_dir_all(&out).unwrap();
    if let Ok(only) = std::env::var("DYN_BLIND_ONLY") {
        for seed in only.split(',').filter_map(|s| s.trim().parse::<u64>().ok()) {
            let null = seed >= 1_000_000;
            let u = Unit::draw(seed, null);
            println!("{u:#?}");
            let o = run_unit(&u, null, &out.join(format!("only-{seed}")));
            println!("{}\n{}", o.log, line(&o));
        }
        return;
    }
    let seed = env_num("DYN_BLIND_SEED", 1u64);
    let n = env_num("DYN_BLIND_UNITS", 40u64);
    let nn = env_num("DYN_BLIND_NULLS", 20u64);
    // Null units' seeds are offset by a million (so `DYN_BLIND_ONLY` tells them apart).
    let units: Vec<(Unit, bool)> = (seed..seed + n)
        .map(|s| (Unit::draw(s, false), false))
        .chain((seed..seed + nn).map(|s| (Unit::draw(1_000_000 + s, true), true)))
        .collect();
    let r = run_all(&units, threads, &out);
    for o in &r {
        println!("{}", line(o));
    }
    for l in scorecard(&r) {
        println!("{l}");
    }
    write_csv(&r, &out.join("dynamics_blind.csv"));
    plot(&r, &out.join("dynamics_blind.png"));
    println!("wrote {} and {}", out.join("dynamics_blind.csv").display(), out.join("dynamics_blind.png").display());
}

#[test]
fn dynamics_blind_few() {
    let tmp = tempfile::tempdir().unwrap();
    let units = vec![(Unit::draw(3, false), false), (Unit::draw(4, false), false), (Unit::draw(1_000_001, true), true)];
    let r = run_all(&units, 2, tmp.path());
    for o in &r {
        assert!(o.pass(), "{}\n{}", line(o), o.log);
    }
}
