//! The calibration blob: the one byte format in which a calibration travels from the host
//! tool to the CALIB flash region. This module owns that format (specified in
//! `docs/calibration-blob.md`), its parser, its encoder, its CRC-32 and the physical limits a
//! flashed calibration must respect.
//!
//! The parser is zero-copy over `&[u8]`, allocates nothing and cannot panic; every way a blob
//! can be wrong is a typed [`BlobError`] naming the field (as the calibration file spells it,
//! see [`Field`]) and the byte offset where that applies. A blob that parses is a calibration
//! [`Calibration::new`] accepts (and, with the optional vibration sections, a configuration
//! [`VibrationConfig::new`] accepts): [`parse`] runs their checks too (the vibration ones
//! value by value, with limits that imply them). [`load_region`] gives
//! the firmware both configurations of the per-sample step from the CALIB region.
//!
//! # Layout (format version 1, all integers and floats little-endian)
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `"BCAL"` |
//! | 4 | 2 | format version (1) |
//! | 6 | 2 | section count n (≤ [`MAX_SECTIONS`]) |
//! | 8 | 4 | total length L, CRC included ([`MIN_BLOB_BYTES`]..=[`MAX_BLOB_BYTES`]) |
//! | 12 | 4 | reserved, zero |
//! | 16 | 12·n | section table: id u16, flags u16, offset u32, length u32 |
//! | … | … | section payloads, inside `[16 + 12·n, L − 4)`, not overlapping |
//! | L − 4 | 4 | CRC-32 (IEEE, reflected) of bytes `[0, L − 4)` |
//!
//! Checks run in this order: length ≥ header, magic, version, declared length, CRC, then the
//! header's reserved word, the section table and the sections. So a corrupted blob is
//! reported as such (bad magic, bad version, a length error or a CRC mismatch) before any of
//! its contents is interpreted.

use core::cell::Cell;

use crate::compensate::{Calibration, CalibrationError, CalibrationParams, Form, Method};
use crate::dynamics::{self, DynamicsError, FixedRate, ThermalDynamics};
use crate::float::Float;
use crate::float::cmp_f64::{eq, le, lt};
use crate::model::Constants;
use crate::temperature::{CoefDelta, MAX_KNOTS, MAX_POLY_ORDER, TempModel};
use crate::vibration::{
    ConversionFunction, MAX_LEVEL_G, MAX_PROFILES, Variant, Vibration, VibrationConfig, VibrationParams,
};

/// The first four bytes of every blob.
pub const MAGIC: [u8; 4] = *b"BCAL";
/// The format version this parser reads and this encoder writes. It changes only for an
/// incompatible change of the header, the section table or an existing section; new content
/// comes as new sections (see [`FLAG_REQUIRED`]).
pub const FORMAT_VERSION: u16 = 1;
/// Size of the fixed header.
pub const HEADER_BYTES: usize = 16;
/// Size of one section-table entry.
pub const ENTRY_BYTES: usize = 12;
/// Size of the trailing CRC.
pub const CRC_BYTES: usize = 4;
/// Smallest possible declared length: a header and a CRC.
pub const MIN_BLOB_BYTES: usize = HEADER_BYTES + CRC_BYTES;
/// Largest blob: the size of the CALIB flash region.
pub const MAX_BLOB_BYTES: usize = 4096;
/// Most sections a blob may have.
pub const MAX_SECTIONS: usize = 16;
/// Longest text (serial, tool version) in bytes; text is printable ASCII (0x20..=0x7E).
pub const MAX_TEXT_BYTES: usize = 32;
/// Section flag: a parser that does not know the section's id must reject the blob. Unknown
/// sections without it are skipped. All other flag bits are reserved and must be zero.
pub const FLAG_REQUIRED: u16 = 1 << 0;

/// Section ids. Id 0 is never assigned.
pub mod section {
    /// The 12 constants at T0 and T0 (required).
    pub const CONSTANTS: u16 = 0x0001;
    /// The temperature model and its coefficients (required).
    pub const TEMP_MODEL: u16 = 0x0002;
    /// The compensation method and, for method 2, its form (required).
    pub const METHOD: u16 = 0x0003;
    /// The calibrated temperature range (required).
    pub const TEMP_RANGE: u16 = 0x0004;
    /// The vibration error: the variant and the conversion-function coefficients of each
    /// accelerometer (optional; written REQUIRED).
    pub const VIBRATION: u16 = 0x0005;
    /// The flight-phase vibration profiles (optional, only with [`VIBRATION`]; written
    /// REQUIRED).
    pub const FLIGHT_PHASES: u16 = 0x0006;
    /// The thermal dynamics between the thermistor and the sensing elements (optional;
    /// written REQUIRED). Absent: no dynamics, the temperature model is evaluated at the
    /// reading.
    pub const THERMAL_DYNAMICS: u16 = 0x0007;
    /// The unit's serial number, printable ASCII (optional).
    pub const SERIAL: u16 = 0x0101;
    /// The calibration date (optional).
    pub const CAL_DATE: u16 = 0x0102;
    /// The version of the tool that produced the calibration, printable ASCII (optional).
    pub const TOOL_VERSION: u16 = 0x0103;
    /// Every id this version of the parser understands.
    pub const KNOWN: [u16; 10] = [
        CONSTANTS,
        TEMP_MODEL,
        METHOD,
        TEMP_RANGE,
        VIBRATION,
        FLIGHT_PHASES,
        THERMAL_DYNAMICS,
        SERIAL,
        CAL_DATE,
        TOOL_VERSION,
    ];
    /// The ids a version-1 blob must contain.
    pub const MANDATORY: [u16; 4] = [CONSTANTS, TEMP_MODEL, METHOD, TEMP_RANGE];
}

/// Size of the constants section: T0, K row-major, U0 (13 × f64).
pub const CONSTANTS_BYTES: usize = 13 * 8;
/// Size of the method section.
pub const METHOD_BYTES: usize = 8;
/// Size of the temperature-range section: min, max (2 × f64).
pub const TEMP_RANGE_BYTES: usize = 16;
/// Size of the calibration-date section: year u16, month u8, day u8.
pub const CAL_DATE_BYTES: usize = 4;
/// Size of the temperature-model section's own header: kind u8, count u8, 6 reserved bytes.
pub const MODEL_HEADER_BYTES: usize = 8;
/// Size of one coefficient set in the model section: ΔU0 (3 × f64), then ΔK/K row-major
/// (9 × f64), the order of [`CoefDelta::to_array`].
pub const COEF_SET_BYTES: usize = 12 * 8;

/// Size of the vibration section's own header: variant u8, 7 reserved bytes.
pub const VIBRATION_HEADER_BYTES: usize = 8;
/// Size of one accelerometer's conversion function in the vibration section: the 10
/// coefficients of [`ConversionFunction::to_array`] as f64.
pub const CONVERSION_FUNCTION_BYTES: usize = 10 * 8;
/// Size of the vibration section: header and the x, y, z conversion functions.
pub const VIBRATION_BYTES: usize = VIBRATION_HEADER_BYTES + 3 * CONVERSION_FUNCTION_BYTES;
/// Size of the flight-phase section's own header: count u8, 7 reserved bytes.
pub const PROFILES_HEADER_BYTES: usize = 8;
/// Size of one profile: kind u8, 7 reserved bytes, 5 f64.
pub const PROFILE_BYTES: usize = 48;

/// Vibration-section code of [`Variant::Paper`].
pub const VARIANT_PAPER: u8 = 1;
/// Vibration-section code of [`Variant::Exact`].
pub const VARIANT_EXACT: u8 = 2;
/// Profile kind code of [`Vibration::None`].
pub const PROFILE_NONE: u8 = 0;
/// Profile kind code of [`Vibration::Harmonic`].
pub const PROFILE_SINE: u8 = 1;
/// Profile kind code of [`Vibration::Random`].
pub const PROFILE_RANDOM: u8 = 2;

/// Header of the thermal-dynamics section: its layout version u8, 7 reserved zero bytes.
pub const DYNAMICS_HEADER_BYTES: usize = 8;
/// Size of the thermal-dynamics section: the header and 8 × f64 (`lag_tau_s`,
/// `hysteresis_width_c`, `self_heating_c`, `self_heating_tau_s`, `bias_play_width_c`,
/// `bias_play_g` x, y, z).
pub const DYNAMICS_BYTES: usize = DYNAMICS_HEADER_BYTES + 8 * 8;
/// The layout version of the thermal-dynamics section this parser reads.
pub const DYNAMICS_LAYOUT: u8 = 1;

/// Model-section kind code of [`TempModel::Poly`].
pub const KIND_POLY: u8 = 1;
/// Model-section kind code of [`TempModel::Pwl`].
pub const KIND_PWL: u8 = 2;

/// Physical limits a calibration must respect to be flashed. Anything outside is a unit, a
/// fit or a file gone wrong, not a calibration.
pub mod limits {
    /// Smallest |K_ii| [V/g].
    pub const SCALE_FACTOR_MIN_V_PER_G: f64 = 1e-3;
    /// Largest |K_ii| [V/g].
    pub const SCALE_FACTOR_MAX_V_PER_G: f64 = 1e3;
    /// Largest |K_ij| (i ≠ j) as a fraction of |K_ii| of the same row.
    pub const CROSS_RATIO_MAX: f64 = 0.5;
    /// Largest |U0_i| \[V\].
    pub const U0_MAX_V: f64 = 100.0;
    /// Lowest T0, range end or knot [°C].
    pub const TEMP_MIN_C: f64 = -100.0;
    /// Highest T0, range end or knot [°C].
    pub const TEMP_MAX_C: f64 = 200.0;
    /// Largest change of U0 one temperature term may make \[V\] (see [`super::Field::limit`]).
    pub const DU0_MAX_V: f64 = 100.0;
    /// Largest relative change of a scale factor one temperature term may make \[1\].
    pub const REL_SCALE_MAX: f64 = 1.0;
    /// Largest |a0| of a conversion function \[g\].
    pub const A0_MAX_G: f64 = 1.0;
    /// Largest |δ_1A| (scale-factor asymmetry) \[1\].
    pub const DELTA_1A_MAX: f64 = 0.1;
    /// Largest |m1|, |m2| (additive cross-sensitivity) [g/g].
    pub const M_LINEAR_MAX: f64 = 0.5;
    /// The nonlinear terms k2…k5, m31, m32 may contribute at most this much each \[g\] at the
    /// full scale [`crate::vibration::MAX_STATIC_G`] (10 g): |k_n|·10ⁿ ≤ 1 g, |m3j|·10² ≤ 1 g.
    pub const NONLINEAR_TERM_MAX_G: f64 = 1.0;
    /// Highest profile frequency or band edge \[Hz\].
    pub const FREQ_MAX_HZ: f64 = 1e5;
    /// Earliest calibration year.
    pub const YEAR_MIN: u16 = 1970;
    /// Latest calibration year.
    pub const YEAR_MAX: u16 = 9999;
}

