//! Hostile inputs and interruptions against the real `bins-cal` binary (docs/output-safety.md,
//! docs/recording-format.md): one test per defect a sweep of bad inputs found, then the sweep
//! itself, which keeps them fixed — no panic, no input destroyed, no temporary file left after
//! SIGINT/SIGTERM, and a one-line error naming the file for every bad input.
#![cfg(unix)]
#![allow(unsafe_code, reason = "libc: signals sent to the child and its SIGINT disposition before exec")]

mod common;
mod hostile;
use common::csv_text::Csv;
use hostile::{run_in, s, text};

use std::os::unix::fs::symlink;
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::path::{Path, PathBuf};
use std::process::{Child, Output, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

/// A small valid campaign shared by the tests: a tilter recording, its calibration file and
/// blob, and two scenarios (one endless, one tiny).
struct Fixture {
    rec: PathBuf,
    cal_toml: PathBuf,
    cal_bin: PathBuf,
    long: PathBuf,
    tiny: PathBuf,
}

const LONG: &str = "description = \"endless\"\n[recording]\nrate_Hz = 1000.0\n[unit]\npreset = \"paper\"\n\
                    [[step]]\nkind = \"hold\"\nposition = \"TP3\"\ndwell_s = 2.0e5\n";
const TINY: &str = "description = \"tiny\"\n[recording]\nrate_Hz = 10.0\n[unit]\npreset = \"paper\"\n\
                    [[step]]\nkind = \"hold\"\nposition = \"TP3\"\ndwell_s = 1.0\n";

fn fixture() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| {
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("hostile-inputs");
        let (rec, cal_toml, cal_bin) = hostile::campaign(&dir);
        let f = Fixture { rec, cal_toml, cal_bin, long: dir.join("long.toml"), tiny: dir.join("tiny.toml") };
        std::fs::write(&f.long, LONG).unwrap();
        std::fs::write(&f.tiny, TINY).unwrap();
        f
    })
}

/// No panic: not exit 101 (panic) nor 134/SIGABRT (abort), no "panicked" on stderr.
fn assert_no_panic(o: &Output, args: &[&str]) {
    let err = text(&o.stderr);
    assert!(!matches!(o.status.code(), Some(101 | 134)), "{args:?} panicked: {:?} {err}", o.status);
    assert_ne!(o.status.signal(), Some(libc::SIGABRT), "{args:?} aborted: {err}");
    assert!(!err.contains("panicked"), "{args:?} panicked: {err}");
}

/// A refusal: exit 1, one line `bins-cal: error: …` containing every needle. Returns it.
fn assert_refused(o: &Output, args: &[&str], needles: &[&str]) -> String {
    assert_no_panic(o, args);
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{args:?} should be refused: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: one line: {err}");
    assert!(err.starts_with("bins-cal: error: "), "{args:?}: {err}");
    for n in needles {
        assert!(err.contains(n), "{args:?}: {err:?} should contain {n:?}");
    }
    err
}

/// The names of the temporary files (`.NAME.tmp-PID`) in `dir`.
fn temporaries(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains(".tmp-"))
        .collect()
}

/// Copies `src` into `dir` as `name`; returns the copy's path.
fn copy(src: &Path, dir: &Path, name: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::copy(src, &p).unwrap();
    p
}

/// The recording of the fixture with `edit` applied to its lines (0-based, comments and
/// header included), written to `dir/name`.
fn edited(dir: &Path, name: &str, edit: impl FnOnce(&mut Vec<String>)) -> PathBuf {
    let text = std::fs::read_to_string(&fixture().rec).unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    edit(&mut lines);
    let p = dir.join(name);
    std::fs::write(&p, lines.join("\n") + "\n").unwrap();
    p
}

/// The recording of the fixture with cell `col` (by header name) of data row `k` (0-based)
/// set to `value`, written to `dir/name`.
fn with_cell(dir: &Path, name: &str, k: usize, col: &str, value: &str) -> PathBuf {
    let mut rec = Csv::read(&fixture().rec);
    let c = rec.col(col);
    rec.rows[k][c] = value.to_string();
    let p = dir.join(name);
    rec.write(&p);
    p
}

