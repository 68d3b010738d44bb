//! PNG plots of a diagnosis (plotters, bitmap backend, the embedded DejaVu Sans through
//! ab_glyph, so no system font library is needed):
//!
//! - `residual_<axis>.png`: the raw residual (one offset removed) over time, before and after
//!   the model, and the drift the noise model sees in what the model leaves, as its own curve
//!   (block means, at most 2000 points);
//! - `allan_<axis>.png`: the Allan deviation of the residual in the static segments before and
//!   after the named terms, with the noise model's line (white floor and random walk), log–log;
//! - `effect_<id>_<axis>.png`: the partial residual (residual − the rest of the model, offset
//!   removed) against the term's fitted contribution, with the line y = x and binned means.
//!
//! The plots are rendered to bytes ([`render_plots`]); the command writes them with its other
//! outputs, all or nothing (`fsio::write_all_or_nothing`).

use super::{DiagnoseError, Diagnosis};
use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// The font (DejaVu Sans; licence in `assets/DejaVuSans.LICENSE`).
pub(crate) static FONT: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");

fn err(path: &Path, e: impl std::fmt::Display) -> DiagnoseError {
    DiagnoseError(format!("{}: {e}", path.display()))
}

/// Block means of `(x, y)` pairs: at most `max` points.
fn decimate(x: &[f64], y: &[f64], max: usize) -> Vec<(f64, f64)> {
    let n = x.len().min(y.len());
    let b = n.div_ceil(max.max(1)).max(1);
    (0..n)
        .step_by(b)
        .map(|s| {
            let e = (s + b).min(n);
            let m = (e - s) as f64;
            (x[s..e].iter().sum::<f64>() / m, y[s..e].iter().sum::<f64>() / m)
        })
        .collect()
}

fn range(v: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) =
        v.filter(|x| x.is_finite()).fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| (a.min(x), b.max(x)));
    if !(hi > lo) {
        let c = if lo.is_finite() { lo } else { 0.0 };
        return (c - 1e-3, c + 1e-3);
    }
    let pad = 0.05 * (hi - lo);
    (lo - pad, hi + pad)
}

/// A plotters error in words: an I/O or encoder error by its own message (the bitmap
/// backend's `Display` is its `Debug`), anything else as plotters says it.
pub fn drawing_error<E: std::error::Error + Send + Sync + 'static>(e: DrawingAreaErrorKind<E>) -> String {
    use plotters::drawing::DrawingAreaErrorKind as A;
    use plotters_backend::DrawingErrorKind as D;
    if let A::BackendError(D::DrawingError(inner)) = &e {
        match (inner as &dyn std::any::Any).downcast_ref::<plotters_bitmap::BitMapBackendError>() {
            Some(plotters_bitmap::BitMapBackendError::IOError(io)) => return io.to_string(),
            Some(plotters_bitmap::BitMapBackendError::ImageError(i)) => return i.to_string(),
            _ => {}
        }
    }
    e.to_string()
}

/// Renders a plot of `size` pixels as PNG bytes (drawn in a private scratch directory, as the
/// encoder writes only to a path). Errors name `what`.
pub fn render_png(
    what: &Path,
    size: (u32, u32),
    f: impl FnOnce(&DrawingArea<BitMapBackend, plotters::coord::Shift>) -> Result<(), String>,
) -> Result<Vec<u8>, DiagnoseError> {
    let scratch =
        crate::fsio::ScratchDir::new("plot").map_err(|e| DiagnoseError(format!("{}: {e}", what.display())))?;
    let tmp = scratch.path().join("plot.png");
    let result = {
        let root = BitMapBackend::new(&tmp, size).into_drawing_area();
        root.fill(&WHITE)
            .map_err(drawing_error)
            .and_then(|_| f(&root))
            .and_then(|_| root.present().map_err(drawing_error))
    };
    result.and_then(|_| std::fs::read(&tmp).map_err(|e| e.to_string())).map_err(|e| err(what, e))
}

/// Renders `dir/name`; returns the path and the PNG bytes (written by the caller with the
/// other outputs).
fn draw(
    dir: &Path,
    name: &str,
    f: impl FnOnce(&DrawingArea<BitMapBackend, plotters::coord::Shift>) -> Result<(), String>,
) -> Result<(PathBuf, Vec<u8>), DiagnoseError> {
    let path = dir.join(name);
    let png = render_png(&path, (1000, 520), f)?;
    Ok((path, png))
}

