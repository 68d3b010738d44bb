//! The subcommands, one module each.

pub mod blob;
pub mod tempco;
pub mod vibration;
