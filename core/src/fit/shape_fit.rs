//! The leading shape coefficients by damped Gauss–Newton on the image, for a fixed pose, light
//! and albedo: a step that moves the identity the way the image asks, where the image chain's
//! random walk accepts a few shape moves in hundreds.
//!
//! For vertices sampled as in [`super::color_fit`] (every `stride`-th one facing the camera), the
//! residual is `r_v = I(π(R x_v + t)) − a_v ⊙ e(R n_v)`: the image (bilinear) where the vertex
//! projects, minus its albedo times the irradiance of its normal. It depends on the shape through
//! the position (where the vertex looks in the image: edges, the nose's side) and through the
//! normal (shading). The objective is the posterior's, `w Σ |r_v|² + |α|²` with `w =
//! weight / σ²`, over the leading `components` coefficients (the others are held).
//! Its Jacobian is taken by forward differences, one component at a time: the instance is linear
//! in the coefficients (`x + h U_k`), the normals are recomputed over the whole mesh. A damped
//! (Levenberg–Marquardt) step is kept only if the objective on the same samples falls.
//! Visibility is a back-facing test only, as in the colour and light solves.
//!
//! Memory: the caller's spare shape buffers and solve scratch ([`Instance::with_solve_scratch`]:
//! `3 (components + 1)` values a sample) and two `MAX_SHAPE_SOLVE²` matrices on the stack; it runs
//! where the caller gives that room (the host), and refuses to run without it.

use super::image::TargetImage;
use super::landmarks::LandmarkTarget;
use super::FitError;
use crate::model::instance::{Instance, SolverView};
use crate::model::morphable::MorphableModel;
use crate::model::morphable::MAX_LANDMARKS;
use crate::model::params::FitParams;
use crate::render::pose::mat_vec;
use crate::render::shading::{vertex_normals, TriIndex};
use crate::{Camera, ShLight, Vec3};

/// Most shape components one solve moves.
pub const MAX_SHAPE_SOLVE: usize = 64;
/// Forward-difference step of the Jacobian (coefficient units: prior standard deviations).
const DIFFERENCE_STEP: f32 = 0.05;
/// Most shape coefficients a parameter vector has (the landmark residuals' coefficient copy).
const KS_MAX: usize = 512;
/// Damping tries per iteration (each multiplies the damping by 10).
const DAMPING_TRIES: usize = 4;

/// How vertices are sampled and weighted, how many components move, how long it runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShapeSolveConfig {
    /// Use every `stride`-th vertex (≥ 1).
    pub stride: usize,
    /// Minimum cosine between the normal and the direction to the camera.
    pub min_cos: f32,
    /// Pixel noise σ of the image likelihood (linear colour).
    pub pixel_sigma: f32,
    /// Pixels one sample stands for: the data term is `weight / σ²` per sample and channel.
    pub weight: f32,
    /// Leading shape components moved (at most [`MAX_SHAPE_SOLVE`]).
    pub components: usize,
    /// Gauss–Newton iterations.
    pub iterations: u32,
}

/// What a solve did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ShapeSolveReport {
    /// Samples of the last iteration.
    pub samples: usize,
    /// Steps kept.
    pub steps: u32,
    /// The objective (data term + the moved components' prior) before the first step.
    pub objective_before: f32,
    /// The objective after the last kept step (on that iteration's samples).
    pub objective_after: f32,
}

/// Pose, camera, light and image of a solve: where residuals are taken.
struct Frame<'s, 'i> {
    rotation: [[f32; 3]; 3],
    translation: Vec3,
    camera: Camera,
    light: ShLight,
    image: &'s TargetImage<'i>,
}

impl Frame<'_, '_> {
    /// The residual of a vertex at position `p` with normal `n` and albedo `a` (model space), if
    /// it projects into the image.
    fn residual(&self, p: Vec3, n: Vec3, a: Vec3) -> Option<Vec3> {
        let q = mat_vec(&self.rotation, p);
        let pc = [q[0] + self.translation[0], q[1] + self.translation[1], q[2] + self.translation[2]];
        let s = self.camera.project(pc)?;
        let target = self.image.sample_bilinear(s.x, s.y)?;
        let e = self.light.irradiance(mat_vec(&self.rotation, n));
        Some([target[0] - a[0] * e[0], target[1] - a[1] * e[1], target[2] - a[2] * e[2]])
    }