/// A value of the calibration, named as the calibration file (TOML) spells it. Indices are
/// zero-based; `row`/`col`/`axis` 0, 1, 2 are x, y, z.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Field {
    /// `t0_C`
    T0,
    /// `k_V_per_g[row][col]`
    K {
        /// Accelerometer (row of K).
        row: u8,
        /// Axis (column of K).
        col: u8,
    },
    /// `u0_V[axis]`
    U0 {
        /// Accelerometer.
        axis: u8,
    },
    /// `temp_range_C[end]` (0 = min, 1 = max)
    TempRange {
        /// 0 = min, 1 = max.
        end: u8,
    },
    /// `temperature_model.kind`
    ModelKind,
    /// The number of `temperature_model.term` entries (the polynomial order).
    PolyOrder,
    /// The number of `temperature_model.knot` entries.
    KnotCount,
    /// `temperature_model.knot[knot].t_C`
    Knot {
        /// Knot index.
        knot: u8,
    },
    /// `temperature_model.knot[knot].du0_V[axis]`
    KnotDu0 {
        /// Knot index.
        knot: u8,
        /// Accelerometer.
        axis: u8,
    },
    /// `temperature_model.knot[knot].rel_k[row][col]`
    KnotRelK {
        /// Knot index.
        knot: u8,
        /// Row of K.
        row: u8,
        /// Column of K.
        col: u8,
    },
    /// `temperature_model.term[term].alpha_V_per_Cn[axis]` (coefficient of ΔT^(term+1))
    TermAlpha {
        /// Term index (power − 1).
        term: u8,
        /// Accelerometer.
        axis: u8,
    },
    /// `temperature_model.term[term].rel_k_per_Cn[row][col]` (coefficient of ΔT^(term+1))
    TermRelK {
        /// Term index (power − 1).
        term: u8,
        /// Row of K.
        row: u8,
        /// Column of K.
        col: u8,
    },
    /// `method.kind`
    Method,
    /// `method.form`
    Form,
    /// `serial`
    Serial,
    /// `calibration_date`
    CalDate,
    /// `tool_version`
    ToolVersion,
    /// `vibration.variant`
    VibVariant,
    /// `vibration.<x|y|z>.<key>`: coefficient `coef` (index in
    /// [`ConversionFunction::to_array`], key [`CONVERSION_FUNCTION_KEYS`]) of an accelerometer.
    VibCoef {
        /// Accelerometer.
        axis: u8,
        /// Coefficient index.
        coef: u8,
    },
    /// The number of `vibration.profile` entries.
    ProfileCount,
    /// `vibration.profile[profile].kind`
    ProfileKind {
        /// Profile index.
        profile: u8,
    },
    /// `vibration.profile[profile].amp_g[axis]` (sine)
    ProfileAmp {
        /// Profile index.
        profile: u8,
        /// Axis.
        axis: u8,
    },
    /// `vibration.profile[profile].freq_Hz` (sine)
    ProfileFreq {
        /// Profile index.
        profile: u8,
    },
    /// `vibration.profile[profile].sigma_g[axis]` (random)
    ProfileSigma {
        /// Profile index.
        profile: u8,
        /// Axis.
        axis: u8,
    },
    /// `vibration.profile[profile].band_Hz[end]` (random; 0 = low, 1 = high)
    ProfileBand {
        /// Profile index.
        profile: u8,
        /// 0 = low edge, 1 = high edge.
        end: u8,
    },
    /// The layout version of the thermal-dynamics section (no key in the calibration file:
    /// the tool writes the version it knows).
    DynamicsLayout,
    /// `thermal_dynamics.<key>`: parameter `param` in the section's order
    /// ([`DYNAMICS_KEYS`]; 5, 6, 7 are `bias_play_mg[0..3]`).
    Dynamics {
        /// Parameter index.
        param: u8,
    },
}

/// The calibration file's keys of the thermal-dynamics parameters, in the section's order
/// (the last three are the x, y, z elements of `bias_play_mg`).
pub const DYNAMICS_KEYS: [&str; 8] = [
    "lag_tau_s",
    "hysteresis_width_C",
    "self_heating_C",
    "self_heating_tau_s",
    "bias_play_width_C",
    "bias_play_mg",
    "bias_play_mg",
    "bias_play_mg",
];

const fn dynamics_key(param: u8) -> &'static str {
    match param {
        0 => "thermal_dynamics.lag_tau_s",
        1 => "thermal_dynamics.hysteresis_width_C",
        2 => "thermal_dynamics.self_heating_C",
        3 => "thermal_dynamics.self_heating_tau_s",
        4 => "thermal_dynamics.bias_play_width_C",
        _ => "thermal_dynamics.bias_play_mg",
    }
}

/// The calibration file's keys of the ten conversion-function coefficients, in the order of
/// [`ConversionFunction::to_array`] (the order of the vibration section).
pub const CONVERSION_FUNCTION_KEYS: [&str; 10] = [
    "a0_g",
    "delta_1a",
    "k2_g_per_g2",
    "k3_g_per_g3",
    "k4_g_per_g4",
    "k5_g_per_g5",
    "m1_g_per_g",
    "m2_g_per_g",
    "m31_g_per_g2",
    "m32_g_per_g2",
];

/// Largest magnitude of conversion-function coefficient `coef` ([`limits`]): the nonlinear
/// ones so that their term stays within [`limits::NONLINEAR_TERM_MAX_G`] at 10 g.
pub const fn coefficient_limit(coef: u8) -> f64 {
    let t = limits::NONLINEAR_TERM_MAX_G;
    match coef {
        0 => limits::A0_MAX_G,
        1 => limits::DELTA_1A_MAX,
        2 => t * 1e-2,
        3 => t * 1e-3,
        4 => t * 1e-4,
        5 => t * 1e-5,
        6 | 7 => limits::M_LINEAR_MAX,
        _ => t * 1e-2,
    }
}

const fn coef_key(coef: u8) -> &'static str {
    match coef {
        0 => "a0_g",
        1 => "delta_1a",
        2 => "k2_g_per_g2",
        3 => "k3_g_per_g3",
        4 => "k4_g_per_g4",
        5 => "k5_g_per_g5",
        6 => "m1_g_per_g",
        7 => "m2_g_per_g",
        8 => "m31_g_per_g2",
        _ => "m32_g_per_g2",
    }
}

const fn axis_name(axis: u8) -> &'static str {
    match axis {
        0 => "x",
        1 => "y",
        _ => "z",
    }
}

impl Field {
    /// The key in the calibration file, without indices (e.g. `"k_V_per_g"`).
    pub const fn name(&self) -> &'static str {
        match self {
            Field::T0 => "t0_C",
            Field::K { .. } => "k_V_per_g",
            Field::U0 { .. } => "u0_V",
            Field::TempRange { .. } => "temp_range_C",
            Field::ModelKind => "temperature_model.kind",
            Field::PolyOrder => "temperature_model.term",
            Field::KnotCount => "temperature_model.knot",
            Field::Knot { .. } => "temperature_model.knot.t_C",
            Field::KnotDu0 { .. } => "temperature_model.knot.du0_V",
            Field::KnotRelK { .. } => "temperature_model.knot.rel_k",
            Field::TermAlpha { .. } => "temperature_model.term.alpha_V_per_Cn",
            Field::TermRelK { .. } => "temperature_model.term.rel_k_per_Cn",
            Field::Method => "method.kind",
            Field::Form => "method.form",
            Field::Serial => "serial",
            Field::CalDate => "calibration_date",
            Field::ToolVersion => "tool_version",
            Field::VibVariant => "vibration.variant",
            Field::VibCoef { coef, .. } => coef_key(*coef),
            Field::ProfileCount => "vibration.profile",
            Field::ProfileKind { .. } => "vibration.profile.kind",
            Field::ProfileAmp { .. } => "vibration.profile.amp_g",
            Field::ProfileFreq { .. } => "vibration.profile.freq_Hz",
            Field::ProfileSigma { .. } => "vibration.profile.sigma_g",
            Field::ProfileBand { .. } => "vibration.profile.band_Hz",
            Field::DynamicsLayout => "thermal_dynamics",
            Field::Dynamics { param } => dynamics_key(*param),
        }
    }

    /// What the field must satisfy, in words (see [`limits`]).
    pub const fn limit(&self) -> &'static str {
        match self {
            Field::T0 | Field::TempRange { .. } | Field::Knot { .. } => "finite, within [-100, 200] °C",
            Field::K { row, col } if *row == *col => "finite, |K_ii| within [1e-3, 1e3] V/g",
            Field::K { .. } => "finite, |K_ij| <= 0.5·|K_ii| of the same row",
            Field::U0 { .. } => "finite, |U0| <= 100 V",
            Field::ModelKind => "poly or pwl",
            Field::PolyOrder => "1 to 4 terms",
            Field::KnotCount => "2 to 8 knots",
            Field::KnotDu0 { .. } => "finite, |ΔU0| <= 100 V at the knot",
            Field::KnotRelK { row, col, .. } if *row == *col => "finite, |ΔK_ii/K_ii| <= 1 at the knot",
            Field::KnotRelK { .. } => "finite, |K_ij·ΔK_ij/K_ij| <= 0.5·|K_ii| at the knot",
            Field::TermAlpha { .. } => "finite, |α_n|·ΔT_max^n <= 100 V over the valid range",
            Field::TermRelK { row, col, .. } if *row == *col => "finite, |β_n|·ΔT_max^n <= 1 over the valid range",
            Field::TermRelK { .. } => "finite, |K_ij·γ_n|·ΔT_max^n <= 0.5·|K_ii| over the valid range",
            Field::Method => "uncorrected, coefficient-correction or output-correction",
            Field::Form => "full, simplified or linearized for output-correction; none otherwise",
            Field::Serial | Field::ToolVersion => "1 to 32 printable ASCII characters",
            Field::CalDate => "a calendar date, year 1970 to 9999",
            Field::VibVariant => "paper or exact",
            Field::VibCoef { coef: 0, .. } => "finite, |a0| <= 1 g",
            Field::VibCoef { coef: 1, .. } => "finite, |δ_1A| <= 0.1",
            Field::VibCoef { coef: 2..=5, .. } => "finite, |k_n|·10^n <= 1 g (each term within 1 g at 10 g)",
            Field::VibCoef { coef: 6 | 7, .. } => "finite, |m1|, |m2| <= 0.5 g/g",
            Field::VibCoef { .. } => "finite, |m31|, |m32|·10² <= 1 g (within 1 g at 10 g)",
            Field::ProfileCount => "1 to 8 profiles",
            Field::ProfileKind { .. } => "none, sine or random",
            Field::ProfileAmp { .. } => "finite, |amplitude| <= 10 g",
            Field::ProfileFreq { .. } => "finite, within [0, 1e5] Hz",
            Field::ProfileSigma { .. } => "finite, σ within [0, 10] g",
            Field::ProfileBand { .. } => "finite, 0 <= low < high <= 1e5 Hz",
            Field::DynamicsLayout => "layout version 1",
            Field::Dynamics { param: 0 | 3 } => "finite, within [0, 1e5] s",
            Field::Dynamics { param: 1 | 4 } => "finite, within [0, 50] °C",
            Field::Dynamics { param: 2 } => "finite, within [-50, 50] °C",
            Field::Dynamics { .. } => "finite, within [-100, 100] mg, and 0 when bias_play_width_C is 0",
        }
    }
}

