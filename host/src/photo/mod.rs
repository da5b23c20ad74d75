//! Photos for fitting: loading (PNG, JPEG, PPM), the square face crop around the landmarks and
//! its resampling to the working size.
//!
//! **Crop rule** ([`crop_box`]): the landmarks' bounding box has centre `c` and larger side `e`;
//! the crop is the square of side `S = ceil(CROP_FACTOR · e)` pixels centred on
//! `c − (0, CROP_LIFT · e)` (lifted so the forehead, which no landmark marks, fits), snapped to
//! whole pixels. If the square fits in the image it is shifted to lie inside it; otherwise the
//! missing pixels are filled by repeating the nearest border pixel, and the working pixels whose
//! centres lie outside the photo are left out of the fit ([`CropBox::covered`]). The crop is resampled to
//! `size × size` with a Lanczos-3 filter (`image::imageops::resize`, which widens the kernel
//! when shrinking, so it does not alias). Coordinates map exactly: working = (original − corner) ·
//! size / S in continuous pixel coordinates (centres at +0.5 in both images).

pub mod calibration;
pub mod pts;

use gpmm_core::fit::CoveredPixels;
use image::{imageops::FilterType, RgbImage};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Crop side over the landmarks' larger bounding-box side, and the upward shift of the crop
/// centre as a fraction of it: the core's, which the device's crop (`gpmm_core::net::crop`) uses.
pub use gpmm_core::net::crop::{CROP_FACTOR, CROP_LIFT};
/// Largest image side accepted (pixels).
pub const MAX_PHOTO_SIDE: u32 = 16384;

/// Why a photo could not be used.
#[derive(Debug, thiserror::Error)]
pub enum PhotoError {
    /// The file could not be opened or decoded.
    #[error("{}: cannot read the image: {message}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// What the decoder said.
        message: String,
    },
    /// The image is empty or too large.
    #[error("{}: image size {width}x{height} is not supported (each side 1 to {MAX_PHOTO_SIDE} pixels)", path.display())]
    Size {
        /// The file.
        path: PathBuf,
        /// Width.
        width: u32,
        /// Height.
        height: u32,
    },
    /// The landmarks span no area (all on one point or line).
    #[error("the landmarks span no area (bounding box {0} x {1} px): cannot crop a face")]
    Degenerate(f32, f32),
}

/// Loads an image as 8-bit RGB (alpha dropped, colours as stored: no gamma conversion).
pub fn load_rgb(path: &Path) -> Result<RgbImage, PhotoError> {
    let reader = image::ImageReader::open(path).map_err(|e| PhotoError::Read { path: path.to_path_buf(), message: e.to_string() })?;
    let reader = reader.with_guessed_format().map_err(|e| PhotoError::Read { path: path.to_path_buf(), message: e.to_string() })?;
    let img = reader.decode().map_err(|e| PhotoError::Read { path: path.to_path_buf(), message: e.to_string() })?;
    let (w, h) = (img.width(), img.height());
    if w == 0 || h == 0 || w > MAX_PHOTO_SIDE || h > MAX_PHOTO_SIDE {
        return Err(PhotoError::Size { path: path.to_path_buf(), width: w, height: h });
    }
    Ok(img.to_rgb8())
}

/// A square crop in original-image pixels (it may extend past the image: those pixels are padded).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct CropBox {
    /// Left edge (pixels; may be negative).
    pub x: i64,
    /// Top edge (pixels; may be negative).
    pub y: i64,
    /// Side (pixels).
    pub side: u32,
}

impl CropBox {
    /// An original-image point in the `size × size` working image.
    pub fn to_working(&self, p: [f32; 2], size: u32) -> [f32; 2] {
        let s = size as f32 / self.side as f32;
        [(p[0] - self.x as f32) * s, (p[1] - self.y as f32) * s]
    }

    /// A working-image point in the original image.
    pub fn to_original(&self, p: [f32; 2], size: u32) -> [f32; 2] {
        let s = self.side as f32 / size as f32;
        [p[0] * s + self.x as f32, p[1] * s + self.y as f32]
    }

    /// Original pixels per working pixel.
    pub fn scale(&self, size: u32) -> f32 {
        self.side as f32 / size as f32
    }

    /// The pixels of the `size × size` working image that a `width × height` photo covers (the
    /// others are padding, left out of the fit: [`gpmm_core::fit::frame`]).
    pub fn covered(&self, size: u32, width: u32, height: u32) -> CoveredPixels {
        CoveredPixels::of_crop(self.x as f32, self.y as f32, self.scale(size), size, width, height)
    }

