//! Project tasks: `cargo xtask test` (everything CI checks) and `cargo xtask demo`.
//!
//! The Cortex-M4F binaries are built with rustup's toolchain when it has the
//! `thumbv7em-none-eabihf` target installed. Otherwise Debian's Rust (`rustc-web`, linked into
//! rustup as the `debian` toolchain) builds them with `-Zbuild-std=core`; the packages it needs
//! are installed with apt when missing. Firmware builds use their own target directory
//! (`target/thumb`), so host and target builds never invalidate each other.

use std::env;
use std::ffi::{OsStr, OsString};
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode, Stdio};
use std::time::{Duration, Instant};

const THUMB: &str = "thumbv7em-none-eabihf";
/// Target directory of the firmware builds, relative to the repository root.
const THUMB_TARGET_DIR: &str = "target/thumb";
/// Test vectors the firmware replays (its path is fixed in the firmware).
const VECTORS_IN: &str = "target/fw-vectors/in.bin";
/// The calibration file whose blob the firmware finds in its CALIB region during the test.
const CALIBRATION: &str = "calibrations/paper-two-range.toml";
/// The same unit with thermal dynamics (blob section 0x0007), for the replay test.
const CALIBRATION_DYNAMICS: &str = "calibrations/paper-two-range-dynamics.toml";
/// That blob, and the same as Intel HEX at the CALIB origin (the address the loader uses).
const BLOB: &str = "target/fw-vectors/cal.bin";
const BLOB_HEX: &str = "target/fw-vectors/cal.hex";
/// Working directory of the second QEMU run, with a corrupted blob (its firmware paths
/// `target/fw-vectors/…` are relative to it).
const CORRUPT_DIR: &str = "target/fw-corrupt";
/// The corrupted blob: [`BLOB`] with one payload bit flipped.
const CORRUPT_BLOB: &str = "target/fw-corrupt/cal.bin";
/// The byte flipped in the corrupted blob (inside the constants section).
const CORRUPT_BYTE: usize = 0x90;
/// The replay test's recording: short, 1 kHz, temperature ramps and vibration.
const REPLAY_SCENARIO: &str = "scenarios/replay-short.toml";
/// Working directory of the replay test (the replay firmware's paths `target/fw-replay/…` are
/// relative to QEMU's working directory).
const REPLAY_DIR: &str = "target/replay-test";
/// Where the flight image's UART output is captured in QEMU, relative to the repository root.
const FLIGHT_CAPTURE: &str = "target/fw-flight/uart.bin";
/// How long the flight image runs in QEMU (wall time; it never exits by itself).
const FLIGHT_RUN: Duration = Duration::from_millis(2500);
/// Frames the capture must hold at least: 3 s of sampling at 1 kHz (3 health frames). A
/// 2.5 s run gave about 19 000 frames on a 2-core machine (`-icount shift=0,sleep=off` runs
/// the mostly idle image faster than real time).
const FLIGHT_MIN_FRAMES: usize = 3000;
/// Bytes of one flight output frame (`bins_comp::frame::FRAME_BYTES`).
const FLIGHT_FRAME_BYTES: f64 = 24.0;
/// QEMU runner (also cargo's `runner` for the thumb target).
const RUNNER: &str = "tools/qemu-run.sh";
/// Debian packages of the fallback toolchain and of the QEMU run.
const DEBIAN_PACKAGES: [&str; 7] =
    ["rustc-web", "cargo-web", "rust-web-src", "rust-web-clippy", "rustfmt-web", "lld", "qemu-system-arm"];
/// Variables a parent cargo/rustup sets that must not leak into a child of another toolchain.
const TOOLCHAIN_VARS: [&str; 6] =
    ["RUSTUP_TOOLCHAIN", "RUSTC", "RUSTDOC", "CARGO", "RUSTC_WORKSPACE_WRAPPER", "CLIPPY_ARGS"];
/// The sampling rate \[Hz\] the replay firmware's pipeline is configured for (its
/// `REPLAY_SAMPLE_HZ`; SysTick stays at 1 kHz), unless a recording needs its own.
const REPLAY_SAMPLE_HZ: u32 = 1000;
/// Default limit on one QEMU run; override with `XTASK_QEMU_TIMEOUT` (seconds).
const QEMU_TIMEOUT_S: u64 = 300;

type Result<T = ()> = std::result::Result<T, String>;
/// A step of a task.
type StepFn = fn(&mut Xtask) -> Result;

fn main() -> ExitCode {
    let args: Vec<String> = env::args().skip(1).collect();
    let mut x = Xtask::new();
    let ok = match args.first().map(String::as_str) {
        Some("test") => x.test(),
        Some("demo") => x.demo(),
        Some("replay") => x.replay(args.get(1..).unwrap_or(&[])),
        Some("bench") => x.bench(),
        _ => {
            eprintln!("usage: cargo xtask <test|demo|replay|bench>");
            eprintln!(
                "  bench  instructions per sample in QEMU, stack depth, flash/RAM of the firmware images, host samples per second"
            );
            eprintln!(
                "  test   fmt, clippy, doc, host tests, thumb clippy, vectors, firmware build + link check, flight image and firmware in QEMU"
            );
            eprintln!(
                "  demo   simulate, calibrate, replay in QEMU, verify: the paper's check end to end (target/demo)"
            );
            eprintln!("  replay REC.csv --calib CAL.bin -o OUT.csv   a recording through the replay firmware in QEMU");
            return ExitCode::from(2);
        }
    };
    if ok { ExitCode::SUCCESS } else { ExitCode::FAILURE }
}

/// How the thumb binaries are built.
#[derive(Clone, Copy, Debug)]
enum Toolchain {
    /// rustup's active toolchain, which has the thumbv7em target.
    Rustup,
    /// Debian's Rust with `-Zbuild-std=core`: `cargo +debian` through rustup, or
    /// `/usr/bin/cargo` without rustup.
    Debian { via_rustup: bool },
}

struct Xtask {
    root: PathBuf,
    toolchain: Option<Toolchain>,
    /// Prepended to PATH for children (where `cargo install` put defmt-print).
    extra_path: Option<PathBuf>,
    passed: Vec<(String, Duration)>,
}

impl Xtask {
    fn new() -> Self {
        let manifest_dir = Path::new(env!("CARGO_MANIFEST_DIR"));
        let root = manifest_dir.parent().unwrap_or(manifest_dir).to_path_buf();
        Xtask { root, toolchain: None, extra_path: None, passed: Vec::new() }
    }