impl core::fmt::Display for Field {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Field::K { row, col } => write!(f, "k_V_per_g[{row}][{col}]"),
            Field::U0 { axis } => write!(f, "u0_V[{axis}]"),
            Field::TempRange { end } => write!(f, "temp_range_C[{end}]"),
            Field::Knot { knot } => write!(f, "temperature_model.knot[{knot}].t_C"),
            Field::KnotDu0 { knot, axis } => write!(f, "temperature_model.knot[{knot}].du0_V[{axis}]"),
            Field::KnotRelK { knot, row, col } => write!(f, "temperature_model.knot[{knot}].rel_k[{row}][{col}]"),
            Field::TermAlpha { term, axis } => write!(f, "temperature_model.term[{term}].alpha_V_per_Cn[{axis}]"),
            Field::TermRelK { term, row, col } => {
                write!(f, "temperature_model.term[{term}].rel_k_per_Cn[{row}][{col}]")
            }
            Field::VibCoef { axis, coef } => write!(f, "vibration.{}.{}", axis_name(axis), coef_key(coef)),
            Field::ProfileKind { profile } => write!(f, "vibration.profile[{profile}].kind"),
            Field::ProfileAmp { profile, axis } => write!(f, "vibration.profile[{profile}].amp_g[{axis}]"),
            Field::ProfileFreq { profile } => write!(f, "vibration.profile[{profile}].freq_Hz"),
            Field::ProfileSigma { profile, axis } => write!(f, "vibration.profile[{profile}].sigma_g[{axis}]"),
            Field::ProfileBand { profile, end } => write!(f, "vibration.profile[{profile}].band_Hz[{end}]"),
            Field::Dynamics { param: param @ 5.. } => write!(f, "thermal_dynamics.bias_play_mg[{}]", param - 5),
            other => f.write_str(other.name()),
        }
    }
}

/// Why a blob was rejected (or could not be written). Offsets are byte offsets from the start
/// of the blob.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum BlobError {
    /// Fewer bytes than the header, or than the header's declared length.
    Truncated {
        /// Bytes needed.
        needed: usize,
        /// Bytes present.
        got: usize,
    },
    /// The first four bytes are not [`MAGIC`] (erased or foreign flash).
    BadMagic,
    /// A format version this parser does not read.
    UnsupportedVersion(u16),
    /// The declared total length is outside [`MIN_BLOB_BYTES`]..=[`MAX_BLOB_BYTES`].
    BadLength(u32),
    /// More bytes than the declared length.
    LengthMismatch {
        /// Declared length.
        declared: usize,
        /// Bytes present.
        actual: usize,
    },
    /// The CRC does not match the contents.
    CrcMismatch {
        /// CRC stored in the blob.
        stored: u32,
        /// CRC of the contents.
        computed: u32,
    },
    /// A reserved byte or flag bit is not zero.
    ReservedNotZero {
        /// Offset of the byte (or of the flags word).
        offset: usize,
    },
    /// The section count exceeds [`MAX_SECTIONS`] or the table does not fit.
    BadSectionCount(u16),
    /// A section's payload lies outside the payload area.
    SectionOutOfBounds {
        /// Section id.
        id: u16,
        /// Offset of its table entry.
        offset: usize,
    },
    /// Two sections' payloads overlap.
    OverlappingSections {
        /// Id of the earlier table entry.
        first: u16,
        /// Id of the later table entry.
        second: u16,
    },
    /// A section id appears twice.
    DuplicateSection {
        /// Section id.
        id: u16,
        /// Offset of the second table entry.
        offset: usize,
    },
    /// A section this parser does not know is flagged [`FLAG_REQUIRED`].
    UnknownRequiredSection {
        /// Section id.
        id: u16,
        /// Offset of its table entry.
        offset: usize,
    },
    /// A section the format version requires is absent.
    MissingSection(u16),
    /// A section's length does not fit its contents.
    SectionLength {
        /// Section id.
        id: u16,
        /// Offset of the section's payload.
        offset: usize,
        /// Its length.
        len: usize,
    },
    /// A value is not finite or outside its physical range (see [`Field::limit`]).
    OutOfRange {
        /// The value.
        field: Field,
        /// Offset of its first byte.
        offset: usize,
    },
    /// An enumeration code (model kind, method, form) is unknown or does not fit.
    BadCode {
        /// The field.
        field: Field,
        /// Offset of the code byte.
        offset: usize,
        /// The code.
        code: u8,
    },
    /// Polynomial order outside 1..=4.
    UnsupportedOrder {
        /// The order.
        order: u8,
        /// Offset of the order byte.
        offset: usize,
    },
    /// Knot count outside 2..=8.
    KnotCount {
        /// The count.
        count: u8,
        /// Offset of the count byte.
        offset: usize,
    },
    /// A knot temperature is not above the previous one.
    KnotsNotIncreasing {
        /// Index of the offending knot.
        knot: u8,
        /// Offset of its temperature.
        offset: usize,
    },
    /// The temperature range is empty or does not contain T0.
    BadRange {
        /// Offset of the range section's payload.
        offset: usize,
    },
    /// K at T0 is singular or ill-conditioned.
    SingularK,
    /// K(T) becomes singular, or a scale factor leaves [1/2, 2]× its T0 value, inside the
    /// valid temperature range.
    SingularInRange,
    /// Any other rejection by [`Calibration::new`].
    Calibration(CalibrationError),
    /// Flight-phase profile count outside 1..=[`MAX_PROFILES`].
    ProfileCount {
        /// The count.
        count: u8,
        /// Offset of the count byte.
        offset: usize,
    },
    /// A rejection by [`ThermalDynamics::validate`] (not reached for a blob whose values
    /// passed the checks above; kept so that nothing unchecked is ever used).
    Dynamics(DynamicsError),
    /// The encoder's output buffer is too small.
    BufferTooSmall {
        /// Bytes needed.
        needed: usize,
    },
}

impl From<CalibrationError> for BlobError {
    fn from(e: CalibrationError) -> Self {
        match e {
            CalibrationError::SingularK => BlobError::SingularK,
            CalibrationError::SingularInRange => BlobError::SingularInRange,
            other => BlobError::Calibration(other),
        }
    }
}

