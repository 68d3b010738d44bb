//! The scenario file (TOML) of `bins-cal simulate`: the unit, its thermal and noise
//! behaviour, and the rig program as a list of `[[step]]` tables. Units are in the key
//! names. The format is described in `docs/simulator.md`; `scenarios/*.toml` are examples.
//!
//! Every table denies unknown keys. Errors name the file, the key (as a path such as
//! `step[2].theta_deg`) and the reason; syntax errors also the line.

use super::Simulation;
use super::rig::Timeline;
use super::thermal::ThermalParams;
use super::unit::{NoiseParams, UnitModel};
use crate::calfile::{CalibrationFile, MethodKind, MethodSpec, ModelSpec};
use bins_comp::dynamics::{MAX_BIAS_PLAY_G, MAX_TAU_S, MAX_WIDTH_C};
use bins_comp::ident::{self, TILTER_POSITIONS_G, check_positions_g};
use bins_comp::temperature::MAX_POLY_ORDER;
use bins_comp::vibration::{self, AccelAxes, Axis, ConversionFunction, Vibration};
use bins_comp::{CalibrationParams, Constants, Method, TempModel, paper};
use serde::Deserialize;
use std::fmt;
use std::path::{Path, PathBuf};

/// A scenario file as written.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScenarioFile {
    /// Free text, copied into the recording's comments.
    #[serde(default)]
    pub description: Option<String>,
    /// `[recording]`
    pub recording: RecordingSpec,
    /// `[unit]`
    pub unit: UnitSpec,
    /// `[thermal]`
    #[serde(default)]
    pub thermal: ThermalSpec,
    /// `[noise]` (absent: no noise).
    #[serde(default)]
    pub noise: NoiseSpec,
    /// `[[step]]`, in order.
    pub step: Vec<StepSpec>,
}

/// `[recording]`
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RecordingSpec {
    /// Logger rate \[Hz\].
    #[serde(rename = "rate_Hz")]
    pub rate_hz: f64,
    /// Time since power-on at the first row \[s\].
    #[serde(default)]
    pub power_on_s: f64,
    /// Whether `chamber_C` is written (default true).
    #[serde(default = "yes")]
    pub log_chamber: bool,
    /// The unit's static specific force before the first step \[g\] (default TP1, `[0, 0, 1]`).
    #[serde(default)]
    #[serde(deserialize_with = "crate::exact::option_array")]
    pub start_f_g: Option<[f64; 3]>,
    /// Further comment lines.
    #[serde(default)]
    pub comments: Vec<String>,
}

fn yes() -> bool {
    true
}

/// `[unit]`
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UnitSpec {
    /// `paper` (Tables T1/T2 of the temperature paper, via `bins_comp::paper`) or `al15`
    /// (three AL-15 accelerometers of Table V1, no temperature dependence).
    #[serde(default)]
    pub preset: Option<Preset>,
    /// T0 [°C].
    #[serde(default, rename = "t0_C")]
    pub t0_c: Option<f64>,
    /// K at T0 [V/g].
    #[serde(default, rename = "k_V_per_g")]
    #[serde(deserialize_with = "crate::exact::option_matrix")]
    pub k_v_per_g: Option<[[f64; 3]; 3]>,
    /// U0 at T0 \[V\].
    #[serde(default, rename = "u0_V")]
    #[serde(deserialize_with = "crate::exact::option_array")]
    pub u0_v: Option<[f64; 3]>,
    /// Constants measured at further temperatures.
    #[serde(default)]
    pub at: Vec<AtSpec>,
    /// How the constants between measured temperatures are formed: `poly` (least squares of
    /// order `order`, T(11)) or `pwl` (piecewise-linear through them, T(12)).
    #[serde(default)]
    pub fit: Option<FitKind>,
    /// Polynomial order for `fit = "poly"` (default 2).
    #[serde(default)]
    pub order: Option<usize>,
    /// A temperature model as in the calibration file.
    #[serde(default)]
    pub temperature_model: Option<ModelSpec>,
    /// The nonlinear conversion function V(2).
    #[serde(default)]
    pub conversion: Option<ConversionSpec>,
    /// Warm-up transient at power-on \[V\] per axis.
    #[serde(default, rename = "warmup_V")]
    #[serde(deserialize_with = "crate::exact::array")]
    pub warmup_v: [f64; 3],
    /// Warm-up time constant \[s\].
    #[serde(default)]
    pub warmup_tau_s: f64,
    /// Additive bias play: heating/cooling bias difference per axis \[mg\] (±this beyond the play).
    #[serde(default, rename = "bias_play_mg")]
    #[serde(deserialize_with = "crate::exact::array")]
    pub bias_play_mg: [f64; 3],
    /// Width of the bias play [°C] (on the temperature the constants follow).
    #[serde(default, rename = "bias_play_width_C")]
    pub bias_play_width_c: f64,
}

/// `unit.preset`
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Preset {
    /// Tables T1/T2.
    Paper,
    /// AL-15 (Table V1).
    Al15,
}

/// `unit.fit`
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FitKind {
    /// Polynomial.
    Poly,
    /// Piecewise-linear.
    Pwl,
}

/// `[[unit.at]]`
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AtSpec {
    /// Temperature [°C].
    #[serde(rename = "temp_C")]
    pub temp_c: f64,
    /// K [V/g].
    #[serde(rename = "k_V_per_g")]
    #[serde(deserialize_with = "crate::exact::matrix")]
    pub k_v_per_g: [[f64; 3]; 3],
    /// U0 \[V\].
    #[serde(rename = "u0_V")]
    #[serde(deserialize_with = "crate::exact::array")]
    pub u0_v: [f64; 3],
}

/// `[unit.conversion]`: `preset = "al15"` for all three, or `x`, `y`, `z` tables.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ConversionSpec {
    /// `al15`: Table V1 on every axis.
    #[serde(default)]
    pub preset: Option<ConversionPreset>,
    /// The x accelerometer.
    #[serde(default)]
    pub x: Option<CfSpec>,
    /// The y accelerometer.
    #[serde(default)]
    pub y: Option<CfSpec>,
    /// The z accelerometer.
    #[serde(default)]
    pub z: Option<CfSpec>,
}

/// `unit.conversion.preset`
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ConversionPreset {
    /// Table V1.
    Al15,
}

