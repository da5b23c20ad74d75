//! Line charts as PNG (no font files: labels use the 8×8 bitmap font of [`crate::render::figure`]).

use image::{Rgba, RgbaImage};

use crate::render::figure::{draw_text, text_width, GLYPH};

/// One line of a chart.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend label.
    pub label: String,
    /// (x, y) points in drawing order (non-finite values are skipped).
    pub points: Vec<(f64, f64)>,
}

/// A chart.
#[derive(Debug, Clone, PartialEq)]
pub struct Chart {
    /// Title above the plot.
    pub title: String,
    /// x-axis label.
    pub x_label: String,
    /// y-axis label (written above the axis).
    pub y_label: String,
    /// Logarithmic x axis.
    pub log_x: bool,
    /// Fixed y range (otherwise from the data, starting at 0 when all values are positive).
    pub y_range: Option<(f64, f64)>,
    /// The lines.
    pub series: Vec<Series>,
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

const WHITE: Rgba<u8> = Rgba([255, 255, 255, 255]);
const INK: Rgba<u8> = Rgba([30, 30, 30, 255]);
const GRID: Rgba<u8> = Rgba([225, 225, 225, 255]);

/// The colour of series `k`.
pub fn series_color(k: usize) -> Rgba<u8> {
    let c = PALETTE[k % PALETTE.len()];
    Rgba([c[0], c[1], c[2], 255])
}

/// "Nice" tick values covering `[lo, hi]` (steps of 1, 2 or 5 × 10^k, about 6 ticks).
pub fn nice_ticks(lo: f64, hi: f64) -> Vec<f64> {
    if !(lo.is_finite() && hi.is_finite()) || hi <= lo {
        return vec![lo];
    }
    let raw = (hi - lo) / 6.0;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0].iter().map(|m| m * mag).find(|s| *s >= raw).unwrap_or(10.0 * mag);
    let mut t = (lo / step).ceil() * step;
    let mut out = Vec::new();
    while t <= hi + 1e-9 * step && out.len() < 50 {
        out.push(if t.abs() < 1e-12 * step { 0.0 } else { t });
        t += step;
    }
    out
}

fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let mut out = Vec::new();
    let mut e = lo.log10().floor() as i32;
    while 10f64.powi(e) <= hi * 1.0001 && out.len() < 60 {
        for m in [1.0, 2.0, 5.0] {
            let v = m * 10f64.powi(e);
            if v >= lo * 0.9999 && v <= hi * 1.0001 {
                out.push(v);
            }
        }
        e += 1;
    }
    out
}

fn label(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    let a = v.abs();
    if !(0.01..1000.0).contains(&a) {
        format!("{v:.1e}")
    } else if (v - v.round()).abs() < 1e-9 {
        format!("{}", v.round() as i64)
    } else if a >= 1.0 {
        format!("{v:.1}")
    } else {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').to_string()
    }
}

fn put(img: &mut RgbaImage, x: i64, y: i64, c: Rgba<u8>) {
    if x >= 0 && y >= 0 && x < i64::from(img.width()) && y < i64::from(img.height()) {
        img.put_pixel(x as u32, y as u32, c);
    }
}

/// A line `thick` pixels wide (Bresenham with a square brush).
fn line(img: &mut RgbaImage, a: (f64, f64), b: (f64, f64), thick: i64, c: Rgba<u8>) {
    let (mut x0, mut y0, x1, y1) = (a.0.round() as i64, a.1.round() as i64, b.0.round() as i64, b.1.round() as i64);
    let (dx, dy) = ((x1 - x0).abs(), -(y1 - y0).abs());
    let (sx, sy) = (if x0 < x1 { 1 } else { -1 }, if y0 < y1 { 1 } else { -1 });
    let mut err = dx + dy;
    let r0 = -(thick - 1) / 2;
    for _ in 0..100_000 {
        for ox in r0..r0 + thick {
            for oy in r0..r0 + thick {
                put(img, x0 + ox, y0 + oy, c);
            }
        }
        if x0 == x1 && y0 == y1 {
            break;
        }
        let e2 = 2 * err;
        if e2 >= dy {
            err += dy;
            x0 += sx;
        }
        if e2 <= dx {
            err += dx;
            y0 += sy;
        }
    }
}

