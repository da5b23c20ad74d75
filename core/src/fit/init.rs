//! A starting point for the chains from the target landmarks alone.

use super::landmarks::{LandmarkTarget, MAX_LANDMARKS};
use super::morph::MorphableModel;
use super::params::FitParams;
use super::FitError;
use crate::shading::TriIndex;
use crate::{Pose, ShLight, Vec3};

/// Centroid of the mean shape's landmarks selected by the target's validity mask (all if none match).
pub fn landmark_pivot<I: TriIndex>(model: &MorphableModel<'_, I>, target: Option<&LandmarkTarget<'_>>) -> Result<Vec3, FitError> {
    let mut lm = [[0.0f32; 3]; MAX_LANDMARKS];
    let n = model.landmark_positions(&[], &mut lm)?;
    let (mut c, mut k) = ([0.0f32; 3], 0.0f32);
    for (i, p) in lm.iter().take(n).enumerate() {
        if target.is_some_and(|t| !t.valid().get(i).copied().unwrap_or(false)) {
            continue;
        }
        c = [c[0] + p[0], c[1] + p[1], c[2] + p[2]];
        k += 1.0;
    }
    if k == 0.0 {
        return Err(FitError::NoValidLandmarks);
    }
    Ok([c[0] / k, c[1] / k, c[2] / k])
}

/// A frontal pose that puts the model's (mean-shape) landmark centroid on the target's centroid,
/// at the distance where the landmarks' RMS spread matches, for focal length `focal` px on a
/// `width × height` image; zero coefficients (`shape_len`/`color_len` active) and `light`.
#[allow(clippy::too_many_arguments)]
pub fn initial_guess<I: TriIndex, const KS: usize, const KC: usize>(
    model: &MorphableModel<'_, I>,
    target: &LandmarkTarget<'_>,
    focal: f32,
    width: u32,
    height: u32,
    light: ShLight,
    shape_len: usize,
    color_len: usize,
) -> Result<FitParams<KS, KC>, FitError> {
    if target.len() != model.landmarks().len() {
        return Err(FitError::LengthMismatch);
    }
    if !(focal > 0.0 && focal.is_finite()) || width == 0 || height == 0 {
        return Err(FitError::BadConfig);
    }
    let pivot = landmark_pivot(model, Some(target))?;
    let mut lm = [[0.0f32; 3]; MAX_LANDMARKS];
    let n = model.landmark_positions(&[], &mut lm)?;
    let (mut r2, mut k) = (0.0f32, 0.0f32);
    for (p, _) in lm.iter().take(n).zip(target.valid()).filter(|(_, &v)| v) {
        r2 += (p[0] - pivot[0]) * (p[0] - pivot[0]) + (p[1] - pivot[1]) * (p[1] - pivot[1]);
        k += 1.0;
    }
    let r_model = libm::sqrtf(r2 / k.max(1.0));
    let (c_px, r_px) = target.spread();
    if !(r_px > 0.0 && r_model > 0.0) {
        return Err(FitError::BadConfig);
    }
    let w = focal * r_model / r_px;
    let (cx, cy) = (width as f32 * 0.5, height as f32 * 0.5);
    let cam = [(c_px[0] - cx) * w / focal, -(c_px[1] - cy) * w / focal, -w];
    let pose = Pose { yaw: 0.0, pitch: 0.0, roll: 0.0, translation: [cam[0] - pivot[0], cam[1] - pivot[1], cam[2] - pivot[2]] };
    let p = FitParams::new(pose, focal, light, shape_len.min(model.shape_rank()), color_len.min(model.color_rank()));
    if !p.is_valid() {
        return Err(FitError::NonFinite);
    }
    Ok(p)
}