/// The rectifying coefficients of V(2) for one accelerometer (g units). Its linear part
/// (a0, m1, m2, the scale factor) is T(1)'s: give it in `k_V_per_g`, `u0_V`.
#[derive(Clone, Copy, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CfSpec {
    /// δ_1A \[1\].
    #[serde(default)]
    pub delta_1a: f64,
    /// k2 [g/g²].
    #[serde(default)]
    pub k2_g_per_g2: f64,
    /// k3 [g/g³].
    #[serde(default)]
    pub k3_g_per_g3: f64,
    /// k4 [g/g⁴].
    #[serde(default)]
    pub k4_g_per_g4: f64,
    /// k5 [g/g⁵].
    #[serde(default)]
    pub k5_g_per_g5: f64,
    /// m31 [g/g²].
    #[serde(default)]
    pub m31_g_per_g2: f64,
    /// m32 [g/g²].
    #[serde(default)]
    pub m32_g_per_g2: f64,
}

/// `[thermal]`
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ThermalSpec {
    /// Chamber temperature at the start [°C] (default T0).
    #[serde(default, rename = "start_C")]
    pub start_c: Option<f64>,
    /// Chamber ramp rate [°C/min] (default 1; `inf` jumps).
    #[serde(default = "one", rename = "rate_C_per_min")]
    pub rate_c_per_min: f64,
    /// Air → case time constant \[s\].
    #[serde(default)]
    pub case_tau_s: f64,
    /// Case → die time constant \[s\].
    #[serde(default)]
    pub die_tau_s: f64,
    /// Die above case once powered [°C].
    #[serde(default, rename = "self_heating_C")]
    pub self_heating_c: f64,
    /// Thermistor position: 0 = case, 1 = die.
    #[serde(default)]
    pub thermistor_at: f64,
    /// Thermistor time constant \[s\].
    #[serde(default)]
    pub thermistor_tau_s: f64,
    /// Hysteresis (play) width [°C].
    #[serde(default, rename = "hysteresis_C")]
    pub hysteresis_c: f64,
}

fn one() -> f64 {
    1.0
}

impl Default for ThermalSpec {
    fn default() -> Self {
        ThermalSpec {
            start_c: None,
            rate_c_per_min: 1.0,
            case_tau_s: 0.0,
            die_tau_s: 0.0,
            self_heating_c: 0.0,
            thermistor_at: 0.0,
            thermistor_tau_s: 0.0,
            hysteresis_c: 0.0,
        }
    }
}

/// A number for every axis, or one for all three.
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(untagged)]
pub enum PerAxis {
    /// The same on x, y, z.
    One(f64),
    /// x, y, z.
    Three([f64; 3]),
}

impl Default for PerAxis {
    fn default() -> Self {
        PerAxis::One(0.0)
    }
}

impl PerAxis {
    fn get(self) -> [f64; 3] {
        match self {
            PerAxis::One(v) => [v; 3],
            PerAxis::Three(v) => v,
        }
    }
}

/// `[noise]`
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseSpec {
    /// White noise per sample [V RMS].
    #[serde(default, rename = "white_V")]
    pub white_v: PerAxis,
    /// Bias random walk [V/√s].
    #[serde(default, rename = "random_walk_V_per_sqrt_s")]
    pub random_walk: PerAxis,
    /// Bias instability [V RMS].
    #[serde(default, rename = "bias_instability_V")]
    pub bias_instability: PerAxis,
    /// Bias instability correlation time \[s\] (one value or one per axis).
    #[serde(default)]
    pub bias_tau_s: PerAxis,
    /// A second Gauss–Markov bias [V RMS] (one value or one per axis).
    #[serde(default, rename = "bias_instability2_V")]
    pub bias_instability2: PerAxis,
    /// Its correlation time \[s\].
    #[serde(default)]
    pub bias_tau2_s: PerAxis,
    /// ADC step \[V\].
    #[serde(default, rename = "adc_lsb_V")]
    pub adc_lsb_v: f64,
    /// Thermistor noise [°C RMS].
    #[serde(default, rename = "temp_noise_C")]
    pub temp_noise_c: f64,
    /// Thermistor resolution [°C].
    #[serde(default, rename = "temp_resolution_C")]
    pub temp_resolution_c: f64,
    /// Thermistor offset [°C].
    #[serde(default, rename = "temp_offset_C")]
    pub temp_offset_c: f64,
    /// Vibration's fluctuation over one sample period (default false).
    #[serde(default)]
    pub vibration_sampling: bool,
}

