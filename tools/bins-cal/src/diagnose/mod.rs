//! `bins-cal diagnose`: locate a mismatch between a simulated and a real recording of the same
//! test, name the physics the simulation misses, model it and show that the fit improves.
//!
//! 1. [`prep`]: residual REAL − SIM per accelerometer in g (SIM's own scale factors).
//! 2. [`noise`]: white + random-walk noise model; noise floor from the Allan deviation of the
//!    static segments.
//! 3. [`locate`]: strata of the test that carry the mismatch.
//! 4. [`mech`] + [`fit`]: the mechanism library, forward selection scored on held-out blocks
//!    with a significance test against the autocorrelated noise, ambiguity between
//!    mechanisms the data cannot separate, and [`separate`]: the deviance a rival cannot
//!    absorb of what the selected model predicts on this design (groups below the naming
//!    threshold). Before it, the die's rise at power-on a thermal lag misses, the unit's
//!    ([`mech::missed_die_rise`]); each accelerometer keeps the lag with or without it,
//!    whichever predicts its held-out rows better.
//! 5. [`steps`]: bias steps located by an innovation-outlier test, fitted jointly with the
//!    selected mechanisms (the selection re-run with their columns in).
//! 6. [`report`]: the JSON report and the augmented model; [`plot`]: PNGs.
//!
//! [`follow`] predicts SIM for a real recording from a calibration. [`cases`] generates the
//! concealed-effect cases of the proof suite. The method is described
//! in `docs/diagnosis.md`.

pub mod cases;
pub mod fit;
pub mod follow;
pub mod locate;
pub mod mech;
pub mod noise;
pub mod plot;
pub mod prep;
pub mod propose;
pub mod report;
pub mod separate;
pub mod stats;
pub mod steps;

use crate::progress::CountedReader;
use crate::recording::{self, Row};
use std::cell::Cell;
use std::fmt;
use std::path::Path;
use std::rc::Rc;

/// An input the diagnosis cannot use: one line naming the file (and line, column).
#[derive(Clone, Debug, PartialEq)]
pub struct DiagnoseError(pub String);

impl fmt::Display for DiagnoseError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for DiagnoseError {}

/// Everything the diagnosis found.
pub struct Diagnosis {
    /// The aligned data.
    pub prepared: prep::Prepared,
    /// Per accelerometer: SIM's temperature sensitivity used by the thermal terms.
    pub sensitivity: Vec<mech::Sensitivity>,
    /// Per accelerometer: the selection and fit.
    pub axes: Vec<fit::AxisFit>,
    /// The report.
    pub report: report::Report,
}

/// How the diagnosis runs.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Options {
    /// The sensor's random walk [mg/√h] to test mechanisms against (a specification);
    /// `None`: estimated from the data with the richest model in ([`fit::fit_axis`]).
    pub random_walk_mg_per_sqrt_h: Option<f64>,
    /// The sensor's bias instability (its specification): the standard deviation \[mg\] and
    /// correlation time \[s\] of a first-order Gauss–Markov bias, a second state of the noise
    /// model beside the random walk ([`noise::Gm`]); `None`: white + random walk alone.
    pub bias_instability: Option<(f64, f64)>,
    /// The sensor's noise per accelerometer from a scenario's `[noise]` table (`--noise`:
    /// what `bins-cal allan --noise-toml` fits to a quiet recording of the unit), scaled to
    /// the residual by its white level ([`noise::SensorNoise`]); instead of the two above.
    pub sensor_noise: Option<noise::SensorNoise>,
    /// A progress bar on stderr while the recordings are read (drawn on a terminal only).
    pub progress: bool,
    /// Reduce the rows to means over blocks of at most this many seconds before the search
    /// ([`prep::Builder::with_blocks`]); `Some(0)`: every row; `None`: the length the data
    /// allow ([`prep::Builder::blocks_from_data`], [`prep::Builder::block_choice`]), every row
    /// where they allow none (up to [`AUTO_BLOCK_ROWS`] usable rows).
    pub block_s: Option<f64>,
}

