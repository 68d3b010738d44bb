//! What `bins-cal allan` writes: the table, the JSON and CSV of the curves and terms, the
//! twin scenario with the fitted `[noise]` table, and the Kalibr `imu.yaml`. Every number's
//! unit is in its key or header.

use super::pass::Analysis;
use super::terms::{self, FLICKER_FLOOR, Terms};
use super::twin::{self, TwinNoise};
use super::{Point, estimate};
use serde_json::{Value, json};
use std::fmt::Write as _;

/// Standard gravity \[m/s²\]: g to m/s².
pub const G0: f64 = 9.806_65;

/// One channel as shown: its points and terms in the display unit.
#[derive(Clone, Debug)]
pub struct Shown {
    /// Column name.
    pub name: String,
    /// Display unit: `g` (through a scale factor), `V` or `°C`.
    pub unit: &'static str,
    /// The scale factor used \[V/g\], for the accelerometers shown in g.
    pub scale_v_per_g: Option<f64>,
    /// The curve in the display unit.
    pub points: Vec<Point>,
    /// The terms in the display unit.
    pub terms: Terms,
    /// The step of the values in the display unit (0: none).
    pub resolution: f64,
}

/// The channels of `a` in their display units: an accelerometer with a scale factor
/// (`scales[i]` for `ux_V`, `uy_V`, `uz_V`) in g, otherwise in its recording unit; the terms
/// fitted to the points that have degrees of freedom.
pub fn shown(a: &Analysis, scales: Option<[f64; 3]>) -> Vec<Shown> {
    a.channels
        .iter()
        .map(|c| {
            let axis = super::pass::CHANNELS.iter().position(|x| x.0 == c.name).filter(|&i| i < 3);
            let scale = axis.and_then(|i| scales.map(|s| s[i]));
            let (unit, factor) = match scale {
                Some(s) => ("g", 1.0 / s),
                None => (c.unit, 1.0),
            };
            let points: Vec<Point> = c.points.iter().map(|p| p.scaled(factor)).collect();
            let fit: Vec<(f64, f64, f64)> =
                points.iter().map(|p| (p.tau_s, p.dev * p.dev, p.edf.unwrap_or(f64::NAN))).collect();
            Shown {
                name: c.name.clone(),
                unit,
                scale_v_per_g: scale,
                terms: terms::fit(&fit),
                points,
                resolution: c.resolution * factor,
            }
        })
        .collect()
}

/// The terms with their units spelled out, as `(key, value, label)`: keys carry the unit.
pub fn term_rows(t: &Terms, unit: &str) -> Vec<(String, f64, String)> {
    let mut v = vec![
        (format!("quantization_{u}_s", u = key_unit(unit)), t.q, format!("quantisation Q [{unit}·s]")),
        (
            format!("white_{u}_per_sqrt_Hz", u = key_unit(unit)),
            t.n,
            format!("white noise N [{unit}/√Hz] (velocity random walk)"),
        ),
        (
            format!("bias_instability_{u}", u = key_unit(unit)),
            t.b,
            format!("bias instability B [{unit}] (floor 0.664·B)"),
        ),
        (
            format!("random_walk_{u}_per_sqrt_s", u = key_unit(unit)),
            t.k,
            format!("random walk K [{unit}/√s] (acceleration random walk)"),
        ),
        (format!("ramp_{u}_per_s", u = key_unit(unit)), t.r, format!("ramp R [{unit}/s]")),
    ];
    if unit == "g" {
        v.extend([
            ("velocity_random_walk_ug_per_sqrt_Hz".into(), t.n * 1e6, "velocity random walk [µg/√Hz]".into()),
            ("velocity_random_walk_m_per_s_per_sqrt_h".into(), t.n * G0 * 60.0, "velocity random walk [m/s/√h]".into()),
            ("bias_instability_ug".into(), t.b * 1e6, "bias instability [µg]".into()),
            ("acceleration_random_walk_ug_per_sqrt_s".into(), t.k * 1e6, "acceleration random walk [µg/√s]".into()),
            (
                "acceleration_random_walk_m_per_s2_per_sqrt_h".into(),
                t.k * G0 * 60.0,
                "acceleration random walk [m/s²/√h]".into(),
            ),
            ("ramp_ug_per_h".into(), t.r * 1e6 * 3600.0, "ramp [µg/h]".into()),
            ("quantization_m_per_s".into(), t.q * G0, "quantisation [m/s]".into()),
        ]);
    }
    v
}

