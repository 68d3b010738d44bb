//! The calibration file: one unit's calibration as TOML, with units in the key names (see
//! `docs/calibration-blob.md`), optionally with its vibration-error model (`[vibration]`) and
//! its thermal dynamics (`[thermal_dynamics]`).
//! Owns its serde types, the structural checks that name the
//! offending key, and the conversions to and from [`CalibrationParams`] and the blob.
//!
//! Physical checks are not duplicated here: [`CalibrationFile::to_blob`] runs the core's
//! encoder, which parses its own output, so a file is accepted exactly when the firmware would
//! accept its blob. Errors from there name the field with the same key path as this file.

use bins_comp::blob::{self, BlobError, CalDate, Meta};
use bins_comp::dynamics::ThermalDynamics;
use bins_comp::temperature::{MAX_KNOTS, MAX_POLY_ORDER};
use bins_comp::vibration::MAX_PROFILES;
use bins_comp::{
    CalibrationParams, CoefDelta, Constants, ConversionFunction, Form, Method, TempModel, Variant, Vibration,
    VibrationParams,
};
use serde::{Deserialize, Serialize};
use std::path::Path;
use toml::value::{Date, Datetime};

/// A calibration file as written on disk.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrationFile {
    /// The unit's serial number (1–32 printable ASCII characters).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub serial: Option<String>,
    /// The calibration date (a TOML local date, e.g. `2024-01-15`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibration_date: Option<Datetime>,
    /// The tool that produced the calibration; filled in by the encoder when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tool_version: Option<String>,
    /// T0 [°C].
    #[serde(rename = "t0_C")]
    pub t0_c: f64,
    /// Calibrated temperature range [°C]: `[min, max]`.
    #[serde(rename = "temp_range_C")]
    #[serde(deserialize_with = "crate::exact::array")]
    pub temp_range_c: [f64; 2],
    /// K at T0 [V/g], row-major.
    #[serde(rename = "k_V_per_g")]
    #[serde(deserialize_with = "crate::exact::matrix")]
    pub k_v_per_g: [[f64; 3]; 3],
    /// U0 at T0 \[V\].
    #[serde(rename = "u0_V")]
    #[serde(deserialize_with = "crate::exact::array")]
    pub u0_v: [f64; 3],
    /// Compensation method.
    pub method: MethodSpec,
    /// Temperature model.
    pub temperature_model: ModelSpec,
    /// Vibration-error model (conversion functions, variant, flight-phase profiles); absent:
    /// no VE model.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vibration: Option<VibrationSpec>,
    /// Thermal dynamics between the thermistor and the sensing elements (blob section
    /// 0x0007); absent: none, the temperature model is evaluated at the reading.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub thermal_dynamics: Option<DynamicsSpec>,
}

/// `[thermal_dynamics]`: what `bins-cal diagnose` names `thermal_lag`, `thermal_hysteresis`,
/// `self_heating` and `bias_hysteresis`, in the units of the keys (the bias play in mg; the
/// core takes g). A missing key is 0 (that stage off).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DynamicsSpec {
    /// τ of the die's lag behind the thermistor \[s\].
    pub lag_tau_s: f64,
    /// Width of the hysteresis play on the lagged temperature [°C].
    #[serde(rename = "hysteresis_width_C")]
    pub hysteresis_width_c: f64,
    /// ΔT_sh: how much warmer the die settles than the thermistor after power-on [°C].
    #[serde(rename = "self_heating_C")]
    pub self_heating_c: f64,
    /// τ_sh of the self-heating \[s\].
    pub self_heating_tau_s: f64,
    /// Width of the bias play on the effective temperature [°C].
    #[serde(rename = "bias_play_width_C")]
    pub bias_play_width_c: f64,
    /// Bias per unit of the play fraction, x, y, z \[mg\].
    #[serde(deserialize_with = "crate::exact::array")]
    pub bias_play_mg: [f64; 3],
}