/// Usable rows kept as they are before a recording is reduced to blocks by default: at about
/// 1.2 KB a row in the selection, 2.4 GB (a 3-hour recording at 100 Hz, 1.08 M rows, stays
/// whole).
pub const AUTO_BLOCK_ROWS: usize = 2_000_000;

/// The most the residual may spread inside the default blocks, over what its consecutive
/// differences predict, for the blocks to be used ([`prep::BlockChoice::accepts`]); white noise
/// gives 1 (within ±0.01 over 20 000 rows in blocks of 34).
pub const BLOCK_WITHIN_RATIO: f64 = 1.1;

/// The fewest rows a default block holds: below, the rows are kept whole.
pub const BLOCK_MIN_ROWS: usize = 4;

/// The range of the `--noise` file's scaling to the residual, in units of the scale factor,
/// outside which the report says the residual's white noise is not the file's: 1 where SIM is
/// noiseless, √2 where SIM and REAL each carry the noise ([`noise::SensorNoise`]), with room
/// for the white level's estimate.
pub const NOISE_RATIO_PLAUSIBLE: (f64, f64) = (0.7, 2.0);

/// The most blocks the default reduction makes of a record: a longer record gets longer blocks
/// (its span over this many), so the search's time and memory are bounded by the model, not by
/// the file (about 1.2 KB a block in the selection: 120 MB; a day at 100 Hz in 1 s blocks).
pub const MAX_BLOCKS: usize = 100_000;

impl Options {
    /// The random-walk intensity [g²/s] of [`Options::random_walk_mg_per_sqrt_h`].
    pub fn random_walk_g2_per_s(&self) -> Option<f64> {
        self.random_walk_mg_per_sqrt_h.map(|rw| (rw * 1e-3).powi(2) / 3600.0)
    }

    /// Whether the sensor's noise is given ([`Options::random_walk_mg_per_sqrt_h`],
    /// [`Options::bias_instability`] or [`Options::sensor_noise`]) rather than estimated.
    pub fn noise_given(&self) -> bool {
        self.random_walk_mg_per_sqrt_h.is_some() || self.bias_instability.is_some() || self.sensor_noise.is_some()
    }

    /// The noise model's bias instability of [`Options::bias_instability`].
    pub fn gm(&self) -> Option<noise::Gm> {
        self.bias_instability.map(|(mg, tau_s)| noise::Gm { var_g2: (mg * 1e-3).powi(2), tau_s })
    }
}

/// Diagnoses a pair of recordings held in memory (`sim_name`, `real_name` name them in
/// errors and in the report), with the default [`Options`].
pub fn diagnose(sim: &[Row], real: &[Row], sim_name: &Path, real_name: &Path) -> Result<Diagnosis, DiagnoseError> {
    diagnose_with(sim, real, sim_name, real_name, &Options::default())
}

/// [`diagnose`] with options.
pub fn diagnose_with(
    sim: &[Row],
    real: &[Row],
    sim_name: &Path,
    real_name: &Path,
    opt: &Options,
) -> Result<Diagnosis, DiagnoseError> {
    check_options(opt)?;
    let p = prep::prepare_blocks(sim, real, sim_name, real_name, opt.block_s)?;
    diagnose_prepared(p, sim_name, real_name, opt)
}

