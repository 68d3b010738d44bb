//! `bins-cal simulate SCENARIO.toml -o REC.csv [--seed N]`: runs the simulator
//! ([`bins_cal::sim`]) on a scenario file and writes the recording (format v1) in a stream,
//! to a temporary file renamed into place at the end, with a progress bar on standard error.
//! The same scenario and seed give the same file, bit for bit.
//!
//! `bins-cal simulate --follow REAL.csv SCENARIO.toml -o SIM.csv`: instead of the scenario's
//! rig program, the scenario's unit follows a real recording row for row
//! ([`Simulation::follow`](bins_cal::sim::Simulation::follow)): a SIM for `bins-cal diagnose`.
//! REAL is read twice row by row (its columns, then the prediction), never held.

use bins_cal::sim::scenario;
use std::path::PathBuf;

/// Arguments of `bins-cal simulate`.
#[derive(clap::Args)]
pub struct Args {
    /// The scenario file (TOML; see docs/simulator.md and scenarios/).
    scenario: PathBuf,
    /// The recording to write (CSV, recording format v1).
    #[arg(short, long)]
    output: PathBuf,
    /// Seed of the noise generator (ChaCha8).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
    /// Predict this real recording row for row (its reference, temp_C and power_s) with the
    /// scenario's unit, instead of running the scenario's rig program.
    #[arg(long, value_name = "REAL.csv")]
    follow: Option<PathBuf>,
}

/// Runs `bins-cal simulate`.
pub fn run(args: Args) -> anyhow::Result<()> {
    bins_cal::fsio::refuse_overwriting_inputs(
        [Some(&args.scenario), args.follow.as_ref()].into_iter().flatten(),
        [&args.output],
    )?;
    let sim = scenario::load(&args.scenario)?;
    if let Some(real) = &args.follow {
        let n = sim.write_follow(real, &args.output)?;
        eprintln!(
            "{}: {n} rows predicted for {} by the unit of {}",
            args.output.display(),
            real.display(),
            args.scenario.display()
        );
        return Ok(());
    }
    let name =
        args.scenario.file_name().map_or_else(|| args.scenario.display().to_string(), |n| n.to_string_lossy().into());
    let rows = sim.write(&name, args.seed, &args.output, !args.quiet)?;
    eprintln!(
        "{}: {rows} rows, {:.1} s at {} Hz, seed {}",
        args.output.display(),
        sim.duration_s(),
        sim.rate_hz,
        args.seed
    );
    Ok(())
}
