//! `spread.png`: where the fit is sure of the surface and where not. The fitted face, seen as the
//! fit sees it, coloured by each vertex's standard deviation along its normal
//! ([`super::ShapeSpread::vertex_sd_mm`]) over the dimmed working image, with a colour bar in mm.

use super::overlay::OVERLAY_SCALE;
use super::params::Params;
use super::FitRunError;
use crate::gp::model::GpModel;
use crate::render::figure::{draw_text, shape_light, text_width};
use crate::render::{Background, Instance, Renderer};
use gpmm_core::render::Cull;
use image::{RgbImage, Rgba, RgbaImage};

/// The colour of a share `t` in [0, 1] of the colour bar: blue (sure), through green and yellow,
/// to red (unsure).
pub fn spread_color(t: f32) -> [f32; 3] {
    const STOPS: [[f32; 3]; 4] = [[0.15, 0.25, 0.85], [0.1, 0.75, 0.35], [0.95, 0.85, 0.1], [0.9, 0.15, 0.1]];
    let t = if t.is_finite() { t.clamp(0.0, 1.0) } else { 1.0 };
    let x = t * (STOPS.len() - 1) as f32;
    let i = (x.floor() as usize).min(STOPS.len() - 2);
    let f = x - i as f32;
    core::array::from_fn(|c| STOPS[i][c] * (1.0 - f) + STOPS[i + 1][c] * f)
}

/// The picture of `sd` (mm per vertex of `model`) on the fit `params` over the working image
/// `crop`; the colour bar runs from 0 to the largest spread.
pub fn spread_picture(model: &GpModel, params: &Params, sd: &[f32], crop: &RgbImage) -> Result<RgbaImage, FitRunError> {
    if sd.len() != model.vertices() {
        return Err(FitRunError::Model(format!("{} vertex spreads for {} vertices", sd.len(), model.vertices())));
    }
    let (w, h) = crop.dimensions();
    let render_error = |e: crate::render::RenderError| FitRunError::Model(format!("render: {e}"));
    let top = sd.iter().copied().filter(|s| s.is_finite()).fold(0.0f32, f32::max).max(1e-3);
    let mut instance = Instance::of_model(model, params.shape_coeffs(), &[]).map_err(render_error)?;
    instance.albedos = sd.iter().map(|s| spread_color(s / top)).collect();
    let mut renderer = Renderer::new();
    renderer.vertex_stage(&instance, &model.triangles, &params.pose, &params.camera(w, h), &shape_light()).map_err(render_error)?;
    let (face, _) = renderer.rasterize(&model.triangles, w, h, Cull::Clockwise, Background::Transparent).map_err(render_error)?;
    let s = OVERLAY_SCALE;
    let (pw, ph) = (w * s, h * s);
    let (gap, header, bar) = (4u32, 14u32, 16u32);
    let label_w = text_width(&format!("{top:.1} mm"), 1);
    let bg = Rgba([24, 24, 24, 255]);
    let mut out = RgbaImage::from_pixel(pw + bar + label_w + 4 * gap, ph + header + gap, bg);
    for y in 0..ph {
        for x in 0..pw {
            let (c, f) = (crop.get_pixel(x / s, y / s).0, face.get_pixel(x / s, y / s).0);
            let px = if f[3] > 0 { Rgba([f[0], f[1], f[2], 255]) } else { Rgba([c[0] / 3, c[1] / 3, c[2] / 3, 255]) };
            out.put_pixel(gap + x, header + y, px);
        }
    }
    // The colour bar: the largest spread at the top, 0 at the bottom.
    let bx = gap * 2 + pw;
    for y in 0..ph {
        let c = spread_color(1.0 - y as f32 / (ph - 1).max(1) as f32).map(|v| (v * 255.0).round() as u8);
        for x in 0..bar {
            out.put_pixel(bx + x, header + y, Rgba([c[0], c[1], c[2], 255]));
        }
    }
    let ink = Rgba([230, 230, 230, 255]);
    draw_text(&mut out, gap, 3, "surface sd along the normal (mm)", 1, ink);
    draw_text(&mut out, bx + bar + gap, header, &format!("{top:.1} mm"), 1, ink);
    draw_text(&mut out, bx + bar + gap, header + ph - 8, "0 mm", 1, ink);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_colour_bar_runs_from_blue_to_red_and_clamps() {
        let (low, high) = (spread_color(0.0), spread_color(1.0));
        assert!(low[2] > low[0] && high[0] > high[2], "{low:?} {high:?}");
        assert_eq!(spread_color(-1.0), low);
        assert_eq!(spread_color(2.0), high);
        assert_eq!(spread_color(f32::NAN), high);
        // Continuous: no jump between neighbouring shares.
        for k in 0..100 {
            let (a, b) = (spread_color(k as f32 / 100.0), spread_color((k + 1) as f32 / 100.0));
            assert!(a.iter().zip(b).all(|(x, y)| (x - y).abs() < 0.05), "{k}");
        }
    }
}
