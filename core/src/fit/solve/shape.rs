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
//! Its Jacobian is taken by forward differences (the instance is linear in the coefficients, `x +
//! h U_k`) a sample at a time, for all moved components at once: a vertex normal depends on its
//! one-ring only, so a sample's normal under a moved shape is recomputed from the triangles
//! around it ([`crate::fit::solve::ring`]; the same sums as over the whole mesh). Each sample's
//! row goes straight into the normal equations `JᵀJ`, `Jᵀr`: nothing is stored per sample. A
//! damped (Levenberg–Marquardt) step is kept only if the objective on the same samples falls.
//! Visibility: a back-facing test (as in the colour and light solves) and an occlusion test on a
//! coarse depth grid of the instance's vertices (`DepthGrid`).
//!
//! Memory, fixed: on the stack the normal equations (`56²` floats, `70²` past 50 components and
//! the pose), one chunk of sampled vertices with their rings and the landmarks' positions; the
//! depth grid ([`DEPTH_CELLS`] 16-bit cells) in the memory of the instance's compact frame cache
//! when it has one (a device: its stack holds the solve only so), else on the stack. The same
//! code runs on the host and on a device.

use crate::error::FitError;
use crate::fit::likelihood::image::TargetImage;
use crate::fit::likelihood::landmarks::LandmarkTarget;
use crate::fit::solve::ring::{Chunk, Ring, RING_VERTICES};
use crate::geometry::mat_vec;
use crate::geometry::{TriIndex, Vec3};
use crate::model::instance::{Instance, Vertices};
use crate::model::morphable::MorphableModel;
use crate::model::params::FitParams;
use crate::model::MAX_LANDMARKS;
use crate::render::{Camera, Pose, ShLight};

/// Most shape components one solve moves.
pub const MAX_SHAPE_SOLVE: usize = 64;
/// Forward-difference step of the Jacobian (coefficient units: prior standard deviations).
const DIFFERENCE_STEP: f32 = 0.05;
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
/// Cells of the depth grid: the scratch memory a solve needs, 2 bytes each (a device lends its
/// frame cache's, [`Instance::vertices_and_scratch`]; without one the solve keeps its own).
pub const DEPTH_CELLS: usize = DEPTH_GRID * DEPTH_GRID;
/// Depth steps per mm of a grid cell's 16-bit value: 1/16 mm over 4 m around the face's centre.
const DEPTH_STEPS_PER_MM: f32 = 16.0;
/// A cell no vertex falls in.
const EMPTY: u16 = u16::MAX;
/// How far (mm) behind the nearest vertex of its cell a sample may lie and still count as seen:
/// the surface's own depth change across a cell at the samples' slopes stays below it, a nose in
/// front of a cheek does not.
pub const OCCLUSION_TOLERANCE_MM: f32 = 5.0;

/// The nearest vertex depth in each cell of a coarse grid over the image (cells of
/// `side / DEPTH_GRID` pixels, at least one): a z-buffer of vertex splats, in 16-bit steps of
/// 1/16 mm (rounded toward the camera). A point farther than [`OCCLUSION_TOLERANCE_MM`] behind
/// its cell's nearest vertex is hidden by another part of the face (the nose, at 30–45° yaw,
/// hides the far cheek's vertices that still face the camera). The occlusion test of the shape
/// solve, and of every host step that asks which vertices an image shows.
pub struct DepthGrid<'g> {
    cell: f32,
    /// The depth (mm) of step 0: 2 m in front of the pose's centre.
    origin_mm: f32,
    /// [`DEPTH_CELLS`] cells, row by row.
    depth: &'g mut [u16],
    rotation: [[f32; 3]; 3],
    translation: Vec3,
    camera: Camera,
}