    /// The share of the crop's area that lies outside a `width × height` photo (0 to 1).
    pub fn outside_fraction(&self, width: u32, height: u32) -> f32 {
        let span = |start: i64, extent: u32| (start + i64::from(self.side)).min(i64::from(extent)) - start.max(0);
        let inside = span(self.x, width).max(0) as f64 * span(self.y, height).max(0) as f64;
        (1.0 - inside / (f64::from(self.side) * f64::from(self.side))) as f32
    }
}

/// The crop of the module docs for landmarks `points` in a `width × height` image.
pub fn crop_box(points: &[[f32; 2]], width: u32, height: u32) -> Result<CropBox, PhotoError> {
    let (mut lo, mut hi) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
    for p in points {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let (ew, eh) = (hi[0] - lo[0], hi[1] - lo[1]);
    let e = ew.max(eh);
    if !(e >= 1.0 && e.is_finite()) {
        return Err(PhotoError::Degenerate(ew, eh));
    }
    let side = (CROP_FACTOR * e).ceil().max(8.0) as u32;
    let c = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]) - CROP_LIFT * e];
    let place = |centre: f32, extent: u32| -> i64 {
        let start = (centre - side as f32 * 0.5).round() as i64;
        if side <= extent {
            start.clamp(0, i64::from(extent - side))
        } else {
            start
        }
    };
    Ok(CropBox { x: place(c[0], width), y: place(c[1], height), side })
}

/// Cuts `crop` out of `image` (border pixels repeated where it extends past the image) and
/// resamples it to `size × size` (Lanczos-3).
pub fn crop_resize(image: &RgbImage, crop: &CropBox, size: u32) -> RgbImage {
    let (w, h) = image.dimensions();
    let side = crop.side;
    let inside = crop.x >= 0 && crop.y >= 0 && crop.x + i64::from(side) <= i64::from(w) && crop.y + i64::from(side) <= i64::from(h);
    let cut = if inside {
        image::imageops::crop_imm(image, crop.x as u32, crop.y as u32, side, side).to_image()
    } else {
        RgbImage::from_fn(side, side, |i, j| {
            let x = (crop.x + i64::from(i)).clamp(0, i64::from(w) - 1) as u32;
            let y = (crop.y + i64::from(j)).clamp(0, i64::from(h) - 1) as u32;
            *image.get_pixel(x, y)
        })
    };
    if side == size {
        cut
    } else {
        image::imageops::resize(&cut, size, size, FilterType::Lanczos3)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    #[test]
    fn crop_is_square_inside_and_maps_points() {
        let pts = [[100.0, 100.0], [200.0, 150.0], [150.0, 220.0]];
        let b = crop_box(&pts, 1000, 1000).unwrap();
        assert_eq!(b.side, 216);
        let c = b.to_working([150.0, 160.0 - 12.0], 128);
        assert!((c[0] - 64.0).abs() < 1.0 && (c[1] - 64.0).abs() < 1.0, "{c:?}");
        let back = b.to_original(b.to_working([123.0, 45.0], 128), 128);
        assert!((back[0] - 123.0).abs() < 1e-3 && (back[1] - 45.0).abs() < 1e-3);
        // Near a border: shifted inside when it fits, padded when it does not.
        let b = crop_box(&pts, 230, 1000).unwrap();
        assert_eq!(b.x, 230 - 216);
        let b = crop_box(&pts, 200, 200).unwrap();
        assert!(b.side > 200);
        let img = RgbImage::from_fn(200, 200, |x, y| image::Rgb([x as u8, y as u8, 7]));
        let out = crop_resize(&img, &b, 64);
        assert_eq!(out.dimensions(), (64, 64));
        // 216 px from (42, 40): 58 px past the right edge, 56 past the bottom (3.375 px a working px).
        assert_eq!((b.x, b.y, b.side), (42, 40, 216));
        let cov = b.covered(64, 200, 200);
        assert_eq!((cov.x0, cov.y0), (0, 0));
        assert_eq!((cov.x1, cov.y1), (47, 47));
        let outside = 1.0 - (158.0 * 160.0) / (216.0 * 216.0);
        assert!((b.outside_fraction(200, 200) - outside).abs() < 1e-6, "{}", b.outside_fraction(200, 200));
        assert_eq!(crop_box(&pts, 1000, 1000).unwrap().outside_fraction(1000, 1000), 0.0);
        assert!(crop_box(&[[3.0, 3.0], [3.0, 3.0]], 10, 10).is_err());
    }
}

/// The rotation `Q` (rows) taking the fit's camera frame (its axis through the centre of the
/// `size × size` working crop `crop`, focal length `focal` in working pixels) onto the photo's
/// camera frame (principal point `principal`, photo pixels): a point `p` of the fit's camera lies at
/// `Q p` in the photo's ([`pose_in_photo_frame`]).
pub fn crop_axis_rotation(focal: f32, crop: &CropBox, size: u32, principal: [f32; 2]) -> [[f64; 3]; 3] {
    let c = crop.to_original([size as f32 * 0.5, size as f32 * 0.5], size);
    let f = f64::from(focal * crop.scale(size));
    let d = [f64::from(c[0] - principal[0]) / f, -f64::from(c[1] - principal[1]) / f, -1.0];
    let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let d = [d[0] / n, d[1] / n, d[2] / n];
    // Q: the smallest rotation taking the fit's axis (0, 0, −1) onto d (Rodrigues).
    let axis = [d[1], -d[0], 0.0]; // (0, 0, −1) × d
    let s = (axis[0] * axis[0] + axis[1] * axis[1]).sqrt();
    let cos = -d[2];
    if s < 1e-12 {
        [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    } else {
        let k = [axis[0] / s, axis[1] / s, 0.0];
        let v = 1.0 - cos;
        [
            [cos + k[0] * k[0] * v, k[0] * k[1] * v - k[2] * s, k[0] * k[2] * v + k[1] * s],
            [k[1] * k[0] * v + k[2] * s, cos + k[1] * k[1] * v, k[1] * k[2] * v - k[0] * s],
            [k[2] * k[0] * v - k[1] * s, k[2] * k[1] * v + k[0] * s, cos + k[2] * k[2] * v],
        ]
    }
}

/// Yaw, pitch and roll (radians) of a fitted rotation `(yaw, pitch, roll)`, found on the crop
/// `crop` resampled to `size × size` with the principal point at the crop's centre and focal
/// length `focal` (working pixels), expressed in the photo's camera frame (principal point
/// `principal`, photo pixels: a photo's centre unless the camera says otherwise). The fit takes the crop's centre as the optical axis: a
/// face off the photo's axis by an angle `α` is fitted as turned by `α` (2.6° for a face 26 mm
/// below the axis at 570 mm). Rotating the fit's camera onto the photo's axis removes that.
pub fn pose_in_photo_frame(angles: [f32; 3], focal: f32, crop: &CropBox, size: u32, principal: [f32; 2]) -> [f32; 3] {
    let q = crop_axis_rotation(focal, crop, size, principal);
    let pose = gpmm_core::render::Pose { yaw: angles[0], pitch: angles[1], roll: angles[2], translation: [0.0; 3] };
    let r = pose.rotation().map(|row| row.map(f64::from));
    let mut m = [[0.0f64; 3]; 3];
    for (i, row) in m.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = (0..3).map(|k| q[i][k] * r[k][j]).sum();
        }
    }
    euler_angles(&m).map(|a| a as f32)
}

