//! `bins-cal calibrate`: a calibration file (and blob, Intel HEX) from tilter recordings.
//!
//! 1. The dwells of every position and temperature ([`segments`](bins_cal::calib::segments)).
//! 2. Per temperature, the 12 constants: T(10) when the dwells are exactly TP1…TP6 at the
//!    ideal positions, otherwise the least squares fit over the dwell means and their
//!    reference specific forces (`ident::fit_constants`).
//! 3. The temperature model from the constants: piecewise-linear through the temperatures
//!    (T(12), `ident::pwl_from_constants`) or a polynomial (T(11)/least squares,
//!    `ident::poly_from_constants`). With one temperature only the T0 constants can be
//!    written (`--model none`, or `auto`), and the file says so.
//!
//! 4. With `--shaker`: the vibration-error coefficients from shake-table recordings
//!    ([`shaker`](bins_cal::calib::shaker)), written as the file's `[vibration]` table and the blob's
//!    vibration section.
//!
//! Every fit's residual and the dwells it used are printed as a table. The fits are in
//! [`bins_cal::calib`]; this module parses the arguments and prints.

use anyhow::{anyhow, bail};
use bins_cal::calfile::CalibrationFile;
use bins_cal::calib::segments::{self, Segment};
use bins_cal::calib::tilter::{ModelRequest, fit_temperature, parse_model};
use bins_cal::{fsio, ihex, memmap};
use bins_comp::blob::Meta;
use bins_comp::{Constants, Form, Method};
use std::path::PathBuf;

/// Arguments of `bins-cal calibrate`.
#[derive(clap::Args)]
pub struct Args {
    /// Tilter recordings (format v1 with `pos` and fx/fy/fz), one or several.
    #[arg(long, num_args = 1.., required = true)]
    tilter: Vec<PathBuf>,
    /// Reference temperature T0 [°C]: the dwells nearest to it give the T0 constants, and
    /// their measured mean temperature becomes the calibration's T0.
    #[arg(long, default_value_t = 20.0)]
    t0: f64,
    /// Temperature model: `pwl` (knots at the calibration temperatures), `poly:N` (N = 1..4),
    /// `none` (T0 constants only) or `auto` (`pwl`, or `none` with one temperature).
    #[arg(long, default_value = "auto")]
    model: String,
    /// For `pwl`: use only the temperatures nearest to these [°C] as knots (T0 is always one).
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true)]
    knots: Vec<f64>,
    /// Compensation method: 1 (coefficient correction) or 2 (output correction).
    #[arg(long, default_value_t = 1)]
    method: u8,
    /// Form of method 2: full, simplified or linearized.
    #[arg(long, default_value = "full")]
    form: String,
    /// The unit's serial number.
    #[arg(long)]
    serial: Option<String>,
    /// Output calibration file (TOML).
    #[arg(short, long)]
    output: PathBuf,
    /// Also write the calibration blob here.
    #[arg(long)]
    blob: Option<PathBuf>,
    /// Also write the blob as Intel HEX at the CALIB region's address.
    #[arg(long)]
    ihex: Option<PathBuf>,
    /// memory.x giving the CALIB origin (default: found upwards from the working directory).
    #[arg(long)]
    memory_x: Option<PathBuf>,
    /// Only dwells whose label starts with this (`""`: every labelled dwell).
    #[arg(long, default_value = "TP")]
    pos_prefix: String,
    /// Shake-table recordings (format v1 with `pos`, fx/fy/fz and the vibration columns): the
    /// vibration-error coefficients of each accelerometer shaken on a plan (physics §8).
    #[arg(long, num_args = 1..)]
    shaker: Vec<PathBuf>,
    /// VE formulas the firmware uses for the flight-phase profiles: exact or paper.
    #[arg(long, default_value = "exact", requires = "shaker")]
    ve_variant: String,
    #[command(flatten)]
    seg: segments::Options,
}

/// The method requested on the command line.
pub fn parse_method(method: u8, form: &str) -> anyhow::Result<Method> {
    let form = match form {
        "full" => Form::Full,
        "simplified" => Form::Simplified,
        "linearized" => Form::Linearized,
        _ => bail!("--form `{form}`: expected full, simplified or linearized"),
    };
    match method {
        1 => Ok(Method::CoefficientCorrection),
        2 => Ok(Method::OutputCorrection(form)),
        _ => bail!("--method {method}: expected 1 or 2"),
    }
}

/// Prints the dwells (used and rejected).
pub fn print_segments(all: &[Segment]) {
    println!("dwells:");
    println!(
        "  {:<28} {:<5} {:>9} {:>9} {:>5} {:>9} {:>8} {:>10}  status",
        "file", "pos", "from_s", "to_s", "rows", "temp_C", "C/min", "std_mV"
    );
    for s in all {
        let name = s.file.file_name().map_or_else(String::new, |n| n.to_string_lossy().into_owned());
        println!(
            "  {:<28} {:<5} {:>9.1} {:>9.1} {:>5} {:>9.2} {:>+8.3} {:>10.4}  {}",
            name,
            s.pos,
            s.t_s.0,
            s.t_s.1,
            s.rows.len(),
            s.temp_c,
            s.rate_c_per_min,
            s.std_u_v.iter().fold(0.0f64, |a, b| a.max(*b)) * 1e3,
            s.rejected.as_deref().unwrap_or("used")
        );
    }
}

