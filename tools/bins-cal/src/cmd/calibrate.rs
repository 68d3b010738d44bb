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
//! 5. With `--dynamics identify`: the thermal dynamics (die lag, play, bias play) fitted
//!    jointly with the polynomial model on every dwell, ramps included
//!    ([`dynamics`](bins_cal::calib::dynamics)), written as `[thermal_dynamics]` with the joint
//!    model; with `--dynamics MODEL.toml` that file's `[thermal_dynamics]` is written as given.
//!
//! Without a tilter (`--free`, or when no recording has a reference): the static intervals
//! are found in the signals, the 9 frame-independent constants fitted per temperature to
//! `|f| = 1 g` (`calib::free`), then the temperature model as above. With `--tilt`, the
//! labelled path fits each dwell's tilt from its label jointly with the constants and says
//! how far each dwell was from its label.
//!
//! Every fit's residual and the dwells it used are printed as a table. The fits are in
//! [`bins_cal::calib`]; this module parses the arguments and prints.

use anyhow::{anyhow, bail};
use bins_cal::calfile::{CalibrationFile, DynamicsSpec};
use bins_cal::calib::dynamics::{self, Request, Series};
use bins_cal::calib::free::{self, FrameFree, FreeParams, StaticOptions};
use bins_cal::calib::segments::{self, Reference, Segment};
use bins_cal::calib::tilter::{ModelArg, ModelRequest, TempFit, fit_temperature, parse_model};
use bins_cal::{fsio, memmap};
use bins_comp::blob::Meta;
use bins_comp::{CalibrationParams, Constants, Form, Method};
use std::path::PathBuf;

/// Arguments of `bins-cal calibrate`.
#[derive(clap::Args)]
pub struct Args {
    /// Tilter recordings (format v1 with `pos` and fx/fy/fz), one or several; with `--free`
    /// (or without any reference) recordings of holds placed by hand.
    #[arg(long, num_args = 1.., required = true)]
    tilter: Vec<PathBuf>,
    /// Reference temperature T0 [°C]: the dwells nearest to it give the T0 constants, and
    /// their measured mean temperature becomes the calibration's T0.
    #[arg(long, default_value_t = 20.0, value_parser = bins_cal::numarg::temp_c)]
    t0: f64,
    /// Temperature model: `pwl` (knots at the calibration temperatures), `poly:N` (N = 1..4),
    /// `none` (T0 constants only) or `auto` (`pwl`, or `none` with one temperature).
    #[arg(long, default_value = "auto")]
    model: String,
    /// For `pwl`: use only the temperatures nearest to these [°C] as knots (T0 is always one).
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true, value_parser = bins_cal::numarg::temp_c)]
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
    /// Calibrate without a tilter: static intervals found in the signals, the constants fitted
    /// to |f| = 1 g (automatic when no recording has a reference).
    #[arg(long)]
    free: bool,
    /// Free fit: `full` (biases, scale factors, non-orthogonality) or `bias-scale` (axes taken
    /// as orthogonal: for holds near the axes only).
    #[arg(long, value_enum, default_value = "full")]
    free_params: FreeParams,
    /// Free fit: the signs of K_xx, K_yy, K_zz (`+++`, `---`, …), which |f| = 1 g cannot tell.
    #[arg(long, default_value = "+++")]
    free_signs: String,
    #[command(flatten)]
    stat: StaticOptions,
    /// Labelled dwells: fit each dwell's tilt from its label with the constants, and report it.
    #[arg(long, conflicts_with = "free")]
    tilt: bool,
    /// The rig's tilt tolerance [mrad]: the prior of `--tilt`, and a dwell beyond it is warned of.
    #[arg(long, default_value_t = 10.0, value_parser = bins_cal::numarg::positive)]
    tilt_tol_mrad: f64,
    /// Thermal dynamics: `identify` (lag, play and bias play fitted jointly with the
    /// polynomial model from every dwell, ramps included; needs `--model poly:N`), or a TOML
    /// file whose `[thermal_dynamics]` table is written as given (a calibration file, or the
    /// model of `bins-cal diagnose --model`).
    #[arg(long, value_name = "identify|MODEL.toml", conflicts_with = "free")]
    dynamics: Option<String>,
    /// `--dynamics identify`: dwells enter the fit as means over blocks of at most this [s].
    #[arg(long, default_value_t = 10.0, value_parser = bins_cal::numarg::duration_s)]
    dynamics_block_s: f64,
}

