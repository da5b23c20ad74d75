//! The borrowed model view used by the fitter, and the cached per-vertex instance.

use crate::error::FitError;
use crate::model::basis::{Basis, Vec3};
use crate::model::params::FitParams;
use crate::render::shading::{project_vertices, shade_vertices, vertex_normals, ProjectedVertex, TriIndex};

/// Most landmarks a model or a fit target has.
pub const MAX_LANDMARKS: usize = 128;

/// A morphable model, borrowed: means, bases, triangles and landmark vertex ids (iBUG-68 order).
#[derive(Debug, Clone, Copy)]
pub struct MorphableModel<'a, I: TriIndex = u32> {
    shape_mean: &'a [Vec3],
    color_mean: &'a [Vec3],
    shape: Basis<'a>,
    color: Basis<'a>,
    triangles: &'a [[I; 3]],
    landmarks: &'a [u32],
}

impl<'a, I: TriIndex> MorphableModel<'a, I> {
    /// Wraps borrowed model data, checking every length and index once (O(vertices + triangles)).
    pub fn new(
        shape_mean: &'a [Vec3],
        color_mean: &'a [Vec3],
        shape: Basis<'a>,
        color: Basis<'a>,
        triangles: &'a [[I; 3]],
        landmarks: &'a [u32],
    ) -> Result<Self, FitError> {
        let n = shape_mean.len();
        if color_mean.len() != n || shape.vertices() != n || color.vertices() != n {
            return Err(FitError::LengthMismatch);
        }
        if landmarks.len() > MAX_LANDMARKS {
            return Err(FitError::TooManyLandmarks);
        }
        if landmarks.iter().any(|&l| l as usize >= n) || triangles.iter().flatten().any(|i| i.index() >= n) {
            return Err(FitError::IndexOutOfRange);
        }
        if !shape_mean.iter().chain(color_mean).flatten().all(|v| v.is_finite()) {
            return Err(FitError::NonFinite);
        }
        Ok(Self { shape_mean, color_mean, shape, color, triangles, landmarks })
    }

    /// Number of vertices.
    pub fn vertices(&self) -> usize {
        self.shape_mean.len()
    }

    /// Shape rank (number of shape components).
    pub fn shape_rank(&self) -> usize {
        self.shape.rank()
    }

    /// Colour rank.
    pub fn color_rank(&self) -> usize {
        self.color.rank()
    }

    /// The triangle list.
    pub fn triangles(&self) -> &'a [[I; 3]] {
        self.triangles
    }

    /// Landmark vertex ids.
    pub fn landmarks(&self) -> &'a [u32] {
        self.landmarks
    }

    /// The shape mean.
    pub fn shape_mean(&self) -> &'a [Vec3] {
        self.shape_mean
    }

    /// Shape instance positions into `out` (one per vertex).
    pub fn shape_instance(&self, coeffs: &[f32], out: &mut [Vec3]) -> Result<(), FitError> {
        if out.len() != self.vertices() {
            return Err(FitError::LengthMismatch);
        }
        out.copy_from_slice(self.shape_mean);
        Ok(self.shape.add_instance(coeffs, out)?)
    }

    /// Colour instance (albedo) into `out` (one per vertex).
    pub fn color_instance(&self, coeffs: &[f32], out: &mut [Vec3]) -> Result<(), FitError> {
        if out.len() != self.vertices() {
            return Err(FitError::LengthMismatch);
        }
        out.copy_from_slice(self.color_mean);
        Ok(self.color.add_instance(coeffs, out)?)
    }

    /// Instance position of one vertex (`rank` multiply-adds per coordinate).
    pub fn vertex_position(&self, coeffs: &[f32], vertex: u32) -> Result<Vec3, FitError> {
        let mut p = self.shape_mean.get(vertex as usize).copied().ok_or(FitError::IndexOutOfRange)?;
        self.shape.add_vertex(coeffs, vertex as usize, &mut p)?;
        Ok(p)
    }

    /// Instance positions of the landmark vertices only (`rank × landmarks` multiply-adds) into
    /// `out[..landmarks]`; returns the number written.
    pub fn landmark_positions(&self, coeffs: &[f32], out: &mut [Vec3]) -> Result<usize, FitError> {
        let n = self.landmarks.len();
        let out = out.get_mut(..n).ok_or(FitError::LengthMismatch)?;
        for (o, &l) in out.iter_mut().zip(self.landmarks) {
            *o = self.shape_mean.get(l as usize).copied().ok_or(FitError::IndexOutOfRange)?;
        }
        self.shape.add_vertices(coeffs, self.landmarks, out)?;
        Ok(n)
    }
}