/// `[[step]]`, by `kind`.
#[derive(Clone, Debug, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum StepSpec {
    /// New chamber set point, then hold the current position for `dwell_s`.
    Soak {
        /// Set point [°C].
        #[serde(rename = "chamber_C")]
        chamber_c: f64,
        /// Hold \[s\].
        dwell_s: f64,
        /// The rate of the move to this set point [°C/min] (default `thermal.rate_C_per_min`;
        /// `inf` jumps).
        #[serde(default, rename = "rate_C_per_min")]
        rate_c_per_min: Option<f64>,
    },
    /// A power cycle: the unit off for `off_s` where it is (no rows), the chamber holding or
    /// moving to `chamber_C`, then on again: `power_s`, the warm-up and the self-heating
    /// restart.
    Power {
        /// Time off \[s\].
        off_s: f64,
        /// A new set point from the turn-off on [°C] (default: the chamber holds).
        #[serde(default, rename = "chamber_C")]
        chamber_c: Option<f64>,
        /// The rate of the move to it [°C/min] (default `thermal.rate_C_per_min`).
        #[serde(default, rename = "rate_C_per_min")]
        rate_c_per_min: Option<f64>,
    },
    /// Tilter test positions TP1…TP6.
    Tilter {
        /// Which (1-based, default all six, in order).
        #[serde(default)]
        positions: Option<Vec<usize>>,
        /// Hold per position \[s\].
        dwell_s: f64,
        /// Turn between positions \[s\].
        #[serde(default)]
        move_s: f64,
        /// Placed by hand, not level: the largest tilt from the label [°] (default 0: level).
        #[serde(default)]
        tilt_deg: f64,
        /// The draw of the tilts.
        #[serde(default)]
        tilt_seed: u64,
    },
    /// A calibration by hand: a still start, then random orientations (no reference).
    Hand {
        /// New chamber set point from the still start on [°C] (which is then the soak).
        #[serde(default, rename = "chamber_C")]
        chamber_c: Option<f64>,
        /// Number of orientations.
        holds: usize,
        /// The still start where the unit is \[s\].
        init_s: f64,
        /// Hold per orientation \[s\].
        dwell_s: f64,
        /// Turn between orientations \[s\].
        #[serde(default)]
        move_s: f64,
        /// The draw of the orientations.
        #[serde(default)]
        seed: u64,
    },
    /// Check positions CP1…CP6.
    Check {
        /// Tilt [°], default 25, below 45.
        #[serde(default = "theta_default")]
        theta_deg: f64,
        /// Which (1-based, default all six).
        #[serde(default)]
        positions: Option<Vec<usize>>,
        /// Hold per position \[s\].
        dwell_s: f64,
        /// Turn between positions \[s\].
        #[serde(default)]
        move_s: f64,
    },
    /// The shake table's ten-position plan at each amplitude.
    Shake {
        /// `x`, `y` or `z`: the accelerometer under test.
        accelerometer: AxisName,
        /// `sine` (peak amplitude) or `random` (σ).
        vibration: ShakeKind,
        /// Table levels \[g\]: peak (sine) or σ (random).
        levels_g: Vec<f64>,
        /// Sine frequency \[Hz\].
        #[serde(default, rename = "freq_Hz")]
        freq_hz: Option<f64>,
        /// Random band \[Hz\].
        #[serde(default, rename = "band_Hz")]
        #[serde(deserialize_with = "keyed_band_hz_opt")]
        band_hz: Option<[f64; 2]>,
        /// Quiet hold per position \[s\].
        quiet_s: f64,
        /// Vibration hold per position \[s\].
        shake_s: f64,
        /// Turn between positions \[s\].
        #[serde(default)]
        move_s: f64,
    },
    /// Hold a given force (or a named position) with optional vibration.
    Hold {
        /// Static specific force \[g\].
        #[serde(default)]
        #[serde(deserialize_with = "keyed_f_g")]
        f_g: Option<[f64; 3]>,
        /// Or a position label: TP1…TP6, CP1…CP6 (with `theta_deg`).
        #[serde(default)]
        position: Option<String>,
        /// Tilt for CP positions [°].
        #[serde(default = "theta_default")]
        theta_deg: f64,
        /// Hold \[s\].
        dwell_s: f64,
        /// Turn to it first \[s\].
        #[serde(default)]
        move_s: f64,
        /// Vibration.
        #[serde(default)]
        vibration: Option<VibSpec>,
        /// `pos` label (default: the position's).
        #[serde(default)]
        label: Option<String>,
    },
    /// A flight segment: ramp to an acceleration, hold it under vibration.
    Flight {
        /// Static specific force \[g\].
        #[serde(deserialize_with = "keyed_accel_g")]
        accel_g: [f64; 3],
        /// Ramp from the previous acceleration \[s\] (reference known).
        #[serde(default)]
        ramp_s: f64,
        /// Hold \[s\].
        duration_s: f64,
        /// Vibration (ramp and hold).
        #[serde(default)]
        vibration: Option<VibSpec>,
        /// `pos` label.
        #[serde(default)]
        label: Option<String>,
    },
}

fn theta_default() -> f64 {
    25.0
}

/// `accelerometer`
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AxisName {
    /// x
    X,
    /// y
    Y,
    /// z
    Z,
}

/// `vibration` of a shake step.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ShakeKind {
    /// Harmonic.
    Sine,
    /// Random.
    Random,
}

crate::keyed_array!(keyed_band_hz_opt, "band_Hz", Option, 2);
crate::keyed_array!(keyed_f_g, "f_g", Option, 3);
crate::keyed_array!(keyed_accel_g, "accel_g", 3);
crate::keyed_array!(keyed_amp_g, "amp_g", 3);
crate::keyed_array!(keyed_sigma_g, "sigma_g", Option, 3);
crate::keyed_array!(keyed_psd, "psd_g2_per_Hz", Option, 3);
crate::keyed_array!(keyed_band_hz, "band_Hz", 2);

/// A vibration, by `kind`.
#[derive(Clone, Debug, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum VibSpec {
    /// None.
    None,
    /// Harmonic, in phase on all axes.
    Sine {
        /// Peak amplitude per axis \[g\].
        #[serde(deserialize_with = "keyed_amp_g")]
        amp_g: [f64; 3],
        /// Frequency \[Hz\].
        #[serde(rename = "freq_Hz")]
        freq_hz: f64,
    },
    /// Random, flat over the band, fully correlated.
    Random {
        /// σ per axis \[g\] (or `psd_g2_per_Hz`).
        #[serde(default)]
        #[serde(deserialize_with = "keyed_sigma_g")]
        sigma_g: Option<[f64; 3]>,
        /// Spectral density per axis [g²/Hz] (σ² = S·Δf).
        #[serde(default, rename = "psd_g2_per_Hz")]
        #[serde(deserialize_with = "keyed_psd")]
        psd: Option<[f64; 3]>,
        /// Band \[Hz\].
        #[serde(rename = "band_Hz")]
        #[serde(deserialize_with = "keyed_band_hz")]
        band_hz: [f64; 2],
    },
    /// One of the core's flight profiles from Tables V2/V3
    /// (`bins_comp::vibration::tables::flight_profiles`).
    FlightProfile {
        /// Index 0…6.
        index: usize,
    },
}

/// Why a scenario was rejected.
#[derive(Clone, Debug, PartialEq)]
pub struct ScenarioError {
    /// The file.
    pub file: PathBuf,
    /// Line, when known (syntax errors).
    pub line: Option<usize>,
    /// Key path (`step[2].theta_deg`), when there is one.
    pub key: Option<String>,
    /// What is wrong.
    pub reason: String,
}

impl fmt::Display for ScenarioError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file.display())?;
        if let Some(l) = self.line {
            write!(f, ":{l}")?;
        }
        if let Some(k) = &self.key {
            write!(f, ": {k}")?;
        }
        write!(f, ": {}", self.reason)
    }
}

impl std::error::Error for ScenarioError {}

/// A key error (no line).
fn kerr(key: impl Into<String>, reason: impl Into<String>) -> Issue {
    Issue { key: Some(key.into()), reason: reason.into() }
}

/// An error before the file is attached.
#[derive(Debug)]
struct Issue {
    key: Option<String>,
    reason: String,
}

