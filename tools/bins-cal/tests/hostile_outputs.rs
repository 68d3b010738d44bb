//! Hostile outputs against the real `bins-cal` binary (docs/output-safety.md): what a second
//! sweep found on the writing side. A temporary file is never opened through a link planted
//! at its name; a special file given as the output is written in place or refused, never
//! replaced; a replaced file keeps its mode; every command with several outputs writes all or
//! none; `diagnose --plots` never replaces an input or another output; the messages name the
//! output the user gave.
#![cfg(unix)]

#[allow(dead_code)] // the helpers other test files use
mod common;
mod hostile;
use hostile::{run_in, s, text};

use std::os::unix::fs::{FileTypeExt, PermissionsExt, symlink};
use std::path::{Path, PathBuf};
use std::process::Output;
use std::sync::OnceLock;

/// A small valid campaign: a tilter recording, its calibration file and blob.
struct Fixture {
    rec: PathBuf,
    cal_toml: PathBuf,
    cal_bin: PathBuf,
}

fn fixture() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| {
        let (rec, cal_toml, cal_bin) =
            hostile::campaign(&Path::new(env!("CARGO_TARGET_TMPDIR")).join("hostile-outputs"));
        Fixture { rec, cal_toml, cal_bin }
    })
}

/// Runs `bins-cal args` in `dir` through `sh`, after `setup` (shell commands in which `$$` is
/// the PID `bins-cal` will have: `exec` keeps it), so that a file can be planted at the name
/// of its temporary file.
fn run_planted(dir: &Path, setup: &str, args: &[&str]) -> Output {
    let script = format!("{setup} && exec \"$0\" \"$@\"");
    std::process::Command::new("sh")
        .arg("-c")
        .arg(script)
        .arg(env!("CARGO_BIN_EXE_bins-cal"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("sh runs")
}

fn copy(src: &Path, dir: &Path, name: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::copy(src, &p).unwrap();
    p
}

/// The files in `dir` (names), sorted.
fn listing(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> =
        std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    v.sort();
    v
}

/// A refusal: exit 1, one line `bins-cal: error: …` containing every needle. Returns it.
fn assert_refused(o: &Output, args: &[&str], needles: &[&str]) -> String {
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{args:?} should be refused: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: one line: {err}");
    assert!(err.starts_with("bins-cal: error: "), "{args:?}: {err}");
    for n in needles {
        assert!(err.contains(n), "{args:?}: {err:?} should contain {n:?}");
    }
    assert!(!err.contains(".tmp-"), "{args:?}: the temporary name in the message: {err}");
    err
}

fn assert_ok(o: &Output, args: &[&str]) {
    assert!(o.status.success(), "{args:?}: {}", text(&o.stderr));
}

/// Round 2, item 4: a symbolic link (or a directory) planted at the temporary file's name is
/// not followed: the file it points to is unchanged, the output is a regular file with the
/// data, and the link is left as it was.
#[test]
fn a_link_planted_at_the_temporary_name_is_not_followed() {
    let f = fixture();
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    copy(&f.cal_bin, dir, "cal.bin");
    std::fs::write(dir.join("victim"), "precious\n").unwrap();
    let args = ["blob", "decode", "cal.bin", "-o", "out.toml"];
    let o = run_planted(dir, "ln -s victim .out.toml.tmp-$$", &args);
    assert_ok(&o, &args);
    assert_eq!(std::fs::read_to_string(dir.join("victim")).unwrap(), "precious\n");
    let meta = std::fs::symlink_metadata(dir.join("out.toml")).unwrap();
    assert!(meta.file_type().is_file(), "out.toml is a {:?}", meta.file_type());
    assert!(std::fs::read_to_string(dir.join("out.toml")).unwrap().contains("k_V_per_g"));
    // A directory at the name ("o.csv: Is a directory" named the output for the temporary).
    let args = ["replay", "--rec", s(&f.rec), "--calib", "cal.bin", "-o", "o.csv"];
    let o = run_planted(dir, "mkdir .o.csv.tmp-$$", &args);
    assert_ok(&o, &args);
    assert!(std::fs::symlink_metadata(dir.join("o.csv")).unwrap().file_type().is_file());
}

/// Round 2, item 5: an output onto a special file is written in place (a character device,
/// a FIFO with a reader) or refused (a FIFO without one, a directory), never replaced by a
/// regular file; a replaced regular file keeps its mode (a 0600 file came back 0644).
#[test]
fn a_special_file_is_never_replaced_and_a_mode_is_kept() {
    let f = fixture();
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    copy(&f.cal_bin, dir, "cal.bin");
    // A FIFO nobody reads: refused at once (not a hang), and still a FIFO.
    assert!(std::process::Command::new("mkfifo").arg(dir.join("fifo")).status().unwrap().success());
    let args = ["blob", "decode", "cal.bin", "-o", "fifo"];
    assert_refused(&run_in(dir, &args), &args, &["fifo", "nobody reads"]);
    assert!(std::fs::symlink_metadata(dir.join("fifo")).unwrap().file_type().is_fifo());
    // A FIFO with a reader: written into.
    let fifo = dir.join("fifo");
    let reader = std::thread::spawn(move || std::fs::read_to_string(fifo).unwrap());
    // The reader opens first (the open blocks until both ends are there); retry until it has.
    let mut o = run_in(dir, &args);
    for _ in 0..200 {
        if o.status.success() {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
        o = run_in(dir, &args);
    }
    assert_ok(&o, &args);
    assert!(reader.join().unwrap().contains("k_V_per_g"));
    assert!(std::fs::symlink_metadata(dir.join("fifo")).unwrap().file_type().is_fifo());
    // A character device: /dev/null takes the output in place.
    let args = ["blob", "decode", "cal.bin", "-o", "/dev/null"];
    assert_ok(&run_in(dir, &args), &args);
    assert!(std::fs::metadata("/dev/null").unwrap().file_type().is_char_device());
    // A directory.
    std::fs::create_dir(dir.join("d.toml")).unwrap();
    let args = ["blob", "decode", "cal.bin", "-o", "d.toml"];
    assert_refused(&run_in(dir, &args), &args, &["d.toml", "is a directory"]);
    // A 0600 file replaced stays 0600; a new file has the usual mode.
    std::fs::write(dir.join("secret.toml"), "old\n").unwrap();
    std::fs::set_permissions(dir.join("secret.toml"), std::fs::Permissions::from_mode(0o600)).unwrap();
    let args = ["blob", "decode", "cal.bin", "-o", "secret.toml"];
    assert_ok(&run_in(dir, &args), &args);
    let m = std::fs::metadata(dir.join("secret.toml")).unwrap();
    assert_eq!(m.permissions().mode() & 0o7777, 0o600);
    assert!(std::fs::read_to_string(dir.join("secret.toml")).unwrap().contains("k_V_per_g"));
    // A symbolic link to a regular file as the output: the file replaced, the link kept.
    std::fs::write(dir.join("target.toml"), "old\n").unwrap();
    symlink("target.toml", dir.join("link.toml")).unwrap();
    let args = ["blob", "decode", "cal.bin", "-o", "link.toml"];
    assert_ok(&run_in(dir, &args), &args);
    assert!(std::fs::symlink_metadata(dir.join("link.toml")).unwrap().file_type().is_symlink());
    assert!(std::fs::read_to_string(dir.join("target.toml")).unwrap().contains("k_V_per_g"));
    assert!(listing(dir).iter().all(|n| !n.contains(".tmp-")), "{:?}", listing(dir));
}

/// Round 2, item 7: a command with several outputs writes all of them or none: when one
/// cannot be written (its directory is missing, or it is a directory), the others are not
/// left behind.
#[test]
fn several_outputs_are_written_all_or_nothing() {
    let f = fixture();
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    copy(&f.rec, dir, "t.csv");
    copy(&f.cal_toml, dir, "cal.toml");
    let before = listing(dir);
    let cases: [&[&str]; 7] = [
        &["calibrate", "--tilter", "t.csv", "--model", "poly:2", "-o", "ok.toml", "--blob", "nodir/x.bin"],
        &["calibrate", "--tilter", "t.csv", "--model", "poly:2", "-o", "ok.toml", "--ihex", "nodir/x.hex"],
        &[
            "calibrate",
            "--tilter",
            "t.csv",
            "--model",
            "poly:2",
            "-o",
            "ok.toml",
            "--blob",
            "ok.bin",
            "--ihex",
            "nodir/x.hex",
        ],
        &["blob", "encode", "cal.toml", "-o", "ok.bin", "--ihex", "nodir/x.hex"],
        &["diagnose", "--calib", "cal.toml", "--real", "t.csv", "--report", "ok.json", "--model", "nodir/m.toml"],
        &[
            "diagnose",
            "--calib",
            "cal.toml",
            "--real",
            "t.csv",
            "--report",
            "ok.json",
            "--plots",
            "plots",
            "--model",
            "nodir/m.toml",
        ],
        &[
            "diagnose", "--calib", "cal.toml", "--real", "t.csv", "--report", "ok.json", "--model", "ok.toml",
            "--plots", "t.csv",
        ],
    ];
    for args in cases {
        let o = run_in(dir, args);
        assert_refused(&o, args, &[]);
        assert_eq!(listing(dir), before, "{args:?} left an output");
    }
    // verify: verify.png cannot be written (a directory there), so verify.csv is not either.
    std::fs::create_dir_all(dir.join("v/verify.png")).unwrap();
    let args = ["verify", "--check", "t.csv", "--calib", "cal.toml", "--pos-prefix", "TP", "-o", "v"];
    assert_refused(&run_in(dir, &args), &args, &["verify.png"]);
    assert_eq!(listing(&dir.join("v")), ["verify.png"]);
}

/// Round 2, item 3: `diagnose --plots DIR` never replaces an input or another output named
/// like one of its plots: refused, naming both, before anything is written.
#[test]
fn diagnose_plots_never_replace_an_input_or_the_report() {
    let f = fixture();
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    std::fs::create_dir(dir.join("p")).unwrap();
    let real = copy(&f.rec, &dir.join("p"), "residual_x.png");
    let cal = copy(&f.cal_toml, &dir.join("p"), "residual_y.png");
    copy(&f.rec, dir, "t.csv");
    copy(&f.cal_toml, dir, "cal.toml");
    let (rec_bytes, cal_bytes) = (std::fs::read(&real).unwrap(), std::fs::read(&cal).unwrap());
    let cases: [(&[&str], &str); 3] = [
        (
            &["diagnose", "--calib", "cal.toml", "--real", "p/residual_x.png", "--report", "r.json", "--plots", "p"],
            "p/residual_x.png",
        ),
        (
            &["diagnose", "--calib", "p/residual_y.png", "--real", "t.csv", "--report", "r.json", "--plots", "p"],
            "p/residual_y.png",
        ),
        (
            &["diagnose", "--calib", "cal.toml", "--real", "t.csv", "--report", "q/residual_z.png", "--plots", "q"],
            "q/residual_z.png",
        ),
    ];
    for (args, clash) in cases {
        assert_refused(&run_in(dir, args), args, &[clash]);
    }
    assert_eq!(std::fs::read(&real).unwrap(), rec_bytes);
    assert_eq!(std::fs::read(&cal).unwrap(), cal_bytes);
    assert!(!dir.join("r.json").exists() && !dir.join("q").exists());
    // With no clash the same run writes the report and the plots.
    let args = ["diagnose", "--calib", "cal.toml", "--real", "t.csv", "--report", "r.json", "--plots", "q"];
    assert_ok(&run_in(dir, &args), &args);
    assert!(dir.join("r.json").is_file() && dir.join("q/residual_z.png").is_file());
}

/// Round 2, item 13: the messages. replay on a full device names the output; an output name
/// of 250 characters works (the temporary file's suffix made it too long); `-o -` is refused
/// saying what to give instead, and no file `-` appears; a plotting error is said in words
/// (an I/O error was printed as `IOError(Os { … })`).
#[test]
fn the_messages_name_the_output_in_words() {
    let f = fixture();
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    copy(&f.rec, dir, "t.csv");
    copy(&f.cal_bin, dir, "cal.bin");
    let args = ["replay", "--rec", "t.csv", "--calib", "cal.bin", "-o", "/dev/full"];
    assert_refused(&run_in(dir, &args), &args, &["/dev/full", "No space left on device"]);
    assert!(std::fs::metadata("/dev/full").unwrap().file_type().is_char_device());
    let long = format!("{}.toml", "n".repeat(245));
    let args = ["blob", "decode", "cal.bin", "-o", &long];
    assert_ok(&run_in(dir, &args), &args);
    assert!(dir.join(&long).is_file());
    let args = ["blob", "decode", "cal.bin", "-o", "-"];
    assert_refused(&run_in(dir, &args), &args, &["`-`", "give a file name"]);
    let args = ["replay", "--rec", "t.csv", "--calib", "cal.bin", "-o", "-"];
    assert_refused(&run_in(dir, &args), &args, &["`-`"]);
    assert!(!dir.join("-").exists());
    // Plots: a directory planted where the plots used to be drawn does not matter any more,
    // and a plotting error reads as words.
    copy(&f.cal_toml, dir, "cal.toml");
    let args = ["diagnose", "--calib", "cal.toml", "--real", "t.csv", "--report", "r.json", "--plots", "p"];
    let o = run_planted(dir, "mkdir -p p/.residual_x.png.tmp-$$.png", &args);
    assert_ok(&o, &args);
    use plotters::drawing::DrawingAreaErrorKind;
    let io = std::io::Error::from(std::io::ErrorKind::PermissionDenied);
    let e = DrawingAreaErrorKind::BackendError(plotters_backend::DrawingErrorKind::DrawingError(
        plotters_bitmap::BitMapBackendError::IOError(io),
    ));
    let words = bins_cal::diagnose::plot::drawing_error(e);
    assert_eq!(words, "permission denied");
}
