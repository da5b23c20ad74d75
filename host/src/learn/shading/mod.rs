//! Shape from shading: per-vertex shape and albedo beyond a fitted model instance, the detail the
//! model's subspaces cannot express (the paper's third step of the learning loop).
//!
//! Given a fit (pose, camera, light, shape and colour coefficients) and the image it saw, the
//! unknowns are a height `h_v` per vertex along the instance's normal `n_v` (mm, model space: the
//! offset `D_v = h_v n_v`; a move along the surface changes the shape only to second order) and
//! an albedo offset `c_v` per vertex (linear RGB). Gradient descent (Adam, analytic gradients)
//! minimizes
//!
//! `Σ_seen |I(π(x_v + D_v)) − (a_v + c_v) ⊙ E(R n_v(x + D))|² / σ²  +  P_shape(D) + P_albedo(c)  +  μ |L h|²`
//!
//! - the image term over the vertices the image speaks about ([`visibility`]: facing the camera,
//!   not hidden, projecting into the photo, and not far from the fit's colour: see
//!   [`ShadingSettings::max_residual`]), `I(π(·))` the image's colour where the moved vertex projects (bilinear, its slope from half a pixel either side: a height of a few
//!   mm moves a projection by a pixel or two at the fit's working size, which matters next to the
//!   nose), `E` the fit's SH irradiance of the moved normal (recomputed from the
//!   one-ring, as the core computes normals), `σ` the fit's pixel noise;
//! - the paper's penalty of each part ([`subspace`]): the offsets' distance from the model's
//!   subspace (the fit's components) over a per-vertex σ, plus the prior on their projection into it;
//! - a mesh Laplacian of the heights, keeping neighbours together: each normal depends on a ring
//!   of heights, so the image alone leaves zig-zag patterns free.
//!
//! Only the vertices the image speaks about move: the others keep the model's instance (left
//! free, they would follow the in-span part of the seen vertices' offsets, the model's own
//! extrapolation, and the Laplacian's reach). The result is deterministic (one thread, fixed order).

pub mod subspace;
pub mod surface;
pub mod visibility;

use std::borrow::Cow;

use crate::fit::{morphable, FitBuffers, FitRunError, Params, KC, KS};
use crate::gp::model::GpModel;
use crate::mesh::Mesh;
use gpmm_core::fit::TargetImage;
use gpmm_core::geometry::mat_vec;
use subspace::{Subspace, SubspaceError};

type Vec3 = [f32; 3];

/// How shape from shading weighs and runs.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ShadingSettings {
    /// Gradient steps.
    pub steps: u32,
    /// Least cosine between a vertex's normal and its direction to the camera for it to be used.
    pub min_cos: f32,
    /// Pixel noise σ of the image term (linear colour).
    pub pixel_sigma: f32,
    /// Vertices whose residual at the fitted instance exceeds this (RMS over the channels, linear
    /// colour) are left out: the image there shows something the fit does not (hair, an occluder,
    /// background at the silhouette), not detail.
    pub max_residual: f32,
    /// σ (mm) of a vertex's shape offset away from the model's shape subspace.
    pub shape_sigma_mm: f32,
    /// σ (linear colour) of a vertex's albedo offset away from the model's colour subspace.
    pub albedo_sigma: f32,
    /// Weight μ of the heights' Laplacian `μ |L h|²` (1/mm²).
    pub smoothness: f32,
    /// Adam's step of the heights (mm), falling linearly to a tenth over the run.
    pub shape_rate_mm: f32,
    /// Adam's step of the albedo offsets (linear colour), falling likewise.
    pub albedo_rate: f32,
}

impl ShadingSettings {
    /// The settings of `gpmm learn`: 300 steps (on the bump test of `host/tests/shading.rs`, 3000
    /// end at the same objective, 324.2 against 324.1, at ten times the cost; the paper's 5000
    /// would add seconds per image to a loop whose fits take about one), the fit's pixel σ.
    pub const DEFAULT: Self = Self {
        steps: 300,
        min_cos: 0.3,
        pixel_sigma: gpmm_core::fit::DEFAULT_PIXEL_SIGMA,
        max_residual: 0.15,
        shape_sigma_mm: 5.0,
        albedo_sigma: 0.02,
        smoothness: 0.5,
        shape_rate_mm: 0.1,
        albedo_rate: 0.004,
    };
}

