//! `bins-cal replay`: a recording through the firmware's per-sample step on the host, and the
//! conversions of a recording to and from the firmware's replay streams
//! ([`bins_comp::replay`]).
//!
//! The host path runs [`Tick::step`] in `f32` over the rows in order, exactly as the
//! firmware's sampling interrupt does, so with no overrun the two outputs are identical byte
//! for byte. Output CSV: `t_s` (from the recording), `ax_g`, `ay_g`, `az_g` (shortest decimal
//! that reads back to the same `f32`), `status` (decimal bits of [`bins_comp::Status`]).

use anyhow::{Context, bail};
use bins_cal::calfile::{CalibrationFile, describe};
use bins_cal::fsio::{self, AtomicFile};
use bins_cal::recording::{Reader, Row};
use bins_comp::replay::{self, Input, OUTPUT_BYTES, Tick, WINDOW};
use bins_comp::{Pipeline, Sample, Status, VibrationSource};
use std::io::Write;
use std::path::{Path, PathBuf};

/// Arguments of `bins-cal replay`.
#[derive(clap::Args)]
pub struct Args {
    /// The recording (format v1).
    #[arg(long)]
    rec: PathBuf,
    /// The calibration: a blob or a calibration file (TOML), told apart by the content.
    #[arg(long, required_unless_present_any = ["write_stream", "read_stream"])]
    calib: Option<PathBuf>,
    /// The output CSV (`t_s,ax_g,ay_g,az_g,status`).
    #[arg(short, long, required_unless_present = "write_stream")]
    output: Option<PathBuf>,
    /// Instead: write the recording as the firmware's input stream (16 bytes per row).
    #[arg(long, value_name = "IN.bin", conflicts_with_all = ["read_stream", "output"])]
    write_stream: Option<PathBuf>,
    /// Instead of computing: take the results from the firmware's output stream (16 bytes per
    /// row) and write them as the output CSV.
    #[arg(long, value_name = "OUT.bin")]
    read_stream: Option<PathBuf>,
    /// The VE subtracted: `online` (the moment window over the replayed samples, as in
    /// flight), `none`, or `profile:N` (the calibration's flight-phase profile N). The replay
    /// firmware takes the same choice as `REPLAY_VE` at build time.
    #[arg(long, value_name = "SOURCE", default_value = "online", value_parser = parse_source)]
    ve: VibrationSource,
    /// The sampling rate of the interrupt being reproduced [Hz]: the thermal dynamics (if the
    /// calibration has them) run at the period 1/RATE, as the replay firmware's SysTick does
    /// (`REPLAY_TICK_HZ` at build time, 1000 by default).
    #[arg(long, value_name = "RATE", default_value_t = 1000, value_parser = clap::value_parser!(u32).range(1..))]
    tick_hz: u32,
}

fn parse_source(name: &str) -> Result<VibrationSource, String> {
    VibrationSource::parse(name).ok_or_else(|| format!("`{name}` is not none, online or profile:N (N = 0 to 255)"))
}

/// Runs `bins-cal replay …`.
pub fn run(args: Args) -> anyhow::Result<()> {
    fsio::refuse_overwriting_inputs(
        [Some(&args.rec), args.calib.as_ref(), args.read_stream.as_ref()].into_iter().flatten(),
        args.output.iter().chain(&args.write_stream),
    )?;
    let mut reader = Reader::open(&args.rec)?;
    let mut row = Row::default();
    if let Some(path) = &args.write_stream {
        let mut out = AtomicFile::create(path)?;
        while reader.read_row(&mut row)? {
            let input = input_of(&row);
            out.writer().write_all(&input.encode()).with_context(|| path.display().to_string())?;
        }
        reader.require_rows()?;
        return out.commit();
    }
    let Some(output) = &args.output else { bail!("--output is required") };
    let mut csv = AtomicFile::create(output)?;
    // A write error (a full disk) names the output.
    let named = |e: std::io::Error| anyhow::anyhow!("{}: {e}", output.display());
    writeln!(csv.writer(), "t_s,ax_g,ay_g,az_g,status").map_err(named)?;
    let mut rows = 0u64;
    if let Some(stream) = &args.read_stream {
        let bytes = std::fs::read(stream).with_context(|| stream.display().to_string())?;
        if bytes.len() % OUTPUT_BYTES != 0 {
            bail!("{}: {} bytes is not a whole number of {OUTPUT_BYTES}-byte results", stream.display(), bytes.len());
        }
        let mut results = bytes.chunks_exact(OUTPUT_BYTES);
        while reader.read_row(&mut row)? {
            let Some(r) = results.next() else {
                bail!("{}: {} results, the recording has more rows", stream.display(), rows)
            };
            let r: &[u8; OUTPUT_BYTES] = r.try_into()?;
            let sample = replay::decode_output(r);
            check_result(&sample).map_err(|e| {
                anyhow::anyhow!("{}: result {} (byte {}): {e}", stream.display(), rows + 1, rows * OUTPUT_BYTES as u64)
            })?;
            write_row(csv.writer(), row.t_s, &sample).map_err(named)?;
            rows += 1;
        }
        if results.next().is_some() {
            bail!("{}: more results than the recording's {rows} rows", stream.display());
        }
    } else {
        let Some(calib) = &args.calib else { bail!("--calib is required") };
        let (pipeline, profiles) = load_pipeline(calib, args.tick_hz)?;
        if let VibrationSource::Profile(n) = args.ve
            && usize::from(n) >= profiles
        {
            bail!(
                "--ve profile:{n}: {} has {profiles} flight-phase profile(s){}",
                calib.display(),
                if profiles == 0 { String::new() } else { format!(", profile:0 to profile:{}", profiles - 1) }
            );
        }
        let mut tick = Tick::<f32, WINDOW>::new(pipeline);
        while reader.read_row(&mut row)? {
            write_row(csv.writer(), row.t_s, &tick.step(&input_of(&row), args.ve)).map_err(named)?;
        }
    }
    reader.require_rows()?;
    csv.commit()
}

