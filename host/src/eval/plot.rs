//! Line charts as PNG, drawn with `plotters` on its bitmap backend: axes with ticks, real text in
//! DejaVu Sans (the `dejavu` crate's copy, compiled in: no system fonts are needed), a legend on
//! the right, and optional error bars (e.g. the Wilson intervals of the recognition accuracies).

use std::sync::OnceLock;

use image::{Rgba, RgbaImage};
use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::{register_font, FontStyle};

/// The font family the charts are written in (registered from [`dejavu`] on first use).
const FONT: &str = "sans-serif";

/// One line of a chart.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend label.
    pub label: String,
    /// (x, y) points in drawing order (non-finite values are skipped).
    pub points: Vec<(f64, f64)>,
    /// An error bar (low, high) per point, in the order of `points` (empty: no error bars).
    pub intervals: Vec<(f64, f64)>,
}

/// A chart.
#[derive(Debug, Clone, PartialEq)]
pub struct Chart {
    /// Title above the plot.
    pub title: String,
    /// x-axis label.
    pub x_label: String,
    /// y-axis label (written along the axis).
    pub y_label: String,
    /// Logarithmic x axis.
    pub log_x: bool,
    /// Fixed y range (otherwise from the data, starting at 0 when all values are positive).
    pub y_range: Option<(f64, f64)>,
    /// The lines.
    pub series: Vec<Series>,
}

/// Why a chart could not be drawn.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// The compiled-in font was refused by the text renderer.
    #[error("the chart font cannot be loaded: {0}")]
    Font(String),
    /// The drawing failed.
    #[error("drawing the chart: {0}")]
    Draw(String),
}

impl<E: std::error::Error + Send + Sync> From<DrawingAreaErrorKind<E>> for PlotError {
    fn from(e: DrawingAreaErrorKind<E>) -> Self {
        PlotError::Draw(e.to_string())
    }
}

/// Line colours (distinguishable on white).
const PALETTE: [[u8; 3]; 12] = [
    [31, 119, 180],
    [255, 127, 14],
    [44, 160, 44],
    [214, 39, 40],
    [148, 103, 189],
    [140, 86, 75],
    [227, 119, 194],
    [127, 127, 127],
    [188, 189, 34],
    [23, 190, 207],
    [0, 0, 0],
    [255, 187, 120],
];

/// The colour of series `k`.
pub fn series_color(k: usize) -> Rgba<u8> {
    let c = PALETTE[k % PALETTE.len()];
    Rgba([c[0], c[1], c[2], 255])
}

fn plot_color(k: usize) -> RGBColor {
    let c = PALETTE[k % PALETTE.len()];
    RGBColor(c[0], c[1], c[2])
}

/// Registers the chart font once per process.
fn ensure_font() -> Result<(), PlotError> {
    static REGISTERED: OnceLock<Result<(), String>> = OnceLock::new();
    REGISTERED
        .get_or_init(|| {
            register_font(FONT, FontStyle::Normal, dejavu::sans::regular()).map_err(|_| "DejaVu Sans is not a valid font".to_string())
        })
        .clone()
        .map_err(PlotError::Font)
}

/// A point and its error bar (low, high), if any.
type Marked = ((f64, f64), Option<(f64, f64)>);

/// The points of `s` that can be drawn (finite, and positive x on a logarithmic axis), with their
/// error bars if it has them.
fn drawable(s: &Series, log_x: bool) -> Vec<Marked> {
    s.points
        .iter()
        .enumerate()
        .filter(|(_, p)| p.0.is_finite() && p.1.is_finite() && (!log_x || p.0 > 0.0))
        .map(|(k, &p)| (p, s.intervals.get(k).copied().filter(|(lo, hi)| lo.is_finite() && hi.is_finite())))
        .collect()
}

