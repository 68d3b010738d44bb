//! One pass over a recording: every chosen channel's Allan curve, its resolution, the sampling
//! interval and the gaps. Memory is the estimators' (bounded by the τ grid), not the file's.
//!
//! The sampling interval τ₀ is the mean interval between consecutive rows within segments;
//! an interval outside ½ … 1½ of the first one is a gap, and the rows after it start a new
//! segment (the estimators pool segments, [`super::estimate`]). Rows outside the time range
//! (or, with [`Options::held_only`], outside the rig's holds) are read (the file is checked to
//! its end) and left out; a row left out between two kept ones is a gap as well.

use super::estimate::{Config, Estimator};
use super::twin::Resolution;
use super::{Point, points};
use crate::progress::Pass;
use crate::recording::{Row, col};
use anyhow::{anyhow, bail};
use std::path::{Path, PathBuf};

/// The channels a curve can be computed of, with their unit.
pub const CHANNELS: [(&str, &str); 4] = [(col::UX_V, "V"), (col::UY_V, "V"), (col::UZ_V, "V"), (col::TEMP_C, "°C")];

/// What to compute.
#[derive(Clone, Debug)]
pub struct Options {
    /// Channel names (of [`CHANNELS`]).
    pub channels: Vec<String>,
    /// Rows from this time \[s\] (inclusive).
    pub from_s: Option<f64>,
    /// Rows before this time \[s\].
    pub to_s: Option<f64>,
    /// Only the rows whose reference (`fx_g`, `fy_g`, `fz_g`) is known: a rig's holds, each
    /// run of them a segment.
    pub held_only: bool,
    /// The estimator.
    pub config: Config,
    /// Confidence of the intervals (e.g. 0.95).
    pub level: f64,
}

/// One channel's result, in its recording unit.
#[derive(Clone, Debug)]
pub struct Channel {
    /// Column name.
    pub name: String,
    /// Its unit in the recording.
    pub unit: &'static str,
    /// The curve.
    pub points: Vec<Point>,
    /// The step of its values (0: none found).
    pub resolution: f64,
    /// Mean value.
    pub mean: f64,
}

/// The result of a pass.
#[derive(Clone, Debug)]
pub struct Analysis {
    /// The recording.
    pub file: PathBuf,
    /// Rows used.
    pub rows: u64,
    /// Segments (1 + gaps).
    pub segments: u64,
    /// Mean sampling interval within segments \[s\].
    pub tau0_s: f64,
    /// Largest relative deviation of an interval within a segment from τ₀.
    pub jitter: f64,
    /// Time of the first and last row used \[s\].
    pub span_s: (f64, f64),
    /// One per channel, in the order asked.
    pub channels: Vec<Channel>,
}

fn value(row: &Row, c: usize) -> f64 {
    if c < 3 { row.u_v[c] } else { row.temp_c }
}

/// The channel indices of `names` (into [`CHANNELS`]); an unknown name is an error naming the
/// ones accepted.
pub fn channel_indices(names: &[String]) -> anyhow::Result<Vec<usize>> {
    names
        .iter()
        .map(|n| {
            CHANNELS.iter().position(|c| c.0 == n).ok_or_else(|| {
                anyhow!("channel `{n}`: not one of {}", CHANNELS.iter().map(|c| c.0).collect::<Vec<_>>().join(", "))
            })
        })
        .collect()
}

/// Reads `path` once and computes every channel's curve.
pub fn analyse(path: &Path, opt: &Options) -> anyhow::Result<Analysis> {
    let idx = channel_indices(&opt.channels)?;
    if idx.is_empty() {
        bail!("no channel asked");
    }
    let mut pass = Pass::open(path, "allan")?;
    let mut row = Row::default();
    let mut est: Vec<Estimator> = idx.iter().map(|_| Estimator::new(&opt.config)).collect();
    let mut res: Vec<Resolution> = idx.iter().map(|_| Resolution::default()).collect();
    let mut sums = vec![0.0; idx.len()];
    let (from, to) = (opt.from_s.unwrap_or(f64::NEG_INFINITY), opt.to_s.unwrap_or(f64::INFINITY));
    let (mut prev_t, mut dt_ref): (Option<f64>, Option<f64>) = (None, None);
    let (mut dt_sum, mut dt_n, mut dt_min, mut dt_max) = (0.0, 0u64, f64::INFINITY, 0.0f64);
    let (mut rows, mut first_t, mut last_t) = (0u64, f64::NAN, f64::NAN);
    let mut gap = false;
    while pass.read_row(&mut row)? {
        if !(row.t_s >= from && row.t_s < to) || (opt.held_only && row.reference_f_g().is_none()) {
            if prev_t.is_some() && opt.held_only {
                // A row left out between kept ones: the next kept row starts a segment.
                gap = true;
            }
            continue;
        }
        if let Some(p) = prev_t {
            let dt = row.t_s - p;
            if gap {
                gap = false;
                est.iter_mut().for_each(Estimator::end_segment);
                res.iter_mut().for_each(Resolution::end_segment);
            } else if dt_ref.is_some_and(|r| dt > 1.5 * r || dt < 0.5 * r) {
                est.iter_mut().for_each(Estimator::end_segment);
                res.iter_mut().for_each(Resolution::end_segment);
            } else {
                dt_ref.get_or_insert(dt);
                dt_sum += dt;
                dt_n += 1;
                dt_min = dt_min.min(dt);
                dt_max = dt_max.max(dt);
            }
        } else {
            first_t = row.t_s;
        }
        prev_t = Some(row.t_s);
        last_t = row.t_s;
        rows += 1;
        for (k, &c) in idx.iter().enumerate() {
            let v = value(&row, c);
            est[k].push(v);
            res[k].push(v);
            sums[k] += v;
        }
    }
    if dt_n == 0 {
        bail!(
            "{}: fewer than two consecutive rows{} to compute an Allan deviation from",
            path.display(),
            if opt.from_s.is_some() || opt.to_s.is_some() { " in the time range" } else { "" }
        );
    }
    let tau0_s = dt_sum / dt_n as f64;
    let jitter = ((dt_max - tau0_s).max(tau0_s - dt_min)) / tau0_s;
    let mut segments = 0;
    let channels = idx
        .iter()
        .zip(est)
        .zip(res)
        .zip(sums)
        .map(|(((&c, e), r), s)| {
            let (raw, segs) = e.finish();
            segments = segs.values().sum();
            Channel {
                name: CHANNELS[c].0.to_string(),
                unit: CHANNELS[c].1,
                points: points(&raw, &segs, opt.config.kind, tau0_s, opt.level),
                resolution: r.step(),
                mean: s / rows as f64,
            }
        })
        .collect();
    Ok(Analysis { file: path.to_path_buf(), rows, segments, tau0_s, jitter, span_s: (first_t, last_t), channels })
}
