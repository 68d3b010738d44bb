//! Speed and exactness of `bins-cal allan` (run by `cargo xtask bench`, step 9), in release,
//! on one thread (CPU time of the thread; wall time beside it):
//!
//! 1. 10⁷ samples of one channel (0.98 V offset, white noise, a random walk), octave τ: the
//!    streaming estimator, and the `allan` crate 0.4.1 beside it on the same τ (1, 2, 4, 8,
//!    10, 20, … up to 10⁶, its `Decade1248` style) with each one's largest relative difference
//!    from the definition at m = 1, 10, 100, 1000, 10⁴ (cluster means summed with compensation);
//! 2. with `--python PY` (a Python with allantools): allantools' `oadev(taus="octave")` of
//!    10⁷ samples timed inside Python, against the budget of 10× slower than ours;
//! 3. with `--day DAY.csv` (a day at 100 Hz): a bare pass of the streaming reader
//!    (`recording::Reader::read_row`) and `allan::pass::analyse` of the three accelerometers
//!    and `temp_C`, one after the other on the warm file, against the budget of 1.5×.
//!
//! Exits non-zero when a budget is missed.
//!
//! `cargo run --release -p bins-cal --example allan_speed -- [--python PY] [--day DAY.csv]`
#![allow(unsafe_code, reason = "libc: the thread's CPU time (`clock_gettime`), which std does not give")]

use bins_cal::allan::{Config, Estimator, Grid, Kind, pass};
use bins_cal::recording::{Reader, Row};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use std::path::PathBuf;
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |flag: &str| args.iter().position(|a| a == flag).and_then(|i| args.get(i + 1)).cloned();
    let mut missed = false;

    let n = 10_000_000usize;
    let y = signal(n);
    let (ours_s, ours_wall, raw) = timed(|| {
        let mut e = Estimator::new(&Config::allan_octaves());
        e.extend(&y);
        e.finish().0
    });
    println!(
        "10^7 samples, octave τ ({} points, fully overlapping to m = 2^12): bins-cal allan estimator {ours_s:.3} s CPU ({ours_wall:.3} s wall)",
        raw.len()
    );
    // The allan crate and ours on its τ (1, 2, 4, 8 a decade).
    let taus: Vec<usize> =
        (0..=5).flat_map(|p| [1, 2, 4, 8].map(|s| s * 10usize.pow(p))).filter(|&t| t <= 1_000_000).collect();
    let (crate_s, crate_wall, crate_dev) = timed(|| {
        let mut a = allan::Allan::builder()
            .style(allan::Style::Decade1248)
            .max_tau(1_000_000)
            .data_type(allan::DataType::Frequency)
            .build_allan();
        for &v in &y {
            a.record(v);
        }
        taus.iter().map(|&t| (t, a.get(t).and_then(|x| x.deviation()))).collect::<Vec<_>>()
    });
    let (same_s, same_wall, same) = timed(|| {
        let mut e =
            Estimator::new(&Config { kind: Kind::Allan, grid: Grid::List(taus.clone()), exact_max_m: 1_000_000 });
        e.extend(&y);
        e.finish().0
    });
    println!(
        "  the allan crate 0.4.1 ({} τ, 1 2 4 8 a decade to 10^6): {crate_s:.3} s CPU ({crate_wall:.3} s wall); bins-cal on the same τ, every one fully overlapping: {same_s:.3} s CPU ({same_wall:.3} s wall)",
        taus.len()
    );
    let (mut err_ours, mut err_crate) = (0.0f64, 0.0f64);
    for m in [1usize, 10, 100, 1000, 10_000] {
        let want = definition(&y, m).sqrt();
        let ours = same.iter().find(|r| r.m == m).map_or(f64::NAN, |r| r.var.sqrt());
        let theirs = crate_dev.iter().find(|c| c.0 == m).and_then(|c| c.1).unwrap_or(f64::NAN);
        err_ours = err_ours.max((ours / want - 1.0).abs());
        err_crate = err_crate.max((theirs / want - 1.0).abs());
    }
    println!(
        "  largest relative difference from the definition at m = 1 … 10^4: bins-cal {err_ours:.1e}, allan crate {err_crate:.1e}"
    );

    if let Some(py) = arg("--python") {
        match allantools_seconds(&py) {
            Some(at) => {
                let ratio = at / ours_s;
                let ok = ratio >= 10.0;
                missed |= !ok;
                println!(
                    "allantools oadev(taus=\"octave\"), 10^7 samples: {at:.3} s; allantools / bins-cal = {ratio:.1} (budget ≥ 10: {})",
                    if ok { "met" } else { "MISSED" }
                );
            }
            None => println!("allantools: not run ({py} could not import it)"),
        }
    }

    if let Some(day) = arg("--day") {
        let day = PathBuf::from(day);
        let (read_s, read_wall, rows) = timed(|| {
            let mut r = Reader::open(&day).expect("the day file");
            let mut row = Row::default();
            let mut k = 0u64;
            while r.read_row(&mut row).expect("a valid day file") {
                k += 1;
            }
            k
        });
        let opt = pass::Options {
            channels: ["ux_V", "uy_V", "uz_V", "temp_C"].map(String::from).to_vec(),
            from_s: None,
            to_s: None,
            held_only: false,
            config: Config::allan_octaves(),
            level: 0.95,
        };
        let (all_s, all_wall, a) = timed(|| pass::analyse(&day, &opt).expect("the day's curves"));
        let ratio = all_s / read_s;
        let ok = ratio <= 1.5;
        missed |= !ok;
        println!(
            "a day at 100 Hz ({rows} rows): the streaming reader alone {read_s:.2} s CPU ({read_wall:.2} s wall); allan of ux_V, uy_V, uz_V, temp_C ({} τ each) {all_s:.2} s CPU ({all_wall:.2} s wall); ratio {ratio:.2} (budget ≤ 1.5: {})",
            a.channels[0].points.len(),
            if ok { "met" } else { "MISSED" }
        );
    }
    if missed {
        std::process::exit(1);
    }
}

