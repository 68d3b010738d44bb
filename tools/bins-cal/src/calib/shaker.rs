//! The shake-table path of `bins-cal calibrate --shaker`: the vibration-error coefficients
//! from shake-table recordings (physics §8), with the core's identification
//! ([`bins_comp::vibration::shake`]). Owns the holds (finding, sine-free means, pairing) and
//! the per-accelerometer fits; the command prints what [`identify`] returns.
//!
//! 1. Holds: maximal runs of rows with the same `pos`, static force (fx/fy/fz) and vibration
//!    (`vib_kind`, `vib_*_g`, `vib_hz`, `vib_bw_hz`); the first `settle_s` seconds (at most a
//!    quarter) are dropped. A quiet hold (`vib_kind = none`) is the static reference; a
//!    shaking hold (`sine`, `random`) is paired with the quiet hold at the same position and
//!    force nearest in time, and `ΔU = ⟨U^B⟩ − U`, V(20).
//! 2. Means: the logger's sample is the mean over its period, so a sine still shows in the
//!    samples (its linear response, `K·ã̄`). A sine hold's mean is therefore the constant of a
//!    least squares fit of `[1, cos 2πft, sin 2πft]` at the rig's `vib_hz` (exact for any
//!    sample rate, also an aliased frequency), not the plain mean, which keeps up to
//!    `2a/(ωT)` of the sine. Quiet and random holds use the plain mean. Standard errors are
//!    those of white noise: the residual σ over √n.
//! 3. Per accelerometer (x, y, z: IA/PA/OA by `AccelAxes::from_unit`) the shaking holds whose
//!    vibration has an IA component give positions `(a_p3, amplitudes on IA/PA/OA, ΔU_i)`.
//!    An accelerometer is identified when its sine positions cover at least four distinct
//!    static IA accelerations (a plan): per sine level V(21)/V(22) (`fit_ve_terms`), over
//!    every sine level the conversion function's δ_1A, k2…k5, m31, m32
//!    (`fit_conversion_function`, at least two levels), with the standard error of each
//!    coefficient from the design matrix and the residual σ. Random holds are not fitted (the
//!    fit's columns are harmonic); the identified function's prediction is printed beside
//!    their measured ΔU and its standard error.
//!
//! `ΔU` is divided by the accelerometer's scale factor `K_ii` at the hold's temperature from
//! the tilter calibration.

use super::segments::{Options, RunRow, after_settling, temp_rate_c_per_min};
use crate::recording::{Reader, Row, col};
use anyhow::{anyhow, bail};
use bins_comp::vibration::shake::{
    CfFit, ShakePosition, VeTermsFit, VibFitError, fit_conversion_function, fit_ve_terms,
};
use bins_comp::vibration::{
    AccelAxes, AccelVibration, Axis, ConversionFunction, VibMoments, exact_terms, harmonic_abs_excess_g, ve_terms,
};
use bins_comp::{Constants, Variant, Vibration, VibrationParams};
use std::path::{Path, PathBuf};

/// A shaking hold's IA amplitude below this \[g\] counts as "no IA vibration".
const MIN_IA_LEVEL_G: f64 = 1e-9;
/// Sine levels within this fraction of each other form one level.
const LEVEL_TOL: f64 = 0.01;

/// One hold of a shake-table recording.
#[derive(Clone, Debug)]
pub struct Hold {
    /// The recording.
    pub file: PathBuf,
    /// `pos` label.
    pub pos: String,
    /// Static specific force \[g\].
    pub f_g: [f64; 3],
    /// The vibration the rig applied.
    pub vib: Vibration<f64>,
    /// First and last time used \[s\].
    pub t_s: (f64, f64),
    /// Rows used.
    pub n: usize,
    /// Mean signals \[V\] (sine removed for a sine hold).
    pub mean_u_v: [f64; 3],
    /// Standard error of the mean \[V\].
    pub se_u_v: [f64; 3],
    /// Standard deviation of the signals about the mean (about the fitted sine) \[V\].
    pub std_u_v: [f64; 3],
    /// Mean temperature [°C].
    pub temp_c: f64,
    /// Why it is not used.
    pub rejected: Option<String>,
    /// For a shaking hold paired with its quiet hold: `ΔU` \[V\].
    pub du_v: Option<[f64; 3]>,
}

