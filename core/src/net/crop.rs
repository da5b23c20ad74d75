//! The fit's working image cut from a camera frame around detected landmarks: the one routine the
//! landmark-free fit on a device and the host's run of it both use (`gpmm device-fit --init`).
//!
//! The crop is the host's photo crop (`gpmm fit`): a square of side `CROP_FACTOR · e` around the
//! landmarks' bounding box (`e` its larger side), lifted by `CROP_LIFT · e` so the forehead fits,
//! moved inside the frame where it fits there; it is resampled to `side × side` by the networks'
//! sampler ([`sample_rgb8`]: `n × n` bilinear samples a pixel, integer arithmetic, mid-grey outside
//! the frame), so the host and the device get the same bytes.

use super::resample::{sample_rgb8, Window};
use super::NetError;

/// Side of the crop in landmark-box sizes (the larger side of the landmarks' bounding box).
pub const CROP_FACTOR: f32 = 1.8;
/// Upward shift of the crop's centre in landmark-box sizes (the forehead has no landmark).
pub const CROP_LIFT: f32 = 0.1;

/// The crop of a `w × h` frame around `landmarks` (frame px), sampled into `side × side` pixels;
/// `None` if the landmarks span no area or are not finite.
pub fn fit_window(landmarks: &[[f32; 2]], w: usize, h: usize, side: usize) -> Option<Window> {
    let (cx, cy, e) = super::face_box::landmark_box(landmarks);
    if !(cx.is_finite() && cy.is_finite() && e.is_finite() && e >= 1.0) || side == 0 {
        return None;
    }
    let size = CROP_FACTOR * e;
    let place = |centre: f32, extent: usize| {
        let start = centre - size * 0.5;
        if size <= extent as f32 {
            start.clamp(0.0, extent as f32 - size)
        } else {
            start
        }
    };
    Some(Window { x0: place(cx, w), y0: place(cy - CROP_LIFT * e, h), step: size / side as f32 })
}

/// Cuts the working image out of the frame `rgb` (`w × h` RGB8) around `landmarks`: `pixels`
/// (`side × side`) get the crop, `working` the landmarks in its pixels; returns the crop's window
/// (working px → frame px with [`Window::to_source`]).
pub fn crop_for_fit(
    rgb: &[u8],
    w: usize,
    h: usize,
    landmarks: &[[f32; 2]],
    side: usize,
    pixels: &mut [[u8; 3]],
    working: &mut [[f32; 2]],
) -> Result<Window, NetError> {
    if working.len() != landmarks.len() {
        return Err(NetError::LengthMismatch);
    }
    let window = fit_window(landmarks, w, h, side).ok_or(NetError::DegenerateLandmarks)?;
    sample_rgb8(rgb, w, h, window, side, pixels)?;
    for (o, p) in working.iter_mut().zip(landmarks) {
        let (x, y) = window.from_source(p[0], p[1]);
        *o = [x, y];
    }
    Ok(window)
}
