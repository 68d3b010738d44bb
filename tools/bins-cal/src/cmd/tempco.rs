//! `bins-cal tempco`: the temperature coefficients of T(3)/T(4) from the constants measured at
//! several temperatures — T(12) for the piecewise-linear model (slopes between consecutive
//! knots; the paper's Table T3 for knots −40, +20, +70 °C), T(11) or least squares for the
//! polynomial. Prints a table and optionally writes JSON.

use anyhow::{Context, anyhow, bail};
use bins_cal::{constants_table, fsio};
use bins_comp::{CoefDelta, TempModel, ident};
use serde_json::{Map, Value, json};
use std::path::PathBuf;

/// Arguments of `bins-cal tempco`.
#[derive(clap::Args)]
pub struct Args {
    /// Constants table (CSV: temp_C, Kxx … Kzz, U0x … U0z), one row per temperature.
    #[arg(long)]
    constants: PathBuf,
    /// The reference temperature T0 [°C]; the table must have a row at T0.
    #[arg(long, default_value_t = 20.0)]
    t0: f64,
    /// `pwl` (piecewise-linear through every temperature) or `poly:N` (order N = 1..4).
    #[arg(long, default_value = "pwl")]
    model: String,
    /// Write the coefficients as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
}

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

const AXES: [&str; 3] = ["x", "y", "z"];

/// `{"x":…,"y":…,"z":…}`, `{"xx":…,"yy":…,"zz":…}` and the six `γ` pairs of a coefficient set.
fn coef_json(c: &CoefDelta<f64>) -> (Value, Value, Value) {
    let mut alpha = Map::new();
    let mut beta = Map::new();
    let mut gamma = Map::new();
    for i in 0..3 {
        alpha.insert(AXES[i].into(), json!(c.du0_v[i]));
        for j in 0..3 {
            let key = format!("{}{}", AXES[i], AXES[j]);
            if i == j {
                beta.insert(key, json!(c.rel_k[i][j]));
            } else {
                gamma.insert(key, json!(c.rel_k[i][j]));
            }
        }
    }
    (Value::Object(alpha), Value::Object(beta), Value::Object(gamma))
}

/// Slopes of every coefficient between two knots.
fn slope(a: &CoefDelta<f64>, b: &CoefDelta<f64>, dt: f64) -> CoefDelta<f64> {
    let (x, y) = (a.to_array(), b.to_array());
    let mut s = [0.0; 12];
    for k in 0..12 {
        s[k] = (y[k] - x[k]) / dt;
    }
    CoefDelta::from_array(&s)
}

/// Identifies the model and returns its JSON description (keys `alpha_V_per_C`,
/// `beta_per_C`, `gamma_per_C` per range or per power).
pub fn tempco_json(points: &[(f64, bins_comp::Constants<f64>)], t0_c: f64, spec: ModelSpec) -> anyhow::Result<Value> {
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
            let ranges: Vec<Value> = (0..n - 1)
                .map(|l| {
                    let s = slope(&at_knot[l], &at_knot[l + 1], knots_c[l + 1] - knots_c[l]);
                    let (a, b, g) = coef_json(&s);
                    json!({"from_C": knots_c[l], "to_C": knots_c[l + 1], "alpha_V_per_C": a, "beta_per_C": b, "gamma_per_C": g})
                })
                .collect();
            Ok(json!({"model": "pwl", "t0_C": t0_c, "ranges": ranges}))
        }
        ModelSpec::Poly(order) => {
            let model = ident::poly_from_constants(t0_c, &c0, &others, order).map_err(|e| match e {
                ident::FitError::TooFewPoints { needed, got } => anyhow!(
                    "a polynomial of order {order} needs at least {needed} temperatures besides T0 = {t0_c} °C, the table has {got}"
                ),
                e => anyhow!("{e}"),
            })?;
            let TempModel::Poly { coef, .. } = model else { unreachable!("poly") };
            let terms: Vec<Value> = (0..order)
                .map(|n| {
                    let (a, b, g) = coef_json(&coef[n]);
                    json!({"power": n + 1, "alpha_V_per_C": a, "beta_per_C": b, "gamma_per_C": g})
                })
                .collect();
            Ok(
                json!({"model": "poly", "order": order, "t0_C": t0_c, "units_note": "coefficients of the term of power n are per °C^n", "terms": terms}),
            )
        }
    }
}

/// Runs `bins-cal tempco`.
pub fn run(args: Args) -> anyhow::Result<()> {
    fsio::refuse_overwriting_inputs([&args.constants], &args.json)?;
    let spec: ModelSpec = args.model.parse()?;
    let points = constants_table::read(&args.constants)?;
    let out = tempco_json(&points, args.t0, spec).with_context(|| format!("{}", args.constants.display()))?;
    print_table(&out);
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&out)? + "\n";
        fsio::write_atomic(path, text.as_bytes())?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

fn print_table(v: &Value) {
    let blocks: Vec<(String, &Value)> = match v["model"].as_str() {
        Some("pwl") => v["ranges"]
            .as_array()
            .into_iter()
            .flatten()
            .map(|r| (format!("{:+} … {:+} °C", r["from_C"], r["to_C"]), r))
            .collect(),
        _ => v["terms"].as_array().into_iter().flatten().map(|r| (format!("ΔT^{}", r["power"]), r)).collect(),
    };
    print!("{:<10}", "coef");
    for (name, _) in &blocks {
        print!("{name:>22}");
    }
    println!();
    let rows: [(&str, &str, [&str; 3]); 3] = [
        ("beta_per_C", "β_", ["xx", "yy", "zz"]),
        ("alpha_V_per_C", "α_", ["x", "y", "z"]),
        ("gamma_per_C", "γ_", ["xy", "xz", "yx"]),
    ];
    let mut all_rows: Vec<(&str, String)> = Vec::new();
    for (key, prefix, names) in rows {
        for n in names {
            all_rows.push((key, format!("{prefix}{n}|{n}")));
        }
    }
    for n in ["yz", "zx", "zy"] {
        all_rows.push(("gamma_per_C", format!("γ_{n}|{n}")));
    }
    for (key, label) in all_rows {
        let (shown, field) = label.split_once('|').unwrap_or((&label, &label));
        print!("{shown:<10}");
        for (_, b) in &blocks {
            print!("{:>22.8e}", b[key][field].as_f64().unwrap_or(f64::NAN));
        }
        println!();
    }
}
