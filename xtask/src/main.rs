//! Project tasks: `cargo xtask test` (everything CI checks) and `cargo xtask demo`.
//!
//! The Cortex-M4F binaries are built with rustup's toolchain when it has the
//! `thumbv7em-none-eabihf` target installed. Otherwise Debian's Rust (`rustc-web`, linked into
//! rustup as the `debian` toolchain) builds them with `-Zbuild-std=core`; the packages it needs
//! are installed with apt when missing. Firmware builds use their own target directory
//! (`target/thumb`), so host and target builds never invalidate each other.
//!
//! `main` only dispatches; each concern has its module: [`task`] (steps and their timing),
//! [`process`] (child processes), [`toolchain`] (host and thumb cargo, firmware builds),
//! [`qemu`] (runs in QEMU, the replay), [`rusage`] (one child's CPU time and peak memory), [`test`](mod@test), [`bench`](mod@bench), [`demo`], [`verify_csv`] (`bins-cal
//! verify`'s table, by column name).

mod bench;
mod demo;
mod process;
mod qemu;
mod rusage;
mod task;
mod test;
mod toolchain;
mod verify_csv;

use std::env;
use std::process::ExitCode;
use task::Xtask;

fn main() -> ExitCode {
    let args: Vec<String> = env::args().skip(1).collect();
    let mut x = Xtask::new();
    let ok = match args.first().map(String::as_str) {
        Some("test") => x.test(),
        Some("demo") => x.demo(),
        Some("replay") => x.replay(args.get(1..).unwrap_or(&[])),
        Some("bench") => x.bench(args.get(1..).unwrap_or(&[])),
        _ => {
            eprintln!("usage: cargo xtask <test|demo|replay|bench>");
            eprintln!(
                "  bench [--only N]  instructions per sample in QEMU, stack depth, flash/RAM of the firmware images, host samples per second, the diagnosis's speed, calibrate/verify on a day at 100 Hz"
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