fn check_options(opt: &Options) -> Result<(), DiagnoseError> {
    if let Some(rw) = opt.random_walk_mg_per_sqrt_h
        && !(rw.is_finite() && rw >= 0.0)
    {
        return Err(DiagnoseError(format!("--random-walk {rw}: must be a finite value ≥ 0 mg/√h")));
    }
    if let Some((mg, tau)) = opt.bias_instability {
        if !(mg.is_finite() && mg > 0.0) {
            return Err(DiagnoseError(format!("--bias-instability {mg}: must be a finite value > 0 mg")));
        }
        if !(tau.is_finite() && tau > 0.0) {
            return Err(DiagnoseError(format!("--bias-tau {tau}: must be a finite value > 0 s")));
        }
    }
    if opt.sensor_noise.is_some() && (opt.random_walk_mg_per_sqrt_h.is_some() || opt.bias_instability.is_some()) {
        return Err(DiagnoseError(
            "--noise gives the random walk and the bias instability: not with --random-walk or --bias-instability"
                .into(),
        ));
    }
    if let Some(b) = opt.block_s
        && !(b.is_finite() && b >= 0.0)
    {
        return Err(DiagnoseError(format!("--block-s {b}: must be a finite value ≥ 0 s (0: every row)")));
    }
    Ok(())
}