impl<'g> DepthGrid<'g> {
    /// The grid of `positions` (model space) seen under `pose` through `camera` in a
    /// `width × height` image, written over `depth` in place; `None` if `depth` holds fewer than
    /// [`DEPTH_CELLS`] cells.
    pub fn new(depth: &'g mut [u16], pose: &Pose, camera: Camera, positions: &[Vec3], width: u32, height: u32) -> Option<Self> {
        let depth = depth.get_mut(..DEPTH_CELLS)?;
        let cell = (width.max(height) as f32 / DEPTH_GRID as f32).max(1.0);
        depth.fill(EMPTY);
        let origin_mm = -pose.translation[2] - f32::from(EMPTY) / DEPTH_STEPS_PER_MM / 2.0;
        let grid = Self { cell, origin_mm, depth, rotation: pose.rotation(), translation: pose.translation, camera };
        for p in positions {
            if let Some((i, j, d)) = grid.locate(*p) {
                let q = grid.steps(d);
                if let Some(c) = grid.depth.get_mut(j * DEPTH_GRID + i) {
                    *c = (*c).min(q);
                }
            }
        }
        Some(grid)
    }

    /// Depth `d` (mm) in whole steps from the origin, rounded down, clamped below [`EMPTY`].
    fn steps(&self, d: f32) -> u16 {
        let q = (d - self.origin_mm) * DEPTH_STEPS_PER_MM;
        let top = f32::from(EMPTY - 1);
        // Saturating casts: a point past either end of the range clamps to it (NaN to 0).
        if q >= top {
            EMPTY - 1
        } else {
            q.max(0.0) as u16
        }
    }

    /// The cell and depth (mm along the view axis) of model-space point `p`.
    fn locate(&self, p: Vec3) -> Option<(usize, usize, f32)> {
        let q = mat_vec(&self.rotation, p);
        let pc = [q[0] + self.translation[0], q[1] + self.translation[1], q[2] + self.translation[2]];
        let s = self.camera.project(pc)?;
        if !(s.x >= 0.0 && s.y >= 0.0) {
            return None;
        }
        // Saturating float-to-integer casts; cells past the grid are refused by the bounds below.
        let (i, j) = ((s.x / self.cell) as usize, (s.y / self.cell) as usize);
        (i < DEPTH_GRID && j < DEPTH_GRID).then_some((i, j, -pc[2]))
    }

    /// Whether model-space point `p` is within the tolerance of its cell's nearest vertex (false
    /// outside the grid).
    pub fn seen(&self, p: Vec3) -> bool {
        self.locate(p)
            .and_then(|(i, j, d)| {
                let near = *self.depth.get(j * DEPTH_GRID + i)?;
                let near_mm = self.origin_mm + f32::from(near) / DEPTH_STEPS_PER_MM;
                Some(near == EMPTY || d <= near_mm + OCCLUSION_TOLERANCE_MM)
            })
            .unwrap_or(false)
    }
}

fn dot3(a: Vec3, b: Vec3) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Moves the leading shape coefficients of `params` (and with [`ShapeSolveConfig::pose`] the
/// pose) toward the mode of the image term times the prior (focal length, light and colour held).
/// `instance` holds `params`' instance on return.
/// Errors on a bad configuration ([`FitError::BadConfig`]) or fewer than 16
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
        let (current, scratch) = instance.vertices_and_scratch();
        let problem = Problem { model, vertices: current, scene: &scene, landmarks, config, w, coeffs, columns };
        // The depth grid in the frame cache's memory where the instance lends it (a device's
        // stack does not hold both), else in a frame of its own.
        let step = match scratch.and_then(|s| s.get_mut(..DEPTH_CELLS)) {
            Some(depth) => problem.iterate::<KS>(depth, &mut damping)?,
            None => problem.iterate_own_grid::<KS>(&mut damping)?,
        };
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
/// Columns of the smaller normal equations (50 components and the pose, as a device fits them).
const SMALL_COLUMNS: usize = 56;

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
    pose_moved_by(pose, i, POSE_STEPS.get(i).copied().unwrap_or(0.0))
}