impl DynamicsSpec {
    /// The core's parameters (bias in g: `bias_play_mg / 1000`).
    pub fn to_dynamics(&self) -> ThermalDynamics<f64> {
        ThermalDynamics {
            lag_tau_s: self.lag_tau_s,
            hysteresis_width_c: self.hysteresis_width_c,
            self_heating_c: self.self_heating_c,
            self_heating_tau_s: self.self_heating_tau_s,
            bias_play_width_c: self.bias_play_width_c,
            bias_play_g: self.bias_play_mg.map(|mg| mg / 1000.0),
        }
    }

    /// The inverse of [`to_dynamics`](Self::to_dynamics): each bias in mg is the shortest
    /// decimal whose `/ 1000` gives the bias in g back exactly. The g the core uses is lossless
    /// through file → blob → file; the mg text is too for values of up to 9 significant digits
    /// (two mg values an ulp apart can give one g, and the shorter is written).
    pub fn from_dynamics(d: &ThermalDynamics<f64>) -> Self {
        DynamicsSpec {
            lag_tau_s: d.lag_tau_s,
            hysteresis_width_c: d.hysteresis_width_c,
            self_heating_c: d.self_heating_c,
            self_heating_tau_s: d.self_heating_tau_s,
            bias_play_width_c: d.bias_play_width_c,
            bias_play_mg: d.bias_play_g.map(g_to_mg),
        }
    }

    /// Reads the `[thermal_dynamics]` table of a TOML file (a calibration file, or the model
    /// `bins-cal diagnose --model` writes; other tables are ignored) and checks it as the
    /// firmware would. Errors name the file and the key.
    pub fn read_table(path: &Path) -> anyhow::Result<Self> {
        let text = crate::fsio::read_text(path)?;
        let value: toml::Table =
            toml::from_str(&text).map_err(|e| anyhow::anyhow!("{}: {}", path.display(), one_line(&e.to_string())))?;
        let table = value
            .get("thermal_dynamics")
            .ok_or_else(|| anyhow::anyhow!("{}: no [thermal_dynamics] table", path.display()))?;
        let spec: DynamicsSpec = table.clone().try_into().map_err(|e: toml::de::Error| {
            anyhow::anyhow!("{}: thermal_dynamics: {}", path.display(), one_line(&e.to_string()))
        })?;
        spec.to_dynamics().validate().map_err(|e| anyhow::anyhow!("{}: thermal_dynamics.{e}", path.display()))?;
        Ok(spec)
    }
}

/// An mg value `m` with `m / 1000 == g`: of those within a few ulps of `g·1000`, the one
/// with the shortest decimal form (so a file's `0.015` comes back as `0.015`, not as another
/// value that gives the same g).
fn g_to_mg(g: f64) -> f64 {
    let m = g * 1000.0;
    if !m.is_finite() {
        return m;
    }
    let (mut best, mut best_len) = (m, usize::MAX);
    let mut c = m;
    for _ in 0..4 {
        c = c.next_down();
    }
    for _ in 0..9 {
        if c / 1000.0 == g {
            let len = format!("{c:?}").len();
            if len < best_len {
                (best, best_len) = (c, len);
            }
        }
        c = c.next_up();
    }
    best
}

/// `[vibration]`: the VE model of the unit (blob sections 0x0005, 0x0006).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VibrationSpec {
    /// `variant`: the formulas of the profiles' VE.
    pub variant: VariantKind,
    /// `[vibration.x]`: the x accelerometer's conversion function (absent: all zero).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub x: Option<ConversionSpec>,
    /// `[vibration.y]`
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub y: Option<ConversionSpec>,
    /// `[vibration.z]`
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub z: Option<ConversionSpec>,
    /// `[[vibration.profile]]`: flight-phase profiles, index 0, 1, … in order (at most 8).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub profile: Vec<ProfileSpec>,
}

/// `vibration.variant`
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum VariantKind {
    /// V(13)/V(14) as printed.
    Paper,
    /// The exact time mean.
    Exact,
}