type Check<T> = Result<T, Issue>;

fn finite(key: &str, v: f64) -> Check<f64> {
    if v.is_finite() { Ok(v) } else { Err(kerr(key, format!("must be a finite number, got {v}"))) }
}

fn non_negative(key: &str, v: f64) -> Check<f64> {
    if v.is_finite() && v >= 0.0 { Ok(v) } else { Err(kerr(key, format!("must be ≥ 0, got {v}"))) }
}

fn positive(key: &str, v: f64) -> Check<f64> {
    if v.is_finite() && v > 0.0 { Ok(v) } else { Err(kerr(key, format!("must be > 0, got {v}"))) }
}

fn temp_c(key: &str, v: f64) -> Check<f64> {
    if v.is_finite() && (-150.0..=250.0).contains(&v) {
        Ok(v)
    } else {
        Err(kerr(key, format!("must be a temperature in −150…250 °C, got {v}")))
    }
}

/// Most rows a scenario may make: 3 days at 1 kHz (the longest chamber runs, 72 h, at the
/// fastest logger rate are 2.6e8 rows, 35 GB of CSV); a scenario asking for 1e9 rows
/// (130 GB) is refused before anything is written.
pub const MAX_ROWS: f64 = 3e8;

/// Most rig segments (holds, moves, ramps) a scenario may make: checked as the steps are
/// built, so that a step like `holds = 1000000000` is refused before its segments are
/// allocated.
pub const MAX_SEGMENTS: usize = 1_000_000;

/// Largest noise amplitude of the signals \[V\] (white, random walk per √s, bias
/// instability): far above any accelerometer's, well below what overflows the sums.
pub const MAX_NOISE_V: f64 = 1.0;

/// Smallest ADC step \[V\] other than 0 (off): a 32-bit converter over 1 V has a step of
/// 2.3e-10 V.
pub const MIN_ADC_LSB_V: f64 = 1.0e-12;

/// A value in `lo..=hi`, the key named.
fn within(key: &str, v: f64, lo: f64, hi: f64, unit: &str) -> Check<f64> {
    if v.is_finite() && (lo..=hi).contains(&v) {
        Ok(v)
    } else {
        Err(kerr(key, format!("must be within {lo} … {hi} {unit}, got {v}")))
    }
}

/// A static specific force within the measuring range, each component's key named.
fn static_force(key: &str, f: &[f64; 3]) -> Check<()> {
    for (i, x) in f.iter().enumerate() {
        let kk = format!("{key}[{i}]");
        let a = finite(&kk, *x)?;
        if a.abs() > vibration::MAX_STATIC_G {
            return Err(kerr(kk, format!("{a} g is beyond the ±{} g measuring range", vibration::MAX_STATIC_G)));
        }
    }
    Ok(())
}

impl ScenarioFile {
    /// Parses TOML text; errors name `file`, the key path and, for syntax errors, the line.
    pub fn parse(text: &str, file: &Path) -> Result<Self, ScenarioError> {
        let line_of = |span: Option<std::ops::Range<usize>>| {
            span.map(|s| text[..s.start.min(text.len())].bytes().filter(|&b| b == b'\n').count() + 1)
        };
        let de = toml::Deserializer::parse(text).map_err(|e| ScenarioError {
            file: file.to_path_buf(),
            line: line_of(e.span()),
            key: None,
            reason: e.message().trim().to_string(),
        })?;
        serde_path_to_error::deserialize(de).map_err(|e| {
            let path = e.path().to_string();
            let inner = e.into_inner();
            ScenarioError {
                file: file.to_path_buf(),
                line: line_of(inner.span()),
                key: (path != ".").then_some(path),
                reason: inner.message().trim().to_string(),
            }
        })
    }

    /// Reads and parses a file.
    pub fn read(path: &Path) -> Result<Self, ScenarioError> {
        let text = crate::fsio::read_text(path).map_err(|e| {
            // read_text names the file; the error adds it again.
            let reason = e.to_string();
            let prefix = format!("{}: ", path.display());
            ScenarioError {
                file: path.to_path_buf(),
                line: None,
                key: None,
                reason: reason.strip_prefix(&prefix).unwrap_or(&reason).to_string(),
            }
        })?;
        Self::parse(&text, path)
    }

    /// Checks every value and builds the simulation; errors name `file` and the key.
    pub fn build(&self, file: &Path) -> Result<Simulation, ScenarioError> {
        self.build_inner().map_err(|i| ScenarioError {
            file: file.to_path_buf(),
            line: None,
            key: i.key,
            reason: i.reason,
        })
    }

    fn build_inner(&self) -> Check<Simulation> {
        let r = &self.recording;
        let rate_hz = positive("recording.rate_Hz", r.rate_hz)?;
        let power_on_s = within("recording.power_on_s", r.power_on_s, 0.0, crate::numarg::MAX_DURATION_S, "s")?;
        for (i, c) in r.comments.iter().enumerate() {
            if c.contains(['\n', '\r']) {
                return Err(kerr(format!("recording.comments[{i}]"), "must be one line"));
            }
        }
        let unit = self.unit.build()?;
        let thermal = self.thermal.build(unit.params.t0_c)?;
        let noise = self.noise.build()?;
        let start_f = match r.start_f_g {
            Some(f) => {
                static_force("recording.start_f_g", &f)?;
                f
            }
            None => TILTER_POSITIONS_G[0],
        };
        if self.step.is_empty() {
            return Err(kerr("step", "no steps: the scenario needs at least one [[step]]"));
        }
        let mut tl = Timeline::new(start_f);
        for (i, s) in self.step.iter().enumerate() {
            if matches!(s, StepSpec::Power { .. }) && i + 1 == self.step.len() {
                return Err(kerr(
                    format!("step[{i}]"),
                    "a power cycle must be followed by a step (the one the unit is back on for)",
                ));
            }
            build_step(&mut tl, s, &format!("step[{i}]"), rate_hz)?;
            if tl.segments.len() > MAX_SEGMENTS {
                return Err(kerr(format!("step[{i}]"), format!("more than {MAX_SEGMENTS} rig segments in all")));
            }
        }
        let rows = tl.duration_s() * rate_hz;
        if rows > MAX_ROWS {
            return Err(kerr(
                "step",
                format!("{rows:.3e} rows at recording.rate_Hz = {rate_hz}: more than {MAX_ROWS:e}"),
            ));
        }
        if rows < 1.0 {
            return Err(kerr("step", "the steps last less than one sample period"));
        }
        let mut comments = Vec::new();
        if let Some(d) = &self.description {
            comments.extend(d.lines().map(str::to_string));
        }
        comments.extend(r.comments.iter().cloned());
        let sim = Simulation {
            unit,
            thermal,
            noise,
            segments: tl.segments,
            rate_hz,
            power_on_s,
            log_chamber: r.log_chamber,
            comments,
        };
        if sim.n_rows() == 0 {
            return Err(kerr("step", "the unit is off at every row"));
        }
        Ok(sim)
    }
}

