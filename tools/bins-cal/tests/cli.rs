//! `bins-cal blob …` run as a process: encode/decode/check of the sample calibration, Intel
//! HEX at the CALIB address, one-line errors and exit status 1 for bad input, and no output
//! file written (or clobbered) on failure.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn bins_cal(args: &[&str], cwd: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_bins-cal")).args(args).current_dir(cwd).output().expect("run bins-cal")
}

fn sample() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../calibrations/paper-two-range.toml")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// Asserts a failure: exit status 1, nothing on stdout, exactly one line on stderr that
/// contains every `needle`. Returns that line.
fn assert_fails(out: &Output, needles: &[&str]) -> String {
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "stderr: {err}");
    assert_eq!(text(&out.stdout), "");
    assert_eq!(err.lines().count(), 1, "one line: {err:?}");
    assert!(err.starts_with("bins-cal: error: "), "{err}");
    for n in needles {
        assert!(err.contains(n), "{err:?} should contain {n:?}");
    }
    err
}

fn encode_sample(dir: &Path) -> Vec<u8> {
    let out = bins_cal(&["blob", "encode", sample().to_str().unwrap(), "-o", "cal.bin"], dir);
    assert!(out.status.success(), "{}", text(&out.stderr));
    std::fs::read(dir.join("cal.bin")).unwrap()
}

/// Independent Intel HEX reader: checks every record's checksum and returns (address, byte)
/// pairs.
fn read_ihex(hex: &str) -> Vec<(u32, u8)> {
    let mut upper = 0u32;
    let mut out = Vec::new();
    let mut eof = false;
    for line in hex.lines() {
        assert!(!eof, "data after EOF record");
        let raw: Vec<u8> =
            (1..line.len()).step_by(2).map(|i| u8::from_str_radix(&line[i..i + 2], 16).unwrap()).collect();
        assert!(line.starts_with(':'));
        assert_eq!(raw.iter().fold(0u8, |a, b| a.wrapping_add(*b)), 0, "checksum of {line}");
        let (n, addr, kind, data) =
            (raw[0] as usize, u16::from_be_bytes([raw[1], raw[2]]), raw[3], &raw[4..raw.len() - 1]);
        assert_eq!(data.len(), n);
        match kind {
            0 => out.extend(data.iter().enumerate().map(|(i, b)| (upper + addr as u32 + i as u32, *b))),
            1 => eof = true,
            4 => upper = (u16::from_be_bytes([data[0], data[1]]) as u32) << 16,
            k => panic!("record type {k}"),
        }
    }
    assert!(eof, "no EOF record");
    out
}

#[test]
fn encode_check_decode_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let blob = encode_sample(dir.path());
    assert_eq!(&blob[..4], b"BCAL");
    let out = bins_cal(&["blob", "check", "cal.bin"], dir.path());
    assert!(out.status.success());
    let line = text(&out.stdout);
    assert_eq!(line.lines().count(), 1, "{line}");
    assert!(line.starts_with("cal.bin: valid: blob v1"), "{line}");
    assert!(line.contains("serial PAPER-T1T2") && line.contains("pwl 3 knots, output-correction/simplified"), "{line}");
    let out = bins_cal(&["blob", "decode", "cal.bin", "-o", "back.toml"], dir.path());
    assert!(out.status.success(), "{}", text(&out.stderr));
    let back = std::fs::read_to_string(dir.path().join("back.toml")).unwrap();
    assert_eq!(back, std::fs::read_to_string(sample()).unwrap(), "decode(encode(sample)) == sample");
    // Without -o the file goes to stdout.
    let out = bins_cal(&["blob", "decode", "cal.bin"], dir.path());
    assert_eq!(text(&out.stdout), back);
    // A calibration file can be checked directly.
    let out = bins_cal(&["blob", "check", sample().to_str().unwrap()], dir.path());
    assert!(out.status.success());
    assert!(text(&out.stdout).contains("valid: blob v1"));
    // No temporary files left behind.
    let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(names.len(), 2, "{names:?}");
}

#[test]
fn ihex_is_placed_at_the_calib_origin_of_memory_x() {
    let dir = tempfile::tempdir().unwrap();
    let s = sample();
    let out = bins_cal(&["blob", "encode", s.to_str().unwrap(), "-o", "cal.bin", "--ihex", "cal.hex"], dir.path());
    assert!(out.status.success(), "{}", text(&out.stderr));
    let blob = std::fs::read(dir.path().join("cal.bin")).unwrap();
    let hex = std::fs::read_to_string(dir.path().join("cal.hex")).unwrap();
    // The repository's memory.x: CALIB = the last 4 KiB of 4 MiB.
    assert!(text(&out.stdout).contains("0x003FF000"), "{}", text(&out.stdout));
    let bytes = read_ihex(&hex);
    assert_eq!(bytes.len(), blob.len());
    for (i, (addr, b)) in bytes.iter().enumerate() {
        assert_eq!((*addr, *b), (0x003F_F000 + i as u32, blob[i]));
    }
    // An explicit linker script, with an origin that crosses a 64 KiB boundary.
    let mx = dir.path().join("other.x");
    std::fs::write(&mx, "MEMORY {\n  FLASH : ORIGIN = 0x08000000, LENGTH = 1M\n  CALIB (r) : ORIGIN = 0x0800FF00, LENGTH = 4K /* cal */\n}\n").unwrap();
    let args = ["blob", "encode", s.to_str().unwrap(), "-o", "c2.bin", "--ihex", "c2.hex", "--memory-x", "other.x"];
    assert!(bins_cal(&args, dir.path()).status.success());
    let bytes = read_ihex(&std::fs::read_to_string(dir.path().join("c2.hex")).unwrap());
    assert_eq!(bytes.iter().map(|p| p.1).collect::<Vec<_>>(), blob);
    assert!(bytes.iter().enumerate().all(|(i, (a, _))| *a == 0x0800_FF00 + i as u32));
    // A linker script without CALIB given explicitly is an error.
    std::fs::write(&mx, "MEMORY { FLASH : ORIGIN = 0, LENGTH = 1M }\n").unwrap();
    assert_fails(&bins_cal(&args, dir.path()), &["other.x", "CALIB"]);
}