impl Hold {
    /// True for a shaking hold (`vib_kind` sine or random).
    pub fn shaking(&self) -> bool {
        !matches!(self.vib, Vibration::None)
    }
}

struct Run {
    pos: String,
    f_g: [f64; 3],
    vib: Vibration<f64>,
    rows: Vec<RunRow>,
}

/// Every hold of a recording. Errors name the file and the missing column; a file without
/// any shaking hold is an error.
pub fn find(path: &Path, opt: &Options) -> anyhow::Result<Vec<Hold>> {
    let mut reader = Reader::open(path).map_err(|e| anyhow!("{e}"))?;
    let needed = [
        (col::POS, "the rig position label"),
        (col::FX_G, "the static force"),
        (col::FY_G, "the static force"),
        (col::FZ_G, "the static force"),
        (col::VIB_KIND, "the vibration reference"),
        (col::VIB_X_G, "the vibration reference"),
        (col::VIB_Y_G, "the vibration reference"),
        (col::VIB_Z_G, "the vibration reference"),
        (col::VIB_HZ, "the vibration reference"),
    ];
    for (c, what) in needed {
        if !reader.has_column(c) {
            bail!("{}: missing column `{c}` ({what}): cannot find the shaking holds", path.display());
        }
    }
    let mut runs: Vec<Run> = Vec::new();
    let mut cur: Option<Run> = None;
    let mut row = Row::default();
    while reader.read_row(&mut row).map_err(|e| anyhow!("{e}"))? {
        let key = match (&row.pos, row.reference_f_g(), row.vibration()) {
            (Some(p), Some(f), Some(v)) if !p.is_empty() => Some((p.as_str(), f, v)),
            _ => None,
        };
        match key {
            Some((p, f, v)) => {
                let same = cur.as_ref().is_some_and(|r| r.pos == p && r.f_g == f && r.vib == v);
                if !same {
                    runs.extend(cur.take());
                    cur = Some(Run { pos: p.to_string(), f_g: f, vib: v, rows: Vec::new() });
                }
                if let Some(r) = cur.as_mut() {
                    r.rows.push((row.t_s, row.u_v, row.temp_c));
                }
            }
            None => runs.extend(cur.take()),
        }
    }
    runs.extend(cur.take());
    if !runs.iter().any(|r| !matches!(r.vib, Vibration::None)) {
        bail!(
            "{}: no shaking segment (no row with vib_kind sine or random, a `pos` label and a known static force)",
            path.display()
        );
    }
    Ok(runs.into_iter().map(|r| hold(path, r, opt)).collect())
}