/// `pose` with parameter `i` (yaw, pitch, roll, translation x, y, z) moved by `step`.
pub(crate) fn pose_moved_by(pose: &Pose, i: usize, step: f32) -> Pose {
    let mut delta = [0.0f32; POSE_PARAMS];
    if let Some(d) = delta.get_mut(i) {
        *d = step;
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

/// The landmark residual `(target − projection) / σ` of landmark `i` at model-space point `p`
/// (zero if it is invalid or does not project).
fn landmark_residual(frame: &Frame<'_, '_>, target: &LandmarkTarget<'_>, i: usize, p: Vec3) -> [f32; 2] {
    let (Some(t), Some(true), Some(s)) = (target.points().get(i), target.valid().get(i), frame.camera.project(frame.to_camera(p))) else {
        return [0.0; 2];
    };
    let sigma = target.sigma() * target.sigma_factor(i);
    [(t[0] - s.x) / sigma, (t[1] - s.y) / sigma]
}

/// The landmark term `Σ |r|²` of shape coefficients `coeffs` seen through `frame`.
fn landmark_term<I: TriIndex>(
    model: &MorphableModel<'_, I>,
    frame: &Frame<'_, '_>,
    target: &LandmarkTarget<'_>,
    coeffs: &[f32],
) -> Result<f32, FitError> {
    let mut lm = [[0.0f32; 3]; MAX_LANDMARKS];
    let n = model.landmark_positions(coeffs, &mut lm)?.min(target.len());
    Ok(lm.iter().take(n).enumerate().map(|(i, p)| landmark_residual(frame, target, i, *p)).map(|r| r[0] * r[0] + r[1] * r[1]).sum())
}

/// The normal equations of an iteration in fixed memory: `w JᵀJ` plus the landmarks' (its strict
/// lower triangle kept transposed above the diagonal, so that the Cholesky factor of a damped
/// copy fills the lower triangle), its diagonal, and the gradient `−w Jᵀ r`.
struct NormalEquations<const N: usize> {
    matrix: [[f32; N]; N],
    diagonal: [f32; N],
    gradient: [f32; N],
    columns: usize,
}

impl<const N: usize> NormalEquations<N> {
    fn new(columns: usize) -> Self {
        Self { matrix: [[0.0; N]; N], diagonal: [0.0; N], gradient: [0.0; N], columns: columns.min(N) }
    }

    /// Adds one residual's row: `jacobian[i]` its derivatives (`dot` their product), `residual` its value.
    fn add<T: Copy>(&mut self, jacobian: &[T], residual: T, dot: impl Fn(T, T) -> f32, w: f32) {
        for i in 0..self.columns {
            let Some(&ji) = jacobian.get(i) else { continue };
            if let Some(gi) = self.gradient.get_mut(i) {
                *gi -= w * dot(ji, residual);
            }
            for (l, &jl) in jacobian.iter().enumerate().take(i) {
                if let Some(e) = self.matrix.get_mut(l).and_then(|r| r.get_mut(i)) {
                    *e += w * dot(ji, jl);
                }
            }
            if let Some(d) = self.diagonal.get_mut(i) {
                *d += w * dot(ji, ji);
            }
        }
    }

    /// The step of the damped equations `(A (1 + damping on the diagonal) + P) δ = g` (`P`: 1 on
    /// the first `shape` columns, the prior's precision, 1e-6 on the pose's).
    fn step(&mut self, shape: usize, damping: f32) -> Result<[f32; MAX_COLUMNS], FitError> {
        for i in 0..self.columns {
            for l in 0..i {
                let v = self.matrix.get(l).and_then(|r| r.get(i)).copied().unwrap_or(0.0);
                if let Some(e) = self.matrix.get_mut(i).and_then(|r| r.get_mut(l)) {
                    *e = v;
                }
            }
            let d = self.diagonal.get(i).copied().unwrap_or(0.0);
            if let Some(e) = self.matrix.get_mut(i).and_then(|r| r.get_mut(i)) {
                *e = d * (1.0 + damping) + if i < shape { 1.0 } else { 1e-6 };
            }
        }
        let x = super::cholesky::solve(&mut self.matrix, &self.gradient, self.columns)?;
        let mut delta = [0.0f32; MAX_COLUMNS];
        for (d, v) in delta.iter_mut().zip(x) {
            *d = v;
        }
        if delta.iter().all(|v| v.is_finite()) {
            Ok(delta)
        } else {
            Err(FitError::Singular)
        }
    }
}

/// What an iteration's samples are taken from: the instance seen through the frame, the depth
/// grid, the stride and the facing threshold.
struct Sampling<'a, 's, 'i> {
    positions: &'a [Vec3],
    normals: &'a [Vec3],
    albedos: &'a [Vec3],
    frame: &'a Frame<'s, 'i>,
    grid: &'a DepthGrid<'a>,
    stride: usize,
    min_cos: f32,
}

impl Sampling<'_, '_, '_> {
    /// The residual of vertex `v` if it is a sample: facing the camera, not hidden, in the image.
    fn residual(&self, v: usize) -> Option<Vec3> {
        let (p, n, a) = (*self.positions.get(v)?, *self.normals.get(v)?, *self.albedos.get(v)?);
        if !self.frame.faces(p, n, self.min_cos) || !self.grid.seen(p) {
            return None;
        }
        self.frame.residual(p, n, a)
    }

    /// Visits the samples in vertex order with their residual and ring, a chunk at a time
    /// (`chunk`: the room); returns their count.
    fn visit<I: TriIndex>(
        &self,
        triangles: &[[I; 3]],
        chunk: &mut Chunk,
        mut visit: impl FnMut(usize, Vec3, &Ring) -> Result<(), FitError>,
    ) -> Result<usize, FitError> {
        let (mut v, mut count) = (0usize, 0usize);
        while v < self.positions.len() {
            chunk.clear();
            while v < self.positions.len() && !chunk.is_full() {
                if let Some(r) = self.residual(v) {
                    chunk.push(v, r);
                }
                v += self.stride;
            }
            chunk.gather(triangles);
            for (s, r, ring) in chunk.samples(triangles) {
                visit(s, r, &ring)?;
                count += 1;
            }
        }
        Ok(count)
    }
}