/// What `--dynamics` asks for.
enum DynamicsArg {
    Identify,
    Given(PathBuf),
}

fn dynamics_arg(a: &Option<String>) -> Option<DynamicsArg> {
    a.as_ref().map(|s| if s == "identify" { DynamicsArg::Identify } else { DynamicsArg::Given(PathBuf::from(s)) })
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
            s.n_rows,
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
    let given: Option<PathBuf> = match dynamics_arg(&args.dynamics) {
        Some(DynamicsArg::Given(p)) => Some(p),
        _ => None,
    };
    fsio::refuse_overwriting_inputs(
        args.tilter.iter().chain(&args.shaker).chain(&args.memory_x).chain(&given),
        [&args.output].into_iter().chain(&args.blob).chain(&args.ihex),
    )?;
    let model_arg = parse_model(&args.model)?;
    if matches!(dynamics_arg(&args.dynamics), Some(DynamicsArg::Identify)) && !matches!(model_arg, ModelArg::Poly(_)) {
        bail!(
            "--dynamics identify: needs --model poly:N (the dynamics are fitted jointly with a polynomial model), got --model {}",
            args.model
        );
    }
    if !(args.dynamics_block_s > 0.0) {
        bail!("--dynamics-block-s {}: must be positive", args.dynamics_block_s);
    }
    let method = parse_method(args.method, &args.form)?;
    let ve_variant = match args.ve_variant.as_str() {
        "exact" => bins_comp::Variant::Exact,
        "paper" => bins_comp::Variant::Paper,
        v => bail!("--ve-variant `{v}`: expected exact or paper"),
    };
    let mut notes: Vec<String> = Vec::new();
    let free = args.free || no_reference(&args.tilter, &mut notes)?;
    let (all, files) = if free {
        free_intervals(&args.tilter, &args.stat, &args.seg)?
    } else {
        for p in &args.tilter {
            let missing = segments::missing_reference_columns(p)?;
            if !missing.is_empty() {
                notes.push(format!(
                    "{}: no column(s) {}: the dwells are taken as free of vibration (their reference is fx_g, fy_g, fz_g)",
                    p.display(),
                    missing.join(", ")
                ));
            }
        }
        let (all, files) = segments::find_all(&args.tilter, &args.seg)?;
        (all.into_iter().filter(|s| s.pos.starts_with(&args.pos_prefix)).collect(), files)
    };
    print_segments(&all);
    let groups = segments::by_temperature(&all, args.seg.temp_tol_c);
    if groups.is_empty() {
        bail!("{files}: no stationary dwell with a settled temperature (see the table above)");
    }
    if free {
        if args.tilt {
            notes.push(format!(
                "{files}: --tilt ignored: the free fit (|f| = 1 g) has no labelled references whose tilts it could fit"
            ));
        }
        return run_free(&args, groups, &all, &files, notes, (model_arg, method, ve_variant));
    }
    let mut fits = Vec::new();
    let n_groups = groups.len();
    let mut first_skipped: Option<anyhow::Error> = None;
    for (t, segs) in groups {
        // A temperature with fewer than 4 positions (dwells that happened to be settled during
        // a ramp's reversal, say) cannot give the 12 constants: skipped with a note while
        // other temperatures can.
        let positions = segs.iter().fold(Vec::<[f64; 3]>::new(), |mut v, s| {
            if !v.contains(&s.f_g) {
                v.push(s.f_g);
            }
            v
        });
        if positions.len() < 4 && n_groups > 1 {
            let labels: Vec<&str> = segs.iter().map(|s| s.pos.as_str()).collect();
            notes.push(format!(
                "{files}: at {t:.2} °C only {} settled dwell(s) ({}) at {} position(s): skipped (the 12 constants need at least 4 positions)",
                segs.len(),
                labels.join(", "),
                positions.len()
            ));
            first_skipped.get_or_insert(
                fit_temperature(t, segs, &files)
                    .err()
                    .unwrap_or_else(|| anyhow!("{files}: at {t:.2} °C too few positions")),
            );
            continue;
        }
        let mut fit = fit_temperature(t, segs, &files)?;
        if args.tilt {
            notes.push(refine_tilt(&mut fit, args.tilt_tol_mrad, &files)?);
        }
        fits.push(fit);
    }
    if fits.is_empty() {
        return Err(first_skipped.unwrap_or_else(|| anyhow!("{files}: no temperature with enough dwells")));
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
    finish(&args, &points, &kept, &files, notes, (model_arg, method, ve_variant))
}

/// The temperature model, the vibration model and the outputs from the constants at each
/// temperature (`points`); `kept_temps_c`: the temperatures of the used dwells.
fn finish(
    args: &Args,
    points: &[(f64, Constants<f64>)],
    kept_temps_c: &[f64],
    files: &str,
    mut notes: Vec<String>,
    (model_arg, method, ve_variant): (ModelArg, Method, bins_comp::Variant),
) -> anyhow::Result<()> {
    let req = ModelRequest {
        t0_c: args.t0,
        model: model_arg,
        knots: args.knots.clone(),
        temp_tol_c: args.seg.temp_tol_c,
        method,
    };
    let (mut params, model_notes) = bins_cal::calib::tilter::calibration_params(points, kept_temps_c, &req, files)?;
    notes.splice(0..0, model_notes);
    let dynamics = match dynamics_arg(&args.dynamics) {
        None => None,
        Some(DynamicsArg::Given(path)) => {
            let spec = DynamicsSpec::read_table(&path)?;
            notes.push(format!("thermal dynamics as given in {} ([thermal_dynamics])", path.display()));
            Some(spec)
        }
        Some(DynamicsArg::Identify) => {
            let (found, n) = identify_dynamics(args, &params, files)?;
            notes.extend(n);
            found.map(|(p, d)| {
                params = p;
                d
            })
        }
    };
    let method = params.method;
    // Model residual: the constants the model gives at each temperature vs the measured ones.
    if dynamics.is_some() && matches!(dynamics_arg(&args.dynamics), Some(DynamicsArg::Identify)) {
        println!(
            "\ntemperature model residual (the joint model with dynamics, at the reading, − the constants measured in the soaks; the soaks' dwells carry the plays, so this is not zero):"
        );
    } else {
        println!("\ntemperature model residual (model − measured at each calibration temperature):");
    }
    println!("  {:>9} {:>12} {:>14}", "temp_C", "max|dU0| mg", "max|dK/K| ppm");
    for (t, c) in points {
        let (du, dk) = bins_cal::calib::tilter::model_residual(&params, *t, c);
        println!("  {:>9.2} {:>12.4} {:>14.2}", t, du * 1e3, dk * 1e6);
    }
    let vibration = if args.shaker.is_empty() {
        None
    } else {
        let r = super::shaker::calibrate(&args.shaker, &args.seg, ve_variant, |t| params.constants_at(t))?;
        notes.extend(r.notes);
        Some(r.params)
    };
    let meta = Meta { serial: args.serial.as_deref().unwrap_or(""), date: None, tool_version: bins_cal::TOOL_VERSION };
    let mut file = CalibrationFile::from_parts(&params, vibration.as_ref(), &meta);
    file.thermal_dynamics = dynamics;
    // Everything is computed and checked before anything is written.
    let blob = file.to_blob().map_err(|e| anyhow!("{files}: the calibration is not valid: {e}"))?;
    let hex = match &args.ihex {
        Some(_) => Some(memmap::calib_hex(args.memory_x.as_deref(), &blob)?.0),
        None => None,
    };
    let mut header = String::from("# bins-cal calibrate from: ");
    header.push_str(files);
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
    // All or nothing: the file, the blob and the HEX.
    let mut outputs: Vec<(&std::path::Path, &[u8])> = vec![(&args.output, text.as_bytes())];
    if let Some(p) = &args.blob {
        outputs.push((p, &blob));
    }
    if let (Some(p), Some(h)) = (&args.ihex, &hex) {
        outputs.push((p, h.as_bytes()));
    }
    fsio::write_all_or_nothing(&outputs)?;
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
        println!("wrote {} ({} bytes)", p.display(), blob.len());
    }
    if let Some(p) = &args.ihex {
        println!("wrote {}", p.display());
    }
    Ok(())
}

