//! Thermal dynamics from rig recordings with temperature ramps in both directions
//! (`bins-cal calibrate --dynamics identify`): the lag τ of the die behind the thermistor, the
//! play (backlash) width h of the temperature the constants follow, and the additive bias play
//! (width h_b, amplitude per axis), identified jointly with the static temperature model of the
//! 12 constants.
//!
//! The model of the signals, per row of a dwell with known specific force `f`:
//!
//! ```text
//! U_i = Σ_j K_ij(T_e)·f_j + U0_i(T_e) + K_ii·b_i·d,    T_e = play_h(lag_τ(T)),
//! d   = (play_hb(T_e) − T_e)/(h_b/2) ∈ [−1, 1]
//! ```
//!
//! with `K(T)`, `U0(T)` the polynomial T(3) of the requested order about T0 (exactly the form
//! the core evaluates, `CalibrationParams::constants_at`). For fixed (τ, h, h_b) the model is
//! linear in the constants, their temperature coefficients and the amplitudes `b_i`: they are
//! fitted by least squares. The three nonlinear parameters are searched as the diagnosis
//! searches its θ: a log-spaced grid over (τ, h), then h_b, then Nelder–Mead on the logarithms
//! of the non-zero ones together, within the grids' ranges. A component is kept only when dropping it (and re-fitting the rest) raises the
//! residual beyond what the noise allows (`Component::on`); a lag below the resolution of the
//! recording (three sample periods, at least 1 s) is reported as off.
//!
//! Dwells are found as for the static calibration ([`segments`] finds them), but dwells
//! during temperature ramps are used too (they are what tells the dynamics); each dwell is cut
//! into blocks of at most `block_s` whose means enter the fit. The lag and play run over every
//! row of the recording, moves included, so the state at a dwell carries the whole temperature
//! history. The f64 operators are the diagnosis's regressors ([`lagged`], [`play`]); the
//! compensation with the identified dynamics is the core's.

use super::segments::{self, Options};
use crate::diagnose::mech::{lagged, play};
use crate::diagnose::noise::ls_sse;
use crate::recording::{Row, read_all};
use anyhow::{anyhow, bail};
use bins_comp::dynamics::{DynamicsState, Effective, ThermalDynamics};
use bins_comp::temperature::MAX_POLY_ORDER;
use bins_comp::{Calibration, CalibrationParams, CoefDelta, Constants, Method, TempModel};
use std::path::Path;

/// Scale of ΔT in the regressors [°C] (conditioning only).
const DT_SCALE: f64 = 30.0;

/// One recording, every row, with the dwells that enter the fit.
#[derive(Clone, Debug)]
pub struct Series {
    /// The file (for messages).
    pub name: String,
    /// `t_s` of every row.
    pub t_s: Vec<f64>,
    /// `temp_C` of every row (the thermistor).
    pub temp_c: Vec<f64>,
    /// Signals of every row \[V\].
    pub u_v: Vec<[f64; 3]>,
    /// The dwells' blocks: row range `[from, to)` and the reference specific force \[g\].
    pub blocks: Vec<(usize, usize, [f64; 3])>,
}

impl Series {
    /// Reads a recording and finds its dwells (labels starting with `pos_prefix`), ramping or
    /// not ([`from_rows`](Self::from_rows)). Errors name the file.
    pub fn read(path: &Path, opt: &Options, pos_prefix: &str, block_s: f64) -> anyhow::Result<Series> {
        let (_, rows) = read_all(path).map_err(|e| anyhow!("{e}"))?;
        Self::from_rows(&path.display().to_string(), &rows, opt, pos_prefix, block_s)
    }

