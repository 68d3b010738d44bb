//! The tilter path's fits: the 12 constants at one temperature from labelled dwells (T(10) or
//! least squares), and the temperature model through the constants at several temperatures
//! (T(11)/T(12), `bins_comp::ident`) with the calibration's T0 and temperature range.

use super::segments::Segment;
use anyhow::{anyhow, bail};
use bins_comp::ident::{self, FitError, TILTER_POSITIONS_G};
use bins_comp::{CalibrationParams, CoefDelta, Constants, Method, TempModel};

/// The temperature model requested.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ModelArg {
    /// `pwl` with two or more temperatures, `none` with one.
    Auto,
    /// T0 constants only.
    None,
    /// Piecewise-linear through the calibration temperatures, T(12).
    Pwl,
    /// Polynomial of this order (1..=4), T(11)/least squares.
    Poly(usize),
}

/// Parses `--model`: `auto`, `none`, `pwl` or `poly:N` (N = 1..4).
pub fn parse_model(s: &str) -> anyhow::Result<ModelArg> {
    Ok(match s {
        "auto" => ModelArg::Auto,
        "none" => ModelArg::None,
        "pwl" => ModelArg::Pwl,
        _ => ModelArg::Poly(
            s.strip_prefix("poly:")
                .and_then(|n| n.parse::<usize>().ok())
                .filter(|n| (1..=4).contains(n))
                .ok_or_else(|| anyhow!("--model `{s}`: expected auto, none, pwl or poly:N with N in 1..=4"))?,
        ),
    })
}

/// The constants identified at one temperature.
pub struct TempFit<'a> {
    /// Mean temperature of its dwells [°C].
    pub temp_c: f64,
    /// The dwells used.
    pub segments: Vec<&'a Segment>,
    /// The constants.
    pub constants: Constants<f64>,
    /// `T(10)` or `LS`.
    pub how: &'static str,
    /// Residual of each dwell, `U − (K·f + U0)` in g (divided by K_ii), per axis.
    pub residual_g: Vec<[f64; 3]>,
}

/// The constants at one temperature from its dwells.
pub fn fit_temperature<'a>(temp_c: f64, segs: Vec<&'a Segment>, files: &str) -> anyhow::Result<TempFit<'a>> {
    let f: Vec<[f64; 3]> = segs.iter().map(|s| s.f_g).collect();
    let u: Vec<[f64; 3]> = segs.iter().map(|s| s.mean_u_v).collect();
    let labels: Vec<&str> = segs.iter().map(|s| s.pos.as_str()).collect();
    let six: Option<[[f64; 3]; 6]> = (segs.len() == 6)
        .then(|| {
            let mut out = [[0.0; 3]; 6];
            for (k, ideal) in TILTER_POSITIONS_G.iter().enumerate() {
                let s = segs.iter().find(|s| s.pos == format!("TP{}", k + 1) && s.f_g == *ideal)?;
                out[k] = s.mean_u_v;
            }
            Some(out)
        })
        .flatten();
    let (constants, how) = match six {
        Some(u6) => (ident::six_position(&u6), "T(10)"),
        None => {
            let c = ident::fit_constants(&f, &u).map_err(|e| match e {
                FitError::TooFewPoints { got, .. } => {
                    let missing: Vec<String> =
                        (1..=6).map(|k| format!("TP{k}")).filter(|p| !labels.contains(&p.as_str())).collect();
                    anyhow!(
                        "{files}: at {temp_c:.2} °C only {got} stationary dwell(s) ({}); the 12 constants need at least 4 positions (missing: {})",
                        labels.join(", "),
                        missing.join(", ")
                    )
                }
                FitError::Singular => anyhow!(
                    "{files}: at {temp_c:.2} °C the dwells ({}) do not determine the constants (singular fit: positions coplanar)",
                    labels.join(", ")
                ),
                e => anyhow!("{files}: at {temp_c:.2} °C: {e}"),
            })?;
            (c, "LS")
        }
    };
    let k = &constants.k_v_per_g;
    let residual_g = segs
        .iter()
        .map(|s| {
            let mut r = [0.0; 3];
            for i in 0..3 {
                let model = k[i][0] * s.f_g[0] + k[i][1] * s.f_g[1] + k[i][2] * s.f_g[2] + constants.u0_v[i];
                r[i] = (s.mean_u_v[i] - model) / k[i][i];
            }
            r
        })
        .collect();
    Ok(TempFit { temp_c, segments: segs, constants, how, residual_g })
}

/// How the temperature model is built from the constants at the calibration temperatures.
#[derive(Clone, Debug)]
pub struct ModelRequest {
    /// Requested T0 [°C]: the temperature nearest to it gives the T0 constants.
    pub t0_c: f64,
    /// The model.
    pub model: ModelArg,
    /// For `pwl`: only the temperatures nearest to these [°C] as knots (empty: all).
    pub knots: Vec<f64>,
    /// Temperatures within this of each other are one [°C].
    pub temp_tol_c: f64,
    /// The compensation method (with a temperature model).
    pub method: Method,
}

