//! `bins-cal diagnose`: where a simulated recording and a real one of the same test disagree,
//! which physics the simulation misses, the fitted terms, and the fit before and after. The
//! method is in `docs/diagnosis.md`.

use anyhow::{Context, anyhow};
use bins_cal::diagnose::noise::SensorNoise;
use bins_cal::diagnose::{DiagnoseError, Options, diagnose_against_calibration, diagnose_files, plot, propose};
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
    /// It is the residual's: √2 times the sensor's where SIM is simulated with the same noise.
    #[arg(long, value_name = "MG_PER_SQRT_H")]
    random_walk: Option<f64>,
    /// The sensor's bias instability [mg] (its specification: the standard deviation of a
    /// first-order Gauss–Markov bias, with --bias-tau its correlation time): a second state of
    /// the noise model beside the random walk, so structure at averaging times beyond τ is not
    /// taken for drift. Without it, white noise and a random walk alone. The residual's, as for
    /// --random-walk.
    #[arg(long, value_name = "MG", requires = "bias_tau")]
    bias_instability: Option<f64>,
    /// The correlation time [s] of --bias-instability.
    #[arg(long, value_name = "SECONDS", requires = "bias_instability")]
    bias_tau: Option<f64>,
    /// The sensor's noise per accelerometer instead of --random-walk and --bias-instability: a
    /// scenario whose [noise] table holds it, as `bins-cal allan --noise-toml` fits it to a
    /// quiet recording of the unit (or SIM's own scenario). Scaled to the residual by the ratio
    /// of their white levels, which holds the scale factor and the √2 of two noisy recordings.
    #[arg(long, value_name = "NOISE.toml", conflicts_with_all = ["random_walk", "bias_instability"])]
    noise: Option<PathBuf>,
    /// Reduce the rows to means over blocks of at most this many seconds before the search;
    /// the noise floor and the held-out figures stay per row of the recording. 0: every row.
    /// Without it: blocks of the length the data allow (a third of a second at 100 Hz), every
    /// row where blocks would change what the search sees (the report's note says which)
    #[arg(long, value_name = "SECONDS")]
    block_s: Option<f64>,
    /// Where the recording cannot decide between explanations, propose the test that will:
    /// print the three best candidates with their length and expected evidence for every pair,
    /// and write the best as a scenario `bins-cal simulate` runs (with its plot beside it,
    /// NEXT.png). Nothing to separate: it says so and writes neither. Without --twin, the
    /// candidates' thermal path is identified from the recording (chamber_C, power_s).
    #[arg(long, value_name = "NEXT.toml")]
    propose: Option<PathBuf>,
    /// The scenario of SIM (its unit, thermal and noise tables): the candidates' thermal path is
    /// simulated with it, and the proposed scenario keeps its tables (default: the paper's unit
    /// with the thermal path identified from REAL's temp_C, chamber_C and power_s).
    #[arg(long, value_name = "SCENARIO.toml", requires = "propose")]
    twin: Option<PathBuf>,
    /// The chamber's lowest set point for a proposal [°C] (default: the recording's lowest temp_C).
    #[arg(long, value_name = "C", allow_negative_numbers = true, value_parser = bins_cal::numarg::temp_c, requires = "propose")]
    chamber_min: Option<f64>,
    /// The chamber's highest set point for a proposal [°C] (default: the recording's highest temp_C).
    #[arg(long, value_name = "C", allow_negative_numbers = true, value_parser = bins_cal::numarg::temp_c, requires = "propose")]
    chamber_max: Option<f64>,
    /// The largest ramp rate for a proposal [°C/min] (default: the recording's fastest over a minute).
    #[arg(long, value_name = "C_PER_MIN", value_parser = bins_cal::numarg::positive, requires = "propose")]
    max_rate: Option<f64>,
    /// The longest test to propose \[h\] (default: twice the recording's length, at least 4 h).
    #[arg(long, value_name = "HOURS", value_parser = bins_cal::numarg::positive, requires = "propose")]
    max_test_h: Option<f64>,
}