    /// The dwells of `rows`: runs of consecutive rows with the same `pos` label (starting with
    /// `pos_prefix`) and a known specific force, less the settling margin
    /// ([`segments::after_settling`]), kept when every signal's standard deviation is at most
    /// `opt.max_std_v` (the temperature may ramp); blocks of at most `block_s`. Errors name
    /// `name`: a row without a temperature, no dwell.
    pub fn from_rows(
        name: &str,
        rows: &[Row],
        opt: &Options,
        pos_prefix: &str,
        block_s: f64,
    ) -> anyhow::Result<Series> {
        if let Some(r) = rows.iter().find(|r| !r.temp_c.is_finite()) {
            bail!("{name}: line {}: no `temp_C`: the dynamics need the temperature of every row", r.line);
        }
        let t_s: Vec<f64> = rows.iter().map(|r| r.t_s).collect();
        // Runs: (first row, end row, f).
        let mut runs: Vec<(usize, usize, [f64; 3])> = Vec::new();
        let mut k = 0;
        while k < rows.len() {
            let key = |r: &Row| match (&r.pos, r.reference_f_g()) {
                (Some(p), Some(f)) if p.starts_with(pos_prefix) && !p.is_empty() => Some((p.clone(), f)),
                _ => None,
            };
            let Some(first) = key(&rows[k]) else {
                k += 1;
                continue;
            };
            let mut e = k + 1;
            while e < rows.len() && key(&rows[e]).as_ref() == Some(&first) {
                e += 1;
            }
            runs.push((k, e, first.1));
            k = e;
        }
        let mut blocks = Vec::new();
        for (a, b, f) in runs {
            let run: Vec<segments::RunRow> = (a..b).map(|k| (rows[k].t_s, rows[k].u_v, rows[k].temp_c)).collect();
            let kept = segments::after_settling(&run, opt);
            if kept.len() < 3 {
                continue;
            }
            let n = kept.len() as f64;
            let stationary = (0..3).all(|i| {
                let m = kept.iter().map(|r| r.1[i]).sum::<f64>() / n;
                (kept.iter().map(|r| (r.1[i] - m).powi(2)).sum::<f64>() / n).sqrt() <= opt.max_std_v
            });
            if !stationary {
                continue;
            }
            let a = a + (run.len() - kept.len());
            let mut k = a;
            while k < b {
                let mut e = k + 1;
                while e < b && t_s[e] - t_s[k] < block_s {
                    e += 1;
                }
                blocks.push((k, e, f));
                k = e;
            }
        }
        if blocks.is_empty() {
            bail!(
                "{name}: no stationary dwell labelled `{pos_prefix}…` with a known specific force (signal std ≤ {} V)",
                opt.max_std_v
            );
        }
        Ok(Series {
            name: name.to_string(),
            t_s,
            temp_c: rows.iter().map(|r| r.temp_c).collect(),
            u_v: rows.iter().map(|r| r.u_v).collect(),
            blocks,
        })
    }

    /// The series keeping only the blocks whose rows lie in `[from_s, to_s)` (the rows
    /// themselves stay: the dynamics run over the whole history).
    pub fn window(&self, from_s: f64, to_s: f64) -> Series {
        self.keep(|a, b| a >= from_s && b < to_s)
    }

    /// The series keeping only the blocks for which `keep(first t_s, last t_s)` holds (the rows
    /// stay).
    pub fn keep(&self, keep: impl Fn(f64, f64) -> bool) -> Series {
        let mut s = self.clone();
        s.blocks.retain(|b| keep(self.t_s[b.0], self.t_s[b.1 - 1]));
        s
    }

    /// Duration \[s\].
    pub fn duration_s(&self) -> f64 {
        self.t_s.last().copied().unwrap_or(0.0) - self.t_s.first().copied().unwrap_or(0.0)
    }

    /// The median sample period \[s\].
    pub fn dt_s(&self) -> f64 {
        let mut d: Vec<f64> = self.t_s.windows(2).map(|w| w[1] - w[0]).collect();
        if d.is_empty() {
            return 0.0;
        }
        let m = d.len() / 2;
        *d.select_nth_unstable_by(m, f64::total_cmp).1
    }
}

/// The nonlinear parameters of the dynamics (0 = off).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Theta {
    /// Lag of the die behind the thermistor \[s\].
    pub lag_tau_s: f64,
    /// Play width of the temperature the constants follow [°C].
    pub hysteresis_width_c: f64,
    /// Play width of the additive bias [°C].
    pub bias_play_width_c: f64,
}