fn key_unit(unit: &str) -> &'static str {
    match unit {
        "g" => "g",
        "V" => "V",
        _ => "C",
    }
}

/// What the estimator did, in words.
pub fn estimator_note(exact_max_m: usize, tau0_s: f64) -> String {
    format!(
        "overlapping Allan deviation; fully overlapping up to m = {exact_max_m} samples ({:.6} s), beyond it a cluster starts every m/{} samples (partially overlapping)",
        exact_max_m as f64 * tau0_s,
        estimate::PARTIAL_POSITIONS
    )
}

/// The JSON of an analysis.
pub fn json(a: &Analysis, shown: &[Shown], exact_max_m: usize, level: f64) -> Value {
    let channels: Vec<Value> = shown
        .iter()
        .map(|c| {
            let pts: Vec<Value> = c
                .points
                .iter()
                .map(|p| {
                    json!({
                        "tau_s": p.tau_s, "m": p.m, "adev": p.dev, "lower": p.interval.0, "upper": p.interval.1,
                        "edf": p.edf, "alpha": p.alpha, "alpha_from": p.alpha_from.as_str(), "terms": p.n,
                        "exact": p.stride == 1, "stride": p.stride,
                    })
                })
                .collect();
            let terms: serde_json::Map<String, Value> =
                term_rows(&c.terms, c.unit).into_iter().map(|(k, v, _)| (k, json!(v))).collect();
            json!({
                "name": c.name, "unit": c.unit, "scale_V_per_g": c.scale_v_per_g, "resolution": c.resolution,
                "points": pts, "terms": terms,
            })
        })
        .collect();
    json!({
        "file": a.file.display().to_string(),
        "rows": a.rows,
        "segments": a.segments,
        "tau0_s": a.tau0_s,
        "rate_Hz": 1.0 / a.tau0_s,
        "sampling_jitter": a.jitter,
        "span_s": [a.span_s.0, a.span_s.1],
        "estimator": estimator_note(exact_max_m, a.tau0_s),
        "confidence": level,
        "interval": "chi-squared with the Greenhall-Riley equivalent degrees of freedom of the noise type alpha (S_y ~ f^alpha) from the lag-1 autocorrelation",
        "channels": channels,
    })
}

/// The CSV of the curves: one row per channel and τ.
pub fn csv(shown: &[Shown]) -> String {
    let mut s = String::from("channel,unit,tau_s,m,adev,lower,upper,edf,alpha,alpha_from,terms,stride\n");
    for c in shown {
        for p in &c.points {
            let _ = writeln!(
                s,
                "{},{},{},{},{},{},{},{},{},{},{},{}",
                c.name,
                c.unit,
                p.tau_s,
                p.m,
                p.dev,
                p.interval.0,
                p.interval.1,
                p.edf.map_or(String::new(), |v| v.to_string()),
                p.alpha,
                p.alpha_from.as_str(),
                p.n,
                p.stride
            );
        }
    }
    s
}