/// `[vibration.x]` etc.: the conversion function V(2) in acceleration units; a missing key is
/// zero. Keys are [`blob::CONVERSION_FUNCTION_KEYS`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ConversionSpec {
    /// a0 \[g\].
    pub a0_g: f64,
    /// δ_1A \[1\].
    pub delta_1a: f64,
    /// k2 [g/g²].
    pub k2_g_per_g2: f64,
    /// k3 [g/g³].
    pub k3_g_per_g3: f64,
    /// k4 [g/g⁴].
    pub k4_g_per_g4: f64,
    /// k5 [g/g⁵].
    pub k5_g_per_g5: f64,
    /// m1 [g/g].
    pub m1_g_per_g: f64,
    /// m2 [g/g].
    pub m2_g_per_g: f64,
    /// m31 [g/g²].
    pub m31_g_per_g2: f64,
    /// m32 [g/g²].
    pub m32_g_per_g2: f64,
}

impl ConversionSpec {
    /// The core's conversion function.
    pub fn to_cf(&self) -> ConversionFunction<f64> {
        ConversionFunction {
            a0_g: self.a0_g,
            delta_1a: self.delta_1a,
            k2_g_per_g2: self.k2_g_per_g2,
            k3_g_per_g3: self.k3_g_per_g3,
            k4_g_per_g4: self.k4_g_per_g4,
            k5_g_per_g5: self.k5_g_per_g5,
            m1_g_per_g: self.m1_g_per_g,
            m2_g_per_g: self.m2_g_per_g,
            m31_g_per_g2: self.m31_g_per_g2,
            m32_g_per_g2: self.m32_g_per_g2,
        }
    }

    /// The inverse of [`to_cf`](Self::to_cf).
    pub fn from_cf(c: &ConversionFunction<f64>) -> Self {
        ConversionSpec {
            a0_g: c.a0_g,
            delta_1a: c.delta_1a,
            k2_g_per_g2: c.k2_g_per_g2,
            k3_g_per_g3: c.k3_g_per_g3,
            k4_g_per_g4: c.k4_g_per_g4,
            k5_g_per_g5: c.k5_g_per_g5,
            m1_g_per_g: c.m1_g_per_g,
            m2_g_per_g: c.m2_g_per_g,
            m31_g_per_g2: c.m31_g_per_g2,
            m32_g_per_g2: c.m32_g_per_g2,
        }
    }
}

/// `[[vibration.profile]]`: one flight-phase vibration environment, by `kind`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum ProfileSpec {
    /// `kind = "none"`: no vibration (nothing subtracted in this phase).
    None,
    /// `kind = "sine"`: harmonic, in phase on all axes.
    Sine {
        /// Peak amplitude per axis x, y, z \[g\], signed.
        #[serde(deserialize_with = "keyed_amp_g")]
        amp_g: [f64; 3],
        /// Frequency \[Hz\].
        #[serde(rename = "freq_Hz")]
        freq_hz: f64,
    },
    /// `kind = "random"`: flat band, fully correlated components.
    Random {
        /// σ per axis x, y, z \[g\].
        #[serde(deserialize_with = "keyed_sigma_g")]
        sigma_g: [f64; 3],
        /// Band [low, high] \[Hz\].
        #[serde(rename = "band_Hz")]
        #[serde(deserialize_with = "keyed_band_hz")]
        band_hz: [f64; 2],
    },
}

crate::keyed_array!(keyed_amp_g, "amp_g", 3);
crate::keyed_array!(keyed_sigma_g, "sigma_g", 3);
crate::keyed_array!(keyed_band_hz, "band_Hz", 2);

impl ProfileSpec {
    /// The core's vibration.
    pub fn to_vibration(&self) -> Vibration<f64> {
        match *self {
            ProfileSpec::None => Vibration::None,
            ProfileSpec::Sine { amp_g, freq_hz } => Vibration::Harmonic { amp_g, freq_hz },
            ProfileSpec::Random { sigma_g, band_hz } => {
                Vibration::Random { sigma_g, band_hz: (band_hz[0], band_hz[1]) }
            }
        }
    }

