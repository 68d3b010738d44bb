//! `bins-cal import`: flight-controller logs into recordings (docs/logs.md).
//!
//! Logs written byte by byte by an independent writer (`common/fclog_writer.rs`) in the three
//! layouts (DataFlash old and new style, ULog), read back value for value; bad input (cut
//! off, corrupted, unknown, without accelerometer or temperature, non-finite or absurd
//! samples) refused in one line naming the byte offset and the message, nothing written; and
//! the two public logs, when present (`data/real/` or the shared `../shared/data/real/`),
//! against the figures of their projects' own readers.

#[allow(dead_code)]
mod common;

use common::fclog_writer::{self as w, S};
use common::{bin, csv_text::Csv};
use std::path::{Path, PathBuf};

fn run_import(log: &Path, out: &Path, extra: &[&str]) -> std::process::Output {
    bin().arg("import").arg(log).arg("-o").arg(out).arg("--quiet").args(extra).output().unwrap()
}

/// A recording's row: t_s, [ux, uy, uz], temp_C.
type RowOf = (f64, [f64; 3], f64);

/// The rows of a recording and its comment lines.
fn rows(path: &Path) -> (Vec<RowOf>, Vec<String>) {
    let c = Csv::parse(&std::fs::read_to_string(path).unwrap());
    let col = |n: &str| c.header.iter().position(|h| h == n).unwrap();
    let (t, x, y, z, temp) = (col("t_s"), col("ux_V"), col("uy_V"), col("uz_V"), col("temp_C"));
    let num = |r: &Vec<String>, k: usize| r[k].parse::<f64>().unwrap();
    let v = c.rows.iter().map(|r| (num(r, t), [num(r, x), num(r, y), num(r, z)], num(r, temp))).collect();
    (v, c.comments)
}

/// Every sample of `instance` comes out as written: time in s, acceleration / 9.80665 (the
/// f32 value widened exactly, then divided), temperature.
fn assert_rows_equal(path: &Path, samples: &[S], instance: u8, time_scale_us: u64) {
    let (got, _) = rows(path);
    let want: Vec<&S> = samples.iter().filter(|s| s.instance == instance).collect();
    assert_eq!(got.len(), want.len(), "{}", path.display());
    for (g, s) in got.iter().zip(&want) {
        let t_us = s.time_us / time_scale_us * time_scale_us;
        assert_eq!(g.0, t_us as f64 / 1e6);
        for i in 0..3 {
            assert_eq!(g.1[i], s.accel[i] as f64 / 9.80665, "{} row at {}", path.display(), g.0);
        }
        assert_eq!(g.2, s.temp as f64);
    }
}

