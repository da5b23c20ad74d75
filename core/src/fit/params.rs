//! The parameter vector of a fit: pose, focal length, SH light, shape and colour coefficients.

use crate::{Camera, Pose, ShLight};

/// Parameters of one sample, with capacities `KS` (shape) and `KC` (colour) in const generics.
///
/// Only the first `shape_len` / `color_len` coefficients are active (the others stay zero and
/// are never proposed); the principal point is the image centre and is not a parameter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitParams<const KS: usize, const KC: usize> {
    /// Rigid pose (Euler angles in radians, translation in mm; see [`Pose`]).
    pub pose: Pose,
    /// Focal length in pixels.
    pub focal: f32,
    /// Spherical-harmonics light (camera space).
    pub light: ShLight,
    /// Shape coefficients (N(0, 1) prior); entries from `shape_len` on are zero.
    pub shape: [f32; KS],
    /// Colour coefficients (N(0, 1) prior); entries from `color_len` on are zero.
    pub color: [f32; KC],
    /// Number of active shape coefficients (`<= KS`).
    pub shape_len: usize,
    /// Number of active colour coefficients (`<= KC`).
    pub color_len: usize,
}

impl<const KS: usize, const KC: usize> FitParams<KS, KC> {
    /// Zero coefficients; `shape_len`/`color_len` are clamped to the capacities.
    pub fn new(pose: Pose, focal: f32, light: ShLight, shape_len: usize, color_len: usize) -> Self {
        Self { pose, focal, light, shape: [0.0; KS], color: [0.0; KC], shape_len: shape_len.min(KS), color_len: color_len.min(KC) }
    }

    /// The active shape coefficients.
    pub fn shape_coeffs(&self) -> &[f32] {
        self.shape.get(..self.shape_len).unwrap_or(&self.shape)
    }

    /// The active colour coefficients.
    pub fn color_coeffs(&self) -> &[f32] {
        self.color.get(..self.color_len).unwrap_or(&self.color)
    }

    /// The active shape coefficients, mutable.
    pub fn shape_coeffs_mut(&mut self) -> &mut [f32] {
        let n = self.shape_len.min(KS);
        self.shape.get_mut(..n).unwrap_or(&mut [])
    }

    /// The active colour coefficients, mutable.
    pub fn color_coeffs_mut(&mut self) -> &mut [f32] {
        let n = self.color_len.min(KC);
        self.color.get_mut(..n).unwrap_or(&mut [])
    }

    /// The camera for a `width × height` image: this focal length, principal point at the centre.
    pub fn camera(&self, width: u32, height: u32) -> Camera {
        Camera::centered(width, height, self.focal)
    }

    /// Whether every value is finite, the focal length positive and the active counts within capacity.
    pub fn is_valid(&self) -> bool {
        let p = &self.pose;
        let pose_ok = p.yaw.is_finite() && p.pitch.is_finite() && p.roll.is_finite() && p.translation.iter().all(|v| v.is_finite());
        pose_ok
            && self.focal.is_finite()
            && self.focal > 0.0
            && self.light.coeffs.iter().flatten().all(|v| v.is_finite())
            && self.shape.iter().chain(self.color.iter()).all(|v| v.is_finite())
            && self.shape_len <= KS
            && self.color_len <= KC
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    #[test]
    fn active_slices_and_validity() {
        let mut p = FitParams::<4, 2>::new(Pose::frontal(500.0), 300.0, ShLight::frontal(), 9, 1);
        assert_eq!(p.shape_coeffs().len(), 4);
        assert_eq!(p.color_coeffs().len(), 1);
        p.shape_coeffs_mut()[1] = 0.5;
        assert!(p.is_valid());
        p.color[1] = f32::NAN;
        assert!(!p.is_valid());
        p.color[1] = 0.0;
        p.focal = 0.0;
        assert!(!p.is_valid());
    }
}
