//! Colour coefficients by regularized least squares, for fixed geometry and light.
//!
//! For a sampled vertex facing the camera, the rendered colour is `e_c · (m_c + Σ_k a_k B_k,c)`
//! (irradiance `e` of its rotated normal under the light, mean albedo `m`, colour basis `B`): linear
//! in the coefficients `a`. Against the target colours `I` at the projected vertices, the
//! posterior mode under the prior `a ~ N(0, I)` with pixel noise σ minimizes
//! `w Σ (e (m + B a) − I)² + |a|²`, `w` = [`ColorSolveConfig::weight`] / σ² per sample. The
//! normal equations `(w AᵀA + I) a = w Aᵀ (I − e m)` are solved by conjugate gradients (Jacobi
//! preconditioned) without
//! forming the matrix (each iteration is one pass over the samples), so memory is a few
//! coefficient vectors and one row of the basis: nothing scales with the model.
//! Visibility is a back-facing test only, as in [`crate::fit::solve::light`].

use crate::error::FitError;
use crate::fit::likelihood::image::TargetImage;
use crate::fit::solve::light::visit_facing;
use crate::geometry::{TriIndex, Vec3};
use crate::model::basis::ModelError;
use crate::model::morphable::MorphableModel;
use crate::render::{Camera, Pose, ShLight};

/// How vertices are sampled, weighted against the prior, and how long the solver runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ColorSolveConfig {
    /// Use every `stride`-th vertex (≥ 1).
    pub stride: usize,
    /// Minimum cosine between the normal and the direction to the camera.
    pub min_cos: f32,
    /// Pixel noise σ of the image likelihood (linear colour).
    pub pixel_sigma: f32,
    /// Pixels one sample stands for: the data term is `weight / σ²` per sample and channel.
    pub weight: f32,
    /// Conjugate-gradient iterations (at most; it stops early once converged).
    pub iterations: u32,
}

/// Geometry and light of the solve: where the instance is and how it is lit.
#[derive(Debug, Clone, Copy)]
pub struct ColorScene<'s, 'i> {
    /// Model-space vertex positions of the shape instance.
    pub positions: &'s [Vec3],
    /// Unit model-space vertex normals of the shape instance.
    pub normals: &'s [Vec3],
    /// The pose.
    pub pose: &'s Pose,
    /// The camera.
    pub camera: &'s Camera,
    /// The light.
    pub light: &'s ShLight,
    /// The target image.
    pub image: &'s TargetImage<'i>,
}

/// Calls `f(vertex, irradiance, target)` for every usable sampled vertex; returns their number.
fn visit_samples(scene: &ColorScene<'_, '_>, config: &ColorSolveConfig, mut f: impl FnMut(usize, Vec3, Vec3)) -> usize {
    let ColorScene { positions, normals, pose, camera, light, image } = *scene;
    visit_facing(positions, normals, pose, camera, image, 0, config.stride, config.min_cos, |v, nc, target| {
        f(v, light.irradiance(nc), target)
    })
}

/// The rendered colour change `e ⊙ Σ_k x_k row_k` of one vertex (`row`: its basis row).
fn row_times(row: &[Vec3], e: Vec3, x: &[f32]) -> Vec3 {
    let mut s = [0.0f32; 3];
    for (b, xk) in row.iter().zip(x) {
        s[0] += xk * b[0];
        s[1] += xk * b[1];
        s[2] += xk * b[2];
    }
    [e[0] * s[0], e[1] * s[1], e[2] * s[2]]
}

/// Adds `scale · Σ_c e_c row_k,c d_c` to `out[k]` for every component `k`.
fn add_row_transposed(row: &[Vec3], e: Vec3, d: Vec3, scale: f32, out: &mut [f32]) {
    let ed = [scale * e[0] * d[0], scale * e[1] * d[1], scale * e[2] * d[2]];
    for (o, b) in out.iter_mut().zip(row) {
        *o += b[0] * ed[0] + b[1] * ed[1] + b[2] * ed[2];
    }
}