    /// The inverse of [`to_vibration`](Self::to_vibration).
    pub fn from_vibration(v: &Vibration<f64>) -> Self {
        match *v {
            Vibration::None => ProfileSpec::None,
            Vibration::Harmonic { amp_g, freq_hz } => ProfileSpec::Sine { amp_g, freq_hz },
            Vibration::Random { sigma_g, band_hz } => ProfileSpec::Random { sigma_g, band_hz: [band_hz.0, band_hz.1] },
        }
    }
}

impl VibrationSpec {
    /// The core's parameters; structural checks only (the profile count), physical ranges are
    /// the encoder's.
    pub fn to_params(&self) -> Result<VibrationParams, CalFileError> {
        let cf = [&self.x, &self.y, &self.z].map(|c| c.unwrap_or_default().to_cf());
        let variant = match self.variant {
            VariantKind::Paper => Variant::Paper,
            VariantKind::Exact => Variant::Exact,
        };
        let mut p = VibrationParams::new(cf, variant);
        if self.profile.len() > MAX_PROFILES {
            return Err(key_error(
                "vibration.profile",
                format!("{} profiles; at most {MAX_PROFILES}", self.profile.len()),
            ));
        }
        for (i, prof) in self.profile.iter().enumerate() {
            p.push_profile(prof.to_vibration())
                .map_err(|e| key_error(format!("vibration.profile[{i}]"), e.to_string()))?;
        }
        Ok(p)
    }

    /// The `[vibration]` table of parameters (every axis written, also an all-zero one).
    pub fn from_params(p: &VibrationParams) -> Self {
        let [x, y, z] = p.cf.map(|c| Some(ConversionSpec::from_cf(&c)));
        VibrationSpec {
            variant: match p.variant {
                Variant::Paper => VariantKind::Paper,
                Variant::Exact => VariantKind::Exact,
            },
            x,
            y,
            z,
            profile: p.profiles.iter().take(p.n_profiles as usize).map(ProfileSpec::from_vibration).collect(),
        }
    }
}

/// `[method]`
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MethodSpec {
    /// `kind`
    pub kind: MethodKind,
    /// `form`, for `output-correction` only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub form: Option<FormKind>,
}

/// `method.kind`
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MethodKind {
    /// No temperature correction.
    Uncorrected,
    /// Method 1.
    CoefficientCorrection,
    /// Method 2.
    OutputCorrection,
}

/// `method.form`
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FormKind {
    /// T(5)/T(6).
    Full,
    /// T(7)/T(8).
    Simplified,
    /// −N·(ΔK·â + ΔU0).
    Linearized,
}

/// `temperature_model.kind`
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ModelKind {
    /// Polynomial T(3): `[[temperature_model.term]]` tables.
    Poly,
    /// Piecewise-linear T(4): `[[temperature_model.knot]]` tables.
    Pwl,
}

/// `[temperature_model]`
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelSpec {
    /// `kind`
    pub kind: ModelKind,
    /// Piecewise-linear knots, increasing.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub knot: Vec<KnotSpec>,
    /// Polynomial terms, power 1, 2, … in order.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub term: Vec<TermSpec>,
}

/// `[[temperature_model.knot]]`: the change of the constants at one knot, relative to T0.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KnotSpec {
    /// Knot temperature [°C].
    #[serde(rename = "t_C")]
    pub t_c: f64,
    /// ΔU0 at the knot \[V\].
    #[serde(rename = "du0_V")]
    #[serde(deserialize_with = "crate::exact::array")]
    pub du0_v: [f64; 3],
    /// ΔK_ij/K_ij at the knot \[1\].
    #[serde(deserialize_with = "crate::exact::matrix")]
    pub rel_k: [[f64; 3]; 3],
}

/// `[[temperature_model.term]]`: the coefficients of ΔTⁿ.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TermSpec {
    /// n.
    pub power: u8,
    /// α_n [V/°Cⁿ].
    #[serde(rename = "alpha_V_per_Cn")]
    #[serde(deserialize_with = "crate::exact::array")]
    pub alpha_v_per_cn: [f64; 3],
    /// β_n on the diagonal, γ_n off it [1/°Cⁿ].
    #[serde(rename = "rel_k_per_Cn")]
    #[serde(deserialize_with = "crate::exact::matrix")]
    pub rel_k_per_cn: [[f64; 3]; 3],
}