/// Runs `bins-cal diagnose`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let inputs: Vec<&PathBuf> =
        [args.sim.as_ref(), args.calib.as_ref(), Some(&args.real)].into_iter().flatten().collect();
    let inputs: Vec<&PathBuf> = inputs.into_iter().chain(args.twin.as_ref()).chain(args.noise.as_ref()).collect();
    let next_png = args.propose.as_ref().map(|p| p.with_extension("png"));
    let named_outputs =
        || [Some(&args.report), args.model.as_ref(), args.propose.as_ref(), next_png.as_ref()].into_iter().flatten();
    fsio::refuse_overwriting_inputs(inputs.iter(), named_outputs())?;
    let twin = args.twin.as_deref().map(propose::Twin::read).transpose().map_err(|e| anyhow!("{e}"))?;
    let sensor_noise = args.noise.as_deref().map(SensorNoise::read).transpose().map_err(|e| anyhow!("{e}"))?;
    let t0 = std::time::Instant::now();
    let opt = Options {
        random_walk_mg_per_sqrt_h: args.random_walk,
        bias_instability: args.bias_instability.zip(args.bias_tau),
        sensor_noise,
        progress: true,
        block_s: args.block_s,
    };
    let d = match (&args.sim, &args.calib) {
        (Some(sim), _) => diagnose_files(sim, &args.real, &opt),
        (None, Some(calib)) => diagnose_against_calibration(&args.real, calib, &opt),
        (None, None) => Err(DiagnoseError("give --sim SIM.csv or --calib CAL.toml".into())),
    }
    .map_err(|e| anyhow!("{e}"))?;
    let diagnosis_s = t0.elapsed().as_secs_f64();
    let r = &d.report;
    let mut proposal = None;
    let mut proposed: Option<(String, Vec<u8>)> = None;
    if args.propose.is_some() {
        let t1 = std::time::Instant::now();
        let mut lim = propose::Limits::from_recording(&d.prepared);
        lim.temp_min_c = args.chamber_min.unwrap_or(lim.temp_min_c);
        lim.temp_max_c = args.chamber_max.unwrap_or(lim.temp_max_c);
        lim.max_rate_c_per_min = args.max_rate.unwrap_or(lim.max_rate_c_per_min);
        lim.max_duration_s = args.max_test_h.map_or(lim.max_duration_s, |h| h * 3600.0);
        if !(lim.temp_max_c > lim.temp_min_c) {
            return Err(anyhow!(
                "--chamber-min {} --chamber-max {}: the range must not be empty",
                lim.temp_min_c,
                lim.temp_max_c
            ));
        }
        let identified;
        let (twin, twin_note) = match &twin {
            Some(t) => (t, format!("unit, thermal and noise tables from {}", t.source)),
            None => {
                identified = propose::Twin::identified(&d.prepared, &lim).map_err(|e| anyhow!("{e}"))?;
                (&identified.0, identified.1.clone())
            }
        };
        let bar = indicatif::ProgressBar::new(0);
        bar.set_style(
            indicatif::ProgressStyle::with_template("proposing {bar:30} {pos}/{len} candidates, {elapsed}")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        let p = propose::propose(&d, twin, Some(lim), &|i, n| {
            bar.set_length(n as u64);
            bar.set_position(i as u64);
        })
        .map_err(|e| anyhow!("{e}"))?;
        bar.finish_and_clear();
        if let (Some(p), Some(png_path)) = (&p, &next_png)
            && let Some(best) = p.ranked.first()
        {
            let rate = twin.table.get("recording").and_then(|t| t.get("rate_Hz")).and_then(toml::Value::as_float);
            let text = twin.scenario(&best.candidate, rate.unwrap_or(1.0), true);
            let png = propose::plot(&d, twin, p, png_path).map_err(|e| anyhow!("{e}"))?;
            proposed = Some((text, png));
        }
        proposal = Some((p, t1.elapsed().as_secs_f64(), twin_note));
    }
    let mut value = serde_json::to_value(r).context("report")?;
    if let (Some((p, _, note)), serde_json::Value::Object(m)) = (&proposal, &mut value) {
        let file = proposed.as_ref().and(args.propose.as_deref());
        let mut j = propose::to_json(p.as_ref(), file);
        if let serde_json::Value::Object(o) = &mut j {
            o.insert("thermal_path".into(), serde_json::Value::String(note.clone()));
        }
        m.insert("proposal".into(), j);
    }
    let json = serde_json::to_string_pretty(&value).context("report")?;
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
    fsio::refuse_overwriting_inputs(inputs, named_outputs().chain(plots.iter().map(|p| &p.0)))?;
    let mut outputs: Vec<(&std::path::Path, &[u8])> = vec![(&args.report, json.as_bytes())];
    if let (Some(m), Some(text)) = (&args.model, &model) {
        outputs.push((m, text.as_bytes()));
    }
    if let (Some(next), Some(png_path), Some((text, png))) = (&args.propose, &next_png, &proposed) {
        outputs.push((next, text.as_bytes()));
        outputs.push((png_path, png.as_slice()));
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
    println!("diagnosed {} rows ({} used) in {diagnosis_s:.1} s", r.rows, r.rows_used);
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
    let rw_from = match r.random_walk_source.as_str() {
        "given" => "given".to_string(),
        "estimated" => "estimated with the whole library in".to_string(),
        file => format!("from {file}"),
    };
    for ax in ["x", "y", "z"] {
        let beside = r.bias_instability_mg_tau_s.get(ax).map_or(String::new(), |(mg, tau_s)| {
            format!(" beside a bias instability of {mg:.4} mg, τ = {tau_s:.0} s (given)")
        });
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
            "   drift {:.4} mg RMS (not subtracted); random walk tested against {:.3} mg/√h ({rw_from}){beside}, the sensor's own at τ ≤ 60 s: {sensor}",
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
    if let Some((p, secs, note)) = &proposal {
        print_proposal(p.as_ref(), args.propose.as_deref(), next_png.as_deref(), proposed.is_some(), *secs);
        if p.is_some() {
            println!("    candidates simulated with: {note}");
        }
    }
    println!("report: {}", args.report.display());
    for p in plots {
        println!("plot: {}", p.display());
    }
    Ok(())
}

/// Prints what `--propose` found: the pairs, the three best candidates with their length and
/// the expected evidence for every pair, and the files written.
fn print_proposal(
    p: Option<&propose::Proposal>,
    next: Option<&std::path::Path>,
    png: Option<&std::path::Path>,
    written: bool,
    secs: f64,
) {
    let Some(p) = p else {
        println!("proposal: nothing to separate (no ambiguous group): no test proposed, no file written");
        return;
    };
    let l = &p.limits;
    println!(
        "proposal ({secs:.1} s): {} pairs this recording could not separate; chamber {:.1} … {:.1} °C, ramps up to {} °C/min, tests up to {:.1} h",
        p.pairs.len(),
        l.temp_min_c,
        l.temp_max_c,
        l.max_rate_c_per_min,
        l.max_duration_s / 3600.0
    );
    let name = |q: &propose::Pair| format!("{} {} / {}", bins_cal::diagnose::prep::AXES[q.axis], q.a.id(), q.b.id());
    for q in &p.pairs {
        println!(
            "    {}: expected deviance on this recording {:.1} (a name needs {:.1})",
            name(q),
            q.recording,
            q.needed
        );
    }
    if p.ranked.is_empty() {
        println!("proposal: no candidate fits the chamber's limits: no file written");
        return;
    }
    for (i, e) in p.ranked.iter().take(propose::REPORTED).enumerate() {
        let c = &e.candidate;
        println!(
            "candidate {}: {} ({:.1} h{}; worst pair at {:.2}× what it needs, {:.2}× per hour): {}",
            i + 1,
            c.name,
            c.duration_s() / 3600.0,
            if e.separates_all { ", separates every pair" } else { "" },
            e.worst_ratio,
            e.worst_ratio_per_h,
            c.what
        );
        let list: Vec<String> = p
            .pairs
            .iter()
            .zip(&e.deviance)
            .enumerate()
            .map(|(k, (q, v))| match e.intervals.get(k).cloned().flatten() {
                Some(iv) => {
                    let iv: Vec<String> = iv.iter().map(|(lo, hi)| format!("{lo:.0}–{hi:.0}")).collect();
                    format!("{} {v:.1} ({})", name(q), iv.join(" or "))
                }
                None => format!("{} (the rival has no column on this test)", name(q)),
            })
            .collect();
        println!(
            "    expected deviance were the modelled term true (90 % of runs within{}): {}",
            if e.if_others.is_empty() { "" } else { ", whichever member of its group is true" },
            list.join(", ")
        );
    }
    if let (true, Some(n), Some(g)) = (written, next, png) {
        println!("proposed test: {} (bins-cal simulate runs it; plot {})", n.display(), g.display());
    }
}