/// The effective temperature and the bias play's output `d` of every row of `s` under `th`
/// (the diagnosis's f64 operators: the identification's regressors).
pub fn effective(s: &Series, th: &Theta) -> (Vec<f64>, Vec<f64>) {
    let lag = if th.lag_tau_s > 0.0 { lagged(&s.t_s, &s.temp_c, th.lag_tau_s) } else { s.temp_c.clone() };
    let te = if th.hysteresis_width_c > 0.0 { play(&lag, th.hysteresis_width_c) } else { lag };
    let d = if th.bias_play_width_c > 0.0 {
        let hb = th.bias_play_width_c;
        play(&te, hb).iter().zip(&te).map(|(p, t)| (p - t) / (0.5 * hb)).collect()
    } else {
        vec![0.0; te.len()]
    };
    (te, d)
}

/// What the fit is asked for.
#[derive(Clone, Debug)]
pub struct Request {
    /// Polynomial order of the temperature model (1..=4).
    pub order: usize,
    /// T0 of the model [°C].
    pub t0_c: f64,
    /// K at T0 [V/g] for the columns the data cannot determine (an `f_j` that never changes:
    /// one orientation); its temperature coefficients are then zero.
    pub k_prior: [[f64; 3]; 3],
    /// The compensation method written with the model.
    pub method: Method,
}

/// The linear fit at one θ.
#[derive(Clone, Debug)]
pub struct JointFit {
    /// The dynamics it was fitted at.
    pub theta: Theta,
    /// The constants and their temperature model (method and range from the request and data).
    pub params: CalibrationParams,
    /// Additive bias play amplitude per axis \[g\] (0 without a bias play).
    pub bias_play_g: [f64; 3],
    /// Residual sum of squares per axis over the blocks \[g²\].
    pub sse_g2: [f64; 3],
    /// Blocks fitted.
    pub n_blocks: usize,
    /// Linear parameters per axis.
    pub n_params: usize,
}

impl JointFit {
    /// RMS residual of the block means per axis \[g\].
    pub fn rms_g(&self) -> [f64; 3] {
        self.sse_g2.map(|s| (s / self.n_blocks.max(1) as f64).sqrt())
    }

    /// The objective: the total residual \[g²\].
    pub fn sse(&self) -> f64 {
        self.sse_g2.iter().sum()
    }
}

/// Which `f_j` vary over the blocks (their K columns can be fitted).
fn varying(series: &[Series]) -> [bool; 3] {
    let mut first: Option<[f64; 3]> = None;
    let mut v = [false; 3];
    for s in series {
        for b in &s.blocks {
            let f0 = *first.get_or_insert(b.2);
            for j in 0..3 {
                v[j] |= (b.2[j] - f0[j]).abs() > 1e-6;
            }
        }
    }
    v
}

