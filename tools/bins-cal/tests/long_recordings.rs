//! Long recordings in bounded memory: `calibrate --free` and `simulate --follow` each read a
//! million-row recording with their address space limited to 100 MiB (they hold the window and
//! the static run being read, or one row, never the file), and a scenario asking for a billion
//! rows is refused in under a second within the same limit.
//!
//! The recording is written here from its own closed form (a unit with known constants put
//! down in 400 orientations by a simple generator that shares no code with the simulator), so
//! the free fit's answer is checked against that truth too.

use std::io::Write;
use std::path::Path;
use std::time::{Duration, Instant};

/// Address-space limit of the commands [KiB]: 100 MiB.
const LIMIT_KIB: u64 = 100 * 1024;

/// Runs `bins-cal args` in `dir` under `ulimit -v LIMIT_KIB`.
fn run_limited(dir: &Path, args: &[&str]) -> std::process::Output {
    let bin = env!("CARGO_BIN_EXE_bins-cal");
    let quoted: Vec<String> = args.iter().map(|a| format!("'{a}'")).collect();
    // A run that would go on for minutes is cut after 60 s (and then fails the test).
    let script = format!("ulimit -v {LIMIT_KIB} && exec timeout 60 '{bin}' {}", quoted.join(" "));
    std::process::Command::new("sh").args(["-c", &script]).current_dir(dir).output().unwrap()
}

/// The unit's constants: K \[V/g\] (upper triangular: the free fit's gauge) and U0 \[V\].
const K: [[f64; 3]; 3] = [[0.50, 0.004, -0.003], [0.0, 0.49, 0.002], [0.0, 0.0, 0.51]];
const U0: [f64; 3] = [0.012, -0.007, 0.004];

/// Rows per second, holds, and a hold's and a turn's length \[s\].
const RATE_HZ: f64 = 100.0;
const HOLDS: usize = 400;
const HOLD_S: f64 = 20.0;
const TURN_S: f64 = 5.0;

/// Orientation `k` of the holds: a Fibonacci sphere (every direction, deterministic).
fn direction(k: usize) -> [f64; 3] {
    let z = 1.0 - 2.0 * (k as f64 + 0.5) / HOLDS as f64;
    let r = (1.0 - z * z).sqrt();
    let phi = k as f64 * std::f64::consts::PI * (3.0 - 5f64.sqrt());
    [r * phi.cos(), r * phi.sin(), z]
}

/// Writes the million-row recording: 400 holds of 20 s joined by 5 s turns at 100 Hz, white
/// noise of 10 µV (a linear congruential generator), 20 °C throughout; the reference columns
/// give the true specific force, every fourth hold is labelled `CP1`…`CP6`. Returns the row
/// count.
fn write_hand_recording(path: &Path) -> usize {
    let mut out = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    writeln!(out, "# recording format v1 -- written by the long_recordings test").unwrap();
    writeln!(out, "t_s,ux_V,uy_V,uz_V,temp_C,fx_g,fy_g,fz_g,pos").unwrap();
    let mut state: u64 = 0x2545_f491_4f6c_dd1d;
    let mut noise = || {
        state = state.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
        ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 2e-5 * 3f64.sqrt()
    };
    let per_hold = ((HOLD_S + TURN_S) * RATE_HZ) as usize;
    let n = HOLDS * per_hold;
    for k in 0..n {
        let (hold, j) = (k / per_hold, k % per_hold);
        let t = j as f64 / RATE_HZ - HOLD_S;
        let (a, b) = (direction(hold), direction((hold + 1) % HOLDS));
        // Still during the hold, then a turn to the next orientation.
        let w = if t < 0.0 { 0.0 } else { 0.5 - 0.5 * (std::f64::consts::PI * t / TURN_S).cos() };
        let mut f = [0.0; 3];
        for i in 0..3 {
            f[i] = a[i] + w * (b[i] - a[i]);
        }
        let norm = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
        let f = f.map(|x| x / norm);
        let u: Vec<f64> = (0..3).map(|i| U0[i] + (0..3).map(|j| K[i][j] * f[j]).sum::<f64>() + noise()).collect();
        // Every fourth hold is labelled as a check dwell (for `verify`).
        let pos = if t < 0.0 && hold % 4 == 0 { format!("CP{}", 1 + (hold / 4) % 6) } else { String::new() };
        writeln!(
            out,
            "{},{:.8},{:.8},{:.8},20.0,{:.6},{:.6},{:.6},{pos}",
            k as f64 / RATE_HZ,
            u[0],
            u[1],
            u[2],
            f[0],
            f[1],
            f[2]
        )
        .unwrap();
    }
    out.flush().unwrap();
    n
}