/// Renders the plots of `d` for the directory `dir`; returns each file's path and PNG bytes,
/// for the caller to write with its other outputs, all or nothing (nothing is written here).
pub fn render_plots(d: &Diagnosis, dir: &Path) -> Result<Vec<(PathBuf, Vec<u8>)>, DiagnoseError> {
    use plotters::style::{FontStyle, register_font};
    let _ = register_font("sans-serif", FontStyle::Normal, FONT);
    let p = &d.prepared;
    let hours: Vec<f64> = p.t.iter().map(|t| t / 3600.0).collect();
    let mut out = Vec::new();
    for fit in &d.axes {
        let ax = super::prep::AXES[fit.axis];
        let y = &p.r[fit.axis];
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
        let my = mean(y);
        let before: Vec<f64> = y.iter().map(|a| (a - my) * 1e3).collect();
        let e: Vec<f64> = y.iter().zip(&fit.prediction).map(|(a, b)| a - b).collect();
        let me = mean(&e);
        let after: Vec<f64> = e.iter().map(|a| (a - me) * 1e3).collect();
        let drift: Vec<f64> = fit.drift.iter().map(|a| (a - me) * 1e3).collect();
        let pb = decimate(&hours, &before, 2000);
        let pa = decimate(&hours, &after, 2000);
        let pd = decimate(&hours, &drift, 2000);
        let (x0, x1) = range(hours.iter().copied());
        let (y0, y1) = range(pb.iter().chain(&pa).map(|q| q.1));
        let title = format!(
            "accelerometer {ax}: REAL − SIM, held-out RMS {:.4} → {:.4} mg",
            fit.heldout_rms.0 * 1e3,
            fit.heldout_rms.1 * 1e3
        );
        out.push(draw(dir, &format!("residual_{ax}.png"), |root| {
            let mut chart = ChartBuilder::on(root)
                .caption(title, ("sans-serif", 20))
                .margin(12)
                .x_label_area_size(40)
                .y_label_area_size(70)
                .build_cartesian_2d(x0..x1, y0..y1)
                .map_err(drawing_error)?;
            chart
                .configure_mesh()
                .x_desc("time [h]")
                .y_desc("residual [mg]")
                .label_style(("sans-serif", 14))
                .draw()
                .map_err(drawing_error)?;
            let cb = RGBColor(214, 39, 40);
            let ca = RGBColor(31, 119, 180);
            chart
                .draw_series(LineSeries::new(pb.iter().copied(), cb.stroke_width(1)))
                .map_err(drawing_error)?
                .label("before (REAL − SIM)")
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 14, y)], cb.stroke_width(2)));
            chart
                .draw_series(LineSeries::new(pa.iter().copied(), ca.stroke_width(1)))
                .map_err(drawing_error)?
                .label("after the found terms")
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 14, y)], ca.stroke_width(2)));
            let cd = RGBColor(44, 160, 44);
            chart
                .draw_series(LineSeries::new(pd.iter().copied(), cd.stroke_width(2)))
                .map_err(drawing_error)?
                .label("drift left (random walk, not subtracted)")
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 14, y)], cd.stroke_width(2)));
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::UpperRight)
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .label_font(("sans-serif", 14))
                .draw()
                .map_err(drawing_error)
        })?);
        if let Some(png) = allan_plot(d, dir, ax)? {
            out.push(png);
        }
        // A term whose held-out cut is not material gets no plot of its own (the report lists
        // it as negligible).
        let negligible = |id: &str| d.report.model.term.iter().any(|t| t.id == id && t.axis == *ax && t.negligible);
        for term in fit.terms.iter().filter(|t| !negligible(t.mech.id())) {
            let partial: Vec<f64> = (0..y.len()).map(|i| y[i] - fit.prediction[i] + term.contribution[i]).collect();
            let off = mean(&partial) - mean(&term.contribution);
            let xs: Vec<f64> = term.contribution.iter().map(|v| v * 1e3).collect();
            let ys: Vec<f64> = partial.iter().map(|v| (v - off) * 1e3).collect();
            // Sort by the regressor for binned means.
            let mut idx: Vec<usize> = (0..xs.len()).collect();
            idx.sort_by(|a, b| xs[*a].total_cmp(&xs[*b]));
            let sx: Vec<f64> = idx.iter().map(|&i| xs[i]).collect();
            let sy: Vec<f64> = idx.iter().map(|&i| ys[i]).collect();
            let bins = decimate(&sx, &sy, 60);
            let pts: Vec<(f64, f64)> =
                (0..xs.len()).step_by(xs.len().div_ceil(3000).max(1)).map(|i| (xs[i], ys[i])).collect();
            let (x0, x1) = range(xs.iter().copied());
            let (y0, y1) = range(pts.iter().map(|q| q.1).chain(bins.iter().map(|q| q.1)));
            let theta = term.theta.map_or(String::new(), |t| format!(", {}", theta_label(term.mech, t)));
            let title = format!("{} on {ax}{theta}: partial residual vs fitted term", term.mech.id());
            out.push(draw(dir, &format!("effect_{}_{ax}.png", term.mech.id()), |root| {
                let mut chart = ChartBuilder::on(root)
                    .caption(title, ("sans-serif", 20))
                    .margin(12)
                    .x_label_area_size(40)
                    .y_label_area_size(70)
                    .build_cartesian_2d(x0..x1, y0..y1)
                    .map_err(drawing_error)?;
                chart
                    .configure_mesh()
                    .x_desc("fitted term [mg]")
                    .y_desc("residual − other terms, offset removed [mg]")
                    .label_style(("sans-serif", 14))
                    .draw()
                    .map_err(drawing_error)?;
                let grey = RGBColor(160, 160, 160);
                chart
                    .draw_series(pts.iter().map(|&(x, y)| Circle::new((x, y), 1, grey.filled())))
                    .map_err(drawing_error)?
                    .label("rows")
                    .legend(move |(x, y)| Circle::new((x + 7, y), 3, grey.filled()));
                let c = RGBColor(214, 39, 40);
                chart
                    .draw_series(bins.iter().map(|&(x, y)| Circle::new((x, y), 4, c.filled())))
                    .map_err(drawing_error)?
                    .label("binned means")
                    .legend(move |(x, y)| Circle::new((x + 7, y), 4, c.filled()));
                chart
                    .draw_series(LineSeries::new([(x0, x0), (x1, x1)], BLACK.stroke_width(2)))
                    .map_err(drawing_error)?
                    .label("y = x")
                    .legend(|(x, y)| PathElement::new([(x, y), (x + 14, y)], BLACK.stroke_width(2)));
                chart
                    .configure_series_labels()
                    .position(SeriesLabelPosition::UpperLeft)
                    .background_style(WHITE.mix(0.85))
                    .border_style(BLACK)
                    .label_font(("sans-serif", 14))
                    .draw()
                    .map_err(drawing_error)
            })?);
        }
    }
    Ok(out)
}

