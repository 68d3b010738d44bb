//! `cargo xtask test`: every check CI runs, in order, stopping at the first failure: fmt,
//! clippy, rustdoc, host tests (with the core's doc examples), the thumb build and its checks,
//! the firmware and the flight image in QEMU, the replay against the host, a short fuzz pass.

use std::env;
use std::time::Instant;

use crate::process::{cmd, probe, read};
use crate::qemu::{DEFAULT_VE, REPLAY_SAMPLE_HZ};
use crate::task::{Result, StepFn, Xtask};

/// Test vectors the firmware replays (its path is fixed in the firmware).
pub(crate) const VECTORS_IN: &str = "target/fw-vectors/in.bin";

/// The calibration file whose blob the firmware finds in its CALIB region during the test.
pub(crate) const CALIBRATION: &str = "calibrations/paper-two-range.toml";

/// The same unit with thermal dynamics (blob section 0x0007), for the replay test.
pub(crate) const CALIBRATION_DYNAMICS: &str = "calibrations/paper-two-range-dynamics.toml";

/// That blob, and the same as Intel HEX at the CALIB origin (the address the loader uses).
pub(crate) const BLOB: &str = "target/fw-vectors/cal.bin";

pub(crate) const BLOB_HEX: &str = "target/fw-vectors/cal.hex";

/// Working directory of the second QEMU run, with a corrupted blob (its firmware paths
/// `target/fw-vectors/…` are relative to it).
pub(crate) const CORRUPT_DIR: &str = "target/fw-corrupt";

/// The corrupted blob: [`BLOB`] with one payload bit flipped.
pub(crate) const CORRUPT_BLOB: &str = "target/fw-corrupt/cal.bin";

/// The byte flipped in the corrupted blob (inside the constants section).
pub(crate) const CORRUPT_BYTE: usize = 0x90;

/// The replay test's recording: short, 1 kHz, temperature ramps and vibration.
pub(crate) const REPLAY_SCENARIO: &str = "scenarios/replay-short.toml";

/// Working directory of the replay test (the replay firmware's paths `target/fw-replay/…` are
/// relative to QEMU's working directory).
pub(crate) const REPLAY_DIR: &str = "target/replay-test";

/// Seconds of the fuzz pass in `cargo xtask test` (`XTASK_FUZZ_SECONDS` overrides).
pub(crate) const FUZZ_SECONDS: u32 = 30;

impl Xtask {
    pub(crate) fn test(&mut self) -> bool {
        let started = Instant::now();
        let steps: &[(&str, StepFn)] = &[
            ("fmt", |x| x.run(x.host_cargo(["fmt", "--all", "--check"]))),
            ("clippy (host)", |x| {
                x.run(x.host_cargo(["clippy", "--workspace", "--all-targets", "--", "-D", "warnings"]))
            }),
            ("doc (no broken links)", |x| {
                let mut c = x.host_cargo(["doc", "--workspace", "--no-deps"]);
                c.env("RUSTDOCFLAGS", "-D warnings");
                x.run(c)
            }),
            ("test (host)", |x| x.run(x.host_cargo(["test", "--workspace"]))),
            ("toolchain", Xtask::setup_toolchain),
            ("clippy (thumb)", |x| {
                x.run(
                    x.thumb_cargo("clippy", ["--features", "firmware-log", "--lib", "--bins", "--", "-D", "warnings"])?,
                )
            }),
            ("vectors", Xtask::gen_vectors),
            ("build firmware + link check", |x| {
                x.build_firmware()?;
                x.build_linkcheck()
            }),
            ("flight image in QEMU: boots, samples at 1 kHz, flags the missing sensors", Xtask::flight_test),
            ("qemu", |x| x.run_qemu_with_blob(&x.elf("firmware"), &x.root, &x.root.join(BLOB), &x.root.join(BLOB_HEX))),
            ("qemu (corrupted calibration blob)", |x| {
                let (elf, hex) = (x.elf("firmware"), x.root.join(BLOB_HEX));
                x.run_qemu_with_blob(&elf, &x.root.join(CORRUPT_DIR), &x.root.join(CORRUPT_BLOB), &hex)
            }),
            ("replay: QEMU vs host, bit for bit", Xtask::replay_test),
            ("fuzz (blob parser, short pass)", Xtask::fuzz_short),
        ];
        let mut failed = None;
        for (i, (name, f)) in steps.iter().enumerate() {
            if !self.step(i + 1, name, *f) {
                failed = Some(*name);
                break;
            }
        }
        self.summary(started);
        match failed {
            None => {
                println!("xtask test: {} passed, 0 failed", self.passed.len());
                true
            }
            Some(name) => {
                println!("xtask test: {} passed, 1 failed (step '{name}')", self.passed.len());
                false
            }
        }
    }

