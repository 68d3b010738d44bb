//! The subcommands, one module each.

pub mod blob;
pub mod calibrate;
pub mod diagnose;
pub mod export;
pub mod import;
pub mod replay;
pub mod shaker;
pub mod simulate;
pub mod tempco;
pub mod verify;
pub mod vibration;
