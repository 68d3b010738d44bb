//! Runs in QEMU (mps2-an386): an image with a blob in its CALIB region, the replay firmware on a
//! recording (`cargo xtask replay`) compared with `bins-cal replay` on the host, and the flight
//! image with its UART captured.

use std::env;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::process::{read, run_for, run_with_timeout};
use crate::task::{Result, Xtask};
use crate::test::{BLOB, BLOB_HEX, CALIBRATION};

/// QEMU runner (also cargo's `runner` for the thumb target).
pub(crate) const RUNNER: &str = "tools/qemu-run.sh";

/// Default limit on one QEMU run; override with `XTASK_QEMU_TIMEOUT` (seconds).
pub(crate) const QEMU_TIMEOUT_S: u64 = 300;

/// The sampling rate \[Hz\] the replay firmware's pipeline is configured for (its
/// `REPLAY_SAMPLE_HZ`; SysTick stays at 1 kHz), unless a recording needs its own.
pub(crate) const REPLAY_SAMPLE_HZ: u32 = 1000;

/// The VE source of a replay unless another is chosen (`REPLAY_VE`, `bins-cal replay --ve`):
/// the online moment window, as in flight.
pub(crate) const DEFAULT_VE: &str = "online";

/// Where the flight image's UART output is captured in QEMU, relative to the repository root.
pub(crate) const FLIGHT_CAPTURE: &str = "target/fw-flight/uart.bin";

/// How long the flight image runs in QEMU (wall time; it never exits by itself).
pub(crate) const FLIGHT_RUN: Duration = Duration::from_millis(2500);

/// Frames the capture must hold at least: 3 s of sampling at 1 kHz (3 health frames). A
/// 2.5 s run gave about 19 000 frames on a 2-core machine (`-icount shift=0,sleep=off` runs
/// the mostly idle image faster than real time).
pub(crate) const FLIGHT_MIN_FRAMES: usize = 3000;

/// Bytes of one flight output frame (`bins_comp::frame::FRAME_BYTES`).
pub(crate) const FLIGHT_FRAME_BYTES: f64 = 24.0;

/// The address of the first data byte of an Intel HEX file: the first extended-linear-address
/// record (type 04) plus the first data record's offset.
pub(crate) fn ihex_start(hex: &str) -> Option<u32> {
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

impl Xtask {
    /// `cargo xtask replay REC.csv --calib CAL.bin -o OUT.csv [--ve SOURCE]`: the recording
    /// through the replay firmware in QEMU (SysTick at 1 kHz, or `REPLAY_TICK_HZ` at build
    /// time) with the VE of SOURCE subtracted (`online`, the default, `none` or `profile:N`, as
    /// `bins-cal replay --ve`), results as CSV.
    pub(crate) fn replay(&mut self, args: &[String]) -> bool {
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
    pub(crate) fn calib_hex(&self, work: &Path) -> Result<PathBuf> {
        std::fs::create_dir_all(work).map_err(|e| format!("{}: {e}", work.display()))?;
        let hex = work.join("calib-origin.hex");
        let mut c = self.bins_cal();
        c.args(["blob", "encode", CALIBRATION, "-o"]).arg(work.join("calib-origin.bin")).arg("--ihex").arg(&hex);
        self.run(c)?;
        Ok(hex)
    }

    /// The release `bins-cal` binary (built by the step that calls this).
    pub(crate) fn bins_cal(&self) -> Command {
        self.command(self.root.join("target/release/bins-cal"))
    }

    /// A recording through the replay firmware in QEMU, in `work`: the recording as the input
    /// stream, the blob in CALIB (at the address of the Intel HEX file `hex`), the VE of `ve`
    /// subtracted, the output stream back to CSV (`t_s` from the recording).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn replay_firmware(
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

    /// `bins-cal replay` of `rec` with `blob` on the host into `host`, which must equal the
    /// firmware's output `fw` byte for byte.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn replay_host_identical(
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

    /// The flight image in QEMU for [`FLIGHT_RUN`] with the paper blob in CALIB and UART0
    /// captured to [`FLIGHT_CAPTURE`], then stopped (it runs forever); `flight-check` decodes
    /// the capture with the library's frame decoder. No sensor is attached in QEMU, so the
    /// image must boot with the blob accepted, send at least [`FLIGHT_MIN_FRAMES`] frames with
    /// consecutive sequence numbers, flag every sample `SENSOR_FAULT` and count the faults.
    pub(crate) fn flight_test(&mut self) -> Result {
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
    pub(crate) fn run_qemu_with_blob(&self, elf: &Path, cwd: &Path, blob: &Path, hex: &Path) -> Result {
        let limit = env::var("XTASK_QEMU_TIMEOUT").ok().and_then(|s| s.parse().ok()).unwrap_or(QEMU_TIMEOUT_S);
        let mut c = self.command(self.root.join(RUNNER));
        c.env("QEMU_EXTRA", self.loader_arg(blob, hex)?);
        c.arg(elf).current_dir(cwd).stdin(Stdio::null());
        run_with_timeout(c, Duration::from_secs(limit))
    }

    /// QEMU's option that places `blob` at the CALIB origin: the address of the Intel HEX file
    /// `hex`, which `bins-cal` writes at the ORIGIN of CALIB in `memory.x`.
    pub(crate) fn loader_arg(&self, blob: &Path, hex: &Path) -> Result<String> {
        let text = std::fs::read_to_string(hex).map_err(|e| format!("{}: {e}", hex.display()))?;
        let addr = ihex_start(&text).ok_or(format!("{}: no extended-address and data record", hex.display()))?;
        Ok(format!("-device loader,file={},addr=0x{addr:08x}", blob.display()))
    }

    /// Runs an ELF in QEMU with `cwd` as its working directory: the firmware's semihosting
    /// paths (`target/fw-vectors/…`) are relative to it.
    pub(crate) fn run_qemu_in(&self, elf: &Path, cwd: &Path) -> Result {
        let limit = env::var("XTASK_QEMU_TIMEOUT").ok().and_then(|s| s.parse().ok()).unwrap_or(QEMU_TIMEOUT_S);
        let mut c = self.command(self.root.join(RUNNER));
        c.arg(elf).current_dir(cwd).stdin(Stdio::null());
        run_with_timeout(c, Duration::from_secs(limit))
    }
}
