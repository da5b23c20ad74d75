//! `overlay.png`: the working image, the rendered fit and their blend side by side, with the
//! target and fitted landmarks drawn on, and (for an occlusion-aware fit) the pixels it left to
//! the non-face model.

use image::{GrayImage, RgbImage, Rgba, RgbaImage};

/// Upscaling of the overlay panels (nearest neighbour).
pub const OVERLAY_SCALE: u32 = 3;
/// Colour of the target landmarks in the overlay (green dots).
pub const TARGET_COLOR: Rgba<u8> = Rgba([40, 230, 60, 255]);
/// Colour of the fitted landmarks in the overlay (red crosses).
pub const FITTED_COLOR: Rgba<u8> = Rgba([255, 40, 40, 255]);

/// Colour of the occluded pixels in the overlay's fourth panel (magenta).
pub const OCCLUDED_COLOR: Rgba<u8> = Rgba([230, 40, 200, 255]);

/// `input crop | rendered fit | 50 % blend [| occluded]`, each upscaled by [`OVERLAY_SCALE`], target
/// landmarks as green dots and fitted ones as red crosses on the first and third panel, labels on
/// top. With `occluded` (white: labelled occluded), a fourth panel shows the crop dimmed, the
/// occluded pixels in [`OCCLUDED_COLOR`].
pub fn overlay(crop: &RgbImage, render: &RgbaImage, occluded: Option<&GrayImage>, target: &[[f32; 2]], fitted: &[[f32; 2]]) -> RgbaImage {
    let (w, h) = crop.dimensions();
    let s = OVERLAY_SCALE;
    let (pw, ph) = (w * s, h * s);
    let (gap, header) = (4u32, 14u32);
    let bg = Rgba([24, 24, 24, 255]);
    let panels = if occluded.is_some() { 4 } else { 3 };
    let mut out = RgbaImage::from_pixel(panels * pw + (panels + 1) * gap, ph + header + gap, bg);
    let panel = |i: u32| (gap + i * (pw + gap), header);
    for y in 0..ph {
        for x in 0..pw {
            let c = crop.get_pixel(x / s, y / s).0;
            let r = render.get_pixel(x / s, y / s).0;
            let covered = r[3] > 0;
            let ren = if covered { Rgba([r[0], r[1], r[2], 255]) } else { Rgba([0, 0, 0, 255]) };
            let blend = if covered {
                let avg = |k: usize| (u16::from(c[k]) + u16::from(r[k])).div_ceil(2) as u8;
                Rgba([avg(0), avg(1), avg(2), 255])
            } else {
                Rgba([c[0], c[1], c[2], 255])
            };
            for (i, px) in [Rgba([c[0], c[1], c[2], 255]), ren, blend].into_iter().enumerate() {
                let (ox, oy) = panel(i as u32);
                out.put_pixel(ox + x, oy + y, px);
            }
            if let Some(m) = occluded {
                let labelled = m.get_pixel_checked(x / s, y / s).is_some_and(|v| v.0[0] > 127);
                let px = if labelled { OCCLUDED_COLOR } else { Rgba([c[0] / 2, c[1] / 2, c[2] / 2, 255]) };
                let (ox, oy) = panel(3);
                out.put_pixel(ox + x, oy + y, px);
            }
        }
    }
    let ink = Rgba([230, 230, 230, 255]);
    for (i, label) in ["input", "fit", "blend", "occluded"].iter().take(panels as usize).enumerate() {
        let (ox, _) = panel(i as u32);
        crate::render::figure::draw_text(&mut out, ox, 3, label, 1, ink);
    }
    for i in [0u32, 2] {
        let (ox, oy) = panel(i);
        let to = |p: &[f32; 2]| -> Option<(i64, i64)> {
            let (x, y) = (p[0] * s as f32, p[1] * s as f32);
            (x.is_finite() && y.is_finite() && x >= 0.0 && y >= 0.0 && x < pw as f32 && y < ph as f32)
                .then(|| (i64::from(ox) + x as i64, i64::from(oy) + y as i64))
        };
        for p in target.iter().filter_map(to) {
            for dy in -2..=2 {
                for dx in -2..=2 {
                    if dx * dx + dy * dy <= 5 {
                        put(&mut out, p.0 + dx, p.1 + dy, TARGET_COLOR);
                    }
                }
            }
        }
        for p in fitted.iter().filter_map(to) {
            for d in -3..=3 {
                for t in 0..2 {
                    put(&mut out, p.0 + d + t, p.1 + d, FITTED_COLOR);
                    put(&mut out, p.0 + d + t, p.1 - d, FITTED_COLOR);
                }
            }
        }
    }
    out
}

