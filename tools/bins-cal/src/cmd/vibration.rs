//! `bins-cal vibration`: the vibration error of a conversion function V(2) in a vibration
//! environment — V(13) (harmonic) and V(14) (random) split as V(15)/V(16) — in the paper's
//! variant (reproduces Tables V4/V5) or the exact one. Each environment entry gives ranges
//! (low, high); the table shows the VE at both ends.

use anyhow::{anyhow, bail};
use bins_cal::recording::Table;
use bins_comp::vibration::{AccelAxes, AccelVibration, ConversionFunction, Variant, VeTerms, ve_terms};
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// Arguments of `bins-cal vibration`.
#[derive(clap::Args)]
pub struct Args {
    /// Conversion-function coefficients (CSV in the units of Table V1: a0_mg, K1_V_per_g,
    /// delta_1A_ppm, k2_ug_per_g2 … k5_ug_per_g5, m1_mg_per_g, m2_mg_per_g, m31_ug_per_g2,
    /// m32_ug_per_g2), one accelerometer per row.
    #[arg(long)]
    cf: PathBuf,
    /// Vibration environment (TOML: `a_p3_g`, `[[harmonic]]` and `[[random]]` entries).
    #[arg(long)]
    env: PathBuf,
    /// `paper` (V(13)/V(14) as printed) or `exact` (true time means).
    #[arg(long, default_value = "paper")]
    variant: String,
}

/// The environment file.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct Env {
    /// Static acceleration along IA at which the multiplicative parts are evaluated \[g\]
    /// (the paper: the range limit, 10 g).
    pub a_p3_g: f64,
    /// Harmonic entries.
    #[serde(default)]
    pub harmonic: Vec<HarmonicEntry>,
    /// Broadband random entries.
    #[serde(default)]
    pub random: Vec<RandomEntry>,
}

/// A harmonic environment V(3): amplitude ranges along IA, OA, PA (in phase).
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct HarmonicEntry {
    /// Row label.
    pub label: String,
    /// Amplitude along IA (low, high) \[g\].
    #[serde(deserialize_with = "bins_cal::exact::array")]
    pub ia_amp_g: [f64; 2],
    /// Amplitude along OA (low, high) \[g\].
    #[serde(deserialize_with = "bins_cal::exact::array")]
    pub oa_amp_g: [f64; 2],
    /// Amplitude along PA (low, high) \[g\].
    #[serde(deserialize_with = "bins_cal::exact::array")]
    pub pa_amp_g: [f64; 2],
}

/// A random environment V(4)–V(6): flat density over a band, the same along IA, OA, PA and
/// fully correlated.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct RandomEntry {
    /// Row label.
    pub label: String,
    /// Band (f_low, f_up) \[Hz\].
    #[serde(rename = "band_Hz")]
    #[serde(deserialize_with = "bins_cal::exact::array")]
    pub band_hz: [f64; 2],
    /// Spectral density range (low, high) [g²/Hz].
    #[serde(rename = "psd_g2_per_Hz")]
    #[serde(deserialize_with = "bins_cal::exact::array")]
    pub psd_g2_per_hz: [f64; 2],
}

/// Largest |K1| \[V/g\] of a conversion function.
pub const MAX_K1_V_PER_G: f64 = 1.0e3;
/// Largest amplitude of a harmonic environment and σ of a random one \[g\].
pub const MAX_ENV_G: f64 = 100.0;
/// Highest frequency of a random environment's band \[Hz\].
pub const MAX_ENV_HZ: f64 = 1.0e6;