/// `--dynamics identify`: the dynamics and the polynomial model fitted jointly on every dwell
/// of the tilter recordings (`static_params`: the model from the settled dwells, whose order,
/// T0, K (for what the dwells cannot determine) and method it keeps). Prints the search, the
/// components and the residuals; returns the joint parameters and the table (`None` when no
/// component is kept: nothing of the dynamics is then written) and the notes.
#[allow(clippy::type_complexity)]
fn identify_dynamics(
    args: &Args,
    static_params: &CalibrationParams,
    files: &str,
) -> anyhow::Result<(Option<(CalibrationParams, DynamicsSpec)>, Vec<String>)> {
    let ModelArg::Poly(order) = parse_model(&args.model)? else { bail!("--dynamics identify: needs --model poly:N") };
    let series: Vec<Series> = args
        .tilter
        .iter()
        .map(|p| Series::read(p, &args.seg, &args.pos_prefix, args.dynamics_block_s))
        .collect::<anyhow::Result<_>>()?;
    let req = Request {
        order,
        t0_c: static_params.t0_c,
        k_prior: static_params.constants.k_v_per_g,
        method: static_params.method,
    };
    println!("\nthermal dynamics (every dwell, ramps included, in blocks of ≤ {} s):", args.dynamics_block_s);
    let started = std::time::Instant::now();
    let id = dynamics::identify(&series, &req, &mut |l| println!("  {l}")).map_err(|e| anyhow!("{files}: {e}"))?;
    let took_s = started.elapsed().as_secs_f64();
    println!("  {:<11} {:>10} {:>10}     {:>22}  status", "component", "value", "std_error", "held-out gain [µg²]");
    for c in &id.components {
        let unit = if c.name == "lag" { "s" } else { "°C" };
        println!(
            "  {:<11} {:>10.3} {:>10.3} {:<3} {:>+11.1} ± {:<8.1}  {}",
            c.name,
            c.value,
            c.std_error,
            unit,
            c.heldout_gain_g2 * 1e12,
            c.heldout_se_g2 * 1e12,
            c.why_off.as_deref().unwrap_or("kept")
        );
    }
    // The time-halves check of what is kept, both directions, per axis (the search printed
    // its table): a note in the file.
    let halves = id.halves.as_ref().filter(|_| id.any_kept()).map(|h| {
        let mg = |v: [f64; 3]| format!("{:.3} / {:.3} / {:.3}", v[0] * 1e3, v[1] * 1e3, v[2] * 1e3);
        let dirs = ["first half → second", "second half → first"];
        format!(
            "time-halves check (the model refitted at the kept θ on one half of the dwells predicts the other), block RMS x/y/z static → with the dynamics: {}",
            (0..2)
                .map(|d| format!("{} {} → {} mg", dirs[d], mg(h.static_rms_g[d]), mg(h.dynamic_rms_g[d])))
                .collect::<Vec<_>>()
                .join("; ")
        )
    });
    let off: Vec<String> =
        id.components.iter().filter_map(|c| c.why_off.as_ref().map(|w| format!("{} off: {w}", c.name))).collect();
    if !id.any_kept() {
        // Nothing found, nothing written: the static calibration, no [thermal_dynamics].
        let head = match &id.not_searched {
            Some(why) => format!("thermal dynamics not identified: {why}"),
            None => format!(
                "thermal dynamics not identified: lag, hysteresis and bias play tried jointly with the poly:{order} model on {} blocks, none kept ({}); no [thermal_dynamics] written",
                id.fit.n_blocks,
                off.join("; ")
            ),
        };
        println!("  {head}");
        return Ok((None, vec![head]));
    }
    let b = id.fit.bias_play_g;
    println!("  bias play amplitude x/y/z: {:+.4} / {:+.4} / {:+.4} mg", b[0] * 1e3, b[1] * 1e3, b[2] * 1e3);
    let (r0, r1) = (id.static_fit.rms_g(), id.fit.rms_g());
    println!(
        "  block residual RMS x/y/z: static poly:{order} {:.4} / {:.4} / {:.4} mg → with the dynamics {:.4} / {:.4} / {:.4} mg ({} blocks, {} evaluations, {took_s:.2} s)",
        r0[0] * 1e3,
        r0[1] * 1e3,
        r0[2] * 1e3,
        r1[0] * 1e3,
        r1[1] * 1e3,
        r1[2] * 1e3,
        id.fit.n_blocks,
        id.evaluations
    );
    let d = id.dynamics();
    let spec = DynamicsSpec::from_dynamics(&d);
    let kept: Vec<String> = id
        .components
        .iter()
        .filter(|c| c.on)
        .map(|c| match c.name {
            "lag" => format!("τ = {:.1} ± {:.1} s", d.lag_tau_s, c.std_error),
            "hysteresis" => format!("h = {:.3} ± {:.3} °C", d.hysteresis_width_c, c.std_error),
            _ => format!(
                "h_b = {:.3} ± {:.3} °C with {:+.4} / {:+.4} / {:+.4} mg{}",
                d.bias_play_width_c,
                c.std_error,
                b[0] * 1e3,
                b[1] * 1e3,
                b[2] * 1e3,
                match id.halves.as_ref().map(|h| &h.bias_notes) {
                    Some(n) if !n.is_empty() => format!(
                        " (0 where it does not predict the other half better in both directions: {})",
                        n.join("; ")
                    ),
                    _ => String::new(),
                }
            ),
        })
        .collect();
    let mut notes = vec![format!(
        "thermal dynamics identified jointly with the poly:{order} model on {} blocks of every dwell (ramps included): {}; block residual RMS {:.4} → {:.4} mg (worst axis)",
        id.fit.n_blocks,
        kept.join(", "),
        r0.iter().fold(0.0f64, |a, b| a.max(*b)) * 1e3,
        r1.iter().fold(0.0f64, |a, b| a.max(*b)) * 1e3
    )];
    if !off.is_empty() {
        notes.push(off.join("; "));
    }
    notes.extend(halves);
    notes.push("self-heating is not identified from a tilter recording without a power-on (0)".into());
    let mut params = id.fit.params;
    // The calibrated range covers the static model's too.
    params.temp_range_c = (
        params.temp_range_c.0.min(static_params.temp_range_c.0),
        params.temp_range_c.1.max(static_params.temp_range_c.1),
    );
    Ok((Some((params, spec)), notes))
}

