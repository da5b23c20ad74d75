//! How well a fit's landmarks pin its pose down: a Laplace approximation of the pose's posterior
//! in which the landmarks' noise is what the fit left of them.
//!
//! The image chain's own spread says how far its samples wander, not how far the fit is from the
//! truth: thousands of pixels counted as independent witnesses make its posterior far too
//! narrow, and what limits a fit is the model's mismatch with the face (the template's landmark
//! depths are not the person's), which no pixel noise model describes. Here the pose's
//! covariance is that of a least-squares fit of the six pose parameters (yaw, pitch, roll,
//! translation) to the target landmarks, `σ̂² (JᵀJ)⁻¹`, with `J` the projected landmarks'
//! derivatives (central differences) and `σ̂²` the residual variance the fit left
//! (`Σ r² / (2m − 6)` over its `m` usable landmarks): a fit whose landmarks the model cannot
//! reach gets a wider spread. A caller scales it by a factor calibrated on a development set
//! (the host's `POSE_SPREAD_FACTOR`), since the residuals of one face are not independent.

use crate::error::FitError;
use crate::fit::likelihood::landmarks::LandmarkTarget;
use crate::fit::solve::cholesky;
use crate::fit::solve::shape::pose_moved_by;
use crate::geometry::{TriIndex, Vec3};
use crate::model::morphable::MorphableModel;
use crate::model::params::FitParams;
use crate::render::Pose;

/// Parameters of the pose the spread is about: yaw, pitch, roll (radians), translation (mm).
const POSE_PARAMS: usize = 6;
/// Central-difference steps: 1 mrad for the angles, 0.5 mm for the translation.
const STEPS: [f32; POSE_PARAMS] = [1e-3, 1e-3, 1e-3, 0.5, 0.5, 0.5];

/// The pose's spread from the landmarks (before any calibration factor).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PoseSpread {
    /// Standard deviations of yaw, pitch and roll (radians).
    pub angles_sd: [f32; 3],
    /// Standard deviations of the translation (mm).
    pub translation_sd: [f32; 3],
    /// The residual σ of the landmarks (px) the spread is scaled by.
    pub residual_sigma_px: f32,
    /// Landmarks used.
    pub landmarks: u32,
}