/// Reads conversion functions from a Table V1-style CSV (errors name file, line, column).
pub fn read_cf(path: &Path) -> anyhow::Result<Vec<(f64, ConversionFunction<f64>)>> {
    let table = Table::read(path)?;
    // (column, scale to g units)
    let cols: [(&str, f64); 11] = [
        ("a0_mg", 1e-3),
        ("K1_V_per_g", 1.0),
        ("delta_1A_ppm", 1e-6),
        ("k2_ug_per_g2", 1e-6),
        ("k3_ug_per_g3", 1e-6),
        ("k4_ug_per_g4", 1e-6),
        ("k5_ug_per_g5", 1e-6),
        ("m1_mg_per_g", 1e-3),
        ("m2_mg_per_g", 1e-3),
        ("m31_ug_per_g2", 1e-6),
        ("m32_ug_per_g2", 1e-6),
    ];
    let idx: Vec<usize> = cols.iter().map(|(name, _)| table.column(name)).collect::<Result<_, _>>()?;
    let mut out = Vec::new();
    for (line, cells) in &table.rows {
        let mut v = [0.0; 11];
        for (k, (&c, (_, scale))) in idx.iter().zip(cols.iter()).enumerate() {
            v[k] = table.number(*line, cells, c)? * scale;
        }
        let cf = ConversionFunction {
            a0_g: v[0],
            delta_1a: v[2],
            k2_g_per_g2: v[3],
            k3_g_per_g3: v[4],
            k4_g_per_g4: v[5],
            k5_g_per_g5: v[6],
            m1_g_per_g: v[7],
            m2_g_per_g: v[8],
            m31_g_per_g2: v[9],
            m32_g_per_g2: v[10],
        };
        // Each coefficient within the firmware's limit (blob::coefficient_limit: a nonlinear
        // term within 1 g at the 10 g full scale), said in the column's own unit.
        for (k, (&c, (name, scale))) in idx.iter().zip(cols.iter()).enumerate() {
            if k == 1 {
                continue;
            }
            let limit_g = bins_comp::blob::coefficient_limit(if k == 0 { 0 } else { (k - 1) as u8 });
            if !(v[k].abs() <= limit_g) {
                let unit = name.split_once('_').map_or("", |(_, u)| u);
                bail!(
                    "{}:{line}, column {} `{name}`: `{}` is beyond ±{} ({unit}), the firmware's limit of this coefficient (a term of at most 1 g at the 10 g full scale; a0 1 g, δ_1A 0.1, m1 and m2 0.5 g/g)",
                    path.display(),
                    c + 1,
                    cells[c],
                    limit_g / scale
                );
            }
        }
        if !(v[1] != 0.0 && v[1].abs() <= MAX_K1_V_PER_G) {
            bail!(
                "{}:{line}, column `K1_V_per_g`: {} V/g: the scale factor must be nonzero and within ±{MAX_K1_V_PER_G} V/g",
                path.display(),
                v[1]
            );
        }
        out.push((v[1], cf));
    }
    if out.is_empty() {
        bail!("{}: no data rows", path.display());
    }
    Ok(out)
}

/// Reads an environment file (errors name the file and the key).
pub fn read_env(path: &Path) -> anyhow::Result<Env> {
    let text = bins_cal::fsio::read_text(path)?;
    let env: Env = toml::from_str(&text)
        .map_err(|e| anyhow!("{}: {}", path.display(), bins_cal::calfile::one_line(&e.to_string())))?;
    let bad = |what: &str| Err(anyhow!("{}: {what}", path.display()));
    if !(env.a_p3_g.is_finite() && env.a_p3_g.abs() <= 100.0) {
        return bad("`a_p3_g` must be a finite acceleration within ±100 g");
    }
    for h in &env.harmonic {
        for (k, r) in [("ia_amp_g", h.ia_amp_g), ("oa_amp_g", h.oa_amp_g), ("pa_amp_g", h.pa_amp_g)] {
            if !(r.iter().all(|x| x.is_finite() && *x >= 0.0 && *x <= MAX_ENV_G) && r[0] <= r[1]) {
                return bad(&format!(
                    "harmonic `{}`: `{k}` must be a range [low, high] of amplitudes from 0 to {MAX_ENV_G} g",
                    h.label
                ));
            }
        }
    }
    for r in &env.random {
        if !(r.band_hz.iter().all(|x| x.is_finite() && *x >= 0.0 && *x <= MAX_ENV_HZ) && r.band_hz[0] < r.band_hz[1]) {
            return bad(&format!(
                "random `{}`: `band_Hz` must be [low, high] with 0 ≤ low < high ≤ {MAX_ENV_HZ:e} Hz",
                r.label
            ));
        }
        if !(r.psd_g2_per_hz.iter().all(|x| x.is_finite() && *x >= 0.0) && r.psd_g2_per_hz[0] <= r.psd_g2_per_hz[1]) {
            return bad(&format!("random `{}`: `psd_g2_per_Hz` must be a range [low, high] ≥ 0", r.label));
        }
        // σ = √(PSD·bandwidth).
        let sigma_g = (r.psd_g2_per_hz[1] * (r.band_hz[1] - r.band_hz[0])).sqrt();
        if !(sigma_g <= MAX_ENV_G) {
            return bad(&format!(
                "random `{}`: `psd_g2_per_Hz` {} over {} Hz is σ = {sigma_g} g, more than {MAX_ENV_G} g",
                r.label,
                r.psd_g2_per_hz[1],
                r.band_hz[1] - r.band_hz[0]
            ));
        }
    }
    if env.harmonic.is_empty() && env.random.is_empty() {
        return bad("no [[harmonic]] or [[random]] entry");
    }
    Ok(env)
}

