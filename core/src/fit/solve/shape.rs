//! The leading shape coefficients by damped Gauss–Newton on the image, for a fixed pose, light
//! and albedo: a step that moves the identity the way the image asks, where the image chain's
//! random walk accepts a few shape moves in hundreds.
//!
//! For vertices sampled as in [`crate::fit::solve::color`] (every `stride`-th one facing the camera), the
//! residual is `r_v = I(π(R x_v + t)) − a_v ⊙ e(R n_v)`: the image (bilinear) where the vertex
//! projects, minus its albedo times the irradiance of its normal. It depends on the shape through
//! the position (where the vertex looks in the image: edges, the nose's side) and through the
//! normal (shading). The objective is the posterior's, `w Σ |r_v|² + |α|²` with `w =
//! weight / σ²`, over the leading `components` coefficients (the others are held).
//! Its Jacobian is taken by forward differences, one component at a time: the instance is linear
//! in the coefficients (`x + h U_k`), the normals are recomputed over the whole mesh. A damped
//! (Levenberg–Marquardt) step is kept only if the objective on the same samples falls.
//! Visibility: a back-facing test (as in the colour and light solves) and an occlusion test on a
//! coarse depth grid of the instance's vertices (`DepthGrid`).
//!
//! Memory: the caller's spare shape buffers and solve scratch ([`Instance::with_solve_scratch`]:
//! `3 (components + 1)` values a sample) and two `MAX_SHAPE_SOLVE²` matrices on the stack; it runs
//! where the caller gives that room (the host), and refuses to run without it.

use crate::error::FitError;
use crate::fit::likelihood::image::TargetImage;
use crate::fit::likelihood::landmarks::LandmarkTarget;
use crate::geometry::mat_vec;
use crate::geometry::{TriIndex, Vec3};
use crate::model::instance::{Instance, SolverView};
use crate::model::morphable::MorphableModel;
use crate::model::morphable::MAX_LANDMARKS;
use crate::model::params::FitParams;
use crate::render::shading::vertex_normals;
use crate::render::{Camera, Pose, ShLight};

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
    /// Whether the pose (yaw, pitch, roll, translation) moves with the shape.
    pub pose: bool,
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
    /// Model-space point `p` in camera space.
    fn to_camera(&self, p: Vec3) -> Vec3 {
        let q = mat_vec(&self.rotation, p);
        [q[0] + self.translation[0], q[1] + self.translation[1], q[2] + self.translation[2]]
    }

    /// The residual of a vertex at position `p` with normal `n` and albedo `a` (model space), if
    /// it projects into the image.
    fn residual(&self, p: Vec3, n: Vec3, a: Vec3) -> Option<Vec3> {
        let s = self.camera.project(self.to_camera(p))?;
        let target = self.image.sample_bilinear(s.x, s.y)?;
        let e = self.light.irradiance(mat_vec(&self.rotation, n));
        Some([target[0] - a[0] * e[0], target[1] - a[1] * e[1], target[2] - a[2] * e[2]])
    }

    /// Whether a vertex faces the camera by at least `min_cos`.
    fn faces(&self, p: Vec3, n: Vec3, min_cos: f32) -> bool {
        crate::fit::solve::light::facing(&self.rotation, self.translation, p, n).cos >= min_cos
    }
}

/// Cells per side of the solve's depth grid (its occlusion test).
const DEPTH_GRID: usize = 64;
/// How far (mm) behind the nearest vertex of its cell a sample may lie and still count as seen:
/// the surface's own depth change across a cell at the samples' slopes stays below it, a nose in
/// front of a cheek does not.
const OCCLUSION_TOLERANCE_MM: f32 = 5.0;

/// The nearest vertex depth in each cell of a coarse grid over the image (cells of
/// `side / DEPTH_GRID` pixels, at least one): a z-buffer of vertex splats. A sample farther than
/// [`OCCLUSION_TOLERANCE_MM`] behind its cell's nearest vertex is hidden by another part of the
/// face (the nose, at 30–45° yaw, hides the far cheek's vertices that still face the camera).
struct DepthGrid {
    cell: f32,
    depth: [[f32; DEPTH_GRID]; DEPTH_GRID],
}

