//! The Cortex-M4F firmware, run in QEMU (ARM MPS2 AN386) with semihosting.
//!
//! It owns the replay of the host's test vectors on the target: it builds the calibration
//! variants once at boot ([`bins_comp::vectors::calibrations`]) — the flashed variant from the
//! blob in the CALIB region ([`calib`]; uncalibrated, every sample flagged
//! `INVALID_CALIBRATION`, if the blob is missing or invalid) — reads
//! `target/fw-vectors/in.bin` (relative to QEMU's working directory) in chunks of whole
//! [`RECORD_BYTES`] records, runs every record through its variant, writes the results to
//! `target/fw-vectors/out.bin` ([`RESULT_BYTES`] each) and compares them bit for bit with the
//! host's `f32` results. It logs with defmt over semihosting and exits QEMU with success iff at
//! least one record was read and none mismatched. A panic or a HardFault exits with failure.
#![no_std]
#![no_main]
#![allow(unsafe_code, reason = "the Cortex-M runtime's entry and exception handlers, the CALIB region read by address")]

use core::sync::atomic::{AtomicBool, Ordering};

mod calib;
mod interrupts;

use bins_comp::Calibration;
use bins_comp::blob::BlobError;
use bins_comp::vectors::{self, RECORD_BYTES, RESULT_BYTES, Record};
use cortex_m_rt::{ExceptionFrame, entry, exception};
use semihosting::fs::File;
use semihosting::io::{Read, Write};

// Links the single-core critical-section implementation the logger needs.
use cortex_m as _;
// The defmt global logger: frames go to QEMU's stdout.
use defmt_semihosting as _;

/// Input file, relative to QEMU's working directory (the repository root).
const IN_PATH: &core::ffi::CStr = c"target/fw-vectors/in.bin";
/// Output file: one result per input record, in input order.
const OUT_PATH: &core::ffi::CStr = c"target/fw-vectors/out.bin";
/// Records per read (about 4 KiB of input).
const CHUNK_RECORDS: usize = 4096 / RECORD_BYTES;
/// Mismatches logged in full; the rest are only counted.
const SHOWN_MISMATCHES: u32 = 5;

/// Semihosting exit status of a passing run.
const EXIT_SUCCESS: i32 = 0;
/// Semihosting exit status of a failing run.
const EXIT_FAILURE: i32 = 1;

#[entry]
fn main() -> ! {
    let code = match run() {
        Ok(totals) => {
            defmt::info!("records: {}, mismatches: {}", totals.records, totals.mismatches);
            if totals.records > 0 && totals.mismatches == 0 {
                defmt::info!("PASS");
                EXIT_SUCCESS
            } else {
                defmt::error!("FAIL");
                EXIT_FAILURE
            }
        }
        Err(e) => {
            defmt::error!("FAIL: {}", e);
            EXIT_FAILURE
        }
    };
    semihosting::process::exit(code)
}

/// What a run counted.
struct Totals {
    records: u32,
    mismatches: u32,
}

/// Why a run stopped early.
#[derive(defmt::Format)]
enum RunError {
    OpenInput,
    CreateOutput,
    Read,
    Write,
    /// The input's length is not a whole number of records; the field is the stray byte count.
    TrailingBytes(usize),
}

