//! Colour coefficients by regularized least squares, for fixed geometry and light.
//!
//! For a sampled vertex facing the camera, the rendered colour is `e_c · (m_c + Σ_k a_k B_k,c)`
//! (irradiance `e` of its rotated normal under the light, mean albedo `m`, colour basis `B`): linear
//! in the coefficients `a`. Against the target colours `I` at the projected vertices, the
//! posterior mode under the prior `a ~ N(0, I)` with pixel noise σ minimizes
//! `w Σ (e (m + B a) − I)² + |a|²`, `w` = [`ColorSolveConfig::weight`] / σ² per sample. The
//! normal equations `(w AᵀA + I) a = w Aᵀ (I − e m)` are solved by conjugate gradients without
//! forming the matrix (each iteration is one pass over the samples), so memory is a few
//! coefficient vectors and one row of the basis: nothing scales with the model.
//! Visibility is a back-facing test only, as in [`super::light_fit`].

use super::image::TargetImage;
use super::FitError;
use crate::model::basis::ModelError;
use crate::model::morphable::MorphableModel;
use crate::render::pose::mat_vec;
use crate::render::shading::TriIndex;
use crate::{Camera, Pose, ShLight, Vec3};

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
    let r = scene.pose.rotation();
    let t = scene.pose.translation;
    let mut m = 0;
    for (v, (p, n)) in scene.positions.iter().zip(scene.normals).enumerate().step_by(config.stride.max(1)) {
        let nc = mat_vec(&r, *n);
        let q = mat_vec(&r, *p);
        let pc = [q[0] + t[0], q[1] + t[1], q[2] + t[2]];
        let dist = libm::sqrtf(pc[0] * pc[0] + pc[1] * pc[1] + pc[2] * pc[2]);
        let cos = -(nc[0] * pc[0] + nc[1] * pc[1] + nc[2] * pc[2]) / dist;
        if cos.is_nan() || cos < config.min_cos {
            continue;
        }
        let Some(s) = scene.camera.project(pc) else { continue };
        let Some(target) = scene.image.sample(s.x, s.y) else { continue };
        f(v, scene.light.irradiance(nc), target);
        m += 1;
    }
    m
}

/// The rendered colour change `e ⊙ Σ_k x_k B_k` at `vertex` (first `x.len()` components).
fn basis_times<I: TriIndex>(model: &MorphableModel<'_, I>, vertex: usize, e: Vec3, x: &[f32]) -> Vec3 {
    let mut s = [0.0f32; 3];
    for (k, xk) in x.iter().enumerate() {
        let b = model.color_component(k, vertex);
        s[0] += xk * b[0];
        s[1] += xk * b[1];
        s[2] += xk * b[2];
    }
    [e[0] * s[0], e[1] * s[1], e[2] * s[2]]
}

/// Adds `scale · Σ_c e_c B_k,c d_c` to `out[k]` for every component `k < out.len()`.
fn add_transposed<I: TriIndex>(model: &MorphableModel<'_, I>, vertex: usize, e: Vec3, d: Vec3, scale: f32, out: &mut [f32]) {
    let ed = [scale * e[0] * d[0], scale * e[1] * d[1], scale * e[2] * d[2]];
    for (k, o) in out.iter_mut().enumerate() {
        let b = model.color_component(k, vertex);
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
    let (Some(x), Some(res), Some(p), Some(ap)) = (x.get_mut(..k), res.get_mut(..k), p.get_mut(..k), ap.get_mut(..k)) else {
        return Err(FitError::Model(ModelError::TooManyCoefficients));
    };
    x.copy_from_slice(coeffs);
    // res = w Aᵀ (I − e m − A x) − x: the negative gradient at the start.
    let samples = visit_samples(scene, config, |v, e, target| {
        let m = mean.get(v).copied().unwrap_or([0.0; 3]);
        let ax = basis_times(model, v, e, x);
        let d = [target[0] - e[0] * m[0] - ax[0], target[1] - e[1] * m[1] - ax[1], target[2] - e[2] * m[2] - ax[2]];
        add_transposed(model, v, e, d, w, res);
    });
    if samples < 16 {
        return Err(FitError::Singular);
    }
    for (r, xi) in res.iter_mut().zip(x.iter()) {
        *r -= xi;
    }
    p.copy_from_slice(res);
    let mut rr = dot(res, res);
    let tolerance = rr * 1e-10;
    for _ in 0..config.iterations {
        if rr.is_nan() || rr <= tolerance {
            break;
        }
        // ap = (w AᵀA + I) p
        ap.copy_from_slice(p);
        visit_samples(scene, config, |v, e, _| {
            let a = basis_times(model, v, e, p);
            add_transposed(model, v, e, a, w, ap);
        });
        let pap = dot(p, ap);
        if pap.is_nan() || pap <= 0.0 {
            break;
        }
        let alpha = rr / pap;
        for ((xi, ri), (pi, api)) in x.iter_mut().zip(res.iter_mut()).zip(p.iter().zip(ap.iter())) {
            *xi += alpha * pi;
            *ri -= alpha * api;
        }
        let rr_new = dot(res, res);
        let beta = rr_new / rr;
        for (pi, ri) in p.iter_mut().zip(res.iter()) {
            *pi = ri + beta * *pi;
        }
        rr = rr_new;
    }
    if !x.iter().all(|v| v.is_finite()) {
        return Err(FitError::Singular);
    }
    coeffs.copy_from_slice(x);
    Ok(samples)
}