/// Why a calibration file was rejected: the key and what is wrong with it.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CalFileError {
    /// Not TOML, a missing or unknown key, or a value of the wrong type.
    #[error("{0}")]
    Syntax(String),
    /// A key whose value is structurally wrong.
    #[error("{key}: {message}")]
    Key {
        /// Dotted key path, with array indices.
        key: String,
        /// What is wrong.
        message: String,
    },
    /// A value the blob format refuses (physical range, singular K, …).
    #[error("{}", describe(.0))]
    Blob(BlobError),
}

fn key_error(key: impl Into<String>, message: impl Into<String>) -> CalFileError {
    CalFileError::Key { key: key.into(), message: message.into() }
}

/// A blob error as a calibration-file user reads it: value errors name the key and its limit
/// but not the byte offset (which refers to the encoded blob, not the file).
pub fn describe(e: &BlobError) -> String {
    match e {
        BlobError::OutOfRange { field, .. } => format!("{field} out of range (must be {})", field.limit()),
        BlobError::KnotsNotIncreasing { knot, .. } => {
            format!("temperature_model.knot[{knot}].t_C: knots not strictly increasing")
        }
        BlobError::BadRange { .. } => "temp_range_C: must satisfy min < max and contain t0_C".to_string(),
        other => other.to_string(),
    }
}

/// The traceability data of a calibration, owned.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct OwnedMeta {
    /// Serial ("" = absent).
    pub serial: String,
    /// Date.
    pub date: Option<CalDate>,
    /// Tool version ("" = absent).
    pub tool_version: String,
}

impl OwnedMeta {
    /// Borrowed view for the encoder.
    pub fn as_meta(&self) -> Meta<'_> {
        Meta { serial: &self.serial, date: self.date, tool_version: &self.tool_version }
    }
}

impl CalibrationFile {
    /// Parses TOML text.
    pub fn from_toml(text: &str) -> Result<Self, CalFileError> {
        toml::from_str(text).map_err(|e| CalFileError::Syntax(one_line(&e.to_string())))
    }

    /// Reads and parses a calibration file (TOML); errors name the file. A blob given
    /// instead (decided by its content, the magic `BCAL`, not by the name) is said to be one.
    pub fn read(path: &Path) -> anyhow::Result<Self> {
        let bytes = crate::fsio::read_capped(path, crate::fsio::MAX_TEXT_INPUT_BYTES)?;
        if is_blob(&bytes) {
            anyhow::bail!(
                "{}: a calibration blob (it starts with the magic BCAL), not a calibration file (TOML); `bins-cal blob decode` turns it into one",
                path.display()
            );
        }
        Self::from_toml(&toml_text(path, &bytes)?).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
    }

    /// Reads a calibration, a calibration file (TOML) or a blob, told apart by the content
    /// (UTF-8 text not starting with the blob's magic `BCAL` is a calibration file, anything
    /// else is read as a blob; the name does not matter), and checks it as the
    /// firmware would check it ([`check`](Self::check)); returns the file and its blob. Errors
    /// name the file and the key or blob field. Every command that uses a calibration goes
    /// through this, so a calibration is accepted or refused the same way whatever its
    /// container.
    pub fn read_checked(path: &Path) -> anyhow::Result<(Self, Vec<u8>)> {
        let bytes = crate::fsio::read_capped(path, crate::fsio::MAX_TEXT_INPUT_BYTES)?;
        let file = if is_blob(&bytes) || std::str::from_utf8(&bytes).is_err() {
            Self::from_blob(&bytes).map_err(|e| anyhow::anyhow!("{}: {}", path.display(), describe(&e)))?
        } else {
            Self::from_toml(&toml_text(path, &bytes)?).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?
        };
        let bytes = file.check().map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        Ok((file, bytes))
    }

