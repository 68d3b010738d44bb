//! `bins-cal verify`: the check of §6, T(13). In every check dwell the recorded signals are
//! compensated sample by sample by the core (`Calibration::compensate`) with the T0 constants
//! alone (uncorrected), method 1 and method 2 in its three forms; the error is
//! `Δg = |mean a| − |f_ref|` (|f_ref| = 1 g on a tilter). Writes a table (stdout and
//! `verify.csv`) and one PNG in the style of the paper's Figures 5/6: a panel per check
//! temperature, grouped bars per check position and method, the ±0.3 mg and ±1 mg tolerances
//! as lines.
//!
//! With `--replayed` (the output CSV of `bins-cal replay` or of the replay firmware, one per
//! check recording) the same dwells are also averaged from that per-sample output: a column
//! `replayed` beside the host's, so the firmware's |g| error is read on the very dwells the
//! host's is.

use anyhow::{Context, anyhow, bail};
use bins_cal::calfile::CalibrationFile;
use bins_cal::calib::dynamics;
use bins_cal::calib::segments::{self, Segment};
use bins_cal::diagnose::plot::drawing_error;
use bins_cal::fsio;
use bins_cal::recording::Table;
use bins_comp::dynamics::Effective;
use bins_comp::{Calibration, CalibrationParams, Form, Method, Status};
use std::fmt::Write as _;
use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

/// Arguments of `bins-cal verify`.
#[derive(clap::Args)]
pub struct Args {
    /// Check recordings (format v1 with `pos` and fx/fy/fz), one or several.
    #[arg(long, num_args = 1.., required = true)]
    check: Vec<PathBuf>,
    /// The calibration: a calibration file (TOML) or a blob, told apart by the content.
    #[arg(long)]
    calib: PathBuf,
    /// Output directory: verify.csv, verify.png.
    #[arg(short, long)]
    output: PathBuf,
    /// Only dwells whose label starts with this (`""`: every labelled dwell).
    #[arg(long, default_value = "CP")]
    pos_prefix: String,
    /// Per-sample output of the calibration's method on each check recording, in the same
    /// order (`t_s,ax_g,ay_g,az_g,status`, from `bins-cal replay` or `cargo xtask replay`): its
    /// Δg in the same dwells is added as the method `replayed`.
    #[arg(long, num_args = 1.., value_name = "OUT.csv")]
    replayed: Vec<PathBuf>,
    /// Also check the dwells during temperature ramps (faster than `--max-rate-c-per-min`),
    /// in two panels: heating and cooling.
    #[arg(long)]
    ramps: bool,
    #[command(flatten)]
    seg: segments::Options,
}

/// The label of the column compensated with the calibration's thermal dynamics.
pub const WITH_DYNAMICS: &str = "with dynamics";

/// The methods compared, with their labels.
pub const METHODS: [(&str, Method); 5] = [
    ("T0 constants", Method::Uncorrected),
    ("method 1", Method::CoefficientCorrection),
    ("method 2 full", Method::OutputCorrection(Form::Full)),
    ("method 2 simplified", Method::OutputCorrection(Form::Simplified)),
    ("method 2 linearized", Method::OutputCorrection(Form::Linearized)),
];

/// Δg \[g\] of one dwell with one calibration: mean of the per-sample compensated accelerations.
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

/// The label of the `--replayed` column.
pub const REPLAYED: &str = "replayed";