/// Why shape from shading could not run.
#[derive(Debug, thiserror::Error)]
pub enum ShadingError {
    /// The model's instance could not be made.
    #[error(transparent)]
    Fit(#[from] FitRunError),
    /// A subspace could not be prepared.
    #[error(transparent)]
    Subspace(#[from] SubspaceError),
}

/// A model's subspace penalties and mesh neighbours for shape from shading (owned, so that a
/// worker that keeps a model can keep them beside it and prepare them once).
#[derive(Debug, Clone)]
pub struct ShadingBases {
    vertices: usize,
    shape: Subspace,
    color: Subspace,
    neighbours: Vec<Vec<u32>>,
}

impl ShadingBases {
    /// Those of `model` with the fit's ranks (`shape_rank`, `color_rank` leading components).
    pub fn new(model: &GpModel, shape_rank: usize, color_rank: usize, settings: &ShadingSettings) -> Result<Self, ShadingError> {
        Ok(Self {
            vertices: model.shape.mean.len(),
            shape: Subspace::new(&model.shape, shape_rank, settings.shape_sigma_mm, "shape")?,
            color: Subspace::new(&model.color, color_rank, settings.albedo_sigma, "colour")?,
            neighbours: surface::neighbours(model.shape.mean.len(), &model.triangles),
        })
    }
}

/// A model prepared for shape from shading: its subspaces' penalties and its mesh's neighbours
/// (made once per model, used for every image).
#[derive(Debug, Clone)]
pub struct ShadingModel<'m> {
    model: &'m GpModel,
    bases: Cow<'m, ShadingBases>,
}

impl<'m> ShadingModel<'m> {
    /// `model` with the fit's ranks (`shape_rank`, `color_rank` leading components).
    pub fn new(model: &'m GpModel, shape_rank: usize, color_rank: usize, settings: &ShadingSettings) -> Result<Self, ShadingError> {
        Ok(Self { model, bases: Cow::Owned(ShadingBases::new(model, shape_rank, color_rank, settings)?) })
    }

    /// `model` with bases prepared from it before ([`ShadingBases::new`]); `None` when they were
    /// prepared for a mesh of another size.
    pub fn with_bases(model: &'m GpModel, bases: &'m ShadingBases) -> Option<Self> {
        (bases.vertices == model.shape.mean.len()).then_some(Self { model, bases: Cow::Borrowed(bases) })
    }

    /// Each vertex's neighbours.
    pub fn neighbours(&self) -> &[Vec<u32>] {
        &self.bases.neighbours
    }
}

/// The detail found beyond a fitted instance.
#[derive(Debug, Clone, PartialEq)]
pub struct Detail {
    /// Per vertex: the height (mm) along the instance's normal.
    pub heights: Vec<f32>,
    /// Per vertex: the instance's unit normal (model space).
    pub normals: Vec<Vec3>,
    /// Per vertex: the albedo offset (linear RGB).
    pub albedo: Vec<Vec3>,
    /// Per vertex: whether the image spoke about it.
    pub seen: Vec<bool>,
    /// The objective before the first step and after the last.
    pub objective: [f64; 2],
}

impl Detail {
    /// The shape offset of vertex `v` (mm, model space).
    pub fn shape_offset(&self, v: usize) -> Vec3 {
        let (h, n) = (self.heights[v], self.normals[v]);
        [h * n[0], h * n[1], h * n[2]]
    }

    /// Vertices the image spoke about.
    pub fn seen_count(&self) -> usize {
        self.seen.iter().filter(|s| **s).count()
    }

    /// The mean per-vertex albedo change over the seen vertices: the mean absolute offset of the
    /// three channels (linear colour, 0–1), 0 when none was seen.
    pub fn mean_albedo_change(&self) -> f32 {
        let (sum, count) = self
            .albedo
            .iter()
            .zip(&self.seen)
            .filter(|(_, s)| **s)
            .fold((0.0f64, 0usize), |(s, c), (a, _)| (s + f64::from(a[0].abs() + a[1].abs() + a[2].abs()) / 3.0, c + 1));
        if count == 0 {
            0.0
        } else {
            (sum / count as f64) as f32
        }
    }

    /// The mean absolute height over the seen vertices (mm).
    pub fn mean_height(&self) -> f32 {
        let (sum, count) = self
            .heights
            .iter()
            .zip(&self.seen)
            .filter(|(_, s)| **s)
            .fold((0.0f64, 0usize), |(s, c), (h, _)| (s + f64::from(h.abs()), c + 1));
        if count == 0 {
            0.0
        } else {
            (sum / count as f64) as f32
        }
    }

