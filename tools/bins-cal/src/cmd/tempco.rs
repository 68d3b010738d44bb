//! `bins-cal tempco`: the temperature coefficients of T(3)/T(4) from the constants measured at
//! several temperatures — T(12) for the piecewise-linear model (slopes between consecutive
//! knots; the paper's Table T3 for knots −40, +20, +70 °C), T(11) or least squares for the
//! polynomial ([`bins_cal::calib::tempco`]). Prints a table and optionally writes JSON.

use anyhow::Context;
use bins_cal::calib::tempco::{self, ModelSpec, Tempco};
use bins_cal::{constants_table, fsio};
use bins_comp::CoefDelta;
use serde_json::{Map, Value, json};
use std::path::PathBuf;

/// Arguments of `bins-cal tempco`.
#[derive(clap::Args)]
pub struct Args {
    /// Constants table (CSV: temp_C, Kxx … Kzz, U0x … U0z), one row per temperature.
    #[arg(long)]
    constants: PathBuf,
    /// The reference temperature T0 [°C]; the table must have a row at T0.
    #[arg(long, default_value_t = 20.0, value_parser = bins_cal::numarg::temp_c)]
    t0: f64,
    /// `pwl` (piecewise-linear through every temperature) or `poly:N` (order N = 1..4).
    #[arg(long, default_value = "pwl")]
    model: String,
    /// Write the coefficients as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
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

/// Identifies the model and returns its JSON description (keys `alpha_V_per_C`,
/// `beta_per_C`, `gamma_per_C` per range or per power).
pub fn tempco_json(points: &[(f64, bins_comp::Constants<f64>)], t0_c: f64, spec: ModelSpec) -> anyhow::Result<Value> {
    match tempco::identify(points, t0_c, spec)? {
        Tempco::Pwl(ranges) => {
            let ranges: Vec<Value> = ranges
                .iter()
                .map(|(from, to, s)| {
                    let (a, b, g) = coef_json(s);
                    json!({"from_C": from, "to_C": to, "alpha_V_per_C": a, "beta_per_C": b, "gamma_per_C": g})
                })
                .collect();
            Ok(json!({"model": "pwl", "t0_C": t0_c, "ranges": ranges}))
        }
        Tempco::Poly(coef) => {
            let order = coef.len();
            let terms: Vec<Value> = coef
                .iter()
                .enumerate()
                .map(|(n, c)| {
                    let (a, b, g) = coef_json(c);
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