/// Draws `chart` into a `width × height` image (legend on the right).
pub fn line_chart(chart: &Chart, width: u32, height: u32) -> RgbaImage {
    let mut img = RgbaImage::from_pixel(width, height, WHITE);
    let legend_w = chart.series.iter().map(|s| text_width(&s.label, 1)).max().unwrap_or(0) + 34;
    let (left, right, top, bottom) = (64.0, f64::from(width.saturating_sub(legend_w + 12)), 48.0, f64::from(height) - 44.0);
    let pts: Vec<(f64, f64)> = chart
        .series
        .iter()
        .flat_map(|s| s.points.iter().copied())
        .filter(|p| p.0.is_finite() && p.1.is_finite() && (!chart.log_x || p.0 > 0.0))
        .collect();
    let (mut xlo, mut xhi) = pts.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| (a.min(p.0), b.max(p.0)));
    if !(xlo.is_finite() && xhi.is_finite()) {
        (xlo, xhi) = (1.0, 2.0);
    }
    if xhi <= xlo {
        xhi = xlo + 1.0;
        if chart.log_x {
            xhi = xlo * 2.0;
        }
    }
    let (ylo, yhi) = chart.y_range.unwrap_or_else(|| {
        let (a, b) = pts.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| (a.min(p.1), b.max(p.1)));
        if !(a.is_finite() && b.is_finite()) {
            return (0.0, 1.0);
        }
        let a = if a >= 0.0 { 0.0 } else { a };
        let b = if b > a { b + 0.05 * (b - a) } else { a + 1.0 };
        (a, b)
    });
    let fx = |x: f64| {
        let t = if chart.log_x { (x.ln() - xlo.ln()) / (xhi.ln() - xlo.ln()) } else { (x - xlo) / (xhi - xlo) };
        left + t * (right - left)
    };
    let fy = |y: f64| bottom - (y - ylo) / (yhi - ylo) * (bottom - top);

    // Grid, ticks and their labels.
    let yt = nice_ticks(ylo, yhi);
    for &y in &yt {
        let py = fy(y);
        line(&mut img, (left, py), (right, py), 1, GRID);
        let l = label(y);
        let tx = (left as u32).saturating_sub(text_width(&l, 1) + 6);
        draw_text(&mut img, tx, (py as u32).saturating_sub(GLYPH / 2), &l, 1, INK);
    }
    let xt = if chart.log_x { log_ticks(xlo, xhi) } else { nice_ticks(xlo, xhi) };
    for &x in &xt {
        let px = fx(x);
        line(&mut img, (px, top), (px, bottom), 1, GRID);
        let l = label(x);
        draw_text(&mut img, (px as u32).saturating_sub(text_width(&l, 1) / 2), bottom as u32 + 6, &l, 1, INK);
    }
    line(&mut img, (left, bottom), (right, bottom), 1, INK);
    line(&mut img, (left, top), (left, bottom), 1, INK);

    // Series.
    for (k, s) in chart.series.iter().enumerate() {
        let c = series_color(k);
        let p: Vec<(f64, f64)> = s
            .points
            .iter()
            .filter(|p| p.0.is_finite() && p.1.is_finite() && (!chart.log_x || p.0 > 0.0))
            .map(|&(x, y)| (fx(x), fy(y.clamp(ylo - 0.05 * (yhi - ylo), yhi + 0.05 * (yhi - ylo)))))
            .collect();
        for w in p.windows(2) {
            line(&mut img, w[0], w[1], 2, c);
        }
        for &q in &p {
            line(&mut img, (q.0 - 2.0, q.1), (q.0 + 2.0, q.1), 5, c);
        }
        // Legend entry.
        let ly = top as u32 + 4 + k as u32 * (GLYPH + 8);
        let lx = right as u32 + 16;
        line(&mut img, (f64::from(lx), f64::from(ly + 4)), (f64::from(lx + 18), f64::from(ly + 4)), 3, c);
        draw_text(&mut img, lx + 24, ly, &s.label, 1, INK);
    }

    draw_text(&mut img, (left as u32).saturating_sub(40), 10, &chart.title, 1, INK);
    draw_text(&mut img, (left as u32).saturating_sub(40), 24, &chart.y_label, 1, INK);
    let xl = text_width(&chart.x_label, 1);
    draw_text(&mut img, ((left + right) / 2.0) as u32 - xl / 2, height.saturating_sub(18), &chart.x_label, 1, INK);
    img
}

/// Places images side by side (top-aligned) on white.
pub fn side_by_side(parts: &[RgbaImage]) -> RgbaImage {
    let w = parts.iter().map(|p| p.width()).sum::<u32>().max(1);
    let h = parts.iter().map(|p| p.height()).max().unwrap_or(1).max(1);
    let mut out = RgbaImage::from_pixel(w, h, WHITE);
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

    #[test]
    fn ticks_are_nice_and_cover_the_range() {
        assert_eq!(nice_ticks(0.0, 100.0), vec![0.0, 20.0, 40.0, 60.0, 80.0, 100.0]);
        let t = nice_ticks(0.0, 1.0);
        assert_eq!(t.len(), 6);
        assert!(t.iter().zip([0.0, 0.2, 0.4, 0.6, 0.8, 1.0]).all(|(a, b)| (a - b).abs() < 1e-9), "{t:?}");
        assert_eq!(log_ticks(1.0, 200.0), vec![1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0]);
        assert_eq!(label(50.0), "50");
        assert_eq!(label(0.25), "0.25");
    }

    #[test]
    fn chart_draws_series_in_their_colours() {
        let chart = Chart {
            title: "t".into(),
            x_label: "x".into(),
            y_label: "y".into(),
            log_x: true,
            y_range: None,
            series: vec![
                Series { label: "a".into(), points: vec![(1.0, 1.0), (100.0, 3.0)] },
                Series { label: "b".into(), points: vec![(1.0, 2.0), (100.0, 0.5)] },
            ],
        };
        let img = line_chart(&chart, 400, 300);
        for k in 0..2 {
            let c = series_color(k);
            assert!(img.pixels().filter(|p| **p == c).count() > 100, "series {k} is drawn");
        }
    }
}