/// The least-squares fit of the constants and their temperature model at `th`. `scale_v_per_g`
/// converts each axis's residual to g (K_ii). Errors: too few blocks for the parameters.
pub fn fit_at(series: &[Series], th: &Theta, req: &Request, scale_v_per_g: [f64; 3]) -> anyhow::Result<JointFit> {
    let order = req.order;
    if !(1..=MAX_POLY_ORDER).contains(&order) {
        bail!("the polynomial order must be 1 to {MAX_POLY_ORDER}, got {order}");
    }
    let var = varying(series);
    let nf = var.iter().filter(|v| **v).count();
    let with_bias = th.bias_play_width_c > 0.0;
    let n_params = (order + 1) * (1 + nf) + usize::from(with_bias);
    let n_blocks: usize = series.iter().map(|s| s.blocks.len()).sum();
    if n_blocks < n_params + 2 {
        bail!(
            "{} block(s) of dwells for {n_params} parameters per axis: record more dwells (ramping or not)",
            n_blocks
        );
    }
    // Block means: ΔT^p (scaled), d, U.
    let mut cols_base: Vec<Vec<f64>> = vec![Vec::with_capacity(n_blocks); order + 1];
    let mut dcol = Vec::with_capacity(n_blocks);
    let mut fblk: Vec<[f64; 3]> = Vec::with_capacity(n_blocks);
    let mut ublk: Vec<[f64; 3]> = Vec::with_capacity(n_blocks);
    let (mut tmin, mut tmax) = (req.t0_c, req.t0_c);
    for s in series {
        let (te, d) = effective(s, th);
        for &(a, b, f) in &s.blocks {
            let n = (b - a) as f64;
            let mut pw = vec![0.0; order + 1];
            let (mut dm, mut um) = (0.0, [0.0; 3]);
            for k in a..b {
                tmin = tmin.min(te[k]);
                tmax = tmax.max(te[k]);
                let x = (te[k] - req.t0_c) / DT_SCALE;
                let mut xp = 1.0;
                for p in pw.iter_mut() {
                    *p += xp / n;
                    xp *= x;
                }
                dm += d[k] / n;
                for i in 0..3 {
                    um[i] += s.u_v[k][i] / n;
                }
            }
            for (c, p) in cols_base.iter_mut().zip(&pw) {
                c.push(*p);
            }
            dcol.push(dm);
            fblk.push(f);
            ublk.push(um);
        }
    }
    let mut k0 = req.k_prior;
    let mut u0 = [0.0; 3];
    let mut coef = [CoefDelta::<f64>::zero(); MAX_POLY_ORDER];
    let mut bias_play_g = [0.0; 3];
    let mut sse_g2 = [0.0; 3];
    for i in 0..3 {
        // Columns: ΔT^p, then ΔT^p·f_j for each varying j, then d.
        let mut cols: Vec<Vec<f64>> = cols_base.clone();
        let mut tags: Vec<(usize, Option<usize>)> = (0..=order).map(|p| (p, None)).collect();
        for j in (0..3).filter(|&j| var[j]) {
            for p in 0..=order {
                cols.push(cols_base[p].iter().zip(&fblk).map(|(x, f)| x * f[j]).collect());
                tags.push((p, Some(j)));
            }
        }
        if with_bias {
            cols.push(dcol.clone());
        }
        // The fixed columns' part of the signal.
        let y: Vec<f64> = ublk
            .iter()
            .zip(&fblk)
            .map(|(u, f)| u[i] - (0..3).filter(|&j| !var[j]).map(|j| req.k_prior[i][j] * f[j]).sum::<f64>())
            .collect();
        let (sse, beta) = ls_sse(&y, &cols);
        sse_g2[i] = sse / scale_v_per_g[i].powi(2);
        let mut kp = [[0.0; 3]; MAX_POLY_ORDER + 1];
        for (b, (p, j)) in beta.iter().zip(&tags) {
            let v = b / DT_SCALE.powi(*p as i32);
            match j {
                None if *p == 0 => u0[i] = v,
                None => coef[p - 1].du0_v[i] = v,
                Some(j) => kp[*p][*j] = v,
            }
        }
        for j in (0..3).filter(|&j| var[j]) {
            k0[i][j] = kp[0][j];
        }
        for j in (0..3).filter(|&j| var[j]) {
            for p in 1..=order {
                coef[p - 1].rel_k[i][j] = if k0[i][j] != 0.0 { kp[p][j] / k0[i][j] } else { 0.0 };
            }
        }
        if with_bias {
            bias_play_g[i] = beta.last().copied().unwrap_or(0.0) / k0[i][i];
        }
    }
    let params = CalibrationParams {
        constants: Constants { k_v_per_g: k0, u0_v: u0 },
        t0_c: req.t0_c,
        model: TempModel::Poly { order: order as u8, coef },
        method: req.method,
        temp_range_c: ((tmin - 1.0).floor(), (tmax + 1.0).ceil()),
    };
    Ok(JointFit { theta: *th, params, bias_play_g, sse_g2, n_blocks, n_params })
}

/// One identified component of the dynamics.
#[derive(Clone, Debug, PartialEq)]
pub struct Component {
    /// `lag`, `hysteresis` or `bias_play`.
    pub name: &'static str,
    /// Its best value (τ \[s\] or width [°C]).
    pub value: f64,
    /// Residual with it dropped and the rest re-fitted, relative to the full model's: `SSE₀/SSE − 1`.
    pub gain: f64,
    /// Whether it is kept.
    pub on: bool,
    /// Why it is off, when it is.
    pub why_off: Option<String>,
}