/// The calibration from the constants at each temperature (`points`, any order): T0 is the
/// measured temperature nearest to `req.t0_c`, the model is T(12) (`pwl`) or T(11)/least
/// squares (`poly:N`) through the others. `kept_temps_c` are the temperatures of every used
/// dwell (the range of a T0-only calibration). Returns the parameters and the notes for the
/// file's header; errors name `files`.
pub fn calibration_params(
    points: &[(f64, Constants<f64>)],
    kept_temps_c: &[f64],
    req: &ModelRequest,
    files: &str,
) -> anyhow::Result<(CalibrationParams, Vec<String>)> {
    if points.is_empty() {
        bail!("{files}: no constants at any temperature");
    }
    // T0: the temperature nearest to --t0.
    let i0 = (0..points.len())
        .min_by(|&a, &b| (points[a].0 - req.t0_c).abs().total_cmp(&(points[b].0 - req.t0_c).abs()))
        .unwrap_or(0);
    if (points[i0].0 - req.t0_c).abs() > req.temp_tol_c {
        let temps: Vec<String> = points.iter().map(|f| format!("{:.2}", f.0)).collect();
        bail!(
            "{files}: no dwells at T0 = {} °C (within {} °C); the recordings have {} °C",
            req.t0_c,
            req.temp_tol_c,
            temps.join(", ")
        );
    }
    let t0 = points[i0].0;
    let c0 = points[i0].1;
    let others: Vec<(f64, Constants<f64>)> =
        points.iter().enumerate().filter(|(i, _)| *i != i0).map(|(_, f)| *f).collect();
    let model_arg = match req.model {
        ModelArg::Auto if others.is_empty() => ModelArg::None,
        ModelArg::Auto => ModelArg::Pwl,
        m => m,
    };
    let mut notes: Vec<String> =
        vec![format!("T0 = {t0:.2} °C: the measured mean temperature of the dwells nearest to --t0 {}", req.t0_c)];
    let (model, method, range) = match model_arg {
        ModelArg::None | ModelArg::Auto => {
            notes.push(format!(
                "one temperature only ({t0:.2} °C): T0 constants only, no temperature model (method: uncorrected)"
            ));
            let lo = kept_temps_c.iter().copied().fold(t0, f64::min);
            let hi = kept_temps_c.iter().copied().fold(t0, f64::max);
            let zero = TempModel::Poly { order: 1, coef: [CoefDelta::zero(); 4] };
            (zero, Method::Uncorrected, ((lo - 1.0).floor(), (hi + 1.0).ceil()))
        }
        ModelArg::Pwl => {
            if others.is_empty() {
                bail!(
                    "{files}: only one temperature ({t0:.2} °C): the piecewise-linear model needs at least one more (use --model none for T0 constants only)"
                );
            }
            let chosen: Vec<(f64, Constants<f64>)> = if req.knots.is_empty() {
                others.clone()
            } else {
                let mut v: Vec<(f64, Constants<f64>)> = Vec::new();
                for k in &req.knots {
                    if (k - req.t0_c).abs() <= req.temp_tol_c {
                        continue;
                    }
                    let best = others
                        .iter()
                        .min_by(|a, b| (a.0 - k).abs().total_cmp(&(b.0 - k).abs()))
                        .filter(|p| (p.0 - k).abs() <= req.temp_tol_c)
                        .ok_or_else(|| {
                            anyhow!("{files}: --knots {k}: no calibration temperature within {} °C", req.temp_tol_c)
                        })?;
                    if !v.iter().any(|p| p.0 == best.0) {
                        v.push(*best);
                    }
                }
                v
            };
            let m = ident::pwl_from_constants(t0, &c0, &chosen)
                .map_err(|e| anyhow!("{files}: piecewise-linear model: {e}"))?;
            let lo = chosen.iter().map(|p| p.0).fold(t0, f64::min);
            let hi = chosen.iter().map(|p| p.0).fold(t0, f64::max);
            (m, req.method, (lo, hi))
        }
        ModelArg::Poly(order) => {
            let m = ident::poly_from_constants(t0, &c0, &others, order).map_err(|e| match e {
                FitError::TooFewPoints { needed, got } => anyhow!(
                    "{files}: a polynomial of order {order} needs at least {needed} temperature(s) besides T0 = {t0:.2} °C, the recordings have {got}"
                ),
                e => anyhow!("{files}: polynomial model: {e}"),
            })?;
            let lo = others.iter().map(|p| p.0).fold(t0, f64::min);
            let hi = others.iter().map(|p| p.0).fold(t0, f64::max);
            (m, req.method, (lo, hi))
        }
    };
    Ok((CalibrationParams { constants: c0, t0_c: t0, model, method, temp_range_c: range }, notes))
}

/// The temperature model's residual at one calibration temperature: the largest
/// `|ΔU0|/K_ii` \[g\] and `|ΔK_ij|/K_ii` of the model's constants against the measured ones.
pub fn model_residual(params: &CalibrationParams, temp_c: f64, measured: &Constants<f64>) -> (f64, f64) {
    let m = params.constants_at(temp_c);
    let (mut du, mut dk) = (0.0f64, 0.0f64);
    for i in 0..3 {
        du = du.max(((m.u0_v[i] - measured.u0_v[i]) / measured.k_v_per_g[i][i]).abs());
        for j in 0..3 {
            dk = dk.max(((m.k_v_per_g[i][j] - measured.k_v_per_g[i][j]) / measured.k_v_per_g[i][i]).abs());
        }
    }
    (du, dk)
}