#[test]
fn check_rejects_corrupt_blobs_with_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let blob = encode_sample(dir.path());
    let write = |name: &str, b: &[u8]| std::fs::write(dir.path().join(name), b).unwrap();
    let mut flipped = blob.clone();
    flipped[200] ^= 0x10;
    write("flipped.bin", &flipped);
    assert_fails(&bins_cal(&["blob", "check", "flipped.bin"], dir.path()), &["flipped.bin", "CRC mismatch"]);
    write("short.bin", &blob[..blob.len() - 3]);
    assert_fails(&bins_cal(&["blob", "check", "short.bin"], dir.path()), &["short.bin", "truncated"]);
    write("erased.bin", &[0xff; 4096]);
    assert_fails(&bins_cal(&["blob", "check", "erased.bin"], dir.path()), &["bad magic", "0x0000"]);
    // A physically impossible value under a valid CRC: K_yx set to 0.4 V/g (> 0.5·|K_yy|).
    let mut bad = blob.clone();
    let constants = u32::from_le_bytes(bad[20..24].try_into().unwrap()) as usize; // first entry's offset
    let off = constants + 8 + 8 * 3;
    bad[off..off + 8].copy_from_slice(&0.4f64.to_le_bytes());
    let n = bad.len();
    let crc = crc32(&bad[..n - 4]);
    bad[n - 4..].copy_from_slice(&crc.to_le_bytes());
    write("bad.bin", &bad);
    let line = assert_fails(&bins_cal(&["blob", "check", "bad.bin"], dir.path()), &["k_V_per_g[1][0]"]);
    assert!(line.contains(&format!("at byte 0x{off:04x}")), "{line}");
    // decode refuses the same blob.
    assert_fails(&bins_cal(&["blob", "decode", "bad.bin"], dir.path()), &["k_V_per_g[1][0]"]);
    // Missing file.
    assert_fails(&bins_cal(&["blob", "check", "nope.bin"], dir.path()), &["nope.bin"]);
}

fn crc32(data: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in data {
        crc ^= b as u32;
        for _ in 0..8 {
            crc = if crc & 1 == 1 { (crc >> 1) ^ 0xedb8_8320 } else { crc >> 1 };
        }
    }
    !crc
}

#[test]
fn bad_calibration_files_are_rejected_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let good = std::fs::read_to_string(sample()).unwrap();
    let cases = [
        ("unknown.toml", good.replace("t0_C = 20.0", "t0_C = 20.0\ncolour = \"red\""), vec!["unknown.toml", "colour"]),
        (
            "range.toml",
            good.replace("temp_range_C = [-40.0, 70.0]", "temp_range_C = [-40.0, 700.0]"),
            vec!["temp_range_C[1]", "out of range"],
        ),
        ("knots.toml", good.replace("t_C = 70.0", "t_C = -50.0"), vec!["temperature_model.knot[2].t_C"]),
        ("type.toml", good.replace("t0_C = 20.0", "t0_C = \"20\""), vec!["line 6", "t0_C", "expected f64"]),
        ("singular.toml", singular_k(&good), vec!["k_V_per_g", "singular"]),
    ];
    std::fs::write(dir.path().join("cal.bin"), b"previous").unwrap();
    for (name, body, needles) in &cases {
        std::fs::write(dir.path().join(name), body).unwrap();
        let out = bins_cal(&["blob", "encode", name, "-o", "cal.bin", "--ihex", "cal.hex"], dir.path());
        let mut needles = needles.clone();
        needles.push(name);
        assert_fails(&out, &needles);
        assert_fails(&bins_cal(&["blob", "check", name], dir.path()), &needles);
        assert_eq!(std::fs::read(dir.path().join("cal.bin")).unwrap(), b"previous", "{name}: output untouched");
        assert!(!dir.path().join("cal.hex").exists());
    }
    let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(names.len(), cases.len() + 1, "no temporary files: {names:?}");
}

/// The sample with K = [[1, −½, −½], [−½, 1, −½], [−½, −½, 1]]: every cross-sensitivity at
/// its limit, and (1, 1, 1) in the null space.
fn singular_k(good: &str) -> String {
    let start = good.find("k_V_per_g = [").unwrap();
    let end = start + good[start..].find("\n]\n").unwrap() + 3;
    let k = "k_V_per_g = [[1.0, -0.5, -0.5], [-0.5, 1.0, -0.5], [-0.5, -0.5, 1.0]]\n";
    format!("{}{k}{}", &good[..start], &good[end..])
}

#[test]
fn usage_errors_exit_2() {
    let dir = tempfile::tempdir().unwrap();
    assert_eq!(bins_cal(&["blob", "encode", "x.toml"], dir.path()).status.code(), Some(2));
    assert_eq!(bins_cal(&["blob", "frobnicate"], dir.path()).status.code(), Some(2));
    assert!(bins_cal(&["--help"], dir.path()).status.success());
}
