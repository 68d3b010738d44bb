//! `bins-cal blob`: encode a calibration file into the blob the firmware reads from its CALIB
//! region, decode a blob back into a calibration file, check either.

use anyhow::{Context, anyhow};
use bins_cal::calfile::{CalibrationFile, describe, is_blob, method_name};
use bins_cal::{fsio, memmap};
use bins_comp::TempModel;
use bins_comp::blob::{self, ParsedCalibration};
use std::path::{Path, PathBuf};

/// Arguments of `bins-cal blob`.
#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    command: BlobCommand,
}

#[derive(clap::Subcommand)]
enum BlobCommand {
    /// Calibration file (TOML) → blob, optionally also as Intel HEX at the CALIB address.
    Encode {
        /// The calibration file.
        input: PathBuf,
        /// The blob to write.
        #[arg(short, long)]
        output: PathBuf,
        /// Also write the blob as Intel HEX placed at the CALIB region.
        #[arg(long, value_name = "FILE")]
        ihex: Option<PathBuf>,
        /// The linker script whose CALIB ORIGIN gives the HEX address (default: the nearest
        /// memory.x, else 0x003FF000).
        #[arg(long, value_name = "FILE")]
        memory_x: Option<PathBuf>,
    },
    /// Blob → calibration file (TOML).
    Decode {
        /// The blob.
        input: PathBuf,
        /// The calibration file to write (default: standard output).
        #[arg(short, long)]
        output: Option<PathBuf>,
    },
    /// Checks a blob or a calibration file (told apart by the content: a blob starts with the
    /// magic `BCAL`): one summary line and exit 0 if valid, one error line and exit 1 if not.
    Check {
        /// The blob or calibration file.
        file: PathBuf,
    },
}

/// Runs `bins-cal blob …`.
pub fn run(args: Args) -> anyhow::Result<()> {
    match args.command {
        BlobCommand::Encode { input, output, ihex, memory_x } => {
            encode(&input, &output, ihex.as_deref(), memory_x.as_deref())
        }
        BlobCommand::Decode { input, output } => decode(&input, output.as_deref()),
        BlobCommand::Check { file } => check(&file),
    }
}

fn encode(input: &Path, output: &Path, hex: Option<&Path>, memory_x: Option<&Path>) -> anyhow::Result<()> {
    fsio::refuse_overwriting_inputs([input].into_iter().chain(memory_x), [output].into_iter().chain(hex))?;
    let file = CalibrationFile::read(input)?;
    let bytes = file.to_blob().map_err(|e| anyhow!("{}: {e}", input.display()))?;
    let summary = summary(&blob::parse(&bytes).context("re-parse")?);
    match hex {
        Some(path) => {
            let (text, region, from) = memmap::calib_hex(memory_x, &bytes)?;
            fsio::write_all_or_nothing(&[(output, &bytes), (path, text.as_bytes())])?;
            println!("{}: {summary}", output.display());
            println!("{}: Intel HEX at 0x{:08X} ({from})", path.display(), region.origin);
        }
        None => {
            fsio::write_atomic(output, &bytes)?;
            println!("{}: {summary}", output.display());
        }
    }
    Ok(())
}

/// The first bytes of a file (enough for the magic).
fn read_head(path: &Path) -> anyhow::Result<Vec<u8>> {
    use std::io::Read;
    let mut head = Vec::new();
    std::fs::File::open(path)
        .and_then(|f| f.take(blob::MAGIC.len() as u64).read_to_end(&mut head))
        .map_err(|e| anyhow!("{}: {e}", path.display()))?;
    Ok(head)
}

