//! The plot of `prism tradeoff`: relative MSE against render time, both on
//! log scales, one colour per knob, the Pareto front joined by a line.
//!
//! The PNG is drawn into our own RGB buffer and encoded with the `image`
//! crate; the SVG is drawn by plotters' SVG backend. Text needs a TrueType
//! font read at run time; without one the plot is drawn without text.

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

use prism::core::error::{Error, Result};
use prism::image::output::write_atomic;

use super::{Knob, Row};

/// Plot size in pixels.
const SIZE: (u32, u32) = (1100, 760);

/// Where [`load_font`] looks when no font is given.
const SYSTEM_FONTS: [&str; 3] = [
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
];

/// Reads `path` (or the first system font found) and registers it as
/// plotters' `sans-serif`. The error says what was tried.
pub fn load_font(path: Option<&Path>) -> std::result::Result<(), String> {
    let candidates: Vec<PathBuf> = match path {
        Some(p) => vec![p.to_path_buf()],
        None => SYSTEM_FONTS.iter().map(PathBuf::from).collect(),
    };
    let mut tried = Vec::new();
    for c in &candidates {
        match std::fs::read(c) {
            Ok(bytes) => {
                // plotters keeps fonts for the life of the program.
                let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
                return plotters::style::register_font("sans-serif", FontStyle::Normal, bytes)
                    .map_err(|_| format!("{} is not a usable TrueType font", c.display()));
            }
            Err(e) => tried.push(format!("{}: {e}", c.display())),
        }
    }
    Err(format!("no font for the plot ({})", tried.join("; ")))
}

/// Indices of the rows on the Pareto front: no other row is both at least
/// as fast and at least as accurate (by relMSE) and better in one of them.
pub fn pareto_front(rows: &[Row]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..rows.len()).collect();
    order.sort_by(|&a, &b| {
        rows[a]
            .seconds
            .total_cmp(&rows[b].seconds)
            .then(rows[a].metrics.rel_mse.total_cmp(&rows[b].metrics.rel_mse))
    });
    let mut front = Vec::new();
    let mut best = f64::INFINITY;
    for i in order {
        if rows[i].metrics.rel_mse < best {
            best = rows[i].metrics.rel_mse;
            front.push(i);
        }
    }
    front
}

fn knob_colour(knob: &str) -> RGBColor {
    const PALETTE: [RGBColor; 8] = [
        RGBColor(31, 119, 180),
        RGBColor(255, 127, 14),
        RGBColor(44, 160, 44),
        RGBColor(214, 39, 40),
        RGBColor(148, 103, 189),
        RGBColor(140, 86, 75),
        RGBColor(227, 119, 194),
        RGBColor(23, 190, 207),
    ];
    Knob::ALL
        .iter()
        .position(|k| k.name() == knob)
        .map_or(BLACK, |i| PALETTE[i % PALETTE.len()])
}

/// The label of a point: the knob's value, or `base`.
fn point_label(r: &Row) -> String {
    match r.planned.knob {
        "base" => "base".into(),
        "spp" => format!("{} spp", r.planned.value),
        "max-depth" => format!("depth {}", r.planned.value),
        "min-contribution" => format!("min {}", r.planned.value),
        "light-samples" => format!("{} ls", r.planned.value),
        "russian-roulette" => format!("rr {}", r.planned.value),
        "rr-weight" => format!("rr weight {}", r.planned.value),
        "split" => format!("split {}", r.planned.value),
        "bvh" => format!("bvh {}", r.planned.value),
        _ => r.planned.value.clone(),
    }
}

/// Whether a row can be placed on the log-log axes.
fn plottable(r: &Row) -> bool {
    r.metrics.rel_mse > 0.0 && r.seconds > 0.0
}

