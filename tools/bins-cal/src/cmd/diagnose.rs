//! `bins-cal diagnose`: where a simulated recording and a real one of the same test disagree,
//! which physics the simulation misses, the fitted terms, and the fit before and after. The
//! method is in `docs/diagnosis.md`.

use anyhow::{Context, anyhow};
use bins_cal::diagnose::{DiagnoseError, Options, diagnose_against_calibration, diagnose_files, plot};
use bins_cal::fsio;
use std::path::PathBuf;

/// Arguments of `bins-cal diagnose`.
#[derive(clap::Args)]
pub struct Args {
    /// The simulated recording (format v1).
    #[arg(long, value_name = "SIM.csv", required_unless_present = "calib", conflicts_with = "calib")]
    sim: Option<PathBuf>,
    /// Instead of SIM: the unit's calibration (a calibration file or a blob, told apart by the
    /// content); SIM is what it predicts for REAL's reference, temperature and time, row for
    /// row.
    #[arg(long, value_name = "CAL.toml")]
    calib: Option<PathBuf>,
    /// The real recording of the same test, row for row.
    #[arg(long, value_name = "REAL.csv")]
    real: PathBuf,
    /// The report to write (JSON).
    #[arg(long, value_name = "OUT.json")]
    report: PathBuf,
    /// Also write PNG plots into this directory.
    #[arg(long, value_name = "DIR")]
    plots: Option<PathBuf>,
    /// Also write the augmented model (the found terms) as TOML, with the thermal dynamics
    /// they name as a `[thermal_dynamics]` table (`bins-cal calibrate --dynamics MODEL.toml`).
    #[arg(long, value_name = "MODEL.toml")]
    model: Option<PathBuf>,
    /// The sensor's random walk [mg/√h] (its specification) to test mechanisms against;
    /// without it, estimated from the data with every mechanism of the library in the model.
    #[arg(long, value_name = "MG_PER_SQRT_H")]
    random_walk: Option<f64>,
    /// Reduce the rows to means over blocks of at most this many seconds before the search;
    /// the noise floor and the held-out figures stay per row of the recording. 0: every row.
    /// Without it: blocks of the length the data allow (a third of a second at 100 Hz), every
    /// row where blocks would change what the search sees (the report's note says which)
    #[arg(long, value_name = "SECONDS")]
    block_s: Option<f64>,
}