fn positions(key: &str, p: &Option<Vec<usize>>) -> Check<Vec<usize>> {
    match p {
        None => Ok((1..=6).collect()),
        Some(v) if v.is_empty() => Err(kerr(key, "empty list")),
        Some(v) => {
            for (i, k) in v.iter().enumerate() {
                if !(1..=6).contains(k) {
                    return Err(kerr(format!("{key}[{i}]"), format!("position {k} does not exist (1…6)")));
                }
            }
            Ok(v.clone())
        }
    }
}

/// A chamber rate given in °C/min, as °C/s: > 0, `inf` jumps.
fn chamber_rate(key: &str, per_min: f64) -> Check<f64> {
    if per_min > 0.0 { Ok(per_min / 60.0) } else { Err(kerr(key, format!("must be > 0 (inf: jumps), got {per_min}"))) }
}

fn theta(key: &str, v: f64) -> Check<f64> {
    if v.is_finite() && (0.0..45.0).contains(&v) {
        Ok(v)
    } else {
        Err(kerr(key, format!("must be in [0, 45) ° (the check positions need θ < 45°), got {v}")))
    }
}

fn build_step(tl: &mut Timeline, s: &StepSpec, key: &str, rate_hz: f64) -> Check<()> {
    let k = |f: &str| format!("{key}.{f}");
    match s {
        StepSpec::Soak { chamber_c, dwell_s, rate_c_per_min } => {
            let c = temp_c(&k("chamber_C"), *chamber_c)?;
            match rate_c_per_min {
                Some(r) => tl.set_chamber_at_rate(c, chamber_rate(&k("rate_C_per_min"), *r)?),
                None => tl.set_chamber(c),
            }
            tl.hold(positive(&k("dwell_s"), *dwell_s)?, Vibration::None, None);
        }
        StepSpec::Power { off_s, chamber_c, rate_c_per_min } => {
            let off = positive(&k("off_s"), *off_s)?;
            within(&k("off_s"), off, 0.0, crate::numarg::MAX_DURATION_S, "s")?;
            match (chamber_c, rate_c_per_min) {
                (Some(c), Some(r)) => {
                    let c = temp_c(&k("chamber_C"), *c)?;
                    tl.set_chamber_at_rate(c, chamber_rate(&k("rate_C_per_min"), *r)?);
                }
                (Some(c), None) => tl.set_chamber(temp_c(&k("chamber_C"), *c)?),
                (None, Some(_)) => return Err(kerr(k("rate_C_per_min"), "only with chamber_C (a new set point)")),
                (None, None) => {}
            }
            tl.power_off(off);
        }
        StepSpec::Tilter { positions: p, dwell_s, move_s, tilt_deg, tilt_seed } => {
            let which = positions(&k("positions"), p)?;
            let (dwell, mv) = (positive(&k("dwell_s"), *dwell_s)?, non_negative(&k("move_s"), *move_s)?);
            let tilt = non_negative(&k("tilt_deg"), *tilt_deg)?;
            if tilt > 10.0 {
                return Err(kerr(k("tilt_deg"), format!("{tilt}° is not a small tilt (at most 10°)")));
            }
            if tilt > 0.0 {
                tl.tilter_unlevel(&which, dwell, mv, tilt.to_radians(), *tilt_seed);
            } else {
                tl.tilter(&which, dwell, mv);
            }
        }
        StepSpec::Hand { chamber_c, holds, init_s, dwell_s, move_s, seed } => {
            if *holds == 0 {
                return Err(kerr(k("holds"), "at least one orientation"));
            }
            // Two segments (move, hold) per orientation, checked before any is made.
            if *holds > MAX_SEGMENTS / 2 {
                return Err(kerr(k("holds"), format!("{holds} orientations: at most {}", MAX_SEGMENTS / 2)));
            }
            if let Some(c) = chamber_c {
                tl.set_chamber(temp_c(&k("chamber_C"), *c)?);
            }
            let (init, dwell, mv) = (
                positive(&k("init_s"), *init_s)?,
                positive(&k("dwell_s"), *dwell_s)?,
                non_negative(&k("move_s"), *move_s)?,
            );
            // The rows the whole timeline would have with this step, checked before its
            // segments are made (up to a million of them).
            let rows = (tl.duration_s() + init + *holds as f64 * (dwell + mv)) * rate_hz;
            if rows > MAX_ROWS {
                return Err(kerr(
                    k("holds"),
                    format!(
                        "{holds} holds of {dwell} + {mv} s: {rows:.3e} rows at recording.rate_Hz = {rate_hz}, more than {MAX_ROWS:e}"
                    ),
                ));
            }
            tl.hand(*holds, init, dwell, mv, *seed);
        }
        StepSpec::Check { theta_deg, positions: p, dwell_s, move_s } => {
            let which = positions(&k("positions"), p)?;
            let th = theta(&k("theta_deg"), *theta_deg)?;
            tl.check(&which, th, positive(&k("dwell_s"), *dwell_s)?, non_negative(&k("move_s"), *move_s)?);
        }
        StepSpec::Shake { accelerometer, vibration: kind, levels_g, freq_hz, band_hz, quiet_s, shake_s, move_s } => {
            let axis = match accelerometer {
                AxisName::X => Axis::X,
                AxisName::Y => Axis::Y,
                AxisName::Z => Axis::Z,
            };
            if levels_g.is_empty() {
                return Err(kerr(k("levels_g"), "empty list"));
            }
            let quiet = positive(&k("quiet_s"), *quiet_s)?;
            let shake = positive(&k("shake_s"), *shake_s)?;
            let mv = non_negative(&k("move_s"), *move_s)?;
            let make: Box<dyn Fn([f64; 3]) -> Vibration<f64>> = match kind {
                ShakeKind::Sine => {
                    if band_hz.is_some() {
                        return Err(kerr(k("band_Hz"), "only for vibration = \"random\""));
                    }
                    let f = positive(&k("freq_Hz"), freq_hz.ok_or_else(|| kerr(k("freq_Hz"), "required for sine"))?)?;
                    Box::new(move |a| Vibration::Harmonic { amp_g: a, freq_hz: f })
                }
                ShakeKind::Random => {
                    if freq_hz.is_some() {
                        return Err(kerr(k("freq_Hz"), "only for vibration = \"sine\" (random takes band_Hz)"));
                    }
                    let b = band_hz.ok_or_else(|| kerr(k("band_Hz"), "required for random"))?;
                    let b = band(&k("band_Hz"), b)?;
                    Box::new(move |a| Vibration::Random { sigma_g: a, band_hz: b })
                }
            };
            for (i, l) in levels_g.iter().enumerate() {
                let lk = format!("{}[{i}]", k("levels_g"));
                let l = positive(&lk, *l)?;
                // TP9/TP10 vibrate along a diagonal at √2 times the level.
                if l * std::f64::consts::SQRT_2 > vibration::MAX_LEVEL_G {
                    return Err(kerr(
                        lk,
                        format!("{l} g: the diagonal positions would exceed {} g", vibration::MAX_LEVEL_G),
                    ));
                }
                tl.shake_plan(axis, l, &make, quiet, shake, mv);
                if tl.segments.len() > MAX_SEGMENTS {
                    return Err(kerr(lk, format!("more than {MAX_SEGMENTS} rig segments in all")));
                }
            }
        }
        StepSpec::Hold { f_g, position, theta_deg, dwell_s, move_s, vibration: v, label } => {
            let (f, default_label) = match (f_g, position) {
                (Some(_), Some(_)) => return Err(kerr(k("position"), "give f_g or position, not both")),
                (None, None) => return Err(kerr(key, "needs f_g or position")),
                (Some(f), None) => {
                    static_force(&k("f_g"), f)?;
                    (*f, None)
                }
                (None, Some(p)) => {
                    (named_position(&k("position"), p, theta(&k("theta_deg"), *theta_deg)?)?, Some(p.clone()))
                }
            };
            let vib = vib_spec(&k("vibration"), v.as_ref())?;
            tl.move_to(f, non_negative(&k("move_s"), *move_s)?);
            tl.hold(positive(&k("dwell_s"), *dwell_s)?, vib, label.clone().or(default_label));
        }
        StepSpec::Flight { accel_g, ramp_s, duration_s, vibration: v, label } => {
            for (i, x) in accel_g.iter().enumerate() {
                let a = finite(&format!("{}[{i}]", k("accel_g")), *x)?;
                if a.abs() > vibration::MAX_STATIC_G {
                    return Err(kerr(
                        format!("{}[{i}]", k("accel_g")),
                        format!("{a} g is beyond the ±{} g measuring range", vibration::MAX_STATIC_G),
                    ));
                }
            }
            let vib = vib_spec(&k("vibration"), v.as_ref())?;
            // A ramp of zero length is a step change: the hold starts at the new value.
            tl.ramp_to(*accel_g, non_negative(&k("ramp_s"), *ramp_s)?, vib, label.clone());
            tl.hold(positive(&k("duration_s"), *duration_s)?, vib, label.clone());
        }
    }
    Ok(())
}