#[test]
fn free_calibration_reads_a_million_rows_in_100_mib() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    assert_eq!(write_hand_recording(&dir.join("hand.csv")), 1_000_000);

    let args = ["calibrate", "--free", "--tilter", "hand.csv", "--model", "none", "-o", "cal.toml"];
    let o = run_limited(dir, &args);
    assert!(o.status.success(), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("over 400 static intervals"), "{out}");
    // The truth of the generator (the fit's gauge, K upper triangular, is the generator's
    // frame): U0 within 20 µV, every element of K within 50 µV/g.
    let cal: toml::Value = toml::from_str(&std::fs::read_to_string(dir.join("cal.toml")).unwrap()).unwrap();
    let num = |v: &toml::Value| v.as_float().unwrap();
    for i in 0..3 {
        let u0 = num(&cal["u0_V"][i]);
        assert!((u0 - U0[i]).abs() < 2e-5, "U0[{i}] {u0} vs {}", U0[i]);
        for j in 0..3 {
            let k = num(&cal["k_V_per_g"][i][j]);
            assert!((k - K[i][j]).abs() < 5e-5, "K[{i}][{j}] {k} vs {}", K[i][j]);
        }
    }
}

#[test]
fn follow_reads_a_million_rows_in_100_mib() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let n = write_hand_recording(&dir.join("hand.csv"));
    let scenario = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios/paper-tilter.toml");
    let args = ["simulate", "--follow", "hand.csv", scenario.to_str().unwrap(), "-o", "sim.csv"];
    let o = run_limited(dir, &args);
    assert!(o.status.success(), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("1000000 rows predicted"), "{err}");
    let text = std::fs::read_to_string(dir.join("sim.csv")).unwrap();
    assert_eq!(text.lines().filter(|l| !l.starts_with('#')).count(), n + 1, "header and every row");
}

/// `verify` with a calibration that has thermal dynamics runs them over every row and keeps
/// the check dwells' rows only.
#[test]
fn verify_with_dynamics_reads_a_million_rows_in_100_mib() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    write_hand_recording(&dir.join("hand.csv"));
    let cal = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../calibrations/paper-two-range-dynamics.toml");
    let args = ["verify", "--check", "hand.csv", "--calib", cal.to_str().unwrap(), "-o", "v"];
    let o = run_limited(dir, &args);
    assert!(o.status.success(), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
    let table = std::fs::read_to_string(dir.join("v/verify.csv")).unwrap();
    // 100 labelled holds, each a dwell with a value of the method with the dynamics.
    let with_dynamics = table.lines().filter(|l| l.contains("dynamics")).count();
    assert!(with_dynamics >= 100, "{with_dynamics} rows with the dynamics:\n{table}");
}

/// A scenario asking for a billion rows, by its rate, by a long step or by many holds: one
/// line naming the file and the key, in under a second, within 100 MiB, nothing written.
#[test]
fn a_scenario_of_a_billion_rows_is_refused_in_a_second() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let unit = "[unit]\npreset = \"paper\"\n";
    let cases = [
        (
            "rate.toml",
            format!("[recording]\nrate_Hz = 1.0e9\n{unit}[[step]]\nkind = \"soak\"\nchamber_C = 20.0\ndwell_s = 1.0\n"),
        ),
        (
            "long.toml",
            format!(
                "[recording]\nrate_Hz = 100.0\n{unit}[[step]]\nkind = \"soak\"\nchamber_C = 20.0\ndwell_s = 1.0e7\n"
            ),
        ),
        (
            "holds.toml",
            format!(
                "[recording]\nrate_Hz = 1.0\n{unit}[[step]]\nkind = \"hand\"\nholds = 250000\ninit_s = 1.0\ndwell_s = 3995.0\nmove_s = 5.0\n"
            ),
        ),
    ];
    for (name, text) in &cases {
        std::fs::write(dir.join(name), text).unwrap();
        let args = ["simulate", name, "-o", "out.csv", "--quiet"];
        let t = Instant::now();
        let o = run_limited(dir, &args);
        let took = t.elapsed();
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{name}: accepted");
        assert!(took < Duration::from_secs(1), "{name}: {took:?}");
        assert_eq!(e.trim_end().lines().count(), 1, "{name}: {e}");
        assert!(e.starts_with(&format!("bins-cal: error: {name}")) && e.contains("step") && e.contains("rows"), "{e}");
    }
    let mut left: Vec<String> =
        std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    left.sort();
    assert_eq!(left, ["holds.toml", "long.toml", "rate.toml"], "nothing written");
}