    /// Whether a vertex faces the camera by at least `min_cos`.
    fn faces(&self, p: Vec3, n: Vec3, min_cos: f32) -> bool {
        let q = mat_vec(&self.rotation, p);
        let pc = [q[0] + self.translation[0], q[1] + self.translation[1], q[2] + self.translation[2]];
        let nc = mat_vec(&self.rotation, n);
        let dist = libm::sqrtf(pc[0] * pc[0] + pc[1] * pc[1] + pc[2] * pc[2]);
        let cos = -(nc[0] * pc[0] + nc[1] * pc[1] + nc[2] * pc[2]) / dist;
        cos >= min_cos
    }
}

fn dot3(a: Vec3, b: Vec3) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The three values at `at` (zero past the end).
fn triple(values: &[f32], at: usize) -> Vec3 {
    match values.get(at..at + 3) {
        Some(&[a, b, c]) => [a, b, c],
        _ => [0.0; 3],
    }
}

/// Moves the leading shape coefficients of `params` toward the mode of the image term times the
/// prior (pose, focal length, light and colour held). `instance` must carry a spare and a solve
/// scratch; it holds `params`' instance on return. Errors on a bad configuration, missing room
/// ([`FitError::BadConfig`]) or fewer than 16 samples ([`FitError::Singular`]); a failed step
/// leaves `params` as it was.
#[inline(never)]
pub fn solve_shape<I: TriIndex, const KS: usize, const KC: usize>(
    model: &MorphableModel<'_, I>,
    instance: &mut Instance<'_, KS, KC>,
    params: &mut FitParams<KS, KC>,
    image: &TargetImage<'_>,
    landmarks: Option<&LandmarkTarget<'_>>,
    config: &ShapeSolveConfig,
) -> Result<ShapeSolveReport, FitError> {
    let ok = |v: f32| v > 0.0 && v.is_finite();
    if config.stride == 0 || !config.min_cos.is_finite() || !ok(config.pixel_sigma) || !ok(config.weight) {
        return Err(FitError::BadConfig);
    }
    let k = config.components.min(params.shape_coeffs().len()).min(MAX_SHAPE_SOLVE);
    let mut report = ShapeSolveReport::default();
    if k == 0 {
        return Ok(report);
    }
    let w = config.weight / (config.pixel_sigma * config.pixel_sigma);
    let (width, height) = (image.width(), image.height());
    let mut damping = 1e-3f32;
    for iteration in 0..config.iterations {
        instance.update(model, params, width, height)?;
        let frame = Frame {
            rotation: params.pose.rotation(),
            translation: params.pose.translation,
            camera: params.camera(width, height),
            light: params.light,
            image,
        };
        let coeffs = params.shape_coeffs();
        let view = instance.solver_view().ok_or(FitError::BadConfig)?;
        let step = iterate(model, view, &frame, landmarks, config, w, coeffs, k, &mut damping)?;
        report.samples = step.samples;
        if iteration == 0 {
            report.objective_before = step.before;
        }
        report.objective_after = step.after;
        if let Some(delta) = step.delta {
            for (c, d) in params.shape_coeffs_mut().iter_mut().zip(delta.iter().take(k)) {
                *c += d;
            }
            report.steps += 1;
        }
    }
    instance.update(model, params, width, height)?;
    Ok(report)
}

/// One Gauss–Newton iteration's outcome.
struct Iteration {
    samples: usize,
    before: f32,
    after: f32,
    delta: Option<[f32; MAX_SHAPE_SOLVE]>,
}