/// The result of [`identify`].
#[derive(Clone, Debug)]
pub struct Identification {
    /// The joint fit with the kept components.
    pub fit: JointFit,
    /// The joint fit of the same order without dynamics (same blocks).
    pub static_fit: JointFit,
    /// Lag, hysteresis, bias play: their best values and whether kept.
    pub components: Vec<Component>,
    /// The lag resolution of the recordings \[s\] (a τ below it is off).
    pub lag_resolution_s: f64,
    /// Objective evaluations of the search.
    pub evaluations: usize,
}

impl Identification {
    /// The identified dynamics as the core's parameters (self-heating 0: a tilter recording has
    /// no power-on to identify it from; the bias play only with its play).
    pub fn dynamics(&self) -> ThermalDynamics<f64> {
        let th = self.fit.theta;
        ThermalDynamics {
            lag_tau_s: th.lag_tau_s,
            hysteresis_width_c: th.hysteresis_width_c,
            self_heating_c: 0.0,
            self_heating_tau_s: 0.0,
            bias_play_width_c: th.bias_play_width_c,
            bias_play_g: if th.bias_play_width_c > 0.0 { self.fit.bias_play_g } else { [0.0; 3] },
        }
    }
}

/// A component is kept when dropping it raises the residual by more than this fraction …
pub const MIN_GAIN: f64 = 0.05;
/// … and by more than this many times the residual variance per block (the block means are
/// correlated in time by drift, so the bar is far above a white-noise F test's).
pub const MIN_DELTA_PER_SIGMA2: f64 = 30.0;

fn log_grid(lo: f64, hi: f64, per_decade: f64) -> Vec<f64> {
    if !(hi > lo && lo > 0.0) {
        return Vec::new();
    }
    let n = ((hi / lo).log10() * per_decade).ceil().max(1.0) as usize;
    (0..=n).map(|k| lo * (hi / lo).powf(k as f64 / n as f64)).collect()
}

/// Parameter `k` of θ: 0 lag, 1 hysteresis, 2 bias play width.
fn get(th: &Theta, k: usize) -> f64 {
    match k {
        0 => th.lag_tau_s,
        1 => th.hysteresis_width_c,
        _ => th.bias_play_width_c,
    }
}

fn set(th: &mut Theta, k: usize, v: f64) {
    match k {
        0 => th.lag_tau_s = v,
        1 => th.hysteresis_width_c = v,
        _ => th.bias_play_width_c = v,
    }
}

/// Nelder–Mead minimum of `f` from `x0` with initial steps `step`, at most `max_evals`
/// evaluations, stopping when the simplex's values agree within `ftol` (relative).
fn nelder_mead(x0: &[f64], step: f64, max_evals: usize, ftol: f64, f: &dyn Fn(&[f64]) -> f64) -> (Vec<f64>, f64) {
    let n = x0.len();
    let mut pts: Vec<(Vec<f64>, f64)> = Vec::with_capacity(n + 1);
    pts.push((x0.to_vec(), f(x0)));
    for k in 0..n {
        let mut x = x0.to_vec();
        x[k] += step;
        let v = f(&x);
        pts.push((x, v));
    }
    let mut evals = n + 1;
    while evals < max_evals {
        pts.sort_by(|a, b| a.1.total_cmp(&b.1));
        let (lo, hi) = (pts[0].1, pts[n].1);
        if (hi - lo).abs() <= ftol * lo.abs().max(1e-300) {
            break;
        }
        let centroid: Vec<f64> = (0..n).map(|k| pts[..n].iter().map(|p| p.0[k]).sum::<f64>() / n as f64).collect();
        let along = |t: f64| -> Vec<f64> { (0..n).map(|k| centroid[k] + t * (pts[n].0[k] - centroid[k])).collect() };
        let xr = along(-1.0);
        let fr = f(&xr);
        evals += 1;
        if fr < pts[0].1 {
            let xe = along(-2.0);
            let fe = f(&xe);
            evals += 1;
            pts[n] = if fe < fr { (xe, fe) } else { (xr, fr) };
        } else if fr < pts[n - 1].1 {
            pts[n] = (xr, fr);
        } else {
            let xc = if fr < pts[n].1 { along(-0.5) } else { along(0.5) };
            let fc = f(&xc);
            evals += 1;
            if fc < pts[n].1.min(fr) {
                pts[n] = (xc, fc);
            } else {
                // Shrink towards the best.
                let best = pts[0].0.clone();
                for p in pts.iter_mut().skip(1) {
                    p.0 = (0..n).map(|k| best[k] + 0.5 * (p.0[k] - best[k])).collect();
                    p.1 = f(&p.0);
                    evals += 1;
                }
            }
        }
    }
    pts.sort_by(|a, b| a.1.total_cmp(&b.1));
    pts.swap_remove(0)
}