/// Sets a pixel if it lies in the image.
pub(super) fn put(img: &mut RgbaImage, x: i64, y: i64, c: Rgba<u8>) {
    if x >= 0 && y >= 0 && x < i64::from(img.width()) && y < i64::from(img.height()) {
        img.put_pixel(x as u32, y as u32, c);
    }
}

/// The working image's occlusion labels `labels` (white: occluded; `size × size`, cut from the
/// photo at `crop`) on a `photo_size` photo: each photo pixel takes the label of the working pixel
/// its centre falls in, photo pixels outside the crop are not labelled (`occlusion.png`, Python's
/// `occluded_photo`).
pub fn labels_in_photo(labels: &GrayImage, crop: &crate::photo::CropBox, photo_size: [u32; 2]) -> GrayImage {
    let size = labels.width();
    let mut out = GrayImage::new(photo_size[0], photo_size[1]);
    if size == 0 || crop.side == 0 {
        return out;
    }
    // The photo rows and columns the crop spans.
    let span = |start: i64, extent: u32| {
        (start.clamp(0, i64::from(extent)) as u32, (start + i64::from(crop.side)).clamp(0, i64::from(extent)) as u32)
    };
    let ((x0, x1), (y0, y1)) = (span(crop.x, photo_size[0]), span(crop.y, photo_size[1]));
    for y in y0..y1 {
        for x in x0..x1 {
            // The working pixel of the photo pixel's centre.
            let [u, v] = crop.to_working([x as f32 + 0.5, y as f32 + 0.5], size).map(f32::floor);
            if u >= 0.0 && v >= 0.0 {
                if let Some(p) = labels.get_pixel_checked(u as u32, v as u32) {
                    out.put_pixel(x, y, *p);
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::photo::CropBox;

    #[test]
    fn labels_land_on_the_photo_pixels_their_working_pixel_covers() {
        // A 64 px crop at (10, -6) of a 100 x 50 photo, worked at 32 px: two photo pixels a working one.
        let mut labels = GrayImage::new(32, 32);
        labels.put_pixel(3, 4, image::Luma([255]));
        labels.put_pixel(31, 31, image::Luma([255]));
        let photo = labels_in_photo(&labels, &CropBox { x: 10, y: -6, side: 64 }, [100, 50]);
        assert_eq!(photo.dimensions(), (100, 50));
        let on: Vec<(u32, u32)> = photo.enumerate_pixels().filter(|(_, _, p)| p.0[0] == 255).map(|(x, y, _)| (x, y)).collect();
        // Working (3, 4) covers photo x 16..18, y 2..4; (31, 31) lies below the photo.
        assert_eq!(on, vec![(16, 2), (17, 2), (16, 3), (17, 3)]);
        // Outside the crop nothing is labelled, whatever the labels say.
        let all = GrayImage::from_pixel(32, 32, image::Luma([255]));
        let photo = labels_in_photo(&all, &CropBox { x: 10, y: -6, side: 64 }, [100, 50]);
        assert_eq!(photo.get_pixel(9, 10).0[0], 0);
        assert_eq!(photo.get_pixel(74, 10).0[0], 0);
        assert_eq!((photo.get_pixel(10, 0).0[0], photo.get_pixel(73, 49).0[0]), (255, 255));
    }
}
