//! `cargo xtask bench`: instructions per sample and stack depth in QEMU, flash and static RAM
//! of the images against their budgets, host samples per second, the diagnosis's speed, the
//! CPU time and peak memory of `calibrate` and `verify` on a day at 100 Hz, of `import` on
//! 100 MB flight-controller logs, and the Allan deviation's speed against the streaming reader
//! and allantools.

use std::path::Path;
use std::process::Stdio;
use std::time::Instant;

use crate::process::{output, show};
use crate::rusage::measured;
use crate::task::{Result, StepFn, Xtask};

/// Flash budget of the flight image \[B\]: 28 KiB, so that 4 KiB of a 32 KiB part stay free.
pub(crate) const FLASH_BUDGET: u64 = 28 * 1024;

/// Static RAM budget of the flight image \[B\]: 3 KiB.
pub(crate) const RAM_BUDGET: u64 = 3 * 1024;

/// Symbols of the flight image listed by size (the largest first) after its sections.
const LARGEST_SYMBOLS: usize = 30;

/// The largest code and data symbols of an image from `llvm-nm --print-size --size-sort
/// --radix=d` (lines `address size type name`), largest first: (size, type, name).
pub(crate) fn largest_symbols(nm: &str, n: usize) -> Vec<(u64, char, String)> {
    let mut out: Vec<(u64, char, String)> = nm
        .lines()
        .filter_map(|l| {
            let mut cols = l.split_whitespace();
            let (_addr, size, kind) = (cols.next()?, cols.next()?, cols.next()?);
            let name = cols.collect::<Vec<_>>().join(" ");
            let kind = kind.chars().next()?;
            // Code and read-only data in flash, data and bss in RAM.
            if !"tTrRdDbB".contains(kind) || name.is_empty() {
                return None;
            }
            Some((size.parse().ok()?, kind, name))
        })
        .collect();
    out.sort_by(|a, b| b.0.cmp(&a.0).then_with(|| a.2.cmp(&b.2)));
    out.truncate(n);
    out
}