/// Identifies the dynamics and the static model jointly (see the module's text). `progress`
/// receives one line per stage of the search.
pub fn identify(series: &[Series], req: &Request, progress: &mut dyn FnMut(&str)) -> anyhow::Result<Identification> {
    if series.is_empty() {
        bail!("no recording");
    }
    let names = series.iter().map(|s| s.name.clone()).collect::<Vec<_>>().join(", ");
    let n_blocks: usize = series.iter().map(|s| s.blocks.len()).sum();
    if n_blocks == 0 {
        bail!("{names}: no stationary dwell to fit the dynamics to");
    }
    // Axis scales from the static fit.
    let first = fit_at(series, &Theta::default(), req, [1.0; 3]).map_err(|e| anyhow!("{names}: {e}"))?;
    let k = first.params.constants.k_v_per_g;
    let scale = [k[0][0], k[1][1], k[2][2]];
    if scale.iter().any(|s| !(s.abs() > 0.0)) {
        bail!("{names}: a scale factor K_ii is zero: the dwells do not determine the constants");
    }
    let static_fit = fit_at(series, &Theta::default(), req, scale)?;
    let evals = std::cell::Cell::new(1usize);
    let cost = |th: &Theta| -> f64 {
        evals.set(evals.get() + 1);
        fit_at(series, th, req, scale).map_or(f64::INFINITY, |f| f.sse())
    };
    let dur = series.iter().map(Series::duration_s).fold(0.0, f64::max);
    let dt = series.iter().map(Series::dt_s).fold(0.0, f64::max);
    let lag_res = (3.0 * dt).max(1.0);
    let trange = series
        .iter()
        .flat_map(|s| s.temp_c.iter())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &t| (a.min(t), b.max(t)));
    let trange = trange.1 - trange.0;
    let taus: Vec<f64> = std::iter::once(0.0).chain(log_grid(lag_res, (0.25 * dur).max(2.0 * lag_res), 4.0)).collect();
    let widths: Vec<f64> = std::iter::once(0.0).chain(log_grid(0.02, (0.25 * trange).max(0.04), 4.0)).collect();
    // Stage 1: (τ, h) grid.
    let mut best = (Theta::default(), static_fit.sse());
    for &tau in &taus {
        for &h in &widths {
            let th = Theta { lag_tau_s: tau, hysteresis_width_c: h, bias_play_width_c: 0.0 };
            let c = cost(&th);
            if c < best.1 {
                best = (th, c);
            }
        }
    }
    progress(&format!(
        "dynamics: grid over τ ({} values) × h ({} values): τ = {:.1} s, h = {:.3} °C",
        taus.len(),
        widths.len(),
        best.0.lag_tau_s,
        best.0.hysteresis_width_c
    ));
    // Stage 2: h_b grid.
    for &hb in &widths[1..] {
        let th = Theta { bias_play_width_c: hb, ..best.0 };
        let c = cost(&th);
        if c < best.1 {
            best = (th, c);
        }
    }
    progress(&format!(
        "dynamics: grid over h_b ({} values): h_b = {:.3} °C",
        widths.len() - 1,
        best.0.bias_play_width_c
    ));
    // Stage 3: refine the nonzero parameters together (Nelder–Mead on their logarithms): lag
    // and play trade against each other along a valley, which one at a time would not follow.
    let on: Vec<usize> = (0..3).filter(|&k| get(&best.0, k) > 0.0).collect();
    if !on.is_empty() {
        // Within the grids' ranges.
        let bound =
            |k: usize| if k == 0 { (taus[1], taus[taus.len() - 1]) } else { (widths[1], widths[widths.len() - 1]) };
        let f = |x: &[f64]| {
            let mut th = best.0;
            for (v, &k) in x.iter().zip(&on) {
                let (lo, hi) = bound(k);
                if !(v.exp() >= lo && v.exp() <= hi) {
                    return f64::INFINITY;
                }
                set(&mut th, k, v.exp());
            }
            cost(&th)
        };
        let x0: Vec<f64> = on.iter().map(|&k| get(&best.0, k).ln()).collect();
        let (x, c) = nelder_mead(&x0, 0.3, 300, 1e-4, &f);
        if c < best.1 {
            for (v, &k) in x.iter().zip(&on) {
                set(&mut best.0, k, v.exp());
            }
            best.1 = c;
        }
    }
    progress(&format!(
        "dynamics: refined: τ = {:.1} s, h = {:.3} °C, h_b = {:.3} °C",
        best.0.lag_tau_s, best.0.hysteresis_width_c, best.0.bias_play_width_c
    ));
    // Keep or drop each component: drop it, re-fit the rest, compare.
    let full = fit_at(series, &best.0, req, scale)?;
    let sigma2 = full.sse() / ((3 * full.n_blocks).saturating_sub(3 * full.n_params).max(1)) as f64;
    let mut components = Vec::new();
    let mut kept = best.0;
    for (name, value) in
        [("lag", best.0.lag_tau_s), ("hysteresis", best.0.hysteresis_width_c), ("bias_play", best.0.bias_play_width_c)]
    {
        let mut th = best.0;
        match name {
            "lag" => th.lag_tau_s = 0.0,
            "hysteresis" => th.hysteresis_width_c = 0.0,
            _ => th.bias_play_width_c = 0.0,
        }
        let dropped = fit_at(series, &th, req, scale)?.sse();
        let gain = dropped / full.sse().max(1e-300) - 1.0;
        let delta = dropped - full.sse();
        let why_off = if value == 0.0 {
            Some("not found (best at zero)".to_string())
        } else if name == "lag" && value < lag_res {
            Some(format!("τ = {value:.2} s below the resolution {lag_res:.1} s"))
        } else if !(gain > MIN_GAIN && delta > MIN_DELTA_PER_SIGMA2 * sigma2) {
            Some(format!(
                "not significant (residual {:+.1} % without it; {:.1} residual variances)",
                100.0 * gain,
                delta / sigma2
            ))
        } else {
            None
        };
        if why_off.is_some() {
            match name {
                "lag" => kept.lag_tau_s = 0.0,
                "hysteresis" => kept.hysteresis_width_c = 0.0,
                _ => kept.bias_play_width_c = 0.0,
            }
        }
        components.push(Component { name, value, gain, on: why_off.is_none(), why_off });
    }
    let fit = fit_at(series, &kept, req, scale)?;
    Ok(Identification { fit, static_fit, components, lag_resolution_s: lag_res, evaluations: evals.get() })
}