/// Caller-provided per-vertex buffers (each exactly one entry per model vertex).
#[derive(Debug)]
pub struct InstanceBuffers<'b> {
    /// Model-space positions (mm).
    pub positions: &'b mut [Vec3],
    /// Albedos (linear RGB).
    pub albedos: &'b mut [Vec3],
    /// Model-space unit normals.
    pub normals: &'b mut [Vec3],
    /// Shaded and projected vertices, ready for the rasterizer.
    pub projected: &'b mut [ProjectedVertex],
}

/// The per-vertex stage of a parameter vector, cached: a change of pose, focal length or light
/// re-shades and re-projects only; shape and colour instances are recomputed only when their
/// coefficients change.
#[derive(Debug)]
pub struct Instance<'b, const KS: usize, const KC: usize> {
    bufs: InstanceBuffers<'b>,
    shape_key: Option<heapless::Vec<f32, KS>>,
    color_key: Option<heapless::Vec<f32, KC>>,
    /// Shape instances computed so far (positions and normals).
    pub shape_updates: u32,
    /// Colour instances computed so far.
    pub color_updates: u32,
}

impl<'b, const KS: usize, const KC: usize> Instance<'b, KS, KC> {
    /// Wraps the buffers, checking that all have `vertices` entries.
    pub fn new(bufs: InstanceBuffers<'b>, vertices: usize) -> Result<Self, FitError> {
        let n = vertices;
        if bufs.positions.len() != n || bufs.albedos.len() != n || bufs.normals.len() != n || bufs.projected.len() != n {
            return Err(FitError::LengthMismatch);
        }
        Ok(Self { bufs, shape_key: None, color_key: None, shape_updates: 0, color_updates: 0 })
    }

    /// Brings the buffers up to date with `params` for a `width × height` image.
    pub fn update<I: TriIndex>(
        &mut self,
        model: &MorphableModel<'_, I>,
        params: &FitParams<KS, KC>,
        width: u32,
        height: u32,
    ) -> Result<(), FitError> {
        if self.bufs.positions.len() != model.vertices() {
            return Err(FitError::LengthMismatch);
        }
        if self.shape_key.as_ref() != Some(&params.shape) {
            self.shape_key = None;
            model.shape_instance(params.shape_coeffs(), self.bufs.positions)?;
            vertex_normals(self.bufs.positions, model.triangles(), self.bufs.normals)?;
            self.shape_key = Some(params.shape.clone());
            self.shape_updates = self.shape_updates.wrapping_add(1);
        }
        if self.color_key.as_ref() != Some(&params.color) {
            self.color_key = None;
            model.color_instance(params.color_coeffs(), self.bufs.albedos)?;
            self.color_key = Some(params.color.clone());
            self.color_updates = self.color_updates.wrapping_add(1);
        }
        shade_vertices(self.bufs.albedos, self.bufs.normals, &params.pose, &params.light, self.bufs.projected)?;
        project_vertices(self.bufs.positions, &params.pose, &params.camera(width, height), self.bufs.projected)?;
        Ok(())
    }

    /// Shaded, projected vertices of the last [`Instance::update`].
    pub fn projected(&self) -> &[ProjectedVertex] {
        self.bufs.projected
    }

    /// Model-space positions of the last update.
    pub fn positions(&self) -> &[Vec3] {
        self.bufs.positions
    }

    /// Model-space normals of the last update.
    pub fn normals(&self) -> &[Vec3] {
        self.bufs.normals
    }

    /// Albedos of the last update.
    pub fn albedos(&self) -> &[Vec3] {
        self.bufs.albedos
    }

    /// Forgets the cache (the next update recomputes everything).
    pub fn invalidate(&mut self) {
        self.shape_key = None;
        self.color_key = None;
    }
}
