//! Helpers shared by the CLI tests that run the real `bins-cal` binary, and the one way the
//! tests read and rewrite CSV files ([`csv_text`]).

pub mod csv_text;
pub mod fclog_writer;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_bins-cal"))
}

pub fn repo(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").join(rel)
}

pub fn run(args: &[&str]) -> Output {
    bin().args(args).output().expect("bins-cal runs")
}

pub fn ok(args: &[&str]) -> String {
    let o = run(args);
    assert!(o.status.success(), "{args:?} failed: {}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// The one-line error of a run that must fail.
pub fn err(args: &[&str]) -> String {
    let o = run(args);
    assert!(!o.status.success(), "{args:?} should fail");
    let e = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(e.trim_end().lines().count(), 1, "one line: {e}");
    assert!(e.starts_with("bins-cal: error: "), "{e}");
    e
}

/// The text of a recording without its column `name` (comment lines kept as they are).
pub fn without_column(csv: &str, name: &str) -> String {
    let mut c = csv_text::Csv::parse(csv);
    c.remove_column(name);
    c.to_text()
}

/// Writes `rows` as a recording (format v1, every column) at `path`.
#[allow(dead_code)] // not every test file that includes this module writes recordings
pub fn write_recording(path: &Path, rows: &[bins_cal::recording::Row]) {
    use bins_cal::recording::{Columns, Writer};
    let f = std::fs::File::create(path).unwrap();
    let mut w =
        Writer::new(std::io::BufWriter::new(f), path, Columns::all(), &["recording format v1 -- test"]).unwrap();
    for r in rows {
        w.write_row(r).unwrap();
    }
    w.finish().unwrap();
}
