//! `bins-cal`: the host tools of the compensation core. One subcommand per task, each in its
//! own module under `cmd/`:
//!
//! | subcommand | module | does |
//! |---|---|---|
//! | `blob encode\|decode\|check` | [`cmd::blob`] | calibration file (TOML) ⇄ calibration blob, checks |
//! | `calibrate` | [`cmd::calibrate`], [`cmd::shaker`] | tilter (and shake-table) recordings, or holds placed by hand (`--free`, `--tilt`) → calibration file, blob |
//! | `verify` | [`cmd::verify`] | check recordings + calibration → \|g\| errors, table, plots |
//! | `diagnose` | [`cmd::diagnose`] | SIM vs REAL recording → mismatch located, mechanisms named and fitted, report, plots |
//! | `export` | [`cmd::export`] | calibration file → PX4 `TC_A*` / ArduPilot `INS_TCAL*` parameters, what they lose |
//! | `import` | [`cmd::import`] | flight-controller log (PX4 ULog, ArduPilot DataFlash) → recordings, one per accelerometer |
//! | `replay` | [`cmd::replay`] | recording + calibration → the firmware's per-sample output on the host; replay streams |
//! | `simulate` | [`cmd::simulate`] | scenario file (TOML) → simulated recording (format v1) |
//! | `tempco` | [`cmd::tempco`] | temperature coefficients from constants at several temperatures |
//! | `vibration` | [`cmd::vibration`] | the VE table of a conversion function in an environment |
//!
//! Errors are printed as one line, `bins-cal: error: …`, naming the file and the key or byte
//! offset; the exit status is 1 (2 for a usage error). A closed standard output (`| head`)
//! ends the process quietly by SIGPIPE; SIGINT/SIGTERM/SIGHUP remove the temporary outputs
//! first ([`bins_cal::fsio`]).

mod cmd;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

#[derive(Parser)]
#[command(name = "bins-cal", version, about = "Calibration tools for the triaxial accelerometer")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// The calibration blob flashed into the CALIB region.
    Blob(cmd::blob::Args),
    /// Calibrate from tilter recordings: constants per temperature, temperature model; with
    /// --shaker also the vibration-error coefficients.
    Calibrate(Box<cmd::calibrate::Args>),
    /// Check a calibration on check-position recordings: |g| error per method (T(13)).
    Verify(cmd::verify::Args),
    /// Locate a sim-vs-real mismatch, name the missing physics, model it (report, plots).
    Diagnose(cmd::diagnose::Args),
    /// A calibration's bias against temperature as PX4 (TC_A*) or ArduPilot (INS_TCAL*)
    /// parameters.
    Export(cmd::export::Args),
    /// A flight-controller log (PX4 ULog, ArduPilot DataFlash) into recordings, one per
    /// accelerometer instance.
    Import(cmd::import::Args),
    /// A recording through the firmware's per-sample step (host), or its replay streams.
    Replay(cmd::replay::Args),
    /// Simulate a unit on its rigs (scenario file → recording).
    Simulate(cmd::simulate::Args),
    /// Temperature coefficients T(11)/T(12) from constants measured at several temperatures.
    Tempco(cmd::tempco::Args),
    /// The vibration error of a conversion function in a vibration environment (Tables V4/V5).
    Vibration(cmd::vibration::Args),
}

fn main() -> ExitCode {
    // Before any other thread exists: a closed pipe ends the process quietly, and an
    // interrupted run leaves no temporary file (docs/output-safety.md).
    bins_cal::fsio::restore_sigpipe();
    bins_cal::fsio::remove_temporaries_on_signals();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Blob(args) => cmd::blob::run(args),
        Command::Calibrate(args) => cmd::calibrate::run(*args),
        Command::Verify(args) => cmd::verify::run(args),
        Command::Diagnose(args) => cmd::diagnose::run(args),
        Command::Export(args) => cmd::export::run(args),
        Command::Import(args) => cmd::import::run(args),
        Command::Replay(args) => cmd::replay::run(args),
        Command::Simulate(args) => cmd::simulate::run(args),
        Command::Tempco(args) => cmd::tempco::run(args),
        Command::Vibration(args) => cmd::vibration::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // `{:#}` prints the whole context chain on one line.
            eprintln!("bins-cal: error: {}", format!("{e:#}").replace('\n', " "));
            ExitCode::FAILURE
        }
    }
}
