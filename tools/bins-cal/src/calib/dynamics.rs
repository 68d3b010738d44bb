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
//! fitted by least squares (profiled out). The three nonlinear parameters are searched jointly:
//! one log-spaced grid over (τ, h, h_b) with 0 in each, so that every combination of
//! components (lag, play, bias play, on or off) is searched; per combination the best grid
//! points are refined by Nelder–Mead on the logarithms of the non-zero ones ([`Candidate`]).
//! The combination is chosen on held-out prediction: the blocks are grouped into chunks of time
//! held out in turn, and a component is kept only when the prediction of the held-out blocks
//! without it is worse by more than [`MIN_HELDOUT_Z`] standard errors (the scatter of the
//! per-chunk gains, drift included) and by more than [`MIN_HELDOUT_REL`] of the residual. The
//! chosen model then goes through a time-halves check ([`HalvesCheck`]): refitted at its θ on
//! the first half of the recording it predicts the second, and the reverse. The bias play's
//! amplitude is kept only on the axes where it predicts better in both directions (elsewhere
//! the axis is fitted without it, [`fit_at_axes`]), and a lag or play that still leaves an
//! axis predicted worse than by the static model in either direction (beyond
//! [`MIN_HELDOUT_Z`] standard errors) is dropped. The kept parameters get standard errors from
//! the residual's curvature. Without a dwell during a ramp nothing is searched
//! ([`Identification::not_searched`]).
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
use crate::progress::Pass;
use crate::recording::Row;
use anyhow::{anyhow, bail};
use bins_comp::dynamics::{DynamicsState, Effective, ThermalDynamics};
use bins_comp::temperature::MAX_POLY_ORDER;
use bins_comp::{Calibration, CalibrationParams, CoefDelta, Constants, Method, TempModel};
use std::path::Path;

/// Scale of ΔT in the regressors [°C] (conditioning only).
const DT_SCALE: f64 = 30.0;

/// One recording: the time and temperature of every row (what the lag and play run over),
/// and the dwells' blocks that enter the fit with their signals' means. The signals of the
/// rows are not kept: 16 bytes per row of the recording are held.
#[derive(Clone, Debug)]
pub struct Series {
    /// The file (for messages).
    pub name: String,
    /// `t_s` of every row.
    pub t_s: Vec<f64>,
    /// `temp_C` of every row (the thermistor).
    pub temp_c: Vec<f64>,
    /// The dwells' blocks: row range `[from, to)` and the reference specific force \[g\].
    pub blocks: Vec<(usize, usize, [f64; 3])>,
    /// Per block, its signals' mean \[V\] two ways: `[0]` the sum over its rows divided by
    /// their number, `[1]` the sum of each row divided by the number (the two fits' sums).
    pub block_u_v: Vec<[[f64; 3]; 2]>,
    /// A block whose temperature moves faster than this [°C/min] is in a ramp.
    pub max_rate_c_per_min: f64,
}

impl Series {
    /// Reads a recording in one pass (a progress bar on standard error) and finds its dwells
    /// (labels starting with `pos_prefix`), ramping or not ([`from_rows`](Self::from_rows)).
    /// Holds the time and temperature of every row and the rows of the dwell being read.
    /// Errors name the file.
    pub fn read(path: &Path, opt: &Options, pos_prefix: &str, block_s: f64) -> anyhow::Result<Series> {
        let name = path.display().to_string();
        let mut pass = Pass::open(path, "dwells").map_err(|e| anyhow!("{e}"))?;
        let mut b = Builder::new(&name, opt, pos_prefix, block_s);
        let mut row = Row::default();
        while pass.read_row(&mut row).map_err(|e| anyhow!("{e}"))? {
            b.push(&row)?;
        }
        b.finish()
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
        let mut b = Builder::new(name, opt, pos_prefix, block_s);
        for r in rows {
            b.push(r)?;
        }
        b.finish()
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
        let (blocks, means) = self
            .blocks
            .iter()
            .zip(&self.block_u_v)
            .filter(|(b, _)| keep(self.t_s[b.0], self.t_s[b.1 - 1]))
            .map(|(b, m)| (*b, *m))
            .unzip();
        (s.blocks, s.block_u_v) = (blocks, means);
        s
    }