    // ---- tasks -------------------------------------------------------------------------

    fn test(&mut self) -> bool {
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
    fn fuzz_short(&mut self) -> Result {
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

    fn demo(&mut self) -> bool {
        let started = Instant::now();
        let mut ok = self.step(1, "toolchain", Xtask::setup_toolchain);
        for (i, (name, f)) in DEMO_STEPS.iter().enumerate() {
            ok = ok && self.step(i + 2, name, *f);
        }
        self.summary(started);
        ok
    }

    // ---- steps -------------------------------------------------------------------------

    /// Runs one step with a header and its wall time; false if it failed.
    fn step(&mut self, n: usize, name: &str, f: StepFn) -> bool {
        println!("\n==> [{n}] {name}");
        let t = Instant::now();
        let r = f(self);
        let dt = t.elapsed();
        match r {
            Ok(()) => {
                println!("<== [{n}] {name}: ok ({:.1} s)", dt.as_secs_f64());
                self.passed.push((name.to_string(), dt));
                true
            }
            Err(e) => {
                eprintln!("<== [{n}] {name}: FAILED after {:.1} s\nerror: step '{name}' failed: {e}", dt.as_secs_f64());
                false
            }
        }
    }

    fn summary(&self, started: Instant) {
        println!("\nstep times:");
        for (name, dt) in &self.passed {
            println!("  {:>7.1} s  {name}", dt.as_secs_f64());
        }
        println!("  {:>7.1} s  total", started.elapsed().as_secs_f64());
    }

    /// Picks the thumb toolchain and installs what it and the QEMU run need.
    fn setup_toolchain(&mut self) -> Result {
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
    fn ensure_defmt_print(&mut self) -> Result {
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

    /// The calibration blobs and the vectors of both QEMU runs. The valid blob is the paper's
    /// calibration; the corrupted one differs in one bit, and `bins-cal` must reject it.
    /// gen-vectors parses each blob as the firmware does, so the flashed variant expects the
    /// calibrated output with the valid blob and the flagged uncalibrated output with the
    /// corrupted one.
    fn gen_vectors(&mut self) -> Result {
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

    fn build_firmware(&mut self) -> Result {
        let args = ["--release", "--features", "firmware-log", "--bin", "firmware", "--bin", "replay"];
        let mut c = self.thumb_cargo("build", args)?;
        c.env("REPLAY_VE", DEFAULT_VE);
        self.run(c)
    }

    /// The replay firmware subtracting the VE of `ve` (`REPLAY_VE`; cargo rebuilds the image
    /// when it changes).
    fn build_replay(&self, ve: &str, sample_hz: u32) -> Result {
        let mut c = self.thumb_cargo("build", ["--release", "--features", "firmware-log", "--bin", "replay"])?;
        c.env("REPLAY_VE", ve).env("REPLAY_SAMPLE_HZ", sample_hz.to_string());
        self.run(c)
    }

    /// `cargo xtask replay REC.csv --calib CAL.bin -o OUT.csv [--ve SOURCE]`: the recording
    /// through the replay firmware in QEMU (SysTick at 1 kHz, or `REPLAY_TICK_HZ` at build
    /// time) with the VE of SOURCE subtracted (`online`, the default, `none` or `profile:N`, as
    /// `bins-cal replay --ve`), results as CSV.
    fn replay(&mut self, args: &[String]) -> bool {
        let (mut rec, mut calib, mut out, mut ve) = (None, None, None, Some(DEFAULT_VE.to_string()));
        let mut it = args.iter();
        while let Some(a) = it.next() {
            match a.as_str() {
                "--calib" => calib = it.next().cloned(),
                "-o" | "--output" => out = it.next().cloned(),
                "--ve" => ve = it.next().cloned(),
                _ if rec.is_none() => rec = Some(a.clone()),
                _ => rec = None,
            }
        }
        let (Some(rec), Some(calib), Some(out), Some(ve)) = (rec, calib, out, ve) else {
            eprintln!("usage: cargo xtask replay REC.csv --calib CAL.bin -o OUT.csv [--ve online|none|profile:N]");
            return false;
        };
        let cwd = env::current_dir().unwrap_or_default();
        let (rec, calib, out) = (cwd.join(rec), cwd.join(calib), cwd.join(out));
        let started = Instant::now();
        let ok = self.step(1, "toolchain", Xtask::setup_toolchain)
            && self.step(2, "build", |x| {
                x.run(x.host_cargo(["build", "--release", "-q", "-p", "bins-cal"]))?;
                x.build_firmware()
            })
            && {
                let t = Instant::now();
                let work = self.root.join("target/replay");
                match self
                    .calib_hex(&work)
                    .and_then(|hex| self.replay_firmware(&rec, &calib, &hex, &out, &work, &ve, REPLAY_SAMPLE_HZ))
                {
                    Ok(()) => {
                        println!("replay: {} in {:.1} s wall", out.display(), t.elapsed().as_secs_f64());
                        true
                    }
                    Err(e) => {
                        eprintln!("error: {e}");
                        false
                    }
                }
            };
        self.summary(started);
        ok
    }

    /// An Intel HEX file in `work` whose address is the CALIB origin (the sample calibration,
    /// encoded by `bins-cal`, which places it at the ORIGIN of CALIB in `memory.x`): where
    /// QEMU's loader puts any blob.
    fn calib_hex(&self, work: &Path) -> Result<PathBuf> {
        std::fs::create_dir_all(work).map_err(|e| format!("{}: {e}", work.display()))?;
        let hex = work.join("calib-origin.hex");
        let mut c = self.bins_cal();
        c.args(["blob", "encode", CALIBRATION, "-o"]).arg(work.join("calib-origin.bin")).arg("--ihex").arg(&hex);
        self.run(c)?;
        Ok(hex)
    }

    /// `cargo xtask bench`: instructions per sample of each method/model case, the worst
    /// single step and the step's stack high-water mark (the `bench` firmware in QEMU,
    /// `-icount shift=0`), flash and static RAM of the replay firmware, the link-check image
    /// and the flight image (`llvm-size`), the host's samples per second (criterion), and the
    /// diagnosis's wall time on 30 000- and 260 000-row pairs against its budgets.
    fn bench(&mut self) -> bool {
        let started = Instant::now();
        let ok = self.step(1, "toolchain", Xtask::setup_toolchain)
            && self.step(2, "build", |x| {
                x.build_firmware()?;
                let args = ["--release", "--features", "firmware-log", "--bin", "bench"];
                x.run(x.thumb_cargo("build", args)?)
            })
            && self.step(3, "instructions per sample (QEMU)", |x| x.run_qemu_in(&x.elf("bench"), &x.root))
            && self.step(4, "size of the replay firmware, the link-check image and the flight image", |x| {
                x.build_linkcheck()?;
                let mut c = x.command("llvm-size");
                c.arg(x.elf("replay")).arg(x.elf("linkcheck")).arg(x.elf("flight"));
                x.run(c)?;
                let mut c = x.command("llvm-size");
                c.arg("-A").arg(x.elf("flight"));
                println!("$ {}", show(&c));
                let sections = output(&mut c)?;
                print!("{sections}");
                let (flash, ram) = flash_and_ram(&sections)?;
                let verdict = |used: u64, budget: u64| if used <= budget { "met" } else { "MISSED" };
                println!("flight image: flash {flash} B of {FLASH_BUDGET} ({})", verdict(flash, FLASH_BUDGET));
                println!("flight image: static RAM {ram} B of {RAM_BUDGET} ({})", verdict(ram, RAM_BUDGET));
                if flash > FLASH_BUDGET || ram > RAM_BUDGET {
                    return Err("the flight image is over its flash or RAM budget".into());
                }
                Ok(())
            })
            && self.step(5, "host samples per second (criterion)", |x| {
                x.run(x.host_cargo(["bench", "-p", "host-tests", "--bench", "throughput"]))
            })
            && self.step(6, "bins-cal diagnose: 30 000 rows < 2 s, 260 000 rows < 10 s (release, one thread)", |x| {
                x.run(x.host_cargo(["run", "--release", "-q", "-p", "bins-cal", "--example", "diagnose_speed"]))
            });
        self.summary(started);
        ok
    }

    /// The release `bins-cal` binary (built by the step that calls this).
    fn bins_cal(&self) -> Command {
        self.command(self.root.join("target/release/bins-cal"))
    }

    /// A recording through the replay firmware in QEMU, in `work`: the recording as the input
    /// stream, the blob in CALIB (at the address of the Intel HEX file `hex`), the VE of `ve`
    /// subtracted, the output stream back to CSV (`t_s` from the recording).
    #[allow(clippy::too_many_arguments)]
    fn replay_firmware(
        &self,
        rec: &Path,
        calib: &Path,
        hex: &Path,
        out: &Path,
        work: &Path,
        ve: &str,
        sample_hz: u32,
    ) -> Result {
        let stream_dir = work.join("target/fw-replay");
        std::fs::create_dir_all(&stream_dir).map_err(|e| format!("{}: {e}", stream_dir.display()))?;
        // `bins-cal` checks the source's name before the firmware is built with it.
        let mut c = self.bins_cal();
        c.arg("replay").arg("--rec").arg(rec).arg("--ve").arg(ve).arg("--write-stream").arg(stream_dir.join("in.bin"));
        self.run(c)?;
        self.build_replay(ve, sample_hz)?;
        self.run_qemu_with_blob(&self.elf("replay"), work, calib, hex)?;
        let mut c = self.bins_cal();
        c.arg("replay").arg("--rec").arg(rec).arg("--read-stream").arg(stream_dir.join("out.bin")).arg("-o").arg(out);
        self.run(c)
    }

    /// The short recording ([`REPLAY_SCENARIO`]) through the replay firmware in QEMU and
    /// through `bins-cal replay` on the host, with the paper's calibration (method 2,
    /// simplified, piecewise-linear) and the same with method 1, both with the online VE,
    /// method 2 with flight-phase profile 0's, and the same unit with thermal dynamics
    /// ([`CALIBRATION_DYNAMICS`], methods 2 and 1, online VE): the CSVs must be identical, and
    /// the dynamics must change the output.
    fn replay_test(&mut self) -> Result {
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

    /// `bins-cal replay` of `rec` with `blob` on the host into `host`, which must equal the
    /// firmware's output `fw` byte for byte.
    #[allow(clippy::too_many_arguments)]
    fn replay_host_identical(
        &self,
        name: &str,
        rec: &Path,
        blob: &Path,
        fw: &Path,
        host: &Path,
        ve: &str,
        sample_hz: u32,
    ) -> Result {
        let mut c = self.bins_cal();
        c.arg("replay").arg("--rec").arg(rec).arg("--calib").arg(blob).arg("--ve").arg(ve);
        c.arg("--tick-hz").arg(sample_hz.to_string()).arg("-o").arg(host);
        self.run(c)?;
        let (a, b) = (read(fw)?, read(host)?);
        let rows = a.iter().filter(|&&c| c == b'\n').count().saturating_sub(1);
        if a != b {
            let line = a.split(|&c| c == b'\n').zip(b.split(|&c| c == b'\n')).position(|(x, y)| x != y);
            return Err(format!(
                "{name}: {} and {} differ (first at line {})",
                fw.display(),
                host.display(),
                line.map_or(0, |l| l + 1)
            ));
        }
        println!("replay {name}: QEMU and host bit-identical, {rows} rows");
        Ok(())
    }

    /// The release links of `linkcheck` and of the flight image fail iff a panic is reachable
    /// from their code.
    fn build_linkcheck(&mut self) -> Result {
        let args = ["--release", "--features", "firmware", "--bin", "linkcheck", "--bin", "flight"];
        let c = self.thumb_cargo("build", args)?;
        self.run(c).map_err(|e| {
            format!(
                "{e}\n       (`undefined symbol: a_panic_is_reachable` above means a panic is reachable in the core \
                 or the flight image)"
            )
        })
    }

    /// The flight image in QEMU for [`FLIGHT_RUN`] with the paper blob in CALIB and UART0
    /// captured to [`FLIGHT_CAPTURE`], then stopped (it runs forever); `flight-check` decodes
    /// the capture with the library's frame decoder. No sensor is attached in QEMU, so the
    /// image must boot with the blob accepted, send at least [`FLIGHT_MIN_FRAMES`] frames with
    /// consecutive sequence numbers, flag every sample `SENSOR_FAULT` and count the faults.
    fn flight_test(&mut self) -> Result {
        let capture = self.root.join(FLIGHT_CAPTURE);
        if let Some(dir) = capture.parent() {
            std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        }
        if capture.exists() {
            std::fs::remove_file(&capture).map_err(|e| format!("{}: {e}", capture.display()))?;
        }
        let mut c = self.command(self.root.join(RUNNER));
        c.env("QEMU_EXTRA", self.loader_arg(&self.root.join(BLOB), &self.root.join(BLOB_HEX))?);
        c.env("QEMU_SERIAL", format!("file:{}", capture.display()));
        c.arg(self.elf("flight")).stdin(Stdio::null());
        run_for(c, FLIGHT_RUN)?;
        let bytes = std::fs::metadata(&capture).map_err(|e| format!("{}: {e}", capture.display()))?.len();
        println!(
            "flight image: {bytes} bytes on UART0 in {:.1} s wall ({:.0} frames/s)",
            FLIGHT_RUN.as_secs_f64(),
            bytes as f64 / FLIGHT_FRAME_BYTES / FLIGHT_RUN.as_secs_f64()
        );
        let mut c = self.host_cargo(["run", "--release", "-q", "-p", "host-tests", "--bin", "flight-check", "--"]);
        c.arg(&capture).args(["--min-frames", &FLIGHT_MIN_FRAMES.to_string()]);
        self.run(c)
    }

    /// Runs an ELF in QEMU with `cwd` as its working directory and `blob` in the CALIB
    /// region, placed by QEMU's generic loader at the address of the CALIB origin (taken from
    /// the Intel HEX file `hex`, which `bins-cal` writes at the ORIGIN of CALIB in `memory.x`).
    fn run_qemu_with_blob(&self, elf: &Path, cwd: &Path, blob: &Path, hex: &Path) -> Result {
        let limit = env::var("XTASK_QEMU_TIMEOUT").ok().and_then(|s| s.parse().ok()).unwrap_or(QEMU_TIMEOUT_S);
        let mut c = self.command(self.root.join(RUNNER));
        c.env("QEMU_EXTRA", self.loader_arg(blob, hex)?);
        c.arg(elf).current_dir(cwd).stdin(Stdio::null());
        run_with_timeout(c, Duration::from_secs(limit))
    }

    /// QEMU's option that places `blob` at the CALIB origin: the address of the Intel HEX file
    /// `hex`, which `bins-cal` writes at the ORIGIN of CALIB in `memory.x`.
    fn loader_arg(&self, blob: &Path, hex: &Path) -> Result<String> {
        let text = std::fs::read_to_string(hex).map_err(|e| format!("{}: {e}", hex.display()))?;
        let addr = ihex_start(&text).ok_or(format!("{}: no extended-address and data record", hex.display()))?;
        Ok(format!("-device loader,file={},addr=0x{addr:08x}", blob.display()))
    }

    /// Runs an ELF in QEMU with `cwd` as its working directory: the firmware's semihosting
    /// paths (`target/fw-vectors/…`) are relative to it.
    fn run_qemu_in(&self, elf: &Path, cwd: &Path) -> Result {
        let limit = env::var("XTASK_QEMU_TIMEOUT").ok().and_then(|s| s.parse().ok()).unwrap_or(QEMU_TIMEOUT_S);
        let mut c = self.command(self.root.join(RUNNER));
        c.arg(elf).current_dir(cwd).stdin(Stdio::null());
        run_with_timeout(c, Duration::from_secs(limit))
    }

    // ---- commands ----------------------------------------------------------------------

    /// A command run from the repository root, with the extra PATH entry.
    fn command(&self, program: impl AsRef<OsStr>) -> Command {
        let mut c = Command::new(program);
        c.current_dir(&self.root);
        if let Some(p) = &self.extra_path {
            let mut paths = vec![p.clone()];
            paths.extend(env::split_paths(&env::var_os("PATH").unwrap_or_default()));
            if let Ok(joined) = env::join_paths(paths) {
                c.env("PATH", joined);
            }
        }
        c
    }

    /// The host cargo: the toolchain `cargo xtask` itself runs with.
    fn host_cargo<I: IntoIterator<Item = S>, S: AsRef<OsStr>>(&self, args: I) -> Command {
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
    fn thumb_cargo<I: IntoIterator<Item = S>, S: AsRef<OsStr>>(&self, sub: &str, args: I) -> Result<Command> {
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

    fn elf(&self, bin: &str) -> PathBuf {
        self.root.join(THUMB_TARGET_DIR).join(THUMB).join("release").join(bin)
    }

    /// Echoes and runs a command; an error names it and its exit status.
    fn run(&self, mut c: Command) -> Result {
        println!("$ {}", show(&c));
        let status = c.status().map_err(|e| format!("cannot start `{}`: {e}", show(&c)))?;
        if status.success() { Ok(()) } else { Err(format!("`{}` exited with {status}", show(&c))) }
    }
}

/// Flash budget of the flight image \[B\]: 32 KiB.
const FLASH_BUDGET: u64 = 32 * 1024;
/// Static RAM budget of the flight image \[B\]: 8 KiB.
const RAM_BUDGET: u64 = 8 * 1024;

/// Flash (what is loaded: vector table, code, constants, initial values of `.data`) and
/// static RAM (`.data`, `.bss`, `.uninit`) of an image, from `llvm-size -A`.
fn flash_and_ram(sections: &str) -> Result<(u64, u64)> {
    let (mut flash, mut ram, mut seen) = (0, 0, 0);
    for line in sections.lines() {
        let mut cols = line.split_whitespace();
        let (Some(name), Some(size)) = (cols.next(), cols.next()) else { continue };
        let Ok(size) = size.parse::<u64>() else { continue };
        match name {
            ".vector_table" | ".text" | ".rodata" => flash += size,
            ".data" => (flash, ram) = (flash + size, ram + size),
            ".bss" | ".uninit" => ram += size,
            _ => continue,
        }
        seen += 1;
    }
    if seen < 4 {
        return Err(format!(
            "llvm-size -A: expected .vector_table, .text, .rodata, .data and .bss, found {seen} of them"
        ));
    }
    Ok((flash, ram))
}

/// The VE source of a replay unless another is chosen (`REPLAY_VE`, `bins-cal replay --ve`):
/// the online moment window, as in flight.
const DEFAULT_VE: &str = "online";

/// Seconds of the fuzz pass in `cargo xtask test` (`XTASK_FUZZ_SECONDS` overrides).
const FUZZ_SECONDS: u32 = 30;

// ---- the demo ---------------------------------------------------------------------------

/// Output directory of the demo, relative to the repository root; also the replay firmware's
/// and the vector firmware's working directory in QEMU.
const DEMO_DIR: &str = "target/demo";
/// The demo's tilter campaign (calibration and checks) and shaker campaign (same unit).
const DEMO_TILTER: &str = "scenarios/paper-tilter.toml";
const DEMO_SHAKER: &str = "scenarios/paper-unit-shaker.toml";
/// The method of the blob the replay firmware runs (the poly:2 calibration), as `verify`
/// labels it: the host's number the firmware's is compared with.
const DEMO_BLOB_METHOD: &str = "method 1";
/// The VE source of the demo's replay: none. The tilter recording has no vibration, and at its
/// 10 Hz logging rate a 64-sample online block spans 6.4 s, in which a move of the tilter would
/// read as vibration.
const DEMO_VE: &str = "none";

/// A file in the demo directory, as a string argument.
fn demo_path(x: &Xtask, name: &str) -> String {
    x.root.join(DEMO_DIR).join(name).to_string_lossy().into_owned()
}

/// `bins-cal` (release, built by the first call) with these arguments.
fn demo_bins_cal(x: &Xtask, args: &[&str]) -> Command {
    let mut c = x.host_cargo(["run", "--release", "-q", "-p", "bins-cal", "--"]);
    c.args(args);
    c
}

/// The demo's steps after the toolchain: the whole pipeline on the paper's twin. Simulate the
/// temperature paper's tilter campaign and the shake-table plan on the same unit, calibrate
/// with the paper's two-range model and with a quadratic one (with the vibration error, into
/// the blob), replay the tilter recording through the replay firmware in QEMU with that blob
/// (bit for bit against the host), verify both calibrations in the check positions (−10, +20,
/// +45 °C), the firmware's output beside the host's, run the firmware on its test vectors and
/// print the summary; everything in `target/demo/`.
const DEMO_STEPS: [(&str, StepFn); 8] = [
    ("simulate: tilter and shaker campaigns", demo_simulate),
    ("calibrate: two-range (method 2); poly:2 (method 1) + shaker, blob", demo_calibrate),
    ("build firmware", |x| x.build_firmware()),
    ("replay the tilter recording in QEMU, bit for bit against the host", demo_replay),
    ("verify in the check positions (host; firmware's output)", demo_verify),
    ("firmware test vectors in QEMU", demo_vectors),
    ("summary", |x| demo_summary(&x.root.join(DEMO_DIR))),
    (
        "thermal dynamics: die lag and bias play, calibrated from the tilter alone, checked in ramps and holds; replayed in QEMU",
        demo_dynamics,
    ),
];

/// The thermal-dynamics scenario: the paper's unit whose die lags its case and whose bias has
/// a heating/cooling play, tilter and checks during ramps and soaks.
const DEMO_DYNAMICS: &str = "scenarios/dynamics-tilter.toml";
/// Its logging rate \[Hz\]: the replay firmware's pipeline is configured for it, so the dynamics
/// stage advances the recording's own time step (at the default 1 kHz a row would count as
/// 1 ms, and a 180 s lag as 50 h of the recording).
const DEMO_DYNAMICS_SAMPLE_HZ: u32 = 1;
/// Its truth: die lag \[s\], play [°C], bias play width [°C] (`scenarios/dynamics-tilter.toml`).
const DEMO_DYNAMICS_TRUTH: [(&str, f64); 3] =
    [("lag_tau_s", 180.0), ("hysteresis_width_C", 1.0), ("bias_play_width_C", 4.0)];

/// Simulates the dynamics scenario, calibrates it twice from the recording alone (poly:2 from
/// the soaks; poly:2 with the dynamics identified from every dwell), verifies both in the
/// holds and during the ramps, and prints max |Δg| per phase with and without the dynamics
/// stage and the identified parameters against the scenario's truth. Fails unless the stage
/// cuts the ramps' max |Δg| by 3× or more and τ, h are within 20 % of the truth.
fn demo_dynamics(x: &mut Xtask) -> Result {
    let scenario = x.root.join(DEMO_DYNAMICS).to_string_lossy().into_owned();
    let rec = demo_path(x, "dynamics-tilter.csv");
    x.run(demo_bins_cal(x, &["simulate", &scenario, "-o", &rec, "--seed", "1"]))?;
    let (stat, dynm) = (demo_path(x, "cal-dyn-static.toml"), demo_path(x, "cal-dyn.toml"));
    x.run(demo_bins_cal(x, &["calibrate", "--tilter", &rec, "--model", "poly:2", "-o", &stat]))?;
    x.run(demo_bins_cal(
        x,
        &[
            "calibrate",
            "--tilter",
            &rec,
            "--model",
            "poly:2",
            "--dynamics",
            "identify",
            "-o",
            &dynm,
            "--blob",
            &demo_path(x, "cal-dyn.bin"),
            "--ihex",
            &demo_path(x, "cal-dyn.hex"),
        ],
    ))?;
    // The firmware with the identified dynamics in its blob replays the recording in QEMU; its
    // output must be the host's f32 pipeline bit for bit, and its |g| error is read in the same
    // check dwells as the host's (`verify --replayed`).
    let dir = x.root.join(DEMO_DIR);
    let (blob, hex) = (dir.join("cal-dyn.bin"), dir.join("cal-dyn.hex"));
    let (fw, host) = (dir.join("replay-dyn-qemu.csv"), dir.join("replay-dyn-host.csv"));
    let t = Instant::now();
    x.replay_firmware(Path::new(&rec), &blob, &hex, &fw, &dir, DEMO_VE, DEMO_DYNAMICS_SAMPLE_HZ)?;
    println!("replay firmware with dynamics: {} in {:.1} s wall", fw.display(), t.elapsed().as_secs_f64());
    x.replay_host_identical("dynamics-tilter", Path::new(&rec), &blob, &fw, &host, DEMO_VE, DEMO_DYNAMICS_SAMPLE_HZ)?;
    let fw_arg = fw.to_string_lossy().into_owned();
    for (cal, out, replayed) in [(&stat, "verify-dyn-static", None), (&dynm, "verify-dyn", Some(fw_arg.as_str()))] {
        let mut args = vec!["verify", "--check", &rec, "--calib", cal, "--ramps"];
        if let Some(r) = replayed {
            args.extend(["--replayed", r]);
        }
        let out = demo_path(x, out);
        args.extend(["-o", &out]);
        x.run(demo_bins_cal(x, &args))?;
    }
    // max |Δg| per phase: (phase, method) → max.
    let max_of = |sub: &str, method: &str| -> Result<Vec<(String, f64)>> {
        let path = dir.join(sub).join("verify.csv");
        let text = std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
        let mut out: Vec<(String, f64)> = Vec::new();
        for line in text.lines().skip(1) {
            let c: Vec<&str> = line.split(',').collect();
            let (Some(m), Some(v), Some(ph)) = (c.get(2), c.get(3).and_then(|v| v.parse::<f64>().ok()), c.get(4))
            else {
                continue;
            };
            if *m != method {
                continue;
            }
            match out.iter_mut().find(|o| o.0 == *ph) {
                Some(o) => o.1 = o.1.max(v.abs()),
                None => out.push((ph.to_string(), v.abs())),
            }
        }
        Ok(out)
    };
    let without = max_of("verify-dyn-static", "method 1")?;
    let with = max_of("verify-dyn", "with dynamics")?;
    let firmware = max_of("verify-dyn", "replayed")?;
    println!("\nthermal dynamics (simulated: {DEMO_DYNAMICS}, seed 1), max |Δg| [mg] over CP1..CP6:");
    println!(
        "| checks | poly:2, method 1, static (soaks) | poly:2, method 1 + dynamics (identified), host f64 | the same, firmware in QEMU (f32) | ratio |"
    );
    println!("|---|---:|---:|---:|---:|");
    let mut bad = Vec::new();
    let mut worst_ramp_ratio = f64::INFINITY;
    for (phase, a) in &without {
        let b = with.iter().find(|w| w.0 == *phase).map_or(f64::NAN, |w| w.1);
        let label = match phase.as_str() {
            "hold" => "in the holds (−10, +20, +45 °C)",
            "heating" => "during heating ramps (1 °C/min)",
            _ => "during cooling ramps (1 °C/min)",
        };
        let f = firmware.iter().find(|w| w.0 == *phase).map_or(f64::NAN, |w| w.1);
        println!("| {label} | {a:.3} | {b:.3} | {f:.3} | {:.0}× |", a / b);
        if !((f - b).abs() <= 0.005) {
            bad.push(format!("{label}: the firmware's max |Δg| {f:.4} mg is not within 5 µg of the host's {b:.4} mg"));
        }
        if phase != "hold" {
            worst_ramp_ratio = worst_ramp_ratio.min(a / b);
        }
    }
    let text = std::fs::read_to_string(&dynm).map_err(|e| format!("{dynm}: {e}"))?;
    for (key, truth) in DEMO_DYNAMICS_TRUTH {
        let got = text
            .lines()
            .find_map(|l| l.strip_prefix(key).and_then(|r| r.trim_start().strip_prefix('=')))
            .and_then(|v| v.trim().parse::<f64>().ok())
            .ok_or_else(|| format!("{dynm}: no `{key}` in [thermal_dynamics]"))?;
        let err = (got - truth) / truth;
        println!("identified {key} = {got:.3} (truth {truth}, {:+.1} %)", 100.0 * err);
        if key != "bias_play_width_C" && err.abs() > 0.2 {
            bad.push(format!("{key} {got:.3} not within 20 % of {truth}"));
        }
    }
    if !(worst_ramp_ratio >= 3.0) {
        bad.push(format!("the dynamics stage cut the ramps' max |Δg| by {worst_ramp_ratio:.1}× only (< 3×)"));
    }
    println!(
        "plots: {} and {}",
        dir.join("verify-dyn-static/verify.png").display(),
        dir.join("verify-dyn/verify.png").display()
    );
    if bad.is_empty() { Ok(()) } else { Err(bad.join("; ")) }
}

fn demo_simulate(x: &mut Xtask) -> Result {
    let dir = x.root.join(DEMO_DIR);
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    for (scenario, rec) in [(DEMO_TILTER, "paper-tilter.csv"), (DEMO_SHAKER, "paper-shaker.csv")] {
        let scenario = x.root.join(scenario).to_string_lossy().into_owned();
        x.run(demo_bins_cal(x, &["simulate", &scenario, "-o", &demo_path(x, rec), "--seed", "1"]))?;
    }
    Ok(())
}

fn demo_calibrate(x: &mut Xtask) -> Result {
    let (rec, shaker) = (demo_path(x, "paper-tilter.csv"), demo_path(x, "paper-shaker.csv"));
    // The paper's model: two ranges through −40/+20/+70 °C; then the quadratic (T(11)) with
    // the vibration error from the shaker, written into the blob the firmware runs.
    let pwl = demo_path(x, "cal-pwl.toml");
    x.run(demo_bins_cal(x, &["calibrate", "--tilter", &rec, "--model", "pwl", "--method", "2", "-o", &pwl]))?;
    let (toml, bin, hex) =
        (demo_path(x, "cal-poly2.toml"), demo_path(x, "cal-poly2.bin"), demo_path(x, "cal-poly2.hex"));
    x.run(demo_bins_cal(
        x,
        &[
            "calibrate",
            "--tilter",
            &rec,
            "--shaker",
            &shaker,
            "--model",
            "poly:2",
            "--method",
            "1",
            "-o",
            &toml,
            "--blob",
            &bin,
            "--ihex",
            &hex,
        ],
    ))
}

fn demo_replay(x: &mut Xtask) -> Result {
    let dir = x.root.join(DEMO_DIR);
    let (rec, blob, hex) = (dir.join("paper-tilter.csv"), dir.join("cal-poly2.bin"), dir.join("cal-poly2.hex"));
    let (fw, host) = (dir.join("replay-qemu.csv"), dir.join("replay-host.csv"));
    let t = Instant::now();
    x.replay_firmware(&rec, &blob, &hex, &fw, &dir, DEMO_VE, REPLAY_SAMPLE_HZ)?;
    println!("replay firmware: {} in {:.1} s wall", fw.display(), t.elapsed().as_secs_f64());
    x.replay_host_identical("paper-tilter", &rec, &blob, &fw, &host, DEMO_VE, REPLAY_SAMPLE_HZ)
}

fn demo_verify(x: &mut Xtask) -> Result {
    let rec = demo_path(x, "paper-tilter.csv");
    let (pwl, poly) = (demo_path(x, "cal-pwl.toml"), demo_path(x, "cal-poly2.toml"));
    x.run(demo_bins_cal(x, &["verify", "--check", &rec, "--calib", &pwl, "-o", &demo_path(x, "verify-pwl")]))?;
    let (fw, out) = (demo_path(x, "replay-qemu.csv"), demo_path(x, "verify-poly2"));
    x.run(demo_bins_cal(x, &["verify", "--check", &rec, "--calib", &poly, "--replayed", &fw, "-o", &out]))
}

/// The firmware in QEMU on its test vectors (the demo set) and their report.
fn demo_vectors(x: &mut Xtask) -> Result {
    let dir = x.root.join(DEMO_DIR);
    let input = dir.join("target/fw-vectors/in.bin");
    let output = dir.join("target/fw-vectors/out.bin");
    let (inp, out) = (input.to_string_lossy().into_owned(), output.to_string_lossy().into_owned());
    x.run(x.host_cargo(["run", "--release", "-q", "-p", "host-tests", "--bin", "gen-vectors", "--", "--demo", &inp]))?;
    x.run_qemu_in(&x.elf("firmware"), &dir)?;
    x.run(x.host_cargo(["run", "--release", "-q", "-p", "host-tests", "--bin", "demo-report", "--", &inp, &out]))
}

/// max |Δg| \[mg\] per check temperature and method, from the two `verify.csv` files; the
/// poly:2 file also has the firmware's output (`replayed`), set under the host's number it
/// reproduces, and the replay's bit-identity is checked once more.
fn demo_summary(dir: &Path) -> Result {
    let fw_label = format!("{DEMO_BLOB_METHOD}: replay firmware in QEMU (blob)");
    let mut rows: Vec<(String, String, f64, f64)> = Vec::new(); // (model, method, temp, max)
    // (temp, pos, host, firmware) [mg], to compare dwell by dwell.
    let mut pairs: Vec<(f64, String, f64, f64)> = Vec::new();
    for (model, sub) in [("two-range (paper)", "verify-pwl"), ("poly:2", "verify-poly2")] {
        let path = dir.join(sub).join("verify.csv");
        let text = std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
        for line in text.lines().skip(1) {
            let c: Vec<&str> = line.split(',').collect();
            let (Some(t), Some(pos), Some(m), Some(v)) = (c.first(), c.get(1), c.get(2), c.get(3)) else { continue };
            let (Ok(t), Ok(v)) = (t.parse::<f64>(), v.parse::<f64>()) else { continue };
            let poly = model.starts_with("poly");
            if poly && *m == "T0 constants" {
                continue;
            }
            let fw = *m == "replayed";
            if poly && (fw || *m == DEMO_BLOB_METHOD) {
                let k = match pairs.iter().position(|p| p.0 == t && p.1 == *pos) {
                    Some(k) => k,
                    None => {
                        pairs.push((t, pos.to_string(), f64::NAN, f64::NAN));
                        pairs.len() - 1
                    }
                };
                if fw {
                    pairs[k].3 = v;
                } else {
                    pairs[k].2 = v;
                }
            }
            let label = if *m == "T0 constants" { "–".to_string() } else { model.to_string() };
            let method = if fw { fw_label.clone() } else { m.to_string() };
            match rows.iter_mut().find(|r| r.0 == label && r.1 == method && (r.2 - t).abs() < 0.5) {
                Some(r) => r.3 = r.3.max(v.abs()),
                None => rows.push((label, method, t, v.abs())),
            }
        }
    }
    let mut temps: Vec<f64> = rows.iter().map(|r| r.2).collect();
    temps.sort_by(f64::total_cmp);
    temps.dedup();
    // One line per (model, method) in file order, the firmware's under the host's.
    let mut lines: Vec<(String, String)> = Vec::new();
    for r in &rows {
        if !lines.contains(&(r.0.clone(), r.1.clone())) {
            lines.push((r.0.clone(), r.1.clone()));
        }
    }
    if let Some(k) = lines.iter().position(|l| l.1 == fw_label) {
        let fw = lines.remove(k);
        let host = lines.iter().position(|l| l.0 == fw.0 && l.1 == DEMO_BLOB_METHOD).map_or(lines.len(), |h| h + 1);
        lines.insert(host, fw);
    }
    println!("\nmax |Δg| [mg] in the check positions CP1..CP6 (tolerance ±0.3 mg at T0, ±1 mg over the range):");
    print!("| model | method |");
    for t in &temps {
        print!(" {} °C |", format!("{t:+.1}").replace('-', "−"));
    }
    println!();
    println!("|---|---|{}", "---:|".repeat(temps.len()));
    for (model, method) in &lines {
        print!("| {model} | {method} |");
        for t in &temps {
            let v = rows.iter().find(|q| q.0 == *model && q.1 == *method && q.2 == *t).map_or(f64::NAN, |q| q.3);
            print!(" {v:.3} |");
        }
        println!();
    }
    let verify = dir.join("verify-poly2/verify.csv");
    if pairs.is_empty() || pairs.iter().any(|p| p.2.is_nan() || p.3.is_nan()) {
        return Err(format!(
            "{}: not every check dwell has a host {DEMO_BLOB_METHOD} and a `replayed` value",
            verify.display()
        ));
    }
    let worst = pairs.iter().map(|p| (p.3 - p.2).abs()).fold(0.0f64, f64::max);
    let (fw, host) = (dir.join("replay-qemu.csv"), dir.join("replay-host.csv"));
    let replayed = read(&fw)?;
    if replayed != read(&host)? {
        return Err(format!("{} and {} differ", fw.display(), host.display()));
    }
    let n = replayed.iter().filter(|&&c| c == b'\n').count().saturating_sub(1);
    println!(
        "replay firmware in QEMU (VE source {DEMO_VE}) = bins-cal replay on the host, bit for bit ({n} rows, {}); its \
         |g| error minus the host's {DEMO_BLOB_METHOD} (f64, no VE) in the {} check dwells: at most {:.3} µg",
        fw.display(),
        pairs.len(),
        worst * 1e3
    );
    println!(
        "plots: {} and {}",
        dir.join("verify-pwl/verify.png").display(),
        dir.join("verify-poly2/verify.png").display()
    );
    Ok(())
}

// ---- helpers ----------------------------------------------------------------------------

/// A file's bytes, or an error naming it.
fn read(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))
}

/// The address of the first data byte of an Intel HEX file: the first extended-linear-address
/// record (type 04) plus the first data record's offset.
fn ihex_start(hex: &str) -> Option<u32> {
    let field = |line: &str, at: usize, len: usize| u32::from_str_radix(line.get(at..at + len)?, 16).ok();
    let mut upper = 0;
    for line in hex.lines().filter(|l| l.starts_with(':')) {
        match field(line, 7, 2)? {
            0x04 => upper = field(line, 9, 4)?,
            0x00 => return Some((upper << 16) | field(line, 3, 4)?),
            _ => {}
        }
    }
    None
}

fn cmd<I: IntoIterator<Item = S>, S: AsRef<OsStr>>(program: &str, args: I) -> Command {
    let mut c = Command::new(program);
    c.args(args);
    c
}

/// True if the command starts and succeeds (output discarded).
fn probe(c: &mut Command) -> bool {
    c.stdout(Stdio::null()).stderr(Stdio::null()).status().is_ok_and(|s| s.success())
}

/// The command's stdout, or an error naming it.
fn output(c: &mut Command) -> Result<String> {
    let o = c.stderr(Stdio::inherit()).output().map_err(|e| format!("cannot start `{}`: {e}", show(c)))?;
    if !o.status.success() {
        return Err(format!("`{}` exited with {}", show(c), o.status));
    }
    Ok(String::from_utf8_lossy(&o.stdout).into_owned())
}

fn on_path(program: &str) -> bool {
    env::var_os("PATH").is_some_and(|p| env::split_paths(&p).any(|d| d.join(program).is_file()))
}

fn cargo_home() -> Option<PathBuf> {
    env::var_os("CARGO_HOME").map(PathBuf::from).or_else(|| env::var_os("HOME").map(|h| Path::new(&h).join(".cargo")))
}

fn dpkg_installed(package: &str) -> bool {
    Command::new("dpkg").args(["-s", package]).stderr(Stdio::null()).output().is_ok_and(|o| {
        o.status.success() && String::from_utf8_lossy(&o.stdout).contains("Status: install ok installed")
    })
}

/// `apt-get update` + `apt-get install`, through sudo unless running as root.
fn apt_install(packages: &[&str]) -> Result {
    if !on_path("apt-get") {
        return Err(format!("missing {} and no apt-get to install them: install them by hand", packages.join(" ")));
    }
    let root = output(Command::new("id").arg("-u")).is_ok_and(|u| u.trim() == "0");
    let apt = |args: &[&str]| -> Result {
        let mut c = if root { Command::new("apt-get") } else { cmd("sudo", ["apt-get"]) };
        c.env("DEBIAN_FRONTEND", "noninteractive").args(args);
        println!("$ {}", show(&c));
        let status = c.status().map_err(|e| format!("cannot start `{}`: {e}", show(&c)))?;
        if status.success() { Ok(()) } else { Err(format!("`{}` exited with {status}", show(&c))) }
    };
    apt(&["update"])?;
    let mut args = vec!["install", "-y", "--no-install-recommends"];
    args.extend_from_slice(packages);
    apt(&args)
}

/// Runs the command in its own process group, killing the group after `limit`.
fn run_with_timeout(mut c: Command, limit: Duration) -> Result {
    use std::os::unix::process::CommandExt;
    println!("$ {}", show(&c));
    c.process_group(0);
    let mut child = c.spawn().map_err(|e| format!("cannot start `{}`: {e}", show(&c)))?;
    let deadline = Instant::now() + limit;
    loop {
        match child.try_wait().map_err(|e| e.to_string())? {
            Some(status) if status.success() => return Ok(()),
            Some(status) => return Err(format!("`{}` exited with {status}", show(&c))),
            None if Instant::now() >= deadline => {
                let group = format!("-{}", child.id());
                let _ = Command::new("kill").args(["-KILL", "--", &group]).status();
                let _ = child.wait();
                return Err(format!("`{}` timed out after {} s (XTASK_QEMU_TIMEOUT)", show(&c), limit.as_secs()));
            }
            None => std::thread::sleep(Duration::from_millis(20)),
        }
    }
}

/// Runs a program that does not exit by itself (the flight image in QEMU) for `duration`, in
/// its own process group, then kills the group; an error if it exited before.
fn run_for(mut c: Command, duration: Duration) -> Result {
    use std::os::unix::process::CommandExt;
    println!("$ {}", show(&c));
    c.process_group(0);
    let mut child = c.spawn().map_err(|e| format!("cannot start `{}`: {e}", show(&c)))?;
    let deadline = Instant::now() + duration;
    while Instant::now() < deadline {
        if let Some(status) = child.try_wait().map_err(|e| e.to_string())? {
            return Err(format!("`{}` exited with {status} before {} s", show(&c), duration.as_secs_f64()));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let group = format!("-{}", child.id());
    let _ = Command::new("kill").args(["-KILL", "--", &group]).status();
    let _ = child.wait();
    Ok(())
}

/// A shell-like rendering of a command with the variables it sets.
fn show(c: &Command) -> String {
    let mut parts: Vec<String> = c
        .get_envs()
        .filter_map(|(k, v)| v.map(|v| (k, v)))
        .filter(|(k, _)| *k != "PATH")
        .map(|(k, v)| format!("{}={}", k.to_string_lossy(), v.to_string_lossy()))
        .collect();
    parts.push(relative(c.get_program()));
    parts.extend(c.get_args().map(relative));
    parts.join(" ")
}

fn relative(s: &OsStr) -> String {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().map(Path::to_path_buf).unwrap_or_default();
    let p = Path::new(s);
    let s: OsString = p.strip_prefix(&root).map(|r| r.as_os_str().to_owned()).unwrap_or_else(|_| s.to_owned());
    s.to_string_lossy().into_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `llvm-size -A` of a flight image as the Debian LLVM prints it (sizes changed).
    const SIZES: &str = "flight  :
section               size        addr
.vector_table          192           0
.text                31912         192
.rodata                456       32104
.data                   16   536870912
.gnu.sgstubs             0       32576
.bss                  2892   536870928
.uninit                  4   536873820
.defmt                   1           0
.debug_loc          443013           0
Total              1621862
";

    #[test]
    fn flash_counts_what_is_loaded_and_ram_what_is_reserved() {
        assert_eq!(flash_and_ram(SIZES), Ok((192 + 31_912 + 456 + 16, 16 + 2_892 + 4)));
    }

    #[test]
    fn a_listing_without_the_image_sections_is_an_error() {
        let err = flash_and_ram("section size addr\n.debug_loc 10 0\nTotal 10\n").unwrap_err();
        assert!(err.contains("found 0"), "{err}");
    }
}