/// The x and y ranges of the chart: the data's x range and `y_range` or the data's (from 0 when
/// every value is positive, error bars included).
fn ranges(chart: &Chart) -> ((f64, f64), (f64, f64)) {
    let pts: Vec<Marked> = chart.series.iter().flat_map(|s| drawable(s, chart.log_x)).collect();
    let (mut xlo, mut xhi) = pts.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), (p, _)| (a.min(p.0), b.max(p.0)));
    if !(xlo.is_finite() && xhi.is_finite()) {
        (xlo, xhi) = (1.0, 2.0);
    }
    if xhi <= xlo {
        xhi = if chart.log_x { xlo * 2.0 } else { xlo + 1.0 };
    }
    let y = chart.y_range.unwrap_or_else(|| {
        let values = pts.iter().flat_map(|(p, bar)| [Some(p.1), bar.map(|b| b.0), bar.map(|b| b.1)].into_iter().flatten());
        let (a, b) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
        if !(a.is_finite() && b.is_finite()) {
            return (0.0, 1.0);
        }
        let a = if a >= 0.0 { 0.0 } else { a };
        let b = if b > a { b + 0.05 * (b - a) } else { a + 1.0 };
        (a, b)
    });
    ((xlo, xhi), y)
}

/// A tick label: an integer where the value is one, else a few significant digits.
fn tick_label(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 {
        "0".into()
    } else if !(0.01..1e5).contains(&a) {
        format!("{v:.0e}")
    } else if (v - v.round()).abs() < 1e-9 * a.max(1.0) {
        format!("{}", v.round() as i64)
    } else {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').to_string()
    }
}

/// Draws `chart` into a `width × height` image (legend on the right).
pub fn line_chart(chart: &Chart, width: u32, height: u32) -> Result<RgbaImage, PlotError> {
    ensure_font()?;
    let (width, height) = (width.max(64), height.max(64));
    let mut rgb = vec![255u8; 3 * width as usize * height as usize];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (width, height)).into_drawing_area();
        root.fill(&WHITE)?;
        let legend_font = (FONT, 13).into_text_style(&root);
        let legend_w =
            chart.series.iter().map(|s| root.estimate_text_size(&s.label, &legend_font).map_or(0, |(w, _)| w)).max().unwrap_or(0) + 40;
        let legend_w = legend_w.min(width / 2);
        let (plot_area, legend_area) = root.split_horizontally(width - legend_w);
        let ((xlo, xhi), (ylo, yhi)) = ranges(chart);
        if chart.log_x {
            draw_lines(&plot_area, chart, (xlo..xhi).log_scale(), ylo..yhi)?;
        } else {
            draw_lines(&plot_area, chart, xlo..xhi, ylo..yhi)?;
        }
        for (k, s) in chart.series.iter().enumerate() {
            let y = 52 + 22 * k as i32;
            let color = plot_color(k);
            legend_area.draw(&PathElement::new(vec![(6, y), (26, y)], color.stroke_width(3)))?;
            legend_area.draw(&Circle::new((16, y), 3, color.filled()))?;
            legend_area.draw(&Text::new(s.label.clone(), (32, y - 7), legend_font.clone()))?;
        }
        root.present()?;
    }
    let img = image::RgbImage::from_raw(width, height, rgb).ok_or_else(|| PlotError::Draw("the bitmap has the wrong size".into()))?;
    Ok(image::DynamicImage::ImageRgb8(img).to_rgba8())
}