/// The core's thermal dynamics run over a recording's rows (`t_s`, `temp_C`; the time since
/// power-on from `power_s`, else from the first row): the effective temperature and bias-play
/// fraction of every row, as the firmware computes them (in f64).
pub fn run_core(rows: &[crate::recording::Row], d: &ThermalDynamics<f64>) -> Vec<Effective<f64>> {
    let mut st = DynamicsState::new();
    let t_first = rows.first().map_or(0.0, |r| r.t_s);
    let mut prev: Option<f64> = None;
    rows.iter()
        .map(|r| {
            let dt = prev.map_or(0.0, |p| r.t_s - p);
            prev = Some(r.t_s);
            let t_on = r.power_s.unwrap_or(r.t_s - t_first);
            d.step(&mut st, r.temp_c, dt, t_on)
        })
        .collect()
}

/// The compensated acceleration \[g\] of one sample with the thermal dynamics: the core's
/// compensation at the effective temperature, minus the bias play (`bias_play_g·d`).
pub fn compensate(cal: &Calibration<f64>, d: &ThermalDynamics<f64>, u_v: [f64; 3], e: &Effective<f64>) -> [f64; 3] {
    let mut a = cal.compensate(u_v, e.temp_eff_c).accel_g;
    for i in 0..3 {
        a[i] -= d.bias_play_g[i] * e.bias_play;
    }
    a
}
