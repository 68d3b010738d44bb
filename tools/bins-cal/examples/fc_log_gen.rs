//! A synthetic flight-controller log of a given size, for the streaming benchmark of
//! `bins-cal import` (`cargo xtask bench`, step 8): three accelerometers at 1 kHz in a new-style
//! ArduPilot DataFlash log (`.bin`: `IMU` with `TimeUS`, `I`, `T`) or a PX4 ULog (`.ulg`:
//! `sensor_accel`), written in a stream by the tests' independent writer
//! (`tests/common/fclog_writer.rs`): its opening (definitions, subscriptions) once, then its
//! data messages chunk after chunk with the clock running on.
//!
//! `cargo run --release -p bins-cal --example fc_log_gen -- OUT.bin 100` (size in MB, 10⁶ B)

#[path = "../tests/common/fclog_writer.rs"]
mod fclog_writer;

use fclog_writer::S;
use std::io::Write;

/// Samples per chunk and instance.
const CHUNK: usize = 10_000;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let (Some(out), Some(mb)) = (args.get(1), args.get(2).and_then(|m| m.parse::<f64>().ok())) else {
        eprintln!("usage: fc_log_gen OUT.bin|OUT.ulg SIZE_MB");
        std::process::exit(2);
    };
    let ulog = out.ends_with(".ulg");
    let target = (mb * 1e6) as usize;
    let f = std::fs::File::create(out).unwrap_or_else(|e| panic!("{out}: {e}"));
    let mut w = std::io::BufWriter::with_capacity(1 << 20, f);
    let mut written = 0usize;
    let mut chunk = 0u64;
    while written < target {
        // 1 kHz per instance; the chunk's clock starts where the previous one ended.
        let samples: Vec<S> = (0..CHUNK)
            .flat_map(|k| {
                let t_us = 10_000_000 + (chunk * CHUNK as u64 + k as u64) * 1000;
                let x = (t_us as f64 * 1e-6 * 0.3).sin() as f32;
                (0..3u8).map(move |i| S {
                    instance: i,
                    time_us: t_us,
                    accel: [0.02 * x + 0.01 * i as f32, -0.03 * x, -9.80665 + 0.005 * x],
                    temp: 25.0 + 20.0 * (t_us as f64 * 1e-6 / 3600.0).min(1.0) as f32 + i as f32,
                })
            })
            .collect();
        let bytes = if ulog { fclog_writer::ulog(&samples, true) } else { fclog_writer::dataflash(true, &samples) };
        // The opening once: after the first chunk, the data messages alone (the ULog's sync
        // message at its end kept, as a logger writes one now and then).
        let skip = if chunk == 0 {
            0
        } else if ulog {
            bytes.len() - samples.len() * 48 - 11
        } else {
            bytes.len() - samples.len() * 50
        };
        w.write_all(&bytes[skip..]).unwrap_or_else(|e| panic!("{out}: {e}"));
        written += bytes.len() - skip;
        chunk += 1;
    }
    w.flush().unwrap_or_else(|e| panic!("{out}: {e}"));
    println!("{out}: {written} bytes, {} samples per instance", chunk * CHUNK as u64);
}
