//! `bins-cal verify`: the check of §6, T(13). In every check dwell the recorded signals are
//! compensated sample by sample by the core (`Calibration::compensate`) with the T0 constants
//! alone (uncorrected), method 1 and method 2 in its three forms; the error is
//! `Δg = |mean a| − |f_ref|` (|f_ref| = 1 g on a tilter). Writes a table (stdout and
//! `verify.csv`) and one PNG in the style of the paper's Figures 5/6: a panel per check
//! temperature, grouped bars per check position and method, the ±0.3 mg and ±1 mg tolerances
//! as lines.

use super::segments::{self, Segment};
use anyhow::{Context, anyhow, bail};
use bins_cal::calfile::CalibrationFile;
use bins_cal::fsio;
use bins_comp::{Calibration, CalibrationParams, Form, Method};
use std::fmt::Write as _;
use std::path::PathBuf;

/// Arguments of `bins-cal verify`.
#[derive(clap::Args)]
pub struct Args {
    /// Check recordings (format v1 with `pos` and fx/fy/fz), one or several.
    #[arg(long, num_args = 1.., required = true)]
    check: Vec<PathBuf>,
    /// The calibration file (TOML).
    #[arg(long)]
    calib: PathBuf,
    /// Output directory: verify.csv, verify.png.
    #[arg(short, long)]
    output: PathBuf,
    /// Only dwells whose label starts with this (`""`: every labelled dwell).
    #[arg(long, default_value = "CP")]
    pos_prefix: String,
    #[command(flatten)]
    seg: segments::Options,
}

/// The methods compared, with their labels.
pub const METHODS: [(&str, Method); 5] = [
    ("T0 constants", Method::Uncorrected),
    ("method 1", Method::CoefficientCorrection),
    ("method 2 full", Method::OutputCorrection(Form::Full)),
    ("method 2 simplified", Method::OutputCorrection(Form::Simplified)),
    ("method 2 linearized", Method::OutputCorrection(Form::Linearized)),
];

/// Δg [g] of one dwell with one calibration: mean of the per-sample compensated accelerations.
pub fn dg(cal: &Calibration<f64>, s: &Segment) -> f64 {
    let mut sum = [0.0; 3];
    for (u, t) in &s.rows {
        let a = cal.compensate(*u, *t).accel_g;
        for i in 0..3 {
            sum[i] += a[i];
        }
    }
    let n = s.rows.len() as f64;
    let norm = |v: [f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    norm(sum.map(|x| x / n)) - norm(s.f_g)
}

/// One panel: check temperature, then (position, Δg [mg] per method).
pub type Panel = (f64, Vec<(String, [f64; 5])>);

/// Runs `bins-cal verify`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let file = CalibrationFile::read(&args.calib)?;
    let (params, _) = file.to_params().map_err(|e| anyhow!("{}: {e}", args.calib.display()))?;
    let cals: Vec<Calibration<f64>> = METHODS
        .iter()
        .map(|(_, m)| Calibration::new(&params.with_method(*m)))
        .collect::<Result<_, _>>()
        .map_err(|e| anyhow!("{}: {e}", args.calib.display()))?;
    let (all, files) = segments::find_all(&args.check, &args.seg)?;
    let all: Vec<Segment> = all.into_iter().filter(|s| s.pos.starts_with(&args.pos_prefix)).collect();
    let groups = segments::by_temperature(&all, args.seg.temp_tol_c);
    if groups.is_empty() {
        bail!("{files}: no stationary check dwell with a settled temperature");
    }
    let panels: Vec<Panel> = groups
        .iter()
        .map(|(t, segs)| {
            let rows = segs
                .iter()
                .map(|s| {
                    let mut v = [0.0; 5];
                    for (k, c) in cals.iter().enumerate() {
                        v[k] = dg(c, s) * 1e3;
                    }
                    (s.pos.clone(), v)
                })
                .collect();
            (*t, rows)
        })
        .collect();
    let (csv, table) = tables(&panels, &params);
    std::fs::create_dir_all(&args.output).with_context(|| format!("{}", args.output.display()))?;
    let png = plot(&panels, &format!("T0 = {:.2} °C, {}", params.t0_c, args.calib.display()))?;
    print!("{table}");
    fsio::write_atomic(&args.output.join("verify.csv"), csv.as_bytes())?;
    fsio::write_atomic(&args.output.join("verify.png"), &png)?;
    println!("wrote {} and {}", args.output.join("verify.csv").display(), args.output.join("verify.png").display());
    Ok(())
}

/// The CSV (`temp_C,pos,method,dg_mg`) and the printed table (Δg [mg] per dwell and method,
/// then max |Δg| per temperature).
pub fn tables(panels: &[Panel], params: &CalibrationParams) -> (String, String) {
    let mut csv = String::from("temp_C,pos,method,dg_mg\n");
    let mut t = String::new();
    let _ = writeln!(
        t,
        "|g| error Δg = |a| − 1 g [mg], T(13); calibration T0 = {:.2} °C, range {:.1} … {:.1} °C",
        params.t0_c, params.temp_range_c.0, params.temp_range_c.1
    );
    let _ = write!(t, "{:>9} {:<6}", "temp_C", "pos");
    for (name, _) in METHODS {
        let _ = write!(t, " {name:>20}");
    }
    let _ = writeln!(t);
    for (temp, rows) in panels {
        let mut max = [0.0f64; 5];
        for (pos, v) in rows {
            let _ = write!(t, "{temp:>9.2} {pos:<6}");
            for k in 0..5 {
                let _ = write!(t, " {:>+20.4}", v[k]);
                let _ = writeln!(csv, "{temp},{pos},{},{}", METHODS[k].0, v[k]);
                max[k] = max[k].max(v[k].abs());
            }
            let _ = writeln!(t);
        }
        let _ = write!(t, "{temp:>9.2} {:<6}", "max||");
        for m in max {
            let _ = write!(t, " {m:>20.4}");
        }
        let _ = writeln!(t);
    }
    (csv, t)
}

