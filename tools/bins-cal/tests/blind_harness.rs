//! Blind harness of `bins-cal diagnose` (docs/diagnosis-blind.md).
//!
//! `blind_harness` (ignored by default; `cargo test -p bins-cal --release --test blind_harness
//! -- --ignored --nocapture`): `BLIND_CASES` cases (default 200) from seed `BLIND_SEED`
//! (default 1), scorecard on stdout, `blind_cases.csv` and `blind_detectability.png` in
//! `BLIND_OUT` (default `target/blind`). `BLIND_ONLY=seed,seed,…` runs just those seeds and
//! prints their draws (`BLIND_REPORT=1`: and the diagnosis's JSON report). `BLIND_THREADS` (default 2). `BLIND_ASSERT=1` fails the test unless
//! ≥ 90 % of the effects ≥ 5 σ are named exactly and ≤ 5 % of the cases have a false discovery.
//!
//! The combined cases (several mechanisms at once) and the detectability curves are in
//! `blind_combined.rs`.
//!
//! `blind_fixed_cases` (always run): eight fixed cases — two nulls (one with a random walk),
//! strong single effects and two combined cases of two strong members — so the generator and
//! the classification stay honest in CI.

#[allow(dead_code)] // what the combined cases use
mod blind;

use blind::generator::{Case, Mech, Profile};
use blind::{Outcome, plot, run_cases, run_list, summarize, write_csv};
use std::path::PathBuf;

fn env_num<T: std::str::FromStr>(name: &str, default: T) -> T {
    std::env::var(name).ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

#[test]
#[ignore = "200 diagnoses: run in release with --ignored"]
fn blind_harness() {
    let threads = env_num("BLIND_THREADS", 2usize);
    if let Ok(only) = std::env::var("BLIND_ONLY") {
        let cases: Vec<Case> = only.split(',').filter_map(|s| s.trim().parse().ok()).map(Case::draw).collect();
        for r in run_list(&cases, threads, false) {
            println!("{}", blind::line(&r));
            println!("{:#?}", r.case);
            if std::env::var("BLIND_REPORT").is_ok_and(|v| v == "1") {
                println!("{}", blind::report_json(&r.case));
            }
        }
        return;
    }
    let n = env_num("BLIND_CASES", 200usize);
    let seed = env_num("BLIND_SEED", 1u64);
    let out = out_dir();
    let t0 = std::time::Instant::now();
    let res = run_cases(n, seed, threads, true);
    let s = summarize(&res);
    println!("\n{}", s.text);
    println!("wall time {:.0} s on {threads} threads", t0.elapsed().as_secs_f64());
    match write_csv(&res, &out) {
        Ok(p) => println!("cases: {}", p.display()),
        Err(e) => panic!("{}: {e}", out.display()),
    }
    match plot(&res, &out) {
        Ok(p) => println!("curve: {}", p.display()),
        Err(e) => panic!("{e}"),
    }
    assert_eq!(res.len(), n, "every case ran");
    if std::env::var("BLIND_ASSERT").is_ok_and(|v| v == "1") {
        // The done-when of issue 15: ≥ 90 % of the effects ≥ 5 σ named exactly, false
        // discoveries in ≤ 5 % of the cases.
        assert!(s.strong.0 * 10 >= s.strong.1 * 9, "effects ≥ 5 σ named exactly: {}/{}", s.strong.0, s.strong.1);
        assert!(
            s.false_disc.0 * 20 <= s.false_disc.1,
            "cases with a false discovery: {}/{}",
            s.false_disc.0,
            s.false_disc.1
        );
    }
}

fn out_dir() -> PathBuf {
    std::env::var("BLIND_OUT")
        .map(PathBuf::from)
        .unwrap_or_else(|_| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../target/blind"))
}

#[test]
fn blind_fixed_cases() {
    let mut cases = Vec::new();
    for (seed, id, size, rw) in [
        (11u64, "none", 0.0, 0.0),
        (12, "none", 0.0, 2.0),
        (13, "thermal_lag", 15.0, 0.0),
        (14, "scale_factor", 15.0, 0.0),
        (15, "cross_axis", 15.0, 1.0),
        (16, "warmup", 15.0, 0.0),
    ] {
        let mut c = Case::draw_with(seed, id);
        c.size_sigma = size;
        c.rw_ratio = rw;
        c.rows = 3000;
        c.dwell_s = c.dwell_s.min(3000.0 / c.rate_hz / 24.0);
        if id == "thermal_lag" {
            // Nearly first order, two rates with holds: what the library's lag term can fit.
            c.mech = Mech::ThermalLag { tau1_s: 150.0, tau2_s: 5.0 };
            c.profile = Profile::RampsHolds { rates: 2 };
        }
        cases.push(c);
    }
    // Two combined cases of 15 σ members: a warm-up with a misalignment, and a nearly
    // first-order lag with a scale-factor asymmetry.
    for (seed, ids) in [(23u64, ["warmup", "cross_axis"]), (22, ["thermal_lag", "sf_asymmetry"])] {
        let mut c = Case::draw_combined_with(seed, &ids);
        c.size_sigma = 15.0;
        c.extra[0].size_sigma = 15.0;
        c.rw_ratio = 0.0;
        c.rows = 3000;
        c.dwell_s = c.dwell_s.min(3000.0 / c.rate_hz / 24.0);
        if ids[0] == "thermal_lag" {
            c.mech = Mech::ThermalLag { tau1_s: 150.0, tau2_s: 5.0 };
            c.profile = Profile::RampsHolds { rates: 2 };
        }
        cases.push(c);
    }
    let res = run_list(&cases, 2, false);
    for r in &res {
        println!("{}", blind::line(r));
    }
    for r in &res {
        let ok = if r.case.mech.id() == "none" { r.outcome == Outcome::Clean } else { r.outcome.named() };
        assert!(ok, "{}", blind::line(r));
        assert!(r.members.iter().all(|m| m.named) && r.false_ids.is_empty(), "{}", blind::line(r));
    }
}
