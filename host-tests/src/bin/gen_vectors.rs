//! Writes the firmware's input records (see `bins_comp::vectors` for the layout), each with
//! the host's `f32` result, so the firmware can check itself bit for bit.
//!
//! - `gen-vectors OUT.bin`: the test set — every calibration variant over a grid of
//!   accelerations and temperatures (in and out of the calibrated range), random inputs, and
//!   the special inputs of the status policies (NaN, ±∞, overflow, unknown variant).
//! - `gen-vectors --demo OUT.bin`: the demo set — the paper's unit in the six check positions
//!   at −10, +20 and +45 °C, its true constants the quadratic through Tables T1/T2.
//! - `--blob CAL.bin` (either set): the calibration blob the firmware finds in its CALIB
//!   region. The flashed variant ([`vectors::FLASHED_VARIANT`]) is that blob parsed exactly as
//!   the firmware parses it — or, if the blob is invalid, the uncalibrated stand-in, so every
//!   one of its records then expects `INVALID_CALIBRATION`. Without `--blob` the region is
//!   taken to be empty.

use bins_comp::vectors::{self, Record, VARIANTS};
use bins_comp::{Calibration, Sample, Status, ident, paper};
use std::io::Write;

/// Variants the demo runs, in table order: uncorrected, method 1, method 2 simplified, full,
/// linearized — all with the paper's two-range calibration.
pub const DEMO_VARIANTS: [u32; 5] = [0, 1, 2, 3, 4];

fn record(cals: &[Calibration<f32>; VARIANTS], variant: u32, u_v: [f32; 3], temp_c: f32) -> Record {
    let mut rec = Record { variant, u_v, temp_c, expected: Sample { accel_g: [0.0; 3], status: Status::OK } };
    rec.expected = vectors::evaluate(cals, &rec);
    rec
}

/// Signals of the demo's true unit (the quadratic through T1/T2) for specific force `f_g`.
fn truth_signals(f_g: &[f64; 3], temp_c: f64) -> [f32; 3] {
    let truth = paper::params(paper::quadratic_truth().expect("quadratic"), bins_comp::Method::Uncorrected);
    truth.constants_at(temp_c).signals_v(f_g).map(|x| x as f32)
}

