//! The plot of `prism lightfield sweep`: relative MSE against cameras per
//! side (left) and against capture time (right), both log-log, one series
//! per synthesis method.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use prism::core::error::Result;

use super::SweepRow;

/// Plot size in pixels.
const SIZE: (u32, u32) = (1200, 560);

fn colour(method: &str) -> RGBColor {
    match method {
        "quadrilinear" => RGBColor(31, 119, 180),
        _ => RGBColor(214, 39, 40),
    }
}

/// Rows that can sit on log axes.
fn plottable(r: &SweepRow) -> bool {
    r.metrics.rel_mse > 0.0 && r.capture_seconds > 0.0
}

/// `(lo, hi)` around the values, for a log axis.
fn span(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values.fold((f64::INFINITY, 0.0f64), |(l, h), x| (l.min(x), h.max(x)));
    if lo.is_finite() && hi > 0.0 {
        (lo / 1.5, hi * 1.5)
    } else {
        (1e-3, 1.0)
    }
}

/// One panel: relMSE against `x(row)`.
fn panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    rows: &[SweepRow],
    x: impl Fn(&SweepRow) -> f64,
    x_desc: &str,
    x_format: &dyn Fn(&f64) -> String,
    text: bool,
) -> std::result::Result<(), String>
where
    DB::ErrorType: 'static,
{
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let shown: Vec<&SweepRow> = rows.iter().filter(|r| plottable(r)).collect();
    let (x0, x1) = span(shown.iter().map(|r| x(r)));
    let (y0, y1) = span(shown.iter().map(|r| r.metrics.rel_mse));
    let mut builder = ChartBuilder::on(area);
    builder.margin(18);
    if text {
        builder.x_label_area_size(48).y_label_area_size(80);
    }
    let mut chart = builder
        .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
        .map_err(e)?;
    let mut mesh = chart.configure_mesh();
    if text {
        mesh.x_desc(x_desc)
            .y_desc("relative MSE against direct renders")
            .label_style(("sans-serif", 14))
            .axis_desc_style(("sans-serif", 16))
            .x_label_formatter(x_format)
            .y_label_formatter(&|v| format!("{v:.1e}"));
    } else {
        mesh.x_labels(0).y_labels(0);
    }
    mesh.draw().map_err(e)?;
    let mut methods: Vec<&str> = Vec::new();
    for r in &shown {
        if !methods.contains(&r.method) {
            methods.push(r.method);
        }
    }
    for m in methods {
        let c = colour(m);
        let pts: Vec<(f64, f64)> = shown
            .iter()
            .filter(|r| r.method == m)
            .map(|r| (x(r), r.metrics.rel_mse))
            .collect();
        chart
            .draw_series(LineSeries::new(pts.clone(), c.stroke_width(2)))
            .map_err(e)?;
        let series = chart
            .draw_series(pts.iter().map(|&p| Circle::new(p, 5, c.filled())))
            .map_err(e)?;
        if text {
            series
                .label(m)
                .legend(move |(x, y)| Circle::new((x + 10, y), 5, c.filled()));
            chart
                .draw_series(shown.iter().filter(|r| r.method == m).map(|r| {
                    EmptyElement::at((x(r), r.metrics.rel_mse))
                        + Text::new(
                            format!("{0}x{0}", r.grid),
                            (7, -14),
                            ("sans-serif", 12).into_font().color(&c),
                        )
                }))
                .map_err(e)?;
        }
    }
    if text {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 14))
            .draw()
            .map_err(e)?;
    }
    Ok(())
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    rows: &[SweepRow],
    title: &str,
    text: bool,
) -> std::result::Result<(), String>
where
    DB::ErrorType: 'static,
{
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(e)?;
    let body = if text {
        root.titled(title, ("sans-serif", 20)).map_err(e)?
    } else {
        root.clone()
    };
    let (left, right) = body.split_horizontally(SIZE.0 / 2);
    panel(
        &left,
        rows,
        |r| r.grid as f64,
        "cameras per side of the grid (log scale)",
        &|v| format!("{v:.0}"),
        text,
    )?;
    panel(
        &right,
        rows,
        |r| r.capture_seconds,
        "capture time, s (log scale)",
        &|v| format!("{v:.2}"),
        text,
    )?;
    root.present().map_err(e)?;
    Ok(())
}

/// Writes `dir/lightfield_sweep.png` and `.svg`.
pub fn write_plots(dir: &Path, rows: &[SweepRow], title: &str, text: bool) -> Result<()> {
    crate::tradeoff::plot::write_png_and_svg(
        &dir.join("lightfield_sweep.png"),
        &dir.join("lightfield_sweep.svg"),
        SIZE,
        |root| draw(root, rows, title, text),
        |root| draw(root, rows, title, text),
    )
}
