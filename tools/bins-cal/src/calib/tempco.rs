//! The temperature coefficients of T(3)/T(4) from the constants at several temperatures
//! (`bins-cal tempco`): T(12) for the piecewise-linear model (the slopes between consecutive
//! knots; the paper's Table T3 for knots −40, +20, +70 °C), T(11) or least squares for the
//! polynomial, by `bins_comp::ident`.

use anyhow::{anyhow, bail};
use bins_comp::{CoefDelta, Constants, TempModel, ident};

/// The model requested on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModelSpec {
    /// Piecewise-linear.
    Pwl,
    /// Polynomial of this order.
    Poly(usize),
}

impl std::str::FromStr for ModelSpec {
    type Err = anyhow::Error;
    fn from_str(s: &str) -> anyhow::Result<Self> {
        match s {
            "pwl" => Ok(ModelSpec::Pwl),
            _ => {
                let n = s
                    .strip_prefix("poly:")
                    .and_then(|n| n.parse::<usize>().ok())
                    .filter(|n| (1..=4).contains(n))
                    .ok_or_else(|| anyhow!("--model `{s}`: expected `pwl` or `poly:N` with N in 1..=4"))?;
                Ok(ModelSpec::Poly(n))
            }
        }
    }
}

/// The identified coefficients.
#[derive(Clone, Debug, PartialEq)]
pub enum Tempco {
    /// Per range between consecutive knots: from, to [°C] and the slopes (per °C).
    Pwl(Vec<(f64, f64, CoefDelta<f64>)>),
    /// Per power n = 1…order: the coefficients (per °Cⁿ).
    Poly(Vec<CoefDelta<f64>>),
}

/// Slopes of every coefficient between two knots.
pub fn slope(a: &CoefDelta<f64>, b: &CoefDelta<f64>, dt: f64) -> CoefDelta<f64> {
    let (x, y) = (a.to_array(), b.to_array());
    let mut s = [0.0; 12];
    for k in 0..12 {
        s[k] = (y[k] - x[k]) / dt;
    }
    CoefDelta::from_array(&s)
}

/// Identifies the model from the constants at each temperature (`points`, one at `t0_c`).
pub fn identify(points: &[(f64, Constants<f64>)], t0_c: f64, spec: ModelSpec) -> anyhow::Result<Tempco> {
    let c0 =
        points.iter().find(|(t, _)| *t == t0_c).map(|(_, c)| *c).ok_or_else(|| anyhow!("no row at T0 = {t0_c} °C"))?;
    let others: Vec<_> = points.iter().filter(|(t, _)| *t != t0_c).copied().collect();
    match spec {
        ModelSpec::Pwl => {
            if others.is_empty() {
                bail!("the piecewise-linear model needs at least one temperature besides T0 = {t0_c} °C");
            }
            let model = ident::pwl_from_constants(t0_c, &c0, &others).map_err(|e| anyhow!("{e}"))?;
            let TempModel::Pwl { n_knots, knots_c, at_knot } = model else { unreachable!("pwl") };
            let n = n_knots as usize;
            Ok(Tempco::Pwl(
                (0..n - 1)
                    .map(|l| {
                        let s = slope(&at_knot[l], &at_knot[l + 1], knots_c[l + 1] - knots_c[l]);
                        (knots_c[l], knots_c[l + 1], s)
                    })
                    .collect(),
            ))
        }
        ModelSpec::Poly(order) => {
            let model = ident::poly_from_constants(t0_c, &c0, &others, order).map_err(|e| match e {
                ident::FitError::TooFewPoints { needed, got } => anyhow!(
                    "a polynomial of order {order} needs at least {needed} temperatures besides T0 = {t0_c} °C, the table has {got}"
                ),
                e => anyhow!("{e}"),
            })?;
            let TempModel::Poly { coef, .. } = model else { unreachable!("poly") };
            Ok(Tempco::Poly(coef[..order].to_vec()))
        }
    }
}