/// The table on standard output.
pub fn table(a: &Analysis, shown: &[Shown], exact_max_m: usize, level: f64) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{}: {} rows, τ₀ = {:.6} s ({:.4} Hz, intervals within {:.2} %), {} segment{}, t = {} … {} s",
        a.file.display(),
        a.rows,
        a.tau0_s,
        1.0 / a.tau0_s,
        100.0 * a.jitter,
        a.segments,
        if a.segments == 1 { "" } else { "s (gaps between them)" },
        a.span_s.0,
        a.span_s.1
    );
    let _ = writeln!(s, "{}", estimator_note(exact_max_m, a.tau0_s));
    let _ = writeln!(
        s,
        "{:.0} % intervals: χ² with the Greenhall–Riley degrees of freedom of the noise type α (S_y ∝ f^α) from the lag-1 autocorrelation",
        100.0 * level
    );
    for c in shown {
        let unit_note = match c.scale_v_per_g {
            Some(k) => format!("g (scale factor {k} V/g)"),
            None if c.unit == "V" => "V (no scale factor given: --scale-v-per-g or --calib for g)".into(),
            None => c.unit.to_string(),
        };
        let _ = writeln!(s, "\n{} in {}:", c.name, unit_note);
        let _ = writeln!(
            s,
            "  {:>12} {:>9} {:>12} {:>12} {:>12} {:>9} {:>3} {:>8}",
            "tau_s", "m", "adev", "lower", "upper", "edf", "α", "overlap"
        );
        for p in &c.points {
            let _ = writeln!(
                s,
                "  {:>12.6} {:>9} {:>12.4e} {:>12.4e} {:>12.4e} {:>9} {:>3}{} {:>8}",
                p.tau_s,
                p.m,
                p.dev,
                p.interval.0,
                p.interval.1,
                p.edf.map_or("-".into(), |v| format!("{v:.1}")),
                p.alpha,
                match p.alpha_from {
                    super::AlphaFrom::Lag1 => ' ',
                    _ => '*',
                },
                if p.stride == 1 { "full".to_string() } else { format!("1/{}", p.stride) }
            );
        }
        if c.points.iter().any(|p| p.alpha_from != super::AlphaFrom::Lag1) {
            let _ = writeln!(s, "  * α carried from a shorter τ (fewer than 30 cluster means here)");
        }
        let _ = writeln!(s, "  terms (IEEE Std 952/1293 fit of σ² = 3Q²/τ² + N²/τ + 0.664²B² + K²τ/3 + R²τ²/2):");
        for (_, v, label) in term_rows(&c.terms, c.unit) {
            let _ = writeln!(s, "    {label:<48} {v:.4e}");
        }
        if c.resolution > 0.0 {
            let _ = writeln!(s, "    {:<48} {:.4e}", format!("resolution of the values [{}]", c.unit), c.resolution);
        }
    }
    s
}

/// The fitted simulator noise of each accelerometer \[V\] and of the thermistor (white [°C],
/// resolution), for `a`'s curves.
pub fn twin_noise(a: &Analysis) -> anyhow::Result<([TwinNoise; 3], Option<TwinNoise>)> {
    let mut out = [TwinNoise::default(); 3];
    for (i, name) in ["ux_V", "uy_V", "uz_V"].iter().enumerate() {
        let c =
            a.channels.iter().find(|c| c.name == *name).ok_or_else(|| {
                anyhow::anyhow!("--noise-toml needs the three accelerometers: {name} was not analysed")
            })?;
        out[i] = twin::fit(&fit_points(&c.points), a.tau0_s, c.resolution, 2);
    }
    let temp = a
        .channels
        .iter()
        .find(|c| c.name == "temp_C")
        .map(|c| twin::fit(&fit_points(&c.points), a.tau0_s, c.resolution, 0));
    Ok((out, temp))
}

fn fit_points(p: &[Point]) -> Vec<twin::FitPoint> {
    p.iter().map(|p| (p.m as f64, p.dev * p.dev, p.edf.unwrap_or(f64::NAN))).collect()
}

fn arr(v: [f64; 3]) -> String {
    format!("[{:e}, {:e}, {:e}]", v[0], v[1], v[2])
}