fn run() -> Result<Totals, RunError> {
    let mut cals = vectors::calibrations();
    cals[vectors::FLASHED_VARIANT] = flashed_calibration();
    for (i, cal) in cals.iter().enumerate() {
        if !cal.is_valid() {
            defmt::info!("variant {} is the uncalibrated stand-in", i);
        }
    }

    let mut input = File::open(IN_PATH).map_err(|_| RunError::OpenInput)?;
    let mut output = File::create(OUT_PATH).map_err(|_| RunError::CreateOutput)?;

    let mut inbuf = [0u8; CHUNK_RECORDS * RECORD_BYTES];
    let mut outbuf = [0u8; CHUNK_RECORDS * RESULT_BYTES];
    let mut totals = Totals { records: 0, mismatches: 0 };

    loop {
        let filled = read_full(&mut input, &mut inbuf)?;
        let whole = filled - filled % RECORD_BYTES;
        let records = inbuf.get(..whole).unwrap_or(&[]).chunks_exact(RECORD_BYTES);
        let results = outbuf.chunks_exact_mut(RESULT_BYTES);
        let mut out_len = 0;
        for (raw, out) in records.zip(results) {
            let Ok(raw) = <&[u8; RECORD_BYTES]>::try_from(raw) else { continue };
            let rec = Record::decode(raw);
            let got = vectors::evaluate(&cals, &rec);
            out.copy_from_slice(&vectors::encode_result(&got));
            out_len += RESULT_BYTES;
            if !vectors::bit_identical(&got, &rec.expected) {
                if totals.mismatches < SHOWN_MISMATCHES {
                    defmt::error!(
                        "mismatch at record {}: variant {}, u_v {}, temp_c {}: got {} status {:#x}, expected {} status {:#x}",
                        totals.records,
                        rec.variant,
                        rec.u_v,
                        rec.temp_c,
                        got.accel_g,
                        got.status.0,
                        rec.expected.accel_g,
                        rec.expected.status.0
                    );
                }
                totals.mismatches += 1;
            }
            totals.records += 1;
        }
        output.write_all(outbuf.get(..out_len).unwrap_or(&[])).map_err(|_| RunError::Write)?;
        if filled < inbuf.len() {
            // End of file.
            return if filled == whole { Ok(totals) } else { Err(RunError::TrailingBytes(filled - whole)) };
        }
    }
}

/// The calibration in the CALIB region, read and checked once, at boot. On any error it is
/// logged and the uncalibrated stand-in is used: its output is flagged `INVALID_CALIBRATION`
/// on every sample.
fn flashed_calibration() -> Calibration<f32> {
    let region = calib::read_region();
    // The vectors are compensated sample by sample without the thermal dynamics' period:
    // any period serves; the calibration alone is used.
    match calib::calibration(&region, 1.0e-3) {
        Ok((pipeline, parsed)) => {
            defmt::info!(
                "CALIB: valid calibration blob, {} bytes, unit {=str}, by {=str}",
                parsed.blob.bytes().len(),
                parsed.meta.serial,
                parsed.meta.tool_version
            );
            *pipeline.calibration()
        }
        Err(BlobError::BadMagic) => {
            defmt::warn!("CALIB: no calibration blob (bad magic): running uncalibrated");
            Calibration::uncalibrated()
        }
        Err(e) => {
            defmt::error!("CALIB: invalid calibration blob: {}: running uncalibrated", defmt::Display2Format(&e));
            Calibration::uncalibrated()
        }
    }
}

/// Fills `buf` from `file`; returns fewer bytes than `buf.len()` only at end of file.
fn read_full(file: &mut File, buf: &mut [u8]) -> Result<usize, RunError> {
    let mut filled = 0;
    while let Some(rest) = buf.get_mut(filled..) {
        if rest.is_empty() {
            break;
        }
        match file.read(rest) {
            Ok(0) => break,
            Ok(n) => filled += n,
            Err(_) => return Err(RunError::Read),
        }
    }
    Ok(filled)
}

/// Set by the first panic, so a panic while logging the panic does not recurse.
static PANICKING: AtomicBool = AtomicBool::new(false);

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    if !PANICKING.swap(true, Ordering::Relaxed) {
        match info.location() {
            Some(l) => defmt::error!("panic at {}:{}", l.file(), l.line()),
            None => defmt::error!("panic"),
        }
    }
    semihosting::process::exit(EXIT_FAILURE)
}

#[exception]
unsafe fn HardFault(ef: &ExceptionFrame) -> ! {
    if !PANICKING.swap(true, Ordering::Relaxed) {
        defmt::error!("HardFault at pc {:#x}", ef.pc());
    }
    semihosting::process::exit(EXIT_FAILURE)
}
