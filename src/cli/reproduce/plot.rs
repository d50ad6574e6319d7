//! PNG plots and slice images for the reproduction report (plotters, bitmap backend, with a
//! font embedded from egui's default fonts so that no system font is needed).

use std::path::Path;
use std::sync::Once;

use anyhow::anyhow;
use plotters::prelude::*;

static FONT: Once = Once::new();

fn register_font() {
    FONT.call_once(|| {
        // Failure leaves text undrawn but the plot intact; there is nothing better to do.
        let _ = plotters::style::register_font(
            "sans-serif",
            FontStyle::Normal,
            epaint_default_fonts::UBUNTU_LIGHT,
        );
    });
}

const COLOURS: [RGBColor; 7] = [
    RGBColor(200, 30, 30),
    RGBColor(30, 90, 200),
    RGBColor(30, 150, 60),
    RGBColor(220, 140, 0),
    RGBColor(130, 50, 160),
    RGBColor(90, 90, 90),
    RGBColor(0, 160, 170),
];

/// One curve: name and points `(x, y, error)` (error 0 draws no bar).
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64, f64)>,
}

impl Series {
    pub fn new(name: impl Into<String>, points: Vec<(f64, f64, f64)>) -> Self {
        Self {
            name: name.into(),
            points,
        }
    }
}

/// A line plot with markers and optional error bars.
pub fn line_plot(
    path: &Path,
    title: &str,
    x_desc: &str,
    y_desc: &str,
    series: &[Series],
) -> anyhow::Result<()> {
    register_font();
    let pts = series.iter().flat_map(|s| s.points.iter());
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y, e) in pts {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y - e);
        y1 = y1.max(y + e);
    }
    if x0 >= x1 {
        x1 = x0 + 1.0;
    }
    let pad = 0.05 * (x1 - x0);
    // The y range hugs the data (small differences between curves are the point of a plot).
    let y_pad = 0.08 * (y1 - y0).max(1e-3);
    let (y0, y1) = (y0 - y_pad, y1 + y_pad);
    let root = BitMapBackend::new(path, (760, 460)).into_drawing_area();
    let err = |e: DrawingAreaErrorKind<_>| anyhow!("plot {}: {e:?}", path.display());
    root.fill(&WHITE).map_err(err)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(52)
        .build_cartesian_2d((x0 - pad)..(x1 + pad), y0..y1)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .light_line_style(RGBColor(235, 235, 235))
        .draw()
        .map_err(err)?;
    for (n, s) in series.iter().enumerate() {
        let c = COLOURS[n % COLOURS.len()];
        let line: Vec<(f64, f64)> = s.points.iter().map(|p| (p.0, p.1)).collect();
        chart
            .draw_series(LineSeries::new(line.clone(), c.stroke_width(2)))
            .map_err(err)?
            .label(s.name.clone())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
        chart
            .draw_series(
                line.iter()
                    .map(|&(x, y)| Circle::new((x, y), 3, c.filled())),
            )
            .map_err(err)?;
        let bars =
            s.points.iter().filter(|p| p.2 > 0.0).map(|&(x, y, e)| {
                PathElement::new(vec![(x, y - e), (x, y + e)], c.stroke_width(1))
            });
        chart.draw_series(bars).map_err(err)?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 14))
        .draw()
        .map_err(err)?;
    root.present().map_err(err)?;
    Ok(())
}

/// A 2-D image to show: `width x height` values, row-major, first row at the top.
pub struct Panel {
    pub title: String,
    pub width: usize,
    pub height: usize,
    pub values: Vec<f32>,
    /// The value shown white; `None`: the panel's own maximum.
    pub full_scale: Option<f32>,
}

/// Panels side by side, each scaled from 0 (black) to its full scale (white), enlarged by an
/// integer factor so that a 0.5 mm voxel stays visible.
pub fn panels_png(path: &Path, panels: &[Panel], zoom: usize) -> anyhow::Result<()> {
    register_font();
    let title_h = 26;
    let gap = 8;
    let w: usize = panels.iter().map(|p| p.width * zoom + gap).sum::<usize>() + gap;
    let h = panels.iter().map(|p| p.height * zoom).max().unwrap_or(1) + title_h + gap;
    let root = BitMapBackend::new(path, (w as u32, h as u32)).into_drawing_area();
    let err = |e: DrawingAreaErrorKind<_>| anyhow!("image {}: {e:?}", path.display());
    root.fill(&WHITE).map_err(err)?;
    let mut x0 = gap;
    for p in panels {
        let max = p
            .full_scale
            .unwrap_or_else(|| p.values.iter().copied().fold(0.0f32, f32::max))
            .max(1e-12);
        root.draw(&Text::new(
            p.title.clone(),
            (x0 as i32, 4),
            ("sans-serif", 15).into_font(),
        ))
        .map_err(err)?;
        for row in 0..p.height {
            for col in 0..p.width {
                let v = (p.values[col + p.width * row] / max).clamp(0.0, 1.0);
                let g = (v * 255.0).round() as u8;
                let (px, py) = (x0 + col * zoom, title_h + row * zoom);
                root.draw(&Rectangle::new(
                    [
                        (px as i32, py as i32),
                        ((px + zoom) as i32, (py + zoom) as i32),
                    ],
                    RGBColor(g, g, g).filled(),
                ))
                .map_err(err)?;
            }
        }
        x0 += p.width * zoom + gap;
    }
    root.present().map_err(err)?;
    Ok(())
}

/// An RGB image (`width x height` pixels, row-major, first row at the top) under a title,
/// enlarged by an integer factor.
pub fn rgb_png(
    path: &Path,
    title: &str,
    width: usize,
    height: usize,
    pixels: &[[u8; 3]],
    zoom: usize,
) -> anyhow::Result<()> {
    register_font();
    let (title_h, gap) = (26, 8);
    let (w, h) = (width * zoom + 2 * gap, height * zoom + title_h + gap);
    let root = BitMapBackend::new(path, (w as u32, h as u32)).into_drawing_area();
    let err = |e: DrawingAreaErrorKind<_>| anyhow!("image {}: {e:?}", path.display());
    root.fill(&WHITE).map_err(err)?;
    root.draw(&Text::new(
        title.to_owned(),
        (gap as i32, 4),
        ("sans-serif", 15).into_font(),
    ))
    .map_err(err)?;
    for (n, [r, g, b]) in pixels.iter().enumerate().take(width * height) {
        let (px, py) = (gap + (n % width) * zoom, title_h + (n / width) * zoom);
        root.draw(&Rectangle::new(
            [
                (px as i32, py as i32),
                ((px + zoom) as i32, (py + zoom) as i32),
            ],
            RGBColor(*r, *g, *b).filled(),
        ))
        .map_err(err)?;
    }
    root.present().map_err(err)?;
    Ok(())
}