/// Least squares constant of `u ≈ b0 + b1 cos ωt + b2 sin ωt`, and the residual σ. Columns
/// the samples cannot tell from a constant (a frequency aliased to zero) are left out.
fn mean_without_sine(t: &[f64], u: &[f64], freq_hz: f64) -> (f64, f64) {
    let n = t.len() as f64;
    let w = 2.0 * std::f64::consts::PI * freq_hz;
    let t0 = t.first().copied().unwrap_or(0.0);
    let c: Vec<f64> = t.iter().map(|&x| (w * (x - t0)).cos()).collect();
    let s: Vec<f64> = t.iter().map(|&x| (w * (x - t0)).sin()).collect();
    let mean = |v: &[f64]| v.iter().sum::<f64>() / n;
    let (mc, ms, mu) = (mean(&c), mean(&s), mean(u));
    let (mut scc, mut sss, mut scs, mut scu, mut ssu) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for k in 0..t.len() {
        let (dc, ds, du) = (c[k] - mc, s[k] - ms, u[k] - mu);
        scc += dc * dc;
        sss += ds * ds;
        scs += dc * ds;
        scu += dc * du;
        ssu += ds * du;
    }
    let det = scc * sss - scs * scs;
    let tr = scc + sss;
    let (b1, b2) = if tr > 1e-9 * n && det > 1e-9 * tr * tr {
        ((sss * scu - scs * ssu) / det, (scc * ssu - scs * scu) / det)
    } else if scc >= sss && scc > 1e-9 * n {
        (scu / scc, 0.0)
    } else if sss > 1e-9 * n {
        (0.0, ssu / sss)
    } else {
        (0.0, 0.0)
    };
    let b0 = mu - b1 * mc - b2 * ms;
    let ss: f64 = (0..t.len()).map(|k| (u[k] - b0 - b1 * c[k] - b2 * s[k]).powi(2)).sum();
    let dof = (t.len() as f64 - 3.0).max(1.0);
    (b0, (ss / dof).sqrt())
}

fn hold(path: &Path, run: Run, opt: &Options) -> Hold {
    let (t_first, t_last) = (run.rows[0].0, run.rows[run.rows.len() - 1].0);
    let rows = after_settling(&run.rows, opt);
    let n = rows.len();
    let t: Vec<f64> = rows.iter().map(|r| r.0).collect();
    let mut mean = [0.0; 3];
    let mut std = [0.0; 3];
    for i in 0..3 {
        let u: Vec<f64> = rows.iter().map(|r| r.1[i]).collect();
        let (m, s) = match run.vib {
            Vibration::Harmonic { freq_hz, .. } if n >= 4 => mean_without_sine(&t, &u, freq_hz),
            _ => {
                let m = u.iter().sum::<f64>() / n.max(1) as f64;
                let v = u.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n.max(2) - 1) as f64;
                (m, v.sqrt())
            }
        };
        mean[i] = m;
        std[i] = s;
    }
    let temp = rows.iter().map(|r| r.2).sum::<f64>() / n.max(1) as f64;
    let rate = temp_rate_c_per_min(&rows, temp);
    let worst = std.iter().fold(0.0f64, |a, b| a.max(*b));
    let rejected = if n < 4 {
        Some(format!("only {n} rows after the settling margin"))
    } else if !matches!(run.vib, Vibration::Random { .. }) && !(worst <= opt.max_std_v) {
        Some(match run.vib {
            Vibration::None => format!("not stationary (signal std {worst:.2e} V > {:.1e} V)", opt.max_std_v),
            _ => format!("the sine at vib_hz leaves {worst:.2e} V std (> {:.1e} V)", opt.max_std_v),
        })
    } else if !(rate.abs() <= opt.max_rate_c_per_min) {
        Some(format!("temperature not settled ({rate:+.2} °C/min)"))
    } else {
        None
    };
    Hold {
        file: path.to_path_buf(),
        pos: run.pos,
        f_g: run.f_g,
        vib: run.vib,
        t_s: (t.first().copied().unwrap_or(t_first), t.last().copied().unwrap_or(t_last)),
        n,
        mean_u_v: mean,
        se_u_v: std.map(|s| s / (n.max(1) as f64).sqrt()),
        std_u_v: std,
        temp_c: temp,
        rejected,
        du_v: None,
    }
}

/// A shaking hold with its quiet reference.
pub struct Pair<'a> {
    /// The shaking hold.
    pub shake: &'a Hold,
    /// `ΔU` \[V\], V(20).
    pub du_v: [f64; 3],
    /// Its standard error \[V\].
    pub se_du_v: [f64; 3],
}