/// The ring's vertices of the current instance `positions`, each moved by `moved(vertex, position)`.
fn moved_ring(ring: &Ring, positions: &[Vec3], moved: impl Fn(usize, Vec3) -> Vec3, out: &mut [Vec3; RING_VERTICES]) {
    for (q, &u) in out.iter_mut().zip(ring.vertices()) {
        *q = moved(u as usize, positions.get(u as usize).copied().unwrap_or([0.0; 3]));
    }
}

/// What one Gauss–Newton iteration works on: the model, the current instance's vertices, where
/// residuals are taken, the landmarks, the configuration, the data weight, the shape coefficients
/// and the unknowns.
struct Problem<'p, 'm, 's, 'i, I: TriIndex> {
    model: &'p MorphableModel<'m, I>,
    vertices: Vertices<'p>,
    scene: &'p Scene<'s, 'i>,
    landmarks: Option<&'p LandmarkTarget<'p>>,
    config: &'p ShapeSolveConfig,
    w: f32,
    coeffs: &'p [f32],
    columns: Columns,
}

impl<I: TriIndex> Problem<'_, '_, '_, '_, I> {
    /// One iteration with the depth grid in `depth` ([`DEPTH_CELLS`] cells), in the smaller
    /// system where it is enough (a device's stack holds it, the larger one not).
    fn iterate<const KS: usize>(&self, depth: &mut [u16], damping: &mut f32) -> Result<Iteration, FitError> {
        if self.columns.len() <= SMALL_COLUMNS {
            iterate::<I, KS, SMALL_COLUMNS>(self, depth, damping)
        } else {
            iterate::<I, KS, MAX_COLUMNS>(self, depth, damping)
        }
    }

    /// One iteration with a depth grid of its own (in this frame, only when it is called).
    #[inline(never)]
    fn iterate_own_grid<const KS: usize>(&self, damping: &mut f32) -> Result<Iteration, FitError> {
        let mut depth = [EMPTY; DEPTH_CELLS];
        self.iterate::<KS>(&mut depth, damping)
    }
}