/// Flash (what is loaded: vector table, code, constants, initial values of `.data`) and
/// static RAM (`.data`, `.bss`, `.uninit`) of an image, from `llvm-size -A`.
pub(crate) fn flash_and_ram(sections: &str) -> Result<(u64, u64)> {
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

/// CPU-time budget of one `calibrate` or `verify` run on a day at 100 Hz \[s\].
pub(crate) const DAY_CPU_BUDGET_S: f64 = 30.0;

/// Peak-memory budget of one `calibrate` or `verify` run on a day at 100 Hz \[MB\].
pub(crate) const DAY_RSS_BUDGET_MB: f64 = 500.0;

/// CPU-time budget of `diagnose` on a pair of days at 100 Hz \[s\].
pub(crate) const DAY_DIAGNOSE_CPU_BUDGET_S: f64 = 60.0;

/// Peak-memory budget of `diagnose` on a pair of days at 100 Hz \[MB\].
pub(crate) const DAY_DIAGNOSE_RSS_BUDGET_MB: f64 = 1000.0;

/// The day's runs: what is measured and its arguments after `bins-cal` (`DAY` stands for the
/// recording, `DIR` for the directory of the outputs, `ROOT` for the repository). `verify`
/// with a calibration that has thermal dynamics runs them over every row. The day's dwells are at −39.5 and
/// +70.4 °C, so T0 is taken at the cold one; `--max-rate-c-per-min 0.2` keeps the first
/// cooling (a slow −0.34 °C/min on average) out of the free fit's static intervals.
pub(crate) const DAY_RUNS: [(&str, &[&str]); 5] = [
    (
        "calibrate (static tilter)",
        &["calibrate", "--tilter", "DAY", "--model", "poly:1", "--t0=-39.5", "-o", "DIR/static.toml"],
    ),
    (
        "calibrate --free",
        &[
            "calibrate",
            "--free",
            "--tilter",
            "DAY",
            "--model",
            "poly:1",
            "--t0=-39.5",
            "--max-rate-c-per-min",
            "0.2",
            "-o",
            "DIR/free.toml",
        ],
    ),
    (
        "calibrate --dynamics identify",
        &[
            "calibrate",
            "--tilter",
            "DAY",
            "--model",
            "poly:1",
            "--t0=-39.5",
            "--dynamics",
            "identify",
            "-o",
            "DIR/dyn.toml",
        ],
    ),
    ("verify", &["verify", "--check", "DAY", "--calib", "DIR/static.toml", "-o", "DIR/verify"]),
    (
        "verify with thermal dynamics",
        &[
            "verify",
            "--check",
            "DAY",
            "--calib",
            "ROOT/calibrations/paper-two-range-dynamics.toml",
            "-o",
            "DIR/verify-dyn",
        ],
    ),
];

/// CPU budget of `bins-cal import` of a 100 MB log \[s\].
pub(crate) const LOG_CPU_BUDGET_S: f64 = 10.0;

/// Peak-memory budget of `bins-cal import` of a 100 MB log \[MB\]: a stream, bounded by
/// its buffers and the log's definitions, not by the file.
pub(crate) const LOG_RSS_BUDGET_MB: f64 = 50.0;

/// Size of the benchmark's logs \[MB\].
pub(crate) const LOG_MB: &str = "100";

/// A bench step: its number, its title and what it runs.
type BenchStep = (usize, &'static str, StepFn);

impl Xtask {
    /// `cargo xtask bench [--only N]`: instructions per sample of each method/model case, the
    /// worst single step and the step's stack high-water mark (the `bench` firmware in QEMU,
    /// `-icount shift=0`), flash and static RAM of the replay firmware, the link-check image
    /// and the flight image (`llvm-size`), the host's samples per second (criterion), the
    /// diagnosis's wall time on 30 000- and 260 000-row pairs against its budgets, and the CPU
    /// time and peak memory of `calibrate` and `verify` on a simulated day at 100 Hz against
    /// theirs. `--only N` runs step N alone, after step 1 (the toolchain) for the firmware's
    /// steps 2 to 4 and step 2 (the images' build) for steps 3 and 4, so that they measure
    /// the tree as it is.
    pub(crate) fn bench(&mut self, args: &[String]) -> bool {
        let only = match args {
            [] => None,
            [flag, n] if flag == "--only" => match n.parse::<usize>() {
                Ok(n) if (1..=BENCH_STEPS.len()).contains(&n) => Some(n),
                _ => {
                    eprintln!("cargo xtask bench --only N: N is a step number, 1 to {}", BENCH_STEPS.len());
                    return false;
                }
            },
            _ => {
                eprintln!("usage: cargo xtask bench [--only N]");
                return false;
            }
        };
        let started = Instant::now();
        let mut ok = true;
        // The firmware's steps need the toolchain that step 1 finds or installs, and steps 3
        // and 4 the images that step 2 builds (the replay firmware is one of step 4's).
        let wanted = |n: usize| {
            only.is_none_or(|k| k == n || (n == 1 && (2..=4).contains(&k)) || (n == 2 && (3..=4).contains(&k)))
        };
        for &(n, name, f) in BENCH_STEPS.iter().filter(|s| wanted(s.0)) {
            ok = self.step(n, name, f);
            if !ok {
                break;
            }
        }
        self.summary(started);
        ok
    }

    /// Bench step 7: simulates a day at 100 Hz (8.64 M rows, 1.17 GB) into a temporary directory
    /// and measures each of [`DAY_RUNS`] (release, one thread): CPU time and peak resident set
    /// of the child against [`DAY_CPU_BUDGET_S`] and [`DAY_RSS_BUDGET_MB`].
    fn bench_day(&mut self) -> Result {
        self.run(self.host_cargo(["build", "--release", "-q", "-p", "bins-cal"]))?;
        let bin = self.root.join("target/release/bins-cal");
        let dir = std::env::temp_dir().join(format!("bins-cal-bench-day-{}", std::process::id()));
        std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        let r = self.bench_day_in(&bin, &dir);
        let _ = std::fs::remove_dir_all(&dir);
        r
    }

    fn bench_day_in(&self, bin: &Path, dir: &Path) -> Result {
        let day = dir.join("day.csv");
        let scenario = self.root.join("scenarios/day-100hz.toml");
        let mut c = self.command(bin);
        c.arg("simulate").arg(&scenario).arg("-o").arg(&day).arg("--quiet");
        let sim = measured(c)?;
        println!("simulate: {:.1} s CPU, {:.1} MB peak ({:.1} s wall)", sim.cpu_s, sim.peak_rss_mb, sim.wall_s);
        let mut missed = Vec::new();
        let mut table = Vec::new();
        for (what, args) in DAY_RUNS {
            let mut c = self.command(bin);
            for a in args {
                let a = a
                    .replace("DAY", &day.to_string_lossy())
                    .replace("DIR", &dir.to_string_lossy())
                    .replace("ROOT", &self.root.to_string_lossy());
                c.arg(a);
            }
            c.stdout(Stdio::null());
            let u = measured(c)?;
            let met = u.cpu_s < DAY_CPU_BUDGET_S && u.peak_rss_mb < DAY_RSS_BUDGET_MB;
            if !met {
                missed.push(what);
            }
            table.push(format!(
                "  {what:<30} {:>7.1} s CPU {:>8.1} MB peak {:>7.1} s wall  {}",
                u.cpu_s,
                u.peak_rss_mb,
                u.wall_s,
                if met { "met" } else { "MISSED" }
            ));
        }
        println!(
            "a day at 100 Hz (8.64 M rows), budgets < {DAY_CPU_BUDGET_S} s CPU and < {DAY_RSS_BUDGET_MB} MB peak each:"
        );
        for l in &table {
            println!("{l}");
        }
        // The diagnosis of the day against its simulation without warm-up, die lag and play:
        // by default the diagnosis reduces the rows to blocks of the length the data allow.
        let sim = dir.join("sim.csv");
        let mut c = self.command(bin);
        c.arg("simulate").arg(self.root.join("scenarios/day-100hz-sim.toml")).arg("-o").arg(&sim);
        c.args(["--seed", "2", "--quiet"]);
        measured(c)?;
        let mut c = self.command(bin);
        c.arg("diagnose").arg("--sim").arg(&sim).arg("--real").arg(&day).arg("--report");
        c.arg(dir.join("day.json")).stdout(Stdio::null());
        let u = measured(c)?;
        let met = u.cpu_s < DAY_DIAGNOSE_CPU_BUDGET_S && u.peak_rss_mb < DAY_DIAGNOSE_RSS_BUDGET_MB;
        println!(
            "diagnose, the day against its simulation without warm-up, lag and play (blocks of the length the data allow: 1/3 s, at most 100 000 blocks, so 1 s here; budgets < {DAY_DIAGNOSE_CPU_BUDGET_S} s, < {DAY_DIAGNOSE_RSS_BUDGET_MB} MB):\n  {:>7.1} s CPU {:>8.1} MB peak {:>7.1} s wall  {}",
            u.cpu_s,
            u.peak_rss_mb,
            u.wall_s,
            if met { "met" } else { "MISSED" }
        );
        if !met {
            missed.push("diagnose");
        }
        if missed.is_empty() { Ok(()) } else { Err(format!("over budget: {}", missed.join(", "))) }
    }
}

impl Xtask {
    /// Bench step 8: writes a 100 MB ArduPilot DataFlash log and a 100 MB PX4 ULog (three
    /// accelerometers at 1 kHz, the `fc_log_gen` example) into a temporary directory and
    /// measures `bins-cal import` of each (release): CPU time and peak resident set against
    /// [`LOG_CPU_BUDGET_S`] and [`LOG_RSS_BUDGET_MB`].
    fn bench_logs(&mut self) -> Result {
        self.run(self.host_cargo([
            "build",
            "--release",
            "-q",
            "-p",
            "bins-cal",
            "--bin",
            "bins-cal",
            "--example",
            "fc_log_gen",
        ]))?;
        let bin = self.root.join("target/release/bins-cal");
        let gen_bin = self.root.join("target/release/examples/fc_log_gen");
        let dir = std::env::temp_dir().join(format!("bins-cal-bench-logs-{}", std::process::id()));
        std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        let r = self.bench_logs_in(&bin, &gen_bin, &dir);
        let _ = std::fs::remove_dir_all(&dir);
        r
    }

    fn bench_logs_in(&self, bin: &Path, gen_bin: &Path, dir: &Path) -> Result {
        let mut missed = Vec::new();
        for log in ["log.bin", "log.ulg"] {
            let path = dir.join(log);
            let mut c = self.command(gen_bin);
            c.arg(&path).arg(LOG_MB);
            self.run(c)?;
            let mut c = self.command(bin);
            c.arg("import").arg(&path).arg("-o").arg(dir.join("rec.csv")).arg("--quiet").stdout(Stdio::null());
            let u = measured(c)?;
            let met = u.cpu_s < LOG_CPU_BUDGET_S && u.peak_rss_mb < LOG_RSS_BUDGET_MB;
            if !met {
                missed.push(log);
            }
            println!(
                "  import {log} ({LOG_MB} MB) {:>7.2} s CPU {:>8.1} MB peak {:>7.2} s wall  {}",
                u.cpu_s,
                u.peak_rss_mb,
                u.wall_s,
                if met { "met" } else { "MISSED" }
            );
        }
        if missed.is_empty() { Ok(()) } else { Err(format!("over budget: import {}", missed.join(", "))) }
    }
}

/// Peak memory budget of `bins-cal allan` on the day at 100 Hz \[MB\].
const ALLAN_RSS_BUDGET_MB: f64 = 200.0;

/// allantools as the bench installs it (the version the figures and the tests' reference
/// values were taken with).
const ALLANTOOLS: &str = "allantools==2024.6";

impl Xtask {
    /// Bench step 9: the `allan_speed` example (10⁷ samples against the `allan` crate and
    /// against allantools' octave `oadev`, which it needs ≥ 10× faster than; the day's curves
    /// against the streaming reader alone, ≤ 1.5×) and the peak memory of `bins-cal allan` on
    /// the day (< 200 MB). allantools is installed from pip into a virtual environment under
    /// `target/`; where that fails the comparison is skipped and the step says so.
    fn bench_allan(&mut self) -> Result {
        self.run(self.host_cargo([
            "build",
            "--release",
            "-q",
            "-p",
            "bins-cal",
            "--bins",
            "--example",
            "allan_speed",
        ]))?;
        let bin = self.root.join("target/release/bins-cal");
        let example = self.root.join("target/release/examples/allan_speed");
        let python = self.allantools_python();
        let dir = std::env::temp_dir().join(format!("bins-cal-bench-allan-{}", std::process::id()));
        std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        let r = (|| {
            let day = dir.join("day.csv");
            let mut c = self.command(&bin);
            c.arg("simulate").arg(self.root.join("scenarios/day-100hz.toml")).arg("-o").arg(&day).arg("--quiet");
            measured(c)?;
            let mut c = self.command(&example);
            c.arg("--day").arg(&day);
            if let Some(py) = &python {
                c.arg("--python").arg(py);
            }
            self.run(c)?;
            let mut c = self.command(&bin);
            c.arg("allan").arg(&day).arg("--json").arg(dir.join("allan.json")).stdout(Stdio::null());
            let u = measured(c)?;
            let met = u.peak_rss_mb < ALLAN_RSS_BUDGET_MB;
            println!(
                "bins-cal allan on the day (ux_V, uy_V, uz_V, temp_C; reading included): {:.1} s CPU, {:.1} MB peak, {:.1} s wall (budget < {ALLAN_RSS_BUDGET_MB} MB: {})",
                u.cpu_s,
                u.peak_rss_mb,
                u.wall_s,
                if met { "met" } else { "MISSED" }
            );
            if met { Ok(()) } else { Err("bins-cal allan over its memory budget".to_string()) }
        })();
        let _ = std::fs::remove_dir_all(&dir);
        r
    }

    /// A Python with allantools: a virtual environment in `target/bench-allantools` with
    /// [`ALLANTOOLS`] from pip, or `None` (said) where Python, venv or pip cannot provide it.
    fn allantools_python(&self) -> Option<std::path::PathBuf> {
        let venv = self.root.join("target/bench-allantools");
        let py = venv.join("bin/python");
        let has = |py: &Path| {
            std::process::Command::new(py)
                .args(["-c", "import allantools"])
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .status()
                .is_ok_and(|s| s.success())
        };
        if has(&py) {
            return Some(py);
        }
        let mut c = self.command("python3");
        c.arg("-m").arg("venv").arg(&venv);
        let mut pip = self.command(venv.join("bin/pip"));
        pip.args(["install", "-q", ALLANTOOLS]);
        match self.run(c).and_then(|_| self.run(pip)) {
            Ok(()) if has(&py) => Some(py),
            Ok(()) => {
                println!("allantools: skipped (installed, but {} cannot import it)", py.display());
                None
            }
            Err(e) => {
                println!("allantools: skipped (pip could not install {ALLANTOOLS}: {e})");
                None
            }
        }
    }
}

/// The bench's steps in order.
const BENCH_STEPS: [BenchStep; 9] = [
    (1, "toolchain", Xtask::setup_toolchain),
    (2, "build", |x| {
        x.build_firmware()?;
        let args = ["--release", "--features", "firmware-log", "--bin", "bench", "--bin", "bench-stages"];
        x.run(x.thumb_cargo("build", args)?)
    }),
    (3, "instructions per sample against the budgets, and per stage (QEMU)", |x| {
        // Both run, the stages also when a budget was missed.
        let budgets = x.run_qemu_in(&x.elf("bench"), &x.root);
        x.run_qemu_in(&x.elf("bench-stages"), &x.root).and(budgets)
    }),
    (4, "size of the replay firmware, the link-check image and the flight image", |x| {
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
        let mut c = x.command("llvm-nm");
        c.args(["--print-size", "--size-sort", "--radix=d", "--demangle"]).arg(x.elf("flight"));
        println!("$ {}  (the {LARGEST_SYMBOLS} largest symbols)", show(&c));
        for (size, kind, name) in largest_symbols(&output(&mut c)?, LARGEST_SYMBOLS) {
            println!("{size:>7} {kind} {name}");
        }
        let verdict = |used: u64, budget: u64| if used <= budget { "met" } else { "MISSED" };
        println!("flight image: flash {flash} B of {FLASH_BUDGET} ({})", verdict(flash, FLASH_BUDGET));
        println!("flight image: static RAM {ram} B of {RAM_BUDGET} ({})", verdict(ram, RAM_BUDGET));
        if flash > FLASH_BUDGET || ram > RAM_BUDGET {
            return Err("the flight image is over its flash or RAM budget".into());
        }
        Ok(())
    }),
    (5, "host samples per second (criterion)", |x| {
        x.run(x.host_cargo(["bench", "-p", "host-tests", "--bench", "throughput"]))
    }),
    (
        6,
        "bins-cal diagnose: 30 000 rows < 2 s, 260 000 rows < 10 s at 1 Hz, < 3 s at 100 Hz (release, one thread)",
        |x| x.run(x.host_cargo(["run", "--release", "-q", "-p", "bins-cal", "--example", "diagnose_speed"])),
    ),
    (
        7,
        "bins-cal calibrate (static, --free, --dynamics identify) and verify on a day at 100 Hz: < 30 s CPU, < 500 MB peak each; diagnose of the day: < 60 s, < 1 GB (release, one thread)",
        Xtask::bench_day,
    ),
    (
        8,
        "bins-cal import of a 100 MB ArduPilot DataFlash log and a 100 MB PX4 ULog: < 10 s CPU, < 50 MB peak each (release)",
        Xtask::bench_logs,
    ),
    (
        9,
        "bins-cal allan: 10^7 samples ≥ 10× faster than allantools' octave oadev; a day at 100 Hz ≤ 1.5× the streaming reader alone, < 200 MB peak (release, one thread)",
        Xtask::bench_allan,
    ),
];

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
    fn the_largest_symbols_come_first_and_debug_symbols_are_left_out() {
        let nm = "00000400 00000120 T SysTick\n00000010 00000004 N .Ldebug\n20000000 00002892 B bins::ISR\n00000520 00000036 t core::fmt::write\n";
        let got = largest_symbols(nm, 2);
        assert_eq!(got, vec![(2892, 'B', "bins::ISR".to_string()), (120, 'T', "SysTick".to_string())]);
    }

    #[test]
    fn a_listing_without_the_image_sections_is_an_error() {
        let err = flash_and_ram("section size addr\n.debug_loc 10 0\nTotal 10\n").unwrap_err();
        assert!(err.contains("found 0"), "{err}");
    }
}