/// Pairs every usable shaking hold with the quiet hold of the same file, position and force
/// nearest in time; a shaking hold without one is marked rejected.
fn pair(holds: &mut [Hold]) -> Vec<PairIdx> {
    let mut out = Vec::new();
    for k in 0..holds.len() {
        if !holds[k].shaking() || holds[k].rejected.is_some() {
            continue;
        }
        let h = &holds[k];
        let quiet = (0..holds.len())
            .filter(|&j| {
                let q = &holds[j];
                !q.shaking() && q.rejected.is_none() && q.file == h.file && q.pos == h.pos && q.f_g == h.f_g
            })
            .min_by(|&a, &b| {
                let d = |j: usize| (holds[j].t_s.0 - h.t_s.0).abs();
                d(a).total_cmp(&d(b))
            });
        match quiet {
            Some(j) => out.push((k, j)),
            None => holds[k].rejected = Some("no quiet hold (vib_kind none) at this position".into()),
        }
    }
    out
}

/// `none`, `sine` or `random`.
pub fn kind_of(v: &Vibration<f64>) -> &'static str {
    match v {
        Vibration::None => "none",
        Vibration::Harmonic { .. } => "sine",
        Vibration::Random { .. } => "random",
    }
}

/// `x`, `y` or `z`.
pub fn axis_name(i: usize) -> &'static str {
    ["x", "y", "z"][i]
}

/// One accelerometer's position: the core's input and where it came from.
pub struct Position<'a> {
    /// The hold pair.
    pub pair: &'a Pair<'a>,
    /// The core's input.
    pub pos: ShakePosition<f64>,
    /// Standard error of ΔU/K1 \[g\].
    pub se_g: f64,
}

/// The identified VE model of the shaken accelerometers, the notes for the file header.
pub struct ShakerResult {
    /// Conversion functions (unidentified accelerometers zero) and the variant.
    pub params: VibrationParams,
    /// Notes for the calibration file's header.
    pub notes: Vec<String>,
}

/// The columns of `fit_conversion_function` at one position (δ_1A, k2…k5, m31, m32): each
/// coefficient's exact harmonic VE with the others zero.
fn cf_columns(p: &ShakePosition<f64>) -> [f64; 7] {
    let m = VibMoments::harmonic(p.amp_g);
    let abs = harmonic_abs_excess_g(p.a_p3_g, p.amp_g.ia);
    let mut out = [0.0; 7];
    for (o, idx) in out.iter_mut().zip([1usize, 2, 3, 4, 5, 8, 9]) {
        let mut unit = [0.0; 10];
        unit[idx] = 1.0;
        *o = exact_terms(&ConversionFunction::from_array(&unit), &m, abs).total_g(p.a_p3_g);
    }
    out
}

/// Standard errors of the least squares coefficients: `σ·√diag((JᵀJ)⁻¹)` over the active
/// columns, by Gauss–Jordan on the column-scaled normal matrix (7×7, host only).
pub fn standard_errors(rows: &[[f64; 7]], active: &[bool; 7], sigma: f64) -> [f64; 7] {
    let idx: Vec<usize> = (0..7).filter(|&j| active[j]).collect();
    let m = idx.len();
    let scale: Vec<f64> =
        idx.iter().map(|&j| rows.iter().map(|r| r[j].abs()).fold(0.0, f64::max).max(f64::MIN_POSITIVE)).collect();
    let mut a = vec![vec![0.0; 2 * m]; m];
    for r in rows {
        for (p, &jp) in idx.iter().enumerate() {
            for (q, &jq) in idx.iter().enumerate() {
                a[p][q] += r[jp] / scale[p] * r[jq] / scale[q];
            }
        }
    }
    for (p, row) in a.iter_mut().enumerate() {
        row[m + p] = 1.0;
    }
    for c in 0..m {
        let piv = (c..m).max_by(|&x, &y| a[x][c].abs().total_cmp(&a[y][c].abs())).unwrap_or(c);
        a.swap(c, piv);
        let d = a[c][c];
        if d.abs() < 1e-300 {
            return [f64::NAN; 7];
        }
        for v in a[c].iter_mut() {
            *v /= d;
        }
        for r in 0..m {
            if r != c {
                let f = a[r][c];
                if f != 0.0 {
                    let pivot_row = a[c].clone();
                    for (v, pv) in a[r].iter_mut().zip(pivot_row) {
                        *v -= f * pv;
                    }
                }
            }
        }
    }
    let mut out = [0.0; 7];
    for (p, &j) in idx.iter().enumerate() {
        out[j] = sigma * a[p][m + p].max(0.0).sqrt() / scale[p];
    }
    out
}

