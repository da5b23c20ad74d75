//! Closed-form least-squares SH light from sampled visible vertices.
//!
//! For each sampled vertex facing the camera, the target colour at its projected position should
//! equal `albedo_c · Σ_i B_i(R n) · L_i,c` (B: the Lambert-convolved SH basis): linear in the light.
//! Per channel this gives 9×9 normal equations `(Σ a² B Bᵀ + λ m I) L_c = Σ a I_c B + λ m L0_c`
//! (m: number of samples; the ridge term pulls toward a mean light `L0`), solved by Cholesky.
//! Visibility is a back-facing test only (self-occlusion, e.g. by the nose, is ignored).

use crate::error::FitError;
use crate::fit::likelihood::image::TargetImage;
use crate::geometry::mat_vec;
use crate::geometry::Vec3;
use crate::render::light::{lambert_basis, SH_COEFFS};
use crate::render::{Camera, Pose, ShLight};

/// How vertices are sampled and the system regularized.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LightSolveConfig {
    /// Use every `stride`-th vertex (≥ 1).
    pub stride: usize,
    /// Start at this vertex (vary it to use different samples).
    pub offset: usize,
    /// Minimum cosine between the normal and the direction to the camera.
    pub min_cos: f32,
    /// Ridge weight per sample toward `mean`.
    pub lambda: f32,
    /// The light the ridge pulls toward.
    pub mean: ShLight,
}

impl Default for LightSolveConfig {
    fn default() -> Self {
        Self { stride: 7, offset: 0, min_cos: 0.2, lambda: 1e-3, mean: ShLight::ambient([0.8; 3]) }
    }
}

/// Solves the SH light explaining `image` from an instance (model-space `positions`, unit
/// `normals`, `albedos`) under `pose` and `camera`. Errors if fewer than 9 vertices are usable
/// or a system is singular.
pub fn solve_light(
    positions: &[Vec3],
    normals: &[Vec3],
    albedos: &[Vec3],
    pose: &Pose,
    camera: &Camera,
    image: &TargetImage<'_>,
    config: &LightSolveConfig,
) -> Result<ShLight, FitError> {
    if normals.len() != positions.len() || albedos.len() != positions.len() {
        return Err(FitError::LengthMismatch);
    }
    if config.stride == 0 || !(config.lambda >= 0.0 && config.lambda.is_finite()) {
        return Err(FitError::BadConfig);
    }
    let mut ata = [[[0.0f32; SH_COEFFS]; SH_COEFFS]; 3];
    let mut atb = [[0.0f32; SH_COEFFS]; 3];
    let m = visit_facing(positions, normals, pose, camera, image, config.offset, config.stride, config.min_cos, |v, nc, target| {
        let Some(a) = albedos.get(v) else { return };
        let b = lambert_basis(nc);
        for c in 0..3 {
            let (Some(&ac), Some(&ic), Some(mat), Some(rhs)) = (a.get(c), target.get(c), ata.get_mut(c), atb.get_mut(c)) else {
                continue;
            };
            for ((row, rh), bi) in mat.iter_mut().zip(rhs.iter_mut()).zip(&b) {
                let wi = ac * bi;
                *rh += wi * ic;
                for (e, bj) in row.iter_mut().zip(&b) {
                    *e += wi * ac * bj;
                }
            }
        }
    });
    if m < SH_COEFFS {
        return Err(FitError::Singular);
    }
    let ridge = config.lambda * m as f32;
    let mut light = ShLight::zero();
    for c in 0..3 {
        let (Some(mat), Some(rhs)) = (ata.get_mut(c), atb.get_mut(c)) else { continue };
        for (i, (row, rh)) in mat.iter_mut().zip(rhs.iter_mut()).enumerate() {
            if let Some(e) = row.get_mut(i) {
                *e += ridge;
            }
            *rh += ridge * config.mean.coeffs.get(i).and_then(|v| v.get(c)).copied().unwrap_or(0.0);
        }
        let x = cholesky_solve(mat, rhs)?;
        for (l, v) in light.coeffs.iter_mut().zip(x) {
            if let Some(lc) = l.get_mut(c) {
                *lc = v;
            }
        }
    }
    if !light.coeffs.iter().flatten().all(|v| v.is_finite()) {
        return Err(FitError::Singular);
    }
    Ok(light)
}