/// The diagnosis of a prepared pair (steps 2–6 of the module docs).
fn diagnose_prepared(
    mut p: prep::Prepared,
    sim_name: &Path,
    real_name: &Path,
    opt: &Options,
) -> Result<Diagnosis, DiagnoseError> {
    let floor = report::noise_floor(&p);
    // A given random walk is a floor the data may raise, never a licence to take drift for a
    // mechanism: below what the residual itself shows at averaging times up to a minute
    // (where no mechanism of a chamber test moves), that level is used and the report says so.
    // A given bias instability wanders like a random walk of 2σ²/τ there, so it counts.
    let runs = p.static_runs();
    let mut qs = Vec::new();
    let mut gms = Vec::new();
    let mut g_per_v = Vec::new();
    for axis in 0..3 {
        let (given_q, gm) = match &opt.sensor_noise {
            Some(n) => {
                let a = n.for_axis(axis, white_density(&p, &runs, axis), p.dt);
                g_per_v.push(a.g_per_v);
                (Some(a.q), a.gm)
            }
            None => (opt.random_walk_g2_per_s(), opt.gm()),
        };
        let short_gm = gm.map_or(0.0, |g| g.short_q());
        let q = given_q.map(|q| {
            let segs: Vec<&[f64]> = runs.iter().map(|&(a, b)| &p.r[axis][a..b]).collect();
            match noise::short_tau_q(&segs, p.dt) {
                Some((seen, _)) if seen > q + short_gm => {
                    let with = if gm.is_some() { " with the given bias instability's share" } else { "" };
                    p.notes.push(format!(
                        "accelerometer {}: the given random walk {:.3} mg/√h{with} is below what the residual shows at averaging times up to a minute ({:.3} mg/√h); mechanisms are tested against the latter",
                        prep::AXES[axis],
                        (q * 3600.0).sqrt() * 1e3,
                        (seen * 3600.0).sqrt() * 1e3
                    ));
                    seen - short_gm
                }
                _ => q,
            }
        });
        qs.push(q);
        gms.push(gm);
    }
    if let Some(n) = &opt.sensor_noise {
        let ratio: Vec<String> = g_per_v.iter().zip(&p.k_diag).map(|(k, kd)| format!("{:.3}", k * kd)).collect();
        p.notes.push(format!(
            "the sensor's noise is taken from {} and scaled to the residual by the ratio of their white levels: {} times the scale factor's g per volt on x, y, z (√2 = 1.414 where SIM carries the same noise as REAL, 1 where SIM has none or the calibration predicts it); a Gauss–Markov bias faster than a row is in that white level, two slower ones are taken as one",
            n.file.display(),
            ratio.join(" / ")
        ));
        for (axis, (k, kd)) in g_per_v.iter().zip(&p.k_diag).enumerate() {
            let (lo, hi) = NOISE_RATIO_PLAUSIBLE;
            if !(lo..=hi).contains(&(k * kd)) {
                p.notes.push(format!(
                    "accelerometer {}: that ratio, {:.3}, is neither near 1 nor near √2: the residual's white noise is not {}'s (another unit, logger or rate, or vibration in the static rows), and its random walk and bias instability, scaled by it, are not this residual's either",
                    prep::AXES[axis],
                    k * kd,
                    n.file.display()
                ));
            }
        }
    }
    let mut ctxs: Vec<mech::Context> = (0..3).map(|axis| mech::Context::new(&p, axis)).collect();
    let rise_c = mech::missed_die_rise(&p, &mut ctxs).unwrap_or(0.0);
    let mut axes = Vec::new();
    let mut sensitivity = Vec::new();
    let mut nuisance = Vec::new();
    let mut bias_steps = Vec::new();
    let mut with_rise = Vec::new();
    for (axis, ((q, gm), mut ctx)) in qs.into_iter().zip(gms).zip(ctxs).enumerate() {
        ctx.gm = gm;
        ctx.lag_rise_c = rise_c;
        let n_sim = ctx.nuisance.len();
        let (mut fit, mut found) = fit_with_steps(&mut ctx, q);
        // The rise is the unit's, but a lag without it is kept on an accelerometer whose
        // held-out rows it predicts at least as well (a turn-on transient of its own there).
        if rise_c > 0.0 {
            // The same context without the rise (and without the first fit's bias steps).
            ctx.nuisance.truncate(n_sim);
            ctx.lag_rise_c = 0.0;
            let (plain_fit, plain_found) = fit_with_steps(&mut ctx, q);
            if plain_fit.heldout_rms.1 <= fit.heldout_rms.1 {
                (fit, found) = (plain_fit, plain_found);
            } else {
                with_rise.push(prep::AXES[axis]);
            }
        }
        bias_steps.push(found);
        axes.push(fit);
        sensitivity.push(ctx.s.clone());
        nuisance.push(ctx.nuisance_names.clone());
    }
    // The rise is the unit's: the prepared pair carries it for every context built later.
    p.lag_rise_c = rise_c;
    if !with_rise.is_empty() {
        let elsewhere =
            if with_rise.len() < 3 { " (elsewhere the lag without it predicts the held-out rows as well)" } else { "" };
        p.notes.push(format!(
            "REAL's die misses {:.2} °C of its heating at each power-on that SIM's die has at once: a thermal lag acts on `lag(T) − ρ·e^(−P/τ)` on accelerometer {}{elsewhere}",
            rise_c,
            with_rise.join(", ")
        ));
    }
    let located = locate::locate(&p, &axes, false);
    let unexplained_located = locate::locate(&p, &axes, true);
    let input = report::Inputs { sim: sim_name, real: real_name, opt, nuisance: &nuisance };
    let mut report = report::build(&p, &axes, &sensitivity, floor, located, unexplained_located, &input);
    let pr = &p;
    report.steps = bias_steps
        .iter()
        .enumerate()
        .flat_map(|(axis, found)| found.iter().map(move |s| report::StepReport::new(pr, axis, s)))
        .collect();
    let turns = steps::reversals(&p.t, &p.temp_s);
    for (axis, found) in bias_steps.iter().enumerate() {
        let mut located: Vec<(f64, f64)> = found.iter().map(|s| (s.time_s, s.size_g)).collect();
        located.sort_by(|a, b| a.0.total_cmp(&b.0));
        if steps::at_reversals(&located, &turns) {
            report.notes.push(format!(
                "accelerometer {}: the {} bias steps located are each within {:.0} s of a temperature reversal, of one sign at its maxima and the other at its minima: a heating/cooling difference of the bias that switches within a sample at each reversal (a play narrower than the thermometer resolves) shows so; read them together before reading them as steps",
                prep::AXES[axis],
                located.len(),
                steps::REVERSAL_WINDOW_S
            ));
        }
    }
    Ok(Diagnosis { prepared: p, sensitivity, axes, report })
}