/// Runs `bins-cal diagnose`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let inputs: Vec<&PathBuf> =
        [args.sim.as_ref(), args.calib.as_ref(), Some(&args.real)].into_iter().flatten().collect();
    fsio::refuse_overwriting_inputs(inputs.iter(), [Some(&args.report), args.model.as_ref()].into_iter().flatten())?;
    let t0 = std::time::Instant::now();
    let opt = Options { random_walk_mg_per_sqrt_h: args.random_walk, progress: true, block_s: args.block_s };
    let d = match (&args.sim, &args.calib) {
        (Some(sim), _) => diagnose_files(sim, &args.real, &opt),
        (None, Some(calib)) => diagnose_against_calibration(&args.real, calib, &opt),
        (None, None) => Err(DiagnoseError("give --sim SIM.csv or --calib CAL.toml".into())),
    }
    .map_err(|e| anyhow!("{e}"))?;
    let r = &d.report;
    let json = serde_json::to_string_pretty(r).context("report")?;
    let model = match &args.model {
        Some(m) => {
            let text = toml::to_string(&r.model).with_context(|| format!("{}", m.display()))?;
            let head = "# bins-cal diagnose: terms missing from the simulation (add to its model); [thermal_dynamics]:\n\
                        # the dynamics they name, for `bins-cal calibrate --dynamics` (calibration-file keys).\n";
            Some(format!("{head}{text}"))
        }
        None => None,
    };
    let plots = match &args.plots {
        Some(dir) => plot::render_plots(&d, dir).map_err(|e| anyhow!("{e}"))?,
        None => Vec::new(),
    };
    // Every output named, the plots' included, is checked against the inputs again, then all
    // are written or none.
    fsio::refuse_overwriting_inputs(
        inputs,
        [Some(&args.report), args.model.as_ref()].into_iter().flatten().chain(plots.iter().map(|p| &p.0)),
    )?;
    let mut outputs: Vec<(&std::path::Path, &[u8])> = vec![(&args.report, json.as_bytes())];
    if let (Some(m), Some(text)) = (&args.model, &model) {
        outputs.push((m, text.as_bytes()));
    }
    outputs.extend(plots.iter().map(|(p, png)| (p.as_path(), png.as_slice())));
    // A plot directory this run creates goes again with the outputs when they do not appear
    // (an error, or a signal before the renames: fsio::OutputDir).
    let created = args.plots.as_deref().map(fsio::OutputDir::create).transpose()?;
    fsio::write_all_or_nothing(&outputs)?;
    if let Some(d) = created {
        d.keep();
    }
    let plots: Vec<PathBuf> = plots.into_iter().map(|p| p.0).collect();
    println!("diagnosed {} rows ({} used) in {:.1} s", r.rows, r.rows_used, t0.elapsed().as_secs_f64());
    for n in &r.notes {
        println!("note: {n}");
    }
    if r.effects.is_empty() && r.ambiguous.is_empty() && r.verdict.values().all(|v| v == "at the noise") {
        println!(
            "no mechanism found above the noise: no averaging time from 1 s to a tenth of the record shows structure above the noise on any axis"
        );
    } else if r.effects.is_empty() && r.ambiguous.is_empty() {
        println!("no mechanism in the library explains the residual");
    }
    for e in &r.effects {
        println!("effect {} on {}: {}", e.id, e.axes.join(","), e.explanation);
        for (ax, ps) in &e.params {
            let open = e.undetermined.get(ax);
            let list: Vec<String> = ps
                .iter()
                .map(|(k, v)| match (open.is_some_and(|u| u.contains(k)), e.ci.get(ax).and_then(|c| c.get(k))) {
                    (true, Some(c)) => format!("{k} undetermined ({:.3} … {:.3})", c[0], c[1]),
                    _ => format!("{k} = {v:.6}"),
                })
                .collect();
            let cut = e.heldout_cut_mg.get(ax).map_or(String::new(), |c| {
                format!("; cuts the held-out RMS by {:.4} mg (fold-to-fold standard error {:.4} mg)", c[0], c[1])
            });
            println!("    {ax}: {}{cut}", list.join(", "));
        }
    }
    for a in &r.ambiguous {
        println!(
            "ambiguous on {}: {} (modelled as {}) — separate by: {}",
            a.axes.join(","),
            a.ids.join(" / "),
            a.modelled_as,
            a.separating_test
        );
        for (ax, sep) in &a.separability {
            if sep.is_empty() {
                continue;
            }
            let list: Vec<String> = sep.iter().map(|(id, d)| format!("{id} {d:.1}")).collect();
            let thr = a.separation_needed.get(ax).copied().unwrap_or(f64::NAN);
            println!(
                "    {ax}: of what {} predicts here, each alternative refitted cannot absorb: {} (a name needs {thr:.1})",
                a.modelled_as,
                list.join(", ")
            );
        }
    }
    if !r.negligible.is_empty() {
        let list: Vec<String> = r
            .negligible
            .iter()
            .map(|n| {
                format!(
                    "{} on {} (cuts {:.4} ± {:.4} mg of a {:.4} mg floor)",
                    n.id, n.axis, n.heldout_cut_mg, n.heldout_cut_se_mg, n.noise_floor_mg
                )
            })
            .collect();
        println!(
            "negligible (significant, but the held-out cut is under {:.0} % of the noise floor or {} standard errors): {}",
            100.0 * bins_cal::diagnose::report::MATERIAL_FLOOR_SHARE,
            bins_cal::diagnose::report::MATERIAL_SE,
            list.join("; ")
        );
    }
    for s in &r.steps {
        println!(
            "bias step on {} at t = {:.1} s (line {}): {:+.3} ± {:.3} mg (z = {:.1}), fitted with the model",
            s.axis,
            s.time_s,
            s.line,
            s.size_mg,
            1.96 * s.se_mg,
            s.z
        );
    }
    let rw_from = if r.random_walk_source == "given" { "given" } else { "estimated with the whole library in" };
    for ax in ["x", "y", "z"] {
        let g = |m: &std::collections::BTreeMap<String, f64>| m.get(ax).copied().unwrap_or(f64::NAN);
        let scale = r.unexplained_scale_s.get(ax).map_or(String::new(), |s| format!(" at {s:.0} s averaging"));
        println!(
            "{ax}: {}; noise floor {:.4} mg; held-out RMS of the raw residual {:.4} → {:.4} mg; unexplained {:.4} mg{scale}",
            r.verdict.get(ax).map_or("", String::as_str),
            g(&r.noise_floor_mg),
            g(&r.heldout_rms_before_mg),
            g(&r.heldout_rms_after_mg),
            g(&r.unexplained_rms_mg),
        );
        let sensor = r
            .sensor_random_walk_mg_per_sqrt_h
            .get(ax)
            .map_or("not measurable".to_string(), |v| format!("{v:.3} mg/√h"));
        println!(
            "   drift {:.4} mg RMS (not subtracted); random walk tested against {:.3} mg/√h ({rw_from}), the sensor's own at τ ≤ 60 s: {sensor}",
            g(&r.drift_rms_mg),
            g(&r.random_walk_mg_per_sqrt_h),
        );
    }
    for (title, strata) in [("mismatch located", &r.located), ("unexplained structure located", &r.unexplained_located)]
    {
        let shown: Vec<_> = strata
            .iter()
            .filter(|s| r.verdict.get(&s.axis).is_some_and(|v| v != "at the noise" && v != "explained"))
            .take(6)
            .collect();
        if shown.is_empty()
            || (title.starts_with("unexplained")
                && r.verdict.values().all(|v| v != "unexplained" && v != "partly explained"))
        {
            continue;
        }
        println!("{title} (strongest {} of {}):", shown.len(), strata.len());
        for s in shown {
            println!(
                "    {}: {} {}: mean {:+.3} mg (z = {:.1}, {} rows, {:.0} s)",
                s.axis, s.dimension, s.value, s.mean_mg, s.z, s.rows, s.duration_s
            );
        }
    }
    println!("report: {}", args.report.display());
    for p in plots {
        println!("plot: {}", p.display());
    }
    Ok(())
}