impl DepthGrid {
    /// The grid of `positions` (model space) seen through `frame` in a `width × height` image.
    fn new(frame: &Frame<'_, '_>, positions: &[Vec3], width: u32, height: u32) -> Self {
        let cell = (width.max(height) as f32 / DEPTH_GRID as f32).max(1.0);
        let mut grid = Self { cell, depth: [[f32::INFINITY; DEPTH_GRID]; DEPTH_GRID] };
        for p in positions {
            if let Some((i, j, d)) = grid.locate(frame, *p) {
                if let Some(c) = grid.depth.get_mut(j).and_then(|r| r.get_mut(i)) {
                    *c = c.min(d);
                }
            }
        }
        grid
    }

    /// The cell and depth (mm along the view axis) of model-space point `p`.
    fn locate(&self, frame: &Frame<'_, '_>, p: Vec3) -> Option<(usize, usize, f32)> {
        let pc = frame.to_camera(p);
        let s = frame.camera.project(pc)?;
        if !(s.x >= 0.0 && s.y >= 0.0) {
            return None;
        }
        // Saturating float-to-integer casts; cells past the grid are refused by the bounds below.
        let (i, j) = ((s.x / self.cell) as usize, (s.y / self.cell) as usize);
        (i < DEPTH_GRID && j < DEPTH_GRID).then_some((i, j, -pc[2]))
    }