/// Every status bit the firmware defines.
const DEFINED_STATUS: Status = Status(
    Status::TEMP_CLAMPED.0
        | Status::NONFINITE_INPUT.0
        | Status::INVALID_CALIBRATION.0
        | Status::SINGULAR_AT_TEMP.0
        | Status::VIBRATION_ESTIMATE_NOT_READY.0
        | Status::VIBRATION_OUT_OF_RANGE.0
        | Status::OVERRUN.0
        | Status::SENSOR_FAULT.0,
);

/// What the firmware can write as one result: finite accelerations (it writes zero, flagged,
/// for a result that is not) and only the status bits it defines. Anything else is not its
/// output stream (another file, or a corrupted one).
fn check_result(s: &Sample<f32>) -> Result<(), String> {
    let undefined = s.status.0 & !DEFINED_STATUS.0;
    if undefined != 0 {
        return Err(format!(
            "status 0x{:08x} has bits the firmware does not define (0x{undefined:08x}): not a replay output stream",
            s.status.0
        ));
    }
    if let Some(a) = s.accel_g.iter().find(|a| !a.is_finite()) {
        return Err(format!("acceleration {a} is not finite: not a replay output stream"));
    }
    Ok(())
}

/// The `f32` input of one row, as the firmware receives it.
fn input_of(row: &Row) -> Input<f32> {
    Input { u_v: row.u_v.map(|u| u as f32), temp_c: row.temp_c as f32, status: Status::OK }
}

fn write_row(w: &mut impl Write, t_s: f64, s: &Sample<f32>) -> std::io::Result<()> {
    let mut b = ryu::Buffer::new();
    write!(w, "{}", b.format(t_s))?;
    for a in s.accel_g {
        write!(w, ",{}", b.format(a))?;
    }
    writeln!(w, ",{}", s.status.0)
}

/// The `f32` calibration, vibration-error model and thermal dynamics (at the period
/// `1/tick_hz`, computed as the firmware computes it) of a blob or a calibration file (told
/// apart by the content, [`CalibrationFile::read_checked`]): the pipeline the firmware builds
/// from the same blob. Both containers pass the same checks and the firmware's parser.
pub fn load_pipeline(path: &Path, tick_hz: u32) -> anyhow::Result<(Pipeline<f32>, usize)> {
    let err = |e: String| anyhow::anyhow!("{}: {e}", path.display());
    let (file, bytes) = CalibrationFile::read_checked(path)?;
    let profiles = file.vibration.as_ref().map_or(0, |v| v.profile.len());
    let parsed = bins_comp::blob::parse(&bytes).map_err(|e| err(describe(&e)))?;
    let (cal, vib) = parsed.configs::<f32>().map_err(|e| err(describe(&e)))?;
    let pipeline = Pipeline::new(cal, vib);
    let pipeline = match parsed.dynamics_at_rate(1.0 / tick_hz as f32).map_err(|e| err(describe(&e)))? {
        Some(d) => pipeline.with_dynamics(d),
        None => pipeline,
    };
    Ok((pipeline, profiles))
}
