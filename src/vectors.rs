//! The test-vector record the host writes and the firmware replays: one record per
//! (calibration variant, signals, temperature), with the host's `f32` result to compare
//! against bit for bit. Also the table of calibration variants both sides build.
//!
//! Record layout (little-endian, [`RECORD_BYTES`] bytes):
//!
//! | offset | type | field |
//! |---|---|---|
//! | 0 | u32 | variant index into [`variant_method`] |
//! | 4 | f32×3 | `u_v` |
//! | 16 | f32 | `temp_c` |
//! | 20 | f32×3 | expected `accel_g` |
//! | 32 | u32 | expected status bits |
//!
//! The result the firmware writes back is the last 16 bytes of the same layout
//! ([`RESULT_BYTES`]): `accel_g` and status.
//!
//! Variant indices from [`VIB_VARIANT_BASE`] on run the per-sample step with vibration-error
//! subtraction ([`Pipeline`]) instead, see [`vibration_variant`].

use crate::compensate::{Calibration, Form, Method, Sample, Status};
use crate::float::Float;
use crate::linalg::Vec3;
use crate::paper;
use crate::pipeline::{Pipeline, PipelineState, VibrationSource};
use crate::vibration::{Variant, VibrationConfig, VibrationParams, tables};

/// Size of one input record.
pub const RECORD_BYTES: usize = 36;
/// Size of one result record.
pub const RESULT_BYTES: usize = 16;
/// Number of calibration variants.
pub const VARIANTS: usize = 11;
/// The variant that is always [`Calibration::uncalibrated`].
pub const UNCALIBRATED_VARIANT: usize = 9;
/// The variant whose calibration comes from the blob in the CALIB flash region
/// ([`crate::blob`]): the firmware parses the region at boot, the host the same blob file.
/// [`calibrations`] leaves it uncalibrated; the caller sets it.
pub const FLASHED_VARIANT: usize = 10;

/// Temperature model of a variant.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VariantModel {
    /// The paper's two-range piecewise-linear model.
    TwoRange,
    /// The quadratic through Tables T1/T2.
    Quadratic,
}

/// Model and method of each variant: 0 uncorrected; 1–4 two-range with method 1, method 2
/// simplified, full, linearized; 5–8 the same with the quadratic; 9 uncalibrated; 10 the
/// flashed calibration (no fixed model or method: `None`).
pub fn variant_method(index: usize) -> Option<(VariantModel, Method)> {
    const M: [Method; 4] = [
        Method::CoefficientCorrection,
        Method::OutputCorrection(Form::Simplified),
        Method::OutputCorrection(Form::Full),
        Method::OutputCorrection(Form::Linearized),
    ];
    match index {
        0 | 9 => Some((VariantModel::TwoRange, Method::Uncorrected)),
        1..=4 => M.get(index - 1).map(|&m| (VariantModel::TwoRange, m)),
        5..=8 => M.get(index - 5).map(|&m| (VariantModel::Quadratic, m)),
        _ => None,
    }
}

/// Builds every variant's `f32` calibration: identified in `f64`, rounded, re-validated.
/// Variants [`UNCALIBRATED_VARIANT`] and [`FLASHED_VARIANT`] are
/// [`Calibration::uncalibrated`]. A variant that fails to build is also the uncalibrated
/// stand-in (so its samples are flagged), which the tests would notice.
pub fn calibrations() -> [Calibration<f32>; VARIANTS] {
    let mut out = [Calibration::<f32>::uncalibrated(); VARIANTS];
    for (i, slot) in out.iter_mut().enumerate().take(UNCALIBRATED_VARIANT) {
        let Some((model, method)) = variant_method(i) else { continue };
        let model = match model {
            VariantModel::TwoRange => paper::two_range_model(),
            VariantModel::Quadratic => paper::quadratic_truth(),
        };
        if let Ok(cal) = model.map_err(|_| ()).and_then(|m| paper::calibration::<f32>(m, method).map_err(|_| ())) {
            *slot = cal;
        }
    }
    out
}

/// First variant index of the vibration records: `VIB_VARIANT_BASE + k` (k < 8) compensates
/// with variant 1 (two-range model, method 1) and subtracts the exact VE of flight profile k
/// ([`tables::flight_profiles`], AL-15 conversion functions on all three axes);
/// `VIB_VARIANT_BASE + 8 + k` the same with the paper's formulas. Profile 7 does not exist,
/// so its records carry [`Status::VIBRATION_ESTIMATE_NOT_READY`].
pub const VIB_VARIANT_BASE: u32 = 32;
/// Number of vibration variants.
pub const VIB_VARIANTS: u32 = 16;