fn named_position(key: &str, p: &str, theta_deg: f64) -> Check<[f64; 3]> {
    let idx = |s: &str| s.parse::<usize>().ok().filter(|k| (1..=6).contains(k));
    if let Some(k) = p.strip_prefix("TP").and_then(idx) {
        return Ok(TILTER_POSITIONS_G[k - 1]);
    }
    if let Some(k) = p.strip_prefix("CP").and_then(idx) {
        return Ok(check_positions_g(theta_deg)[k - 1]);
    }
    Err(kerr(key, format!("`{p}` is not a position (TP1…TP6, CP1…CP6)")))
}

fn band(key: &str, b: [f64; 2]) -> Check<(f64, f64)> {
    if b[0].is_finite() && b[1].is_finite() && b[0] >= 0.0 && b[1] > b[0] {
        Ok((b[0], b[1]))
    } else {
        Err(kerr(key, format!("must be [low, high] with 0 ≤ low < high, got {b:?}")))
    }
}

fn vib_spec(key: &str, v: Option<&VibSpec>) -> Check<Vibration<f64>> {
    let out = match v {
        None | Some(VibSpec::None) => Vibration::None,
        Some(VibSpec::Sine { amp_g, freq_hz }) => {
            Vibration::Harmonic { amp_g: *amp_g, freq_hz: positive(&format!("{key}.freq_Hz"), *freq_hz)? }
        }
        Some(VibSpec::Random { sigma_g, psd, band_hz }) => {
            let b = band(&format!("{key}.band_Hz"), *band_hz)?;
            match (sigma_g, psd) {
                (Some(s), None) => {
                    for (i, x) in s.iter().enumerate() {
                        non_negative(&format!("{key}.sigma_g[{i}]"), *x)?;
                    }
                    Vibration::Random { sigma_g: *s, band_hz: b }
                }
                (None, Some(p)) => {
                    for (i, x) in p.iter().enumerate() {
                        non_negative(&format!("{key}.psd_g2_per_Hz[{i}]"), *x)?;
                    }
                    Vibration::random_from_psd(*p, b)
                }
                _ => return Err(kerr(key, "random vibration needs exactly one of sigma_g, psd_g2_per_Hz")),
            }
        }
        Some(VibSpec::FlightProfile { index }) => {
            let (profiles, n) = vibration::tables::flight_profiles();
            if *index >= n as usize {
                return Err(kerr(format!("{key}.index"), format!("{index}: the flight profiles are 0…{}", n - 1)));
            }
            profiles[*index]
        }
    };
    if !out.is_valid() {
        return Err(kerr(
            key,
            format!("not a valid vibration (finite, levels within {} g, frequency ≥ 0)", vibration::MAX_LEVEL_G),
        ));
    }
    Ok(out)
}