impl core::fmt::Display for BlobError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            BlobError::Truncated { needed, got } => write!(f, "truncated: {got} bytes, {needed} needed"),
            BlobError::BadMagic => write!(f, "bad magic at byte 0x0000: not a calibration blob"),
            BlobError::UnsupportedVersion(v) => {
                write!(f, "unsupported format version {v} at byte 0x0004 (this parser reads {FORMAT_VERSION})")
            }
            BlobError::BadLength(n) => {
                write!(f, "declared length {n} at byte 0x0008 outside [{MIN_BLOB_BYTES}, {MAX_BLOB_BYTES}]")
            }
            BlobError::LengthMismatch { declared, actual } => {
                write!(f, "length mismatch: header at byte 0x0008 declares {declared} bytes, {actual} present")
            }
            BlobError::CrcMismatch { stored, computed } => {
                write!(f, "CRC mismatch: stored 0x{stored:08x}, computed 0x{computed:08x}")
            }
            BlobError::ReservedNotZero { offset } => write!(f, "reserved bits not zero at byte 0x{offset:04x}"),
            BlobError::BadSectionCount(n) => {
                write!(f, "section count {n} at byte 0x0006 too large (at most {MAX_SECTIONS}, table inside the blob)")
            }
            BlobError::SectionOutOfBounds { id, offset } => {
                write!(f, "section 0x{id:04x} (entry at byte 0x{offset:04x}) lies outside the payload area")
            }
            BlobError::OverlappingSections { first, second } => {
                write!(f, "sections 0x{first:04x} and 0x{second:04x} overlap")
            }
            BlobError::DuplicateSection { id, offset } => {
                write!(f, "duplicate section 0x{id:04x} (entry at byte 0x{offset:04x})")
            }
            BlobError::UnknownRequiredSection { id, offset } => {
                write!(f, "unknown required section 0x{id:04x} (entry at byte 0x{offset:04x})")
            }
            BlobError::MissingSection(id) => write!(f, "missing required section 0x{id:04x}"),
            BlobError::SectionLength { id, offset, len } => {
                write!(f, "section 0x{id:04x} at byte 0x{offset:04x}: length {len} does not fit its contents")
            }
            BlobError::OutOfRange { field, offset } => {
                write!(f, "{field} at byte 0x{offset:04x} out of range (must be {})", field.limit())
            }
            BlobError::BadCode { field, offset, code } => {
                write!(f, "{field} at byte 0x{offset:04x}: code {code} invalid (must be {})", field.limit())
            }
            BlobError::UnsupportedOrder { order, offset } => write!(
                f,
                "temperature_model.term at byte 0x{offset:04x}: polynomial order {order} unsupported (1 to {MAX_POLY_ORDER})"
            ),
            BlobError::KnotCount { count, offset } => {
                write!(f, "temperature_model.knot at byte 0x{offset:04x}: {count} knots unsupported (2 to {MAX_KNOTS})")
            }
            BlobError::KnotsNotIncreasing { knot, offset } => {
                write!(f, "temperature_model.knot[{knot}].t_C at byte 0x{offset:04x}: knots not strictly increasing")
            }
            BlobError::BadRange { offset } => {
                write!(f, "temp_range_C at byte 0x{offset:04x}: must satisfy min < max and contain t0_C")
            }
            BlobError::SingularK => write!(f, "k_V_per_g: K at T0 is singular or ill-conditioned"),
            BlobError::SingularInRange => write!(
                f,
                "temperature_model: K(T) becomes singular, or a scale factor leaves [1/2, 2]x its T0 value, inside temp_range_C"
            ),
            BlobError::Calibration(e) => write!(f, "calibration rejected: {e}"),
            BlobError::ProfileCount { count, offset } => {
                write!(
                    f,
                    "vibration.profile at byte 0x{offset:04x}: {count} profiles unsupported (1 to {MAX_PROFILES})"
                )
            }
            BlobError::Dynamics(e) => write!(f, "thermal_dynamics.{e}"),
            BlobError::BufferTooSmall { needed } => write!(f, "output buffer too small: {needed} bytes needed"),
        }
    }
}

impl core::error::Error for BlobError {}

// ---- CRC-32 -------------------------------------------------------------------------------

/// CRC-32 as in IEEE 802.3, zlib and PNG: reflected, polynomial 0xEDB88320, initial value and
/// final XOR 0xFFFFFFFF. `crc32(b"123456789") == 0xCBF43926`.
///
/// Bit by bit, without a table: it runs once per blob at boot (at most [`MAX_BLOB_BYTES`]:
/// about 130 000 instructions, under 1 ms on a Cortex-M4), so the 1 KiB of flash a table
/// would take is not worth it.
///
/// ```
/// use bins_comp::blob::crc32;
///
/// assert_eq!(crc32(b"123456789"), 0xCBF4_3926); // the standard check value
/// assert_eq!(crc32(b""), 0);
/// assert_ne!(crc32(b"123456788"), crc32(b"123456789"));
/// ```
#[cfg_attr(unstable_target, optimize(size))]
pub fn crc32(bytes: &[u8]) -> u32 {
    let mut c = !0u32;
    for &b in bytes {
        c ^= u32::from(b);
        for _ in 0..8 {
            // All ones when the low bit is set, else zero: the polynomial is XORed in without
            // a branch.
            let mask = (c & 1).wrapping_neg();
            c = (c >> 1) ^ (0xEDB8_8320 & mask);
        }
    }
    !c
}

// ---- little-endian readers ----------------------------------------------------------------

fn u16_at(b: &[u8], off: usize) -> Option<u16> {
    b.get(off..off.checked_add(2)?)?.try_into().ok().map(u16::from_le_bytes)
}

fn u32_at(b: &[u8], off: usize) -> Option<u32> {
    b.get(off..off.checked_add(4)?)?.try_into().ok().map(u32::from_le_bytes)
}

fn f64_at(b: &[u8], off: usize) -> Option<f64> {
    b.get(off..off.checked_add(8)?)?.try_into().ok().map(f64::from_le_bytes)
}

// ---- container ------------------------------------------------------------------------------

/// One entry of the section table.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SectionEntry {
    /// Section id (see [`section`]).
    pub id: u16,
    /// Flags ([`FLAG_REQUIRED`]).
    pub flags: u16,
    /// Offset of the payload from the start of the blob.
    pub offset: u32,
    /// Length of the payload.
    pub len: u32,
}

impl SectionEntry {
    fn start(&self) -> usize {
        self.offset as usize
    }
    fn end(&self) -> usize {
        self.offset as usize + self.len as usize
    }
}

/// A blob whose header, CRC and section table are valid: a view over its bytes, giving each
/// section's payload. What the sections say is checked by [`parse`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Blob<'a> {
    bytes: &'a [u8],
    entries: [SectionEntry; MAX_SECTIONS],
    count: usize,
}

impl<'a> Blob<'a> {
    /// Checks the container: length, magic, version, declared length, CRC, reserved header
    /// word and section table (bounds, overlaps, duplicates, unknown required sections).
    /// `bytes` must be exactly the blob (see [`parse_region`] for a flash region).
    #[inline(never)]
    #[cfg_attr(unstable_target, optimize(size))]
    pub fn new(bytes: &'a [u8]) -> Result<Self, BlobError> {
        let got = bytes.len();
        if got < HEADER_BYTES {
            return Err(BlobError::Truncated { needed: HEADER_BYTES, got });
        }
        if bytes.get(0..4) != Some(&MAGIC[..]) {
            return Err(BlobError::BadMagic);
        }
        let version = u16_at(bytes, 4).unwrap_or(0);
        if version != FORMAT_VERSION {
            return Err(BlobError::UnsupportedVersion(version));
        }
        let declared32 = u32_at(bytes, 8).unwrap_or(0);
        let declared = declared32 as usize;
        if !(MIN_BLOB_BYTES..=MAX_BLOB_BYTES).contains(&declared) {
            return Err(BlobError::BadLength(declared32));
        }
        if got < declared {
            return Err(BlobError::Truncated { needed: declared, got });
        }
        if got > declared {
            return Err(BlobError::LengthMismatch { declared, actual: got });
        }
        let body_end = declared - CRC_BYTES;
        let stored = u32_at(bytes, body_end).unwrap_or(0);
        let computed = crc32(bytes.get(..body_end).unwrap_or(&[]));
        if stored != computed {
            return Err(BlobError::CrcMismatch { stored, computed });
        }
        if u32_at(bytes, 12) != Some(0) {
            return Err(BlobError::ReservedNotZero { offset: 12 });
        }
        let count16 = u16_at(bytes, 6).unwrap_or(u16::MAX);
        let count = count16 as usize;
        let table_end = HEADER_BYTES + ENTRY_BYTES * count;
        if count > MAX_SECTIONS || table_end > body_end {
            return Err(BlobError::BadSectionCount(count16));
        }
        let mut entries = [SectionEntry::default(); MAX_SECTIONS];
        for k in 0..count {
            let at = HEADER_BYTES + ENTRY_BYTES * k;
            let e = SectionEntry {
                id: u16_at(bytes, at).unwrap_or(0),
                flags: u16_at(bytes, at + 2).unwrap_or(0),
                offset: u32_at(bytes, at + 4).unwrap_or(u32::MAX),
                len: u32_at(bytes, at + 8).unwrap_or(u32::MAX),
            };
            if e.flags & !FLAG_REQUIRED != 0 {
                return Err(BlobError::ReservedNotZero { offset: at + 2 });
            }
            // Offsets and lengths are u32 and usize is at least 32 bits on every supported
            // target, but the sum is computed checked anyway.
            let end = (e.offset as usize).checked_add(e.len as usize);
            if (e.offset as usize) < table_end || end.is_none_or(|end| end > body_end) {
                return Err(BlobError::SectionOutOfBounds { id: e.id, offset: at });
            }
            for prev in entries.iter().take(k) {
                if prev.id == e.id {
                    return Err(BlobError::DuplicateSection { id: e.id, offset: at });
                }
                if e.len > 0 && prev.len > 0 && e.start() < prev.end() && prev.start() < e.end() {
                    return Err(BlobError::OverlappingSections { first: prev.id, second: e.id });
                }
            }
            if e.flags & FLAG_REQUIRED != 0 && !section::KNOWN.contains(&e.id) {
                return Err(BlobError::UnknownRequiredSection { id: e.id, offset: at });
            }
            if let Some(slot) = entries.get_mut(k) {
                *slot = e;
            }
        }
        Ok(Blob { bytes, entries, count })
    }

    /// The whole blob.
    pub fn bytes(&self) -> &'a [u8] {
        self.bytes
    }

    /// The section table, in table order.
    pub fn sections(&self) -> &[SectionEntry] {
        self.entries.get(..self.count).unwrap_or(&[])
    }

    /// The entry of section `id`, if present.
    pub fn entry(&self, id: u16) -> Option<SectionEntry> {
        self.sections().iter().find(|e| e.id == id).copied()
    }

    /// The payload of section `id`, if present.
    pub fn section(&self, id: u16) -> Option<&'a [u8]> {
        let e = self.entry(id)?;
        self.bytes.get(e.start()..e.end())
    }
}

// ---- contents -------------------------------------------------------------------------------

/// A calibration date.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CalDate {
    /// Year (1970..=9999).
    pub year: u16,
    /// Month (1..=12).
    pub month: u8,
    /// Day of the month.
    pub day: u8,
}

impl CalDate {
    /// True for a real calendar date within the format's years.
    pub fn is_valid(&self) -> bool {
        let y = self.year;
        let leap = (y.is_multiple_of(4) && !y.is_multiple_of(100)) || y.is_multiple_of(400);
        let days = match self.month {
            1 | 3 | 5 | 7 | 8 | 10 | 12 => 31,
            4 | 6 | 9 | 11 => 30,
            2 if leap => 29,
            2 => 28,
            _ => return false,
        };
        (limits::YEAR_MIN..=limits::YEAR_MAX).contains(&self.year) && (1..=days).contains(&self.day)
    }
}