    /// The one validation of a calibration, whatever its container: the blob encoder's checks
    /// ([`to_blob`](Self::to_blob): structure, physical ranges, conditioning), then the
    /// firmware's own parser on the result ([`blob::parse`]). Returns the blob.
    pub fn check(&self) -> Result<Vec<u8>, CalFileError> {
        let bytes = self.to_blob()?;
        blob::parse(&bytes).map_err(CalFileError::Blob)?;
        Ok(bytes)
    }

    /// The file as TOML text, with a header comment.
    pub fn to_toml(&self) -> String {
        let body = toml::to_string(self).unwrap_or_else(|e| format!("# cannot serialise: {e}\n"));
        format!(
            "# Calibration of one triaxial accelerometer unit (bins-cal calibration file).\n\
             # Format and limits: docs/calibration-blob.md. Units are in the key names.\n\n{}",
            matrices_by_row(&body)
        )
    }

    /// The core's parameters and the traceability data. Checks the structure (method and
    /// form, model kind and its tables, term powers, date) and names the key at fault;
    /// physical ranges are checked by [`to_blob`](Self::to_blob).
    pub fn to_params(&self) -> Result<(CalibrationParams, OwnedMeta), CalFileError> {
        let method = match (self.method.kind, self.method.form) {
            (MethodKind::Uncorrected, None) => Method::Uncorrected,
            (MethodKind::CoefficientCorrection, None) => Method::CoefficientCorrection,
            (MethodKind::OutputCorrection, Some(f)) => Method::OutputCorrection(match f {
                FormKind::Full => Form::Full,
                FormKind::Simplified => Form::Simplified,
                FormKind::Linearized => Form::Linearized,
            }),
            (MethodKind::OutputCorrection, None) => {
                return Err(key_error("method.form", "required for kind = \"output-correction\""));
            }
            (_, Some(_)) => return Err(key_error("method.form", "allowed only for kind = \"output-correction\"")),
        };
        let m = &self.temperature_model;
        let model = match m.kind {
            ModelKind::Poly => {
                if !m.knot.is_empty() {
                    return Err(key_error("temperature_model.knot", "not allowed with kind = \"poly\""));
                }
                if !(1..=MAX_POLY_ORDER).contains(&m.term.len()) {
                    return Err(key_error(
                        "temperature_model.term",
                        format!("{} terms; a polynomial has 1 to {MAX_POLY_ORDER}", m.term.len()),
                    ));
                }
                let mut coef = [CoefDelta::zero(); MAX_POLY_ORDER];
                for (n, (t, c)) in m.term.iter().zip(coef.iter_mut()).enumerate() {
                    if t.power as usize != n + 1 {
                        return Err(key_error(
                            format!("temperature_model.term[{n}].power"),
                            format!("{}, expected {} (terms in order of power)", t.power, n + 1),
                        ));
                    }
                    *c = CoefDelta { du0_v: t.alpha_v_per_cn, rel_k: t.rel_k_per_cn };
                }
                TempModel::Poly { order: m.term.len() as u8, coef }
            }
            ModelKind::Pwl => {
                if !m.term.is_empty() {
                    return Err(key_error("temperature_model.term", "not allowed with kind = \"pwl\""));
                }
                if !(2..=MAX_KNOTS).contains(&m.knot.len()) {
                    return Err(key_error(
                        "temperature_model.knot",
                        format!("{} knots; a piecewise-linear model has 2 to {MAX_KNOTS}", m.knot.len()),
                    ));
                }
                let mut knots_c = [0.0; MAX_KNOTS];
                let mut at_knot = [CoefDelta::zero(); MAX_KNOTS];
                for (i, k) in m.knot.iter().enumerate() {
                    knots_c[i] = k.t_c;
                    at_knot[i] = CoefDelta { du0_v: k.du0_v, rel_k: k.rel_k };
                }
                TempModel::Pwl { n_knots: m.knot.len() as u8, knots_c, at_knot }
            }
        };
        let date = match &self.calibration_date {
            None => None,
            Some(dt) => match (dt.date, dt.time, dt.offset) {
                (Some(d), None, None) => Some(CalDate { year: d.year, month: d.month, day: d.day }),
                _ => return Err(key_error("calibration_date", "must be a local date (YYYY-MM-DD), no time")),
            },
        };
        let params = CalibrationParams {
            constants: Constants { k_v_per_g: self.k_v_per_g, u0_v: self.u0_v },
            t0_c: self.t0_c,
            model,
            method,
            temp_range_c: (self.temp_range_c[0], self.temp_range_c[1]),
        };
        let meta = OwnedMeta {
            serial: self.serial.clone().unwrap_or_default(),
            date,
            tool_version: self.tool_version.clone().unwrap_or_else(|| crate::TOOL_VERSION.to_string()),
        };
        if self.serial.as_deref() == Some("") {
            return Err(key_error("serial", "empty; omit the key instead"));
        }
        if self.tool_version.as_deref() == Some("") {
            return Err(key_error("tool_version", "empty; omit the key instead"));
        }
        Ok((params, meta))
    }