/// Writes the landmark residuals `(target − projection) / σ` of shape coefficients `coeffs` into
/// `out` (two per landmark, zero for invalid or unprojectable ones); returns their count.
fn landmark_residuals<I: TriIndex>(
    model: &MorphableModel<'_, I>,
    frame: &Frame<'_, '_>,
    target: &LandmarkTarget<'_>,
    coeffs: &[f32],
    out: &mut [[f32; 2]; MAX_LANDMARKS],
) -> Result<usize, FitError> {
    let mut lm = [[0.0f32; 3]; MAX_LANDMARKS];
    let n = model.landmark_positions(coeffs, &mut lm)?.min(target.len());
    for (i, (o, p)) in out.iter_mut().zip(lm.iter()).enumerate().take(n) {
        let q = mat_vec(&frame.rotation, *p);
        let pc = [q[0] + frame.translation[0], q[1] + frame.translation[1], q[2] + frame.translation[2]];
        let (Some(t), Some(true), Some(s)) = (target.points().get(i), target.valid().get(i), frame.camera.project(pc)) else {
            *o = [0.0; 2];
            continue;
        };
        let sigma = target.sigma() * target.sigma_factor(i);
        *o = [(t[0] - s.x) / sigma, (t[1] - s.y) / sigma];
    }
    Ok(n)
}