/// The traceability data of a blob. Empty text and `None` mean "absent" (the sections are
/// optional).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Meta<'a> {
    /// The unit's serial number.
    pub serial: &'a str,
    /// When the unit was calibrated.
    pub date: Option<CalDate>,
    /// The tool (and its version) that produced the calibration.
    pub tool_version: &'a str,
}

/// A fully checked blob: the calibration parameters, the vibration-error configuration, the
/// traceability data and the container (for sections added by later versions).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParsedCalibration<'a> {
    /// What [`Calibration::new`] needs; it has accepted these.
    pub params: CalibrationParams,
    /// The vibration-error coefficients and flight-phase profiles (sections
    /// [`section::VIBRATION`] and [`section::FLIGHT_PHASES`]); `None` when the blob has no
    /// vibration section. They pass [`VibrationParams::validate`].
    pub vibration: Option<VibrationParams>,
    /// The thermal dynamics (section [`section::THERMAL_DYNAMICS`]); `None` when the blob has
    /// no such section (no dynamics). They pass [`ThermalDynamics::validate`].
    pub dynamics: Option<ThermalDynamics<f64>>,
    /// Serial, date, tool version.
    pub meta: Meta<'a>,
    /// The container.
    pub blob: Blob<'a>,
}

impl ParsedCalibration<'_> {
    /// The calibration in the working precision. [`parse`] has already run the same checks in
    /// `f64` (they do not depend on `F`), so this does not fail for a parsed blob.
    pub fn calibration<F: Float>(&self) -> Result<Calibration<F>, BlobError> {
        Calibration::new(&self.params).map_err(BlobError::from)
    }

    /// The vibration-error configuration in the working precision:
    /// [`VibrationConfig::none`] (no VE model, nothing subtracted) for a blob without a
    /// vibration section. [`parse`] has checked every value against limits that imply
    /// [`VibrationParams::validate`]'s, so they are not validated again
    /// ([`VibrationConfig::from_validated`]) and this does not fail.
    pub fn vibration_config<F: Float>(&self) -> Result<VibrationConfig<F>, BlobError> {
        Ok(self.vibration.as_ref().map_or_else(VibrationConfig::none, VibrationConfig::from_validated))
    }

    /// Both configurations of the per-sample step ([`crate::Pipeline::new`]): the calibration
    /// and the vibration-error configuration, in the working precision.
    pub fn configs<F: Float>(&self) -> Result<(Calibration<F>, VibrationConfig<F>), BlobError> {
        Ok((self.calibration()?, self.vibration_config()?))
    }

    /// The thermal dynamics at the sampling period `dt_s` \[s\] in the working precision
    /// ([`ThermalDynamics::at_rate`]), for [`crate::Pipeline::with_dynamics`]; `None` for a blob
    /// without the section. Fails only for a period that is not finite and positive.
    pub fn dynamics_at_rate<F: Float>(&self, dt_s: F) -> Result<Option<FixedRate<F>>, BlobError> {
        match &self.dynamics {
            None => Ok(None),
            // `parse` has validated the f64 parameters; rounding to F keeps each within its
            // (rounded) limits, so they are not validated again.
            Some(d) => d.cast::<F>().at_rate_validated(dt_s).map(Some).map_err(BlobError::Dynamics),
        }
    }
}

/// Parses the blob at the start of a flash region ([`parse_region`]) and returns the
/// calibration and vibration-error configuration the per-sample step needs (`Pipeline::new(cal,
/// vib)`): what the firmware calls once at boot. A blob without a vibration section gives
/// [`VibrationConfig::none`].
pub fn load_region<F: Float>(region: &[u8]) -> Result<(Calibration<F>, VibrationConfig<F>), BlobError> {
    parse_region(region)?.configs()
}

/// A rejected blob, inside the parser: the error itself is kept in the parse's error cell
/// ([`reject`]), so that each `?` between the parser's steps passes this mark (nothing)
/// instead of copying the error, in every one of its checks.
#[derive(Clone, Copy, Debug)]
struct Rejected;

/// A step of the parser: its result, or [`Rejected`] with the error in the cell.
type Checked<T> = Result<T, Rejected>;

/// Keeps `e` as the parse's error. One out-of-line copy for every rejection.
#[cold]
#[inline(never)]
#[cfg_attr(unstable_target, optimize(size))]
fn reject(err: &Cell<BlobError>, e: BlobError) -> Rejected {
    err.set(e);
    Rejected
}

/// A section's payload, where it starts in the blob, and the parse's error cell.
#[derive(Clone, Copy)]
struct Payload<'a, 'e> {
    id: u16,
    bytes: &'a [u8],
    base: usize,
    err: &'e Cell<BlobError>,
}

impl<'a, 'e> Payload<'a, 'e> {
    /// One out-of-line copy for every lookup (and [`require`](Self::require)'s).
    #[inline(never)]
    #[cfg_attr(unstable_target, optimize(size))]
    fn get(blob: &Blob<'a>, id: u16, err: &'e Cell<BlobError>) -> Option<Self> {
        let e = blob.entry(id)?;
        Some(Payload { id, bytes: blob.bytes.get(e.start()..e.end())?, base: e.start(), err })
    }

    #[inline(never)]
    #[cfg_attr(unstable_target, optimize(size))]
    fn require(blob: &Blob<'a>, id: u16, err: &'e Cell<BlobError>) -> Checked<Self> {
        Payload::get(blob, id, err).ok_or_else(|| reject(err, BlobError::MissingSection(id)))
    }

    /// Rejects the blob with `e`.
    fn fail(&self, e: BlobError) -> Rejected {
        reject(self.err, e)
    }

    fn expect_len(&self, len: usize) -> Checked<()> {
        if self.bytes.len() == len { Ok(()) } else { Err(self.fail(self.length_error())) }
    }

    fn length_error(&self) -> BlobError {
        BlobError::SectionLength { id: self.id, offset: self.base, len: self.bytes.len() }
    }

    fn byte(&self, at: usize) -> u8 {
        self.bytes.get(at).copied().unwrap_or(0)
    }

    /// The f64 at `at` if `ok` accepts it, else [`BlobError::OutOfRange`] naming `field`.
    fn value(&self, at: usize, field: Field, ok: impl Fn(f64) -> bool) -> Checked<f64> {
        match f64_at(self.bytes, at) {
            Some(x) if x.is_finite() && ok(x) => Ok(x),
            _ => Err(self.fail(BlobError::OutOfRange { field, offset: self.base + at })),
        }
    }

    /// The f64 at `at` into `out` if within `[lo, hi]`, else [`BlobError::OutOfRange`] naming
    /// `field`. One out-of-line copy for every plain range check; the value is stored by it,
    /// so that a check costs its caller a call and a test.
    #[inline(never)]
    #[cfg_attr(unstable_target, optimize(size))]
    fn value_in(&self, out: &mut f64, at: usize, field: Field, lo: f64, hi: f64) -> Checked<()> {
        *out = self.value(at, field, |x| le(lo, x) && le(x, hi))?;
        Ok(())
    }

    /// The f64 x at `at` into `out` if `|a·x|·scale ≤ max`, else [`BlobError::OutOfRange`]
    /// naming `field` (the temperature model's plausibility checks, one out-of-line copy). Evaluated
    /// in `f32`, the precision the firmware computes in (it has no `f64` arithmetic), on host
    /// and target alike: a value within about 10⁻⁶ of its limit, relative, may fall on either
    /// side of it.
    #[inline(never)]
    #[cfg_attr(unstable_target, optimize(size))]
    fn value_scaled(&self, out: &mut f64, at: usize, field: Field, a: f64, scale: f32, max: f32) -> Checked<()> {
        let a = a as f32;
        *out = self.value(at, field, |x| !((a * x as f32).abs() * scale > max))?;
        Ok(())
    }

    #[cfg_attr(unstable_target, optimize(size))]
    fn reserved_zero(&self, range: core::ops::Range<usize>) -> Checked<()> {
        for at in range {
            if self.byte(at) != 0 {
                return Err(self.fail(BlobError::ReservedNotZero { offset: self.base + at }));
            }
        }
        Ok(())
    }

    #[cfg_attr(unstable_target, optimize(size))]
    fn text(&self, field: Field) -> Checked<&'a str> {
        let b = self.bytes;
        let text = if b.is_empty() || b.len() > MAX_TEXT_BYTES || !b.iter().all(|c| (0x20..=0x7e).contains(c)) {
            None
        } else {
            ascii_str(b)
        };
        text.ok_or_else(|| self.fail(BlobError::OutOfRange { field, offset: self.base }))
    }
}

/// `b` as text, when it is ASCII. On the target the ASCII view (no UTF-8 validator and its
/// 256-byte table in flash); elsewhere UTF-8 validation, which gives the same text for ASCII.
fn ascii_str(b: &[u8]) -> Option<&str> {
    #[cfg(unstable_target)]
    return b.as_ascii().map(|a| a.as_str());
    #[cfg(not(unstable_target))]
    return core::str::from_utf8(b).ok();
}

/// `limits::CROSS_RATIO_MAX·|x|`, the largest |K_ij| beside `K_ii = x`, without `f64`
/// arithmetic (the target has none): the ratio is 1/2, so the exponent of |x| one lower,
/// exactly. `x` is a normal number (|K_ii| ≥ 10⁻³ is checked first); 0 otherwise.
fn cross_limit(x: f64) -> f64 {
    const { assert!(limits::CROSS_RATIO_MAX == 0.5) };
    let b = x.to_bits() & !(1 << 63);
    if b >> 52 > 1 && b >> 52 < 0x7ff { f64::from_bits(b - (1 << 52)) } else { 0.0 }
}

/// Which coefficient set [`read_coef_set`] reads: a polynomial term (power − 1) or a knot.
#[derive(Clone, Copy)]
enum CoefSet {
    Term(u8),
    Knot(u8),
}