/// True when no recording has a reference (absent or empty columns): the free fit is then
/// automatic, and `notes` says why.
fn no_reference(paths: &[PathBuf], notes: &mut Vec<String>) -> anyhow::Result<bool> {
    let mut why = Vec::new();
    for p in paths {
        match segments::reference(p)? {
            Reference::Rows(_) => return Ok(false),
            Reference::Absent => why.push(format!("{} has no reference columns fx_g, fy_g, fz_g", p.display())),
            Reference::Empty => why.push(format!("{}: the reference columns are empty in every row", p.display())),
        }
    }
    notes.push(format!("{}: calibrated from static intervals alone (as with --free)", why.join("; ")));
    Ok(true)
}

/// The static intervals of every recording; the names of the files.
fn free_intervals(
    paths: &[PathBuf],
    opt: &StaticOptions,
    seg: &segments::Options,
) -> anyhow::Result<(Vec<Segment>, String)> {
    let mut all = Vec::new();
    for p in paths {
        all.extend(free::find_static(p, opt, seg)?);
    }
    let names = paths.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ");
    Ok((all, names))
}

/// Prints the frame-independent parameters with their standard errors; `fixed` marks the
/// non-orthogonality as assumed zero.
fn print_frame_free(p: &FrameFree, se: &FrameFree, fixed: bool) {
    println!("  {:<20} {:>14} {:>12}", "parameter", "value", "std_error");
    let (v, e) = (p.to_array(), se.to_array());
    for (k, name) in FrameFree::names().iter().enumerate() {
        let scale = if (3..6).contains(&k) { 1.0 } else { 1e3 };
        if k >= 6 && fixed {
            println!("  {:<20} {:>14} {:>12}  assumed (--free-params bias-scale)", name, "0", "-");
        } else if (3..6).contains(&k) {
            println!("  {:<20} {:>14.7} {:>12.2e}", name, v[k], e[k]);
        } else {
            println!("  {:<20} {:>+14.4} {:>12.4}", name, v[k] * scale, e[k] * scale);
        }
    }
}