    /// The blocks (of at least 3 rows) whose temperature's least-squares rate exceeds
    /// `max_rate_c_per_min`: dwells during a ramp, which alone tell a lag or a play.
    pub fn ramp_blocks(&self) -> usize {
        self.blocks
            .iter()
            .filter(|&&(a, b, _)| {
                if b - a < 3 {
                    return false;
                }
                let rows: Vec<segments::RunRow> = (a..b).map(|k| (self.t_s[k], [0.0; 3], self.temp_c[k])).collect();
                let mean = self.temp_c[a..b].iter().sum::<f64>() / (b - a) as f64;
                segments::temp_rate_c_per_min(&rows, mean).abs() > self.max_rate_c_per_min
            })
            .count()
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

/// Builds a [`Series`] from rows given one at a time: the current dwell's rows are held until
/// it ends, then cut into blocks whose signal means are kept.
struct Builder<'a> {
    name: &'a str,
    opt: &'a Options,
    pos_prefix: &'a str,
    block_s: f64,
    t_s: Vec<f64>,
    temp_c: Vec<f64>,
    blocks: Vec<(usize, usize, [f64; 3])>,
    block_u_v: Vec<[[f64; 3]; 2]>,
    /// The dwell being read: its label and force, its first row, its rows.
    run: Option<(String, [f64; 3], usize)>,
    run_rows: Vec<segments::RunRow>,
}

impl<'a> Builder<'a> {
    fn new(name: &'a str, opt: &'a Options, pos_prefix: &'a str, block_s: f64) -> Builder<'a> {
        Builder {
            name,
            opt,
            pos_prefix,
            block_s,
            t_s: Vec::new(),
            temp_c: Vec::new(),
            blocks: Vec::new(),
            block_u_v: Vec::new(),
            run: None,
            run_rows: Vec::new(),
        }
    }

    fn push(&mut self, r: &Row) -> anyhow::Result<()> {
        if !r.temp_c.is_finite() {
            bail!("{}: line {}: no `temp_C`: the dynamics need the temperature of every row", self.name, r.line);
        }
        let k = self.t_s.len();
        self.t_s.push(r.t_s);
        self.temp_c.push(r.temp_c);
        let key = match (&r.pos, r.reference_f_g()) {
            (Some(p), Some(f)) if p.starts_with(self.pos_prefix) && !p.is_empty() => Some((p, f)),
            _ => None,
        };
        let same = match (&self.run, key) {
            (Some((p, f, _)), Some((q, g))) => p == q && *f == g,
            _ => false,
        };
        if !same {
            self.close_run();
            if let Some((p, f)) = key {
                self.run = Some((p.clone(), f, k));
            }
        }
        if self.run.is_some() {
            self.run_rows.push((r.t_s, r.u_v, r.temp_c));
        }
        Ok(())
    }

    /// The dwell read so far, less its settling margin, cut into blocks if stationary.
    fn close_run(&mut self) {
        let Some((_, f, a)) = self.run.take() else { return };
        let run = std::mem::take(&mut self.run_rows);
        let b = a + run.len();
        let kept = segments::after_settling(&run, self.opt);
        if kept.len() < 3 {
            return;
        }
        let n = kept.len() as f64;
        let stationary = (0..3).all(|i| {
            let m = kept.iter().map(|r| r.1[i]).sum::<f64>() / n;
            (kept.iter().map(|r| (r.1[i] - m).powi(2)).sum::<f64>() / n).sqrt() <= self.opt.max_std_v
        });
        if !stationary {
            return;
        }
        let a = a + (run.len() - kept.len());
        let first = b - run.len();
        let mut k = a;
        while k < b {
            let mut e = k + 1;
            while e < b && self.t_s[e] - self.t_s[k] < self.block_s {
                e += 1;
            }
            let rows = &run[k - first..e - first];
            let n = rows.len() as f64;
            let (mut whole, mut parts) = ([0.0; 3], [0.0; 3]);
            for i in 0..3 {
                whole[i] = rows.iter().map(|r| r.1[i]).sum::<f64>() / n;
            }
            for r in rows {
                for i in 0..3 {
                    parts[i] += r.1[i] / n;
                }
            }
            self.blocks.push((k, e, f));
            self.block_u_v.push([whole, parts]);
            k = e;
        }
    }

    fn finish(mut self) -> anyhow::Result<Series> {
        self.close_run();
        if self.blocks.is_empty() {
            bail!(
                "{}: no stationary dwell labelled `{}…` with a known specific force (signal std ≤ {} V)",
                self.name,
                self.pos_prefix,
                self.opt.max_std_v
            );
        }
        Ok(Series {
            name: self.name.to_string(),
            t_s: self.t_s,
            temp_c: self.temp_c,
            blocks: self.blocks,
            block_u_v: self.block_u_v,
            max_rate_c_per_min: self.opt.max_rate_c_per_min,
        })
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
    /// The fit's dynamics as the core's parameters (self-heating 0: a tilter recording has no
    /// power-on to identify it from; the bias play only with its play). No `-0.0`.
    pub fn dynamics(&self) -> ThermalDynamics<f64> {
        let th = self.theta;
        ThermalDynamics {
            lag_tau_s: th.lag_tau_s + 0.0,
            hysteresis_width_c: th.hysteresis_width_c + 0.0,
            self_heating_c: 0.0,
            self_heating_tau_s: 0.0,
            bias_play_width_c: th.bias_play_width_c + 0.0,
            bias_play_g: if th.bias_play_width_c > 0.0 { self.bias_play_g.map(|b| b + 0.0) } else { [0.0; 3] },
        }
    }

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
    fit_at_axes(series, th, req, scale_v_per_g, [true; 3])
}

/// [`fit_at`] with the bias play's amplitude fitted on the axes of `bias_axes` only (on the
/// others the axis is fitted without its column: amplitude 0, and its constants those of the
/// fit without it).
pub fn fit_at_axes(
    series: &[Series],
    th: &Theta,
    req: &Request,
    scale_v_per_g: [f64; 3],
    bias_axes: [bool; 3],
) -> anyhow::Result<JointFit> {
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
        for (&(a, b, f), means) in s.blocks.iter().zip(&s.block_u_v) {
            let n = (b - a) as f64;
            let mut pw = vec![0.0; order + 1];
            let mut dm = 0.0;
            let um = means[1];
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
        let with_bias = with_bias && bias_axes[i];
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

/// One component of the dynamics as the selection judged it.
#[derive(Clone, Debug, PartialEq)]
pub struct Component {
    /// `lag`, `hysteresis` or `bias_play`.
    pub name: &'static str,
    /// Its value in the best candidate that has it (τ \[s\] or width [°C]); in the kept model
    /// when it is kept.
    pub value: f64,
    /// Its standard error when kept (from the curvature of the residual, with the held-out
    /// residual variance), else 0.
    pub std_error: f64,
    /// Held-out residual \[g²\] of the chosen model without the component (when kept) or with
    /// it (when off) less the chosen model's: what it gains on blocks it was not fitted to.
    pub heldout_gain_g2: f64,
    /// Standard error of that gain \[g²\] (the scatter of its per-chunk parts).
    pub heldout_se_g2: f64,
    /// Whether it is kept.
    pub on: bool,
    /// Why it is off, when it is.
    pub why_off: Option<String>,
}

/// One refined candidate of the search: a combination of components and its best θ.
#[derive(Clone, Debug, PartialEq)]
pub struct Candidate {
    /// Which components are on: bit 0 lag, bit 1 hysteresis, bit 2 bias play.
    pub mask: u8,
    /// The refined parameters.
    pub theta: Theta,
    /// The fit's residual over every block \[g²\].
    pub sse_g2: f64,
    /// The held-out residual: each block predicted by the fit without its fold \[g²\].
    pub heldout_g2: f64,
}

impl Candidate {
    /// `lag + hysteresis + bias_play`, or `static`.
    pub fn label(&self) -> String {
        mask_label(self.mask)
    }
}

/// The names of the components of `mask`, joined by `+` (`static` for none).
pub fn mask_label(mask: u8) -> String {
    let v: Vec<&str> = COMPONENTS.iter().enumerate().filter(|(k, _)| mask & (1 << k) != 0).map(|(_, n)| *n).collect();
    if v.is_empty() { "static".to_string() } else { v.join(" + ") }
}

/// The three components, in the order of θ's parameters.
pub const COMPONENTS: [&str; 3] = ["lag", "hysteresis", "bias_play"];

/// The result of [`identify`].
#[derive(Clone, Debug)]
pub struct Identification {
    /// The joint fit with the kept components.
    pub fit: JointFit,
    /// The joint fit of the same order without dynamics (same blocks).
    pub static_fit: JointFit,
    /// Lag, hysteresis, bias play: their values and whether kept.
    pub components: Vec<Component>,
    /// The refined candidates, one or two per combination of components.
    pub candidates: Vec<Candidate>,
    /// The lag resolution of the recordings \[s\] (the search's smallest τ).
    pub lag_resolution_s: f64,
    /// Objective evaluations of the search.
    pub evaluations: usize,
    /// Why nothing was searched, when nothing was (e.g. no dwell during a ramp).
    pub not_searched: Option<String>,
    /// The time-halves check of the kept model (`None` when nothing was searched or a half has
    /// too few blocks).
    pub halves: Option<HalvesCheck>,
}

/// The two-way time-halves check of the kept model: the model refitted at the kept θ on the
/// blocks of one half of each recording's dwell span predicts the other half's.
#[derive(Clone, Debug, PartialEq)]
pub struct HalvesCheck {
    /// Where each recording was split \[s\]: the middle of its blocks' time span.
    pub split_s: Vec<f64>,
    /// Block RMS per axis \[g\] of the prediction of the other half, per direction (`[0]`:
    /// fitted on the first half, predicting the second; `[1]`: the reverse), by the static
    /// model of the same order …
    pub static_rms_g: [[f64; 3]; 2],
    /// … and by the kept model (dynamics and bias play amplitudes on `bias_axes`).
    pub dynamic_rms_g: [[f64; 3]; 2],
    /// Blocks predicted in each direction.
    pub n_blocks: [usize; 2],
    /// The axes the bias play's amplitude is kept on (none without a bias play).
    pub bias_axes: [bool; 3],
    /// Per axis whose amplitude was zeroed, the direction it did not improve (`x: fitted on …
    /// 2.094 → 3.260 mg`).
    pub bias_notes: Vec<String>,
}

/// The axes' names.
pub const AXES: [&str; 3] = ["x", "y", "z"];

impl Identification {
    /// True when at least one component is kept.
    pub fn any_kept(&self) -> bool {
        self.components.iter().any(|c| c.on)
    }

    /// The identified dynamics as the core's parameters ([`JointFit::dynamics`] of the kept
    /// fit).
    pub fn dynamics(&self) -> ThermalDynamics<f64> {
        self.fit.dynamics()
    }
}

/// A component is kept only when the held-out residual without it exceeds the one with it by
/// more than this many standard errors of that difference …
pub const MIN_HELDOUT_Z: f64 = 2.0;
/// … and by more than this fraction of the held-out residual with it (a gain of a few per cent
/// is drift the component happens to follow, not a dynamic worth flying).
pub const MIN_HELDOUT_REL: f64 = 0.1;

/// Held-out chunks: whole spans of time of at least this \[s\] …
pub const CHUNK_MIN_S: f64 = 120.0;
/// … and about this many per recording (longer chunks on long recordings).
pub const CHUNKS_PER_RECORDING: f64 = 48.0;
/// Chunk `c` is held out in fold `c mod FOLDS`.
pub const FOLDS: usize = 4;

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

fn mask_of(th: &Theta) -> u8 {
    (0..3).filter(|&k| get(th, k) > 0.0).fold(0, |m, k| m | (1 << k))
}

/// Nelder–Mead minimum of `f` from `x0` with initial steps `step`, at most `max_evals`
/// evaluations, stopping when the simplex's values agree within `ftol` (absolute) or its
/// points within `xtol`.
fn nelder_mead(
    x0: &[f64],
    step: f64,
    max_evals: usize,
    ftol: f64,
    xtol: f64,
    f: &mut dyn FnMut(&[f64]) -> f64,
) -> (Vec<f64>, f64) {
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
        let size =
            pts[1..].iter().flat_map(|p| p.0.iter().zip(&pts[0].0).map(|(a, b)| (a - b).abs())).fold(0.0, f64::max);
        if (hi - lo).abs() <= ftol || size <= xtol {
            break;
        }
        let centroid: Vec<f64> = (0..n).map(|k| pts[..n].iter().map(|p| p.0[k]).sum::<f64>() / n as f64).collect();
        let along = |t: f64, worst: &[f64]| -> Vec<f64> {
            (0..n).map(|k| centroid[k] + t * (worst[k] - centroid[k])).collect()
        };
        let xr = along(-1.0, &pts[n].0);
        let fr = f(&xr);
        evals += 1;
        if fr < pts[0].1 {
            let xe = along(-2.0, &pts[n].0);
            let fe = f(&xe);
            evals += 1;
            pts[n] = if fe < fr { (xe, fe) } else { (xr, fr) };
        } else if fr < pts[n - 1].1 {
            pts[n] = (xr, fr);
        } else {
            let xc = if fr < pts[n].1 { along(-0.5, &pts[n].0) } else { along(0.5, &pts[n].0) };
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

/// An orthonormal basis of the columns (modified Gram–Schmidt, twice), with `R`, for least
/// squares by projection; a column (numerically) in the span of those before it is dropped.
struct Basis {
    q: Vec<Vec<f64>>,
    /// Per kept column: its index among the inputs and its row of `R` (coefficients on the
    /// kept columns' `q`, upper triangular).
    kept: Vec<usize>,
    r: Vec<Vec<f64>>,
    n_cols: usize,
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

impl Basis {
    fn new(cols: &[&[f64]]) -> Basis {
        let mut q: Vec<Vec<f64>> = Vec::with_capacity(cols.len());
        let mut kept = Vec::new();
        // r[k][j]: coefficient of q_k in column kept[j].
        let mut rcols: Vec<Vec<f64>> = Vec::new();
        for (c, col) in cols.iter().enumerate() {
            let norm0 = dot(col, col).sqrt();
            if !(norm0 > 0.0) {
                continue;
            }
            let mut v = col.to_vec();
            let mut coef = vec![0.0; q.len()];
            for _ in 0..2 {
                for (k, qk) in q.iter().enumerate() {
                    let a = dot(qk, &v);
                    coef[k] += a;
                    for (x, y) in v.iter_mut().zip(qk) {
                        *x -= a * y;
                    }
                }
            }
            let norm = dot(&v, &v).sqrt();
            if !(norm > 1e-9 * norm0) {
                continue;
            }
            v.iter_mut().for_each(|x| *x /= norm);
            coef.push(norm);
            q.push(v);
            kept.push(c);
            rcols.push(coef);
        }
        // R row-major: r[k][j] for j ≥ k.
        let m = q.len();
        let r = (0..m).map(|k| (0..m).map(|j| if j >= k { rcols[j][k] } else { 0.0 }).collect()).collect();
        Basis { q, kept, r, n_cols: cols.len() }
    }

    /// `v` less its projection on the columns.
    fn residual(&self, v: &[f64]) -> Vec<f64> {
        let mut r = v.to_vec();
        for _ in 0..2 {
            for qk in &self.q {
                let a = dot(qk, &r);
                for (x, y) in r.iter_mut().zip(qk) {
                    *x -= a * y;
                }
            }
        }
        r
    }

    /// The least-squares coefficients of `v` on the input columns (0 for dropped ones).
    fn coef(&self, v: &[f64]) -> Vec<f64> {
        let m = self.q.len();
        let qtv: Vec<f64> = self.q.iter().map(|qk| dot(qk, v)).collect();
        let mut b = vec![0.0; m];
        for k in (0..m).rev() {
            let s = qtv[k] - ((k + 1)..m).map(|j| self.r[k][j] * b[j]).sum::<f64>();
            b[k] = s / self.r[k][k];
        }
        let mut out = vec![0.0; self.n_cols];
        for (k, &c) in self.kept.iter().enumerate() {
            out[c] = b[k];
        }
        out
    }
}

/// The blocks of every series, prepared once for the search: the known specific forces, the
/// signals' block means less the part of the fixed K columns, and each block's held-out chunk.
struct Blocks<'a> {
    series: &'a [Series],
    req: &'a Request,
    var: [bool; 3],
    f: Vec<[f64; 3]>,
    y: [Vec<f64>; 3],
    /// 1/K_ii²: the residuals in g².
    w: [f64; 3],
    chunk: Vec<usize>,
    n_chunks: usize,
    /// Per block, its half of its recording's dwell span (0: the first, 1: the second), by the
    /// time of its middle row.
    half: Vec<usize>,
}

impl<'a> Blocks<'a> {
    fn new(series: &'a [Series], req: &'a Request, scale_v_per_g: [f64; 3]) -> Blocks<'a> {
        let var = varying(series);
        let (mut f, mut y, mut chunk) = (Vec::new(), [Vec::new(), Vec::new(), Vec::new()], Vec::new());
        let mut half = Vec::new();
        let mut n_chunks = 0;
        for s in series {
            let mid_s = split_s(s);
            half.extend(s.blocks.iter().map(|&(a, b, _)| usize::from(s.t_s[(a + b - 1) / 2] >= mid_s)));
            let t_first = s.t_s.first().copied().unwrap_or(0.0);
            let len = (s.duration_s() / CHUNKS_PER_RECORDING).max(CHUNK_MIN_S);
            let mut last = 0;
            for (&(a, _, fb), means) in s.blocks.iter().zip(&s.block_u_v) {
                for i in 0..3 {
                    let u = means[0][i];
                    y[i].push(u - (0..3).filter(|&j| !var[j]).map(|j| req.k_prior[i][j] * fb[j]).sum::<f64>());
                }
                f.push(fb);
                let c = ((s.t_s[a] - t_first) / len).floor() as usize;
                chunk.push(n_chunks + c);
                last = last.max(c);
            }
            n_chunks += last + 1;
        }
        Blocks { series, req, var, f, y, w: scale_v_per_g.map(|s| 1.0 / (s * s)), chunk, n_chunks, half }
    }

    /// The lagged temperature (τ) through the play (h) of every row of every series.
    fn temp_eff(&self, tau: f64, h: f64) -> Vec<Vec<f64>> {
        self.series
            .iter()
            .map(|s| {
                let lag = if tau > 0.0 { lagged(&s.t_s, &s.temp_c, tau) } else { s.temp_c.clone() };
                if h > 0.0 { play(&lag, h) } else { lag }
            })
            .collect()
    }

    /// The columns of the constants and their temperature model: block means of ΔT^p, then
    /// ΔT^p·f_j for each varying f_j.
    fn base(&self, te: &[Vec<f64>]) -> Vec<Vec<f64>> {
        let order = self.req.order;
        let mut pw: Vec<Vec<f64>> = vec![Vec::with_capacity(self.f.len()); order + 1];
        for (s, te) in self.series.iter().zip(te) {
            for &(a, b, _) in &s.blocks {
                let n = (b - a) as f64;
                let mut m = [0.0; MAX_POLY_ORDER + 1];
                for &t in &te[a..b] {
                    let x = (t - self.req.t0_c) / DT_SCALE;
                    let mut xp = 1.0;
                    for mp in m.iter_mut().take(order + 1) {
                        *mp += xp;
                        xp *= x;
                    }
                }
                for (p, col) in pw.iter_mut().enumerate() {
                    col.push(m[p] / n);
                }
            }
        }
        let mut cols = pw.clone();
        for j in (0..3).filter(|&j| self.var[j]) {
            for p in &pw {
                cols.push(p.iter().zip(&self.f).map(|(x, f)| x * f[j]).collect());
            }
        }
        cols
    }

    /// The block means of the bias play's output `d` (width `hb`) on `te`.
    fn dcol(&self, te: &[Vec<f64>], hb: f64) -> Vec<f64> {
        let mut out = Vec::with_capacity(self.f.len());
        for (s, te) in self.series.iter().zip(te) {
            let p = play(te, hb);
            for &(a, b, _) in &s.blocks {
                let n = (b - a) as f64;
                out.push((a..b).map(|k| (p[k] - te[k]) / (0.5 * hb)).sum::<f64>() / n);
            }
        }
        out
    }

    /// The columns of the model at θ.
    fn columns(&self, th: &Theta) -> Vec<Vec<f64>> {
        let te = self.temp_eff(th.lag_tau_s, th.hysteresis_width_c);
        let mut cols = self.base(&te);
        if th.bias_play_width_c > 0.0 {
            cols.push(self.dcol(&te, th.bias_play_width_c));
        }
        cols
    }

    /// The residual of the fit at θ over every block \[g²\].
    fn sse(&self, th: &Theta) -> f64 {
        let cols = self.columns(th);
        let refs: Vec<&[f64]> = cols.iter().map(Vec::as_slice).collect();
        let b = Basis::new(&refs);
        (0..3).map(|i| self.w[i] * b.residual(&self.y[i]).iter().map(|x| x * x).sum::<f64>()).sum()
    }

    /// The held-out residual of each chunk at θ \[g²\]: every block predicted by the fit on the
    /// folds other than its own.
    fn heldout(&self, th: &Theta) -> Vec<f64> {
        let cols = self.columns(th);
        let mut out = vec![0.0; self.n_chunks];
        for fold in 0..FOLDS {
            let train: Vec<usize> = (0..self.f.len()).filter(|&k| self.chunk[k] % FOLDS != fold).collect();
            let test: Vec<usize> = (0..self.f.len()).filter(|&k| self.chunk[k] % FOLDS == fold).collect();
            if test.is_empty() || train.len() <= cols.len() {
                continue;
            }
            let sub: Vec<Vec<f64>> = cols.iter().map(|c| train.iter().map(|&k| c[k]).collect()).collect();
            let refs: Vec<&[f64]> = sub.iter().map(Vec::as_slice).collect();
            let basis = Basis::new(&refs);
            for i in 0..3 {
                let yt: Vec<f64> = train.iter().map(|&k| self.y[i][k]).collect();
                let beta = basis.coef(&yt);
                for &k in &test {
                    let pred: f64 = cols.iter().zip(&beta).map(|(c, b)| c[k] * b).sum();
                    out[self.chunk[k]] += self.w[i] * (self.y[i][k] - pred).powi(2);
                }
            }
        }
        out
    }

    /// The two-way time-halves check at θ: per direction (0: the model fitted on the blocks of
    /// the first half of each recording's dwell span, predicting the second; 1: the reverse)
    /// and per axis, the residual of the predicted blocks \[g²\], with the bias play's column on
    /// the axes of `bias_axes` only; and the blocks predicted in each direction. `None` when a
    /// half has no more blocks than the model has parameters.
    fn halves(&self, th: &Theta, bias_axes: [bool; 3]) -> Option<Halves> {
        let te = self.temp_eff(th.lag_tau_s, th.hysteresis_width_c);
        let base = self.base(&te);
        let d = (th.bias_play_width_c > 0.0).then(|| self.dcol(&te, th.bias_play_width_c));
        let mut out = Halves { sse_g2: [[0.0; 3]; 2], n_blocks: [0; 2], chunk_g2: Default::default() };
        for dir in 0..2 {
            let train: Vec<usize> = (0..self.f.len()).filter(|&k| self.half[k] == dir).collect();
            let test: Vec<usize> = (0..self.f.len()).filter(|&k| self.half[k] != dir).collect();
            if test.is_empty() || train.len() <= base.len() + 1 {
                return None;
            }
            out.n_blocks[dir] = test.len();
            // The predicted half's chunks, in order: each test block's index among them.
            let mut ids: Vec<usize> = test.iter().map(|&k| self.chunk[k]).collect();
            ids.dedup();
            let at: Vec<usize> = test.iter().map(|&k| ids.partition_point(|&c| c < self.chunk[k])).collect();
            for i in 0..3 {
                out.chunk_g2[dir][i] = vec![0.0; ids.len()];
                let mut cols: Vec<&Vec<f64>> = base.iter().collect();
                if let (Some(d), true) = (&d, bias_axes[i]) {
                    cols.push(d);
                }
                let sub: Vec<Vec<f64>> = cols.iter().map(|c| train.iter().map(|&k| c[k]).collect()).collect();
                let refs: Vec<&[f64]> = sub.iter().map(Vec::as_slice).collect();
                let beta = Basis::new(&refs).coef(&train.iter().map(|&k| self.y[i][k]).collect::<Vec<_>>());
                for (&k, &c) in test.iter().zip(&at) {
                    let pred: f64 = cols.iter().zip(&beta).map(|(c, b)| c[k] * b).sum();
                    let e2 = self.w[i] * (self.y[i][k] - pred).powi(2);
                    out.sse_g2[dir][i] += e2;
                    out.chunk_g2[dir][i][c] += e2;
                }
            }
        }
        Some(out)
    }
}

/// The residuals of the time-halves check (`Blocks::halves`).
#[derive(Clone, Debug)]
struct Halves {
    /// Per direction (0: fitted on the first half, 1: on the second) and axis \[g²\].
    sse_g2: [[f64; 3]; 2],
    /// Blocks predicted per direction.
    n_blocks: [usize; 2],
    /// The same per chunk of the predicted half (the chunks of the held-out selection, in
    /// time order) \[g²\]: the scatter that gives a difference its standard error.
    chunk_g2: [[Vec<f64>; 3]; 2],
}

impl Halves {
    fn rms_g(&self) -> [[f64; 3]; 2] {
        let mut r = [[0.0; 3]; 2];
        for dir in 0..2 {
            for i in 0..3 {
                r[dir][i] = (self.sse_g2[dir][i] / self.n_blocks[dir].max(1) as f64).sqrt();
            }
        }
        r
    }
}

/// The middle of the time span of `s`'s blocks \[s\] (from the first row of the first block to
/// the last row of the last): where the time-halves check splits the recording.
pub fn split_s(s: &Series) -> f64 {
    match (s.blocks.first(), s.blocks.last()) {
        (Some(a), Some(b)) => 0.5 * (s.t_s[a.0] + s.t_s[b.1 - 1]),
        _ => 0.0,
    }
}

/// `a − b` summed, and its standard error from the scatter of the per-chunk differences.
fn gain_and_se(a: &[f64], b: &[f64]) -> (f64, f64) {
    let d: Vec<f64> = a.iter().zip(b).map(|(x, y)| x - y).collect();
    let n = d.len() as f64;
    let mean = d.iter().sum::<f64>() / n;
    let var = d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
    (mean * n, (var * n).sqrt())
}

/// Identifies the dynamics and the static model jointly (see the module's text). `progress`
/// receives the stages of the search, the candidates and the selection.
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
    let dt = series.iter().map(Series::dt_s).fold(0.0, f64::max);
    let lag_res = (3.0 * dt).max(1.0);
    let off = |why: &str| -> Vec<Component> {
        COMPONENTS
            .iter()
            .map(|&name| Component {
                name,
                value: 0.0,
                std_error: 0.0,
                heldout_gain_g2: 0.0,
                heldout_se_g2: 0.0,
                on: false,
                why_off: Some(why.to_string()),
            })
            .collect()
    };
    // Without a dwell while the temperature moves, a lag or a play changes nothing observable.
    let ramp_blocks: usize = series.iter().map(Series::ramp_blocks).sum();
    if ramp_blocks == 0 {
        let why = "no dwell during a ramp: the dynamics cannot be identified from this recording".to_string();
        progress(&format!("dynamics: {why} (every dwell is in a soak; nothing searched)"));
        return Ok(Identification {
            fit: static_fit.clone(),
            static_fit,
            components: off("no dwell during a ramp"),
            candidates: Vec::new(),
            lag_resolution_s: lag_res,
            evaluations: 2,
            not_searched: Some(why),
            halves: None,
        });
    }
    let blocks = Blocks::new(series, req, scale);
    let dur = series.iter().map(Series::duration_s).fold(0.0, f64::max);
    let trange = series
        .iter()
        .flat_map(|s| s.temp_c.iter())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &t| (a.min(t), b.max(t)));
    let trange = trange.1 - trange.0;
    let taus: Vec<f64> = std::iter::once(0.0).chain(log_grid(lag_res, (0.25 * dur).max(2.0 * lag_res), 3.0)).collect();
    let widths: Vec<f64> = std::iter::once(0.0).chain(log_grid(0.02, (0.25 * trange).max(0.04), 3.0)).collect();
    let bound = |k: usize| if k == 0 { (taus[1], taus[taus.len() - 1]) } else { (widths[1], widths[widths.len() - 1]) };
    // Stage 1: the whole (τ, h, h_b) grid, zero included in each, so every combination of
    // components is searched jointly. Per (τ, h) one basis of the constants' columns; each h_b
    // adds one column, whose effect on the residual is a projection.
    let mut grid: Vec<(Theta, f64, [usize; 3])> = Vec::with_capacity(taus.len() * widths.len() * widths.len());
    let mut evaluations = 2;
    for (it, &tau) in taus.iter().enumerate() {
        for (ih, &h) in widths.iter().enumerate() {
            let te = blocks.temp_eff(tau, h);
            let cols = blocks.base(&te);
            let refs: Vec<&[f64]> = cols.iter().map(Vec::as_slice).collect();
            let basis = Basis::new(&refs);
            let ry: Vec<Vec<f64>> = (0..3).map(|i| basis.residual(&blocks.y[i])).collect();
            let sse0: Vec<f64> = ry.iter().map(|r| dot(r, r)).collect();
            let total0: f64 = (0..3).map(|i| blocks.w[i] * sse0[i]).sum();
            grid.push((Theta { lag_tau_s: tau, hysteresis_width_c: h, bias_play_width_c: 0.0 }, total0, [it, ih, 0]));
            evaluations += 1;
            for (ib, &hb) in widths.iter().enumerate().skip(1) {
                let rd = basis.residual(&blocks.dcol(&te, hb));
                let dd = dot(&rd, &rd);
                let total: f64 = (0..3)
                    .map(|i| {
                        let g = if dd > 0.0 { dot(&rd, &ry[i]).powi(2) / dd } else { 0.0 };
                        blocks.w[i] * (sse0[i] - g).max(0.0)
                    })
                    .sum();
                grid.push((
                    Theta { lag_tau_s: tau, hysteresis_width_c: h, bias_play_width_c: hb },
                    total,
                    [it, ih, ib],
                ));
                evaluations += 1;
            }
        }
    }
    progress(&format!(
        "dynamics: grid over τ ({} values) × h ({} values) × h_b ({} values), each with zero: {} fits",
        taus.len(),
        widths.len(),
        widths.len(),
        grid.len()
    ));
    // Stage 2: per combination of components, the best grid point and the best one not next to
    // it, refined (Nelder–Mead on the logarithms of the non-zero parameters, within the grid).
    let sigma2 = static_fit.sse() / (3 * n_blocks) as f64;
    let mut candidates: Vec<Candidate> = Vec::new();
    for mask in 0u8..8 {
        let mut pts: Vec<&(Theta, f64, [usize; 3])> = grid.iter().filter(|g| mask_of(&g.0) == mask).collect();
        pts.sort_by(|a, b| a.1.total_cmp(&b.1));
        let Some(best) = pts.first().copied() else { continue };
        let second = pts.iter().copied().find(|p| (0..3).any(|k| p.2[k].abs_diff(best.2[k]) > 1));
        let on: Vec<usize> = (0..3).filter(|&k| mask & (1 << k) != 0).collect();
        let mut refined: Vec<(Theta, f64)> = Vec::new();
        for start in std::iter::once(best).chain(second.filter(|_| on.len() > 1)) {
            if on.is_empty() {
                refined.push((start.0, start.1));
                continue;
            }
            let mut f = |x: &[f64]| {
                let mut th = start.0;
                for (v, &k) in x.iter().zip(&on) {
                    let (lo, hi) = bound(k);
                    if !(v.exp() >= lo * 0.999 && v.exp() <= hi * 1.001) {
                        return f64::INFINITY;
                    }
                    set(&mut th, k, v.exp());
                }
                evaluations += 1;
                blocks.sse(&th)
            };
            let x0: Vec<f64> = on.iter().map(|&k| get(&start.0, k).ln()).collect();
            let (x, c) = nelder_mead(&x0, 0.25, 40 * on.len() + 40, 1e-3 * sigma2, 2e-3, &mut f);
            let mut th = start.0;
            if c <= start.1 {
                for (v, &k) in x.iter().zip(&on) {
                    set(&mut th, k, v.exp());
                }
            }
            refined.push((th, c.min(start.1)));
        }
        refined.sort_by(|a, b| a.1.total_cmp(&b.1));
        // Two starts that refined to the same point (within 1 %) are one candidate.
        let same = |a: &Theta, b: &Theta| (0..3).all(|k| (get(a, k) - get(b, k)).abs() <= 0.01 * get(a, k).abs());
        if refined.len() == 2 && same(&refined[0].0, &refined[1].0) {
            refined.truncate(1);
        }
        for (th, sse) in refined.into_iter().take(if on.len() > 1 { 2 } else { 1 }) {
            let heldout_g2 = blocks.heldout(&th).iter().sum();
            candidates.push(Candidate { mask, theta: th, sse_g2: sse, heldout_g2 });
        }
    }
    // The best candidate of each combination (by its held-out residual). A candidate with a
    // parameter at the top of its search range is not identified (the residual falls on beyond
    // it, as when a wide play follows drift): it is printed, not chosen.
    let at_top = |c: &Candidate| (0..3).any(|k| get(&c.theta, k) >= 0.98 * bound(k).1);
    let mut by_mask: Vec<Option<(Candidate, Vec<f64>)>> = vec![None; 8];
    for c in candidates.iter().filter(|c| !at_top(c)) {
        let better = by_mask[c.mask as usize].as_ref().is_none_or(|(b, _)| c.heldout_g2 < b.heldout_g2);
        if better {
            by_mask[c.mask as usize] = Some((c.clone(), blocks.heldout(&c.theta)));
        }
    }
    let nb = n_blocks as f64;
    progress("dynamics: candidates (block RMS of the fit, and of each block predicted without its fold) [µg]:");
    for c in &candidates {
        progress(&format!(
            "  {:<32} τ = {:>7.1} s, h = {:>6.3} °C, h_b = {:>6.3} °C: fit {:>8.2}, held out {:>8.2}{}",
            c.label(),
            c.theta.lag_tau_s,
            c.theta.hysteresis_width_c,
            c.theta.bias_play_width_c,
            (c.sse_g2 / (3.0 * nb)).sqrt() * 1e6,
            (c.heldout_g2 / (3.0 * nb)).sqrt() * 1e6,
            if at_top(c) { " (at the top of the search range: not chosen)" } else { "" }
        ));
    }
    // Selection: from the combination that predicts the held-out blocks best, drop the
    // component whose held-out gain passes the bar (MIN_HELDOUT_Z standard errors and
    // MIN_HELDOUT_REL of the residual) by the least while it fails it.
    let mut chosen = (0..8).filter(|&m| by_mask[m].is_some()).min_by(|&a, &b| {
        let (x, y) = (&by_mask[a].as_ref().unwrap().0, &by_mask[b].as_ref().unwrap().0);
        x.heldout_g2.total_cmp(&y.heldout_g2)
    });
    let Some(mut m) = chosen.take() else { bail!("{names}: no candidate could be fitted") };
    progress(&format!("dynamics: best held-out prediction: {}", mask_label(m as u8)));
    let z_of = |with: usize, without: usize| -> Option<(f64, f64)> {
        let (a, b) = (by_mask[without].as_ref()?, by_mask[with].as_ref()?);
        Some(gain_and_se(&a.1, &b.1))
    };
    // How far a component passes the bar (≤ 1: it fails): the smaller of its gain in standard
    // errors over MIN_HELDOUT_Z and its relative gain over MIN_HELDOUT_REL.
    let margin = |with: usize, g: f64, se: f64| -> f64 {
        let rel = g / by_mask[with].as_ref().map_or(f64::INFINITY, |c| c.0.heldout_g2).max(1e-300);
        (g / se.max(1e-300) / MIN_HELDOUT_Z).min(rel / MIN_HELDOUT_REL)
    };
    loop {
        let mut weakest: Option<(usize, f64, f64, f64)> = None;
        for k in (0..3).filter(|&k| m & (1 << k) != 0) {
            let Some((g, se)) = z_of(m, m & !(1 << k)) else { continue };
            let q = margin(m, g, se);
            if weakest.is_none_or(|w| q < w.1) {
                weakest = Some((k, q, g, se));
            }
        }
        match weakest {
            Some((k, q, g, se)) if q <= 1.0 => {
                progress(&format!(
                    "dynamics: {} dropped: held-out gain {:.1} ± {:.1} µg² ({:.1} standard errors, {:.1} % of the held-out residual; {MIN_HELDOUT_Z} and {} % needed)",
                    COMPONENTS[k],
                    g * 1e12,
                    se * 1e12,
                    g / se.max(1e-300),
                    100.0 * g / by_mask[m].as_ref().map_or(f64::INFINITY, |c| c.0.heldout_g2),
                    100.0 * MIN_HELDOUT_REL
                ));
                m &= !(1 << k);
            }
            _ => break,
        }
    }
    let theta = by_mask[m].as_ref().map_or(Theta::default(), |c| c.0.theta);
    progress(&format!(
        "dynamics: chosen by the held-out chunks {}: τ = {:.1} s, h = {:.3} °C, h_b = {:.3} °C",
        mask_label(m as u8),
        theta.lag_tau_s,
        theta.hysteresis_width_c,
        theta.bias_play_width_c
    ));
    let best_theta: Vec<Option<Theta>> = by_mask.iter().map(|c| c.as_ref().map(|c| c.0.theta)).collect();
    let (m, theta, halves, dropped) = halves_check(&blocks, &best_theta, m, theta, &mut evaluations, progress);
    if !dropped.is_empty() {
        progress(&format!(
            "dynamics: kept {}: τ = {:.1} s, h = {:.3} °C, h_b = {:.3} °C",
            mask_label(m as u8),
            theta.lag_tau_s,
            theta.hysteresis_width_c,
            theta.bias_play_width_c
        ));
    }
    // Standard errors of the kept parameters: the curvature of the residual in their
    // logarithms, with the held-out residual variance (drift included).
    let on: Vec<usize> = (0..3).filter(|&k| m & (1 << k) != 0).collect();
    let heldout_sigma2 = by_mask[m].as_ref().map_or(sigma2, |c| c.0.heldout_g2 / (3.0 * nb));
    let se = std_errors(&blocks, &theta, &on, heldout_sigma2);
    evaluations += 1 + 2 * on.len() + 4 * on.len() * on.len().saturating_sub(1) / 2;
    // What each component gains on held-out blocks against the chosen model.
    let mut components = Vec::new();
    for k in 0..3 {
        let bit = 1usize << k;
        let (with, without) = if m & bit != 0 { (m, m & !bit) } else { (m | bit, m) };
        let (g, s) = z_of(with, without).unwrap_or((0.0, 0.0));
        let value = by_mask[with].as_ref().map_or(0.0, |c| get(&c.0.theta, k));
        let on_k = m & bit != 0;
        let topped = candidates.iter().find(|c| c.mask as usize == with && at_top(c));
        let why_off = (!on_k).then(|| {
            if let (None, Some(c)) = (&by_mask[with], topped) {
                return format!(
                    "best at {} {}, the top of its search range: not identified (a drift the component follows)",
                    fmt_value(k, get(&c.theta, k)),
                    if k == 0 { "s" } else { "°C" }
                );
            }
            let rel = g / by_mask[with].as_ref().map_or(f64::INFINITY, |c| c.0.heldout_g2).max(1e-300);
            format!(
                "best at {} {}, held-out gain {:+.0} ± {:.0} µg² ({:.1} standard errors, {:+.1} %; {MIN_HELDOUT_Z} and {} % needed)",
                fmt_value(k, value),
                if k == 0 { "s" } else { "°C" },
                g * 1e12,
                s * 1e12,
                g / s.max(1e-300),
                100.0 * rel,
                100.0 * MIN_HELDOUT_REL
            )
        });
        let why_off = dropped.iter().find(|d| d.0 == k).map(|d| d.1.clone()).or(why_off);
        let std_error = on.iter().position(|&j| j == k).map_or(0.0, |p| se[p]);
        components.push(Component {
            name: COMPONENTS[k],
            value,
            std_error,
            heldout_gain_g2: g,
            heldout_se_g2: s,
            on: on_k,
            why_off,
        });
    }
    let bias_axes = halves.as_ref().map_or([true; 3], |h| h.bias_axes);
    let fit = fit_at_axes(series, &theta, req, scale, bias_axes)?;
    Ok(Identification {
        fit,
        static_fit,
        components,
        candidates,
        lag_resolution_s: lag_res,
        evaluations,
        not_searched: None,
        halves,
    })
}

/// The time-halves check of the model the held-out chunks chose (mask `m`, parameters
/// `theta`; `best_theta[mask]` the best candidate of each combination): the model refitted at
/// θ on the blocks of the first half of each recording's dwell span predicts the second, and
/// the reverse, and so does the static model of the same order. The bias play's amplitude is
/// kept on an axis only when it lowers that axis's residual in both directions (against the
/// same θ without it); with no such axis the bias play is dropped. Then, if the model still
/// predicts some axis worse than the static model in either direction by more than
/// [`MIN_HELDOUT_Z`] standard errors of the excess (the scatter of its per-chunk parts; only
/// a lag or a play, components of the whole unit with no amplitude of their own, can do
/// that), the one of them whose removal mends the worst axis most is dropped, and everything
/// is checked again at the remaining combination's θ. Returns the kept mask and θ, the check
/// (`None` when a half has too few blocks for the model: nothing is then dropped) and, per
/// dropped component, why.
#[allow(clippy::type_complexity)]
fn halves_check(
    blocks: &Blocks<'_>,
    best_theta: &[Option<Theta>],
    mut m: usize,
    mut theta: Theta,
    evaluations: &mut usize,
    progress: &mut dyn FnMut(&str),
) -> (usize, Theta, Option<HalvesCheck>, Vec<(usize, String)>) {
    const DIRS: [&str; 2] =
        ["fitted on the first half, predicting the second", "fitted on the second half, predicting the first"];
    let mg = |v: [f64; 3]| format!("{:>7.3} / {:>7.3} / {:>7.3}", v[0] * 1e3, v[1] * 1e3, v[2] * 1e3);
    let row = |name: &str, h: &Halves| {
        let r = h.rms_g();
        format!("  {name:<56} {}   {}", mg(r[0]), mg(r[1]))
    };
    let split_s: Vec<f64> = blocks.series.iter().map(split_s).collect();
    let mut dropped: Vec<(usize, String)> = Vec::new();
    *evaluations += 1;
    let Some(static_h) = blocks.halves(&Theta::default(), [false; 3]) else {
        progress("dynamics: time-halves check not made: a half of the dwells has too few blocks for the model");
        return (m, theta, None, dropped);
    };
    progress(&format!(
        "dynamics: time-halves check (split at {} s; at θ the model refitted on one half predicts the other), block RMS x / y / z [mg]:",
        split_s.iter().map(|t| format!("{t:.0}")).collect::<Vec<_>>().join(", ")
    ));
    progress(&format!("  {:<56} {:<29}   {}", "", "first half → second", "second half → first"));
    progress(&row("static", &static_h));
    loop {
        let label = mask_label(m as u8);
        let mut bias_axes = [false; 3];
        let mut bias_notes = Vec::new();
        if m & 4 != 0 {
            let mut th0 = theta;
            th0.bias_play_width_c = 0.0;
            *evaluations += 2;
            // The halves have the blocks for the static model, so for any θ (the bias play's
            // column is allowed for): `None` does not happen here.
            let (Some(with), Some(without)) = (blocks.halves(&theta, [true; 3]), blocks.halves(&th0, [false; 3]))
            else {
                return (m, theta, None, dropped);
            };
            progress(&row(&format!("{label} (amplitude on every axis)"), &with));
            if m & !4 != 0 {
                progress(&row(&mask_label((m & !4) as u8), &without));
            }
            let (rw, ro) = (with.rms_g(), without.rms_g());
            for i in 0..3 {
                bias_axes[i] = (0..2).all(|d| with.sse_g2[d][i] < without.sse_g2[d][i]);
                if let Some(d) = (0..2).find(|&d| with.sse_g2[d][i] >= without.sse_g2[d][i]) {
                    bias_notes.push(format!(
                        "{}: {} {:.3} → {:.3} mg",
                        AXES[i],
                        DIRS[d],
                        ro[d][i] * 1e3,
                        rw[d][i] * 1e3
                    ));
                }
            }
            if bias_axes.iter().all(|b| !b) {
                let why = format!(
                    "chosen by the held-out chunks, dropped by the time-halves check: its amplitude predicts no axis better in both directions ({})",
                    bias_notes.join("; ")
                );
                progress(&format!("dynamics: bias_play {why}"));
                dropped.push((2, why));
                m &= !4;
                theta = best_theta[m].unwrap_or(th0);
                continue;
            }
            if !bias_notes.is_empty() {
                progress(&format!(
                    "dynamics: bias play amplitude kept on {} only (0 where it does not predict better in both directions: {})",
                    (0..3).filter(|&i| bias_axes[i]).map(|i| AXES[i]).collect::<Vec<_>>().join(", "),
                    bias_notes.join("; ")
                ));
            }
        }
        *evaluations += 1;
        let Some(model) = blocks.halves(&theta, bias_axes) else { return (m, theta, None, dropped) };
        let kept_label = if m & 4 != 0 && bias_axes != [true; 3] {
            let on: Vec<&str> = (0..3).filter(|&i| bias_axes[i]).map(|i| AXES[i]).collect();
            format!("{label} (amplitude on {})", on.join(", "))
        } else {
            label.clone()
        };
        progress(&row(&kept_label, &model));
        // The axis predicted worst against the static model, as (the excess of its residual
        // in standard errors of that excess, direction, axis): worse when the excess is more
        // than MIN_HELDOUT_Z of them (the scatter of its per-chunk parts, as for the held-out
        // gains).
        let worst_vs_static = |h: &Halves| {
            let mut w = (f64::NEG_INFINITY, 0, 0);
            for d in 0..2 {
                for i in 0..3 {
                    let (excess, se) = gain_and_se(&h.chunk_g2[d][i], &static_h.chunk_g2[d][i]);
                    let z = excess / se.max(1e-300);
                    if z > w.0 {
                        w = (z, d, i);
                    }
                }
            }
            w
        };
        let (z, d, i) = worst_vs_static(&model);
        if z > MIN_HELDOUT_Z {
            // An axis worse than static that its amplitude cannot mend (kept only where it
            // helps): the unit-wide component whose removal mends the most goes.
            let (rs, rm) = (static_h.rms_g(), model.rms_g());
            let why = format!(
                "chosen by the held-out chunks, dropped by the time-halves check: with it {} is predicted worse than by the static model {} ({:.3} → {:.3} mg, {z:.1} standard errors; {MIN_HELDOUT_Z} allowed)",
                AXES[i],
                DIRS[d],
                rs[d][i] * 1e3,
                rm[d][i] * 1e3
            );
            let mut best: Option<(usize, f64)> = None;
            for k in (0..2).filter(|&k| m & (1 << k) != 0) {
                let mut thk = theta;
                set(&mut thk, k, 0.0);
                *evaluations += 1;
                let Some(without) = blocks.halves(&thk, bias_axes) else { continue };
                progress(&row(&format!("{kept_label} without {}", COMPONENTS[k]), &without));
                let w = worst_vs_static(&without).0;
                if best.is_none_or(|b| w < b.1) {
                    best = Some((k, w));
                }
            }
            // Without a lag or a play, every axis is static or mended by its amplitude; should
            // rounding say otherwise, the bias play goes.
            let k = best.map_or(2, |b| b.0);
            progress(&format!("dynamics: {} {why}", COMPONENTS[k]));
            let mut thk = theta;
            set(&mut thk, k, 0.0);
            dropped.push((k, why));
            m &= !(1 << k);
            theta = best_theta[m].unwrap_or(thk);
            continue;
        }
        let check = HalvesCheck {
            split_s,
            static_rms_g: static_h.rms_g(),
            dynamic_rms_g: model.rms_g(),
            n_blocks: model.n_blocks,
            bias_axes,
            bias_notes,
        };
        return (m, theta, Some(check), dropped);
    }
}

fn fmt_value(k: usize, v: f64) -> String {
    if k == 0 { format!("{v:.1}") } else { format!("{v:.3}") }
}

/// Standard errors of the parameters `on` of θ: `θ_k·√(2σ²·(H⁻¹)_kk)` with `H` the Hessian of
/// the residual in their logarithms (central differences, step 0.05).
fn std_errors(blocks: &Blocks<'_>, th: &Theta, on: &[usize], sigma2: f64) -> Vec<f64> {
    let n = on.len();
    if n == 0 {
        return Vec::new();
    }
    let hstep = 0.05;
    let at = |dx: &[f64]| {
        let mut t = *th;
        for (d, &k) in dx.iter().zip(on) {
            set(&mut t, k, get(th, k) * d.exp());
        }
        blocks.sse(&t)
    };
    let f0 = at(&vec![0.0; n]);
    let mut hm = vec![vec![0.0; n]; n];
    for a in 0..n {
        let mut e = vec![0.0; n];
        e[a] = hstep;
        let fp = at(&e);
        e[a] = -hstep;
        let fm = at(&e);
        hm[a][a] = (fp - 2.0 * f0 + fm) / (hstep * hstep);
        for b in 0..a {
            let v = |sa: f64, sb: f64| {
                let mut e = vec![0.0; n];
                e[a] = sa * hstep;
                e[b] = sb * hstep;
                at(&e)
            };
            let h = (v(1.0, 1.0) - v(1.0, -1.0) - v(-1.0, 1.0) + v(-1.0, -1.0)) / (4.0 * hstep * hstep);
            hm[a][b] = h;
            hm[b][a] = h;
        }
    }
    let inv = invert(&hm);
    on.iter()
        .enumerate()
        .map(|(p, &k)| match &inv {
            Some(i) if i[p][p] > 0.0 => get(th, k) * (2.0 * sigma2 * i[p][p]).sqrt(),
            _ => f64::INFINITY,
        })
        .collect()
}

/// The inverse of a small matrix (Gauss–Jordan with partial pivoting); `None` when singular.
fn invert(a: &[Vec<f64>]) -> Option<Vec<Vec<f64>>> {
    let n = a.len();
    let mut m: Vec<Vec<f64>> = a
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let mut row = r.clone();
            row.extend((0..n).map(|j| if i == j { 1.0 } else { 0.0 }));
            row
        })
        .collect();
    for c in 0..n {
        let p = (c..n).max_by(|&x, &y| m[x][c].abs().total_cmp(&m[y][c].abs()))?;
        if !(m[p][c].abs() > 0.0) {
            return None;
        }
        m.swap(c, p);
        let d = m[c][c];
        m[c].iter_mut().for_each(|x| *x /= d);
        for r in 0..n {
            if r != c {
                let f = m[r][c];
                let row_c = m[c].clone();
                m[r].iter_mut().zip(&row_c).for_each(|(x, y)| *x -= f * y);
            }
        }
    }
    Some(m.into_iter().map(|r| r[n..].to_vec()).collect())
}

/// The core's thermal dynamics run over a recording's rows (`t_s`, `temp_C`; the time since
/// power-on from `power_s`, else from the first row): the effective temperature and bias-play
/// fraction of every row, as the firmware computes them (in f64).
pub fn run_core(rows: &[crate::recording::Row], d: &ThermalDynamics<f64>) -> Vec<Effective<f64>> {
    let mut core = CoreRun::new(d);
    rows.iter().map(|r| core.step(r)).collect()
}

/// [`run_core`] over a recording read row by row (a progress bar on standard error), keeping
/// only the rows whose `t_s` `keep` accepts: their times and effective values. Holds those
/// rows, not the recording. Errors name the file.
pub fn run_core_kept(
    path: &Path,
    d: &ThermalDynamics<f64>,
    keep: impl Fn(f64) -> bool,
) -> anyhow::Result<(Vec<f64>, Vec<Effective<f64>>)> {
    let mut pass = Pass::open(path, "dynamics").map_err(|e| anyhow!("{e}"))?;
    let mut core = CoreRun::new(d);
    let (mut t, mut e) = (Vec::new(), Vec::new());
    let mut row = Row::default();
    while pass.read_row(&mut row).map_err(|e| anyhow!("{e}"))? {
        let eff = core.step(&row);
        if keep(row.t_s) {
            t.push(row.t_s);
            e.push(eff);
        }
    }
    Ok((t, e))
}

/// The core's dynamics stepped one row at a time.
struct CoreRun<'a> {
    d: &'a ThermalDynamics<f64>,
    st: DynamicsState<f64>,
    t_first: Option<f64>,
    prev: Option<f64>,
}

impl<'a> CoreRun<'a> {
    fn new(d: &'a ThermalDynamics<f64>) -> CoreRun<'a> {
        CoreRun { d, st: DynamicsState::new(), t_first: None, prev: None }
    }

    fn step(&mut self, r: &Row) -> Effective<f64> {
        let t_first = *self.t_first.get_or_insert(r.t_s);
        let dt = self.prev.map_or(0.0, |p| r.t_s - p);
        self.prev = Some(r.t_s);
        let t_on = r.power_s.unwrap_or(r.t_s - t_first);
        self.d.step(&mut self.st, r.temp_c, dt, t_on)
    }
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