impl CoefSet {
    /// The field of ΔU0 on `axis`.
    fn du0(self, axis: u8) -> Field {
        match self {
            CoefSet::Term(term) => Field::TermAlpha { term, axis },
            CoefSet::Knot(knot) => Field::KnotDu0 { knot, axis },
        }
    }

    /// The field of ΔK_ij/K_ij.
    fn rel_k(self, row: u8, col: u8) -> Field {
        match self {
            CoefSet::Term(term) => Field::TermRelK { term, row, col },
            CoefSet::Knot(knot) => Field::KnotRelK { knot, row, col },
        }
    }
}

/// A change of the constants (one knot, or one polynomial term at its largest |ΔT|, `scale`
/// = ΔT_max^n) is plausible: see [`Field::limit`]. One copy for terms and knots (`set`).
#[cfg_attr(unstable_target, optimize(size))]
fn read_coef_set(
    p: &Payload<'_, '_>,
    at: usize,
    k: &[[f64; 3]; 3],
    scale: f32,
    set: CoefSet,
) -> Checked<CoefDelta<f64>> {
    let mut a = [0.0; 12];
    for (n, slot) in a.iter_mut().enumerate() {
        let off = at + 8 * n;
        // |a·x|·scale ≤ max: a = 1 for ΔU0 and the scale changes, K_ij for a cross term.
        let (field, a, max) = if n < 3 {
            (set.du0(n as u8), 1.0, limits::DU0_MAX_V as f32)
        } else {
            let (i, j) = ((n - 3) / 3, (n - 3) % 3);
            let row = k.get(i).copied().unwrap_or_default();
            let (k_ij, k_ii) = (row.get(j).copied().unwrap_or(0.0), row.get(i).copied().unwrap_or(0.0));
            let field = set.rel_k(i as u8, j as u8);
            if i == j {
                (field, 1.0, limits::REL_SCALE_MAX as f32)
            } else {
                (field, k_ij, limits::CROSS_RATIO_MAX as f32 * (k_ii as f32).abs())
            }
        };
        p.value_scaled(slot, off, field, a, scale, max)?;
    }
    Ok(CoefDelta::from_array(&a))
}

/// Checks a blob completely and returns its calibration: the container ([`Blob::new`]), every
/// section of format version 1, each value against its physical range ([`limits`]), and
/// finally [`Calibration::new`]'s checks. `bytes` must be exactly the blob.
pub fn parse(bytes: &[u8]) -> Result<ParsedCalibration<'_>, BlobError> {
    let blob = Blob::new(bytes)?;
    // Every rejection overwrites it.
    let err = Cell::new(BlobError::BadMagic);
    parse_sections(blob, &err).map_err(|Rejected| err.get())
}

/// [`parse`] after the container: the sections and the calibration's checks.
#[inline(never)]
#[cfg_attr(unstable_target, optimize(size))]
fn parse_sections<'a>(blob: Blob<'a>, err: &Cell<BlobError>) -> Checked<ParsedCalibration<'a>> {
    for id in section::MANDATORY {
        Payload::require(&blob, id, err)?;
    }

    // Constants at T0.
    let p = Payload::require(&blob, section::CONSTANTS, err)?;
    p.expect_len(CONSTANTS_BYTES)?;
    let mut t0_c = 0.0;
    p.value_in(&mut t0_c, 0, Field::T0, limits::TEMP_MIN_C, limits::TEMP_MAX_C)?;
    let mut k = [[0.0; 3]; 3];
    for i in 0..3 {
        // |K_ii| within the scale-factor limits: at most the largest by the range check, at
        // least the smallest by the test after it (the same error either way).
        let (at, field, max) =
            (8 + 8 * (4 * i), Field::K { row: i as u8, col: i as u8 }, limits::SCALE_FACTOR_MAX_V_PER_G);
        p.value_in(&mut k[i][i], at, field, -max, max)?;
        if !le(limits::SCALE_FACTOR_MIN_V_PER_G, k[i][i].abs()) {
            return Err(p.fail(BlobError::OutOfRange { field, offset: p.base + at }));
        }
    }
    for i in 0..3 {
        for j in 0..3 {
            if i != j {
                let c = cross_limit(k[i][i]);
                p.value_in(&mut k[i][j], 8 + 8 * (3 * i + j), Field::K { row: i as u8, col: j as u8 }, -c, c)?;
            }
        }
    }
    let mut u0_v = [0.0; 3];
    for (i, u) in u0_v.iter_mut().enumerate() {
        p.value_in(u, 80 + 8 * i, Field::U0 { axis: i as u8 }, -limits::U0_MAX_V, limits::U0_MAX_V)?;
    }

    // Temperature range.
    let p = Payload::require(&blob, section::TEMP_RANGE, err)?;
    p.expect_len(TEMP_RANGE_BYTES)?;
    let mut lo = 0.0;
    p.value_in(&mut lo, 0, Field::TempRange { end: 0 }, limits::TEMP_MIN_C, limits::TEMP_MAX_C)?;
    let mut hi = 0.0;
    p.value_in(&mut hi, 8, Field::TempRange { end: 1 }, limits::TEMP_MIN_C, limits::TEMP_MAX_C)?;
    if !(lt(lo, hi) && le(lo, t0_c) && le(t0_c, hi)) {
        return Err(p.fail(BlobError::BadRange { offset: p.base }));
    }

    // Temperature model.
    let p = Payload::require(&blob, section::TEMP_MODEL, err)?;
    if p.bytes.len() < MODEL_HEADER_BYTES {
        return Err(p.fail(p.length_error()));
    }
    let kind = p.byte(0);
    let count = p.byte(1);
    let model = match kind {
        KIND_POLY => {
            let order = count as usize;
            if !(1..=MAX_POLY_ORDER).contains(&order) {
                return Err(p.fail(BlobError::UnsupportedOrder { order: count, offset: p.base + 1 }));
            }
            p.reserved_zero(2..MODEL_HEADER_BYTES)?;
            p.expect_len(MODEL_HEADER_BYTES + COEF_SET_BYTES * order)?;
            // ΔT_max and its powers in `f32` (see `Payload::value_scaled`).
            let (lo32, hi32, t032) = (lo as f32, hi as f32, t0_c as f32);
            let span = (lo32 - t032).abs().max((hi32 - t032).abs());
            let mut coef = [CoefDelta::zero(); MAX_POLY_ORDER];
            let mut scale = 1.0f32;
            for (n, c) in coef.iter_mut().enumerate().take(order) {
                scale *= span;
                let t = n as u8;
                *c = read_coef_set(&p, MODEL_HEADER_BYTES + COEF_SET_BYTES * n, &k, scale, CoefSet::Term(t))?;
            }
            TempModel::Poly { order: count, coef }
        }
        KIND_PWL => {
            let n = count as usize;
            if !(2..=MAX_KNOTS).contains(&n) {
                return Err(p.fail(BlobError::KnotCount { count, offset: p.base + 1 }));
            }
            p.reserved_zero(2..MODEL_HEADER_BYTES)?;
            p.expect_len(MODEL_HEADER_BYTES + (8 + COEF_SET_BYTES) * n)?;
            let mut knots_c = [0.0; MAX_KNOTS];
            for (i, slot) in knots_c.iter_mut().enumerate().take(n) {
                p.value_in(
                    slot,
                    MODEL_HEADER_BYTES + 8 * i,
                    Field::Knot { knot: i as u8 },
                    limits::TEMP_MIN_C,
                    limits::TEMP_MAX_C,
                )?;
            }
            for i in 1..n {
                if let (Some(a), Some(b)) = (knots_c.get(i - 1), knots_c.get(i))
                    && !lt(*a, *b)
                {
                    return Err(p.fail(BlobError::KnotsNotIncreasing {
                        knot: i as u8,
                        offset: p.base + MODEL_HEADER_BYTES + 8 * i,
                    }));
                }
            }
            let mut at_knot = [CoefDelta::zero(); MAX_KNOTS];
            let sets = MODEL_HEADER_BYTES + 8 * n;
            for (i, c) in at_knot.iter_mut().enumerate().take(n) {
                let kn = i as u8;
                *c = read_coef_set(&p, sets + COEF_SET_BYTES * i, &k, 1.0, CoefSet::Knot(kn))?;
            }
            TempModel::Pwl { n_knots: count, knots_c, at_knot }
        }
        code => return Err(p.fail(BlobError::BadCode { field: Field::ModelKind, offset: p.base, code })),
    };

    // Method.
    let p = Payload::require(&blob, section::METHOD, err)?;
    p.expect_len(METHOD_BYTES)?;
    let (m, form) = (p.byte(0), p.byte(1));
    let method = match (m, form) {
        (0, 0) => Method::Uncorrected,
        (1, 0) => Method::CoefficientCorrection,
        (2, 1) => Method::OutputCorrection(Form::Full),
        (2, 2) => Method::OutputCorrection(Form::Simplified),
        (2, 3) => Method::OutputCorrection(Form::Linearized),
        (0..=2, code) => return Err(p.fail(BlobError::BadCode { field: Field::Form, offset: p.base + 1, code })),
        (code, _) => return Err(p.fail(BlobError::BadCode { field: Field::Method, offset: p.base, code })),
    };
    p.reserved_zero(2..METHOD_BYTES)?;

    // Traceability.
    let mut meta = Meta::default();
    if let Some(p) = Payload::get(&blob, section::SERIAL, err) {
        meta.serial = p.text(Field::Serial)?;
    }
    if let Some(p) = Payload::get(&blob, section::TOOL_VERSION, err) {
        meta.tool_version = p.text(Field::ToolVersion)?;
    }
    if let Some(p) = Payload::get(&blob, section::CAL_DATE, err) {
        p.expect_len(CAL_DATE_BYTES)?;
        let date = CalDate { year: u16_at(p.bytes, 0).unwrap_or(0), month: p.byte(2), day: p.byte(3) };
        if !date.is_valid() {
            return Err(p.fail(BlobError::OutOfRange { field: Field::CalDate, offset: p.base }));
        }
        meta.date = Some(date);
    }

    let vibration = parse_vibration(&blob, err)?;
    let dynamics = parse_dynamics(&blob, err)?;

    let params =
        CalibrationParams { constants: Constants { k_v_per_g: k, u0_v }, t0_c, model, method, temp_range_c: (lo, hi) };
    params.validate().map_err(|e| reject(err, e.into()))?;
    // The vibration values' checks above imply `VibrationParams::validate`'s (a host test
    // holds them so); it does not run again.
    Ok(ParsedCalibration { params, vibration, dynamics, meta, blob })
}