/// Names of δ_1A, k2…k5, m31, m32 (file keys).
pub const CF_NAMES: [&str; 7] =
    ["delta_1a", "k2_g_per_g2", "k3_g_per_g3", "k4_g_per_g4", "k5_g_per_g5", "m31_g_per_g2", "m32_g_per_g2"];

/// δ_1A, k2…k5, m31, m32 of a conversion function.
pub fn cf_values(cf: &ConversionFunction<f64>) -> [f64; 7] {
    [cf.delta_1a, cf.k2_g_per_g2, cf.k3_g_per_g3, cf.k4_g_per_g4, cf.k5_g_per_g5, cf.m31_g_per_g2, cf.m32_g_per_g2]
}

fn fit_error(files: &str, axis: usize, what: &str, e: VibFitError) -> anyhow::Error {
    let a = axis_name(axis);
    match e {
        VibFitError::Singular => anyhow!(
            "{files}: {a} accelerometer: {what}: the positions do not determine the coefficients (singular fit: too few distinct static accelerations or levels)"
        ),
        VibFitError::TooFewPoints { needed, got } => {
            anyhow!("{files}: {a} accelerometer: {what}: {got} positions, at least {needed} needed")
        }
        e => anyhow!("{files}: {a} accelerometer: {what}: {e}"),
    }
}

/// Indices (shaking hold, its quiet hold) into the holds.
pub type PairIdx = (usize, usize);

/// The holds of the shake-table recordings, every usable shaking hold paired with its quiet
/// hold (`du_v` set), and the pairs (shaking, quiet) as indices into the holds.
pub fn find_holds(paths: &[PathBuf], opt: &Options) -> anyhow::Result<(Vec<Hold>, Vec<PairIdx>)> {
    let mut holds = Vec::new();
    for p in paths {
        holds.extend(find(p, opt)?);
    }
    let pairs_idx = pair(&mut holds);
    for &(k, j) in &pairs_idx {
        let q = holds[j].mean_u_v;
        holds[k].du_v = Some(std::array::from_fn(|i| holds[k].mean_u_v[i] - q[i]));
    }
    Ok((holds, pairs_idx))
}

/// The pairs of [`find_holds`] with `ΔU` and its standard error.
pub fn pairs<'a>(holds: &'a [Hold], pairs_idx: &[PairIdx]) -> Vec<Pair<'a>> {
    pairs_idx
        .iter()
        .map(|&(k, j)| {
            let (s, q) = (&holds[k], &holds[j]);
            Pair {
                shake: s,
                du_v: std::array::from_fn(|i| s.mean_u_v[i] - q.mean_u_v[i]),
                se_du_v: std::array::from_fn(|i| s.se_u_v[i].hypot(q.se_u_v[i])),
            }
        })
        .collect()
}

/// V(22) at one sine level.
pub struct LevelFit {
    /// The level (IA amplitude) \[g\].
    pub level_g: f64,
    /// The positions' `pos` labels.
    pub names: Vec<String>,
    /// Number of positions.
    pub n: usize,
    /// The fit and its residual RMS \[g\], or why it failed.
    pub fit: Result<(VeTermsFit<f64>, f64), VibFitError>,
}

/// A random hold: the identified function's prediction beside the measurement.
pub struct RandomCheck {
    /// `pos` label.
    pub pos: String,
    /// σ on IA \[g\].
    pub sigma_g: f64,
    /// Static IA acceleration \[g\].
    pub a_p3_g: f64,
    /// Measured ΔU/K1 \[g\].
    pub meas_g: f64,
    /// Predicted VE (exact variant) \[g\].
    pub pred_g: f64,
    /// Standard error of the measurement \[g\].
    pub se_g: f64,
}