/// `--free-signs`: three of `+` and `-`.
fn parse_signs(s: &str) -> anyhow::Result<[f64; 3]> {
    let v: Vec<f64> = s
        .chars()
        .map(|c| match c {
            '+' => Ok(1.0),
            '-' => Ok(-1.0),
            _ => Err(anyhow!("--free-signs `{s}`: expected three of + and - (the signs of K_xx, K_yy, K_zz)")),
        })
        .collect::<anyhow::Result<_>>()?;
    <[f64; 3]>::try_from(v)
        .map_err(|_| anyhow!("--free-signs `{s}`: expected three of + and - (the signs of K_xx, K_yy, K_zz)"))
}

/// The free path: per temperature the free fit of its static intervals, then [`finish`].
fn run_free(
    args: &Args,
    groups: Vec<(f64, Vec<&Segment>)>,
    all: &[Segment],
    files: &str,
    notes: Vec<String>,
    model: (ModelArg, Method, bins_comp::Variant),
) -> anyhow::Result<()> {
    let signs = parse_signs(&args.free_signs)?;
    let mut notes = notes;
    notes.push(format!(
        "free fit (|f| = 1 g): K upper triangular (imu_tk's gauge: the z input axis is the frame's z, the y input axis lies in its y-z plane), signs of K_xx, K_yy, K_zz {}",
        args.free_signs
    ));
    let mut points = Vec::new();
    for (t, segs) in groups {
        let u: Vec<[f64; 3]> = segs.iter().map(|s| s.mean_u_v).collect();
        let fit = free::fit_free(&u, args.free_params, signs).map_err(|e| anyhow!("{files}: at {t:.2} °C: {e}"))?;
        println!(
            "\nfree fit at {t:.2} °C over {} static intervals (|f| = 1 g; K upper triangular: the z input axis is the frame's z, the y input axis lies in its y–z plane):",
            segs.len()
        );
        print_frame_free(&fit.params, &fit.se, fit.which == FreeParams::BiasScale);
        println!("  residual σ {:.4} mg; per interval, |f| − 1 g [mg]:", fit.sigma_g * 1e3);
        for (s, r) in segs.iter().zip(&fit.residual_g) {
            println!("    {:<5} {:>8.1} … {:<8.1} s {:>+9.4}", s.pos, s.t_s.0, s.t_s.1, r * 1e3);
        }
        notes.push(format!(
            "free fit at {t:.2} °C: {} static intervals, residual σ {:.4} mg",
            segs.len(),
            fit.sigma_g * 1e3
        ));
        points.push((t, fit.constants));
    }
    let kept: Vec<f64> = all.iter().filter(|s| s.rejected.is_none()).map(|s| s.temp_c).collect();
    finish(args, &points, &kept, files, notes, model)
}