/// 0.98 V offset, white noise 1e-4 V, a random walk of 3e-6 V a sample.
fn signal(n: usize) -> Vec<f64> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let nrm = Normal::new(0.0, 1.0).unwrap();
    let mut rw = 0.0;
    (0..n)
        .map(|_| {
            rw += 3e-6 * nrm.sample(&mut rng);
            0.98 + rw + 1e-4 * nrm.sample(&mut rng)
        })
        .collect()
}

/// The overlapping Allan variance by its definition: cluster means summed with compensation,
/// by a running window of compensated sums.
fn definition(y: &[f64], m: usize) -> f64 {
    // Prefix sums in two parts (Neumaier), so a cluster's sum is exact to the last bits.
    let mut s = Vec::with_capacity(y.len() + 1);
    let (mut hi, mut lo) = (0.0f64, 0.0f64);
    s.push((0.0, 0.0));
    for &v in y {
        let t = hi + v;
        lo += if hi.abs() >= v.abs() { (hi - t) + v } else { (v - t) + hi };
        hi = t;
        s.push((hi, lo));
    }
    let sum = |a: usize, b: usize| (s[b].0 - s[a].0) + (s[b].1 - s[a].1);
    let (mut acc, mut c, mut k) = (0.0f64, 0.0f64, 0usize);
    while k + 2 * m <= y.len() {
        let d = (sum(k + m, k + 2 * m) - sum(k, k + m)) / m as f64;
        let x = d * d;
        let t = acc + x;
        c += if acc.abs() >= x.abs() { (acc - t) + x } else { (x - t) + acc };
        acc = t;
        k += 1;
    }
    (acc + c) / (2.0 * k as f64)
}

/// Seconds allantools' octave `oadev` takes on 10⁷ normal samples, timed inside Python.
fn allantools_seconds(py: &str) -> Option<f64> {
    let script = "import time, numpy, allantools\n\
                  y = numpy.random.default_rng(1).standard_normal(10_000_000)\n\
                  t = time.process_time()\n\
                  allantools.oadev(y, rate=100.0, data_type='freq', taus='octave')\n\
                  print(time.process_time() - t)\n";
    let out = std::process::Command::new(py).args(["-c", script]).output().ok()?;
    if !out.status.success() {
        return None;
    }
    String::from_utf8_lossy(&out.stdout).trim().parse().ok()
}

/// Runs `f`; its thread CPU time, wall time and result.
fn timed<T>(f: impl FnOnce() -> T) -> (f64, f64, T) {
    let (w, c) = (Instant::now(), thread_cpu_s());
    let r = f();
    (thread_cpu_s() - c, w.elapsed().as_secs_f64(), r)
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
