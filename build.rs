//! Puts `memory.x` (and an empty `device.x`) on the linker's search path for the Cortex-M4F
//! binaries, and decides whether they may use three unstable compiler features (bare-metal
//! targets only; host builds of the library do nothing here).
//!
//! `cfg(unstable_target)`: set for a bare-metal build whose compiler accepts unstable features
//! (a nightly, or `RUSTC_BOOTSTRAP=1` as `cargo xtask` sets with `-Zbuild-std`). Then
//! - the code that runs once at boot (blob parsing, calibration validation, the
//!   precomputation) is compiled with `#[optimize(size)]`; the per-sample path keeps
//!   `opt-level = 3`;
//! - `f32` square roots are the FPU's `vsqrt.f32` (`core::f32::math::sqrt`) instead of libm's
//!   integer algorithm; both are correctly rounded, so the results are the same bits;
//! - the blob's text fields, already checked to be printable ASCII, become `&str` through the
//!   ASCII view (`[u8]::as_ascii`) instead of the UTF-8 validator, whose code and 256-byte
//!   table the flight image then does without; the text is the same.
//!
//! On a stable compiler the same code builds without them: larger and a little slower.

use std::{env, fs, path::PathBuf, process::Command};

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-env-changed=RUSTC_BOOTSTRAP");
    println!("cargo:rustc-check-cfg=cfg(unstable_target)");
    if env::var("CARGO_CFG_TARGET_OS").as_deref() != Ok("none") {
        return;
    }
    if unstable_features_accepted() {
        println!("cargo:rustc-cfg=unstable_target");
    }
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    fs::copy("memory.x", out.join("memory.x")).expect("copy memory.x to OUT_DIR");
    // cortex-m-rt's `device` feature includes `device.x` (weak aliases of named interrupt
    // handlers); the images name none, their table is `src/bin/interrupts.rs`.
    fs::write(out.join("device.x"), "/* No named interrupt handlers: see src/bin/interrupts.rs. */\n")
        .expect("write device.x to OUT_DIR");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=memory.x");
}

/// True when the compiler building this crate accepts `#![feature(..)]`.
fn unstable_features_accepted() -> bool {
    if env::var("RUSTC_BOOTSTRAP").is_ok_and(|v| !v.is_empty() && v != "0") {
        return true;
    }
    let rustc = env::var_os("RUSTC").unwrap_or_else(|| "rustc".into());
    Command::new(rustc).arg("-vV").output().is_ok_and(|o| {
        String::from_utf8_lossy(&o.stdout)
            .lines()
            .any(|l| l.starts_with("release:") && (l.contains("-nightly") || l.contains("-dev")))
    })
}
