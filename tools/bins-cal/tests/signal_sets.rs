//! "All or nothing" through a signal (docs/output-safety.md): a set of outputs committed by
//! `fsio::commit_all` appears whole or not at all when SIGTERM arrives while it is being
//! renamed into place, and a directory made for it goes again when it does not appear.
//!
//! The child is this test binary run again with `SIGNAL_SET_CHILD` set: it takes the signals
//! as `bins-cal` does (`fsio::remove_temporaries_on_signals`), writes 400 outputs (and a
//! fresh directory for them) and commits them together. The parent watches the directory and
//! sends SIGTERM as soon as the first output has been renamed into place, the middle of the
//! renames, where the set used to be left cut (one rename at a time under the registry's
//! lock: a signal between two renames removed the rest).
#![allow(unsafe_code, reason = "libc: SIGTERM sent to the child")]

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const OUTPUTS: usize = 400;

fn names(dir: &Path) -> Vec<String> {
    match std::fs::read_dir(dir) {
        Ok(d) => d.map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect(),
        Err(_) => Vec::new(),
    }
}

/// The child's work (run only with `SIGNAL_SET_CHILD`).
#[test]
fn child_commits_a_set() {
    let Some(dir) = std::env::var_os("SIGNAL_SET_CHILD") else { return };
    let dir = PathBuf::from(dir);
    bins_cal::fsio::remove_temporaries_on_signals();
    let sub = dir.join("set");
    let made = bins_cal::fsio::OutputDir::create(&sub).unwrap();
    let files: Vec<bins_cal::fsio::AtomicFile> = (0..OUTPUTS)
        .map(|k| {
            let mut f = bins_cal::fsio::AtomicFile::create(&sub.join(format!("out{k:04}.txt"))).unwrap();
            use std::io::Write;
            writeln!(f.writer(), "output {k}").unwrap();
            f
        })
        .collect();
    bins_cal::fsio::commit_all(files).unwrap();
    made.keep();
}

#[test]
fn sigterm_during_the_renames_leaves_the_set_whole_or_absent() {
    if std::env::var_os("SIGNAL_SET_CHILD").is_some() {
        return;
    }
    let mut hit_middle = 0;
    for round in 0..6 {
        // On a memory file system where there is one: 400 fsyncs cost nothing there.
        let shm = Path::new("/dev/shm");
        let d = if shm.is_dir() { tempfile::tempdir_in(shm) } else { tempfile::tempdir() }.unwrap();
        let sub = d.path().join("set");
        let child = Command::new(std::env::current_exe().unwrap())
            .args(["--exact", "child_commits_a_set", "--nocapture", "--test-threads=1"])
            .env("SIGNAL_SET_CHILD", d.path())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        // Wait for the first output in place, then signal at once.
        let start = Instant::now();
        let signalled = loop {
            let n = names(&sub);
            if n.iter().any(|f| f.starts_with("out")) {
                let pid = libc::pid_t::try_from(child.id()).unwrap();
                // SAFETY: sends a signal to our own child process, not yet waited for.
                assert_eq!(unsafe { libc::kill(pid, libc::SIGTERM) }, 0);
                break true;
            }
            if start.elapsed() > Duration::from_secs(60) {
                break false;
            }
            std::thread::yield_now();
        };
        let out = child.wait_with_output().unwrap();
        assert!(signalled, "round {round}: no output appeared in 60 s ({:?})", out.status);
        let n = names(&sub);
        let finals = n.iter().filter(|f| f.starts_with("out")).count();
        let temps = n.iter().filter(|f| f.starts_with('.')).count();
        assert_eq!(temps, 0, "round {round}: temporary files left: {n:?}");
        assert!(finals == OUTPUTS || finals == 0, "round {round}: {finals} of {OUTPUTS} outputs: the set was cut");
        if finals == OUTPUTS {
            hit_middle += 1;
        }
    }
    // The signal arrived after the first rename each time: the set is whole every time.
    assert_eq!(hit_middle, 6);
}

/// `diagnose --report --model --plots` killed by SIGTERM at times swept over its run: the
/// report, the model and the plot directory (created by the run) are all there or none is,
/// and no temporary file is left.
#[test]
fn diagnose_outputs_are_whole_or_absent_through_sigterm() {
    if std::env::var_os("SIGNAL_SET_CHILD").is_some() {
        return;
    }
    let bin = env!("CARGO_BIN_EXE_bins-cal");
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let run = |args: &[&str]| {
        let o = Command::new(bin).args(args).current_dir(dir).output().unwrap();
        assert!(o.status.success(), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
    };
    let scen = repo.join("scenarios/test-tilter-3t.toml");
    run(&["simulate", scen.to_str().unwrap(), "-o", "t3.csv", "--quiet"]);
    run(&["calibrate", "--tilter", "t3.csv", "--model", "poly:1", "-o", "cal.toml"]);
    let args = ["diagnose", "--calib", "cal.toml", "--real", "t3.csv", "--report", "r.json", "--model", "m.toml"];
    let started = Instant::now();
    run(&[&args[..], &["--plots", "p0"]].concat());
    let full = started.elapsed();
    let (mut whole, mut absent) = (0, 0);
    for k in 0..8 {
        let sub = dir.join(format!("run{k}"));
        std::fs::create_dir(&sub).unwrap();
        for f in ["cal.toml", "t3.csv"] {
            std::fs::copy(dir.join(f), sub.join(f)).unwrap();
        }
        let child = Command::new(bin)
            .args(args)
            .args(["--plots", "plots/p"])
            .current_dir(&sub)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        std::thread::sleep(full.mul_f64(0.5 + 0.1 * k as f64));
        let pid = libc::pid_t::try_from(child.id()).unwrap();
        // SAFETY: sends a signal to our own child process, not yet waited for.
        unsafe { libc::kill(pid, libc::SIGTERM) };
        child.wait_with_output().unwrap();
        let n = names(&sub);
        assert!(!n.iter().any(|f| f.starts_with('.')), "run {k}: temporary files left: {n:?}");
        let report = sub.join("r.json").exists();
        let model = sub.join("m.toml").exists();
        let plots = names(&sub.join("plots/p")).iter().filter(|f| f.ends_with(".png")).count();
        match (report, model, plots > 0, sub.join("plots").exists()) {
            (true, true, true, true) => whole += 1,
            (false, false, false, false) => absent += 1,
            other => panic!("run {k}: report, model, plots, plot directory: {other:?}: a set cut"),
        }
    }
    eprintln!("{whole} runs left the whole set, {absent} none");
    assert_eq!(whole + absent, 8);
}