/// The conversion function of one accelerometer over every sine level.
pub struct ConversionFit {
    /// Number of sine positions.
    pub n_positions: usize,
    /// The fit.
    pub fit: CfFit<f64>,
    /// Standard error of δ_1A, k2…k5, m31, m32.
    pub se: [f64; 7],
    /// RMS standard error of the positions' ΔU/K1 \[g\].
    pub noise_g: f64,
    /// The random holds, not fitted.
    pub random: Vec<RandomCheck>,
}

/// One accelerometer shaken on a plan.
pub struct AxisFit {
    /// 0, 1, 2 for x, y, z.
    pub axis: usize,
    /// K_ii at the first sine hold's temperature \[V/g\].
    pub k1_v_per_g: f64,
    /// Number of sine positions.
    pub n_sine: usize,
    /// Number of random positions.
    pub n_random: usize,
    /// The sine levels \[g\], ascending.
    pub levels_g: Vec<f64>,
    /// V(22) per level.
    pub level_fits: Vec<LevelFit>,
    /// The conversion function, or the error that stops the calibration.
    pub conversion: anyhow::Result<ConversionFit>,
}

/// What [`identify`] found, in the order it is printed.
pub struct Identification {
    /// Each accelerometer shaken on a plan.
    pub axes: Vec<AxisFit>,
    /// The accelerometers shaken, but not on a plan: why.
    pub skipped: Vec<String>,
}

