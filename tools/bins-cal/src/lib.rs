//! # bins-cal: host tools of the compensation core
//!
//! The library half of the `bins-cal` command: the human-readable calibration file and the
//! helpers the commands share. The binary (`src/main.rs`) holds one module per subcommand.
//!
//! | module | owns |
//! |---|---|
//! | [`autopilot`] | a calibration's bias against temperature as PX4 / ArduPilot parameters, evaluated as their firmware does |
//! | [`calib`] | calibration algorithms: dwells, per-temperature constants and temperature model, shake-table fits |
//! | [`calfile`] | the calibration file (TOML): types, checks naming the key, conversion to and from the core's parameters and the blob |
//! | [`constants_table`] | tables of the constants at several temperatures (CSV) |
//! | [`diagnose`] | sim-vs-real mismatch: residual, strata, mechanism library, selection, report |
//! | [`ihex`] | Intel HEX output |
//! | [`memmap`] | the CALIB region's address, read from `memory.x` |
//! | [`fclog`] | flight-controller logs (PX4 ULog, ArduPilot DataFlash): streaming readers, import into recordings |
//! | [`fsio`] | writing outputs atomically (temporary file + rename) |
//! | [`recording`] | recording format v1: streaming reader and writer |
//! | [`progress`] | a pass over a recording with a progress bar by bytes read |
//! | [`sim`] | the simulator: the unit's truth model on its rigs, scenario files |
#![deny(missing_docs)]

pub mod autopilot;
pub mod calfile;
pub mod calib;
pub mod constants_table;
pub mod diagnose;
pub mod exact;
pub mod fclog;
pub mod fsio;
pub mod ihex;
pub mod memmap;
pub mod numarg;
pub mod progress;
pub mod recording;
pub mod sim;

/// The tool's name and version, as stored in a blob's tool-version section when the
/// calibration file names none.
pub const TOOL_VERSION: &str = concat!("bins-cal ", env!("CARGO_PKG_VERSION"));