/// One table row: label and the terms at the low and high ends.
pub type Row = (String, VeTerms<f64>, VeTerms<f64>);

/// The VE table of `cf` in `env`.
pub fn table(cf: &ConversionFunction<f64>, env: &Env, variant: Variant) -> Vec<Row> {
    let mut rows = Vec::new();
    for h in &env.harmonic {
        let at = |k: usize| {
            let amp = AccelAxes { ia: h.ia_amp_g[k], oa: h.oa_amp_g[k], pa: h.pa_amp_g[k] };
            ve_terms(cf, variant, &AccelVibration::Harmonic(amp), env.a_p3_g)
        };
        rows.push((h.label.clone(), at(0), at(1)));
    }
    for r in &env.random {
        let at = |k: usize| {
            let s = (r.psd_g2_per_hz[k] * (r.band_hz[1] - r.band_hz[0])).sqrt();
            ve_terms(cf, variant, &AccelVibration::Random(AccelAxes { ia: s, oa: s, pa: s }), env.a_p3_g)
        };
        rows.push((r.label.clone(), at(0), at(1)));
    }
    rows
}

/// Runs `bins-cal vibration`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let variant = match args.variant.as_str() {
        "paper" => Variant::Paper,
        "exact" => Variant::Exact,
        v => bail!("--variant `{v}`: expected `paper` or `exact`"),
    };
    let cfs = read_cf(&args.cf)?;
    let env = read_env(&args.env)?;
    let a = env.a_p3_g;
    // Every value of the table finite, or the entry and accelerometer named.
    for (n, (_, cf)) in cfs.iter().enumerate() {
        for (label, lo, hi) in table(cf, &env, variant) {
            if ![lo, hi].iter().all(|t| {
                t.total_g(a).is_finite() && t.d0_1_g.is_finite() && t.d0_2_g.is_finite() && t.d0_3_g.is_finite()
            }) {
                bail!(
                    "{} and {}: the vibration error of accelerometer {} in `{label}` is not finite (coefficients or environment out of range)",
                    args.cf.display(),
                    args.env.display(),
                    n + 1
                );
            }
        }
    }
    for (n, (k1, cf)) in cfs.iter().enumerate() {
        println!(
            "accelerometer {} (K1 = {k1} V/g), {} variant, a_p3 = {a} g; each cell low … high",
            n + 1,
            args.variant
        );
        println!(
            "{:<24}{:>22}{:>22}{:>22}{:>22}{:>22}{:>22}{:>22}",
            "environment",
            "Δ0(1) µg",
            "Δ0(2) µg",
            "Δ0(3) µg",
            "δ(1)a_p3 mg",
            "δ(2)a_p3² mg",
            "δ(3)a_p3³ mg",
            "total mg"
        );
        for (label, lo, hi) in table(cf, &env, variant) {
            let cell = |f: &dyn Fn(&VeTerms<f64>) -> f64| format!("{:>10.4} … {:<9.4}", f(&lo), f(&hi));
            println!(
                "{label:<24}{:>22}{:>22}{:>22}{:>22}{:>22}{:>22}{:>22}",
                cell(&|t| t.d0_1_g * 1e6),
                cell(&|t| t.d0_2_g * 1e6),
                cell(&|t| t.d0_3_g * 1e6),
                cell(&|t| t.delta1_g_per_g * a * 1e3),
                cell(&|t| t.delta2_g_per_g2 * a * a * 1e3),
                cell(&|t| t.delta3_g_per_g3 * a * a * a * 1e3),
                cell(&|t| t.total_g(a) * 1e3),
            );
        }
    }
    Ok(())
}