/// The spread of `params`' pose given the `target` landmarks (its valid ones) in a `width ×
/// height` image. Errors with [`FitError::Singular`] when fewer than 4 landmarks are usable or
/// they do not determine the pose, [`FitError::NonFinite`] when one lies behind the camera.
/// Never inlined: the fit calls it last, and its buffers must not join the fit's own stack frame
/// (a device's stack peak is the chains').
#[inline(never)]
pub fn pose_spread<I: TriIndex, const KS: usize, const KC: usize>(
    model: &MorphableModel<'_, I>,
    params: &FitParams<KS, KC>,
    target: &LandmarkTarget<'_>,
    width: u32,
    height: u32,
) -> Result<PoseSpread, FitError> {
    let n = model.landmarks().len();
    if target.len() != n {
        return Err(FitError::LengthMismatch);
    }
    let cam = params.camera(width, height);
    let project = |pose: &Pose, p: Vec3| -> Result<[f32; 2], FitError> {
        cam.project(pose.transform_point(p)).map(|s| [s.x, s.y]).ok_or(FitError::NonFinite)
    };
    // The normal matrix JᵀJ and the residuals' sum of squares, one landmark at a time (no buffer
    // of every landmark's position on a device's stack).
    let mut jtj = [[0.0f32; POSE_PARAMS]; POSE_PARAMS];
    let (mut rss, mut m) = (0.0f32, 0u32);
    for (k, (t, _)) in target.points().iter().zip(target.valid()).enumerate().filter(|(_, (_, v))| **v) {
        let p = &model.landmark_position(params.shape_coeffs(), k)?;
        let at = project(&params.pose, *p)?;
        rss += (at[0] - t[0]) * (at[0] - t[0]) + (at[1] - t[1]) * (at[1] - t[1]);
        m += 1;
        let mut row = [[0.0f32; 2]; POSE_PARAMS];
        for (k, (r, h)) in row.iter_mut().zip(STEPS).enumerate() {
            let (a, b) = (project(&pose_moved_by(&params.pose, k, h), *p)?, project(&pose_moved_by(&params.pose, k, -h), *p)?);
            *r = [(a[0] - b[0]) / (2.0 * h), (a[1] - b[1]) / (2.0 * h)];
        }
        for (i, ri) in row.iter().enumerate() {
            for (j, rj) in row.iter().enumerate() {
                if let Some(e) = jtj.get_mut(i).and_then(|r| r.get_mut(j)) {
                    *e += ri[0] * rj[0] + ri[1] * rj[1];
                }
            }
        }
    }
    if m < 4 {
        return Err(FitError::Singular);
    }
    let sigma2 = rss / (2 * m - POSE_PARAMS as u32) as f32;
    // Columns scaled to a unit diagonal (radians and millimetres differ by orders of magnitude).
    let scale: [f32; POSE_PARAMS] = core::array::from_fn(|k| {
        let d = jtj.get(k).and_then(|r| r.get(k)).copied().unwrap_or(0.0);
        if d > 0.0 {
            1.0 / libm::sqrtf(d)
        } else {
            0.0
        }
    });
    let scaled: [[f32; POSE_PARAMS]; POSE_PARAMS] = core::array::from_fn(|i| {
        core::array::from_fn(|j| {
            let e = jtj.get(i).and_then(|r| r.get(j)).copied().unwrap_or(0.0);
            e * scale.get(i).copied().unwrap_or(0.0) * scale.get(j).copied().unwrap_or(0.0)
        })
    });
    // The inverse's diagonal, one unit right-hand side at a time.
    let mut sd = [0.0f32; POSE_PARAMS];
    for (k, s) in sd.iter_mut().enumerate() {
        let mut a = scaled;
        let e: [f32; POSE_PARAMS] = core::array::from_fn(|i| if i == k { 1.0 } else { 0.0 });
        let x = cholesky::solve(&mut a, &e, POSE_PARAMS)?;
        let var = x.get(k).copied().unwrap_or(0.0) * scale.get(k).map_or(0.0, |c| c * c) * sigma2;
        if !(var >= 0.0 && var.is_finite()) {
            return Err(FitError::Singular);
        }
        *s = libm::sqrtf(var);
    }
    let [y, p, r, tx, ty, tz] = sd;
    Ok(PoseSpread { angles_sd: [y, p, r], translation_sd: [tx, ty, tz], residual_sigma_px: libm::sqrtf(sigma2), landmarks: m })
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;
    use crate::fit::project_landmarks;
    use crate::model::{Basis, FactoredBasis};
    use crate::render::ShLight;

    /// A ring of 12 points at two depths (a face-like spread of landmarks), no components.
    fn ring() -> ([[f32; 3]; 12], [u32; 12]) {
        let pts = core::array::from_fn(|i| {
            let a = i as f32 * core::f32::consts::TAU / 12.0;
            [60.0 * libm::cosf(a), 70.0 * libm::sinf(a), if i % 2 == 0 { 20.0 } else { -10.0 }]
        });
        (pts, core::array::from_fn(|i| i as u32))
    }

    #[test]
    fn the_spread_grows_with_what_the_fit_leaves_of_the_landmarks() {
        let (pts, ids) = ring();
        let none = || FactoredBasis::new(&[], &[], 12).map(Basis::Factored).unwrap();
        let triangles: [[u32; 3]; 1] = [[0, 1, 2]];
        let model = MorphableModel::new(&pts, &[[0.5; 3]; 12], none(), none(), &triangles, &ids).unwrap();
        let params = FitParams::<0, 0>::new(Pose { yaw: 0.2, ..Pose::frontal(500.0) }, 800.0, ShLight::ambient_white(), 0, 0);
        let mut exact = [[0.0f32; 2]; 12];
        project_landmarks(&model, &params, 256, 256, &mut exact).unwrap();
        // Noise of ±1 and ±3 px in a fixed pattern.
        let noisy = |amp: f32| -> [[f32; 2]; 12] {
            core::array::from_fn(|i| {
                let s = if i % 3 == 0 { 1.0 } else { -1.0 };
                [exact[i][0] + amp * s, exact[i][1] - amp * s * if i % 2 == 0 { 1.0 } else { -0.5 }]
            })
        };
        let valid = [true; 12];
        let (one, three) = (noisy(1.0), noisy(3.0));
        let small = pose_spread(&model, &params, &LandmarkTarget::new(&one, &valid, 1.0).unwrap(), 256, 256).unwrap();
        let large = pose_spread(&model, &params, &LandmarkTarget::new(&three, &valid, 1.0).unwrap(), 256, 256).unwrap();
        assert_eq!(small.landmarks, 12);
        assert!(small.residual_sigma_px > 0.5 && small.residual_sigma_px < 2.0, "{}", small.residual_sigma_px);
        // The residual σ and every standard deviation scale with the noise.
        for k in 0..3 {
            let ratio = large.angles_sd[k] / small.angles_sd[k];
            assert!((ratio - 3.0).abs() < 0.05, "{k}: {ratio}");
            assert!(small.angles_sd[k] > 0.0 && small.angles_sd[k] < 0.05, "{k}: {}", small.angles_sd[k]);
        }
        assert!(small.translation_sd.iter().all(|s| *s > 0.0 && s.is_finite()));
        // Too few landmarks do not determine the pose.
        let few = [true, true, true, false, false, false, false, false, false, false, false, false];
        assert_eq!(pose_spread(&model, &params, &LandmarkTarget::new(&one, &few, 1.0).unwrap(), 256, 256).err(), Some(FitError::Singular));
    }
}
