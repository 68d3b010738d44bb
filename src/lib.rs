//! # bins-comp: compensation core of a navigation-grade triaxial accelerometer
//!
//! This crate owns every formula the flight software applies to a sample, and the
//! identification helpers the host tools use to find the constants those formulas need.
//! It is `#![no_std]`, allocates nothing and contains no reachable panic on the per-sample
//! path (checked at link time by the `linkcheck` binary).
//!
//! Every numeric routine is generic over [`Float`], so the same source runs as `f32` on the
//! Cortex-M4F and as `f64` on the host, where it is the reference the `f32` results are tested
//! against.
//!
//! Equation numbers `T(n)` (temperature paper) and `V(n)` (vibration paper) each have a
//! heading with the formula, units and errata in `docs/equations.md` of the repository
//! (`docs/equations.md#t5` for T(5)).
//!
//! | module | owns |
//! |---|---|
//! | [`float`] | the `Float` abstraction over `f32`/`f64` |
//! | [`linalg`] | 3×3 matrices: products, checked inverse, conditioning |
//! | [`model`] | the metrological model T(1) and its constants |
//! | [`temperature`] | temperature models T(3)/T(4) of the 12 constants |
//! | [`compensate`] | the per-sample step: methods 1 and 2 of §5, status bits |
//! | [`dynamics`] | thermal dynamics: lag, hysteresis and self-heating of the die behind the thermistor, bias hysteresis |
//! | [`ident`] | identification: six-position T(10), least squares, T(11)/T(12) |
//! | [`paper`] | the temperature paper's Tables T1/T2/T3 as constants |
//! | [`vectors`] | the test-vector record shared by the host and the firmware |
//! | [`vibration`] | vibration error V(1)–V(23): conversion function, paper and exact VE, online moments, shake-table identification |
//! | [`pipeline`] | the per-sample step with vibration-error subtraction |
//! | [`blob`] | the calibration blob: byte format, parser, encoder, CRC-32, physical limits |
//! | [`replay`] | the sampling interrupt's step and the replay stream formats shared by the firmware and `bins-cal replay` |
//! | [`drivers`] | sensor drivers (ADS131M04 ADC, TMP117 temperature) over embedded-hal, and the sample source's fault policy |
//! | [`frame`] | the flight image's serial output frames: layout, fixed-point accelerations, encoder and decoder |
#![no_std]
#![cfg_attr(unstable_target, feature(optimize_attribute, core_float_math, ascii_char))]
#![forbid(unsafe_code)]
#![deny(missing_docs)]

pub mod blob;
pub mod compensate;
pub mod drivers;
pub mod dynamics;
pub mod float;
pub mod frame;
pub mod ident;
pub mod linalg;
pub mod model;
pub mod paper;
pub mod pipeline;
pub mod replay;
pub mod temperature;
pub mod vectors;
pub mod vibration;

pub use compensate::{
    AtTemperature, Calibration, CalibrationError, CalibrationParams, Form, Method, Sample, Status, TempCache,
};
pub use dynamics::{DynamicsState, Effective, FixedRate, ThermalDynamics};
pub use float::Float;
pub use linalg::{Mat3, Vec3};
pub use model::Constants;
pub use pipeline::{Pipeline, PipelineState, VibrationSource};
pub use temperature::{CoefDelta, TempModel};
pub use vibration::{ConversionFunction, Variant, Vibration, VibrationConfig, VibrationParams};