fn rms(v: &[[f64; 3]]) -> f64 {
    let n = (v.len() * 3) as f64;
    (v.iter().flatten().map(|x| x * x).sum::<f64>() / n).sqrt()
}

/// Runs `bins-cal calibrate`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let model_arg = parse_model(&args.model)?;
    let method = parse_method(args.method, &args.form)?;
    let ve_variant = match args.ve_variant.as_str() {
        "exact" => bins_comp::Variant::Exact,
        "paper" => bins_comp::Variant::Paper,
        v => bail!("--ve-variant `{v}`: expected exact or paper"),
    };
    let (all, files) = segments::find_all(&args.tilter, &args.seg)?;
    let all: Vec<Segment> = all.into_iter().filter(|s| s.pos.starts_with(&args.pos_prefix)).collect();
    print_segments(&all);
    let groups = segments::by_temperature(&all, args.seg.temp_tol_c);
    if groups.is_empty() {
        bail!("{files}: no stationary dwell with a settled temperature (see the table above)");
    }
    let mut fits = Vec::new();
    for (t, segs) in groups {
        fits.push(fit_temperature(t, segs, &files)?);
    }
    println!("\nconstants per temperature (residual = U − (K·f + U0), in mg of the axis):");
    println!("  {:>9} {:>4} {:<6} {:>10} {:>10}  dwells", "temp_C", "n", "fit", "rms_mg", "max_mg");
    for f in &fits {
        let max = f.residual_g.iter().flatten().fold(0.0f64, |a, b| a.max(b.abs()));
        let names: Vec<&str> = f.segments.iter().map(|s| s.pos.as_str()).collect();
        println!(
            "  {:>9.2} {:>4} {:<6} {:>10.4} {:>10.4}  {}",
            f.temp_c,
            f.segments.len(),
            f.how,
            rms(&f.residual_g) * 1e3,
            max * 1e3,
            names.join(" ")
        );
    }
    let points: Vec<(f64, Constants<f64>)> = fits.iter().map(|f| (f.temp_c, f.constants)).collect();
    let kept: Vec<f64> = all.iter().filter(|s| s.rejected.is_none()).map(|s| s.temp_c).collect();
    let req = ModelRequest {
        t0_c: args.t0,
        model: model_arg,
        knots: args.knots.clone(),
        temp_tol_c: args.seg.temp_tol_c,
        method,
    };
    let (params, mut notes) = bins_cal::calib::tilter::calibration_params(&points, &kept, &req, &files)?;
    let method = params.method;
    // Model residual: the constants the model gives at each temperature vs the measured ones.
    println!("\ntemperature model residual (model − measured at each calibration temperature):");
    println!("  {:>9} {:>12} {:>14}", "temp_C", "max|dU0| mg", "max|dK/K| ppm");
    for f in &fits {
        let (du, dk) = bins_cal::calib::tilter::model_residual(&params, f.temp_c, &f.constants);
        println!("  {:>9.2} {:>12.4} {:>14.2}", f.temp_c, du * 1e3, dk * 1e6);
    }
    let vibration = if args.shaker.is_empty() {
        None
    } else {
        let r = super::shaker::calibrate(&args.shaker, &args.seg, ve_variant, |t| params.constants_at(t))?;
        notes.extend(r.notes);
        Some(r.params)
    };
    let meta = Meta { serial: args.serial.as_deref().unwrap_or(""), date: None, tool_version: bins_cal::TOOL_VERSION };
    let file = CalibrationFile::from_parts(&params, vibration.as_ref(), &meta);
    // Everything is computed and checked before anything is written.
    let blob = file.to_blob().map_err(|e| anyhow!("{files}: the calibration is not valid: {e}"))?;
    let hex = match &args.ihex {
        Some(_) => {
            let (origin, _) = memmap::resolve_calib_origin(args.memory_x.as_deref())?;
            Some(ihex::encode(origin, &blob).map_err(|e| anyhow!(e))?)
        }
        None => None,
    };
    let mut header = String::from("# bins-cal calibrate from: ");
    header.push_str(&files);
    header.push('\n');
    if !args.shaker.is_empty() {
        header.push_str("# shake table: ");
        header.push_str(&args.shaker.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", "));
        header.push('\n');
    }
    for n in &notes {
        header.push_str("# note: ");
        header.push_str(n);
        header.push('\n');
    }
    let text = header + &file.to_toml();
    fsio::write_atomic(&args.output, text.as_bytes())?;
    println!();
    for n in &notes {
        println!("note: {n}");
    }
    println!(
        "wrote {} (model {}, method {})",
        args.output.display(),
        args.model,
        bins_cal::calfile::method_name(method)
    );
    if let Some(p) = &args.blob {
        fsio::write_atomic(p, &blob)?;
        println!("wrote {} ({} bytes)", p.display(), blob.len());
    }
    if let (Some(p), Some(h)) = (&args.ihex, hex) {
        fsio::write_atomic(p, h.as_bytes())?;
        println!("wrote {}", p.display());
    }
    Ok(())
}