/// The static intervals `static_intervals` finds (its window slid over the rows with a bounded
/// buffer) are those of a direct computation: every row's centred window (cut at the ends)
/// summed afresh, its variance against the still period's, runs of static rows. Recordings
/// shorter than the window, as long, and much longer; still periods at both ends.
#[test]
fn the_sliding_window_finds_what_a_direct_computation_finds() {
    use bins_cal::calib::free::{StaticOptions, static_intervals};
    use bins_cal::calib::segments::Options;
    let seg = Options { settle_s: 1.0, max_std_v: 0.01, max_rate_c_per_min: 0.5, temp_tol_c: 3.0 };
    let mut state: u64 = 7;
    let mut noise = || {
        state = state.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
        ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 2e-5
    };
    // (rate, rows, window [s], where the unit moves: every `period` rows for `moving` rows).
    for (rate, n, window_s, period, moving) in
        [(20.0, 30, 10.0, 1000, 0), (20.0, 41, 0.3, 17, 3), (10.0, 400, 1.0, 60, 7), (100.0, 5000, 1.0, 700, 150)]
    {
        let rows: Vec<(f64, [f64; 3], f64)> = (0..n)
            .map(|k| {
                let still = k < 12 || k % period >= moving;
                let step = if still { 0.0 } else { 0.1 * ((k % period) as f64 + 1.0) };
                let t = k as f64 / rate;
                (t, [0.3 + step + noise(), -0.2 + noise(), 0.5 - step + noise()], 20.0)
            })
            .collect();
        let opt =
            StaticOptions { init_s: 11.5 / rate, static_threshold: 6.0, static_window_s: window_s, min_static_s: 0.1 };
        let got = static_intervals(Path::new("w.csv"), &rows, &opt, &seg).unwrap();
        // The direct computation.
        let var = |a: usize, b: usize| -> f64 {
            let m = (b - a) as f64;
            (0..3)
                .map(|i| {
                    let mean = rows[a..b].iter().map(|r| r.1[i]).sum::<f64>() / m;
                    rows[a..b].iter().map(|r| (r.1[i] - mean).powi(2)).sum::<f64>() / m
                })
                .sum()
        };
        let n_init = rows.iter().take_while(|r| r.0 < opt.init_s).count();
        let limit = opt.static_threshold * var(0, n_init);
        let dt = rows[n - 1].0 / (n - 1) as f64;
        let half = ((0.5 * window_s / dt).round() as usize).max(1);
        let still: Vec<bool> = (0..n).map(|k| var(k.saturating_sub(half), (k + half + 1).min(n)) <= limit).collect();
        let mut want = Vec::new();
        let mut k = 0;
        while k < n {
            let a = k;
            while k < n && still[k] {
                k += 1;
            }
            if k - a >= 3 && rows[k - 1].0 - rows[a].0 >= opt.min_static_s {
                want.push((rows[a].0, rows[k - 1].0, k - a));
            }
            k += 1;
        }
        let found: Vec<(f64, f64, usize)> = got.iter().map(|s| (s.t_s.0, s.t_s.1, s.n_rows)).collect();
        assert_eq!(found, want, "rate {rate}, {n} rows, window {window_s} s");
        assert!(!want.is_empty(), "rate {rate}, {n} rows: no interval to compare");
    }
}

/// A recording without a line end (`/dev/zero`) or whose header has 50 000 empty extra
/// columns, given to every command that reads recordings (each pass of `calibrate --free`,
/// `--dynamics identify`, `simulate --follow` included): one line naming the file and line 1,
/// in under a second within 100 MiB, nothing written.
#[test]
fn no_line_end_or_fifty_thousand_columns_are_refused_by_every_reader() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let header = format!("t_s,ux_V,uy_V,uz_V,temp_C,fx_g,fy_g,fz_g,pos{}\n", ",".repeat(50_000));
    std::fs::write(dir.join("wide.csv"), format!("{header}0.0,0,0,0,20,0,0,1,TP1{}\n", ",".repeat(50_000))).unwrap();
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let cal = root.join("calibrations/paper-two-range-dynamics.toml");
    let scenario = root.join("scenarios/paper-tilter.toml");
    let (cal, scenario) = (cal.to_str().unwrap(), scenario.to_str().unwrap());
    for (bad, why) in [("/dev/zero", "/dev/zero:1: line longer than"), ("wide.csv", "wide.csv:1: more than 4096 cells")]
    {
        for args in [
            vec!["calibrate", "--tilter", bad, "-o", "c.toml"],
            vec!["calibrate", "--free", "--tilter", bad, "-o", "c.toml"],
            vec!["calibrate", "--tilter", bad, "--model", "poly:1", "--dynamics", "identify", "-o", "c.toml"],
            vec!["verify", "--check", bad, "--calib", cal, "-o", "v"],
            vec!["replay", "--rec", bad, "--calib", cal, "-o", "r.csv"],
            vec!["simulate", "--follow", bad, scenario, "-o", "f.csv"],
        ] {
            let t = Instant::now();
            let o = run_limited(dir, &args);
            let took = t.elapsed();
            let e = String::from_utf8_lossy(&o.stderr);
            assert!(!o.status.success(), "{args:?}: accepted");
            assert!(took < Duration::from_secs(1), "{args:?}: {took:?}");
            assert_eq!(e.trim_end().lines().count(), 1, "{args:?}: {e}");
            assert!(e.starts_with(&format!("bins-cal: error: {why}")), "{args:?}: {e}");
        }
    }
    let left: Vec<String> =
        std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert_eq!(left, ["wide.csv"], "nothing written");
}