/// Draws the plot on `root`. Rows whose relMSE is not positive cannot be
/// placed on the log axis and are left out.
fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    rows: &[Row],
    title: &str,
    text: bool,
) -> std::result::Result<(), String>
where
    DB::ErrorType: 'static,
{
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(e)?;
    let shown: Vec<&Row> = rows.iter().filter(|r| plottable(r)).collect();
    let span = |v: &mut dyn Iterator<Item = f64>| {
        let (lo, hi) = v.fold((f64::INFINITY, 0.0f64), |(l, h), x| (l.min(x), h.max(x)));
        if lo.is_finite() && hi > 0.0 {
            (lo / 1.6, hi * 1.6)
        } else {
            (1e-3, 1.0)
        }
    };
    let (x0, x1) = span(&mut shown.iter().map(|r| r.seconds));
    let (y0, y1) = span(&mut shown.iter().map(|r| r.metrics.rel_mse));

    let mut builder = ChartBuilder::on(root);
    builder.margin(20);
    if text {
        builder
            .caption(title, ("sans-serif", 24))
            .x_label_area_size(50)
            .y_label_area_size(80);
    }
    let mut chart = builder
        .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
        .map_err(e)?;
    let mut mesh = chart.configure_mesh();
    if text {
        mesh.x_desc("render time (s, log scale)")
            .y_desc("relative MSE against the reference (log scale)")
            .label_style(("sans-serif", 15))
            .axis_desc_style(("sans-serif", 17))
            .x_label_formatter(&|v| format!("{v:.3}"))
            .y_label_formatter(&|v| format!("{v:.1e}"));
    } else {
        mesh.x_labels(0).y_labels(0);
    }
    mesh.draw().map_err(e)?;

    // Pareto front under the points.
    let front: Vec<(f64, f64)> = pareto_front(rows)
        .into_iter()
        .map(|i| &rows[i])
        .filter(|r| plottable(r))
        .map(|r| (r.seconds, r.metrics.rel_mse))
        .collect();
    let front_style = ShapeStyle::from(&RGBColor(90, 90, 90)).stroke_width(2);
    let series = chart
        .draw_series(LineSeries::new(front.clone(), front_style))
        .map_err(e)?;
    if text {
        series
            .label("Pareto front")
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], front_style));
    }
    chart
        .draw_series(
            front
                .iter()
                .map(|&p| Circle::new(p, 9, ShapeStyle::from(&BLACK).stroke_width(2))),
        )
        .map_err(e)?;

    // Each knob's points, joined in sweep order through the base.
    let base = rows.iter().find(|r| r.planned.knob == "base");
    let mut names: Vec<&str> = vec!["base"];
    for r in rows {
        if !names.contains(&r.planned.knob) {
            names.push(r.planned.knob);
        }
    }
    for name in names {
        let colour = knob_colour(name);
        let pts: Vec<&Row> = shown
            .iter()
            .copied()
            .filter(|r| r.planned.knob == name)
            .collect();
        if name != "base" && pts.len() > 1 {
            let mut line: Vec<&Row> = pts.clone();
            if let Some(b) = base.filter(|b| plottable(b)) {
                line.push(b);
            }
            // In the order of the knob's values; the base where its value falls.
            if let Some(knob) = Knob::from_name(name) {
                let values = knob.values();
                let rank = |r: &Row| {
                    let v = if r.planned.knob == "base" {
                        knob.value_of(&r.planned.config)
                    } else {
                        r.planned.value.clone()
                    };
                    values.iter().position(|x| *x == v)
                };
                line.retain(|r| rank(r).is_some());
                line.sort_by_key(|r| rank(r));
            }
            chart
                .draw_series(LineSeries::new(
                    line.iter().map(|r| (r.seconds, r.metrics.rel_mse)),
                    colour.mix(0.5).stroke_width(1),
                ))
                .map_err(e)?;
        }
        let series = chart
            .draw_series(pts.iter().map(|r| {
                let p = (r.seconds, r.metrics.rel_mse);
                if name == "base" {
                    TriangleMarker::new(p, 8, colour.filled()).into_dyn()
                } else {
                    Circle::new(p, 5, colour.filled()).into_dyn()
                }
            }))
            .map_err(e)?;
        if text && !pts.is_empty() {
            series
                .label(name)
                .legend(move |(x, y)| Circle::new((x + 10, y), 5, colour.filled()));
        }
        if text {
            chart
                .draw_series(pts.iter().map(|r| {
                    // Beside the marker, not on it.
                    EmptyElement::at((r.seconds, r.metrics.rel_mse))
                        + Text::new(
                            point_label(r),
                            (7, -14),
                            ("sans-serif", 12).into_font().color(&colour),
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
            .label_font(("sans-serif", 15))
            .draw()
            .map_err(e)?;
    }
    root.present().map_err(e)?;
    Ok(())
}

/// Writes `dir/tradeoff.png` and `dir/tradeoff.svg`; returns how many
/// rows could not be shown (relMSE of zero).
pub fn write_plots(dir: &Path, rows: &[Row], title: &str, text: bool) -> Result<usize> {
    write_png_and_svg(
        &dir.join("tradeoff.png"),
        &dir.join("tradeoff.svg"),
        SIZE,
        |root| draw(root, rows, title, text),
        |root| draw(root, rows, title, text),
    )?;
    Ok(rows.iter().filter(|r| !plottable(r)).count())
}

/// Draws a plot twice, with `draw_png` into an RGB bitmap of `size` and
/// with `draw_svg` into an SVG, and writes both files atomically (each
/// error names the file it was for). Shared by the tradeoff and
/// light-field plots.
pub(crate) fn write_png_and_svg(
    png_path: &Path,
    svg_path: &Path,
    size: (u32, u32),
    draw_png: impl FnOnce(&DrawingArea<BitMapBackend<'_>, Shift>) -> std::result::Result<(), String>,
    draw_svg: impl FnOnce(&DrawingArea<SVGBackend<'_>, Shift>) -> std::result::Result<(), String>,
) -> Result<()> {
    let fail = |path: &Path, m: String| Error::Output {
        path: path.to_path_buf(),
        message: m,
    };
    let mut rgb = vec![0u8; size.0 as usize * size.1 as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, size).into_drawing_area();
        draw_png(&root).map_err(|m| fail(png_path, m))?;
    }
    let mut png = Vec::new();
    image::ImageEncoder::write_image(
        image::codecs::png::PngEncoder::new(&mut png),
        &rgb,
        size.0,
        size.1,
        image::ExtendedColorType::Rgb8,
    )
    .map_err(|e| fail(png_path, e.to_string()))?;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        draw_svg(&root).map_err(|m| fail(svg_path, m))?;
    }
    write_atomic(png_path, &png)?;
    write_atomic(svg_path, svg.as_bytes())
}