impl UnitSpec {
    fn build(&self) -> Check<UnitModel> {
        let (params, preset_cf) = self.constants()?;
        let c0 = &params.constants;
        if c0.inverse().is_none() {
            return Err(kerr("unit.k_V_per_g", "K is singular or ill-conditioned"));
        }
        for i in 0..3 {
            if !(c0.k_v_per_g[i][i].abs() > 1e-6) {
                return Err(kerr("unit.k_V_per_g", format!("scale factor K[{i}][{i}] is zero")));
            }
        }
        if let Err(e) = params.model.check() {
            return Err(kerr("unit", format!("temperature model: {e}")));
        }
        let cf = match &self.conversion {
            None => preset_cf,
            Some(c) => c.build()?,
        };
        for (i, w) in self.warmup_v.iter().enumerate() {
            within(&format!("unit.warmup_V[{i}]"), *w, -MAX_NOISE_V, MAX_NOISE_V, "V")?;
        }
        Ok(UnitModel {
            params,
            cf,
            warmup_v: self.warmup_v,
            warmup_tau_s: within("unit.warmup_tau_s", self.warmup_tau_s, 0.0, MAX_TAU_S, "s")?,
            bias_play_g: {
                let mut g = [0.0; 3];
                for (i, a) in self.bias_play_mg.iter().enumerate() {
                    let max_mg = MAX_BIAS_PLAY_G * 1e3;
                    g[i] = within(&format!("unit.bias_play_mg[{i}]"), *a, -max_mg, max_mg, "mg")? * 1e-3;
                }
                g
            },
            bias_play_width_c: within("unit.bias_play_width_C", self.bias_play_width_c, 0.0, MAX_WIDTH_C, "°C")?,
        })
    }

    /// The constants at T0 with their temperature model, and the preset's conversion
    /// functions (linear unless the preset is `al15`).
    fn constants(&self) -> Check<(CalibrationParams, [ConversionFunction<f64>; 3])> {
        let linear = [ConversionFunction::default(); 3];
        let explicit = self.k_v_per_g.is_some() || self.u0_v.is_some();
        let (t0, c0, points, cf) = match self.preset {
            Some(p) => {
                if explicit {
                    return Err(kerr("unit.preset", "give a preset or k_V_per_g/u0_V, not both"));
                }
                if !self.at.is_empty() {
                    return Err(kerr("unit.at", "not allowed with a preset"));
                }
                match p {
                    Preset::Paper => {
                        if self.t0_c.is_some_and(|t| t != paper::T0_C) {
                            return Err(kerr("unit.t0_C", format!("the paper's T0 is {} °C", paper::T0_C)));
                        }
                        (paper::T0_C, paper::TABLE_CONSTANTS[0], paper::off_nominal_points().to_vec(), linear)
                    }
                    Preset::Al15 => {
                        let t0 = finite("unit.t0_C", self.t0_c.unwrap_or(20.0))?;
                        (t0, al15_constants(), Vec::new(), [vibration::tables::AL15; 3])
                    }
                }
            }
            None => {
                let k = self.k_v_per_g.ok_or_else(|| kerr("unit.k_V_per_g", "required (or unit.preset)"))?;
                let u0 = self.u0_v.ok_or_else(|| kerr("unit.u0_V", "required (or unit.preset)"))?;
                let t0 = self.t0_c.ok_or_else(|| kerr("unit.t0_C", "required (or unit.preset)"))?;
                let c = Constants { k_v_per_g: k, u0_v: u0 };
                if !c.is_finite() {
                    return Err(kerr("unit", "k_V_per_g and u0_V must be finite"));
                }
                let mut pts = Vec::new();
                for (i, a) in self.at.iter().enumerate() {
                    let ci = Constants { k_v_per_g: a.k_v_per_g, u0_v: a.u0_v };
                    temp_c(&format!("unit.at[{i}].temp_C"), a.temp_c)?;
                    if !ci.is_finite() {
                        return Err(kerr(format!("unit.at[{i}]"), "k_V_per_g and u0_V must be finite"));
                    }
                    pts.push((a.temp_c, ci));
                }
                (temp_c("unit.t0_C", t0)?, c, pts, linear)
            }
        };
        let model = match (&self.temperature_model, points.is_empty()) {
            (Some(_), false) => {
                return Err(kerr("unit.temperature_model", "give it or constants at several temperatures, not both"));
            }
            (Some(m), true) => {
                if self.fit.is_some() || self.order.is_some() {
                    return Err(kerr("unit.fit", "only for constants at several temperatures"));
                }
                let file = CalibrationFile {
                    serial: None,
                    calibration_date: None,
                    tool_version: None,
                    t0_c: t0,
                    temp_range_c: [t0 - 1.0, t0 + 1.0],
                    k_v_per_g: c0.k_v_per_g,
                    u0_v: c0.u0_v,
                    method: MethodSpec { kind: MethodKind::Uncorrected, form: None },
                    temperature_model: m.clone(),
                    vibration: None,
                    thermal_dynamics: None,
                };
                file.to_params().map_err(|e| Issue { key: None, reason: format!("unit.{e}") })?.0.model
            }
            (None, true) => {
                if self.fit.is_some() || self.order.is_some() {
                    return Err(kerr("unit.fit", "only for constants at several temperatures"));
                }
                // No temperature dependence: a first-order polynomial with zero coefficients.
                TempModel::Poly { order: 1, coef: [Default::default(); MAX_POLY_ORDER] }
            }
            (None, false) => match self.fit.unwrap_or(FitKind::Poly) {
                FitKind::Poly => {
                    let order = self.order.unwrap_or(2);
                    ident::poly_from_constants(t0, &c0, &points, order)
                        .map_err(|e| kerr("unit.order", format!("polynomial of order {order}: {e}")))?
                }
                FitKind::Pwl => {
                    if self.order.is_some() {
                        return Err(kerr("unit.order", "only for fit = \"poly\""));
                    }
                    ident::pwl_from_constants(t0, &c0, &points).map_err(|e| kerr("unit.at", e.to_string()))?
                }
            },
        };
        let params = CalibrationParams {
            constants: c0,
            t0_c: t0,
            model,
            method: Method::Uncorrected,
            temp_range_c: paper::TEMP_RANGE_C,
        };
        Ok((params, cf))
    }
}

