//! A starting point for the chains from the target landmarks alone.

use crate::error::FitError;
use crate::fit::likelihood::landmarks::LandmarkTarget;
use crate::geometry::mat_vec;
use crate::geometry::{TriIndex, Vec3};
use crate::model::morphable::MorphableModel;
use crate::model::params::FitParams;
use crate::model::MAX_LANDMARKS;
use crate::render::{Pose, ShLight};

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

/// A start pose from the landmarks alone: the rotation of a scaled-orthographic fit of the mean
/// shape's landmarks to the target (frontal if that fit is degenerate), the model's landmark
/// centroid on the target's centroid, at the distance where the landmarks' RMS spread matches, for
/// focal length `focal` px on a `width × height` image; zero coefficients (`shape_len`/`color_len`
/// active) and `light`.
///
/// Why not frontal: the landmark chain starts from here, and a chain that must walk from yaw 0 to a
/// 45° profile spends most of its steps on the way (on synthetic faces it ended 3–6° short, by an
/// amount that depended on the seed).
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
    let (c_px, r_px) = target.spread();
    let angles = orthographic_angles(lm.get(..n).unwrap_or(&[]), pivot, target, c_px).unwrap_or([0.0; 3]);
    let mut pose = Pose { yaw: angles[0], pitch: angles[1], roll: angles[2], translation: [0.0; 3] };
    let rot = pose.rotation();
    let rp = mat_vec(&rot, pivot);
    let (mut r2, mut k) = (0.0f32, 0.0f32);
    for (p, _) in lm.iter().take(n).zip(target.valid()).filter(|(_, &v)| v) {
        let q = mat_vec(&rot, *p);
        r2 += (q[0] - rp[0]) * (q[0] - rp[0]) + (q[1] - rp[1]) * (q[1] - rp[1]);
        k += 1.0;
    }
    let r_model = libm::sqrtf(r2 / k.max(1.0));
    if !(r_px > 0.0 && r_model > 0.0) {
        return Err(FitError::BadConfig);
    }
    let w = focal * r_model / r_px;
    let (cx, cy) = (width as f32 * 0.5, height as f32 * 0.5);
    let cam = [(c_px[0] - cx) * w / focal, -(c_px[1] - cy) * w / focal, -w];
    pose.translation = [cam[0] - rp[0], cam[1] - rp[1], cam[2] - rp[2]];
    let p = FitParams::new(pose, focal, light, shape_len.min(model.shape_rank()), color_len.min(model.color_rank()));
    if !p.is_valid() {
        return Err(FitError::NonFinite);
    }
    Ok(p)
}

/// Yaw, pitch and roll (radians) of the scaled-orthographic camera that best maps the model
/// landmarks `lm` (centred on `pivot`) to the valid target points (centred on `c_px`), by linear
/// least squares for the 2×3 projection and orthonormalization of its rows. `None` if degenerate.
fn orthographic_angles(lm: &[Vec3], pivot: Vec3, target: &LandmarkTarget<'_>, c_px: [f32; 2]) -> Option<[f32; 3]> {
    // Normal equations: M · A = B with A = Σ X Xᵀ (3×3), B = Σ p Xᵀ (2×3); image y points down.
    let (mut a, mut b) = ([[0.0f32; 3]; 3], [[0.0f32; 3]; 2]);
    for ((q, t), _) in lm.iter().zip(target.points()).zip(target.valid()).filter(|(_, &v)| v) {
        let x = [q[0] - pivot[0], q[1] - pivot[1], q[2] - pivot[2]];
        let p = [t[0] - c_px[0], -(t[1] - c_px[1])];
        for (row, xi) in a.iter_mut().zip(x) {
            for (e, xj) in row.iter_mut().zip(x) {
                *e += xi * xj;
            }
        }
        for (row, pi) in b.iter_mut().zip(p) {
            for (e, xj) in row.iter_mut().zip(x) {
                *e += pi * xj;
            }
        }
    }
    let inv = inverse3(&a)?;
    let [i0, i1, i2] = inv;
    let m = b.map(|[r0, r1, r2]| {
        [r0 * i0[0] + r1 * i1[0] + r2 * i2[0], r0 * i0[1] + r1 * i1[1] + r2 * i2[1], r0 * i0[2] + r1 * i1[2] + r2 * i2[2]]
    });
    let [r1, r2] = m;
    let e1 = normalized(r1)?;
    let d = dot(r2, e1);
    let e2 = normalized([r2[0] - d * e1[0], r2[1] - d * e1[1], r2[2] - d * e1[2]])?;
    let e3 = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]];
    // R = Rz(roll) Ry(yaw) Rx(pitch) has rows e1, e2, e3: its last row is (−sin yaw, cos yaw sin pitch,
    // cos yaw cos pitch), and its first column (cos roll cos yaw, sin roll cos yaw, ·).
    let yaw = libm::atan2f(-e3[0], libm::sqrtf(e3[1] * e3[1] + e3[2] * e3[2]));
    let pitch = libm::atan2f(e3[1], e3[2]);
    let roll = libm::atan2f(e2[0], e1[0]);
    let angles = [yaw, pitch, roll];
    angles.iter().all(|v| v.is_finite()).then_some(angles)
}

fn dot(a: Vec3, b: Vec3) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn normalized(v: Vec3) -> Option<Vec3> {
    let n = libm::sqrtf(dot(v, v));
    (n > 0.0 && n.is_finite()).then(|| [v[0] / n, v[1] / n, v[2] / n])
}

/// The inverse of a 3×3 matrix by its adjugate; `None` if (nearly) singular.
fn inverse3(a: &[[f32; 3]; 3]) -> Option<[[f32; 3]; 3]> {
    let [[a00, a01, a02], [a10, a11, a12], [a20, a21, a22]] = *a;
    let c00 = a11 * a22 - a12 * a21;
    let c01 = a12 * a20 - a10 * a22;
    let c02 = a10 * a21 - a11 * a20;
    let det = a00 * c00 + a01 * c01 + a02 * c02;
    let scale = a00.abs() + a11.abs() + a22.abs();
    if det.abs() <= 1e-9 * scale * scale * scale || !det.is_finite() {
        return None;
    }
    let inv = 1.0 / det;
    Some([
        [c00 * inv, (a02 * a21 - a01 * a22) * inv, (a01 * a12 - a02 * a11) * inv],
        [c01 * inv, (a00 * a22 - a02 * a20) * inv, (a02 * a10 - a00 * a12) * inv],
        [c02 * inv, (a01 * a20 - a00 * a21) * inv, (a00 * a11 - a01 * a10) * inv],
    ])
}