/// The VE formulas and profile index of a vibration variant, `None` for other indices.
pub fn vibration_variant(index: u32) -> Option<(Variant, u8)> {
    let k = index.checked_sub(VIB_VARIANT_BASE)?;
    match k {
        0..=7 => Some((Variant::Exact, k as u8)),
        8..=15 => Some((Variant::Paper, (k - 8) as u8)),
        _ => None,
    }
}

/// The VE parameters of the vibration variants: AL-15 on all three accelerometers, the
/// flight profiles of Tables V2/V3.
pub fn vibration_params(variant: Variant) -> VibrationParams {
    let mut p = VibrationParams::new([tables::AL15; 3], variant);
    let (profiles, n) = tables::flight_profiles();
    p.profiles = profiles;
    p.n_profiles = n;
    p
}

/// The VE configuration of [`vibration_params`]; [`VibrationConfig::none`] if it failed to
/// build.
pub fn vibration_config<F: Float>(variant: Variant) -> VibrationConfig<F> {
    VibrationConfig::new(&vibration_params(variant)).unwrap_or(VibrationConfig::none())
}

/// One decoded input record.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Record {
    /// Variant index.
    pub variant: u32,
    /// Signals \[V\].
    pub u_v: Vec3<f32>,
    /// Temperature [°C].
    pub temp_c: f32,
    /// The host's result.
    pub expected: Sample<f32>,
}

fn f32_at(b: &[u8; RECORD_BYTES], off: usize) -> f32 {
    f32::from_bits(u32_at(b, off))
}

fn u32_at(b: &[u8; RECORD_BYTES], off: usize) -> u32 {
    let mut w = [0u8; 4];
    if let Some(s) = b.get(off..off + 4) {
        w.copy_from_slice(s);
    }
    u32::from_le_bytes(w)
}

impl Record {
    /// Decodes a record.
    pub fn decode(b: &[u8; RECORD_BYTES]) -> Record {
        Record {
            variant: u32_at(b, 0),
            u_v: [f32_at(b, 4), f32_at(b, 8), f32_at(b, 12)],
            temp_c: f32_at(b, 16),
            expected: Sample { accel_g: [f32_at(b, 20), f32_at(b, 24), f32_at(b, 28)], status: Status(u32_at(b, 32)) },
        }
    }

    /// Encodes a record.
    pub fn encode(&self) -> [u8; RECORD_BYTES] {
        let mut b = [0u8; RECORD_BYTES];
        let words = [
            self.variant,
            self.u_v[0].to_bits(),
            self.u_v[1].to_bits(),
            self.u_v[2].to_bits(),
            self.temp_c.to_bits(),
            self.expected.accel_g[0].to_bits(),
            self.expected.accel_g[1].to_bits(),
            self.expected.accel_g[2].to_bits(),
            self.expected.status.0,
        ];
        for (chunk, w) in b.chunks_exact_mut(4).zip(words) {
            chunk.copy_from_slice(&w.to_le_bytes());
        }
        b
    }
}

/// Runs a record's inputs through its variant; an unknown variant gives the uncalibrated
/// result.
pub fn evaluate(cals: &[Calibration<f32>; VARIANTS], rec: &Record) -> Sample<f32> {
    if let Some((variant, profile)) = vibration_variant(rec.variant) {
        let cal = cals.get(1).copied().unwrap_or(Calibration::uncalibrated());
        let pipeline = Pipeline::new(cal, vibration_config(variant));
        let mut state = PipelineState::<f32, 1>::new();
        return pipeline.step(&mut state, rec.u_v, rec.temp_c, VibrationSource::Profile(profile));
    }
    match cals.get(rec.variant as usize) {
        Some(cal) => cal.compensate(rec.u_v, rec.temp_c),
        None => Calibration::<f32>::uncalibrated().compensate(rec.u_v, rec.temp_c),
    }
}

/// Encodes a result record.
pub fn encode_result(s: &Sample<f32>) -> [u8; RESULT_BYTES] {
    let mut b = [0u8; RESULT_BYTES];
    let words = [s.accel_g[0].to_bits(), s.accel_g[1].to_bits(), s.accel_g[2].to_bits(), s.status.0];
    for (chunk, w) in b.chunks_exact_mut(4).zip(words) {
        chunk.copy_from_slice(&w.to_le_bytes());
    }
    b
}

/// True when two samples are identical bit for bit.
pub fn bit_identical(a: &Sample<f32>, b: &Sample<f32>) -> bool {
    a.status == b.status && a.accel_g.iter().zip(b.accel_g.iter()).all(|(x, y)| x.to_bits() == y.to_bits())
}