fn dot(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Solves the colour coefficients `coeffs` (at most `KC`; their values on entry are the start)
/// that explain `scene.image` under `scene`'s geometry and light. Returns the number of samples.
/// Errors on a bad configuration, too few samples (fewer than 16) or a non-finite solution
/// (then `coeffs` is left as it was).
pub fn solve_color<I: TriIndex, const KC: usize>(
    model: &MorphableModel<'_, I>,
    scene: &ColorScene<'_, '_>,
    config: &ColorSolveConfig,
    coeffs: &mut [f32],
) -> Result<usize, FitError> {
    let n = model.vertices();
    if scene.positions.len() != n || scene.normals.len() != n {
        return Err(FitError::LengthMismatch);
    }
    let ok = |v: f32| v > 0.0 && v.is_finite();
    if config.stride == 0 || !config.min_cos.is_finite() || !ok(config.pixel_sigma) || !ok(config.weight) {
        return Err(FitError::BadConfig);
    }
    let k = coeffs.len();
    if k > KC || k > model.color_rank() {
        return Err(FitError::Model(ModelError::TooManyCoefficients));
    }
    if k == 0 {
        return Ok(0);
    }
    let w = config.weight / (config.pixel_sigma * config.pixel_sigma);
    let mean = model.color_mean();
    let mut x = [0.0f32; KC];
    let mut res = [0.0f32; KC];
    let mut p = [0.0f32; KC];
    let mut ap = [0.0f32; KC];
    let mut diag = [1.0f32; KC];
    let mut row = [[0.0f32; 3]; KC];
    let (Some(x), Some(res), Some(p), Some(ap), Some(diag), Some(row)) =
        (x.get_mut(..k), res.get_mut(..k), p.get_mut(..k), ap.get_mut(..k), diag.get_mut(..k), row.get_mut(..k))
    else {
        return Err(FitError::Model(ModelError::TooManyCoefficients));
    };
    x.copy_from_slice(coeffs);
    // res = w Aᵀ (I − e m − A x) − x: the negative gradient at the start; diag: the diagonal of
    // w AᵀA + I, the preconditioner (Jacobi).
    let samples = visit_samples(scene, config, |v, e, target| {
        let m = mean.get(v).copied().unwrap_or([0.0; 3]);
        model.color_components_at(v, row);
        let ax = row_times(row, e, x);
        let d = [target[0] - e[0] * m[0] - ax[0], target[1] - e[1] * m[1] - ax[1], target[2] - e[2] * m[2] - ax[2]];
        add_row_transposed(row, e, d, w, res);
        let e2 = [w * e[0] * e[0], w * e[1] * e[1], w * e[2] * e[2]];
        for (g, b) in diag.iter_mut().zip(row.iter()) {
            *g += e2[0] * b[0] * b[0] + e2[1] * b[1] * b[1] + e2[2] * b[2] * b[2];
        }
    });
    if samples < 16 {
        return Err(FitError::Singular);
    }
    for (r, xi) in res.iter_mut().zip(x.iter()) {
        *r -= xi;
    }
    // Preconditioned conjugate gradients: z = res / diag.
    let precondition = |p: &mut [f32], res: &[f32]| {
        for ((pi, ri), g) in p.iter_mut().zip(res).zip(diag.iter()) {
            *pi = ri / g;
        }
    };
    precondition(p, res);
    let mut rz = dot(res, p);
    let tolerance = rz * 1e-10;
    for _ in 0..config.iterations {
        if rz.is_nan() || rz <= tolerance {
            break;
        }
        // ap = (w AᵀA + I) p
        ap.copy_from_slice(p);
        visit_samples(scene, config, |v, e, _| {
            model.color_components_at(v, row);
            let a = row_times(row, e, p);
            add_row_transposed(row, e, a, w, ap);
        });
        let pap = dot(p, ap);
        if pap.is_nan() || pap <= 0.0 {
            break;
        }
        let alpha = rz / pap;
        for ((xi, ri), (pi, api)) in x.iter_mut().zip(res.iter_mut()).zip(p.iter().zip(ap.iter())) {
            *xi += alpha * pi;
            *ri -= alpha * api;
        }
        // p = z + β p with z = res / diag, β = (res·z) / rz.
        let rz_new: f32 = res.iter().zip(diag.iter()).map(|(r, g)| r * r / g).sum();
        let beta = rz_new / rz;
        for ((pi, ri), g) in p.iter_mut().zip(res.iter()).zip(diag.iter()) {
            *pi = ri / g + beta * *pi;
        }
        rz = rz_new;
    }
    if !x.iter().all(|v| v.is_finite()) {
        return Err(FitError::Singular);
    }
    coeffs.copy_from_slice(x);
    Ok(samples)
}