/// Samples, the normal equations accumulated a sample at a time, and the tries of one iteration.
#[inline(never)]
fn iterate<I: TriIndex, const KS: usize, const N: usize>(
    problem: &Problem<'_, '_, '_, '_, I>,
    depth: &mut [u16],
    damping: &mut f32,
) -> Result<Iteration, FitError> {
    let Problem { model, vertices, scene, landmarks, config, w, coeffs, columns } = *problem;
    let Vertices { positions, normals, albedos } = vertices;
    let k = columns.shape;
    let m = columns.len();
    let alpha = coeffs.get(..k).ok_or(FitError::BadConfig)?;
    let frame = scene.frame(&scene.pose);
    let nudged: [Frame<'_, '_>; POSE_PARAMS] = core::array::from_fn(|i| scene.frame(&nudged_pose(&scene.pose, i)));
    let grid = DepthGrid::new(depth, &scene.pose, scene.camera, positions, scene.image.width(), scene.image.height())
        .ok_or(FitError::BadConfig)?;
    let sampling = Sampling { positions, normals, albedos, frame: &frame, grid: &grid, stride: config.stride, min_cos: config.min_cos };
    let mut chunk = Chunk::new();
    let mut equations = NormalEquations::<N>::new(m);
    // The samples' rows: a shape column moves the ring (the normal recomputed from it, as over the
    // whole mesh), a pose column the frame.
    let mut data = 0.0f32;
    let samples = sampling.visit(model.triangles(), &mut chunk, |v, base, ring| {
        data += w * dot3(base, base);
        let (p, n, a) = (positions.get(v).copied(), normals.get(v).copied(), albedos.get(v).copied());
        let (Some(p), Some(n), Some(a)) = (p, n, a) else { return Ok(()) };
        let mut row = [[0.0f32; 3]; MAX_COLUMNS];
        let mut moved = [[0.0f32; 3]; RING_VERTICES];
        for (j, d) in row.iter_mut().enumerate().take(m) {
            let (r, h) = if j < k {
                let h = DIFFERENCE_STEP;
                let step = |u: usize, p: Vec3| {
                    let c = model.shape_component(j, u);
                    [p[0] + h * c[0], p[1] + h * c[1], p[2] + h * c[2]]
                };
                moved_ring(ring, positions, step, &mut moved);
                (frame.residual(moved[0], ring.normal(&moved), a), h)
            } else {
                let i = j - k;
                (nudged.get(i).and_then(|f| f.residual(p, n, a)), POSE_STEPS.get(i).copied().unwrap_or(1.0))
            };
            *d = r.map_or([0.0; 3], |r| [(r[0] - base[0]) / h, (r[1] - base[1]) / h, (r[2] - base[2]) / h]);
        }
        equations.add(&row, base, dot3, w);
        Ok(())
    })?;
    if samples < 16 {
        return Err(FitError::Singular);
    }
    // The landmarks' rows: a shape column bumps its coefficient (and takes it back: the next
    // column sees `(c + h) − h`), a pose column the frame.
    let mut full = [0.0f32; KS];
    let full = full.get_mut(..coeffs.len()).ok_or(FitError::BadConfig)?;
    let mut lm_term = 0.0f32;
    if let Some(target) = landmarks {
        let n = model.landmarks().len().min(target.len());
        for i in 0..n {
            full.copy_from_slice(coeffs);
            let base = landmark_residual(&frame, target, i, model.landmark_position(full, i)?);
            lm_term += base[0] * base[0] + base[1] * base[1];
            let mut row = [[0.0f32; 2]; MAX_COLUMNS];
            for (j, d) in row.iter_mut().enumerate().take(k) {
                let c = full.get_mut(j).ok_or(FitError::BadConfig)?;
                *c += DIFFERENCE_STEP;
                let r = landmark_residual(&frame, target, i, model.landmark_position(full, i)?);
                let c = full.get_mut(j).ok_or(FitError::BadConfig)?;
                *c -= DIFFERENCE_STEP;
                *d = [(r[0] - base[0]) / DIFFERENCE_STEP, (r[1] - base[1]) / DIFFERENCE_STEP];
            }
            let p = model.landmark_position(full, i)?;
            for (j, d) in row.iter_mut().enumerate().take(m).skip(k) {
                let (f, h) = (nudged.get(j - k).ok_or(FitError::BadConfig)?, POSE_STEPS.get(j - k).copied().unwrap_or(1.0));
                let r = landmark_residual(f, target, i, p);
                *d = [(r[0] - base[0]) / h, (r[1] - base[1]) / h];
            }
            equations.add(&row, base, |a: [f32; 2], b: [f32; 2]| a[0] * b[0] + a[1] * b[1], 1.0);
        }
    }
    for (gi, a) in equations.gradient.iter_mut().zip(alpha) {
        *gi -= a;
    }
    let prior: f32 = alpha.iter().map(|a| a * a).sum();
    let before = data + prior + lm_term;
    // Tries: a damped step, kept if the objective on these samples falls.
    full.copy_from_slice(coeffs);
    for _ in 0..DAMPING_TRIES {
        let Ok(delta) = equations.step(k, *damping) else {
            *damping *= 10.0;
            continue;
        };
        let after = objective_at(model, &delta, columns, full, scene, landmarks, &sampling, &mut chunk, w)?;
        if after < before {
            *damping = (*damping * 0.3).max(1e-6);
            return Ok(Iteration { samples, before, after, delta: Some(delta) });
        }
        *damping *= 10.0;
    }
    Ok(Iteration { samples, before, after: before, delta: None })
}