/// The thermal-dynamics section, if present (see `docs/calibration-blob.md`): its layout
/// version, each parameter within its range ([`Field::limit`]), the bias play's gains zero
/// without a play width: the checks of [`ThermalDynamics::validate`], naming the field and
/// its offset.
#[inline(never)]
#[cfg_attr(unstable_target, optimize(size))]
fn parse_dynamics(blob: &Blob<'_>, err: &Cell<BlobError>) -> Checked<Option<ThermalDynamics<f64>>> {
    let Some(p) = Payload::get(blob, section::THERMAL_DYNAMICS, err) else { return Ok(None) };
    p.expect_len(DYNAMICS_BYTES)?;
    let code = p.byte(0);
    if code != DYNAMICS_LAYOUT {
        return Err(p.fail(BlobError::BadCode { field: Field::DynamicsLayout, offset: p.base, code }));
    }
    p.reserved_zero(1..DYNAMICS_HEADER_BYTES)?;
    let mut a = [0.0; 8];
    for n in 0..8 {
        // The bias play's gains (5, 6, 7) must be 0 without a play width (4, read before).
        let (lo, hi) = if n >= 5 && eq(a[4], 0.0) { (0.0, 0.0) } else { dynamics::limits(n as u8) };
        p.value_in(&mut a[n], DYNAMICS_HEADER_BYTES + 8 * n, Field::Dynamics { param: n as u8 }, lo, hi)?;
    }
    let d = ThermalDynamics::from_array(&a);
    // These checks are [`ThermalDynamics::validate`]'s, field by field (the host tests check
    // that the parser accepts exactly what it accepts); `at_rate` does not repeat them.
    Ok(Some(d))
}

/// The vibration section and the flight-phase profiles, if present (see
/// `docs/calibration-blob.md`). Profiles without a vibration section are refused: they mean
/// nothing without the coefficients.
#[inline(never)]
#[cfg_attr(unstable_target, optimize(size))]
fn parse_vibration(blob: &Blob<'_>, err: &Cell<BlobError>) -> Checked<Option<VibrationParams>> {
    let Some(p) = Payload::get(blob, section::VIBRATION, err) else {
        return match Payload::get(blob, section::FLIGHT_PHASES, err) {
            Some(_) => Err(reject(err, BlobError::MissingSection(section::VIBRATION))),
            None => Ok(None),
        };
    };
    p.expect_len(VIBRATION_BYTES)?;
    let variant = match p.byte(0) {
        VARIANT_PAPER => Variant::Paper,
        VARIANT_EXACT => Variant::Exact,
        code => return Err(p.fail(BlobError::BadCode { field: Field::VibVariant, offset: p.base, code })),
    };
    p.reserved_zero(1..VIBRATION_HEADER_BYTES)?;
    let mut cf = [ConversionFunction::<f64>::default(); 3];
    for (axis, c) in cf.iter_mut().enumerate() {
        let mut a = [0.0; 10];
        for (n, x) in a.iter_mut().enumerate() {
            let lim = coefficient_limit(n as u8);
            let at = VIBRATION_HEADER_BYTES + CONVERSION_FUNCTION_BYTES * axis + 8 * n;
            p.value_in(x, at, Field::VibCoef { axis: axis as u8, coef: n as u8 }, -lim, lim)?;
        }
        *c = ConversionFunction::from_array(&a);
    }
    let mut out = VibrationParams::new(cf, variant);
    let Some(p) = Payload::get(blob, section::FLIGHT_PHASES, err) else { return Ok(Some(out)) };
    if p.bytes.len() < PROFILES_HEADER_BYTES {
        return Err(p.fail(p.length_error()));
    }
    let count = p.byte(0);
    let n = count as usize;
    if !(1..=MAX_PROFILES).contains(&n) {
        return Err(p.fail(BlobError::ProfileCount { count, offset: p.base }));
    }
    p.reserved_zero(1..PROFILES_HEADER_BYTES)?;
    p.expect_len(PROFILES_HEADER_BYTES + PROFILE_BYTES * n)?;
    for (i, slot) in out.profiles.iter_mut().enumerate().take(n) {
        let at = PROFILES_HEADER_BYTES + PROFILE_BYTES * i;
        let profile = i as u8;
        let v = at + 8;
        let kind = p.byte(at);
        p.reserved_zero(at + 1..at + 8)?;
        *slot = match kind {
            PROFILE_NONE => {
                p.reserved_zero(v..v + 40)?;
                Vibration::None
            }
            PROFILE_SINE => {
                let mut amp_g = [0.0; 3];
                for (j, a) in amp_g.iter_mut().enumerate() {
                    p.value_in(a, v + 8 * j, Field::ProfileAmp { profile, axis: j as u8 }, -MAX_LEVEL_G, MAX_LEVEL_G)?;
                }
                let mut freq_hz = 0.0;
                p.value_in(&mut freq_hz, v + 24, Field::ProfileFreq { profile }, 0.0, limits::FREQ_MAX_HZ)?;
                p.reserved_zero(v + 32..v + 40)?;
                Vibration::Harmonic { amp_g, freq_hz }
            }
            PROFILE_RANDOM => {
                let mut sigma_g = [0.0; 3];
                for (j, s) in sigma_g.iter_mut().enumerate() {
                    p.value_in(s, v + 8 * j, Field::ProfileSigma { profile, axis: j as u8 }, 0.0, MAX_LEVEL_G)?;
                }
                let mut lo = 0.0;
                p.value_in(&mut lo, v + 24, Field::ProfileBand { profile, end: 0 }, 0.0, limits::FREQ_MAX_HZ)?;
                let field = Field::ProfileBand { profile, end: 1 };
                let mut hi = 0.0;
                p.value_in(&mut hi, v + 32, field, 0.0, limits::FREQ_MAX_HZ)?;
                if !lt(lo, hi) {
                    return Err(p.fail(BlobError::OutOfRange { field, offset: p.base + v + 32 }));
                }
                Vibration::Random { sigma_g, band_hz: (lo, hi) }
            }
            code => {
                return Err(p.fail(BlobError::BadCode {
                    field: Field::ProfileKind { profile },
                    offset: p.base + at,
                    code,
                }));
            }
        };
    }
    out.n_profiles = count;
    Ok(Some(out))
}

/// Parses the blob at the start of a flash region (e.g. the whole CALIB region): the blob's
/// own declared length selects the bytes, the rest of the region (erased flash) is ignored.
pub fn parse_region(region: &[u8]) -> Result<ParsedCalibration<'_>, BlobError> {
    let declared = u32_at(region, 8)
        .map(|n| n as usize)
        .filter(|n| (HEADER_BYTES..=region.len()).contains(n))
        .unwrap_or(region.len());
    parse(region.get(..declared).unwrap_or(region))
}

// ---- encoder ---------------------------------------------------------------------------------

/// The ids, flags and payload lengths the encoder writes for `params` and `meta`, in id
/// order; unused slots have id 0.
fn layout(
    params: &CalibrationParams,
    vib: Option<&VibrationParams>,
    dynamics: Option<&ThermalDynamics<f64>>,
    meta: &Meta<'_>,
) -> ([SectionEntry; MAX_SECTIONS], usize) {
    let model_len = match params.model {
        TempModel::Poly { order, .. } => MODEL_HEADER_BYTES + COEF_SET_BYTES * order as usize,
        TempModel::Pwl { n_knots, .. } => MODEL_HEADER_BYTES + (8 + COEF_SET_BYTES) * n_knots as usize,
    };
    let n_profiles = vib.map_or(0, |v| v.n_profiles as usize);
    let all = [
        (section::CONSTANTS, FLAG_REQUIRED, CONSTANTS_BYTES, true),
        (section::TEMP_MODEL, FLAG_REQUIRED, model_len, true),
        (section::METHOD, FLAG_REQUIRED, METHOD_BYTES, true),
        (section::TEMP_RANGE, FLAG_REQUIRED, TEMP_RANGE_BYTES, true),
        (section::VIBRATION, FLAG_REQUIRED, VIBRATION_BYTES, vib.is_some()),
        (section::FLIGHT_PHASES, FLAG_REQUIRED, PROFILES_HEADER_BYTES + PROFILE_BYTES * n_profiles, n_profiles > 0),
        (section::THERMAL_DYNAMICS, FLAG_REQUIRED, DYNAMICS_BYTES, dynamics.is_some()),
        (section::SERIAL, 0, meta.serial.len(), !meta.serial.is_empty()),
        (section::CAL_DATE, 0, CAL_DATE_BYTES, meta.date.is_some()),
        (section::TOOL_VERSION, 0, meta.tool_version.len(), !meta.tool_version.is_empty()),
    ];
    let mut out = [SectionEntry::default(); MAX_SECTIONS];
    let mut n = 0;
    for (id, flags, len, present) in all {
        if present && let Some(slot) = out.get_mut(n) {
            *slot = SectionEntry { id, flags, offset: 0, len: len.min(u32::MAX as usize) as u32 };
            n += 1;
        }
    }
    (out, n)
}

fn align8(x: usize) -> usize {
    x.div_ceil(8) * 8
}

/// A bounds-checked writer over the output buffer.
struct Writer<'a> {
    out: &'a mut [u8],
}

impl Writer<'_> {
    fn put(&mut self, at: usize, bytes: &[u8]) -> Result<(), BlobError> {
        let needed = at.saturating_add(bytes.len());
        match self.out.get_mut(at..needed) {
            Some(dst) => {
                dst.copy_from_slice(bytes);
                Ok(())
            }
            None => Err(BlobError::BufferTooSmall { needed }),
        }
    }
    fn f64s(&mut self, at: usize, xs: &[f64]) -> Result<(), BlobError> {
        for (n, x) in xs.iter().enumerate() {
            self.put(at + 8 * n, &x.to_le_bytes())?;
        }
        Ok(())
    }
}

