//! The PNG of `bins-cal allan --plot`: one panel per channel, log–log, the deviation at each τ
//! with its confidence band, the fitted IEEE terms as lines and their sum.

use super::output::Shown;
use crate::diagnose::plot::{drawing_error, render_png};
use plotters::prelude::*;
use std::path::Path;

/// The font (DejaVu Sans; licence in `assets/DejaVuSans.LICENSE`).
static FONT: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");

/// The terms' names and colours.
const TERMS: [(&str, RGBColor); 5] = [
    ("Q (τ⁻¹)", RGBColor(150, 150, 150)),
    ("N (τ^-½)", RGBColor(0, 140, 60)),
    ("B (flat)", RGBColor(200, 120, 0)),
    ("K (τ^+½)", RGBColor(160, 0, 160)),
    ("R (τ)", RGBColor(120, 80, 40)),
];

/// Renders the panels of `channels` as PNG bytes (`what` names the file in errors).
pub fn render(what: &Path, title: &str, channels: &[Shown]) -> anyhow::Result<Vec<u8>> {
    use plotters::style::{FontStyle, register_font};
    let _ = register_font("sans-serif", FontStyle::Normal, FONT);
    let cols = if channels.len() > 1 { 2 } else { 1 };
    let rows = channels.len().div_ceil(cols).max(1);
    let size = (if cols == 2 { 1400 } else { 900 }, 60 + 520 * rows as u32);
    render_png(what, size, |root| {
        let (top, body) = root.split_vertically(50);
        top.titled(title, ("sans-serif", 22)).map_err(drawing_error)?;
        let areas = body.split_evenly((rows, cols));
        for (c, area) in channels.iter().zip(areas.iter()) {
            panel(area, c)?;
        }
        Ok(())
    })
    .map_err(|e| anyhow::anyhow!("{e}"))
}

fn panel<DB: DrawingBackend>(area: &DrawingArea<DB, plotters::coord::Shift>, c: &Shown) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let pts: Vec<_> = c.points.iter().filter(|p| p.dev > 0.0 && p.tau_s > 0.0).collect();
    if pts.is_empty() {
        return Ok(());
    }
    let (t0, t1) = (pts[0].tau_s / 1.5, pts[pts.len() - 1].tau_s * 1.5);
    let lo = pts.iter().map(|p| p.interval.0.max(p.dev * 1e-3)).fold(f64::INFINITY, f64::min);
    let hi = pts.iter().map(|p| p.interval.1).fold(0.0, f64::max);
    let (y0, y1) = (lo / 2.0, hi * 2.0);
    let mut chart = ChartBuilder::on(area)
        .caption(format!("{} [{}]", c.name, c.unit), ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(80)
        .build_cartesian_2d((t0..t1).log_scale(), (y0..y1).log_scale())
        .map_err(drawing_error)?;
    chart
        .configure_mesh()
        .x_desc("τ [s]")
        .y_desc(format!("Allan deviation [{}]", c.unit))
        .y_label_formatter(&|v| format!("{v:.1e}"))
        .x_max_light_lines(1)
        .y_max_light_lines(1)
        .x_label_formatter(&|v| format!("{v:.3}"))
        .draw()
        .map_err(drawing_error)?;
    // The interval band.
    let mut band: Vec<(f64, f64)> = pts.iter().map(|p| (p.tau_s, p.interval.1)).collect();
    band.extend(pts.iter().rev().map(|p| (p.tau_s, p.interval.0.max(y0))));
    chart.draw_series(std::iter::once(Polygon::new(band, RGBColor(70, 110, 220).mix(0.2)))).map_err(drawing_error)?;
    // The term lines and their sum.
    let grid: Vec<f64> = (0..=200).map(|k| t0 * (t1 / t0).powf(k as f64 / 200.0)).collect();
    for (i, (name, color)) in TERMS.iter().enumerate() {
        let line: Vec<(f64, f64)> =
            grid.iter().map(|&t| (t, c.terms.parts(t)[i].sqrt())).filter(|p| p.1 > y0 && p.1 < y1).collect();
        if line.len() < 2 {
            continue;
        }
        chart
            .draw_series(DashedLineSeries::new(line, 6, 4, color.stroke_width(1)))
            .map_err(drawing_error)?
            .label(*name)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2)));
    }
    let fit: Vec<(f64, f64)> =
        grid.iter().map(|&t| (t, c.terms.avar(t).sqrt())).filter(|p| p.1 > y0 && p.1 < y1).collect();
    chart
        .draw_series(LineSeries::new(fit, BLACK.stroke_width(1)))
        .map_err(drawing_error)?
        .label("terms' sum")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], BLACK.stroke_width(2)));
    let blue = RGBColor(30, 70, 200);
    chart
        .draw_series(LineSeries::new(pts.iter().map(|p| (p.tau_s, p.dev)), blue.stroke_width(2)))
        .map_err(drawing_error)?
        .label("overlapping ADEV, interval band")
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], blue.stroke_width(2)));
    chart.draw_series(pts.iter().map(|p| Circle::new((p.tau_s, p.dev), 3, blue.filled()))).map_err(drawing_error)?;
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 13))
        .draw()
        .map_err(drawing_error)?;
    Ok(())
}
