//! The subcommands, one module each.

pub mod blob;
pub mod simulate;
pub mod tempco;
pub mod vibration;