    /// This detail with its spikes removed ([`surface::despike`] of the heights and of each
    /// albedo channel against the vertex's ring).
    pub fn despiked(&self, neighbours: &[Vec<u32>]) -> Self {
        let heights = surface::despike(&self.heights, neighbours);
        let channel = |c: usize| surface::despike(&self.albedo.iter().map(|a| a[c]).collect::<Vec<_>>(), neighbours);
        let (r, g, b) = (channel(0), channel(1), channel(2));
        let albedo = (0..self.albedo.len()).map(|v| [r[v], g[v], b[v]]).collect();
        Self { heights, albedo, ..self.clone() }
    }

    /// `instance` with this detail added: positions moved by the shape offsets, colours by the
    /// albedo offsets (kept within 0–1).
    pub fn applied_to(&self, instance: &Mesh) -> Mesh {
        let mut out = instance.clone();
        for (v, p) in out.positions.iter_mut().enumerate().take(self.heights.len()) {
            let d = self.shape_offset(v);
            for (pj, dj) in p.iter_mut().zip(d) {
                *pj += f64::from(dj);
            }
        }
        for (c, a) in out.colors.iter_mut().zip(&self.albedo) {
            for (cj, aj) in c.iter_mut().zip(a) {
                *cj = (*cj + f64::from(*aj)).clamp(0.0, 1.0);
            }
        }
        out
    }
}

/// The fitted instance the detail is sought around, and what the image says about it.
struct Problem<'a> {
    image: &'a TargetImage<'a>,
    camera: gpmm_core::render::Camera,
    translation: Vec3,
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    albedos: Vec<Vec3>,
    seen: Vec<visibility::Seen>,
    rotation: [[f32; 3]; 3],
    light: gpmm_core::render::ShLight,
    /// `bn[v · K + k] = B_k(v) · n_v`: the shape basis along each normal.
    along_normal: Vec<f32>,
    sm: &'a ShadingModel<'a>,
    weight: f32,
    smoothness: f32,
}