/// Samples, the Jacobian, the damped normal equations and the tries of one iteration.
#[allow(clippy::too_many_arguments)]
fn iterate<I: TriIndex>(
    model: &MorphableModel<'_, I>,
    view: SolverView<'_>,
    frame: &Frame<'_, '_>,
    landmarks: Option<&LandmarkTarget<'_>>,
    config: &ShapeSolveConfig,
    w: f32,
    coeffs: &[f32],
    k: usize,
    damping: &mut f32,
) -> Result<Iteration, FitError> {
    let SolverView { positions, normals, albedos, spare_positions, spare_normals, samples, values } = view;
    let alpha = coeffs.get(..k).ok_or(FitError::BadConfig)?;
    let row = 3 * (k + 1);
    let cap = samples.len().min(values.len() / row);
    // The landmarks: residuals and their forward differences (the Jacobian's last rows).
    let mut full = [0.0f32; KS_MAX];
    let full = full.get_mut(..coeffs.len()).ok_or(FitError::BadConfig)?;
    full.copy_from_slice(coeffs);
    let mut lm_base = [[0.0f32; 2]; MAX_LANDMARKS];
    let mut lm_jac = [[[0.0f32; 2]; MAX_LANDMARKS]; MAX_SHAPE_SOLVE];
    let mut lm_count = 0;
    if let Some(target) = landmarks {
        lm_count = landmark_residuals(model, frame, target, full, &mut lm_base)?;
        let mut moved = [[0.0f32; 2]; MAX_LANDMARKS];
        for (j, col) in lm_jac.iter_mut().enumerate().take(k) {
            if let Some(c) = full.get_mut(j) {
                *c += DIFFERENCE_STEP;
            }
            landmark_residuals(model, frame, target, full, &mut moved)?;
            if let Some(c) = full.get_mut(j) {
                *c -= DIFFERENCE_STEP;
            }
            for ((d, m), b) in col.iter_mut().zip(moved.iter()).zip(lm_base.iter()).take(lm_count) {
                *d = [(m[0] - b[0]) / DIFFERENCE_STEP, (m[1] - b[1]) / DIFFERENCE_STEP];
            }
        }
    }
    let lm_term = |r: &[[f32; 2]; MAX_LANDMARKS]| -> f32 { r.iter().take(lm_count).map(|r| r[0] * r[0] + r[1] * r[1]).sum() };
    let at = |v: usize| (positions.get(v).copied(), normals.get(v).copied(), albedos.get(v).copied());
    // The samples and their residuals.
    let mut count = 0usize;
    for v in (0..positions.len()).step_by(config.stride) {
        if count >= cap {
            break;
        }
        let (Some(p), Some(n), Some(a)) = at(v) else { continue };
        if !frame.faces(p, n, config.min_cos) {
            continue;
        }
        let Some(r) = frame.residual(p, n, a) else { continue };
        if let (Some(id), Some(slot)) = (samples.get_mut(count), values.get_mut(count * row..count * row + 3)) {
            *id = v as u32;
            slot.copy_from_slice(&r);
            count += 1;
        }
    }
    if count < 16 {
        return Err(FitError::Singular);
    }
    let prior: f32 = alpha.iter().map(|a| a * a).sum();
    let data = |values: &[f32]| -> f32 { (0..count).map(|s| triple(values, s * row)).map(|r| w * dot3(r, r)).sum() };
    let before = data(values) + prior + lm_term(&lm_base);
    // The Jacobian, a component at a time.
    let h = DIFFERENCE_STEP;
    for j in 0..k {
        for (v, (sp, p)) in spare_positions.iter_mut().zip(positions.iter()).enumerate() {
            let u = model.shape_component(j, v);
            *sp = [p[0] + h * u[0], p[1] + h * u[1], p[2] + h * u[2]];
        }
        vertex_normals(spare_positions, model.triangles(), spare_normals)?;
        for s in 0..count {
            let v = samples.get(s).map_or(0, |&v| v as usize);
            let (Some(p), Some(n), Some(a)) = (spare_positions.get(v), spare_normals.get(v), albedos.get(v)) else { continue };
            let base = triple(values, s * row);
            let d = match frame.residual(*p, *n, *a) {
                Some(r) => [(r[0] - base[0]) / h, (r[1] - base[1]) / h, (r[2] - base[2]) / h],
                None => [0.0; 3],
            };
            if let Some(slot) = values.get_mut(s * row + 3 + 3 * j..s * row + 6 + 3 * j) {
                slot.copy_from_slice(&d);
            }
        }
    }
    // Normal equations: (w JᵀJ + I) δ = −w Jᵀ r − α.
    let mut a = [[0.0f32; MAX_SHAPE_SOLVE]; MAX_SHAPE_SOLVE];
    let mut g = [0.0f32; MAX_SHAPE_SOLVE];
    for s in 0..count {
        let base = triple(values, s * row);
        for i in 0..k {
            let ji = triple(values, s * row + 3 + 3 * i);
            if let Some(gi) = g.get_mut(i) {
                *gi -= w * dot3(ji, base);
            }
            let Some(ai) = a.get_mut(i) else { continue };
            for (l, aij) in ai.iter_mut().enumerate().take(i + 1) {
                *aij += w * dot3(ji, triple(values, s * row + 3 + 3 * l));
            }
        }
    }
    for l in 0..lm_count {
        let b = lm_base.get(l).copied().unwrap_or([0.0; 2]);
        for i in 0..k {
            let ji = lm_jac.get(i).and_then(|c| c.get(l)).copied().unwrap_or([0.0; 2]);
            if let Some(gi) = g.get_mut(i) {
                *gi -= ji[0] * b[0] + ji[1] * b[1];
            }
            let Some(ai) = a.get_mut(i) else { continue };
            for (m, aim) in ai.iter_mut().enumerate().take(i + 1) {
                let jm = lm_jac.get(m).and_then(|c| c.get(l)).copied().unwrap_or([0.0; 2]);
                *aim += ji[0] * jm[0] + ji[1] * jm[1];
            }
        }
    }
    for (i, gi) in g.iter_mut().enumerate().take(k) {
        *gi -= alpha.get(i).copied().unwrap_or(0.0);
    }
    // Tries: a damped step, kept if the objective on these samples falls.
    for _ in 0..DAMPING_TRIES {
        let mut m = [[0.0f32; MAX_SHAPE_SOLVE]; MAX_SHAPE_SOLVE];
        for i in 0..k {
            for l in 0..=i {
                let v = a.get(i).and_then(|r| r.get(l)).copied().unwrap_or(0.0);
                let v = if i == l { v * (1.0 + *damping) + 1.0 } else { v };
                if let Some(e) = m.get_mut(i).and_then(|r| r.get_mut(l)) {
                    *e = v;
                }
            }
        }
        let Ok(delta) = cholesky_solve(&mut m, &g, k) else {
            *damping *= 10.0;
            continue;
        };
        // The objective at α + δ on the same samples.
        for (v, (sp, p)) in spare_positions.iter_mut().zip(positions.iter()).enumerate() {
            let mut q = *p;
            for (j, d) in delta.iter().enumerate().take(k) {
                let u = model.shape_component(j, v);
                q = [q[0] + d * u[0], q[1] + d * u[1], q[2] + d * u[2]];
            }
            *sp = q;
        }
        let mut after_prior: f32 = alpha.iter().zip(delta.iter()).map(|(a, d)| (a + d) * (a + d)).sum();
        if let Some(target) = landmarks {
            for (c, (a, d)) in full.iter_mut().zip(alpha.iter().zip(delta.iter())) {
                *c = a + d;
            }
            let mut moved = [[0.0f32; 2]; MAX_LANDMARKS];
            landmark_residuals(model, frame, target, full, &mut moved)?;
            full.get_mut(..k).ok_or(FitError::BadConfig)?.copy_from_slice(alpha);
            after_prior += lm_term(&moved);
        }
        let after = if vertex_normals(spare_positions, model.triangles(), spare_normals).is_ok() {
            let mut sum = after_prior;
            for s in 0..count {
                let v = samples.get(s).map_or(0, |&v| v as usize);
                let (Some(p), Some(n), Some(al)) = (spare_positions.get(v), spare_normals.get(v), albedos.get(v)) else { continue };
                // A sample that leaves the image counts as the residual it had.
                let r = frame.residual(*p, *n, *al).unwrap_or_else(|| triple(values, s * row));
                sum += w * dot3(r, r);
            }
            sum
        } else {
            f32::INFINITY
        };
        if after < before {
            *damping = (*damping * 0.3).max(1e-6);
            return Ok(Iteration { samples: count, before, after, delta: Some(delta) });
        }
        *damping *= 10.0;
    }
    Ok(Iteration { samples: count, before, after: before, delta: None })
}