/// Defect 1: an output that is an input — by name, through a symbolic link, through a hard
/// link — is refused, naming both, for every command that writes; the input is unchanged.
#[test]
fn an_output_that_is_an_input_is_refused_and_the_input_kept() {
    let f = fixture();
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let rec = copy(&f.rec, dir, "t.csv");
    let toml = copy(&f.cal_toml, dir, "cal.toml");
    let bin = copy(&f.cal_bin, dir, "cal.bin");
    let scen = copy(&f.tiny, dir, "tiny.toml");
    let consts = copy(&common::repo("data/paper-constants.csv"), dir, "k.csv");
    std::fs::create_dir(dir.join("v")).unwrap();
    let check = copy(&f.rec, &dir.join("v"), "verify.csv");
    symlink(&rec, dir.join("link.csv")).unwrap();
    std::fs::hard_link(&rec, dir.join("hard.csv")).unwrap();
    let inputs = [&rec, &toml, &bin, &scen, &consts, &check];
    let before: Vec<Vec<u8>> = inputs.iter().map(|p| std::fs::read(p).unwrap()).collect();
    let cases: &[(&[&str], &str, &str)] = &[
        (&["calibrate", "--tilter", "t.csv", "-o", "t.csv"], "t.csv", "t.csv"),
        (&["calibrate", "--tilter", "t.csv", "-o", "c.toml", "--blob", "t.csv"], "t.csv", "t.csv"),
        (&["calibrate", "--tilter", "t.csv", "-o", "link.csv"], "link.csv", "t.csv (the same file)"),
        (&["calibrate", "--tilter", "t.csv", "-o", "hard.csv"], "hard.csv", "t.csv (the same file)"),
        (&["replay", "--rec", "t.csv", "--calib", "cal.toml", "-o", "t.csv"], "t.csv", "t.csv"),
        (&["replay", "--rec", "t.csv", "--calib", "cal.toml", "-o", "cal.toml"], "cal.toml", "cal.toml"),
        (&["replay", "--rec", "t.csv", "--write-stream", "t.csv"], "t.csv", "t.csv"),
        (&["replay", "--rec", "t.csv", "--write-stream", "./link.csv"], "./link.csv", "t.csv"),
        (&["blob", "encode", "cal.toml", "-o", "cal.toml"], "cal.toml", "cal.toml"),
        (&["blob", "encode", "cal.toml", "-o", "x.bin", "--ihex", "./cal.toml"], "./cal.toml", "cal.toml"),
        (&["blob", "decode", "cal.bin", "-o", "cal.bin"], "cal.bin", "cal.bin"),
        (&["simulate", "tiny.toml", "-o", "tiny.toml", "--quiet"], "tiny.toml", "tiny.toml"),
        (&["diagnose", "--sim", "t.csv", "--real", "hard.csv", "--report", "t.csv"], "t.csv", "t.csv"),
        (
            &["diagnose", "--sim", "t.csv", "--real", "t.csv", "--report", "r.json", "--model", "t.csv"],
            "t.csv",
            "t.csv",
        ),
        (&["verify", "--check", "v/verify.csv", "--calib", "cal.toml", "-o", "v"], "verify.csv", "v/verify.csv"),
        (&["tempco", "--constants", "k.csv", "--json", "k.csv"], "k.csv", "k.csv"),
    ];
    for (args, out, input) in cases {
        let o = run_in(dir, args);
        assert_refused(&o, args, &[&format!("{out}: refusing to write the output over the input {input}")]);
    }
    // Two outputs on one file.
    let args = ["calibrate", "--tilter", "t.csv", "-o", "c.toml", "--blob", "c.toml"];
    assert_refused(&run_in(dir, &args), &args, &["c.toml: given for two outputs"]);
    for (p, b) in inputs.iter().zip(&before) {
        assert_eq!(&std::fs::read(p).unwrap(), b, "{} changed", p.display());
    }
    assert!(!dir.join("c.toml").exists() && !dir.join("x.bin").exists() && !dir.join("r.json").exists());
}

/// Starts `simulate` of the endless scenario into `dir/out.csv` and waits until its temporary
/// file exists; returns the child and that file.
fn start_long_simulation(dir: &Path) -> (Child, PathBuf) {
    let mut cmd = common::bin();
    cmd.args(["simulate", s(&fixture().long), "-o", "out.csv", "--quiet"]).current_dir(dir).stderr(Stdio::null());
    // SAFETY: only async-signal-safe calls between fork and exec. The test may run with
    // SIGINT ignored (a background job of a script), which the child would inherit and keep.
    unsafe {
        cmd.pre_exec(|| {
            libc::signal(libc::SIGINT, libc::SIG_DFL);
            Ok(())
        });
    }
    let child = cmd.spawn().unwrap();
    let tmp = dir.join(format!(".out.csv.tmp-{}", child.id()));
    let t0 = Instant::now();
    while !tmp.exists() {
        assert!(t0.elapsed() < Duration::from_secs(30), "no temporary file {}", tmp.display());
        std::thread::sleep(Duration::from_millis(5));
    }
    // Some data written, the run well under way (on a loaded machine the first buffer can
    // take longer than any fixed pause).
    while std::fs::metadata(&tmp).map_or(0, |m| m.len()) == 0 {
        assert!(t0.elapsed() < Duration::from_secs(30), "nothing written to {}", tmp.display());
        std::thread::sleep(Duration::from_millis(5));
    }
    std::thread::sleep(Duration::from_millis(50));
    (child, tmp)
}

fn signal(child: &Child, sig: i32) {
    let pid = libc::pid_t::try_from(child.id()).unwrap();
    // SAFETY: sends a signal to our own child process.
    assert_eq!(unsafe { libc::kill(pid, sig) }, 0);
}

/// Defect 2: SIGINT and SIGTERM remove the temporary output (the final name is never
/// created) and end the process by that signal.
#[test]
fn sigint_and_sigterm_leave_no_temporary_file() {
    for sig in [libc::SIGINT, libc::SIGTERM] {
        let d = tempfile::tempdir().unwrap();
        let (mut child, tmp) = start_long_simulation(d.path());
        assert!(std::fs::metadata(&tmp).unwrap().len() > 0);
        signal(&child, sig);
        let status = child.wait().unwrap();
        assert_eq!(status.signal(), Some(sig), "{status:?}");
        assert_eq!(temporaries(d.path()), Vec::<String>::new(), "signal {sig}");
        assert!(!d.path().join("out.csv").exists());
    }
}