fn read_blob(path: &Path) -> anyhow::Result<Vec<u8>> {
    // One byte more than a blob may have: enough to say it is too long.
    let bytes = fsio::read_capped(path, blob::MAX_BLOB_BYTES as u64 + 1)
        .or_else(|_| fsio::read_capped(path, fsio::MAX_TEXT_INPUT_BYTES))?;
    if !is_blob(&bytes) && CalibrationFile::from_toml(&String::from_utf8_lossy(&bytes)).is_ok() {
        return Err(anyhow!(
            "{}: a calibration file (TOML), not a blob; `bins-cal blob encode` makes its blob",
            path.display()
        ));
    }
    if bytes.len() > blob::MAX_BLOB_BYTES {
        return Err(anyhow!(
            "{}: {} bytes, larger than the {}-byte CALIB region",
            path.display(),
            bytes.len(),
            blob::MAX_BLOB_BYTES
        ));
    }
    Ok(bytes)
}

fn decode(input: &Path, output: Option<&Path>) -> anyhow::Result<()> {
    fsio::refuse_overwriting_inputs([input], output)?;
    let bytes = read_blob(input)?;
    let file = CalibrationFile::from_blob(&bytes).map_err(|e| anyhow!("{}: {e}", input.display()))?;
    let text = file.to_toml();
    match output {
        Some(path) => {
            fsio::write_atomic(path, text.as_bytes())?;
            println!("{}: calibration file of {}", path.display(), input.display());
        }
        None => print!("{text}"),
    }
    Ok(())
}

fn check(path: &Path) -> anyhow::Result<()> {
    // A blob or a calibration file by the content: UTF-8 text not starting with the blob's
    // magic is a calibration file, anything else is checked as a blob.
    let head = read_head(path)?;
    let text = !is_blob(&head) && fsio::read_text(path).is_ok();
    let bytes = if text {
        let file = CalibrationFile::read(path)?;
        file.to_blob().map_err(|e| anyhow!("{}: {e}", path.display()))?
    } else {
        let bytes = read_blob(path)?;
        // Byte offsets belong in the message for a blob.
        blob::parse(&bytes).map_err(|e| anyhow!("{}: {e}", path.display()))?;
        bytes
    };
    let parsed = blob::parse(&bytes).map_err(|e| anyhow!("{}: {}", path.display(), describe(&e)))?;
    println!("{}: valid: {}", path.display(), summary(&parsed));
    Ok(())
}

/// One line describing a valid blob.
fn summary(p: &ParsedCalibration<'_>) -> String {
    let b = p.blob.bytes();
    let crc =
        b.len().checked_sub(4).and_then(|i| b.get(i..)).map_or(0, |c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]));
    let model = match p.params.model {
        TempModel::Poly { order, .. } => format!("poly order {order}"),
        TempModel::Pwl { n_knots, .. } => format!("pwl {n_knots} knots"),
    };
    let mut s = format!(
        "blob v{} {} bytes CRC 0x{crc:08x}, {model}, {}, T0 {} °C, range [{}, {}] °C",
        blob::FORMAT_VERSION,
        b.len(),
        method_name(p.params.method),
        p.params.t0_c,
        p.params.temp_range_c.0,
        p.params.temp_range_c.1
    );
    if let Some(v) = &p.vibration {
        let variant = match v.variant {
            bins_comp::Variant::Paper => "paper",
            bins_comp::Variant::Exact => "exact",
        };
        s += &format!(", vibration model ({variant}, {} profile(s))", v.n_profiles);
    }
    if let Some(d) = &p.dynamics {
        s += &format!(
            ", thermal dynamics (lag {} s, hysteresis {} °C, self-heating {} °C τ {} s, bias play {} °C)",
            d.lag_tau_s, d.hysteresis_width_c, d.self_heating_c, d.self_heating_tau_s, d.bias_play_width_c
        );
    }
    if !p.meta.serial.is_empty() {
        s += &format!(", serial {}", p.meta.serial);
    }
    if let Some(d) = p.meta.date {
        s += &format!(", calibrated {:04}-{:02}-{:02}", d.year, d.month, d.day);
    }
    if !p.meta.tool_version.is_empty() {
        s += &format!(", by {}", p.meta.tool_version);
    }
    s
}