/// Solves `M x = b` for the leading `n × n` block of a symmetric positive-definite `M` (lower
/// triangle given; overwritten by its Cholesky factor).
fn cholesky_solve(
    m: &mut [[f32; MAX_SHAPE_SOLVE]; MAX_SHAPE_SOLVE],
    b: &[f32; MAX_SHAPE_SOLVE],
    n: usize,
) -> Result<[f32; MAX_SHAPE_SOLVE], FitError> {
    let at = |m: &[[f32; MAX_SHAPE_SOLVE]; MAX_SHAPE_SOLVE], i: usize, j: usize| m.get(i).and_then(|r| r.get(j)).copied().unwrap_or(0.0);
    for j in 0..n {
        let mut d = at(m, j, j);
        for l in 0..j {
            d -= at(m, j, l) * at(m, j, l);
        }
        if !(d > 0.0 && d.is_finite()) {
            return Err(FitError::Singular);
        }
        let d = libm::sqrtf(d);
        if let Some(e) = m.get_mut(j).and_then(|r| r.get_mut(j)) {
            *e = d;
        }
        for i in j + 1..n {
            let mut s = at(m, i, j);
            for l in 0..j {
                s -= at(m, i, l) * at(m, j, l);
            }
            if let Some(e) = m.get_mut(i).and_then(|r| r.get_mut(j)) {
                *e = s / d;
            }
        }
    }
    let mut y = [0.0f32; MAX_SHAPE_SOLVE];
    for i in 0..n {
        let mut s = b.get(i).copied().unwrap_or(0.0);
        for l in 0..i {
            s -= at(m, i, l) * y.get(l).copied().unwrap_or(0.0);
        }
        if let Some(e) = y.get_mut(i) {
            *e = s / at(m, i, i);
        }
    }
    let mut x = [0.0f32; MAX_SHAPE_SOLVE];
    for i in (0..n).rev() {
        let mut s = y.get(i).copied().unwrap_or(0.0);
        for l in i + 1..n {
            s -= at(m, l, i) * x.get(l).copied().unwrap_or(0.0);
        }
        if let Some(e) = x.get_mut(i) {
            *e = s / at(m, i, i);
        }
    }
    if x.iter().all(|v| v.is_finite()) {
        Ok(x)
    } else {
        Err(FitError::Singular)
    }
}