/// A model-space vertex seen from the camera: where it is, where its normal points, and how
/// squarely it faces the camera.
pub struct Facing {
    /// Camera-space position.
    pub position: Vec3,
    /// Camera-space normal.
    pub normal: Vec3,
    /// Cosine between the normal and the direction to the camera (1: facing it, < 0: turned away;
    /// NaN at the camera's centre or for a degenerate normal).
    pub cos: f32,
}

/// The vertex at `p` with normal `n` (model space) under rotation `r` and translation `t`: the one
/// facing test of the light, colour and shape solves and of the contour landmarks.
pub fn facing(r: &[[f32; 3]; 3], t: Vec3, p: Vec3, n: Vec3) -> Facing {
    let normal = mat_vec(r, n);
    let q = mat_vec(r, p);
    let position = [q[0] + t[0], q[1] + t[1], q[2] + t[2]];
    let dist = libm::sqrtf(position[0] * position[0] + position[1] * position[1] + position[2] * position[2]);
    let cos = -(normal[0] * position[0] + normal[1] * position[1] + normal[2] * position[2]) / dist;
    Facing { position, normal, cos }
}

/// Calls `f(vertex, camera-space normal, target colour)` for every `stride`-th vertex from
/// `offset` that faces the camera (cosine ≥ `min_cos`) and projects into `image`; returns their
/// number. The sample walk of the light and colour solves (visibility is a back-facing test only).
#[allow(clippy::too_many_arguments)]
pub(in crate::fit) fn visit_facing(
    positions: &[Vec3],
    normals: &[Vec3],
    pose: &Pose,
    camera: &Camera,
    image: &TargetImage<'_>,
    offset: usize,
    stride: usize,
    min_cos: f32,
    mut f: impl FnMut(usize, Vec3, Vec3),
) -> usize {
    let r = pose.rotation();
    let mut m = 0;
    for (v, (p, n)) in positions.iter().zip(normals).enumerate().skip(offset).step_by(stride.max(1)) {
        let Facing { position: pc, normal: nc, cos } = facing(&r, pose.translation, *p, *n);
        if cos.is_nan() || cos < min_cos {
            continue;
        }
        let Some(s) = camera.project(pc) else { continue };
        let Some(target) = image.sample(s.x, s.y) else { continue };
        f(v, nc, target);
        m += 1;
    }
    m
}

/// Solves `A x = b` for a symmetric positive-definite 9×9 `A` (overwritten by its Cholesky factor).
fn cholesky_solve(a: &mut [[f32; SH_COEFFS]; SH_COEFFS], b: &[f32; SH_COEFFS]) -> Result<[f32; SH_COEFFS], FitError> {
    super::cholesky::solve(a, b, SH_COEFFS)
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing, clippy::needless_range_loop)]
mod tests {
    use super::*;

    #[test]
    fn cholesky_solves_a_known_system() {
        let mut a = [[0.0f32; 9]; 9];
        for i in 0..9 {
            for j in 0..9 {
                a[i][j] = 1.0 / (1.0 + (i as f32 - j as f32).abs());
            }
            a[i][i] += 2.0;
        }
        let x_true = [1.0, -2.0, 0.5, 0.0, 3.0, -1.0, 0.25, 2.0, -0.75];
        let mut b = [0.0f32; 9];
        for i in 0..9 {
            b[i] = (0..9).map(|j| a[i][j] * x_true[j]).sum();
        }
        let x = cholesky_solve(&mut a, &b).unwrap();
        for (u, v) in x.iter().zip(&x_true) {
            assert!((u - v).abs() < 1e-4, "{x:?}");
        }
        let mut z = [[0.0f32; 9]; 9];
        assert_eq!(cholesky_solve(&mut z, &b).err(), Some(FitError::Singular));
    }
}