/// The objective at the trial step `delta` on the same samples (a sample that leaves the image
/// counts as the residual it had). `full`: the shape coefficients, restored on return.
#[allow(clippy::too_many_arguments)]
fn objective_at<I: TriIndex>(
    model: &MorphableModel<'_, I>,
    delta: &[f32; MAX_COLUMNS],
    columns: Columns,
    full: &mut [f32],
    scene: &Scene<'_, '_>,
    landmarks: Option<&LandmarkTarget<'_>>,
    sampling: &Sampling<'_, '_, '_>,
    chunk: &mut Chunk,
    w: f32,
) -> Result<f32, FitError> {
    let k = columns.shape;
    let pose = if columns.pose > 0 { moved_pose(&scene.pose, delta.get(k..).unwrap_or(&[])) } else { scene.pose };
    let frame = scene.frame(&pose);
    let alpha = full.get(..k).ok_or(FitError::BadConfig)?;
    let mut sum: f32 = alpha.iter().zip(delta.iter()).map(|(a, d)| (a + d) * (a + d)).sum();
    if let Some(target) = landmarks {
        let mut kept = [0.0f32; MAX_SHAPE_SOLVE];
        let kept = kept.get_mut(..k).ok_or(FitError::BadConfig)?;
        kept.copy_from_slice(alpha);
        for (c, (a, d)) in full.iter_mut().zip(kept.iter().zip(delta.iter())) {
            *c = a + d;
        }
        let term = landmark_term(model, &frame, target, full);
        full.get_mut(..k).ok_or(FitError::BadConfig)?.copy_from_slice(kept);
        sum += term?;
    }
    let offset = |u: usize, mut q: Vec3| {
        for (j, d) in delta.iter().enumerate().take(k) {
            let c = model.shape_component(j, u);
            q = [q[0] + d * c[0], q[1] + d * c[1], q[2] + d * c[2]];
        }
        q
    };
    let mut moved = [[0.0f32; 3]; RING_VERTICES];
    let mut finite = true;
    sampling.visit(model.triangles(), chunk, |v, base, ring| {
        moved_ring(ring, sampling.positions, offset, &mut moved);
        finite &= moved.iter().take(ring.vertices().len()).all(|p| p.iter().all(|c| c.is_finite()));
        let Some(&a) = sampling.albedos.get(v) else { return Ok(()) };
        let r = frame.residual(moved[0], ring.normal(&moved), a).unwrap_or(base);
        sum += w * dot3(r, r);
        Ok(())
    })?;
    Ok(if finite { sum } else { f32::INFINITY })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn the_depth_grid_hides_what_lies_behind_a_nearer_vertex_only() {
        let identity = Pose { yaw: 0.0, pitch: 0.0, roll: 0.0, translation: [0.0, 0.0, -500.0] };
        let camera = Camera::centered(64, 64, 500.0);
        // A nose tip 20 mm in front of a cheek point on the same line of sight, a lone point
        // elsewhere, and a point 3 mm behind the nose tip (the surface's own slope).
        let (nose, cheek, lone, slope) = ([0.0, 0.0, 20.0], [0.0, 0.0, 0.0], [30.0, 10.0, 0.0], [0.0, 0.0, 17.0]);
        let mut depth = [0u16; DEPTH_CELLS];
        let grid = DepthGrid::new(&mut depth, &identity, camera, &[nose, cheek, lone, slope], 64, 64).unwrap();
        // Too little memory for the grid: refused, not a panic.
        assert!(DepthGrid::new(&mut [0u16; 16], &identity, camera, &[nose], 64, 64).is_none());
        assert!(grid.seen(nose) && grid.seen(lone) && grid.seen(slope));
        assert!(!grid.seen(cheek), "the cheek lies 20 mm behind the nose in its cell");
        // Outside the image nothing is seen (no panic on any point).
        assert!(!grid.seen([1e6, 0.0, 0.0]) && !grid.seen([f32::NAN, 0.0, 0.0]));
    }
}
