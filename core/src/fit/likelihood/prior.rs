//! Prior: N(0, 1) coefficients, weak Gaussian pose, focal-length and light priors.

use crate::geometry::Vec3;
use crate::model::params::FitParams;
use crate::render::ShLight;

/// Independent Gaussian priors on every parameter (log densities up to a constant).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prior {
    /// σ of yaw, pitch and roll around 0 (radians).
    pub rotation_sigma: [f32; 3],
    /// Mean of the translation (mm), usually the initial guess.
    pub translation_mean: Vec3,
    /// σ of the translation per axis (mm).
    pub translation_sigma: Vec3,
    /// Mean focal length (px).
    pub focal_mean: f32,
    /// σ of the focal length (px).
    pub focal_sigma: f32,
    /// Mean light.
    pub light_mean: ShLight,
    /// σ of every SH coefficient around the mean.
    pub light_sigma: f32,
}

impl Prior {
    /// Weak priors around an initial guess: rotation σ 35°, translation σ (150, 150, 40 % of the
    /// distance) mm, focal σ 40 %, light σ 1 per coefficient around an ambient 0.8.
    pub fn around<const KS: usize, const KC: usize>(init: &FitParams<KS, KC>) -> Self {
        let d = libm::fabsf(init.pose.translation[2]).max(1.0);
        Self {
            rotation_sigma: [0.61; 3],
            translation_mean: init.pose.translation,
            translation_sigma: [150.0, 150.0, 0.4 * d],
            focal_mean: init.focal,
            focal_sigma: 0.4 * init.focal,
            light_mean: ShLight::ambient([0.8; 3]),
            light_sigma: 1.0,
        }
    }

    /// Log prior of the shape and colour coefficients alone: `−½ Σ c²`.
    pub fn log_coefficients<const KS: usize, const KC: usize>(p: &FitParams<KS, KC>) -> f32 {
        -0.5 * p.shape_coeffs().iter().chain(p.color_coeffs()).map(|c| c * c).sum::<f32>()
    }

    /// Log prior density of `p` (up to a constant); `−∞` if `p` is not valid (NaN, focal ≤ 0).
    pub fn log_density<const KS: usize, const KC: usize>(&self, p: &FitParams<KS, KC>) -> f32 {
        if !p.is_valid() {
            return f32::NEG_INFINITY;
        }
        let g = |x: f32, m: f32, s: f32| {
            let z = (x - m) / s;
            -0.5 * z * z
        };
        let pose = &p.pose;
        let mut l = g(pose.yaw, 0.0, self.rotation_sigma[0])
            + g(pose.pitch, 0.0, self.rotation_sigma[1])
            + g(pose.roll, 0.0, self.rotation_sigma[2]);
        for ((t, m), s) in pose.translation.iter().zip(&self.translation_mean).zip(&self.translation_sigma) {
            l += g(*t, *m, *s);
        }
        l += g(p.focal, self.focal_mean, self.focal_sigma);
        let mut dl = 0.0f32;
        for (c, m) in p.light.coeffs.iter().flatten().zip(self.light_mean.coeffs.iter().flatten()) {
            dl += (c - m) * (c - m);
        }
        l += -0.5 * dl / (self.light_sigma * self.light_sigma);
        let l = l + Self::log_coefficients(p);
        if l.is_nan() {
            f32::NEG_INFINITY
        } else {
            l
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;
    use crate::render::Pose;

    #[test]
    fn prior_peaks_at_the_mean() {
        let init = FitParams::<3, 3>::new(Pose::frontal(600.0), 400.0, ShLight::ambient([0.8; 3]), 3, 3);
        let prior = Prior::around(&init);
        assert_eq!(prior.log_density(&init), 0.0);
        let mut p = init;
        p.shape[0] = 1.0;
        assert!((prior.log_density(&p) + 0.5).abs() < 1e-6);
        p.pose.yaw = 0.61;
        assert!((prior.log_density(&p) + 1.0).abs() < 1e-5);
        p.focal = f32::NAN;
        assert_eq!(prior.log_density(&p), f32::NEG_INFINITY);
    }
}