/// The font the plots use (DejaVu Sans, embedded; licence in `assets/DejaVuSans.LICENSE`).
static FONT: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");

/// Renders the panels as a PNG (bytes).
pub fn plot(panels: &[Panel], title: &str) -> anyhow::Result<Vec<u8>> {
    use plotters::prelude::*;
    use plotters::style::{FontStyle, register_font};
    let _ = register_font("sans-serif", FontStyle::Normal, FONT);
    let (w, h) = (1000u32, 420 * panels.len() as u32 + 60);
    let dir = tempdir_png()?;
    let path = dir.join("plot.png");
    {
        let root = BitMapBackend::new(&path, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| anyhow!("plot: {e}"))?;
        let (top, body) = root.split_vertically(70);
        top.draw(&Text::new(
            format!("|g| error in the check positions — {title}"),
            (20, 15),
            ("sans-serif", 20).into_font(),
        ))
        .map_err(|e| anyhow!("plot: {e}"))?;
        let areas = body.split_evenly((panels.len(), 1));
        let colors = [
            RGBColor(120, 120, 120),
            RGBColor(31, 119, 180),
            RGBColor(214, 39, 40),
            RGBColor(255, 127, 14),
            RGBColor(44, 160, 44),
        ];
        // The legend, once, under the title.
        let font = ("sans-serif", 14).into_font();
        let mut x = 20;
        for (k, (name, _)) in METHODS.iter().enumerate() {
            top.draw(&Rectangle::new([(x, 45), (x + 14, 59)], colors[k].filled())).map_err(|e| anyhow!("plot: {e}"))?;
            top.draw(&Text::new(name.to_string(), (x + 20, 45), font.clone())).map_err(|e| anyhow!("plot: {e}"))?;
            x += 40 + 8 * name.len() as i32;
        }
        for (label, style) in [("±0.3 mg", BLACK.stroke_width(2)), ("±1 mg", RGBColor(150, 0, 150).stroke_width(1))] {
            top.draw(&PathElement::new([(x, 52), (x + 20, 52)], style)).map_err(|e| anyhow!("plot: {e}"))?;
            top.draw(&Text::new(label.to_string(), (x + 26, 45), font.clone())).map_err(|e| anyhow!("plot: {e}"))?;
            x += 100;
        }
        for ((temp, rows), area) in panels.iter().zip(areas) {
            let lim = rows.iter().flat_map(|r| r.1).fold(1.2f64, |a, b| a.max(b.abs() * 1.1));
            let n = rows.len().max(1);
            let mut chart = ChartBuilder::on(&area)
                .caption(format!("check at {temp:+.1} °C"), ("sans-serif", 18))
                .margin(10)
                .x_label_area_size(30)
                .y_label_area_size(60)
                .build_cartesian_2d(0f64..n as f64, -lim..lim)
                .map_err(|e| anyhow!("plot: {e}"))?;
            let labels: Vec<String> = rows.iter().map(|r| r.0.clone()).collect();
            chart
                .configure_mesh()
                .disable_x_mesh()
                .x_labels(n * 2 + 1)
                .x_label_formatter(&|x| {
                    let i = x.floor() as usize;
                    if (x - i as f64 - 0.5).abs() < 0.01 {
                        labels.get(i).cloned().unwrap_or_default()
                    } else {
                        String::new()
                    }
                })
                .y_desc("Δg [mg]")
                .label_style(("sans-serif", 14))
                .draw()
                .map_err(|e| anyhow!("plot: {e}"))?;
            let bw = 0.8 / 5.0;
            for k in 0..5 {
                let c = colors[k];
                chart
                    .draw_series(rows.iter().enumerate().map(|(i, r)| {
                        let x0 = i as f64 + 0.1 + k as f64 * bw;
                        Rectangle::new([(x0, 0.0), (x0 + bw * 0.9, r.1[k])], c.filled())
                    }))
                    .map_err(|e| anyhow!("plot: {e}"))?;
            }
            for (tol, style) in [(0.3, BLACK.stroke_width(2)), (1.0, RGBColor(150, 0, 150).stroke_width(1))] {
                for s in [-1.0, 1.0] {
                    chart
                        .draw_series(LineSeries::new([(0.0, s * tol), (n as f64, s * tol)], style))
                        .map_err(|e| anyhow!("plot: {e}"))?;
                }
            }
        }
        root.present().map_err(|e| anyhow!("plot: {e}"))?;
    }
    let bytes = std::fs::read(&path).with_context(|| format!("{}", path.display()))?;
    let _ = std::fs::remove_dir_all(&dir);
    Ok(bytes)
}

/// A private scratch directory for the bitmap backend (which writes files only).
fn tempdir_png() -> anyhow::Result<PathBuf> {
    let d = std::env::temp_dir().join(format!("bins-cal-verify-{}", std::process::id()));
    std::fs::create_dir_all(&d).with_context(|| format!("{}", d.display()))?;
    Ok(d)
}