    /// Whether `p` is within the tolerance of its cell's nearest vertex.
    fn seen(&self, frame: &Frame<'_, '_>, p: Vec3) -> bool {
        self.locate(frame, p)
            .and_then(|(i, j, d)| self.depth.get(j).and_then(|r| r.get(i)).map(|near| d <= near + OCCLUSION_TOLERANCE_MM))
            .unwrap_or(false)
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

/// Moves the leading shape coefficients of `params` (and with [`ShapeSolveConfig::pose`] the
/// pose) toward the mode of the image term times the prior (focal length, light and colour held).
/// `instance` must carry a spare and a solve scratch; it holds `params`' instance on return.
/// Errors on a bad configuration, missing room ([`FitError::BadConfig`]) or fewer than 16
/// samples ([`FitError::Singular`]); a failed step leaves `params` as it was.
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
    if k == 0 && !config.pose {
        return Ok(report);
    }
    let columns = Columns { shape: k, pose: if config.pose { POSE_PARAMS } else { 0 } };
    let w = config.weight / (config.pixel_sigma * config.pixel_sigma);
    let (width, height) = (image.width(), image.height());
    let mut damping = 1e-3f32;
    for iteration in 0..config.iterations {
        instance.update(model, params, width, height)?;
        let scene = Scene { pose: params.pose, camera: params.camera(width, height), light: params.light, image };
        let coeffs = params.shape_coeffs();
        let view = instance.solver_view().ok_or(FitError::BadConfig)?;
        let step = iterate(model, view, &scene, landmarks, config, w, coeffs, columns, &mut damping)?;
        report.samples = step.samples;
        if iteration == 0 {
            report.objective_before = step.before;
        }
        report.objective_after = step.after;
        if let Some(delta) = step.delta {
            for (c, d) in params.shape_coeffs_mut().iter_mut().zip(delta.iter().take(k)) {
                *c += d;
            }
            if columns.pose > 0 {
                params.pose = moved_pose(&params.pose, delta.get(k..).unwrap_or(&[]));
            }
            report.steps += 1;
        }
    }
    instance.update(model, params, width, height)?;
    Ok(report)
}

/// Pose parameters a solve can move: yaw, pitch, roll, translation x, y, z.
const POSE_PARAMS: usize = 6;
/// Forward-difference steps of the pose parameters (radians, mm).
const POSE_STEPS: [f32; POSE_PARAMS] = [0.002, 0.002, 0.002, 0.2, 0.2, 1.0];
/// Columns of the Jacobian at most: shape components and pose parameters.
const MAX_COLUMNS: usize = MAX_SHAPE_SOLVE + POSE_PARAMS;

/// The unknowns of a solve: the leading `shape` components, then `pose` pose parameters.
#[derive(Clone, Copy)]
struct Columns {
    shape: usize,
    pose: usize,
}

impl Columns {
    fn len(&self) -> usize {
        self.shape + self.pose
    }
}

/// `pose` moved by `delta` (yaw, pitch, roll, translation; missing entries are zero).
fn moved_pose(pose: &Pose, delta: &[f32]) -> Pose {
    let d = |i: usize| delta.get(i).copied().unwrap_or(0.0);
    let t = pose.translation;
    Pose { yaw: pose.yaw + d(0), pitch: pose.pitch + d(1), roll: pose.roll + d(2), translation: [t[0] + d(3), t[1] + d(4), t[2] + d(5)] }
}

/// The pose with parameter `i` moved by its difference step.
fn nudged_pose(pose: &Pose, i: usize) -> Pose {
    let mut delta = [0.0f32; POSE_PARAMS];
    if let (Some(d), Some(s)) = (delta.get_mut(i), POSE_STEPS.get(i)) {
        *d = *s;
    }
    moved_pose(pose, &delta)
}

/// Pose, camera, light and image: what a [`Frame`] is made from.
#[derive(Clone, Copy)]
struct Scene<'s, 'i> {
    pose: Pose,
    camera: Camera,
    light: ShLight,
    image: &'s TargetImage<'i>,
}

impl<'s, 'i> Scene<'s, 'i> {
    fn frame(&self, pose: &Pose) -> Frame<'s, 'i> {
        Frame { rotation: pose.rotation(), translation: pose.translation, camera: self.camera, light: self.light, image: self.image }
    }
}

/// One Gauss–Newton iteration's outcome.
struct Iteration {
    samples: usize,
    before: f32,
    after: f32,
    delta: Option<[f32; MAX_COLUMNS]>,
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
        let (Some(t), Some(true), Some(s)) = (target.points().get(i), target.valid().get(i), frame.camera.project(frame.to_camera(*p)))
        else {
            *o = [0.0; 2];
            continue;
        };
        let sigma = target.sigma() * target.sigma_factor(i);
        *o = [(t[0] - s.x) / sigma, (t[1] - s.y) / sigma];
    }
    Ok(n)
}

/// The landmark residuals and their forward differences per column.
struct LandmarkRows {
    count: usize,
    base: [[f32; 2]; MAX_LANDMARKS],
    jacobian: [[[f32; 2]; MAX_LANDMARKS]; MAX_COLUMNS],
}

impl LandmarkRows {
    #[allow(clippy::too_many_arguments)]
    fn new<I: TriIndex>(
        model: &MorphableModel<'_, I>,
        scene: &Scene<'_, '_>,
        target: Option<&LandmarkTarget<'_>>,
        full: &mut [f32],
        columns: Columns,
    ) -> Result<Self, FitError> {
        let mut rows = Self { count: 0, base: [[0.0; 2]; MAX_LANDMARKS], jacobian: [[[0.0; 2]; MAX_LANDMARKS]; MAX_COLUMNS] };
        let Some(target) = target else { return Ok(rows) };
        let frame = scene.frame(&scene.pose);
        rows.count = landmark_residuals(model, &frame, target, full, &mut rows.base)?;
        let mut moved = [[0.0f32; 2]; MAX_LANDMARKS];
        for j in 0..columns.len() {
            let step = if j < columns.shape {
                if let Some(c) = full.get_mut(j) {
                    *c += DIFFERENCE_STEP;
                }
                landmark_residuals(model, &frame, target, full, &mut moved)?;
                if let Some(c) = full.get_mut(j) {
                    *c -= DIFFERENCE_STEP;
                }
                DIFFERENCE_STEP
            } else {
                let i = j - columns.shape;
                landmark_residuals(model, &scene.frame(&nudged_pose(&scene.pose, i)), target, full, &mut moved)?;
                POSE_STEPS.get(i).copied().unwrap_or(1.0)
            };
            let Some(col) = rows.jacobian.get_mut(j) else { continue };
            for ((d, m), b) in col.iter_mut().zip(moved.iter()).zip(rows.base.iter()).take(rows.count) {
                *d = [(m[0] - b[0]) / step, (m[1] - b[1]) / step];
            }
        }
        Ok(rows)
    }