/// The residual's white-noise density on accelerometer `axis` \[g²·s\]: the median of its
/// per-row white variance over the static rows `runs` (all rows where there are none), times
/// the row period (a block's mean has the variance of its rows over their number, and lasts
/// their number of rows).
fn white_density(p: &prep::Prepared, runs: &[(usize, usize)], axis: usize) -> f64 {
    let w = &p.r_white[axis];
    let mut v: Vec<f64> = runs.iter().flat_map(|&(a, b)| w[a..b].iter().copied()).filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        v = w.iter().copied().filter(|x| x.is_finite()).collect();
    }
    if v.is_empty() { 0.0 } else { stats::median(&v) * p.dt }
}

/// Selection and fit of one accelerometer with its bias steps ([`steps`]): the selection, the
/// steps located against what it leaves, the selection again with the steps' Heaviside columns
/// in every model (so no mechanism and no drift takes a step's share), until the steps located
/// against the selected model are those in it (at most three rounds). The steps' sizes come from
/// the joint fit with the final model.
fn fit_with_steps(ctx: &mut mech::Context, q: Option<f64>) -> (fit::AxisFit, Vec<steps::BiasStep>) {
    let p = ctx.p;
    let (t, r, y) = (&p.t, &p.r_white[ctx.axis], &p.r[ctx.axis]);
    let n_sim = ctx.nuisance.len();
    let mut rows: Vec<usize> = Vec::new();
    let mut fit = fit::fit_axis(ctx, 3, q);
    let mut found;
    let mut rounds = 0;
    loop {
        let model: Vec<&[f64]> = ctx.nuisance[..n_sim]
            .iter()
            .chain(fit.terms.iter().flat_map(|term| term.columns.iter()))
            .map(Vec::as_slice)
            .collect();
        found = steps::locate(t, r, y, &model, None, fit::ALPHA, 3);
        let now: Vec<usize> = found.iter().map(|s| s.0).collect();
        rounds += 1;
        if now == rows || rounds == 3 {
            if now != rows {
                // Not settled: report the steps the final model carries.
                found = rows.iter().map(|&k| (k, f64::NAN)).collect();
            }
            let sizes = steps::fit_sizes(t, r, y, &model, (fit.q, fit.gm), &found);
            return (fit, sizes);
        }
        rows = now;
        ctx.nuisance.truncate(n_sim);
        ctx.nuisance.extend(rows.iter().map(|&k| steps::heaviside(y.len(), k)));
        fit = fit::fit_axis(ctx, 3, q);
    }
}

/// Reads REAL and diagnoses it against what the calibration `calib` predicts for it
/// ([`follow::predict`]), row by row as REAL is read; the calibration is checked as the
/// firmware checks it.
pub fn diagnose_against_calibration(real: &Path, calib: &Path, opt: &Options) -> Result<Diagnosis, DiagnoseError> {
    check_options(opt)?;
    let (file, _) = crate::calfile::CalibrationFile::read_checked(calib).map_err(|e| DiagnoseError(e.to_string()))?;
    let (params, _) = file.to_params().map_err(|e| DiagnoseError(format!("{}: {e}", calib.display())))?;
    let sim_name = format!("{} (predicted by {})", real.display(), calib.display());
    let p = read_pair(Source::Predicted(&params), real, Path::new(&sim_name), opt.progress, opt.block_s)?;
    diagnose_prepared(p, Path::new(&sim_name), real, opt)
}

/// Reads both recordings in lockstep, row by row (errors name file, line and column), and
/// diagnoses them. Neither recording is held whole: each pair of rows is checked and reduced
/// to what [`prep::Prepared`] keeps as it is read ([`prep::Builder`]).
pub fn diagnose_files(sim: &Path, real: &Path, opt: &Options) -> Result<Diagnosis, DiagnoseError> {
    check_options(opt)?;
    let p = read_pair(Source::File(sim), real, sim, opt.progress, opt.block_s)?;
    diagnose_prepared(p, sim, real, opt)
}

/// The prepared pair of two recordings read in lockstep ([`diagnose_files`] without the
/// diagnosis).
pub fn prepare_files(sim: &Path, real: &Path, progress: bool) -> Result<prep::Prepared, DiagnoseError> {
    read_pair(Source::File(sim), real, sim, progress, None)
}