/// The axes, grid, lines, markers and error bars of `chart` on `area` with the coordinates `x`, `y`.
fn draw_lines<X>(area: &DrawingArea<BitMapBackend<'_>, Shift>, chart: &Chart, x: X, y: std::ops::Range<f64>) -> Result<(), PlotError>
where
    X: AsRangedCoord<Value = f64>,
    X::CoordDescType: ValueFormatter<f64>,
{
    let (ylo, yhi) = (y.start, y.end);
    let mut c = ChartBuilder::on(area)
        .caption(&chart.title, (FONT, 16))
        .margin(10)
        .x_label_area_size(44)
        .y_label_area_size(58)
        .build_cartesian_2d(x, y)?;
    c.configure_mesh()
        .x_desc(chart.x_label.as_str())
        .y_desc(chart.y_label.as_str())
        .x_label_formatter(&|v| tick_label(*v))
        .y_label_formatter(&|v| tick_label(*v))
        .label_style((FONT, 12))
        .axis_desc_style((FONT, 13))
        .light_line_style(WHITE)
        .bold_line_style(RGBColor(225, 225, 225))
        .draw()?;
    let clamp = |v: f64| v.clamp(ylo - 0.05 * (yhi - ylo), yhi + 0.05 * (yhi - ylo));
    for (k, s) in chart.series.iter().enumerate() {
        let color = plot_color(k);
        let points = drawable(s, chart.log_x);
        let bars: Vec<(f64, f64, f64, f64)> =
            points.iter().filter_map(|&((px, py), bar)| bar.map(|(lo, hi)| (px, clamp(lo), clamp(py), clamp(hi)))).collect();
        c.draw_series(bars.iter().map(|&(px, lo, py, hi)| ErrorBar::new_vertical(px, lo, py, hi, color.stroke_width(1), 8)))?;
        c.draw_series(LineSeries::new(points.iter().map(|&((px, py), _)| (px, clamp(py))), color.stroke_width(2)))?;
        c.draw_series(points.iter().map(|&((px, py), _)| Circle::new((px, clamp(py)), 3, color.filled())))?;
    }
    Ok(())
}

/// Places images side by side (top-aligned) on white.
pub fn side_by_side(parts: &[RgbaImage]) -> RgbaImage {
    let w = parts.iter().map(|p| p.width()).sum::<u32>().max(1);
    let h = parts.iter().map(|p| p.height()).max().unwrap_or(1).max(1);
    let mut out = RgbaImage::from_pixel(w, h, Rgba([255, 255, 255, 255]));
    let mut x0 = 0;
    for p in parts {
        for (x, y, px) in p.enumerate_pixels() {
            out.put_pixel(x0 + x, y, *px);
        }
        x0 += p.width();
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chart(log_x: bool, intervals: bool) -> Chart {
        let bars = |v: &[(f64, f64)]| if intervals { v.iter().map(|p| (p.1 - 0.3, p.1 + 0.3)).collect() } else { Vec::new() };
        let a = vec![(1.0, 1.0), (10.0, 2.0), (100.0, 3.0)];
        let b = vec![(1.0, 2.0), (10.0, 1.5), (100.0, 0.5)];
        Chart {
            title: "title".into(),
            x_label: "x".into(),
            y_label: "y".into(),
            log_x,
            y_range: None,
            series: vec![
                Series { label: "a".into(), intervals: bars(&a), points: a },
                Series { label: "b".into(), intervals: bars(&b), points: b },
            ],
        }
    }

    #[test]
    fn chart_draws_series_in_their_colours() {
        for log_x in [false, true] {
            let img = line_chart(&chart(log_x, true), 400, 300).unwrap();
            assert_eq!(img.dimensions(), (400, 300));
            for k in 0..2 {
                let c = series_color(k);
                assert!(img.pixels().filter(|p| **p == c).count() > 100, "series {k} is drawn (log x {log_x})");
            }
        }
    }

    #[test]
    fn error_bars_add_ink_in_the_series_colour() {
        let count = |img: &RgbaImage| img.pixels().filter(|p| **p == series_color(0)).count();
        let with = count(&line_chart(&chart(false, true), 400, 300).unwrap());
        let without = count(&line_chart(&chart(false, false), 400, 300).unwrap());
        assert!(with > without + 20, "{with} vs {without}");
    }

    #[test]
    fn the_range_includes_the_error_bars_and_starts_at_zero() {
        let ((xlo, xhi), (ylo, yhi)) = ranges(&chart(false, true));
        assert_eq!((xlo, xhi), (1.0, 100.0));
        assert_eq!(ylo, 0.0);
        assert!(yhi >= 3.3, "{yhi}");
        // Nothing drawable: a unit range, no panic.
        let empty = Chart {
            series: vec![Series { label: "n".into(), points: vec![(f64::NAN, 1.0)], intervals: Vec::new() }],
            ..chart(true, false)
        };
        assert_eq!(ranges(&empty), ((1.0, 2.0), (0.0, 1.0)));
        assert!(line_chart(&empty, 200, 150).is_ok());
    }

    #[test]
    fn tick_labels_are_short() {
        assert_eq!(tick_label(50.0), "50");
        assert_eq!(tick_label(0.25), "0.25");
        assert_eq!(tick_label(0.0), "0");
        assert_eq!(tick_label(2e-4), "2e-4");
    }
}