#[test]
fn dataflash_old_and_new_style_and_ulog_come_out_sample_for_sample() {
    let dir = tempfile::tempdir().unwrap();
    let samples = w::samples(&[0, 1, 2], 200, 50.0);
    for (name, bytes, scale) in [
        ("old.bin", w::dataflash(false, &samples), 1000),
        ("new.bin", w::dataflash(true, &samples), 1),
        ("px4.ulg", w::ulog(&samples, true), 1),
    ] {
        let log = dir.path().join(name);
        std::fs::write(&log, bytes).unwrap();
        let out = dir.path().join(format!("{name}.csv"));
        let o = run_import(&log, &out, &[]);
        assert!(o.status.success(), "{name}: {}", String::from_utf8_lossy(&o.stderr));
        for k in 0..3u8 {
            let f = bins_cal::fclog::import::output_for(&out, k);
            assert_rows_equal(&f, &samples, k, scale);
            let (_, comments) = rows(&f);
            assert!(comments.iter().any(|c| c.contains(&format!("instance {k}"))), "{comments:?}");
        }
        // One instance into the output itself.
        let one = dir.path().join(format!("{name}-one.csv"));
        let o = run_import(&log, &one, &["--instance", "1"]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert_rows_equal(&one, &samples, 1, scale);
    }
}

#[test]
fn a_reference_instance_fills_the_others_reference_columns() {
    let dir = tempfile::tempdir().unwrap();
    let samples = w::samples(&[0, 1, 2], 50, 50.0);
    let log = dir.path().join("old.bin");
    std::fs::write(&log, w::dataflash(false, &samples)).unwrap();
    let out = dir.path().join("r.csv");
    let o = run_import(&log, &out, &["--reference", "0"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let c = Csv::parse(&std::fs::read_to_string(dir.path().join("r-2.csv")).unwrap());
    let fx = c.header.iter().position(|h| h == "fx_g").unwrap();
    let refs: Vec<f64> = c.rows.iter().map(|r| r[fx].parse().unwrap()).collect();
    let want: Vec<f64> = samples.iter().filter(|s| s.instance == 0).map(|s| s.accel[0] as f64 / 9.80665).collect();
    assert_eq!(refs, want);
    // The reference's own file has no reference columns.
    let c0 = Csv::parse(&std::fs::read_to_string(dir.path().join("r-0.csv")).unwrap());
    assert!(!c0.header.iter().any(|h| h == "fx_g"));
}

/// The files of a directory, sorted.
fn listing(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> =
        std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    v.sort();
    v
}

/// A bad log: refused in one line holding every needle, nothing written, no temporary file.
fn refused(bytes: &[u8], needles: &[&str]) -> String {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("bad.log");
    std::fs::write(&log, bytes).unwrap();
    let o = run_import(&log, &dir.path().join("out.csv"), &[]);
    let e = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(!o.status.success(), "accepted: {needles:?}");
    assert_eq!(e.trim_end().lines().count(), 1, "one line: {e}");
    assert!(e.starts_with("bins-cal: error: "), "{e}");
    for n in needles {
        assert!(e.contains(n), "`{n}` not in: {e}");
    }
    assert_eq!(listing(dir.path()), vec!["bad.log".to_string()], "{e}");
    e
}

#[test]
fn bad_logs_are_refused_naming_the_message_and_offset_and_nothing_is_written() {
    let samples = w::samples(&[0, 1, 2], 20, 50.0);
    let old = w::dataflash(false, &samples);
    let head = 89 * 5 + 27; // four FMT, the PARM
    // Cut off inside the 7th IMU message.
    let at = head + 6 * 43;
    refused(&old[..at + 20], &[&format!("byte {at}"), "IMU", "cut off", "truncated"]);
    // A header byte overwritten.
    let mut c = old.clone();
    c[at] = 0x00;
    refused(&c, &[&format!("byte {at}"), "no message header", "corrupted", "after IMU3"]);
    // A type no FMT defined.
    let mut c = old.clone();
    c[at + 2] = 77;
    refused(&c, &[&format!("byte {at}"), "type 77 has no FMT"]);
    // Non-finite and absurd samples, a temperature no sensor reads.
    for (field, value, needle) in
        [(4 * 4 + 4, f32::NAN, "AccX = NaN"), (5 * 4 + 4, 1e7, "AccY = 10000000"), (9 * 4 + 4, 900.0, "Temp = 900")]
    {
        let mut c = old.clone();
        c[at + 3 + field - 4..at + 3 + field].copy_from_slice(&value.to_le_bytes());
        refused(&c, &[&format!("byte {at}"), "IMU", needle]);
    }
    // No temperature in the IMU format.
    let mut c = old.clone();
    let pos = c.windows(4).position(|w| w == b"Temp").unwrap();
    c[pos..pos + 4].copy_from_slice(b"Tmpr");
    refused(&c, &["byte 178", "FMT of IMU", "no temperature field"]);
    // No accelerometer at all: the FMTs and the PARM alone.
    refused(&old[..head], &["no `IMU` sample", "no accelerometer"]);
    // Not a log, an empty file.
    refused(b"t_s,ux_V\n1,2\n", &["not a flight-controller log", "74 5f 73"]);
    refused(b"", &["not a flight-controller log", "empty file"]);

    let ulog = w::ulog(&samples, true);
    // Cut off in the last sample (45 + 3 bytes each, then the sync message of 8 + 3).
    let last = ulog.len() - 11 - 48;
    refused(&ulog[..last + 30], &[&format!("byte {last}"), "`D` message", "cut off"]);
    let mut c = ulog.clone();
    c[last + 2] = b'z';
    refused(&c, &[&format!("byte {last}"), "0x7a is not a ULog message", "corrupted"]);
    let mut c = ulog.clone();
    c[last + 3] = 9; // message id 9: never subscribed
    refused(&c, &[&format!("byte {last}"), "message id 9", "no `A` message subscribed"]);
    let mut c = ulog.clone();
    c[last + 3 + 2 + 20..last + 3 + 2 + 24].copy_from_slice(&f32::INFINITY.to_le_bytes());
    refused(&c, &[&format!("byte {last}"), "sensor_accel 2", "x = inf"]);
    refused(&w::ulog(&samples, false), &["sensor_accel", "no temperature field"]);
    refused(&ulog[..10], &["byte 0", "file header cut off"]);
}

/// A public log of `data/real/`, or of the shared copy beside the repository; `None` (and a
/// note) when neither is there.
fn public_log(name: &str) -> Option<PathBuf> {
    let here = common::repo(&format!("data/real/{name}"));
    let shared = common::repo(&format!("../shared/data/real/{name}"));
    let found = [here, shared].into_iter().find(|p| p.is_file());
    if found.is_none() {
        eprintln!("{name}: not in data/real/ nor ../shared/data/real/ (see data/real/README.md): its test did not run");
    }
    found
}

/// The samples of every instance, read by the library.
fn read_all(path: &Path) -> (bins_cal::fclog::Summary, Vec<Vec<bins_cal::fclog::Sample>>) {
    let mut per: Vec<Vec<bins_cal::fclog::Sample>> = vec![Vec::new(); 256];
    let s = bins_cal::fclog::read(path, &mut |_| {}, &mut |_, s| {
        per[s.instance as usize].push(*s);
        Ok(())
    })
    .unwrap();
    (s, per)
}

/// log171.bin (dronekit-la-testdata, ArduCopter 3.3-dev, CC BY-SA 3.0) against pymavlink
/// 2.4.50 (`DFReader_binary(…, zero_time_base=False)`, every message through `recv_msg`):
/// 91 530 messages, 11 916 of each of IMU, IMU2, IMU3; first and last AccX, AccY, AccZ, Temp
/// and TimeMS of each; Temp's range.
#[test]
fn log171_matches_pymavlink() {
    let Some(log) = public_log("log171.bin") else { return };
    let (s, per) = read_all(&log);
    assert_eq!(s.messages, 91_530);
    #[allow(clippy::type_complexity)]
    let want: [(&str, u64, u64, [f64; 4], [f64; 4], (f64, f64)); 3] = [
        (
            "IMU",
            11_460,
            254_061,
            [-0.07167863845825195, -0.6270700097084045, -9.587533950805664, 25.603878021240234],
            [-0.42982012033462524, -0.6153112649917603, 9.388047218322754, 30.390583038330078],
            (25.470914840698242, 30.43490219116211),
        ),
        (
            "IMU2",
            11_460,
            254_061,
            [-0.042010631412267685, -0.6534910202026367, -9.3814115524292, 27.625],
            [-0.3901255130767822, -0.5866197943687439, 9.509326934814453, 32.25],
            (27.375, 32.375),
        ),
        (
            "IMU3",
            11_460,
            254_061,
            [0.006453816778957844, -0.40499401092529297, -9.173696517944336, 25.55955696105957],
            [-0.4065084159374237, -0.8639480471611023, 9.684431076049805, 41.82548522949219],
            (25.515235900878906, 41.95845031738281),
        ),
    ];
    for (k, (name, t_first, t_last, first, last, temp)) in want.iter().enumerate() {
        assert_eq!(s.instances[k].message, *name);
        let v = &per[k];
        assert_eq!(v.len(), 11_916, "{name}");
        let four = |x: &bins_cal::fclog::Sample| [x.accel_m_s2[0], x.accel_m_s2[1], x.accel_m_s2[2], x.temp_c];
        assert_eq!(four(&v[0]), *first, "{name}");
        assert_eq!(four(&v[v.len() - 1]), *last, "{name}");
        assert_eq!((v[0].time_us, v[v.len() - 1].time_us), (t_first * 1000, t_last * 1000));
        let lo = v.iter().map(|x| x.temp_c).fold(f64::INFINITY, f64::min);
        let hi = v.iter().map(|x| x.temp_c).fold(f64::NEG_INFINITY, f64::max);
        assert_eq!((lo, hi), *temp, "{name}");
    }
}

/// sample_log_small.ulg (PX4/pyulog test data, BSD-3) against pyulog 1.3.0 (`ULog(path)`,
/// `data_list` entries `sensor_accel` by `multi_id`): 6 samples per instance, device_id,
/// first and last x, y, z, temperature, timestamp_sample.
#[test]
fn sample_log_small_matches_pyulog() {
    let Some(log) = public_log("sample_log_small.ulg") else { return };
    let (s, per) = read_all(&log);
    #[allow(clippy::type_complexity)]
    let want: [(u32, u64, u64, [f64; 4], [f64; 4]); 3] = [
        (
            2_424_842,
            21_311_647,
            26_312_072,
            [0.6821298003196716, 0.2433379590511322, -9.696952819824219, 40.02537155151367],
            [0.6416460275650024, 0.33388230204582214, -9.797073364257812, 40.16913986206055],
        ),
        (
            3_670_050,
            21_310_770,
            26_310_770,
            [0.35673606395721436, 0.3086126148700714, -9.912714004516602, 28.246023178100586],
            [0.34902143478393555, 0.3354542553424835, -9.909867286682129, 28.367332458496094],
        ),
        (
            2_621_474,
            21_311_185,
            26_311_258,
            [0.6771600842475891, 0.272938996553421, -9.899026870727539, 29.62611198425293],
            [0.6075286865234375, 0.25498247146606445, -9.813633918762207, 29.62611198425293],
        ),
    ];
    for (k, (device, t_first, t_last, first, last)) in want.iter().enumerate() {
        let i = s.position(k as u8).unwrap();
        assert_eq!(s.instances[i].device_id, Some(*device));
        let v = &per[k];
        assert_eq!(v.len(), 6);
        let four = |x: &bins_cal::fclog::Sample| [x.accel_m_s2[0], x.accel_m_s2[1], x.accel_m_s2[2], x.temp_c];
        assert_eq!(four(&v[0]), *first);
        assert_eq!(four(&v[5]), *last);
        assert_eq!((v[0].time_us, v[5].time_us), (*t_first, *t_last));
    }
    // Instance 0's heater: 40.03 … 40.36 °C (pyulog's min and max).
    let t: Vec<f64> = per[0].iter().map(|x| x.temp_c).collect();
    assert_eq!(t.iter().cloned().fold(f64::INFINITY, f64::min), 40.02537155151367);
    assert_eq!(t.iter().cloned().fold(f64::NEG_INFINITY, f64::max), 40.3608283996582);
}

/// log171's three IMUs come out with their temperatures, and `diagnose` runs on IMU2 and IMU3
/// against IMU1 (`--reference 0`) over the static period on the ground (31–70 s of the log's
/// clock) with the nominal calibration of an imported log.
#[test]
fn log171_imus_import_and_diagnose_runs_on_them() {
    let Some(log) = public_log("log171.bin") else { return };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("st.csv");
    let o = run_import(&log, &out, &["--reference", "0", "--from-s", "31", "--to-s", "70"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let cal = common::repo("calibrations/imported-nominal.toml");
    for (k, temp) in [(1u8, (27.75, 28.88)), (2, (28.26, 32.39))] {
        let rec = bins_cal::fclog::import::output_for(&out, k);
        let (r, _) = rows(&rec);
        assert_eq!(r.len(), 1928);
        assert!(r.iter().all(|x| (31.0..=70.0).contains(&x.0)));
        let lo = r.iter().map(|x| x.2).fold(f64::INFINITY, f64::min);
        let hi = r.iter().map(|x| x.2).fold(f64::NEG_INFINITY, f64::max);
        assert!((lo - temp.0).abs() < 0.005 && (hi - temp.1).abs() < 0.005, "{lo} … {hi}");
        let report = dir.path().join(format!("d{k}.json"));
        let o = bin()
            .args(["diagnose", "--calib", cal.to_str().unwrap(), "--real"])
            .arg(&rec)
            .arg("--report")
            .arg(&report)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
        assert_eq!(v["rows"], 1928);
    }
}