/// Writes `params` and `meta` as a version-1 blob into `out` and returns its length. Sections
/// are written in id order at 8-byte-aligned offsets, padding zero; the mandatory ones carry
/// [`FLAG_REQUIRED`], the traceability ones (omitted when empty) do not.
///
/// The written blob is then checked by [`parse`], so the encoder refuses exactly what the
/// firmware would refuse, with the same error (offsets refer to the written blob). Polynomial
/// coefficients above the order and knots beyond the count are not stored (they are zero
/// after parsing).
///
/// # Example
///
/// Encode the paper's calibration, parse it back, and see one flipped bit refused.
///
/// ```
/// use bins_comp::blob::{self, BlobError, Meta, MAX_BLOB_BYTES};
/// use bins_comp::compensate::Method;
/// use bins_comp::paper;
///
/// let params = paper::params(paper::two_range_model()?, Method::CoefficientCorrection);
/// let meta = Meta { serial: "SN-0042", date: None, tool_version: "example 1" };
/// let mut bytes = [0u8; MAX_BLOB_BYTES];
/// let n = blob::encode(&params, &meta, &mut bytes)?;
///
/// let parsed = blob::parse(&bytes[..n])?;
/// assert_eq!(parsed.params, params);
/// assert_eq!(parsed.meta.serial, "SN-0042");
/// assert!(parsed.vibration.is_none() && parsed.dynamics.is_none());
///
/// bytes[n / 2] ^= 0x10;
/// assert!(matches!(blob::parse(&bytes[..n]), Err(BlobError::CrcMismatch { .. })));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn encode(params: &CalibrationParams, meta: &Meta<'_>, out: &mut [u8]) -> Result<usize, BlobError> {
    encode_with_vibration(params, None, meta, out)
}

/// [`encode`] with the vibration-error configuration: with `vib`, the vibration section
/// ([`section::VIBRATION`]) and, when it has profiles, the flight-phase section
/// ([`section::FLIGHT_PHASES`]) are written too, both [`FLAG_REQUIRED`]. Profiles beyond
/// `n_profiles` are not stored.
pub fn encode_with_vibration(
    params: &CalibrationParams,
    vib: Option<&VibrationParams>,
    meta: &Meta<'_>,
    out: &mut [u8],
) -> Result<usize, BlobError> {
    encode_with_dynamics(params, vib, None, meta, out)
}

/// [`encode_with_vibration`], with the thermal-dynamics section when `dynamics` is given
/// (written REQUIRED, layout version [`DYNAMICS_LAYOUT`]). Dynamics with every stage off are
/// written as given: the blob then says explicitly that the unit has none.
pub fn encode_with_dynamics(
    params: &CalibrationParams,
    vib: Option<&VibrationParams>,
    dynamics: Option<&ThermalDynamics<f64>>,
    meta: &Meta<'_>,
    out: &mut [u8],
) -> Result<usize, BlobError> {
    if let Some(v) = vib
        && v.n_profiles as usize > MAX_PROFILES
    {
        return Err(BlobError::ProfileCount { count: v.n_profiles, offset: 0 });
    }
    match params.model {
        TempModel::Poly { order, .. } if !(1..=MAX_POLY_ORDER).contains(&(order as usize)) => {
            return Err(BlobError::UnsupportedOrder { order, offset: 0 });
        }
        TempModel::Pwl { n_knots, .. } if !(2..=MAX_KNOTS).contains(&(n_knots as usize)) => {
            return Err(BlobError::KnotCount { count: n_knots, offset: 0 });
        }
        _ => {}
    }
    let (mut entries, n) = layout(params, vib, dynamics, meta);
    let mut at = align8(HEADER_BYTES + ENTRY_BYTES * n);
    for e in entries.iter_mut().take(n) {
        e.offset = at as u32;
        // Text too long to store: refused here, before it could overflow the region.
        let field = match e.id {
            section::SERIAL => Some(Field::Serial),
            section::TOOL_VERSION => Some(Field::ToolVersion),
            _ => None,
        };
        if let Some(field) = field
            && e.len as usize > MAX_TEXT_BYTES
        {
            return Err(BlobError::OutOfRange { field, offset: at });
        }
        at = align8(at + e.len as usize);
    }
    let total = at + CRC_BYTES;
    if total > MAX_BLOB_BYTES || total > out.len() {
        return Err(BlobError::BufferTooSmall { needed: total });
    }
    let mut w = Writer { out };
    if let Some(region) = w.out.get_mut(..total) {
        region.fill(0);
    }
    w.put(0, &MAGIC)?;
    w.put(4, &FORMAT_VERSION.to_le_bytes())?;
    w.put(6, &(n as u16).to_le_bytes())?;
    w.put(8, &(total as u32).to_le_bytes())?;
    for (k, e) in entries.iter().take(n).enumerate() {
        let t = HEADER_BYTES + ENTRY_BYTES * k;
        w.put(t, &e.id.to_le_bytes())?;
        w.put(t + 2, &e.flags.to_le_bytes())?;
        w.put(t + 4, &e.offset.to_le_bytes())?;
        w.put(t + 8, &e.len.to_le_bytes())?;
        let at = e.offset as usize;
        match e.id {
            section::CONSTANTS => {
                let c = &params.constants;
                w.f64s(at, &[params.t0_c])?;
                for i in 0..3 {
                    w.f64s(at + 8 + 24 * i, &c.k_v_per_g[i])?;
                }
                w.f64s(at + 80, &c.u0_v)?;
            }
            section::TEMP_MODEL => match &params.model {
                TempModel::Poly { order, coef } => {
                    w.put(at, &[KIND_POLY, *order])?;
                    for (n, c) in coef.iter().take(*order as usize).enumerate() {
                        w.f64s(at + MODEL_HEADER_BYTES + COEF_SET_BYTES * n, &c.to_array())?;
                    }
                }
                TempModel::Pwl { n_knots, knots_c, at_knot } => {
                    let nk = *n_knots as usize;
                    w.put(at, &[KIND_PWL, *n_knots])?;
                    w.f64s(at + MODEL_HEADER_BYTES, knots_c.get(..nk).unwrap_or(&[]))?;
                    for (i, c) in at_knot.iter().take(nk).enumerate() {
                        w.f64s(at + MODEL_HEADER_BYTES + 8 * nk + COEF_SET_BYTES * i, &c.to_array())?;
                    }
                }
            },
            section::METHOD => {
                let code = match params.method {
                    Method::Uncorrected => [0, 0],
                    Method::CoefficientCorrection => [1, 0],
                    Method::OutputCorrection(Form::Full) => [2, 1],
                    Method::OutputCorrection(Form::Simplified) => [2, 2],
                    Method::OutputCorrection(Form::Linearized) => [2, 3],
                };
                w.put(at, &code)?;
            }
            section::TEMP_RANGE => w.f64s(at, &[params.temp_range_c.0, params.temp_range_c.1])?,
            section::VIBRATION => {
                if let Some(v) = vib {
                    let code = match v.variant {
                        Variant::Paper => VARIANT_PAPER,
                        Variant::Exact => VARIANT_EXACT,
                    };
                    w.put(at, &[code])?;
                    for (axis, cf) in v.cf.iter().enumerate() {
                        w.f64s(at + VIBRATION_HEADER_BYTES + CONVERSION_FUNCTION_BYTES * axis, &cf.to_array())?;
                    }
                }
            }
            section::FLIGHT_PHASES => {
                if let Some(v) = vib {
                    w.put(at, &[v.n_profiles])?;
                    for (i, prof) in v.profiles.iter().take(v.n_profiles as usize).enumerate() {
                        let p = at + PROFILES_HEADER_BYTES + PROFILE_BYTES * i;
                        match prof {
                            Vibration::None => w.put(p, &[PROFILE_NONE])?,
                            Vibration::Harmonic { amp_g, freq_hz } => {
                                w.put(p, &[PROFILE_SINE])?;
                                w.f64s(p + 8, amp_g)?;
                                w.f64s(p + 32, &[*freq_hz])?;
                            }
                            Vibration::Random { sigma_g, band_hz } => {
                                w.put(p, &[PROFILE_RANDOM])?;
                                w.f64s(p + 8, sigma_g)?;
                                w.f64s(p + 32, &[band_hz.0, band_hz.1])?;
                            }
                        }
                    }
                }
            }
            section::THERMAL_DYNAMICS => {
                if let Some(d) = dynamics {
                    w.put(at, &[DYNAMICS_LAYOUT])?;
                    w.f64s(at + DYNAMICS_HEADER_BYTES, &d.to_array())?;
                }
            }
            section::SERIAL => w.put(at, meta.serial.as_bytes())?,
            section::TOOL_VERSION => w.put(at, meta.tool_version.as_bytes())?,
            section::CAL_DATE => {
                if let Some(d) = meta.date {
                    w.put(at, &d.year.to_le_bytes())?;
                    w.put(at + 2, &[d.month, d.day])?;
                }
            }
            _ => {}
        }
    }
    let body_end = total - CRC_BYTES;
    let crc = crc32(w.out.get(..body_end).unwrap_or(&[]));
    w.put(body_end, &crc.to_le_bytes())?;
    parse(w.out.get(..total).unwrap_or(&[]))?;
    Ok(total)
}

/// Recomputes and stores the CRC of a blob whose header declares its length (for tools that
/// patch a blob, and for tests that build invalid contents under a valid CRC). Returns false
/// when the declared length does not fit `bytes`.
pub fn reseal(bytes: &mut [u8]) -> bool {
    let Some(declared) = u32_at(bytes, 8).map(|n| n as usize) else { return false };
    if !(MIN_BLOB_BYTES..=bytes.len()).contains(&declared) {
        return false;
    }
    let body_end = declared - CRC_BYTES;
    let crc = crc32(bytes.get(..body_end).unwrap_or(&[]));
    match bytes.get_mut(body_end..declared) {
        Some(dst) => {
            dst.copy_from_slice(&crc.to_le_bytes());
            true
        }
        None => false,
    }
}