    fn term(&self, r: &[[f32; 2]; MAX_LANDMARKS]) -> f32 {
        r.iter().take(self.count).map(|r| r[0] * r[0] + r[1] * r[1]).sum()
    }

    fn column(&self, j: usize, l: usize) -> [f32; 2] {
        self.jacobian.get(j).and_then(|c| c.get(l)).copied().unwrap_or([0.0; 2])
    }
}

/// Samples, the Jacobian, the damped normal equations and the tries of one iteration.
#[allow(clippy::too_many_arguments)]
fn iterate<I: TriIndex>(
    model: &MorphableModel<'_, I>,
    view: SolverView<'_>,
    scene: &Scene<'_, '_>,
    landmarks: Option<&LandmarkTarget<'_>>,
    config: &ShapeSolveConfig,
    w: f32,
    coeffs: &[f32],
    columns: Columns,
    damping: &mut f32,
) -> Result<Iteration, FitError> {
    let SolverView { positions, normals, albedos, spare_positions, spare_normals, samples, values } = view;
    let k = columns.shape;
    let m = columns.len();
    let alpha = coeffs.get(..k).ok_or(FitError::BadConfig)?;
    let row = 3 * (m + 1);
    let cap = samples.len().min(values.len() / row);
    let frame = scene.frame(&scene.pose);
    let mut full = [0.0f32; KS_MAX];
    let full = full.get_mut(..coeffs.len()).ok_or(FitError::BadConfig)?;
    full.copy_from_slice(coeffs);
    let lm = LandmarkRows::new(model, scene, landmarks, full, columns)?;
    let at = |v: usize| (positions.get(v).copied(), normals.get(v).copied(), albedos.get(v).copied());
    // The samples and their residuals: vertices facing the camera and not hidden by the face.
    let grid = DepthGrid::new(&frame, positions, scene.image.width(), scene.image.height());
    let mut count = 0usize;
    for v in (0..positions.len()).step_by(config.stride) {
        if count >= cap {
            break;
        }
        let (Some(p), Some(n), Some(a)) = at(v) else { continue };
        if !frame.faces(p, n, config.min_cos) || !grid.seen(&frame, p) {
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
    let before = data(values) + prior + lm.term(&lm.base);
    // The Jacobian, a column at a time: shape components (normals recomputed), then the pose.
    for j in 0..m {
        let (moved_frame, h) = if j < k {
            for (v, (sp, p)) in spare_positions.iter_mut().zip(positions.iter()).enumerate() {
                let u = model.shape_component(j, v);
                *sp = [p[0] + DIFFERENCE_STEP * u[0], p[1] + DIFFERENCE_STEP * u[1], p[2] + DIFFERENCE_STEP * u[2]];
            }
            vertex_normals(spare_positions, model.triangles(), spare_normals)?;
            (None, DIFFERENCE_STEP)
        } else {
            let i = j - k;
            (Some(scene.frame(&nudged_pose(&scene.pose, i))), POSE_STEPS.get(i).copied().unwrap_or(1.0))
        };
        for s in 0..count {
            let v = samples.get(s).map_or(0, |&v| v as usize);
            let r = match &moved_frame {
                None => match (spare_positions.get(v), spare_normals.get(v), albedos.get(v)) {
                    (Some(p), Some(n), Some(a)) => frame.residual(*p, *n, *a),
                    _ => None,
                },
                Some(f) => match at(v) {
                    (Some(p), Some(n), Some(a)) => f.residual(p, n, a),
                    _ => None,
                },
            };
            let base = triple(values, s * row);
            let d = r.map_or([0.0; 3], |r| [(r[0] - base[0]) / h, (r[1] - base[1]) / h, (r[2] - base[2]) / h]);
            if let Some(slot) = values.get_mut(s * row + 3 + 3 * j..s * row + 6 + 3 * j) {
                slot.copy_from_slice(&d);
            }
        }
    }
    // Normal equations: (w JᵀJ + P) δ = −w Jᵀ r − P x (P: the prior's precision, 1 on the
    // shape components, 0 on the pose, whose prior is broad).
    let mut a = [[0.0f32; MAX_COLUMNS]; MAX_COLUMNS];
    let mut g = [0.0f32; MAX_COLUMNS];
    for s in 0..count {
        let base = triple(values, s * row);
        for i in 0..m {
            let ji = triple(values, s * row + 3 + 3 * i);
            if let Some(gi) = g.get_mut(i) {
                *gi -= w * dot3(ji, base);
            }
            let Some(ai) = a.get_mut(i) else { continue };
            for (l, ail) in ai.iter_mut().enumerate().take(i + 1) {
                *ail += w * dot3(ji, triple(values, s * row + 3 + 3 * l));
            }
        }
    }
    for l in 0..lm.count {
        let b = lm.base.get(l).copied().unwrap_or([0.0; 2]);
        for i in 0..m {
            let ji = lm.column(i, l);
            if let Some(gi) = g.get_mut(i) {
                *gi -= ji[0] * b[0] + ji[1] * b[1];
            }
            let Some(ai) = a.get_mut(i) else { continue };
            for (q, aiq) in ai.iter_mut().enumerate().take(i + 1) {
                let jq = lm.column(q, l);
                *aiq += ji[0] * jq[0] + ji[1] * jq[1];
            }
        }
    }
    for (i, gi) in g.iter_mut().enumerate().take(k) {
        *gi -= alpha.get(i).copied().unwrap_or(0.0);
    }
    // Tries: a damped step, kept if the objective on these samples falls.
    for _ in 0..DAMPING_TRIES {
        let mut mm = [[0.0f32; MAX_COLUMNS]; MAX_COLUMNS];
        for i in 0..m {
            for l in 0..=i {
                let v = a.get(i).and_then(|r| r.get(l)).copied().unwrap_or(0.0);
                let v = if i == l { v * (1.0 + *damping) + if i < k { 1.0 } else { 1e-6 } } else { v };
                if let Some(e) = mm.get_mut(i).and_then(|r| r.get_mut(l)) {
                    *e = v;
                }
            }
        }
        let Ok(delta) = cholesky_solve(&mut mm, &g, m) else {
            *damping *= 10.0;
            continue;
        };
        let after = objective_at(
            model,
            &delta,
            columns,
            alpha,
            full,
            scene,
            landmarks,
            &lm,
            positions,
            albedos,
            spare_positions,
            spare_normals,
            samples,
            values,
            count,
            row,
            w,
        )?;
        if after < before {
            *damping = (*damping * 0.3).max(1e-6);
            return Ok(Iteration { samples: count, before, after, delta: Some(delta) });
        }
        *damping *= 10.0;
    }
    Ok(Iteration { samples: count, before, after: before, delta: None })
}

/// The objective at the trial step `delta` on the same samples (a sample that leaves the image
/// counts as the residual it had).
#[allow(clippy::too_many_arguments)]
fn objective_at<I: TriIndex>(
    model: &MorphableModel<'_, I>,
    delta: &[f32; MAX_COLUMNS],
    columns: Columns,
    alpha: &[f32],
    full: &mut [f32],
    scene: &Scene<'_, '_>,
    landmarks: Option<&LandmarkTarget<'_>>,
    lm: &LandmarkRows,
    positions: &[Vec3],
    albedos: &[Vec3],
    spare_positions: &mut [Vec3],
    spare_normals: &mut [Vec3],
    samples: &[u32],
    values: &[f32],
    count: usize,
    row: usize,
    w: f32,
) -> Result<f32, FitError> {
    let k = columns.shape;
    let pose = if columns.pose > 0 { moved_pose(&scene.pose, delta.get(k..).unwrap_or(&[])) } else { scene.pose };
    let frame = scene.frame(&pose);
    for (v, (sp, p)) in spare_positions.iter_mut().zip(positions.iter()).enumerate() {
        let mut q = *p;
        for (j, d) in delta.iter().enumerate().take(k) {
            let u = model.shape_component(j, v);
            q = [q[0] + d * u[0], q[1] + d * u[1], q[2] + d * u[2]];
        }
        *sp = q;
    }
    let mut sum: f32 = alpha.iter().zip(delta.iter()).map(|(a, d)| (a + d) * (a + d)).sum();
    if let Some(target) = landmarks {
        for (c, (a, d)) in full.iter_mut().zip(alpha.iter().zip(delta.iter())) {
            *c = a + d;
        }
        let mut moved = [[0.0f32; 2]; MAX_LANDMARKS];
        landmark_residuals(model, &frame, target, full, &mut moved)?;
        full.get_mut(..k).ok_or(FitError::BadConfig)?.copy_from_slice(alpha);
        sum += lm.term(&moved);
    }
    if vertex_normals(spare_positions, model.triangles(), spare_normals).is_err() {
        return Ok(f32::INFINITY);
    }
    for s in 0..count {
        let v = samples.get(s).map_or(0, |&v| v as usize);
        let (Some(p), Some(n), Some(al)) = (spare_positions.get(v), spare_normals.get(v), albedos.get(v)) else { continue };
        let r = frame.residual(*p, *n, *al).unwrap_or_else(|| triple(values, s * row));
        sum += w * dot3(r, r);
    }
    Ok(sum)
}

/// Solves `M x = b` for the leading `n × n` block of a symmetric positive-definite `M` (lower
/// triangle given; overwritten by its Cholesky factor); a non-finite solution is refused.
fn cholesky_solve(m: &mut [[f32; MAX_COLUMNS]; MAX_COLUMNS], b: &[f32; MAX_COLUMNS], n: usize) -> Result<[f32; MAX_COLUMNS], FitError> {
    let x = super::cholesky::solve(m, b, n)?;
    if x.iter().all(|v| v.is_finite()) {
        Ok(x)
    } else {
        Err(FitError::Singular)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn the_depth_grid_hides_what_lies_behind_a_nearer_vertex_only() {
        let pixels = [[0u8; 3]; 64 * 64];
        let image = TargetImage::new(&pixels, 64, 64).unwrap();
        let identity = Pose { yaw: 0.0, pitch: 0.0, roll: 0.0, translation: [0.0, 0.0, -500.0] };
        let scene = Scene { pose: identity, camera: Camera::centered(64, 64, 500.0), light: ShLight::zero(), image: &image };
        let frame = scene.frame(&scene.pose);
        // A nose tip 20 mm in front of a cheek point on the same line of sight, a lone point
        // elsewhere, and a point 3 mm behind the nose tip (the surface's own slope).
        let (nose, cheek, lone, slope) = ([0.0, 0.0, 20.0], [0.0, 0.0, 0.0], [30.0, 10.0, 0.0], [0.0, 0.0, 17.0]);
        let grid = DepthGrid::new(&frame, &[nose, cheek, lone, slope], 64, 64);
        assert!(grid.seen(&frame, nose) && grid.seen(&frame, lone) && grid.seen(&frame, slope));
        assert!(!grid.seen(&frame, cheek), "the cheek lies 20 mm behind the nose in its cell");
        // Outside the image nothing is seen (no panic on any point).
        assert!(!grid.seen(&frame, [1e6, 0.0, 0.0]) && !grid.seen(&frame, [f32::NAN, 0.0, 0.0]));
    }
}