/// Defect 2, SIGKILL: nothing can run then; the next run of the same output removes the
/// temporary files of dead processes, and keeps those of live ones.
#[test]
fn a_killed_run_leaves_a_temporary_file_the_next_run_removes() {
    let d = tempfile::tempdir().unwrap();
    let (mut child, tmp) = start_long_simulation(d.path());
    signal(&child, libc::SIGKILL);
    child.wait().unwrap();
    assert!(tmp.exists(), "SIGKILL cannot clean up");
    // A live process's temporary file (this test's own PID) and another output's.
    let live = d.path().join(format!(".out.csv.tmp-{}", std::process::id()));
    let other = d.path().join(".other.csv.tmp-999999999");
    std::fs::write(&live, "in use").unwrap();
    std::fs::write(&other, "not ours").unwrap();
    let o = run_in(d.path(), &["simulate", s(&fixture().tiny), "-o", "out.csv", "--quiet"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(!tmp.exists(), "the dead run's temporary file is removed");
    assert!(live.exists() && other.exists(), "only this output's files of dead processes go");
    assert!(d.path().join("out.csv").exists());
}

/// Defect 3: one extreme value is refused when read, naming file, line and column, at once
/// (it used to cost `diagnose` two minutes and end in "no mechanism found").
#[test]
fn an_extreme_value_is_refused_naming_file_line_and_column() {
    let f = fixture();
    let d = tempfile::tempdir().unwrap();
    let hot = with_cell(d.path(), "hot.csv", 100, "temp_C", "1e308");
    let line = std::fs::read_to_string(&hot).unwrap().lines().position(|l| l.contains("1e308")).unwrap() + 1;
    let t0 = Instant::now();
    let args = ["diagnose", "--sim", s(&f.rec), "--real", s(&hot), "--report", "r.json"];
    let e = assert_refused(&run_in(d.path(), &args), &args, &[&format!("hot.csv:{line}: column 5 `temp_C`: `1e308`")]);
    assert!(e.contains("outside the physical range -100 … 200 °C"), "{e}");
    assert!(t0.elapsed() < Duration::from_secs(20));
    assert!(!d.path().join("r.json").exists());
    // Saturated signals (defect 6's `verify` on 1e308 V) and a temperature just past the range.
    let sat = with_cell(d.path(), "sat.csv", 5, "uz_V", "-1e308");
    let args = ["verify", "--check", s(&sat), "--calib", s(&f.cal_toml), "-o", "v", "--pos-prefix", "TP"];
    assert_refused(&run_in(d.path(), &args), &args, &["sat.csv:", "column 4 `uz_V`: `-1e308` is outside"]);
    let warm = with_cell(d.path(), "warm.csv", 0, "temp_C", "200.5");
    let args = ["replay", "--rec", s(&warm), "--calib", s(&f.cal_toml), "-o", "o.csv"];
    assert_refused(&run_in(d.path(), &args), &args, &["warm.csv:", "`temp_C`: `200.5` is outside"]);
    assert!(!d.path().join("v").join("verify.csv").exists() && !d.path().join("o.csv").exists());
}

/// Defect 4: a reader that goes away (`| head -1`) ends the process by SIGPIPE, quietly.
#[test]
fn a_closed_pipe_ends_the_process_quietly() {
    let f = fixture();
    let d = tempfile::tempdir().unwrap();
    let mut child = common::bin()
        .args(["verify", "--check", s(&f.rec), "--calib", s(&f.cal_toml), "--pos-prefix", "TP", "-o"])
        .arg(d.path().join("v"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Closed before the table is printed.
    drop(child.stdout.take());
    let o = child.wait_with_output().unwrap();
    assert_eq!(o.status.signal(), Some(libc::SIGPIPE), "{:?}: {}", o.status, text(&o.stderr));
    assert_eq!(text(&o.stderr), "");
}

/// Defect 5: a calibration file goes through the blob encoder and the firmware's parser
/// wherever it is used, so `replay` and `verify` refuse what `blob encode` refuses, with the
/// same message; a replay output stream of random bytes is refused.
#[test]
fn a_calibration_is_checked_the_same_in_every_command() {
    let f = fixture();
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let good = std::fs::read_to_string(&f.cal_toml).unwrap();
    let t0 = good.lines().find(|l| l.starts_with("t0_C = ")).unwrap();
    std::fs::write(dir.join("t0.toml"), good.replace(t0, "t0_C = 250.0")).unwrap();
    let k = good.lines().skip_while(|l| !l.starts_with("k_V_per_g")).nth(1).unwrap();
    let first = k.trim().trim_start_matches('[').split(',').next().unwrap();
    std::fs::write(dir.join("k.toml"), good.replacen(&format!("[{first},"), "[1e-4,", 1)).unwrap();
    for (file, msg) in [
        ("t0.toml", "t0.toml: t0_C out of range"),
        ("k.toml", "k.toml: k_V_per_g[0][0] out of range (must be finite, |K_ii| within [1e-3, 1e3] V/g)"),
    ] {
        let runs: [&[&str]; 4] = [
            &["blob", "encode", file, "-o", "x.bin"],
            &["blob", "check", file],
            &["replay", "--rec", s(&f.rec), "--calib", file, "-o", "o.csv"],
            &["verify", "--check", s(&f.rec), "--calib", file, "-o", "v", "--pos-prefix", "TP"],
        ];
        for args in runs {
            assert_refused(&run_in(dir, args), args, &[msg]);
        }
    }
    // Random bytes of the right length as the firmware's output stream.
    let rows = Csv::read(&f.rec).rows.len();
    let mut x = 0x9E37_79B9_7F4A_7C15u64;
    let bytes: Vec<u8> = (0..rows * 16)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x as u8
        })
        .collect();
    std::fs::write(dir.join("rnd.bin"), &bytes).unwrap();
    let args = ["replay", "--rec", s(&f.rec), "--read-stream", "rnd.bin", "-o", "o.csv"];
    assert_refused(&run_in(dir, &args), &args, &["rnd.bin: result 1 (byte 0): status", "not a replay output stream"]);
    // Valid status words, a NaN acceleration in result 3.
    let mut zeros = vec![0u8; rows * 16];
    zeros[32..36].copy_from_slice(&f32::NAN.to_le_bytes());
    std::fs::write(dir.join("nan.bin"), &zeros).unwrap();
    let args = ["replay", "--rec", s(&f.rec), "--read-stream", "nan.bin", "-o", "o.csv"];
    assert_refused(&run_in(dir, &args), &args, &["nan.bin: result 3 (byte 32): acceleration NaN is not finite"]);
    assert!(!dir.join("o.csv").exists() && !dir.join("x.bin").exists());
}

/// Defect 6: a cut-off last line is an error naming file and line; a header-only recording is
/// refused where the output needs rows; a UTF-8 byte order mark is skipped.
#[test]
fn cut_off_line_header_only_and_byte_order_mark() {
    let f = fixture();
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let full = std::fs::read(&f.rec).unwrap();
    let n_lines = full.iter().filter(|b| **b == b'\n').count();
    let cut = dir.join("cut.csv");
    std::fs::write(&cut, &full[..full.len() - 12]).unwrap();
    let e = common::err(&["replay", "--rec", s(&cut), "--calib", s(&f.cal_toml), "-o", s(&dir.join("o.csv"))]);
    assert!(e.contains(&format!("cut.csv:{n_lines}: last line cut off: ")), "{e}");
    let header_end = full.windows(4).position(|w| w == b"\nt_s").unwrap() + 1;
    let header_len = full[header_end..].iter().position(|b| *b == b'\n').unwrap() + 1;
    std::fs::write(dir.join("head.csv"), &full[..header_end + header_len]).unwrap();
    let cal = s(&f.cal_toml);
    let runs: [&[&str]; 5] = [
        &["replay", "--rec", "head.csv", "--calib", cal, "-o", "o.csv"],
        &["replay", "--rec", "head.csv", "--write-stream", "o.bin"],
        &["verify", "--check", "head.csv", "--calib", cal, "-o", "v"],
        &["calibrate", "--tilter", "head.csv", "-o", "c.toml"],
        &["diagnose", "--sim", "head.csv", "--real", "head.csv", "--report", "r.json"],
    ];
    for args in runs {
        assert_refused(&run_in(dir, args), args, &["head.csv"]);
    }
    assert_eq!(temporaries(dir), Vec::<String>::new());
    for out in ["o.csv", "o.bin", "v", "c.toml", "r.json"] {
        assert!(!dir.join(out).exists(), "{out}");
    }
    let mut bom = b"\xEF\xBB\xBF".to_vec();
    bom.extend_from_slice(&full);
    std::fs::write(dir.join("bom.csv"), bom).unwrap();
    common::ok(&["replay", "--rec", s(&dir.join("bom.csv")), "--calib", cal, "-o", s(&dir.join("a.csv"))]);
    common::ok(&["replay", "--rec", s(&f.rec), "--calib", cal, "-o", s(&dir.join("b.csv"))]);
    assert_eq!(std::fs::read(dir.join("a.csv")).unwrap(), std::fs::read(dir.join("b.csv")).unwrap());
}

/// The sweep: every hostile recording and calibration through every command that reads it.
/// 0 panics, 0 inputs changed, 0 temporary files, a one-line error naming the file for each
/// bad input, success for the good ones.
#[test]
fn sweep_of_hostile_inputs() {
    let f = fixture();
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let full = std::fs::read(&f.rec).unwrap();
    let text_rec = String::from_utf8(full.clone()).unwrap();
    // (file, bad?) recordings.
    let mut recs: Vec<(PathBuf, bool)> = Vec::new();
    let mut add = |name: &str, bytes: Vec<u8>, bad: bool| {
        std::fs::write(dir.join(name), bytes).unwrap();
        recs.push((dir.join(name), bad));
    };
    add("empty.csv", Vec::new(), true);
    add("comments.csv", b"# only a comment\n".to_vec(), true);
    add("binary.csv", (0..4096u32).map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8).collect(), true);
    add("latin1.csv", [&full[..200], b"\xe9\xe9\n", &full[200..]].concat(), true);
    add("cut.csv", full[..full.len() - 7].to_vec(), true);
    add("crlf.csv", text_rec.replace('\n', "\r\n").into_bytes(), false);
    add("bom.csv", [b"\xEF\xBB\xBF".as_slice(), &full].concat(), false);
    add("nobom-noheader.csv", b"0,1,2,3,4\n".to_vec(), true);
    add("no-temp.csv", common::without_column(&text_rec, "temp_C").into_bytes(), true);
    for (name, col, v) in [
        ("t-nan.csv", "temp_C", "NaN"),
        ("t-inf.csv", "temp_C", "inf"),
        ("t-hot.csv", "temp_C", "1e308"),
        ("t-cold.csv", "temp_C", "-273.16"),
        ("u-sat.csv", "ux_V", "1e308"),
        ("u-big.csv", "uy_V", "-100.5"),
        ("f-big.csv", "fz_g", "1e5"),
        ("t-back.csv", "t_s", "-5"),
        ("u-text.csv", "uz_V", "0x1p3"),
    ] {
        let p = with_cell(dir, name, 40, col, v);
        recs.push((p, true));
    }
    let p = edited(dir, "long-line.csv", |l| {
        let n = l.len();
        l[n - 3].push_str(&",9".repeat(100_000));
    });
    recs.push((p, true));
    let cal = copy(&f.cal_toml, dir, "cal.toml");
    let good = copy(&f.rec, dir, "good.csv");
    let mut inputs: Vec<PathBuf> = recs.iter().map(|r| r.0.clone()).collect();
    inputs.extend([cal.clone(), good.clone()]);
    let before: Vec<Vec<u8>> = inputs.iter().map(|p| std::fs::read(p).unwrap()).collect();
    let (mut runs, mut refused) = (0, 0);
    for (rec, bad) in &recs {
        let r = s(rec);
        let name = rec.file_name().unwrap().to_str().unwrap();
        let mut cmds: Vec<Vec<&str>> = vec![
            vec!["replay", "--rec", r, "--calib", "cal.toml", "-o", "o.csv"],
            vec!["replay", "--rec", r, "--write-stream", "o.bin"],
            vec!["verify", "--check", r, "--calib", "cal.toml", "-o", "v", "--pos-prefix", "TP"],
            vec!["calibrate", "--tilter", r, "-o", "c.toml"],
        ];
        if *bad {
            // A good SIM with a bad REAL fails on reading, before any long computation.
            cmds.push(vec!["diagnose", "--sim", "good.csv", "--real", r, "--report", "r.json"]);
        }
        for args in &cmds {
            let o = run_in(dir, args);
            runs += 1;
            if *bad {
                assert_refused(&o, args, &[name]);
                refused += 1;
            } else {
                assert_no_panic(&o, args);
                assert!(o.status.success(), "{args:?}: {}", text(&o.stderr));
            }
        }
        if *bad {
            for out in ["o.csv", "o.bin", "c.toml", "r.json"] {
                assert!(!dir.join(out).exists(), "{out} written for {name}");
            }
        }
        for out in ["o.csv", "o.bin", "c.toml"] {
            let _ = std::fs::remove_file(dir.join(out));
        }
        let _ = std::fs::remove_dir_all(dir.join("v"));
    }
    // Hostile calibrations through every command that reads one.
    let bad_cals: Vec<(&str, Vec<u8>)> = vec![
        ("empty.toml", Vec::new()),
        ("junk.toml", b"\xff\xfe garbage = [".to_vec()),
        ("nan.toml", std::fs::read_to_string(&cal).unwrap().replacen("u0_V = [", "u0_V = [nan, ", 1).into_bytes()),
        ("junk.bin", (0..300u32).map(|i| (i * 7 + 3) as u8).collect()),
        ("empty.bin", Vec::new()),
    ];
    for (name, bytes) in &bad_cals {
        std::fs::write(dir.join(name), bytes).unwrap();
        let mut cmds: Vec<Vec<&str>> =
            vec![vec!["replay", "--rec", "good.csv", "--calib", name, "-o", "o.csv"], vec!["blob", "check", name]];
        if name.ends_with(".toml") {
            cmds.push(vec!["verify", "--check", "good.csv", "--calib", name, "-o", "v", "--pos-prefix", "TP"]);
            cmds.push(vec!["blob", "encode", name, "-o", "o.bin"]);
        } else {
            cmds.push(vec!["blob", "decode", name, "-o", "o.toml"]);
        }
        for args in &cmds {
            assert_refused(&run_in(dir, args), args, &[name]);
            runs += 1;
            refused += 1;
        }
        assert!(!dir.join("o.csv").exists() && !dir.join("o.bin").exists() && !dir.join("o.toml").exists());
    }
    for (p, b) in inputs.iter().zip(&before) {
        assert_eq!(&std::fs::read(p).unwrap(), b, "input {} changed", p.display());
    }
    assert_eq!(temporaries(dir), Vec::<String>::new());
    eprintln!("sweep: {runs} runs, {refused} refused with a one-line error, 0 panics, 0 inputs changed");
}

// Round 2: what a second sweep of hostile inputs found.

/// Runs `bins-cal args` in `dir`, killed after `secs` (a hang fails the test instead of
/// holding the suite).
fn run_bounded(dir: &Path, args: &[&str], secs: u64) -> Output {
    let mut child = common::bin()
        .args(args)
        .current_dir(dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("bins-cal runs");
    let t0 = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if t0.elapsed() > Duration::from_secs(secs) {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{args:?} still running after {secs} s");
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    child.wait_with_output().unwrap()
}

/// The files in `dir` (names), sorted.
fn listing(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> =
        std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    v.sort();
    v
}

/// `text` with the array value of the first line starting `key = [` given one element more
/// (`[[` rows: the first row one element more).
fn one_more(text: &str, key: &str) -> String {
    let start = format!("{key} = [");
    let mut done = false;
    text.lines()
        .map(|l| {
            if !done && l.starts_with(&start) {
                done = true;
                let rest = &l[start.len()..];
                if rest.is_empty() {
                    // A matrix by rows: the first row follows on the next line.
                    return format!("{start}\n    [0.001, ");
                }
                if let Some(r) = rest.strip_prefix('[') {
                    return format!("{start}[0.001, {r}");
                }
                return format!("{start}0.001, {rest}");
            }
            l.to_string()
        })
        .collect::<Vec<_>>()
        .join("\n")
        .replace("[0.001, \n    [", "[0.001, ")
        + "\n"
}

/// Round 2, item 1: an array longer than its key's fixed length is refused, naming the key,
/// by `blob check` and `blob encode` (and `encode` writes nothing); in a scenario by
/// `simulate`; in `vibration --env`. Too few elements were refused already, too many were cut
/// silently, the values shifting.
#[test]
fn an_over_long_array_is_refused_naming_the_key() {
    let f = fixture();
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let cal = std::fs::read_to_string(&f.cal_toml).unwrap();
    let with_dynamics = format!(
        "{cal}\n[thermal_dynamics]\nlag_tau_s = 10.0\nbias_play_width_C = 1.0\nbias_play_mg = [0.1, 0.2, 0.3]\n"
    );
    // A piecewise-linear calibration of the same recording, for the knots' keys.
    let pwl = dir.join("pwl-cal.toml");
    common::ok(&["calibrate", "--tilter", s(&f.rec), "--model", "pwl", "-o", s(&pwl)]);
    let pwl = std::fs::read_to_string(&pwl).unwrap();
    let cases: Vec<(&str, String)> = vec![
        ("du0_V", one_more(&pwl, "du0_V")),
        ("rel_k", one_more(&pwl, "rel_k")),
        ("u0_V", one_more(&cal, "u0_V")),
        ("temp_range_C", one_more(&cal, "temp_range_C")),
        ("k_V_per_g", one_more(&cal, "k_V_per_g")),
        ("alpha_V_per_Cn", one_more(&cal, "alpha_V_per_Cn")),
        ("rel_k_per_Cn", one_more(&cal, "rel_k_per_Cn")),
        ("bias_play_mg", one_more(&with_dynamics, "bias_play_mg")),
    ];
    for (key, text) in &cases {
        assert!(text.contains("[0.001, "), "{key}: the edit applies");
        let p = dir.join(format!("{key}.toml"));
        std::fs::write(&p, text).unwrap();
        for args in [vec!["blob", "check", s(&p)], vec!["blob", "encode", s(&p), "-o", "out.bin"]] {
            let e = assert_refused(&run_in(dir, &args), &args, &[&format!("{key}.toml"), key]);
            assert!(e.contains("exactly"), "{e}");
        }
        assert!(!dir.join("out.bin").exists(), "{key}: a blob was written");
    }
    // The same file with the right lengths passes (the edit, not the file, is refused).
    std::fs::write(dir.join("good.toml"), &with_dynamics).unwrap();
    assert!(run_in(dir, &["blob", "check", "good.toml"]).status.success());
    // A scenario: the start force and a hold's force; the unit's U0.
    let scen = [
        ("start_f_g", TINY.replace("rate_Hz = 10.0\n", "rate_Hz = 10.0\nstart_f_g = [0.0, 0.0, 1.0, 0.0]\n")),
        ("f_g", TINY.replace("position = \"TP3\"", "f_g = [0.0, 0.0, 1.0, 0.5]")),
        (
            "bias_play_mg",
            TINY.replace("preset = \"paper\"\n", "preset = \"paper\"\nbias_play_mg = [0.0, 0.0, 0.0, 1.0]\n"),
        ),
    ];
    for (key, text) in scen {
        let p = dir.join("scen.toml");
        std::fs::write(&p, text).unwrap();
        let args = ["simulate", "scen.toml", "-o", "out.csv", "--quiet"];
        let e = assert_refused(&run_in(dir, &args), &args, &["scen.toml", key]);
        assert!(e.contains("exactly"), "{e}");
        assert!(!dir.join("out.csv").exists());
    }
    // vibration --env.
    let env = std::fs::read_to_string(common::repo("data/vibration-env-paper.toml")).unwrap();
    std::fs::write(dir.join("env.toml"), env.replacen("ia_amp_g = [", "ia_amp_g = [0.1, ", 1)).unwrap();
    let cf = common::repo("data/al15-coefficients.csv");
    let args = ["vibration", "--cf", s(&cf), "--env", "env.toml"];
    assert_refused(&run_in(dir, &args), &args, &["env.toml", "ia_amp_g", "exactly"]);
}

/// Round 2, item 2: `verify --replayed` with a non-finite or absurd acceleration is refused
/// at the line (NaN was printed but skipped by the max, exit 0; `inf` or `1e300` made the
/// plot's axis loop forever), within seconds, and writes nothing.
#[test]
fn verify_refuses_a_non_finite_or_absurd_replayed_value() {
    let f = fixture();
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let rec = copy(&f.rec, dir, "t.csv");
    copy(&f.cal_toml, dir, "cal.toml");
    common::ok(&["replay", "--rec", s(&rec), "--calib", s(&dir.join("cal.toml")), "-o", s(&dir.join("rep.csv"))]);
    let good = std::fs::read_to_string(dir.join("rep.csv")).unwrap();
    let args = ["verify", "--check", "t.csv", "--calib", "cal.toml", "--pos-prefix", "TP", "-o", "v", "--replayed"];
    let mut ok = args.to_vec();
    ok.push("rep.csv");
    assert!(run_bounded(dir, &ok, 120).status.success(), "the unedited replay verifies");
    std::fs::remove_dir_all(dir.join("v")).unwrap();
    for bad in ["NaN", "inf", "-inf", "1e300"] {
        // Every row's ax_g: whatever the dwells, one of them holds it.
        let mut replay = Csv::parse(&good);
        let ax = replay.col("ax_g");
        for r in &mut replay.rows {
            r[ax] = bad.to_string();
        }
        replay.write(&dir.join("bad.csv"));
        let mut a = args.to_vec();
        a.push("bad.csv");
        let o = run_bounded(dir, &a, 60);
        assert_refused(&o, &a, &["bad.csv", "line 2"]);
        assert!(!dir.join("v").exists(), "{bad}: an output was written");
    }
}

/// Round 2, item 6: sizes that would exhaust the memory are refused before anything is
/// allocated: a hand step of a billion holds, a scenario or calibration that is `/dev/zero`.
#[test]
fn sizes_that_would_exhaust_the_memory_are_refused_first() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let hand = "[recording]\nrate_Hz = 10.0\n[unit]\npreset = \"paper\"\n[[step]]\nkind = \"hand\"\nholds = 1000000000\ninit_s = 1.0\ndwell_s = 1.0\n";
    std::fs::write(dir.join("hand.toml"), hand).unwrap();
    let args = ["simulate", "hand.toml", "-o", "out.csv", "--quiet"];
    assert_refused(&run_bounded(dir, &args, 30), &args, &["hand.toml", "step[0].holds", "1000000000"]);
    let cal = s(&fixture().cal_toml);
    let rec = s(&fixture().rec);
    for args in [
        vec!["simulate", "/dev/zero", "-o", "out.csv", "--quiet"],
        vec!["blob", "check", "/dev/zero"],
        vec!["blob", "encode", "/dev/zero", "-o", "out.bin"],
        vec!["replay", "--rec", rec, "--calib", "/dev/zero", "-o", "out.csv"],
        vec!["verify", "--check", rec, "--calib", "/dev/zero", "-o", "v"],
        vec!["calibrate", "--tilter", rec, "--dynamics", "/dev/zero", "-o", "c.toml"],
    ] {
        let o = run_bounded(dir, &args, 30);
        assert_refused(&o, &args, &["/dev/zero"]);
    }
    let _ = cal;
    assert_eq!(listing(dir), ["hand.toml"], "nothing written");
}

/// A usage error of clap: exit 2, the option and the reason named.
fn assert_usage_error(o: &Output, args: &[&str], needles: &[&str]) {
    assert_no_panic(o, args);
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{args:?} should be refused: {err}");
    for n in needles {
        assert!(err.contains(n), "{args:?}: {err:?} should contain {n:?}");
    }
}

/// Round 2, item 8: a non-finite or absurd number given as an option is refused by name
/// before anything runs (`--t0 nan` gave T0 = −40 °C, `--static-window-s 0` changed K, …);
/// `replay --ve profile:N` beyond the calibration's profiles is refused (every sample was
/// flagged).
#[test]
fn a_non_finite_or_absurd_option_is_refused() {
    let f = fixture();
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    copy(&f.rec, dir, "t.csv");
    copy(&f.cal_toml, dir, "cal.toml");
    let cal = ["calibrate", "--tilter", "t.csv", "-o", "c.toml"];
    let free = ["calibrate", "--tilter", "t.csv", "--free", "-o", "c.toml"];
    let ver = ["verify", "--check", "t.csv", "--calib", "cal.toml", "--pos-prefix", "TP", "-o", "v"];
    let consts = common::repo("data/paper-constants.csv");
    let cases: Vec<(Vec<&str>, [&str; 2], &str)> = vec![
        (cal.to_vec(), ["--t0", "nan"], "not a finite number"),
        (cal.to_vec(), ["--t0", "inf"], "not a finite number"),
        (cal.to_vec(), ["--settle-s", "-1"], "must be from 0"),
        (cal.to_vec(), ["--settle-s", "nan"], "not a finite number"),
        (cal.to_vec(), ["--temp-tol-c", "-5"], "greater than 0"),
        (cal.to_vec(), ["--max-std-v", "nan"], "not a finite number"),
        (cal.to_vec(), ["--tilt-tol-mrad", "0"], "greater than 0"),
        (cal.to_vec(), ["--dynamics-block-s", "1e-300"], "must be from"),
        (cal.to_vec(), ["--knots", "nan"], "not a finite number"),
        (free.to_vec(), ["--static-window-s", "0"], "must be from"),
        (free.to_vec(), ["--static-window-s", "-1"], "must be from"),
        (free.to_vec(), ["--static-window-s", "nan"], "not a finite number"),
        (free.to_vec(), ["--min-static-s", "nan"], "not a finite number"),
        (free.to_vec(), ["--init-s", "inf"], "not a finite number"),
        (free.to_vec(), ["--static-threshold", "-1"], "greater than 0"),
        (ver.to_vec(), ["--settle-s", "nan"], "not a finite number"),
        (ver.to_vec(), ["--temp-tol-c", "nan"], "not a finite number"),
        (ver.to_vec(), ["--temp-tol-c", "-5"], "greater than 0"),
        (vec!["tempco", "--constants", s(&consts)], ["--t0", "nan"], "not a finite"),
    ];
    for (base, [opt, val], why) in &cases {
        let mut args = base.clone();
        let given = format!("{opt}={val}");
        args.push(&given);
        assert_usage_error(&run_in(dir, &args), &args, &[opt, why]);
    }
    // The fixture's calibration has no vibration model: no profile to take.
    let args = ["replay", "--rec", "t.csv", "--calib", "cal.toml", "--ve", "profile:0", "-o", "r.csv"];
    assert_refused(&run_in(dir, &args), &args, &["--ve profile:0", "cal.toml", "0 flight-phase profile"]);
    assert_eq!(listing(dir), ["cal.toml", "t.csv"], "nothing written");
}

/// Round 2, item 10: scenario values the simulator cannot stand for are refused naming the
/// scenario's key (they were accepted, or blamed on a line of the output file).
#[test]
fn an_absurd_scenario_value_is_refused_naming_its_key() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let unit = "[unit]\npreset = \"paper\"\n";
    let cases = [
        ("thermal.self_heating_C", TINY.replace(unit, &format!("{unit}[thermal]\nself_heating_C = 500.0\n"))),
        ("step[0].f_g[0]", TINY.replace("position = \"TP3\"", "f_g = [1.0e6, 0.0, 0.0]")),
        ("noise.white_V[0]", TINY.replace(unit, &format!("{unit}[noise]\nwhite_V = 1.0e300\n"))),
        ("noise.adc_lsb_V", TINY.replace(unit, &format!("{unit}[noise]\nadc_lsb_V = 1.0e-320\n"))),
        ("recording.start_f_g[2]", TINY.replace("rate_Hz = 10.0\n", "rate_Hz = 10.0\nstart_f_g = [0.0, 0.0, 1.0e9]\n")),
        ("unit.warmup_V[0]", TINY.replace(unit, &format!("{unit}warmup_V = [1.0e300, 0.0, 0.0]\n"))),
        ("unit.bias_play_mg[0]", TINY.replace(unit, &format!("{unit}bias_play_mg = [1.0e300, 0.0, 0.0]\n"))),
        ("recording.power_on_s", TINY.replace("rate_Hz = 10.0\n", "rate_Hz = 10.0\npower_on_s = 1.0e300\n")),
    ];
    for (key, text) in cases {
        assert_ne!(text, TINY, "{key}: the edit applies");
        std::fs::write(dir.join("scen.toml"), text).unwrap();
        let args = ["simulate", "scen.toml", "-o", "out.csv", "--quiet"];
        let e = assert_refused(&run_bounded(dir, &args, 60), &args, &["scen.toml", key]);
        assert!(!e.contains("out.csv"), "blamed on the output: {e}");
        assert!(!dir.join("out.csv").exists());
    }
}

/// Round 2, item 11: `--ihex` places the blob only where the CALIB region of the linker
/// script can hold it: a region shorter than the blob, an ORIGIN not word-aligned, a second
/// CALIB region are refused naming the linker script, and neither output is written.
#[test]
fn ihex_is_refused_outside_the_calib_region() {
    let f = fixture();
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    copy(&f.cal_toml, dir, "cal.toml");
    let cases = [
        ("CALIB : ORIGIN = 0x003FF000, LENGTH = 16\n", "LENGTH of 16 bytes"),
        ("CALIB : ORIGIN = 0x003FF001, LENGTH = 4K\n", "not a multiple of 4"),
        ("CALIB : ORIGIN = 0x003FF000, LENGTH = 4K\n  CALIB (r) : ORIGIN = 0x003FE000, LENGTH = 4K\n", "second CALIB"),
    ];
    for (region, why) in cases {
        let text = format!("MEMORY\n{{\n  FLASH : ORIGIN = 0x00000000, LENGTH = 1M\n  {region}}}\n");
        std::fs::write(dir.join("m.x"), text).unwrap();
        let args = ["blob", "encode", "cal.toml", "-o", "c.bin", "--ihex", "c.hex", "--memory-x", "m.x"];
        assert_refused(&run_in(dir, &args), &args, &["m.x", why]);
        let args = ["calibrate", "--tilter", s(&f.rec), "--model", "poly:2", "-o", "c.toml", "--blob", "c.bin"];
        let mut args = args.to_vec();
        args.extend(["--ihex", "c.hex", "--memory-x", "m.x"]);
        assert_refused(&run_in(dir, &args), &args, &["m.x", why]);
        assert_eq!(listing(dir), ["cal.toml", "m.x"], "{why}: nothing written");
    }
}

/// Round 2, item 12: `tempco` refuses a temperature of 1e6 °C and an all-zero K row;
/// `vibration` refuses a PSD of 1e300 (it printed `inf`) and K1 = 0.
#[test]
fn tempco_and_vibration_refuse_absurd_values() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let table = Csv::read(&common::repo("data/paper-constants.csv"));
    let row70 = table.rows.iter().position(|r| table.cell(r, "temp_C") == "70").unwrap();
    let (mut hot, mut zero) = (table.clone(), table.clone());
    let t = hot.col("temp_C");
    hot.rows[row70][t] = "1e6".into();
    for k in ["Kxx", "Kxy", "Kxz"] {
        let c = zero.col(k);
        zero.rows[row70][c] = "0".into();
    }
    let cases = [("hot.csv", hot.to_text(), "1000000 °C"), ("zero.csv", zero.to_text(), "Kxx")];
    for (name, text, why) in cases {
        std::fs::write(dir.join(name), text).unwrap();
        let args = ["tempco", "--constants", name];
        // `FILE:LINE, column …`: the file and the line of the row.
        assert_refused(&run_in(dir, &args), &args, &[&format!("{name}:"), ", column `", why]);
    }
    let mut cf = Csv::read(&common::repo("data/al15-coefficients.csv"));
    let k1 = cf.col("K1_V_per_g");
    cf.rows[0][k1] = "0".into();
    cf.write(&dir.join("k0.csv"));
    let env = common::repo("data/vibration-env-paper.toml");
    let args = ["vibration", "--cf", "k0.csv", "--env", s(&env)];
    assert_refused(&run_in(dir, &args), &args, &["k0.csv", "K1_V_per_g"]);
    let text = std::fs::read_to_string(&env).unwrap();
    let psd = text.lines().find(|l| l.starts_with("psd_g2_per_Hz")).unwrap();
    std::fs::write(dir.join("env.toml"), text.replace(psd, "psd_g2_per_Hz = [0.0, 1e300]")).unwrap();
    let cfp = common::repo("data/al15-coefficients.csv");
    let args = ["vibration", "--cf", s(&cfp), "--env", "env.toml"];
    let e = assert_refused(&run_in(dir, &args), &args, &["env.toml", "psd_g2_per_Hz"]);
    assert!(!e.contains("inf"), "{e}");
}