/// `allan_<ax>.png` of [`render_plots`] (`None` when the static segments give no curve).
fn allan_plot(d: &Diagnosis, dir: &Path, ax: &str) -> Result<Option<(PathBuf, Vec<u8>)>, DiagnoseError> {
    let series = |get: fn(&super::report::AllanPoint) -> &super::report::PerAxis<f64>| -> Vec<(f64, f64)> {
        d.report
            .allan
            .iter()
            .filter_map(|pt| get(pt).get(ax).map(|&v| (pt.tau_s, v)))
            .filter(|&(t, v)| t > 0.0 && v > 0.0 && v.is_finite())
            .collect()
    };
    let before = series(|pt| &pt.adev_mg);
    let after = series(|pt| &pt.after_mg);
    let model = series(|pt| &pt.model_mg);
    if before.is_empty() && after.is_empty() {
        return Ok(None);
    }
    let all = || before.iter().chain(&after).chain(&model);
    let (t0, t1) = all().fold((f64::INFINITY, 0.0f64), |(a, b), p| (a.min(p.0), b.max(p.0)));
    let (y0, y1) = all().fold((f64::INFINITY, 0.0f64), |(a, b), p| (a.min(p.1), b.max(p.1)));
    let title = format!("accelerometer {ax}: Allan deviation of REAL − SIM in the static segments");
    draw(dir, &format!("allan_{ax}.png"), |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(title, ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(80)
            .build_cartesian_2d((t0 / 1.5..t1 * 1.5).log_scale(), (y0 / 1.5..y1 * 1.5).log_scale())
            .map_err(drawing_error)?;
        chart
            .configure_mesh()
            .x_desc("averaging time τ [s]")
            .y_desc("Allan deviation [mg]")
            .x_max_light_lines(1)
            .y_max_light_lines(1)
            .x_label_formatter(&|v| format!("{v}"))
            .y_label_formatter(&|v| format!("{v:.3}"))
            .label_style(("sans-serif", 14))
            .draw()
            .map_err(drawing_error)?;
        let cb = RGBColor(214, 39, 40);
        let ca = RGBColor(31, 119, 180);
        for (pts, c, label) in [(&before, cb, "before (REAL − SIM)"), (&after, ca, "after the named terms")] {
            chart
                .draw_series(LineSeries::new(pts.iter().copied(), c.stroke_width(2)))
                .map_err(drawing_error)?
                .label(label)
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 14, y)], c.stroke_width(2)));
            chart.draw_series(pts.iter().map(|&p| Circle::new(p, 3, c.filled()))).map_err(drawing_error)?;
        }
        chart
            .draw_series(DashedLineSeries::new(model.iter().copied(), 6, 4, BLACK.stroke_width(2)))
            .map_err(drawing_error)?
            .label("noise model (white floor + random walk)")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 14, y)], BLACK.stroke_width(2)));
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 14))
            .draw()
            .map_err(drawing_error)
    })
    .map(Some)
}

/// θ with its symbol and unit, as a plot title gives it (`τ = 167 s`, `h = 0.98 °C`).
pub fn theta_label(m: super::mech::Mech, theta: f64) -> String {
    use super::mech::Mech;
    let digits = |v: f64| {
        if v >= 100.0 {
            0
        } else if v >= 10.0 {
            1
        } else if v >= 1.0 {
            2
        } else {
            3
        }
    };
    match m {
        Mech::ThermalHysteresis | Mech::BiasHysteresis => format!("h = {theta:.*} °C", digits(theta)),
        _ => format!("τ = {theta:.*} s", digits(theta)),
    }
}