/// Yaw, pitch and roll (radians) of a rotation `m` (rows) in the core's convention
/// `R = Rz(roll) · Ry(yaw) · Rx(pitch)` ([`gpmm_core::render::Pose::rotation`]).
pub fn euler_angles(m: &[[f64; 3]; 3]) -> [f64; 3] {
    // R[2][0] = −sin(yaw), R[2][1..] = cos(yaw) (sin, cos)(pitch).
    let yaw = (-m[2][0]).clamp(-1.0, 1.0).asin();
    let pitch = m[2][1].atan2(m[2][2]);
    let roll = m[1][0].atan2(m[0][0]);
    [yaw, pitch, roll]
}

#[cfg(test)]
mod frame_tests {
    use super::*;

    #[test]
    fn a_centred_crop_keeps_the_pose_and_an_off_axis_one_turns_it() {
        let a = [0.3f32, -0.1, 0.05];
        // Crop centred on the photo's centre: nothing changes.
        let crop = CropBox { x: 0, y: 0, side: 128 };
        let b = pose_in_photo_frame(a, 200.0, &crop, 128, [64.0, 64.0]);
        assert!(a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-5), "{b:?}");
        // The crop's centre 20 px right of the axis at f = 200: the ray is turned by atan(0.1)
        // about the vertical axis, which adds to the yaw (a frontal face there is seen from the side).
        let crop = CropBox { x: 20, y: 0, side: 128 };
        let b = pose_in_photo_frame([0.0; 3], 200.0, &crop, 128, [64.0, 64.0]);
        assert!((b[0] - (-(0.1f32).atan())).abs() < 1e-4 && b[1].abs() < 1e-5 && b[2].abs() < 1e-5, "{b:?}");
    }
}