/// Round 2, item 13 (containers): a calibration is a blob or a calibration file by its
/// content, whatever its name: `verify`, `diagnose --calib` and `replay` take a blob named
/// `.toml` and a calibration file named `.bin`; `blob encode` given a blob says it is one
/// (it said "stream did not contain valid UTF-8").
#[test]
fn a_calibration_is_told_blob_or_file_by_its_content() {
    let f = fixture();
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    copy(&f.rec, dir, "t.csv");
    copy(&f.cal_bin, dir, "blob.toml");
    copy(&f.cal_toml, dir, "file.bin");
    for cal in ["blob.toml", "file.bin"] {
        let runs: [&[&str]; 4] = [
            &["verify", "--check", "t.csv", "--calib", cal, "--pos-prefix", "TP", "-o", "v"],
            &["diagnose", "--calib", cal, "--real", "t.csv", "--report", "r.json"],
            &["replay", "--rec", "t.csv", "--calib", cal, "-o", "r.csv"],
            &["blob", "check", cal],
        ];
        for args in runs {
            let o = run_bounded(dir, args, 120);
            assert!(o.status.success(), "{args:?}: {}", text(&o.stderr));
        }
    }
    // The two containers give one replay.
    common::ok(&[
        "replay",
        "--rec",
        s(&dir.join("t.csv")),
        "--calib",
        s(&dir.join("file.bin")),
        "-o",
        s(&dir.join("r2.csv")),
    ]);
    assert_eq!(std::fs::read(dir.join("r.csv")).unwrap(), std::fs::read(dir.join("r2.csv")).unwrap());
    let args = ["blob", "encode", "blob.toml", "-o", "x.bin"];
    assert_refused(&run_in(dir, &args), &args, &["blob.toml", "a calibration blob", "blob decode"]);
    let args = ["blob", "decode", "file.bin", "-o", "x.toml"];
    assert_refused(&run_in(dir, &args), &args, &["file.bin", "a calibration file (TOML), not a blob"]);
}