    /// A short libFuzzer pass over the blob parser (`fuzz/`), where a nightly toolchain is
    /// installed (cargo-fuzz needs it); otherwise the step says why it was skipped. The
    /// exhaustive bit-flip and truncation tests run in every case (host tests).
    pub(crate) fn fuzz_short(&mut self) -> Result {
        if !probe(&mut cmd("rustup", ["run", "nightly", "rustc", "--version"])) {
            println!("skipped: no nightly toolchain (rustup toolchain install nightly enables it)");
            return Ok(());
        }
        if !probe(&mut cmd("cargo", ["+nightly", "fuzz", "--version"])) {
            self.run(self.host_cargo(["install", "cargo-fuzz", "--locked"]))?;
        }
        // libFuzzer writes new inputs into the corpus directory (ignored by git) and refuses to
        // start without it; a fresh clone has only the checked-in seeds.
        let corpus = self.root.join("fuzz/corpus/blob_parse");
        std::fs::create_dir_all(&corpus).map_err(|e| format!("{}: {e}", corpus.display()))?;
        let secs = env::var("XTASK_FUZZ_SECONDS").unwrap_or_else(|_| FUZZ_SECONDS.to_string());
        let mut c = self.host_cargo([
            "+nightly",
            "fuzz",
            "run",
            "blob_parse",
            "fuzz/corpus/blob_parse",
            "fuzz/seeds/blob_parse",
        ]);
        c.args(["--", &format!("-max_total_time={secs}")]);
        c.env_remove("RUSTUP_TOOLCHAIN");
        self.run(c)
    }

    /// The calibration blobs and the vectors of both QEMU runs. The valid blob is the paper's
    /// calibration; the corrupted one differs in one bit, and `bins-cal` must reject it.
    /// gen-vectors parses each blob as the firmware does, so the flashed variant expects the
    /// calibrated output with the valid blob and the flagged uncalibrated output with the
    /// corrupted one.
    pub(crate) fn gen_vectors(&mut self) -> Result {
        let bins_cal = ["run", "--release", "-q", "-p", "bins-cal", "--", "blob"];
        // A fresh clone has no target/fw-vectors yet.
        if let Some(dir) = self.root.join(BLOB).parent() {
            std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        }
        let mut c = self.host_cargo(bins_cal);
        c.args(["encode", CALIBRATION, "-o", BLOB, "--ihex", BLOB_HEX]);
        self.run(c)?;
        let mut bad = std::fs::read(self.root.join(BLOB)).map_err(|e| format!("{BLOB}: {e}"))?;
        *bad.get_mut(CORRUPT_BYTE).ok_or(format!("{BLOB}: shorter than {CORRUPT_BYTE} bytes"))? ^= 0x10;
        let corrupt_vectors = self.root.join(CORRUPT_DIR).join(VECTORS_IN);
        if let Some(dir) = corrupt_vectors.parent() {
            std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        }
        std::fs::write(self.root.join(CORRUPT_BLOB), &bad).map_err(|e| format!("{CORRUPT_BLOB}: {e}"))?;
        let mut c = self.host_cargo(bins_cal);
        c.args(["check", CORRUPT_BLOB]);
        if self.run(c).is_ok() {
            return Err(format!("bins-cal accepted the corrupted blob {CORRUPT_BLOB}"));
        }
        println!("(the error above is expected: the corrupted blob must be rejected)");
        let gen_vectors = ["run", "--release", "-p", "host-tests", "--bin", "gen-vectors", "--", "--blob"];
        let mut c = self.host_cargo(gen_vectors);
        c.args([BLOB, VECTORS_IN]);
        self.run(c)?;
        let mut c = self.host_cargo(gen_vectors);
        c.arg(CORRUPT_BLOB).arg(&corrupt_vectors);
        self.run(c)
    }

