//! `bins-cal allan`: the overlapping Allan deviation of a recording's channels at every time
//! scale, with confidence intervals and the IEEE noise terms; optionally the simulator's
//! `[noise]` table fitted to it and a Kalibr `imu.yaml` ([`bins_cal::allan`],
//! `docs/noise.md`).

use anyhow::anyhow;
use bins_cal::allan::{self, Config, Grid, Kind, output, pass};
use bins_cal::calfile::CalibrationFile;
use bins_cal::fsio;
use std::path::{Path, PathBuf};

/// Arguments of `bins-cal allan`.
#[derive(clap::Args)]
pub struct Args {
    /// The recording (format v1).
    #[arg(value_name = "REC.csv")]
    rec: PathBuf,
    /// Channels, comma-separated (of ux_V, uy_V, uz_V, temp_C).
    #[arg(long, value_delimiter = ',', default_value = "ux_V,uy_V,uz_V,temp_C")]
    channels: Vec<String>,
    /// Rows from this time [s] (t_s ≥ FROM).
    #[arg(long, value_name = "S", value_parser = bins_cal::numarg::finite)]
    from: Option<f64>,
    /// Rows before this time [s] (t_s < TO).
    #[arg(long, value_name = "S", value_parser = bins_cal::numarg::finite)]
    to: Option<f64>,
    /// Only the rows whose reference is known (a rig's holds), each run of them a segment.
    #[arg(long)]
    held: bool,
    /// τ at N points a decade instead of octaves.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..=100))]
    per_decade: Option<u32>,
    /// The accelerometers' scale factor [V/g]: one value, or three (x,y,z); shows them in g.
    #[arg(long, value_name = "V_PER_G", value_delimiter = ',', value_parser = bins_cal::numarg::positive, conflicts_with = "calib")]
    scale_v_per_g: Vec<f64>,
    /// A calibration file: the accelerometers in g through its K_ii at T0.
    #[arg(long, value_name = "CAL.toml")]
    calib: Option<PathBuf>,
    /// Confidence of the intervals.
    #[arg(long, default_value_t = 0.95, value_parser = level)]
    confidence: f64,
    /// Write the curves and terms as JSON here.
    #[arg(long, value_name = "OUT.json")]
    json: Option<PathBuf>,
    /// Write the curves as CSV here.
    #[arg(long, value_name = "OUT.csv")]
    csv: Option<PathBuf>,
    /// Write the plot (PNG) here.
    #[arg(long, value_name = "OUT.png")]
    plot: Option<PathBuf>,
    /// Write a scenario whose `[noise]` table is fitted to the curves (the twin's noise).
    #[arg(long, value_name = "TWIN.toml")]
    noise_toml: Option<PathBuf>,
    /// Write a Kalibr-style imu.yaml (needs the accelerometers in g).
    #[arg(long, value_name = "imu.yaml")]
    imu_yaml: Option<PathBuf>,
}

fn level(s: &str) -> Result<f64, String> {
    let x = bins_cal::numarg::finite(s)?;
    if !(x > 0.0 && x < 1.0) {
        return Err(format!("{x}: a confidence is between 0 and 1 (e.g. 0.95)"));
    }
    Ok(x)
}

/// The scale factors [V/g] of the three accelerometers, if given.
fn scales(args: &Args) -> anyhow::Result<Option<[f64; 3]>> {
    if let Some(path) = &args.calib {
        let (params, _) = CalibrationFile::read(path)?.to_params().map_err(|e| anyhow!("{}: {e}", path.display()))?;
        let k = params.constants.k_v_per_g;
        return Ok(Some([k[0][0], k[1][1], k[2][2]]));
    }
    match args.scale_v_per_g.as_slice() {
        [] => Ok(None),
        [s] => Ok(Some([*s; 3])),
        [x, y, z] => Ok(Some([*x, *y, *z])),
        v => Err(anyhow!("--scale-v-per-g: one value or three (x,y,z), got {}", v.len())),
    }
}

/// Runs `bins-cal allan`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let outputs: Vec<&PathBuf> =
        [&args.json, &args.csv, &args.plot, &args.noise_toml, &args.imu_yaml].into_iter().flatten().collect();
    let inputs: Vec<&PathBuf> = [Some(&args.rec), args.calib.as_ref()].into_iter().flatten().collect();
    fsio::refuse_overwriting_inputs(inputs, outputs.iter())?;
    if let (Some(a), Some(b)) = (args.from, args.to)
        && !(a < b)
    {
        return Err(anyhow!("--from {a} must be before --to {b}"));
    }
    let scales = scales(&args)?;
    pass::channel_indices(&args.channels)?;
    let config = Config {
        kind: Kind::Allan,
        grid: args.per_decade.map_or(Grid::Octave, Grid::PerDecade),
        exact_max_m: allan::estimate::EXACT_MAX_M,
    };
    let opt = pass::Options {
        channels: args.channels.clone(),
        from_s: args.from,
        to_s: args.to,
        held_only: args.held,
        config: config.clone(),
        level: args.confidence,
    };
    let a = pass::analyse(&args.rec, &opt)?;
    let shown = output::shown(&a, scales);
    print!("{}", output::table(&a, &shown, config.exact_max_m, args.confidence));
    // Everything rendered first; then written all or nothing.
    let mut files: Vec<(&Path, Vec<u8>)> = Vec::new();
    if let Some(p) = &args.json {
        let v = output::json(&a, &shown, config.exact_max_m, args.confidence);
        files.push((p, (serde_json::to_string_pretty(&v)? + "\n").into_bytes()));
    }
    if let Some(p) = &args.csv {
        files.push((p, output::csv(&shown).into_bytes()));
    }
    if let Some(p) = &args.plot {
        let title =
            format!("{}: overlapping Allan deviation, {:.0} % intervals", a.file.display(), 100.0 * args.confidence);
        files.push((p, allan::plot::render(p, &title, &shown)?));
    }
    if let Some(p) = &args.noise_toml {
        let (noise, temp) = output::twin_noise(&a)?;
        println!("\nfitted noise (simulator's [noise] table, V per axis x / y / z):");
        for (i, n) in noise.iter().enumerate() {
            println!(
                "  {}: white {:.4e} V, random walk {:.4e} V/√s, Gauss–Markov {:.4e} V τ {:.4e} s, {:.4e} V τ {:.4e} s, ADC step {:.4e} V",
                ["x", "y", "z"][i],
                n.white,
                n.random_walk,
                n.gm[0].0,
                n.gm[0].1,
                n.gm[1].0,
                n.gm[1].1,
                n.adc_step
            );
        }
        files.push((p, output::noise_scenario(&a, &noise, temp.as_ref()).into_bytes()));
    }
    if let Some(p) = &args.imu_yaml {
        files.push((p, output::kalibr_yaml(&a, &shown)?.into_bytes()));
    }
    let refs: Vec<(&Path, &[u8])> = files.iter().map(|(p, d)| (*p, d.as_slice())).collect();
    fsio::write_all_or_nothing(&refs)?;
    for (p, _) in &files {
        println!("wrote {}", p.display());
    }
    Ok(())
}
