//! Dwell segments of rig recordings, shared by `calibrate` and `verify`: finding the dwells,
//! their means and stationarity, grouping them by temperature.
//!
//! A segment is a maximal run of consecutive rows with the same `pos` label and the same known
//! reference (fx/fy/fz). Its first `settle_s` seconds (at most a quarter of the run) are
//! dropped as settling margin; the rest is kept if the signals are stationary (standard
//! deviation of every signal at most `max_std_v`) and the temperature settled (its least
//! squares rate at most `max_rate_c_per_min`). Nothing assumes long dwells: a hold of a few
//! seconds at the logger's rate is enough. Kept segments are grouped by temperature: sorted
//! by mean temperature and split where two neighbours differ by more than `temp_tol_c`.

use crate::progress::Pass;
use crate::recording::{Group, Reader, Row, col, names_of};
use anyhow::{anyhow, bail};
use std::path::{Path, PathBuf};

/// How segments are found.
#[derive(Clone, Copy, Debug, clap::Args)]
pub struct Options {
    /// Settling margin dropped at the start of each dwell \[s\] (at most a quarter of the dwell).
    #[arg(long, default_value_t = 1.0, value_parser = crate::numarg::duration_or_zero_s)]
    pub settle_s: f64,
    /// Largest standard deviation of a signal in a stationary dwell \[V\].
    #[arg(long, default_value_t = 0.01, value_parser = crate::numarg::positive)]
    pub max_std_v: f64,
    /// Largest temperature rate in a settled dwell [°C/min].
    #[arg(long, default_value_t = 0.5, value_parser = crate::numarg::positive)]
    pub max_rate_c_per_min: f64,
    /// Dwells whose mean temperatures differ by at most this much form one temperature [°C].
    #[arg(long, default_value_t = 3.0, value_parser = crate::numarg::positive)]
    pub temp_tol_c: f64,
}

/// One dwell.
#[derive(Clone, Debug)]
pub struct Segment {
    /// The recording it comes from.
    pub file: PathBuf,
    /// Its `pos` label.
    pub pos: String,
    /// Reference specific force \[g\].
    pub f_g: [f64; 3],
    /// Time of the first and last row used \[s\].
    pub t_s: (f64, f64),
    /// Rows used (after the settling margin): signals \[V\] and temperature [°C]. Empty for
    /// the static intervals of `calibrate --free`, whose rows are not kept.
    pub rows: Vec<([f64; 3], f64)>,
    /// Number of rows used.
    pub n_rows: usize,
    /// Mean signals \[V\].
    pub mean_u_v: [f64; 3],
    /// Standard deviation of the signals \[V\].
    pub std_u_v: [f64; 3],
    /// Mean temperature [°C].
    pub temp_c: f64,
    /// Temperature rate [°C/min].
    pub rate_c_per_min: f64,
    /// Why it is not used, if it is not.
    pub rejected: Option<String>,
}

struct Run {
    pos: String,
    f_g: [f64; 3],
    rows: Vec<RunRow>,
}

/// One row of a run: `t_s`, `u_v`, `temp_c`.
pub type RunRow = (f64, [f64; 3], f64);

/// The rows of a run after the settling margin (`settle_s`, at most a quarter of the run).
pub fn after_settling(rows: &[RunRow], opt: &Options) -> Vec<RunRow> {
    let (Some(first), Some(last)) = (rows.first(), rows.last()) else { return Vec::new() };
    let margin = opt.settle_s.min(0.25 * (last.0 - first.0));
    rows.iter().filter(|r| r.0 >= first.0 + margin).copied().collect()
}