    /// The vibration-error parameters (`[vibration]`), `None` when the file has none.
    pub fn to_vibration(&self) -> Result<Option<VibrationParams>, CalFileError> {
        self.vibration.as_ref().map(VibrationSpec::to_params).transpose()
    }

    /// The blob: [`to_params`](Self::to_params), [`to_vibration`](Self::to_vibration) and
    /// the thermal dynamics, then the core's encoder (which checks everything the firmware
    /// checks).
    pub fn to_blob(&self) -> Result<Vec<u8>, CalFileError> {
        let (params, meta) = self.to_params()?;
        let vib = self.to_vibration()?;
        let dynamics = self.thermal_dynamics.as_ref().map(DynamicsSpec::to_dynamics);
        let mut buf = [0u8; blob::MAX_BLOB_BYTES];
        let n = blob::encode_with_dynamics(&params, vib.as_ref(), dynamics.as_ref(), &meta.as_meta(), &mut buf)
            .map_err(CalFileError::Blob)?;
        Ok(buf[..n].to_vec())
    }

    /// The core's thermal dynamics of this calibration (`None` without `[thermal_dynamics]`),
    /// as the firmware reads them: the file is checked completely ([`check`](Self::check)) and
    /// the dynamics are taken from its parsed blob, so host tools model exactly what flies.
    /// Errors name the key.
    pub fn dynamics(&self) -> Result<Option<ThermalDynamics<f64>>, CalFileError> {
        let bytes = self.check()?;
        Ok(blob::parse(&bytes).map_err(CalFileError::Blob)?.dynamics)
    }

    /// The file for parameters, a vibration-error model and traceability data.
    pub fn from_parts(params: &CalibrationParams, vib: Option<&VibrationParams>, meta: &Meta<'_>) -> Self {
        let mut f = Self::from_params(params, meta);
        f.vibration = vib.map(VibrationSpec::from_params);
        f
    }

    /// The file for parameters and traceability data, without a vibration-error model (the
    /// inverse of [`to_params`](Self::to_params)).
    pub fn from_params(params: &CalibrationParams, meta: &Meta<'_>) -> Self {
        let method = match params.method {
            Method::Uncorrected => MethodSpec { kind: MethodKind::Uncorrected, form: None },
            Method::CoefficientCorrection => MethodSpec { kind: MethodKind::CoefficientCorrection, form: None },
            Method::OutputCorrection(f) => MethodSpec {
                kind: MethodKind::OutputCorrection,
                form: Some(match f {
                    Form::Full => FormKind::Full,
                    Form::Simplified => FormKind::Simplified,
                    Form::Linearized => FormKind::Linearized,
                }),
            },
        };
        let temperature_model = match &params.model {
            TempModel::Poly { order, coef } => ModelSpec {
                kind: ModelKind::Poly,
                knot: Vec::new(),
                term: coef
                    .iter()
                    .take(*order as usize)
                    .enumerate()
                    .map(|(n, c)| TermSpec { power: n as u8 + 1, alpha_v_per_cn: c.du0_v, rel_k_per_cn: c.rel_k })
                    .collect(),
            },
            TempModel::Pwl { n_knots, knots_c, at_knot } => ModelSpec {
                kind: ModelKind::Pwl,
                knot: knots_c
                    .iter()
                    .zip(at_knot)
                    .take(*n_knots as usize)
                    .map(|(&t_c, c)| KnotSpec { t_c, du0_v: c.du0_v, rel_k: c.rel_k })
                    .collect(),
                term: Vec::new(),
            },
        };
        let text = |s: &str| (!s.is_empty()).then(|| s.to_string());
        CalibrationFile {
            serial: text(meta.serial),
            calibration_date: meta.date.map(|d| Datetime {
                date: Some(Date { year: d.year, month: d.month, day: d.day }),
                time: None,
                offset: None,
            }),
            tool_version: text(meta.tool_version),
            t0_c: params.t0_c,
            temp_range_c: [params.temp_range_c.0, params.temp_range_c.1],
            k_v_per_g: params.constants.k_v_per_g,
            u0_v: params.constants.u0_v,
            method,
            temperature_model,
            vibration: None,
            thermal_dynamics: None,
        }
    }