/// Where SIM's rows come from.
enum Source<'a> {
    /// A recording.
    File(&'a Path),
    /// What a calibration predicts for each row of REAL.
    Predicted(&'a bins_comp::CalibrationParams),
}

/// Opens `path` as a recording whose bytes read are added to `bytes` (the progress bar's
/// position); also returns its size.
fn open_counted(path: &Path, bytes: &Rc<Cell<u64>>) -> Result<(CountedReader, u64), DiagnoseError> {
    crate::progress::open_counted(path, bytes).map_err(|e| DiagnoseError(e.to_string()))
}

/// SIM (from `sim`) and REAL read in lockstep into a [`prep::Builder`]: one row of each in
/// memory at a time. A pair whose row counts differ is refused with both counts (the rest of
/// the longer file is counted, not kept).
fn read_pair(
    sim: Source,
    real: &Path,
    sim_name: &Path,
    progress: bool,
    block_s: Option<f64>,
) -> Result<prep::Prepared, DiagnoseError> {
    let rec = |e: recording::Error| DiagnoseError(e.to_string());
    let bytes = Rc::new(Cell::new(0u64));
    let mut sim_reader = match sim {
        Source::File(path) => Some(open_counted(path, &bytes)?),
        Source::Predicted(_) => None,
    };
    let (mut real_reader, real_size) = open_counted(real, &bytes)?;
    let total = real_size + sim_reader.as_ref().map_or(0, |r| r.1);
    let bar = if progress { indicatif::ProgressBar::new(total) } else { indicatif::ProgressBar::hidden() };
    bar.set_style(
        indicatif::ProgressStyle::with_template("reading {bar:30} {bytes}/{total_bytes}, {elapsed} (eta {eta})")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let mut b = prep::Builder::new(sim_name, real).choose_blocks(block_s);
    let (mut s, mut r) = (Row::default(), Row::default());
    let (mut n_sim, mut n_real) = (0u64, 0u64);
    loop {
        let more_real = real_reader.read_row(&mut r).map_err(rec)?;
        let more_sim = match (&mut sim_reader, &sim) {
            (Some((reader, _)), _) => reader.read_row(&mut s).map_err(rec)?,
            (None, Source::Predicted(params)) => {
                if more_real {
                    follow::predict_into(&r, params, &mut s);
                }
                more_real
            }
            (None, Source::File(_)) => false,
        };
        n_sim += u64::from(more_sim);
        n_real += u64::from(more_real);
        match (more_sim, more_real) {
            (true, true) => b.push(&s, &r)?,
            (false, false) => break,
            _ => {
                // Count what is left of the longer file.
                while more_real && real_reader.read_row(&mut r).map_err(rec)? {
                    n_real += 1;
                }
                if let Some((reader, _)) = &mut sim_reader {
                    while more_sim && reader.read_row(&mut s).map_err(rec)? {
                        n_sim += 1;
                    }
                }
                bar.finish_and_clear();
                return Err(count_mismatch(sim_name, real, n_sim, n_real));
            }
        }
        if n_real.is_multiple_of(65536) {
            bar.set_position(bytes.get());
        }
    }
    bar.finish_and_clear();
    if n_real == 0 {
        return Err(count_mismatch(sim_name, real, n_sim, n_real));
    }
    b.finish()
}

/// The error of a pair whose row counts differ (or are 0), as [`prep::prepare`] words it.
fn count_mismatch(sim_name: &Path, real: &Path, n_sim: u64, n_real: u64) -> DiagnoseError {
    let (sn, rn) = (sim_name.display(), real.display());
    if n_real == 0 || n_sim == 0 {
        let which = if n_real == 0 { &rn } else { &sn };
        return DiagnoseError(format!("{which}: no data rows"));
    }
    DiagnoseError(format!(
        "{rn}: {n_real} data rows but {sn} has {n_sim}: SIM and REAL must be the same test, row for row"
    ))
}