/// Three AL-15s (Table V1) as T(1) constants: `K_ii = K1`, the additive cross-sensitivities
/// `m1` (OA) and `m2` (PA) times K1 off the diagonal, `U0_i = K1·a0`.
pub fn al15_constants() -> Constants<f64> {
    let cf = vibration::tables::AL15;
    let k1 = vibration::tables::AL15_K1_V_PER_G;
    let mut k = [[0.0; 3]; 3];
    for (i, axis) in Axis::ALL.into_iter().enumerate() {
        let row = super::rig::to_unit(AccelAxes { ia: 1.0, pa: cf.m2_g_per_g, oa: cf.m1_g_per_g }, axis);
        k[i] = row.map(|x| k1 * x);
    }
    Constants { k_v_per_g: k, u0_v: [k1 * cf.a0_g; 3] }
}

impl ConversionSpec {
    fn build(&self) -> Check<[ConversionFunction<f64>; 3]> {
        match (self.preset, &self.x, &self.y, &self.z) {
            (Some(ConversionPreset::Al15), None, None, None) => Ok([vibration::tables::AL15; 3]),
            (Some(_), ..) => Err(kerr("unit.conversion.preset", "give a preset or x/y/z tables, not both")),
            (None, x, y, z) => {
                let mut out = [ConversionFunction::default(); 3];
                for (o, (name, s)) in out.iter_mut().zip([("x", x), ("y", y), ("z", z)]) {
                    let s = s.unwrap_or_default();
                    let cf = ConversionFunction {
                        delta_1a: s.delta_1a,
                        k2_g_per_g2: s.k2_g_per_g2,
                        k3_g_per_g3: s.k3_g_per_g3,
                        k4_g_per_g4: s.k4_g_per_g4,
                        k5_g_per_g5: s.k5_g_per_g5,
                        m31_g_per_g2: s.m31_g_per_g2,
                        m32_g_per_g2: s.m32_g_per_g2,
                        ..ConversionFunction::default()
                    };
                    if !cf.is_finite() {
                        return Err(kerr(format!("unit.conversion.{name}"), "coefficients must be finite"));
                    }
                    *o = cf;
                }
                Ok(out)
            }
        }
    }
}

impl ThermalSpec {
    fn build(&self, t0_c: f64) -> Check<ThermalParams> {
        let rate = self.rate_c_per_min;
        if !(rate > 0.0) {
            return Err(kerr("thermal.rate_C_per_min", format!("must be > 0 (inf: jumps), got {rate}")));
        }
        let at = self.thermistor_at;
        if !(0.0..=1.0).contains(&at) {
            return Err(kerr("thermal.thermistor_at", format!("must be in [0, 1] (0 = case, 1 = die), got {at}")));
        }
        Ok(ThermalParams {
            start_c: temp_c("thermal.start_C", self.start_c.unwrap_or(t0_c))?,
            rate_c_per_s: rate / 60.0,
            case_tau_s: within("thermal.case_tau_s", self.case_tau_s, 0.0, MAX_TAU_S, "s")?,
            die_tau_s: within("thermal.die_tau_s", self.die_tau_s, 0.0, MAX_TAU_S, "s")?,
            self_heating_c: within("thermal.self_heating_C", self.self_heating_c, -MAX_WIDTH_C, MAX_WIDTH_C, "°C")?,
            thermistor_at: at,
            thermistor_tau_s: within("thermal.thermistor_tau_s", self.thermistor_tau_s, 0.0, MAX_TAU_S, "s")?,
            hysteresis_c: within("thermal.hysteresis_C", self.hysteresis_c, 0.0, MAX_WIDTH_C, "°C")?,
        })
    }
}

impl NoiseSpec {
    fn build(&self) -> Check<NoiseParams> {
        let per = |key: &str, v: PerAxis| -> Check<[f64; 3]> {
            let a = v.get();
            for (i, x) in a.iter().enumerate() {
                within(&format!("noise.{key}[{i}]"), *x, 0.0, MAX_NOISE_V, "V")?;
            }
            Ok(a)
        };
        // A Gauss–Markov term: its RMS per axis and its correlation time, > 0 where the RMS is.
        let gauss_markov =
            |sigma_key: &str, sigma: PerAxis, tau_key: &str, tau: PerAxis| -> Check<([f64; 3], [f64; 3])> {
                let sigma = per(sigma_key, sigma)?;
                let (one, taus) = (matches!(tau, PerAxis::One(_)), tau.get());
                for i in 0..3 {
                    let key = if one { format!("noise.{tau_key}") } else { format!("noise.{tau_key}[{i}]") };
                    within(&key, taus[i], 0.0, MAX_TAU_S, "s")?;
                    if sigma[i] > 0.0 && taus[i] == 0.0 {
                        return Err(kerr(&key, format!("must be > 0 when {sigma_key} is given")));
                    }
                }
                Ok((sigma, taus))
            };
        let (bias_instability_v, bias_tau_s) =
            gauss_markov("bias_instability_V", self.bias_instability, "bias_tau_s", self.bias_tau_s)?;
        let (bias_instability2_v, bias_tau2_s) =
            gauss_markov("bias_instability2_V", self.bias_instability2, "bias_tau2_s", self.bias_tau2_s)?;
        Ok(NoiseParams {
            white_v: per("white_V", self.white_v)?,
            random_walk_v_per_sqrt_s: per("random_walk_V_per_sqrt_s", self.random_walk)?,
            bias_instability_v,
            bias_tau_s,
            bias_instability2_v,
            bias_tau2_s,
            adc_lsb_v: match within("noise.adc_lsb_V", self.adc_lsb_v, 0.0, MAX_NOISE_V, "V")? {
                v if v > 0.0 && v < MIN_ADC_LSB_V => {
                    return Err(kerr(
                        "noise.adc_lsb_V",
                        format!("{v} V: 0 (no quantisation) or at least {MIN_ADC_LSB_V} V"),
                    ));
                }
                v => v,
            },
            temp_noise_c: within("noise.temp_noise_C", self.temp_noise_c, 0.0, MAX_WIDTH_C, "°C")?,
            temp_resolution_c: within("noise.temp_resolution_C", self.temp_resolution_c, 0.0, MAX_WIDTH_C, "°C")?,
            temp_offset_c: within("noise.temp_offset_C", self.temp_offset_c, -MAX_WIDTH_C, MAX_WIDTH_C, "°C")?,
            vibration_sampling: self.vibration_sampling,
        })
    }
}

/// Reads, checks and builds a scenario file.
pub fn load(path: &Path) -> Result<Simulation, ScenarioError> {
    ScenarioFile::read(path)?.build(path)
}