    /// The file a blob holds; the blob is fully checked first.
    pub fn from_blob(bytes: &[u8]) -> Result<Self, BlobError> {
        let parsed = blob::parse(bytes)?;
        let mut f = Self::from_parts(&parsed.params, parsed.vibration.as_ref(), &parsed.meta);
        f.thermal_dynamics = parsed.dynamics.as_ref().map(DynamicsSpec::from_dynamics);
        Ok(f)
    }
}

/// True when `bytes` are a blob (they start with its magic), not TOML text.
pub fn is_blob(bytes: &[u8]) -> bool {
    bytes.starts_with(&blob::MAGIC)
}

/// `bytes` as the text of a TOML file; not UTF-8 is said so, with the byte offset.
fn toml_text(path: &Path, bytes: &[u8]) -> anyhow::Result<String> {
    String::from_utf8(bytes.to_vec()).map_err(|e| {
        anyhow::anyhow!(
            "{}: not a calibration file (TOML text) nor a blob: byte {} is not UTF-8",
            path.display(),
            e.utf8_error().valid_up_to()
        )
    })
}

/// Puts each row of a 3×3 matrix value (`key = [[…], […], […]]`) on its own line.
fn matrices_by_row(body: &str) -> String {
    let mut out = String::with_capacity(body.len() + 256);
    for line in body.lines() {
        let split = line.split_once(" = [[").and_then(|(key, rest)| Some((key, rest.strip_suffix("]]")?)));
        match split {
            Some((key, inner)) if !key.contains('"') && inner.split("], [").count() == 3 => {
                out.push_str(key);
                out.push_str(" = [\n");
                for row in inner.split("], [") {
                    out.push_str("    [");
                    out.push_str(row);
                    out.push_str("],\n");
                }
                out.push_str("]\n");
            }
            _ => {
                out.push_str(line);
                out.push('\n');
            }
        }
    }
    out
}

/// Joins the TOML parser's multi-line message (position, source excerpt, reason) into one
/// line that keeps the offending source line, e.g.
/// "TOML parse error at line 6, column 8: `t0_C = "x"`: invalid type: string "x", expected f64".
pub fn one_line(s: &str) -> String {
    let mut parts: Vec<String> = Vec::new();
    for line in s.lines().map(str::trim).filter(|l| !l.is_empty()) {
        if line.starts_with('|') {
            continue; // the caret line
        }
        match line.split_once(" |") {
            Some((n, src)) if !n.is_empty() && n.chars().all(|c| c.is_ascii_digit()) => {
                parts.push(format!("`{}`", src.trim()));
            }
            _ => parts.push(line.to_string()),
        }
    }
    parts.join(": ")
}

/// The calibration file's name of a method, e.g. `output-correction/simplified`.
pub fn method_name(m: Method) -> &'static str {
    match m {
        Method::Uncorrected => "uncorrected",
        Method::CoefficientCorrection => "coefficient-correction",
        Method::OutputCorrection(Form::Full) => "output-correction/full",
        Method::OutputCorrection(Form::Simplified) => "output-correction/simplified",
        Method::OutputCorrection(Form::Linearized) => "output-correction/linearized",
    }
}