fn test_set(cals: &[Calibration<f32>; VARIANTS]) -> Vec<Record> {
    let mut out = Vec::new();
    let mut accels: Vec<[f64; 3]> = Vec::new();
    for s in [-10.0, -1.0, 0.0, 0.3, 1.0, 9.5] {
        accels.extend([[s, 0.0, 0.0], [0.0, s, 0.0], [0.0, 0.0, s], [s * 0.6, -s * 0.48, s * 0.64]]);
    }
    accels.extend(ident::check_positions_g(25.0));
    let temps = [-60.0, -40.0, -25.5, -10.0, 0.0, 20.0, 33.3, 45.0, 70.0, 85.0];
    for variant in 0..VARIANTS as u32 {
        for f in &accels {
            for &t in &temps {
                out.push(record(cals, variant, truth_signals(f, t), t as f32));
            }
        }
    }
    // Random inputs (fixed LCG, so the file is the same on every run).
    let mut state: u64 = 0x2545_f491_4f6c_dd1d;
    let mut uniform = || {
        state = state.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    for _ in 0..4000 {
        let f = [0, 1, 2].map(|_| uniform() * 20.0 - 10.0);
        let t = uniform() * 130.0 - 50.0;
        let variant = (uniform() * VARIANTS as f64) as u32;
        out.push(record(cals, variant, truth_signals(&f, t), t as f32));
    }
    // Vibration-error subtraction: every vibration variant (exact and paper formulas, each
    // flight profile and one missing profile) over accelerations up to and beyond the VE
    // model's 10 g range, in and out of the calibrated temperature range.
    for variant in vectors::VIB_VARIANT_BASE..vectors::VIB_VARIANT_BASE + vectors::VIB_VARIANTS {
        for f in [
            [0.0, 0.0, 1.0],
            [9.5, -0.3, 0.2],
            [-7.0, 4.0, -2.0],
            [0.3, 0.2, -0.1],
            [-1.0, 9.9, 0.5],
            [11.0, -10.5, 0.0],
        ] {
            for t in [-40.0, 20.0, 45.0, 85.0] {
                out.push(record(cals, variant, truth_signals(&f, t), t as f32));
            }
        }
        out.push(record(cals, variant, [f32::NAN, 0.1, -0.1], 20.0));
    }
    // The status policies' special inputs, on every variant and one unknown variant.
    let specials: [([f32; 3], f32); 8] = [
        ([f32::NAN, 0.1, -0.1], 20.0),
        ([0.1, f32::INFINITY, -0.1], 20.0),
        ([0.1, 0.2, f32::NEG_INFINITY], -10.0),
        ([0.1, 0.2, 0.3], f32::NAN),
        ([0.1, 0.2, 0.3], f32::INFINITY),
        ([3e38, 3e38, -3e38], 20.0),
        ([1e-40, -1e-40, 0.0], 45.0),
        ([-0.0, 0.0, 5.5], 1e30),
    ];
    for variant in 0..=VARIANTS as u32 {
        for (u, t) in specials {
            out.push(record(cals, variant, u, t));
        }
    }
    out
}

fn demo_set(cals: &[Calibration<f32>; VARIANTS]) -> Vec<Record> {
    let mut out = Vec::new();
    for t in [paper::CHECK_TEMPS_C[0], paper::T0_C, paper::CHECK_TEMPS_C[1]] {
        for f in ident::check_positions_g(25.0) {
            for v in DEMO_VARIANTS {
                out.push(record(cals, v, truth_signals(&f, t), t as f32));
            }
        }
    }
    out
}

/// The flashed variant's calibration: the blob at `path` parsed as the firmware parses the
/// CALIB region, or the uncalibrated stand-in.
fn flashed(path: Option<&str>) -> Calibration<f32> {
    let Some(path) = path else {
        println!("gen-vectors: no blob: the flashed variant is uncalibrated");
        return Calibration::uncalibrated();
    };
    let bytes = std::fs::read(path).unwrap_or_else(|e| fail(std::path::Path::new(path), e));
    match bins_comp::blob::parse_region(&bytes).and_then(|p| p.calibration::<f32>()) {
        Ok(cal) => {
            println!("gen-vectors: {path}: valid: the flashed variant uses it");
            cal
        }
        Err(e) => {
            println!("gen-vectors: {path}: invalid ({e}): the flashed variant is uncalibrated");
            Calibration::uncalibrated()
        }
    }
}

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let blob = match args.iter().position(|a| a == "--blob") {
        Some(i) if i + 1 < args.len() => Some(args.drain(i..i + 2).nth(1).unwrap_or_default()),
        Some(_) => {
            eprintln!("usage: gen-vectors [--demo] [--blob CAL.bin] OUT.bin");
            std::process::exit(2);
        }
        None => None,
    };
    let (demo, path) = match args.as_slice() {
        [p] => (false, p.clone()),
        [flag, p] if flag == "--demo" => (true, p.clone()),
        _ => {
            eprintln!("usage: gen-vectors [--demo] [--blob CAL.bin] OUT.bin");
            std::process::exit(2);
        }
    };
    let mut cals = vectors::calibrations();
    cals[vectors::FLASHED_VARIANT] = flashed(blob.as_deref());
    let records = if demo { demo_set(&cals) } else { test_set(&cals) };
    let path = std::path::PathBuf::from(path);
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).unwrap_or_else(|e| fail(&path, e));
    }
    // Written to a temporary file and renamed, so a reader never sees half a file.
    let tmp = path.with_extension("bin.tmp");
    let mut file = std::io::BufWriter::new(std::fs::File::create(&tmp).unwrap_or_else(|e| fail(&tmp, e)));
    for rec in &records {
        file.write_all(&rec.encode()).unwrap_or_else(|e| fail(&tmp, e));
    }
    file.flush().unwrap_or_else(|e| fail(&tmp, e));
    drop(file);
    std::fs::rename(&tmp, &path).unwrap_or_else(|e| fail(&path, e));
    println!("gen-vectors: {} records -> {}", records.len(), path.display());
}

fn fail(path: &std::path::Path, e: std::io::Error) -> ! {
    eprintln!("gen-vectors: {}: {e}", path.display());
    std::process::exit(1);
}