impl Problem<'_> {
    /// The image's colour where model-space point `p` projects and its gradient in `p`
    /// (`[channel][axis]`), if it projects into the covered pixels (the bilinear image's slope
    /// from half a pixel either side).
    fn sample(&self, p: Vec3) -> Option<(Vec3, [Vec3; 3])> {
        let q = mat_vec(&self.rotation, p);
        let pc = [q[0] + self.translation[0], q[1] + self.translation[1], q[2] + self.translation[2]];
        let s = self.camera.project(pc)?;
        let at = |dx: f32, dy: f32| self.image.sample_bilinear(s.x + dx, s.y + dy);
        let (c, xp, xm, yp, ym) = (at(0.0, 0.0)?, at(0.5, 0.0), at(-0.5, 0.0), at(0.0, 0.5), at(0.0, -0.5));
        let (Some(xp), Some(xm), Some(yp), Some(ym)) = (xp, xm, yp, ym) else { return Some((c, [[0.0; 3]; 3])) };
        // ∂(x, y)/∂(camera point): x = cx + f X / w, y = cy − f Y / w, w = −Z.
        let (f, inv_w) = (self.camera.focal, s.inv_w);
        let dx = [f * inv_w, 0.0, f * pc[0] * inv_w * inv_w];
        let dy = [0.0, -f * inv_w, -f * pc[1] * inv_w * inv_w];
        let r = &self.rotation;
        let mut grad = [[0.0f32; 3]; 3];
        for (ch, g) in grad.iter_mut().enumerate() {
            let (ix, iy) = (xp[ch] - xm[ch], yp[ch] - ym[ch]);
            let camera = [ix * dx[0] + iy * dy[0], ix * dx[1] + iy * dy[1], ix * dx[2] + iy * dy[2]];
            // Back to model space: Rᵀ.
            *g = [0, 1, 2].map(|j| r[0][j] * camera[0] + r[1][j] * camera[1] + r[2][j] * camera[2]);
        }
        Some((c, grad))
    }

    /// The objective at heights `h` and albedo offsets `c`, and its gradients (added to `gh`, `gc`).
    fn evaluate(&self, h: &[f32], c: &[Vec3], gh: &mut [f32], gc: &mut [Vec3]) -> f64 {
        let tri = &self.sm.model.triangles;
        let moved: Vec<Vec3> = self
            .positions
            .iter()
            .zip(&self.normals)
            .zip(h)
            .map(|((p, n), h)| [p[0] + h * n[0], p[1] + h * n[1], p[2] + h * n[2]])
            .collect();
        let m = surface::summed_normals(&moved, tri);
        let mut g_normal = vec![[0.0f32; 3]; moved.len()];
        let mut value = 0.0f64;
        let w = self.weight;
        let mut g_position = vec![[0.0f32; 3]; moved.len()];
        for s in &self.seen {
            let v = s.vertex;
            let (target, d_target) = self.sample(moved[v]).unwrap_or((s.target, [[0.0; 3]; 3]));
            let nc = mat_vec(&self.rotation, surface::unit(m[v]));
            let (e, de) = surface::irradiance_and_gradient(&self.light, nc);
            let albedo = [self.albedos[v][0] + c[v][0], self.albedos[v][1] + c[v][1], self.albedos[v][2] + c[v][2]];
            let mut g_nc = [0.0f32; 3];
            for ch in 0..3 {
                let r = target[ch] - albedo[ch] * e[ch];
                value += f64::from(w * r * r);
                for (g, d) in g_position[v].iter_mut().zip(d_target[ch]) {
                    *g += 2.0 * w * r * d;
                }
                gc[v][ch] -= 2.0 * w * r * e[ch];
                let g_e = -2.0 * w * r * albedo[ch];
                for (g, d) in g_nc.iter_mut().zip(de[ch]) {
                    *g += g_e * d;
                }
            }
            // Rᵀ g: back to model space.
            let r = &self.rotation;
            g_normal[v] = [0, 1, 2].map(|j| r[0][j] * g_nc[0] + r[1][j] * g_nc[1] + r[2][j] * g_nc[2]);
        }
        surface::normal_gradient(&moved, tri, &m, &g_normal, &mut g_position);
        for ((g, gp), n) in gh.iter_mut().zip(&g_position).zip(&self.normals) {
            *g += gp[0] * n[0] + gp[1] * n[1] + gp[2] * n[2];
        }
        // Shape penalty: λ |h|² + yᵀ Q y with y = Σ_v h_v (B(v) · n_v).
        let (shape, k) = (&self.sm.bases.shape, self.sm.bases.shape.rank());
        let mut y = vec![0.0f64; k];
        for (v, hv) in h.iter().enumerate() {
            if *hv != 0.0 {
                for (yk, b) in y.iter_mut().zip(&self.along_normal[v * k..(v + 1) * k]) {
                    *yk += f64::from(hv * b);
                }
            }
        }
        let (quadratic, qy) = shape.quadratic(&y);
        let lambda = shape.lambda();
        value += lambda * h.iter().map(|x| f64::from(x * x)).sum::<f64>() + quadratic;
        for (v, (g, hv)) in gh.iter_mut().zip(h).enumerate() {
            let b = &self.along_normal[v * k..(v + 1) * k];
            let through: f64 = b.iter().zip(&qy).map(|(b, q)| f64::from(*b) * q).sum();
            *g += (2.0 * lambda * f64::from(*hv) + 2.0 * through) as f32;
        }
        // Smoothness.
        let lh = surface::laplacian(h, &self.sm.bases.neighbours);
        value += f64::from(self.smoothness) * lh.iter().map(|x| f64::from(x * x)).sum::<f64>();
        surface::laplacian_gradient(&lh, &self.sm.bases.neighbours, self.smoothness, gh);
        // Albedo penalty.
        let color = &self.sm.bases.color;
        let y = color.project(|v| c[v]);
        let (quadratic, qy) = color.quadratic(&y);
        let lambda = color.lambda();
        value += lambda * c.iter().flatten().map(|x| f64::from(x * x)).sum::<f64>() + quadratic;
        for (v, (g, cv)) in gc.iter_mut().zip(c).enumerate() {
            let mut through = [0.0f64; 3];
            for (kk, q) in qy.iter().enumerate() {
                let b = color.component(kk, v);
                for (t, bj) in through.iter_mut().zip(b) {
                    *t += f64::from(bj) * q;
                }
            }
            for j in 0..3 {
                g[j] += (2.0 * lambda * f64::from(cv[j]) + 2.0 * through[j]) as f32;
            }
        }
        value
    }
}

/// Adam's moments of one array of unknowns.
struct Adam {
    m: Vec<f32>,
    v: Vec<f32>,
}

impl Adam {
    fn new(len: usize) -> Self {
        Self { m: vec![0.0; len], v: vec![0.0; len] }
    }

