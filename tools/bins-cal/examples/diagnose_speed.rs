//! Speed of `bins-cal diagnose` (run by `cargo xtask bench`): time of the diagnosis of pairs
//! of 30 000 and 260 000 rows at the suite's 1 Hz (every row), and of 260 000 rows at 100 Hz
//! (43 min, reduced to blocks by default), in release, on one core, against the budgets of 2 s,
//! 10 s and 3 s.
//! The diagnosis runs on one thread; the budget is checked on that thread's CPU time, so other
//! work on the machine does not count against it (the wall time is printed beside it). The pairs are the proof suite's cases (`warmup`: all four θ-mechanisms searched on
//! three axes; `lag_plus_asymmetry`: the thermal and V(2) terms, vibration on) lengthened;
//! generating them is not timed. Beside each time: the process's peak resident memory so far
//! (`getrusage` `ru_maxrss`: the generated pair in memory, its diagnosis and every earlier
//! case). Exits non-zero when a budget is missed.
//!
//! `cargo run --release -p bins-cal --example diagnose_speed`
#![allow(
    unsafe_code,
    reason = "libc: the thread's CPU time (`clock_gettime`) and the peak memory (`getrusage`), which std does not give"
)]

use bins_cal::diagnose::{cases, diagnose};
use std::path::Path;
use std::time::Instant;

fn main() {
    let mut missed = false;
    // (rows, budget [s], row spacing [s]; `None`: the case's own, 1 s).
    for (rows, budget_s, dt_s) in [(30_000usize, 2.0, None), (260_000, 10.0, None), (260_000, 3.0, Some(0.01))] {
        for name in ["warmup", "lag_plus_asymmetry"] {
            if std::env::var("DIAG_SPEED_CASE").is_ok_and(|c| c != name)
                || (rows > 30_000 && std::env::var("DIAG_SPEED_SHORT").is_ok())
            {
                continue;
            }
            let Some(mut case) = cases::suite().into_iter().find(|c| c.name == name) else {
                eprintln!("no suite case {name}");
                std::process::exit(2);
            };
            case.plan.rows = rows;
            if let Some(dt) = dt_s {
                case.plan.dt_s = dt;
            }
            let (sim, real) = cases::generate(&case);
            let (t0, cpu0) = (Instant::now(), thread_cpu_s());
            let d = match diagnose(&sim, &real, Path::new("sim"), Path::new("real")) {
                Ok(d) => d,
                Err(e) => {
                    eprintln!("{name}: {e}");
                    std::process::exit(2);
                }
            };
            let (wall_s, secs) = (t0.elapsed().as_secs_f64(), thread_cpu_s() - cpu0);
            let ok = secs < budget_s;
            missed |= !ok;
            let named: Vec<&str> = d.report.effects.iter().map(|e| e.id.as_str()).collect();
            println!(
                "diagnosis of {rows:>7} rows at {:>3.0} Hz ({name:<18}): {secs:6.2} s CPU, {wall_s:6.2} s wall (budget {budget_s} s: {}); peak RSS {:.0} MB; named {named:?}",
                1.0 / case.plan.dt_s,
                if ok { "met" } else { "MISSED" },
                peak_rss_mb()
            );
        }
    }
    if missed {
        std::process::exit(1);
    }
}

/// Peak resident set size of the process so far [MB] (`ru_maxrss`, in KiB on Linux).
fn peak_rss_mb() -> f64 {
    // SAFETY: an all-zero `rusage` is a valid value of the plain C struct.
    let mut ru: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: `ru` is a valid, writable rusage; RUSAGE_SELF needs nothing else.
    let rc = unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut ru) };
    if rc != 0 {
        eprintln!("getrusage(RUSAGE_SELF) failed");
        std::process::exit(2);
    }
    ru.ru_maxrss as f64 * 1024.0 / 1e6
}

/// CPU time of the calling thread [s].
fn thread_cpu_s() -> f64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_THREAD_CPUTIME_ID needs nothing else.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    if rc != 0 {
        eprintln!("clock_gettime(CLOCK_THREAD_CPUTIME_ID) failed");
        std::process::exit(2);
    }
    ts.tv_sec as f64 + 1e-9 * ts.tv_nsec as f64
}
