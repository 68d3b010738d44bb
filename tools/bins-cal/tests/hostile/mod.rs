//! What the hostile-input and hostile-output tests share: the binary run in a directory, and a
//! small valid campaign (a tilter recording, its calibration file and blob) made once per test
//! program.

use crate::common;
use std::path::{Path, PathBuf};
use std::process::Output;

/// A path as the `&str` an argument list takes.
pub fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Standard output or error as text.
pub fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// Runs `bins-cal args` with `dir` as the working directory.
pub fn run_in(dir: &Path, args: &[&str]) -> Output {
    common::bin().args(args).current_dir(dir).output().expect("bins-cal runs")
}

/// Makes `dir` anew with `t.csv` (the 3-temperature tilter scenario), `cal.toml` (its poly:2
/// calibration) and `cal.bin` (the blob); returns the three paths.
pub fn campaign(dir: &Path) -> (PathBuf, PathBuf, PathBuf) {
    let _ = std::fs::remove_dir_all(dir);
    std::fs::create_dir_all(dir).unwrap();
    let (rec, cal_toml, cal_bin) = (dir.join("t.csv"), dir.join("cal.toml"), dir.join("cal.bin"));
    let scen = common::repo("scenarios/test-tilter-3t.toml");
    common::ok(&["simulate", s(&scen), "-o", s(&rec), "--quiet"]);
    common::ok(&["calibrate", "--tilter", s(&rec), "--model", "poly:2", "-o", s(&cal_toml)]);
    common::ok(&["blob", "encode", s(&cal_toml), "-o", s(&cal_bin)]);
    (rec, cal_toml, cal_bin)
}