/// `--tilt`: fits each dwell's tilt from its label jointly with the constants (replacing
/// them and their residual in `fit`), prints how far each dwell was from its label and warns
/// of those beyond the rig's tolerance. Returns the note for the file's header.
fn refine_tilt(fit: &mut TempFit<'_>, tol_mrad: f64, files: &str) -> anyhow::Result<String> {
    let labels: Vec<[f64; 3]> = fit.segments.iter().map(|s| s.f_g).collect();
    let u: Vec<[f64; 3]> = fit.segments.iter().map(|s| s.mean_u_v).collect();
    let se: Vec<[f64; 3]> =
        fit.segments.iter().map(|s| s.std_u_v.map(|x| x / (s.n_rows.max(1) as f64).sqrt())).collect();
    let t = fit.temp_c;
    let tf = free::fit_tilted(&labels, &u, &se, &fit.constants, tol_mrad * 1e-3)
        .map_err(|e| anyhow!("{files}: at {t:.2} °C: tilt fit: {e}"))?;
    println!(
        "\ndwells against their labels at {t:.2} °C (tilt fitted with the constants; rig tolerance {tol_mrad} mrad):"
    );
    println!("  {:<5} {:>10} {:>9} {:>9} {:>9} {:>9}  status", "pos", "tilt_mrad", "tilt_deg", "fx_g", "fy_g", "fz_g");
    for (k, s) in fit.segments.iter().enumerate() {
        let tilt = tf.tilt_rad[k];
        let beyond = tilt * 1e3 > tol_mrad;
        let f = tf.f_g[k];
        println!(
            "  {:<5} {:>10.3} {:>9.4} {:>+9.5} {:>+9.5} {:>+9.5}  {}",
            s.pos,
            tilt * 1e3,
            tilt.to_degrees(),
            f[0],
            f[1],
            f[2],
            if beyond { "beyond the rig tolerance" } else { "ok" }
        );
        if beyond {
            eprintln!(
                "bins-cal: warning: {}: {} at {t:.2} °C was {:.1} mrad ({:.2}°) from its label, beyond the rig tolerance {tol_mrad} mrad",
                s.file.display(),
                s.pos,
                tilt * 1e3,
                tilt.to_degrees()
            );
        }
    }
    println!("  constants with the tilts (frame: the one that makes the tilts smallest):");
    print_frame_free(&tf.params, &tf.se, false);
    let (k, worst) = tf.tilt_rad.iter().enumerate().fold((0, 0.0f64), |a, (k, t)| if *t > a.1 { (k, *t) } else { a });
    let note = format!(
        "at {t:.2} °C the dwells' tilts from their labels were fitted with the constants (rig tolerance {tol_mrad} mrad): largest {:.2} mrad ({})",
        worst * 1e3,
        fit.segments.get(k).map_or("", |s| s.pos.as_str())
    );
    fit.constants = tf.constants;
    fit.residual_g = tf.residual_g;
    fit.how = "tilt";
    Ok(note)
}