/// The temperature's least-squares rate over `rows` [°C/min], about their mean time and the
/// mean temperature `temp_c`; 0 when the rows span no time.
pub fn temp_rate_c_per_min(rows: &[RunRow], temp_c: f64) -> f64 {
    let n = rows.len() as f64;
    let t_mean: f64 = rows.iter().map(|r| r.0 / n).sum();
    let (mut stt, mut sty) = (0.0, 0.0);
    for (t, _, tc) in rows {
        stt += (t - t_mean).powi(2);
        sty += (t - t_mean) * (tc - temp_c);
    }
    if stt > 0.0 { sty / stt * 60.0 } else { 0.0 }
}

/// Whether a recording says what specific force the unit was held at.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reference {
    /// No `fx_g`, `fy_g`, `fz_g` columns.
    Absent,
    /// The columns are there, every row's cells are empty.
    Empty,
    /// This many rows have a reference.
    Rows(usize),
}

/// The columns of the specific force the dwells are labelled with.
pub const FORCE: [&str; 3] = [col::FX_G, col::FY_G, col::FZ_G];

/// The reference columns of the format a recording's header lacks (the vibration's, say: a
/// tilter's dwells need only [`FORCE`]). Errors name the file.
pub fn missing_reference_columns(path: &Path) -> anyhow::Result<Vec<&'static str>> {
    let reader = Reader::open(path).map_err(|e| anyhow!("{e}"))?;
    Ok(names_of(Group::Reference).filter(|c| !reader.has_column(c)).collect())
}

/// The [`Reference`] of a recording: its specific force `fx_g`, `fy_g`, `fz_g` (the
/// vibration columns are not needed for a dwell's reference). Reads it through (a progress
/// bar on standard error); errors name the file.
pub fn reference(path: &Path) -> anyhow::Result<Reference> {
    let mut reader = Pass::open(path, "reference").map_err(|e| anyhow!("{e}"))?;
    if !FORCE.iter().all(|c| reader.has_column(c)) {
        return Ok(Reference::Absent);
    }
    let mut row = Row::default();
    let mut n = 0;
    while reader.read_row(&mut row).map_err(|e| anyhow!("{e}"))? {
        n += usize::from(row.reference_f_g().is_some());
    }
    Ok(if n == 0 { Reference::Empty } else { Reference::Rows(n) })
}

/// All dwells of a recording (kept and rejected), in one pass with a progress bar on standard
/// error; the rows of the labelled runs are held, not the others. Errors name the file:
/// unreadable, no `pos` column, no specific-force columns (named), no row with a known
/// reference and a position label. The vibration columns are not needed.
pub fn find(path: &Path, opt: &Options) -> anyhow::Result<Vec<Segment>> {
    let mut reader = Pass::open(path, "dwells").map_err(|e| anyhow!("{e}"))?;
    if !reader.has_column("pos") {
        bail!("{}: missing column `pos` (the rig position label): cannot find the dwells", path.display());
    }
    let missing: Vec<&str> = FORCE.iter().copied().filter(|c| !reader.has_column(c)).collect();
    if !missing.is_empty() {
        bail!(
            "{}: missing reference column(s) `{}` in the header: the dwells' specific force is not known (calibrate --free finds static intervals without it)",
            path.display(),
            missing.join("`, `")
        );
    }
    let mut runs: Vec<Run> = Vec::new();
    let mut cur: Option<Run> = None;
    let mut row = Row::default();
    let mut n_reference = 0usize;
    while reader.read_row(&mut row).map_err(|e| anyhow!("{e}"))? {
        n_reference += usize::from(row.reference_f_g().is_some());
        let key = match (&row.pos, row.reference_f_g()) {
            (Some(p), Some(f)) if !p.is_empty() => Some((p.as_str(), f)),
            _ => None,
        };
        match key {
            Some((p, f)) => {
                let same = cur.as_ref().is_some_and(|r| r.pos == p && r.f_g == f);
                if !same {
                    runs.extend(cur.take());
                    cur = Some(Run { pos: p.to_string(), f_g: f, rows: Vec::new() });
                }
                if let Some(r) = cur.as_mut() {
                    r.rows.push((row.t_s, row.u_v, row.temp_c));
                }
            }
            None => runs.extend(cur.take()),
        }
    }
    runs.extend(cur.take());
    if runs.is_empty() {
        if n_reference == 0 {
            bail!(
                "{}: the reference columns `fx_g`, `fy_g`, `fz_g` are present but empty in every row: the dwells' specific force is not known (calibrate --free finds static intervals without it)",
                path.display()
            );
        }
        bail!(
            "{}: no row with both a `pos` label and a known reference (fx_g, fy_g, fz_g): {n_reference} row(s) have a reference, none a `pos` label",
            path.display()
        );
    }
    Ok(runs.into_iter().map(|r| segment(path, r, opt)).collect())
}