    /// One step of `x` along gradient `g` at rate `rate`, step number `t` (1-based).
    fn step(&mut self, x: &mut [f32], g: &[f32], rate: f32, t: i32) {
        let (b1, b2) = (0.9f32, 0.999f32);
        let (c1, c2) = (1.0 - b1.powi(t), 1.0 - b2.powi(t));
        for ((xi, gi), (mi, vi)) in x.iter_mut().zip(g).zip(self.m.iter_mut().zip(self.v.iter_mut())) {
            *mi = b1 * *mi + (1.0 - b1) * gi;
            *vi = b2 * *vi + (1.0 - b2) * gi * gi;
            *xi -= rate * (*mi / c1) / ((*vi / c2).sqrt() + 1e-8);
        }
    }
}

/// The detail beyond the instance of `params` that explains `image` (the fit's working image,
/// the size its camera assumes).
pub fn shape_from_shading(
    sm: &ShadingModel<'_>,
    params: &Params,
    image: &TargetImage<'_>,
    settings: &ShadingSettings,
) -> Result<Detail, ShadingError> {
    let model = sm.model;
    let mm = morphable(model)?;
    let (w, h) = (image.width(), image.height());
    let core_error = |stage: &'static str| move |error| FitRunError::Core { stage, error };
    let mut buffers = FitBuffers::host(mm.vertices(), w, h);
    let mut inst = buffers.instance::<KS, KC>().map_err(core_error("shape from shading"))?;
    inst.update(&mm, params, w, h).map_err(core_error("shape from shading"))?;
    let (positions, normals, albedos) = (inst.positions().to_vec(), inst.normals().to_vec(), inst.albedos().to_vec());
    let camera = params.camera(w, h);
    let mut seen = visibility::seen_vertices(&positions, &normals, &params.pose, &camera, image, settings.min_cos);
    let rotation = params.pose.rotation();
    seen.retain(|s| {
        let e = params.light.irradiance(mat_vec(&rotation, normals[s.vertex]));
        let a = albedos[s.vertex];
        let r2: f32 = (0..3).map(|c| (s.target[c] - a[c] * e[c]).powi(2)).sum();
        r2 <= 3.0 * settings.max_residual * settings.max_residual
    });
    let n = positions.len();
    let k = sm.bases.shape.rank();
    let mut along_normal = vec![0.0f32; n * k];
    for (v, nv) in normals.iter().enumerate() {
        for (kk, out) in along_normal[v * k..(v + 1) * k].iter_mut().enumerate() {
            let b = sm.bases.shape.component(kk, v);
            *out = b[0] * nv[0] + b[1] * nv[1] + b[2] * nv[2];
        }
    }
    let mut seen_mask = vec![false; n];
    for s in &seen {
        seen_mask[s.vertex] = true;
    }
    let problem = Problem {
        image,
        camera,
        translation: params.pose.translation,
        positions,
        normals,
        albedos,
        seen,
        rotation: params.pose.rotation(),
        light: params.light,
        along_normal,
        sm,
        weight: 1.0 / (settings.pixel_sigma * settings.pixel_sigma),
        smoothness: settings.smoothness,
    };
    let mut heights = vec![0.0f32; n];
    let mut albedo = vec![[0.0f32; 3]; n];
    let (mut adam_h, mut adam_c) = (Adam::new(n), Adam::new(3 * n));
    let mut before = None;
    let mut last = 0.0;
    for t in 0..settings.steps {
        let (mut gh, mut gc) = (vec![0.0f32; n], vec![[0.0f32; 3]; n]);
        last = problem.evaluate(&heights, &albedo, &mut gh, &mut gc);
        before.get_or_insert(last);
        // Only what the image speaks about moves (the rest keeps the instance).
        for (v, free) in seen_mask.iter().enumerate() {
            if !free {
                gh[v] = 0.0;
                gc[v] = [0.0; 3];
            }
        }
        let fall = 1.0 - 0.9 * t as f32 / settings.steps as f32;
        adam_h.step(&mut heights, &gh, settings.shape_rate_mm * fall, t as i32 + 1);
        let flat: Vec<f32> = gc.iter().flatten().copied().collect();
        let mut c: Vec<f32> = albedo.iter().flatten().copied().collect();
        adam_c.step(&mut c, &flat, settings.albedo_rate * fall, t as i32 + 1);
        for (a, chunk) in albedo.iter_mut().zip(c.chunks_exact(3)) {
            *a = [chunk[0], chunk[1], chunk[2]];
        }
    }
    if settings.steps > 0 {
        let (mut gh, mut gc) = (vec![0.0f32; n], vec![[0.0f32; 3]; n]);
        last = problem.evaluate(&heights, &albedo, &mut gh, &mut gc);
    }
    Ok(Detail { heights, normals: problem.normals, albedo, seen: seen_mask, objective: [before.unwrap_or(last), last] })
}
