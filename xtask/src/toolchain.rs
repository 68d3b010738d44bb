//! The toolchains: the host cargo `cargo xtask` runs with, and the thumb toolchain (rustup's
//! with the `thumbv7em-none-eabihf` target, or Debian's Rust with `-Zbuild-std=core`), what it
//! needs installed, and the firmware builds with it.

use std::ffi::OsStr;
use std::path::PathBuf;
use std::process::Command;

use crate::process::{apt_install, cargo_home, cmd, dpkg_installed, on_path, output, probe};
use crate::qemu::DEFAULT_VE;
use crate::task::{Result, Xtask};

pub(crate) const THUMB: &str = "thumbv7em-none-eabihf";

/// Target directory of the firmware builds, relative to the repository root.
pub(crate) const THUMB_TARGET_DIR: &str = "target/thumb";

/// Debian packages of the fallback toolchain and of the QEMU run.
pub(crate) const DEBIAN_PACKAGES: [&str; 7] =
    ["rustc-web", "cargo-web", "rust-web-src", "rust-web-clippy", "rustfmt-web", "lld", "qemu-system-arm"];

/// Variables a parent cargo/rustup sets that must not leak into a child of another toolchain.
pub(crate) const TOOLCHAIN_VARS: [&str; 6] =
    ["RUSTUP_TOOLCHAIN", "RUSTC", "RUSTDOC", "CARGO", "RUSTC_WORKSPACE_WRAPPER", "CLIPPY_ARGS"];

/// How the thumb binaries are built.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Toolchain {
    /// rustup's active toolchain, which has the thumbv7em target.
    Rustup,
    /// Debian's Rust with `-Zbuild-std=core`: `cargo +debian` through rustup, or
    /// `/usr/bin/cargo` without rustup.
    Debian { via_rustup: bool },
}

impl Xtask {
    /// Picks the thumb toolchain and installs what it and the QEMU run need.
    pub(crate) fn setup_toolchain(&mut self) -> Result {
        let has_rustup = probe(Command::new("rustup").arg("--version"));
        let rustup_target = has_rustup
            && output(Command::new("rustup").args(["target", "list", "--installed"]))
                .is_ok_and(|o| o.lines().any(|l| l.trim() == THUMB));
        let tc = if rustup_target {
            println!("using rustup's toolchain (target {THUMB} installed)");
            if !on_path("qemu-system-arm") {
                apt_install(&["qemu-system-arm"])?;
            }
            Toolchain::Rustup
        } else {
            println!("rustup has no {THUMB} target: using Debian's Rust with -Zbuild-std=core");
            let missing: Vec<&str> = DEBIAN_PACKAGES.iter().copied().filter(|p| !dpkg_installed(p)).collect();
            if !missing.is_empty() {
                apt_install(&missing)?;
            }
            if has_rustup {
                let list = output(Command::new("rustup").args(["toolchain", "list"]))?;
                if !list.lines().any(|l| l.split_whitespace().next() == Some("debian")) {
                    self.run(cmd("rustup", ["toolchain", "link", "debian", "/usr"]))?;
                }
            }
            Toolchain::Debian { via_rustup: has_rustup }
        };
        self.toolchain = Some(tc);
        self.ensure_defmt_print()
    }

    /// Installs defmt-print with the host cargo unless it is on PATH (or in cargo's bin dir).
    pub(crate) fn ensure_defmt_print(&mut self) -> Result {
        if on_path("defmt-print") {
            return Ok(());
        }
        let cargo_bin = cargo_home().map(|h| h.join("bin"));
        if cargo_bin.as_ref().is_some_and(|b| b.join("defmt-print").is_file()) {
            self.extra_path = cargo_bin;
            return Ok(());
        }
        self.run(self.host_cargo(["install", "defmt-print", "--locked"]))?;
        self.extra_path = cargo_bin;
        Ok(())
    }

    /// The host cargo: the toolchain `cargo xtask` itself runs with.
    pub(crate) fn host_cargo<I: IntoIterator<Item = S>, S: AsRef<OsStr>>(&self, args: I) -> Command {
        let mut c = self.command("cargo");
        for v in TOOLCHAIN_VARS.iter().filter(|v| **v != "RUSTUP_TOOLCHAIN") {
            c.env_remove(v);
        }
        c.args(args);
        c
    }

    /// cargo for the thumb target on the root package: `cargo <sub> --package bins-comp
    /// --target … --target-dir target/thumb`, plus
    /// `-Zbuild-std=core` and the lld linker under Debian's toolchain.
    pub(crate) fn thumb_cargo<I: IntoIterator<Item = S>, S: AsRef<OsStr>>(
        &self,
        sub: &str,
        args: I,
    ) -> Result<Command> {
        let tc = self.toolchain.ok_or("internal: toolchain step has not run")?;
        let mut c = match tc {
            Toolchain::Rustup => self.host_cargo([sub]),
            Toolchain::Debian { via_rustup } => {
                let mut c = if via_rustup { self.command("cargo") } else { self.command("/usr/bin/cargo") };
                for v in TOOLCHAIN_VARS {
                    c.env_remove(v);
                }
                if via_rustup {
                    c.arg("+debian");
                }
                c.arg(sub).arg("-Zbuild-std=core");
                // The soft-float and memory routines built from source with `core`: only the
                // load-time code calls the `f64` ones, so size over speed (−0.5 KiB of flash,
                // instruction counts per sample unchanged).
                c.args(["--config", "profile.release.package.compiler_builtins.opt-level=\"s\""]);
                c.env("RUSTC_BOOTSTRAP", "1");
                c.env("CARGO_TARGET_THUMBV7EM_NONE_EABIHF_LINKER", "ld.lld");
                c
            }
        };
        c.args(["--package", "bins-comp", "--target", THUMB, "--target-dir", THUMB_TARGET_DIR]);
        c.args(args);
        Ok(c)
    }

    pub(crate) fn elf(&self, bin: &str) -> PathBuf {
        self.root.join(THUMB_TARGET_DIR).join(THUMB).join("release").join(bin)
    }

    pub(crate) fn build_firmware(&mut self) -> Result {
        let args = ["--release", "--features", "firmware-log", "--bin", "firmware", "--bin", "replay"];
        let mut c = self.thumb_cargo("build", args)?;
        c.env("REPLAY_VE", DEFAULT_VE);
        self.run(c)
    }

    /// The replay firmware subtracting the VE of `ve` (`REPLAY_VE`; cargo rebuilds the image
    /// when it changes).
    pub(crate) fn build_replay(&self, ve: &str, sample_hz: u32) -> Result {
        let mut c = self.thumb_cargo("build", ["--release", "--features", "firmware-log", "--bin", "replay"])?;
        c.env("REPLAY_VE", ve).env("REPLAY_SAMPLE_HZ", sample_hz.to_string());
        self.run(c)
    }

    /// The release links of `linkcheck` and of the flight image fail iff a panic is reachable
    /// from their code.
    pub(crate) fn build_linkcheck(&mut self) -> Result {
        let args = ["--release", "--features", "firmware", "--bin", "linkcheck", "--bin", "flight"];
        let c = self.thumb_cargo("build", args)?;
        self.run(c).map_err(|e| {
            format!(
                "{e}\n       (`undefined symbol: a_panic_is_reachable` above means a panic is reachable in the core \
                 or the flight image)"
            )
        })
    }
}