    /// The short recording ([`REPLAY_SCENARIO`]) through the replay firmware in QEMU and
    /// through `bins-cal replay` on the host, with the paper's calibration (method 2,
    /// simplified, piecewise-linear) and the same with method 1, both with the online VE,
    /// method 2 with flight-phase profile 0's, and the same unit with thermal dynamics
    /// ([`CALIBRATION_DYNAMICS`], methods 2 and 1, online VE): the CSVs must be identical, and
    /// the dynamics must change the output.
    pub(crate) fn replay_test(&mut self) -> Result {
        self.run(self.host_cargo(["build", "--release", "-q", "-p", "bins-cal"]))?;
        let dir = self.root.join(REPLAY_DIR);
        std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        let rec = dir.join("rec.csv");
        let mut c = self.bins_cal();
        c.args(["simulate", REPLAY_SCENARIO, "--seed", "1", "-o"]).arg(&rec);
        self.run(c)?;
        let toml = std::fs::read_to_string(self.root.join(CALIBRATION)).map_err(|e| format!("{CALIBRATION}: {e}"))?;
        let m2 = "kind = \"output-correction\"\nform = \"simplified\"";
        if !toml.contains(m2) {
            return Err(format!("{CALIBRATION}: no `{m2}` method to swap for method 1"));
        }
        let m1_toml = dir.join("method1.toml");
        std::fs::write(&m1_toml, toml.replace(m2, "kind = \"coefficient-correction\""))
            .map_err(|e| format!("{}: {e}", m1_toml.display()))?;
        let m1_blob = dir.join("method1.bin");
        let mut c = self.bins_cal();
        c.args(["blob", "encode"]).arg(&m1_toml).arg("-o").arg(&m1_blob);
        self.run(c)?;
        // The unit with thermal dynamics, methods 2 and 1.
        let dyn_toml = std::fs::read_to_string(self.root.join(CALIBRATION_DYNAMICS))
            .map_err(|e| format!("{CALIBRATION_DYNAMICS}: {e}"))?;
        let dyn_m1_toml = dir.join("dynamics-method1.toml");
        std::fs::write(&dyn_m1_toml, dyn_toml.replace(m2, "kind = \"coefficient-correction\""))
            .map_err(|e| format!("{}: {e}", dyn_m1_toml.display()))?;
        let (dyn_blob, dyn_m1_blob) = (dir.join("dynamics.bin"), dir.join("dynamics-method1.bin"));
        for (toml, out) in [(&self.root.join(CALIBRATION_DYNAMICS), &dyn_blob), (&dyn_m1_toml, &dyn_m1_blob)] {
            let mut c = self.bins_cal();
            c.args(["blob", "encode"]).arg(toml).arg("-o").arg(out);
            self.run(c)?;
        }
        let blob = self.root.join(BLOB);
        for (name, blob, ve) in [
            ("method2", &blob, DEFAULT_VE),
            ("method1", &m1_blob, DEFAULT_VE),
            ("method2-profile0", &blob, "profile:0"),
            ("method2-dynamics", &dyn_blob, DEFAULT_VE),
            ("method1-dynamics", &dyn_m1_blob, DEFAULT_VE),
        ] {
            let (fw, host) = (dir.join(format!("{name}-qemu.csv")), dir.join(format!("{name}-host.csv")));
            self.replay_firmware(&rec, blob, &self.root.join(BLOB_HEX), &fw, &dir, ve, REPLAY_SAMPLE_HZ)?;
            self.replay_host_identical(name, &rec, blob, &fw, &host, ve, REPLAY_SAMPLE_HZ)?;
        }
        // The source reached the firmware: profile 0's VE is not the online estimate.
        if read(&dir.join("method2-qemu.csv"))? == read(&dir.join("method2-profile0-qemu.csv"))? {
            return Err("replay: the firmware's output with profile 0's VE equals the online VE's".into());
        }
        // The thermal dynamics reached the firmware: its output differs from the same unit's
        // without them.
        if read(&dir.join("method2-qemu.csv"))? == read(&dir.join("method2-dynamics-qemu.csv"))? {
            return Err("replay: the firmware's output with thermal dynamics equals the output without".into());
        }
        Ok(())
    }
}