/// A scenario whose `[noise]` table is the fit: the paper's unit lying still at constant
/// temperature for the recording's span at its rate, so that `bins-cal simulate` of it gives
/// the twin's static recording; the `[noise]` table can be copied into any scenario.
pub fn noise_scenario(a: &Analysis, noise: &[TwinNoise; 3], temp: Option<&TwinNoise>) -> String {
    let per = |f: &dyn Fn(&TwinNoise) -> f64| arr([f(&noise[0]), f(&noise[1]), f(&noise[2])]);
    let adc = noise.iter().map(|n| n.adc_step).fold(0.0, f64::max);
    let dur = (a.span_s.1 - a.span_s.0) + a.tau0_s;
    let mut s = String::new();
    let _ =
        writeln!(s, "# The noise of {} fitted to its Allan curves (`bins-cal allan --noise-toml`):", a.file.display());
    let _ = writeln!(
        s,
        "# per axis white noise, a bias random walk and up to two first-order Gauss-Markov biases, each with"
    );
    let _ = writeln!(
        s,
        "# its exact Allan variance at the recording's sampling (docs/noise.md). The [noise] table can be copied into"
    );
    let _ =
        writeln!(s, "# any scenario; as it stands this file simulates the unit lying still for the recording's span:");
    let _ = writeln!(s, "#\n#   bins-cal simulate THIS.toml -o twin.csv --seed 1\n");
    let _ = writeln!(s, "description = \"noise twin of {}\"\n", a.file.display().to_string().replace('"', "'"));
    let _ = writeln!(s, "[recording]\nrate_Hz = {}\nlog_chamber = false\n", 1.0 / a.tau0_s);
    let _ = writeln!(s, "[unit]\npreset = \"paper\"\nfit = \"poly\"\norder = 2\n");
    let _ = writeln!(s, "[thermal]\nstart_C = 20.0\n");
    let _ = writeln!(s, "[noise]");
    let _ = writeln!(s, "white_V = {}", per(&|n| n.white));
    let _ = writeln!(s, "random_walk_V_per_sqrt_s = {}", per(&|n| n.random_walk));
    let _ = writeln!(s, "bias_instability_V = {}", per(&|n| n.gm[0].0));
    let _ = writeln!(s, "bias_tau_s = {}", per(&|n| n.gm[0].1));
    let _ = writeln!(s, "bias_instability2_V = {}", per(&|n| n.gm[1].0));
    let _ = writeln!(s, "bias_tau2_s = {}", per(&|n| n.gm[1].1));
    if adc >= crate::sim::scenario::MIN_ADC_LSB_V {
        let _ = writeln!(s, "adc_lsb_V = {adc:e}");
    }
    if let Some(t) = temp {
        let _ = writeln!(s, "temp_noise_C = {:e}", t.white);
        if t.adc_step > 0.0 {
            let _ = writeln!(s, "temp_resolution_C = {:e}", t.adc_step);
        }
    }
    let _ = writeln!(s, "\n[[step]]\nkind = \"soak\"\nchamber_C = 20.0\ndwell_s = {dur}");
    s
}

/// A Kalibr-style `imu.yaml` of the accelerometers (their largest white noise and random walk
/// over the axes, each axis in a comment), from the curves in g.
pub fn kalibr_yaml(a: &Analysis, shown: &[Shown]) -> anyhow::Result<String> {
    let acc: Vec<&Shown> = shown.iter().filter(|c| c.name.starts_with('u')).collect();
    if acc.is_empty() {
        anyhow::bail!("--imu-yaml needs an accelerometer channel");
    }
    if let Some(c) = acc.iter().find(|c| c.unit != "g") {
        anyhow::bail!("--imu-yaml is in m/s²: {} has no scale factor (give --scale-v-per-g or --calib)", c.name);
    }
    let nd: Vec<f64> = acc.iter().map(|c| c.terms.n * G0).collect();
    let rw: Vec<f64> = acc.iter().map(|c| c.terms.k * G0).collect();
    let mut s = String::new();
    let _ = writeln!(s, "# Accelerometer noise of {} for Kalibr (bins-cal allan --imu-yaml).", a.file.display());
    let _ = writeln!(s, "# White noise N and bias random walk K of the IEEE fit to the overlapping Allan deviation;");
    let _ = writeln!(s, "# the largest over the axes (per axis below). Bias instability is not a random walk and is");
    let _ = writeln!(s, "# not in this file; this unit has no gyroscopes.");
    for (c, (n, k)) in acc.iter().zip(nd.iter().zip(&rw)) {
        let _ = writeln!(
            s,
            "#   {}: noise density {n:.6e} m/s^2/sqrt(Hz), random walk {k:.6e} m/s^3/sqrt(Hz), bias instability {:.6e} m/s^2",
            c.name,
            c.terms.b * G0
        );
    }
    let max = |v: &[f64]| v.iter().copied().fold(0.0, f64::max);
    let _ = writeln!(s, "accelerometer_noise_density: {:.6e}  # [ m / s^2 / sqrt(Hz) ]  (white noise)", max(&nd));
    let _ = writeln!(s, "accelerometer_random_walk: {:.6e}  # [ m / s^3 / sqrt(Hz) ]  (bias diffusion)", max(&rw));
    let _ = writeln!(s, "update_rate: {:.6}  # [ Hz ]", 1.0 / a.tau0_s);
    let _ = writeln!(s, "rostopic: /imu0");
    Ok(s)
}

/// The floor of flicker noise over `B` (0.664), for labels.
pub fn flicker_floor_factor() -> f64 {
    FLICKER_FLOOR.sqrt()
}