fn segment(path: &Path, run: Run, opt: &Options) -> Segment {
    let (t_first, t_last) = (run.rows[0].0, run.rows[run.rows.len() - 1].0);
    let rows = after_settling(&run.rows, opt);
    let n = rows.len() as f64;
    let mut mean = [0.0; 3];
    let mut temp = 0.0;
    for (_, u, tc) in &rows {
        for i in 0..3 {
            mean[i] += u[i] / n;
        }
        temp += tc / n;
    }
    let mut var = [0.0; 3];
    for (_, u, _) in &rows {
        for i in 0..3 {
            var[i] += (u[i] - mean[i]).powi(2) / n;
        }
    }
    let std = var.map(f64::sqrt);
    let rate = temp_rate_c_per_min(&rows, temp);
    let rejected = if rows.len() < 3 {
        Some(format!("only {} rows after the settling margin", rows.len()))
    } else if std.iter().any(|s| !(*s <= opt.max_std_v)) {
        Some(format!(
            "not stationary (signal std {:.2e} V > {:.1e} V)",
            std.iter().fold(0.0f64, |a, b| a.max(*b)),
            opt.max_std_v
        ))
    } else if !(rate.abs() <= opt.max_rate_c_per_min) {
        Some(format!("temperature not settled ({rate:+.2} °C/min)"))
    } else {
        None
    };
    Segment {
        file: path.to_path_buf(),
        pos: run.pos,
        f_g: run.f_g,
        t_s: (rows.first().map_or(t_first, |r| r.0), rows.last().map_or(t_last, |r| r.0)),
        rows: rows.iter().map(|r| (r.1, r.2)).collect(),
        n_rows: rows.len(),
        mean_u_v: mean,
        std_u_v: std,
        temp_c: temp,
        rate_c_per_min: rate,
        rejected,
    }
}

/// The kept segments grouped by temperature, coldest first: (mean temperature, segments).
pub fn by_temperature(segments: &[Segment], tol_c: f64) -> Vec<(f64, Vec<&Segment>)> {
    let mut kept: Vec<&Segment> = segments.iter().filter(|s| s.rejected.is_none()).collect();
    kept.sort_by(|a, b| a.temp_c.total_cmp(&b.temp_c));
    let mut groups: Vec<Vec<&Segment>> = Vec::new();
    for s in kept {
        match groups.last_mut() {
            Some(g) if s.temp_c - g[g.len() - 1].temp_c <= tol_c => g.push(s),
            _ => groups.push(vec![s]),
        }
    }
    groups
        .into_iter()
        .map(|mut g| {
            g.sort_by(|a, b| a.pos.cmp(&b.pos).then(a.t_s.0.total_cmp(&b.t_s.0)));
            let t = g.iter().map(|s| s.temp_c).sum::<f64>() / g.len() as f64;
            ((t * 100.0).round() / 100.0, g)
        })
        .collect()
}

/// All segments of several recordings; the names of the files for messages.
pub fn find_all(paths: &[PathBuf], opt: &Options) -> anyhow::Result<(Vec<Segment>, String)> {
    let mut all = Vec::new();
    for p in paths {
        all.extend(find(p, opt)?);
    }
    let names = paths.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ");
    Ok((all, names))
}
