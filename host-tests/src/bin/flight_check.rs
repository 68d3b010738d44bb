//! Checks a UART capture of the flight image in QEMU: `flight-check UART.bin --min-frames N`.
//! The frames are decoded with the library's decoder (`bins_comp::frame`). QEMU attaches no
//! sensor, so a healthy image must boot, accept the flashed blob, sample at its fixed rate and
//! flag the missing sensors on every sample instead of stopping:
//!
//! - the capture starts with the boot frame (sequence 0, blob accepted, this frame format),
//!   and it is the only one (no reset);
//! - at least N frames, no byte outside a valid frame but a cut-off last frame, and
//!   consecutive sequence numbers (mod 2¹⁶);
//! - every sample frame carries `SENSOR_FAULT` and not `INVALID_CALIBRATION`, none saturated;
//! - at least one health frame; in each, the signal and temperature fault counts are at least
//!   the samples sent before it and grow from one health frame to the next; neither sensor is
//!   reported ready (the image keeps trying to initialise them); no overrun and no link error.

use bins_comp::Status;
use bins_comp::frame::{FORMAT_VERSION, Frame, Frames};

fn fail(msg: String) -> ! {
    eprintln!("flight-check: {msg}");
    std::process::exit(1)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (path, min_frames) = match args.as_slice() {
        [p, flag, n] if flag == "--min-frames" => match n.parse::<usize>() {
            Ok(n) => (p.clone(), n),
            Err(e) => fail(format!("--min-frames {n}: {e}")),
        },
        _ => {
            eprintln!("usage: flight-check UART.bin --min-frames N");
            std::process::exit(2)
        }
    };
    let bytes = std::fs::read(&path).unwrap_or_else(|e| fail(format!("{path}: {e}")));
    let mut frames = Frames::new(&bytes);
    let all: Vec<Frame> = frames.by_ref().collect();
    let (skipped, remainder) = (frames.skipped(), frames.remainder());
    if skipped != 0 {
        fail(format!("{path}: {skipped} bytes outside valid frames"));
    }
    if all.len() < min_frames {
        fail(format!("{path}: {} frames, expected at least {min_frames}", all.len()));
    }
    match all.first() {
        Some(Frame::Boot(b)) if b.seq == 0 && b.blob_accepted && b.format_version == FORMAT_VERSION => {
            println!(
                "boot frame: blob accepted (CRC-32 {:#010x}, {} vibration profiles), {} Hz, ADC {}, TMP117 {}",
                b.blob_crc32,
                b.vibration_profiles,
                b.tick_hz,
                if b.adc_ready { "initialised" } else { "not answering" },
                if b.temp_ready { "initialised" } else { "not answering" },
            );
        }
        other => fail(format!("{path}: the first frame is not a boot frame with the blob accepted: {other:?}")),
    }
    let (mut samples, mut health, mut boots) = (0u64, 0u64, 0u64);
    let (mut last_signal, mut last_temp) = (None, None);
    let mut prev_seq: Option<u16> = None;
    for f in &all {
        if let Some(p) = prev_seq
            && f.seq() != p.wrapping_add(1)
        {
            fail(format!("{path}: sequence {} follows {p}", f.seq()));
        }
        prev_seq = Some(f.seq());
        match f {
            Frame::Boot(_) => boots += 1,
            Frame::Sample(s) => {
                if !s.status.contains(Status::SENSOR_FAULT) || s.status.contains(Status::INVALID_CALIBRATION) {
                    fail(format!("{path}: sample frame {} has status {:#x}", s.seq, s.status.0));
                }
                if s.saturated.iter().any(|&x| x) {
                    fail(format!("{path}: sample frame {} is saturated", s.seq));
                }
                samples += 1;
            }
            Frame::Health(h) => {
                health += 1;
                let (sig, tmp) = (u64::from(h.signal_faults), u64::from(h.temp_faults));
                if sig < samples || tmp < samples {
                    fail(format!(
                        "{path}: health frame {}: {sig} signal and {tmp} temperature faults after {samples} samples",
                        h.seq
                    ));
                }
                if last_signal.is_some_and(|l| sig <= l) || last_temp.is_some_and(|l| tmp <= l) {
                    fail(format!("{path}: health frame {}: fault counts did not grow", h.seq));
                }
                // No sensor is attached: the periodic attempts must not report one as ready.
                if h.adc_ready || h.temp_ready {
                    fail(format!(
                        "{path}: health frame {}: ADC ready {}, TMP117 ready {} with no sensor attached",
                        h.seq, h.adc_ready, h.temp_ready
                    ));
                }
                if h.overruns != 0 || h.link_errors != 0 {
                    fail(format!(
                        "{path}: health frame {}: {} overruns, {} link errors",
                        h.seq, h.overruns, h.link_errors
                    ));
                }
                (last_signal, last_temp) = (Some(sig), Some(tmp));
            }
        }
    }
    if boots != 1 {
        fail(format!("{path}: {boots} boot frames (the image reset)"));
    }
    if health == 0 {
        fail(format!("{path}: no health frame"));
    }
    println!(
        "{path}: {} frames ({samples} samples, {health} health, 1 boot; {remainder} bytes of a cut-off frame), sequence \
         consecutive; every sample flagged SENSOR_FAULT; last health frame: {} signal faults, {} temperature faults, 0 \
         overruns, neither sensor ready",
        all.len(),
        last_signal.unwrap_or(0),
        last_temp.unwrap_or(0),
    );
}
