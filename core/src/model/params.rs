//! The parameter vector of a fit: pose, focal length, SH light, shape and colour coefficients.

use crate::render::{Camera, Pose, ShLight};

/// Parameters of one sample, with capacities `KS` (shape) and `KC` (colour) in const generics.
///
/// The coefficients are fixed-capacity vectors holding the active ones only (the leading
/// components of the model; the others are never proposed); the principal point is the image
/// centre and is not a parameter.
#[derive(Debug, Clone, PartialEq)]
pub struct FitParams<const KS: usize, const KC: usize> {
    /// Rigid pose (Euler angles in radians, translation in mm; see [`Pose`]).
    pub pose: Pose,
    /// Focal length in pixels.
    pub focal: f32,
    /// Spherical-harmonics light (camera space).
    pub light: ShLight,
    /// The active shape coefficients (N(0, 1) prior), at most `KS`.
    pub shape: heapless::Vec<f32, KS>,
    /// The active colour coefficients (N(0, 1) prior), at most `KC`.
    pub color: heapless::Vec<f32, KC>,
}

impl<const KS: usize, const KC: usize> FitParams<KS, KC> {
    /// `shape_len` / `color_len` zero coefficients (clamped to the capacities).
    pub fn new(pose: Pose, focal: f32, light: ShLight, shape_len: usize, color_len: usize) -> Self {
        let mut shape = heapless::Vec::new();
        shape.resize(shape_len.min(KS), 0.0).unwrap_or_default();
        let mut color = heapless::Vec::new();
        color.resize(color_len.min(KC), 0.0).unwrap_or_default();
        Self { pose, focal, light, shape, color }
    }

    /// Number of active shape coefficients (`<= KS`).
    pub fn shape_len(&self) -> usize {
        self.shape.len()
    }

    /// Number of active colour coefficients (`<= KC`).
    pub fn color_len(&self) -> usize {
        self.color.len()
    }

    /// The active shape coefficients.
    pub fn shape_coeffs(&self) -> &[f32] {
        &self.shape
    }

    /// The active colour coefficients.
    pub fn color_coeffs(&self) -> &[f32] {
        &self.color
    }

    /// The active shape coefficients, mutable.
    pub fn shape_coeffs_mut(&mut self) -> &mut [f32] {
        &mut self.shape
    }

    /// The active colour coefficients, mutable.
    pub fn color_coeffs_mut(&mut self) -> &mut [f32] {
        &mut self.color
    }

    /// Appends a shape coefficient; hands it back if all `KS` are in use.
    pub fn push_shape(&mut self, c: f32) -> Result<(), f32> {
        self.shape.push(c)
    }

    /// Appends a colour coefficient; hands it back if all `KC` are in use.
    pub fn push_color(&mut self, c: f32) -> Result<(), f32> {
        self.color.push(c)
    }

    /// The camera for a `width × height` image: this focal length, principal point at the centre.
    pub fn camera(&self, width: u32, height: u32) -> Camera {
        Camera::centered(width, height, self.focal)
    }

    /// Whether every value is finite and the focal length positive.
    pub fn is_valid(&self) -> bool {
        let p = &self.pose;
        let pose_ok = p.yaw.is_finite() && p.pitch.is_finite() && p.roll.is_finite() && p.translation.iter().all(|v| v.is_finite());
        pose_ok
            && self.focal.is_finite()
            && self.focal > 0.0
            && self.light.coeffs.iter().flatten().all(|v| v.is_finite())
            && self.shape.iter().chain(self.color.iter()).all(|v| v.is_finite())
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
        p.color_coeffs_mut()[0] = f32::NAN;
        assert!(!p.is_valid());
        p.color_coeffs_mut()[0] = 0.0;
        // A full vector hands the coefficient back.
        assert_eq!(p.push_color(1.0), Ok(()));
        assert_eq!(p.push_color(2.0), Err(2.0));
        p.focal = 0.0;
        assert!(!p.is_valid());
    }
}