/// One panel: its title and phase (`hold`, `heating`, `cooling`), then per dwell (position,
/// mean temperature [°C], Δg \[mg\] per method, in the order of the method labels).
pub type Panel = (String, &'static str, Vec<(String, f64, Vec<f64>)>);

/// The largest acceleration a replayed output may hold \[g\]: far beyond any accelerometer
/// the tool calibrates; a larger value is a corrupted file, not a reading.
pub const MAX_REPLAYED_G: f64 = 1.0e4;

/// The columns of a replayed output, as `bins-cal replay` writes them.
const REPLAYED_COLUMNS: [&str; 5] = ["t_s", "ax_g", "ay_g", "az_g", "status"];

/// The positions of [`REPLAYED_COLUMNS`] in the header of `t`, read from `path`.
fn replayed_columns(path: &Path, t: &Table) -> anyhow::Result<[usize; 5]> {
    let found = REPLAYED_COLUMNS.map(|name| t.header.iter().position(|h| h == name));
    match found {
        [Some(a), Some(b), Some(c), Some(d), Some(e)] => Ok([a, b, c, d, e]),
        _ => bail!(
            "{}: line 1: expected the header `{}` of a replay output, got `{}`",
            path.display(),
            REPLAYED_COLUMNS.join(","),
            t.header.join(",")
        ),
    }
}

/// A replayed output CSV: rows `(t_s, accel \[g\], status bits)` in file order.
pub struct Replayed {
    path: PathBuf,
    rows: Vec<(f64, [f64; 3], u32)>,
}

impl Replayed {
    /// Reads `t_s,ax_g,ay_g,az_g,status` (columns found by name, through
    /// [`recording::Table`]); errors name the file and the line.
    pub fn read(path: &Path) -> anyhow::Result<Replayed> {
        let src = BufReader::new(File::open(path).with_context(|| path.display().to_string())?);
        let mut at = None;
        let mut rows = Vec::new();
        let table = Table::for_each_row(src, path, |t, line, cells| {
            let [c_t, c_x, c_y, c_z, c_status] = match at {
                Some(at) => at,
                None => *at.insert(replayed_columns(path, t)?),
            };
            let bad = |what: &str| anyhow!("{}: line {line}: {what}: `{}`", path.display(), cells.join(","));
            let num = |i: usize| {
                let x = cells[i].parse::<f64>().map_err(|_| bad("not a number"))?;
                if !x.is_finite() {
                    return Err(bad(&format!("`{}` is not a finite number", cells[i])));
                }
                if i != c_t && x.abs() > MAX_REPLAYED_G {
                    return Err(bad(&format!("{x} g is beyond ±{MAX_REPLAYED_G} g: not a replayed acceleration")));
                }
                Ok(x)
            };
            let status = cells[c_status].parse::<u32>().map_err(|_| bad("status is not an unsigned integer"))?;
            rows.push((num(c_t)?, [num(c_x)?, num(c_y)?, num(c_z)?], status));
            anyhow::Ok(())
        })?;
        if at.is_none() {
            replayed_columns(path, &table)?;
        }
        Ok(Replayed { path: path.to_path_buf(), rows })
    }

    /// Δg \[g\] of one dwell from the replayed output: the mean of its rows in the dwell's time
    /// span, which must be as many as the recording's (else it is not this recording's
    /// replay) and calibrated.
    pub fn dg(&self, s: &Segment) -> anyhow::Result<f64> {
        let first = self.rows.partition_point(|r| r.0 < s.t_s.0);
        let end = self.rows.partition_point(|r| r.0 <= s.t_s.1);
        let rows = self.rows.get(first..end).unwrap_or_default();
        if rows.len() != s.rows.len() {
            bail!(
                "{}: {} rows in {} … {} s (dwell {} of {}), the recording has {}: not the replay of that recording",
                self.path.display(),
                rows.len(),
                s.t_s.0,
                s.t_s.1,
                s.pos,
                s.file.display(),
                s.rows.len()
            );
        }
        if rows.iter().any(|r| r.2 & Status::INVALID_CALIBRATION.0 != 0) {
            bail!(
                "{}: dwell {} of {} ({} … {} s): samples flagged INVALID_CALIBRATION (no valid calibration was used)",
                self.path.display(),
                s.pos,
                s.file.display(),
                s.t_s.0,
                s.t_s.1
            );
        }
        let n = rows.len() as f64;
        let mean: [f64; 3] = std::array::from_fn(|i| rows.iter().map(|r| r.1[i]).sum::<f64>() / n);
        let norm = |v: [f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        Ok(norm(mean) - norm(s.f_g))
    }
}

/// Runs `bins-cal verify`.
pub fn run(args: Args) -> anyhow::Result<()> {
    fsio::refuse_overwriting_inputs(
        args.check.iter().chain(&args.replayed).chain([&args.calib]),
        ["verify.csv", "verify.png"].map(|f| args.output.join(f)),
    )?;
    let (file, _) = CalibrationFile::read_checked(&args.calib)?;
    let (params, _) = file.to_params().map_err(|e| anyhow!("{}: {e}", args.calib.display()))?;
    let cals: Vec<Calibration<f64>> = METHODS
        .iter()
        .map(|(_, m)| Calibration::new(&params.with_method(*m)))
        .collect::<Result<_, _>>()
        .map_err(|e| anyhow!("{}: {e}", args.calib.display()))?;
    if !args.replayed.is_empty() && args.replayed.len() != args.check.len() {
        bail!(
            "--replayed: {} file(s) for {} check recording(s): give one replay output per recording, in the same order",
            args.replayed.len(),
            args.check.len()
        );
    }
    let replayed: Vec<Replayed> = args.replayed.iter().map(|p| Replayed::read(p)).collect::<Result<_, _>>()?;
    let mut names: Vec<&str> = METHODS.iter().map(|m| m.0).collect();
    if !replayed.is_empty() {
        names.push(REPLAYED);
    }
    let dynamics = file.dynamics().map_err(|e| anyhow!("{}: {e}", args.calib.display()))?;
    let own = Calibration::new(&params).map_err(|e| anyhow!("{}: {e}", args.calib.display()))?;
    if dynamics.is_some() {
        names.insert(METHODS.len(), WITH_DYNAMICS);
    }
    let seg_opt =
        if args.ramps { segments::Options { max_rate_c_per_min: f64::INFINITY, ..args.seg } } else { args.seg };
    let (all, files) = segments::find_all(&args.check, &seg_opt)?;
    let all: Vec<Segment> = all.into_iter().filter(|s| s.pos.starts_with(&args.pos_prefix)).collect();
    // With dynamics: the effective temperature of the rows of each check recording's dwells
    // (the dynamics run over every row, one at a time).
    let mut effective: Vec<(Vec<f64>, Vec<Effective<f64>>)> = Vec::new();
    if let Some(d) = &dynamics {
        for p in &args.check {
            let mut spans: Vec<(f64, f64)> = all.iter().filter(|s| s.file == *p).map(|s| s.t_s).collect();
            spans.sort_by(|a, b| a.0.total_cmp(&b.0));
            // The dwells of one recording do not overlap: the last one starting before t.
            let in_dwell = |t: f64| {
                let k = spans.partition_point(|s| s.0 <= t);
                k > 0 && t <= spans[k - 1].1
            };
            effective.push(dynamics::run_core_kept(p, d, in_dwell)?);
        }
    }
    let dg_dyn = |s: &Segment| -> anyhow::Result<f64> {
        let (Some(d), Some(k)) = (&dynamics, args.check.iter().position(|p| *p == s.file)) else { return Ok(f64::NAN) };
        let (t, e) = &effective[k];
        let a = t.partition_point(|&x| x < s.t_s.0);
        if a + s.rows.len() > e.len() {
            bail!("{}: dwell {} at {} s: rows out of step with the recording", s.file.display(), s.pos, s.t_s.0);
        }
        let mut sum = [0.0; 3];
        for (j, (u, _)) in s.rows.iter().enumerate() {
            let acc = dynamics::compensate(&own, d, *u, &e[a + j]);
            for i in 0..3 {
                sum[i] += acc[i];
            }
        }
        let n = s.rows.len() as f64;
        let norm = |v: [f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        Ok(norm(sum.map(|x| x / n)) - norm(s.f_g))
    };
    let ramp = |s: &Segment| s.rate_c_per_min.abs() > args.seg.max_rate_c_per_min;
    let holds: Vec<Segment> = all.iter().filter(|s| !ramp(s)).cloned().collect();
    let groups = segments::by_temperature(&holds, args.seg.temp_tol_c);
    if groups.is_empty() && !args.ramps {
        bail!("{files}: no stationary check dwell with a settled temperature");
    }
    let values = |s: &Segment| -> anyhow::Result<Vec<f64>> {
        let mut v: Vec<f64> = cals.iter().map(|c| dg(c, s) * 1e3).collect();
        if dynamics.is_some() {
            v.push(dg_dyn(s)? * 1e3);
        }
        if let Some(r) = args.check.iter().position(|p| *p == s.file).and_then(|k| replayed.get(k)) {
            v.push(r.dg(s)? * 1e3);
        }
        Ok(v)
    };
    let mut panels: Vec<Panel> = Vec::new();
    for (t, segs) in &groups {
        let mut rows = Vec::new();
        for s in segs {
            rows.push((s.pos.clone(), *t, values(s)?));
        }
        panels.push((format!("check at {t:+.1} °C"), "hold", rows));
    }
    if args.ramps {
        for (phase, heating) in [("heating", true), ("cooling", false)] {
            let mut rows = Vec::new();
            for s in all.iter().filter(|s| ramp(s) && (s.rate_c_per_min > 0.0) == heating) {
                rows.push((format!("{} {:+.0}", s.pos, s.temp_c), s.temp_c, values(s)?));
            }
            if !rows.is_empty() {
                let (lo, hi) =
                    rows.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |a, r| (a.0.min(r.1), a.1.max(r.1)));
                panels.push((format!("checks during {phase} ramps, {lo:+.0} … {hi:+.0} °C"), phase, rows));
            }
        }
        if panels.is_empty() {
            bail!("{files}: no stationary check dwell");
        }
    }
    let (csv, table) = tables(&panels, &params, &names);
    let png = plot(&panels, &names, &format!("T0 = {:.2} °C, {}", params.t0_c, args.calib.display()))?;
    print!("{table}");
    // Both or neither; a directory created here goes again when they do not appear (an
    // error, or a signal before the renames: fsio::OutputDir).
    let created = fsio::OutputDir::create(&args.output)?;
    let (csv_path, png_path) = (args.output.join("verify.csv"), args.output.join("verify.png"));
    fsio::write_all_or_nothing(&[(&csv_path, csv.as_bytes()), (&png_path, &png)])?;
    created.keep();
    println!("wrote {} and {}", args.output.join("verify.csv").display(), args.output.join("verify.png").display());
    Ok(())
}

/// The CSV (`temp_C,pos,method,dg_mg,phase`) and the printed table (Δg \[mg\] per dwell and
/// method, then max |Δg| per panel); `names` labels the methods of each row's values.
pub fn tables(panels: &[Panel], params: &CalibrationParams, names: &[&str]) -> (String, String) {
    let mut csv = String::from("temp_C,pos,method,dg_mg,phase\n");
    let mut t = String::new();
    let _ = writeln!(
        t,
        "|g| error Δg = |a| − 1 g [mg], T(13); calibration T0 = {:.2} °C, range {:.1} … {:.1} °C",
        params.t0_c, params.temp_range_c.0, params.temp_range_c.1
    );
    for (title, phase, rows) in panels {
        let _ = writeln!(t, "{title}:");
        let _ = write!(t, "{:>9} {:<10}", "temp_C", "pos");
        for name in names {
            let _ = write!(t, " {name:>20}");
        }
        let _ = writeln!(t);
        let mut max = vec![0.0f64; names.len()];
        for (pos, temp, v) in rows {
            let pos_only = pos.split(' ').next().unwrap_or(pos);
            let _ = write!(t, "{temp:>9.2} {pos_only:<10}");
            for (k, name) in names.iter().enumerate() {
                let x = v.get(k).copied().unwrap_or(f64::NAN);
                let _ = write!(t, " {x:>+20.4}");
                let _ = writeln!(csv, "{temp},{pos_only},{name},{x},{phase}");
                max[k] = max[k].max(x.abs());
            }
            let _ = writeln!(t);
        }
        let _ = write!(t, "{:>9} {:<10}", "", "max||");
        for m in max {
            let _ = write!(t, " {m:>20.4}");
        }
        let _ = writeln!(t);
    }
    (csv, t)
}

/// The font the plots use (DejaVu Sans, embedded; licence in `assets/DejaVuSans.LICENSE`).
static FONT: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");

/// Renders the panels as a PNG (bytes): a bar per method of `names` (at most seven).
pub fn plot(panels: &[Panel], names: &[&str], title: &str) -> anyhow::Result<Vec<u8>> {
    use plotters::prelude::*;
    use plotters::style::{FontStyle, register_font};
    let _ = register_font("sans-serif", FontStyle::Normal, FONT);
    let (w, h) = (1000u32, 420 * panels.len() as u32 + 60);
    let dir = fsio::ScratchDir::new("verify")?;
    let path = dir.path().join("plot.png");
    {
        let root = BitMapBackend::new(&path, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| anyhow!("plot: {}", drawing_error(e)))?;
        let (top, body) = root.split_vertically(70);
        top.draw(&Text::new(
            format!("|g| error in the check positions — {title}"),
            (20, 15),
            ("sans-serif", 20).into_font(),
        ))
        .map_err(|e| anyhow!("plot: {}", drawing_error(e)))?;
        let areas = body.split_evenly((panels.len(), 1));
        let colors = [
            RGBColor(120, 120, 120),
            RGBColor(31, 119, 180),
            RGBColor(214, 39, 40),
            RGBColor(255, 127, 14),
            RGBColor(44, 160, 44),
            RGBColor(148, 103, 189),
            RGBColor(23, 190, 207),
        ];
        let m = names.len().min(colors.len());
        // The legend, once, under the title.
        let font = ("sans-serif", 14).into_font();
        let mut x = 20;
        for (k, name) in names.iter().take(m).enumerate() {
            top.draw(&Rectangle::new([(x, 45), (x + 14, 59)], colors[k].filled()))
                .map_err(|e| anyhow!("plot: {}", drawing_error(e)))?;
            top.draw(&Text::new(name.to_string(), (x + 20, 45), font.clone()))
                .map_err(|e| anyhow!("plot: {}", drawing_error(e)))?;
            x += 30 + 7 * name.len() as i32;
        }
        for (label, style) in [("±0.3 mg", BLACK.stroke_width(2)), ("±1 mg", RGBColor(150, 0, 150).stroke_width(1))] {
            top.draw(&PathElement::new([(x, 52), (x + 20, 52)], style))
                .map_err(|e| anyhow!("plot: {}", drawing_error(e)))?;
            top.draw(&Text::new(label.to_string(), (x + 26, 45), font.clone()))
                .map_err(|e| anyhow!("plot: {}", drawing_error(e)))?;
            x += 100;
        }
        for ((title, phase, rows), area) in panels.iter().zip(areas) {
            if *phase != "hold" {
                ramp_panel(&area, title, rows, &colors[..m])?;
                continue;
            }
            let lim = rows.iter().flat_map(|r| r.2.iter()).fold(1.2f64, |a, b| a.max(b.abs() * 1.1));
            let n = rows.len().max(1);
            let mut chart = ChartBuilder::on(&area)
                .caption(title.as_str(), ("sans-serif", 18))
                .margin(10)
                .x_label_area_size(30)
                .y_label_area_size(60)
                .build_cartesian_2d(0f64..n as f64, -lim..lim)
                .map_err(|e| anyhow!("plot: {}", drawing_error(e)))?;
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
                .map_err(|e| anyhow!("plot: {}", drawing_error(e)))?;
            let bw = 0.8 / m as f64;
            for (k, c) in colors.iter().take(m).enumerate() {
                chart
                    .draw_series(rows.iter().enumerate().map(|(i, r)| {
                        let x0 = i as f64 + 0.1 + k as f64 * bw;
                        Rectangle::new([(x0, 0.0), (x0 + bw * 0.9, r.2.get(k).copied().unwrap_or(0.0))], c.filled())
                    }))
                    .map_err(|e| anyhow!("plot: {}", drawing_error(e)))?;
            }
            for (tol, style) in [(0.3, BLACK.stroke_width(2)), (1.0, RGBColor(150, 0, 150).stroke_width(1))] {
                for s in [-1.0, 1.0] {
                    chart
                        .draw_series(LineSeries::new([(0.0, s * tol), (n as f64, s * tol)], style))
                        .map_err(|e| anyhow!("plot: {}", drawing_error(e)))?;
                }
            }
        }
        root.present().map_err(|e| anyhow!("plot: {}", drawing_error(e)))?;
    }
    let bytes = std::fs::read(&path).with_context(|| format!("{}", path.display()))?;
    Ok(bytes)
}

/// A panel of dwells during a ramp: Δg against the dwell's temperature, a point per dwell and
/// method (the T0 constants, whose error is tens of times larger, are left out: they are in
/// `verify.csv`).
fn ramp_panel<DB: plotters::prelude::DrawingBackend<ErrorType: 'static>>(
    area: &plotters::prelude::DrawingArea<DB, plotters::coord::Shift>,
    title: &str,
    rows: &[(String, f64, Vec<f64>)],
    colors: &[plotters::style::RGBColor],
) -> anyhow::Result<()> {
    use plotters::prelude::*;
    let (lo, hi) = rows.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |a, r| (a.0.min(r.1), a.1.max(r.1)));
    let lim = rows.iter().flat_map(|r| r.2.iter().skip(1)).fold(1.2f64, |a, b| a.max(b.abs() * 1.1));
    let mut chart = ChartBuilder::on(area)
        .caption(format!("{title} (T0 constants off scale, in verify.csv)"), ("sans-serif", 18))
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(60)
        .build_cartesian_2d((lo - 2.0)..(hi + 2.0), -lim..lim)
        .map_err(|e| anyhow!("plot: {}", drawing_error(e)))?;
    chart
        .configure_mesh()
        .x_desc("temperature read by the unit [°C]")
        .y_desc("Δg [mg]")
        .label_style(("sans-serif", 14))
        .draw()
        .map_err(|e| anyhow!("plot: {}", drawing_error(e)))?;
    for (k, c) in colors.iter().enumerate().skip(1) {
        chart
            .draw_series(
                rows.iter().filter_map(|r| {
                    r.2.get(k).filter(|v| v.is_finite()).map(|v| Circle::new((r.1, *v), 3, c.filled()))
                }),
            )
            .map_err(|e| anyhow!("plot: {}", drawing_error(e)))?;
    }
    for (tol, style) in [(0.3, BLACK.stroke_width(2)), (1.0, RGBColor(150, 0, 150).stroke_width(1))] {
        for s in [-1.0, 1.0] {
            chart
                .draw_series(LineSeries::new([(lo - 2.0, s * tol), (hi + 2.0, s * tol)], style))
                .map_err(|e| anyhow!("plot: {}", drawing_error(e)))?;
        }
    }
    Ok(())
}
