//! Pinhole camera.
//!
//! The camera sits at the origin of camera space looking down −z with y up (x right).
//! A camera-space point `(X, Y, Z)` with depth `w = −Z` projects to the pixel coordinates
//! `x = cx + f · X / w`, `y = cy − f · Y / w`. Image pixel `(0, 0)` is the top-left one and
//! covers `[0, 1) × [0, 1)`: its centre is at `(0.5, 0.5)`; y grows downward.

/// A pinhole camera: focal length and principal point in pixels, near plane in mm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Focal length in pixels (the same for x and y).
    pub focal: f32,
    /// Principal point `(cx, cy)` in pixel coordinates (image centre = `(width / 2, height / 2)`).
    pub principal: [f32; 2],
    /// Near-plane distance in mm (> 0); points with depth `w < near` are not projected.
    pub near: f32,
}

/// A camera-space point projected to the image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScreenPoint {
    /// Pixel x (right).
    pub x: f32,
    /// Pixel y (down).
    pub y: f32,
    /// `1 / w`, the reciprocal depth in 1/mm (linear in screen space; larger is closer).
    pub inv_w: f32,
}

impl Camera {
    /// A camera with the principal point at the centre of a `width × height` image and a 10 mm near plane.
    pub fn centered(width: u32, height: u32, focal: f32) -> Self {
        Self { focal, principal: [width as f32 * 0.5, height as f32 * 0.5], near: 10.0 }
    }

    /// Focal length giving a horizontal field of view of `fov_x` radians across `width` pixels.
    pub fn focal_from_fov(width: u32, fov_x: f32) -> f32 {
        width as f32 * 0.5 / libm::tanf(fov_x * 0.5)
    }

    /// Projects a camera-space point; `None` in front of the near plane (`w < near`) or if non-finite.
    pub fn project(&self, p: crate::geometry::Vec3) -> Option<ScreenPoint> {
        let w = -p[2];
        // Written so that NaN fails the test.
        if !(w >= self.near && w.is_finite()) {
            return None;
        }
        let inv_w = 1.0 / w;
        let x = self.principal[0] + self.focal * p[0] * inv_w;
        let y = self.principal[1] - self.focal * p[1] * inv_w;
        if x.is_finite() && y.is_finite() && inv_w.is_finite() && inv_w > 0.0 {
            Some(ScreenPoint { x, y, inv_w })
        } else {
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn projection_signs() {
        let c = Camera::centered(100, 80, 500.0);
        let p = c.project([10.0, 20.0, -1000.0]).unwrap_or(ScreenPoint { x: 0.0, y: 0.0, inv_w: 0.0 });
        assert!((p.x - 55.0).abs() < 1e-4);
        assert!((p.y - 30.0).abs() < 1e-4);
        assert!((p.inv_w - 1e-3).abs() < 1e-9);
        assert!(c.project([0.0, 0.0, -5.0]).is_none());
        assert!(c.project([0.0, 0.0, 5.0]).is_none());
        assert!(c.project([f32::NAN, 0.0, -100.0]).is_none());
    }
}