/// Identifies the VE of every accelerometer shaken along its input axis on a plan.
/// `constants_at(T)` gives the unit's constants (for `K_ii`) at temperature `T`. Errors name
/// `files` (no usable pair).
pub fn identify(
    pairs: &[Pair<'_>],
    files: &str,
    constants_at: impl Fn(f64) -> Constants<f64>,
) -> anyhow::Result<Identification> {
    if pairs.is_empty() {
        bail!(
            "{files}: no usable shaking segment with a quiet reference hold at the same position (see the table above)"
        );
    }
    let mut axes = Vec::new();
    let mut skipped = Vec::new();
    for (i, axis) in Axis::ALL.into_iter().enumerate() {
        let positions: Vec<Position<'_>> = pairs
            .iter()
            .filter_map(|p| {
                let amp = match p.shake.vib.on_accel(axis) {
                    AccelVibration::Harmonic(a) | AccelVibration::Random(a) => a,
                    AccelVibration::None => return None,
                };
                if !(amp.ia.abs() > MIN_IA_LEVEL_G) {
                    return None;
                }
                // ΔU/K_ii [g] with K_ii at the hold's temperature; the fits then take K1 = 1.
                let k1 = constants_at(p.shake.temp_c).k_v_per_g[i][i];
                let a_p3 = AccelAxes::from_unit(&p.shake.f_g, axis).ia;
                let pos = ShakePosition { a_p3_g: a_p3, amp_g: amp, du_v: p.du_v[i] / k1 };
                Some(Position { pair: p, pos, se_g: p.se_du_v[i] / k1.abs() })
            })
            .collect();
        let sine: Vec<&Position<'_>> =
            positions.iter().filter(|p| matches!(p.pair.shake.vib, Vibration::Harmonic { .. })).collect();
        let mut statics: Vec<f64> = sine.iter().map(|p| p.pos.a_p3_g).collect();
        statics.sort_by(f64::total_cmp);
        statics.dedup_by(|a, b| (*a - *b).abs() < 1e-6);
        if statics.len() < 4 {
            if !positions.is_empty() {
                skipped.push(format!(
                    "{}: {} shaking hold(s) along its input axis at {} distinct static acceleration(s) (sine)",
                    axis_name(i),
                    positions.len(),
                    statics.len()
                ));
            }
            continue;
        }
        let k1 = constants_at(sine[0].pair.shake.temp_c).k_v_per_g[i][i];
        // Sine levels.
        let mut levels: Vec<f64> = Vec::new();
        for p in &sine {
            let a = p.pos.amp_g.ia.abs();
            if !levels.iter().any(|l| (l - a).abs() <= LEVEL_TOL * l) {
                levels.push(a);
            }
        }
        levels.sort_by(f64::total_cmp);
        let level_fits = levels
            .iter()
            .map(|l| {
                let at: Vec<&&Position<'_>> =
                    sine.iter().filter(|p| (p.pos.amp_g.ia.abs() - l).abs() <= LEVEL_TOL * l).collect();
                let ps: Vec<ShakePosition<f64>> = at.iter().map(|p| p.pos).collect();
                let names = at.iter().map(|p| p.pair.shake.pos.clone()).collect();
                let fit = fit_ve_terms(&ps, 1.0).map(|f| {
                    let resid = residual_rms(&ps, |p| f.predict_g(p.a_p3_g, p.amp_g.oa, p.amp_g.pa));
                    (f, resid)
                });
                LevelFit { level_g: *l, names, n: ps.len(), fit }
            })
            .collect();
        let conversion = if levels.len() < 2 {
            Err(anyhow!(
                "{files}: {} accelerometer: sine at one level only ({:.3} g): the conversion-function fit needs at least 2 levels",
                axis_name(i),
                levels[0]
            ))
        } else {
            // The conversion function over every sine level.
            let ps: Vec<ShakePosition<f64>> = sine.iter().map(|p| p.pos).collect();
            fit_conversion_function(&ps, 1.0).map_err(|e| fit_error(files, i, "conversion-function fit", e)).map(
                |fit| {
                    let rows: Vec<[f64; 7]> = ps.iter().map(cf_columns).collect();
                    let se = standard_errors(&rows, &fit.determined, fit.residual_sigma_g);
                    let noise_g = (sine.iter().map(|p| p.se_g * p.se_g).sum::<f64>() / sine.len() as f64).sqrt();
                    // Random holds: the identified function's prediction against the measurement.
                    let random = positions
                        .iter()
                        .filter(|p| matches!(p.pair.shake.vib, Vibration::Random { .. }))
                        .map(|p| RandomCheck {
                            pos: p.pair.shake.pos.clone(),
                            sigma_g: p.pos.amp_g.ia,
                            a_p3_g: p.pos.a_p3_g,
                            meas_g: p.pos.du_v,
                            pred_g: ve_terms(
                                &fit.cf,
                                Variant::Exact,
                                &AccelVibration::Random(p.pos.amp_g),
                                p.pos.a_p3_g,
                            )
                            .total_g(p.pos.a_p3_g),
                            se_g: p.se_g,
                        })
                        .collect();
                    ConversionFit { n_positions: ps.len(), fit, se, noise_g, random }
                },
            )
        };
        let n_random = positions.len() - sine.len();
        axes.push(AxisFit {
            axis: i,
            k1_v_per_g: k1,
            n_sine: sine.len(),
            n_random,
            levels_g: levels,
            level_fits,
            conversion,
        });
    }
    Ok(Identification { axes, skipped })
}

impl Identification {
    /// The VE model and the notes for the file's header; the first accelerometer's error, or
    /// an error when none was identified.
    pub fn into_result(self, files: &str, variant: Variant) -> anyhow::Result<ShakerResult> {
        let mut cf = [ConversionFunction::<f64>::default(); 3];
        let mut identified = [false; 3];
        let mut notes = Vec::new();
        for a in self.axes {
            let c = a.conversion?;
            let i = a.axis;
            for k in 0..7 {
                if !c.fit.determined[k] {
                    notes.push(format!(
                        "{} accelerometer: {} not determined by the shaker positions, written as 0",
                        axis_name(i),
                        CF_NAMES[k]
                    ));
                }
            }
            notes.push(format!(
                "{} accelerometer: conversion function from {} sine positions at levels {} g (residual σ {:.3} µg)",
                axis_name(i),
                c.n_positions,
                a.levels_g.iter().map(|l| format!("{l:.3}")).collect::<Vec<_>>().join(", "),
                c.fit.residual_sigma_g * 1e6
            ));
            cf[i] = c.fit.cf;
            identified[i] = true;
        }
        if !identified.iter().any(|&b| b) {
            bail!(
                "{files}: no accelerometer was shaken along its input axis at 4 or more distinct static accelerations with sine vibration (the shake plan of §8); see the table above"
            );
        }
        let unidentified: Vec<&str> = (0..3).filter(|&i| !identified[i]).map(axis_name).collect();
        if !unidentified.is_empty() {
            notes
                .push(format!("accelerometer(s) {} not shaken: no VE model (coefficients 0)", unidentified.join(", ")));
        }
        Ok(ShakerResult { params: VibrationParams::new(cf, variant), notes })
    }
}

/// RMS of measured ΔU/K1 minus `model` \[g\].
fn residual_rms(ps: &[ShakePosition<f64>], model: impl Fn(&ShakePosition<f64>) -> f64) -> f64 {
    let n = ps.len().max(1) as f64;
    (ps.iter().map(|p| (p.du_v - model(p)).powi(2)).sum::<f64>() / n).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_sine_is_removed_from_the_mean_over_any_number_of_periods() {
        let w = 2.0 * std::f64::consts::PI * 16.0;
        for n in [137usize, 150, 151] {
            let t: Vec<f64> = (0..n).map(|k| 3.0 + k as f64 / 100.0).collect();
            let u: Vec<f64> = t.iter().map(|&x| 0.7 + 6.4 * (w * x + 0.3).sin()).collect();
            let plain = u.iter().sum::<f64>() / n as f64;
            let (m, resid) = mean_without_sine(&t, &u, 16.0);
            assert!((m - 0.7).abs() < 1e-12, "n = {n}: {m}");
            assert!(resid < 1e-12, "n = {n}: {resid}");
            if n == 137 {
                assert!((plain - 0.7).abs() > 1e-3, "the plain mean keeps part of the sine: {plain}");
            }
        }
    }

    #[test]
    fn frequencies_the_samples_cannot_separate_fall_back_to_the_mean() {
        let t: Vec<f64> = (0..200).map(|k| k as f64 / 100.0).collect();
        // At the sample rate the cosine column is constant, at Nyquist the sine column is
        // zero: the constant is still the mean of what remains.
        for f in [100.0, 50.0, 0.0] {
            let u: Vec<f64> = t.iter().enumerate().map(|(k, _)| 0.25 + if k % 2 == 0 { 1e-3 } else { -1e-3 }).collect();
            let (m, _) = mean_without_sine(&t, &u, f);
            assert!(m.is_finite() && (m - 0.25).abs() < 1.1e-3, "f = {f}: {m}");
        }
    }

    #[test]
    fn standard_errors_of_a_straight_line() {
        let x = [-2.0, -1.0, 0.5, 1.0, 3.0];
        let rows: Vec<[f64; 7]> = x.iter().map(|&x| [1.0, x, 0.0, 0.0, 0.0, 0.0, 0.0]).collect();
        let mut active = [false; 7];
        active[0] = true;
        active[1] = true;
        let se = standard_errors(&rows, &active, 2.0);
        let n = x.len() as f64;
        let mx = x.iter().sum::<f64>() / n;
        let sxx: f64 = x.iter().map(|v| (v - mx).powi(2)).sum();
        assert!((se[1] - 2.0 / sxx.sqrt()).abs() < 1e-12, "{se:?}");
        assert!((se[0] - 2.0 * (1.0 / n + mx * mx / sxx).sqrt()).abs() < 1e-12, "{se:?}");
        assert_eq!(&se[2..], &[0.0; 5]);
    }
}
