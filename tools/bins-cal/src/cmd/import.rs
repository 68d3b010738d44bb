//! `bins-cal import LOG -o REC.csv [--instance N]`: a flight-controller log (PX4 ULog `.ulg`,
//! ArduPilot DataFlash `.bin`, told apart by the content) into recordings, format v1: each
//! accelerometer instance into `REC-N.csv`, or instance N alone into `REC.csv`
//! ([`bins_cal::fclog::import`], `docs/logs.md`). Streaming, with a progress bar; nothing is
//! written unless the whole log reads without an error.

use bins_cal::fclog::import::{Options, import};
use std::path::PathBuf;

/// Arguments of `bins-cal import`.
#[derive(clap::Args)]
pub struct Args {
    /// The log: PX4 ULog (.ulg) or ArduPilot DataFlash (.bin).
    log: PathBuf,
    /// The recording to write; without --instance, one file per instance: REC-0.csv, REC-1.csv, …
    #[arg(short, long, value_name = "REC.csv")]
    output: PathBuf,
    /// Only this accelerometer instance (the log's own number: PX4 multi_id; ArduPilot I, or
    /// 0, 1, 2 for IMU, IMU2, IMU3), into REC.csv itself.
    #[arg(long, value_name = "N")]
    instance: Option<u8>,
    /// The acceleration of instance N as the reference (fx_g, fy_g, fz_g) of the other
    /// instances' rows: one accelerometer of the log as the rig of the others, for
    /// `calibrate` and `diagnose` (the instances must share their axes, as ArduPilot's IMU
    /// messages do).
    #[arg(long, value_name = "N")]
    reference: Option<u8>,
    /// Only the samples from this time of the log's clock on [s since boot].
    #[arg(long, value_name = "S", value_parser = bins_cal::numarg::finite)]
    from_s: Option<f64>,
    /// Only the samples up to this time of the log's clock [s since boot].
    #[arg(long, value_name = "S", value_parser = bins_cal::numarg::finite)]
    to_s: Option<f64>,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
}

/// Runs `bins-cal import`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let outputs: Vec<PathBuf> = match args.instance {
        Some(_) => vec![args.output.clone()],
        // Every name an instance could be given (the log's instances are known only once read).
        None => (0..=u8::MAX).map(|k| bins_cal::fclog::import::output_for(&args.output, k)).collect(),
    };
    bins_cal::fsio::refuse_overwriting_inputs([&args.log], &outputs)?;
    let t0 = std::time::Instant::now();
    let (summary, files) = import(
        &args.log,
        &args.output,
        &Options {
            instance: args.instance,
            reference: args.reference,
            span_s: (args.from_s, args.to_s),
            progress: !args.quiet,
        },
    )?;
    println!(
        "{}: {}, {} messages, {} bytes, read in {:.2} s",
        args.log.display(),
        summary.format.name(),
        summary.messages,
        summary.bytes,
        t0.elapsed().as_secs_f64()
    );
    for f in &files {
        let i = &f.instance;
        let rate = if f.rows > 1 { (f.rows - 1) as f64 / (f.t_s.1 - f.t_s.0) } else { f64::NAN };
        println!(
            "{}: {} instance {}{}: {} rows, t {:.3} … {:.3} s ({rate:.1} Hz), temperature {:.2} … {:.2} °C",
            f.path.display(),
            i.message,
            i.index,
            i.device_id.map_or(String::new(), |d| format!(" (device_id {d})")),
            f.rows,
            f.t_s.0,
            f.t_s.1,
            f.temp_c.0,
            f.temp_c.1
        );
    }
    Ok(())
}
