//! The per-vertex stage of a parameter vector, cached between the steps of a chain.
//!
//! A change of pose, focal length or light re-shades and re-projects only; the shape and colour
//! instances are recomputed only when their coefficients change. With [`SpareBuffers`] the
//! previous shape and colour instances are kept too, so that coming back to the chain's state
//! after a rejected shape or colour proposal swaps buffers instead of recomputing them. The
//! projection is skipped when the geometry (shape instance, pose, focal length, image size) is
//! the one already projected, and a [`FrameCache`] attached with [`Instance::with_frame_cache`]
//! keeps the covered pixels of the last frames for re-shading without the rasterizer.

use crate::error::FitError;
use crate::geometry::{TriIndex, Vec3};
use crate::model::morphable::MorphableModel;
use crate::model::params::FitParams;
use crate::render::frame_cache::{FrameCache, GeometryKey};
use crate::render::shading::{project_vertices, shade_vertices, vertex_normals, ProjectedVertex, ShadingCache};

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

/// Caller-provided buffers for a second shape and colour instance (one entry per model vertex each).
#[derive(Debug)]
pub struct SpareBuffers<'b> {
    /// Model-space positions of the other shape instance.
    pub positions: &'b mut [Vec3],
    /// Its normals.
    pub normals: &'b mut [Vec3],
    /// Albedos of the other colour instance.
    pub albedos: &'b mut [Vec3],
}

/// The serial of the instance in `key` if its coefficients are `coeffs`.
fn serial_of<const K: usize>(key: &Option<(heapless::Vec<f32, K>, u64)>, coeffs: &heapless::Vec<f32, K>) -> Option<u64> {
    key.as_ref().filter(|(k, _)| k == coeffs).map(|(_, s)| *s)
}

/// A shape instance's coefficients and serial number (the serial names the positions in keys).
type ShapeKey<const KS: usize> = Option<(heapless::Vec<f32, KS>, u64)>;
/// A colour instance's coefficients and serial number.
type ColorKey<const KC: usize> = Option<(heapless::Vec<f32, KC>, u64)>;

#[derive(Debug)]
struct Spare<'b, const KS: usize, const KC: usize> {
    bufs: SpareBuffers<'b>,
    shape: ShapeKey<KS>,
    color: ColorKey<KC>,
}

/// What the shaded colours depend on: shape and colour instances, rotation and light (bit patterns).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct ShadingKey {
    shape: u64,
    color: u64,
    angles: [u32; 3],
    light: [[u32; 3]; crate::render::light::SH_COEFFS],
}

/// An instance's model-space vertices of its last update, read together.
#[derive(Debug, Clone, Copy)]
pub struct Vertices<'v> {
    /// Positions.
    pub positions: &'v [Vec3],
    /// Normals.
    pub normals: &'v [Vec3],
    /// Albedos.
    pub albedos: &'v [Vec3],
}

/// The per-vertex stage of a parameter vector, cached (see the module docs).
#[derive(Debug)]
pub struct Instance<'b, const KS: usize, const KC: usize> {
    bufs: InstanceBuffers<'b>,
    shape_key: ShapeKey<KS>,
    /// The shape instance the buffers held before the last recomputation (coefficients and
    /// serial only): recomputing it gives the same positions, so it gets its serial back, and a
    /// frame recorded for it stays valid (the chain's shape after a rejected shape proposal).
    prev_shape: ShapeKey<KS>,
    color_key: ColorKey<KC>,
    spare: Option<Spare<'b, KS, KC>>,
    shading: Option<ShadingKey>,
    geometry: Option<GeometryKey>,
    serial: u64,
    frames: Option<FrameCache<'b>>,
    shading_cache: Option<ShadingCache<'b>>,
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
        Ok(Self {
            bufs,
            shape_key: None,
            prev_shape: None,
            color_key: None,
            spare: None,
            shading: None,
            geometry: None,
            serial: 0,
            frames: None,
            shading_cache: None,
            shape_updates: 0,
            color_updates: 0,
        })
    }

    /// Keeps a second shape and colour instance in `spare` (each buffer one entry per vertex).
    pub fn with_spare(mut self, spare: SpareBuffers<'b>) -> Result<Self, FitError> {
        let n = self.bufs.positions.len();
        if spare.positions.len() != n || spare.normals.len() != n || spare.albedos.len() != n {
            return Err(FitError::LengthMismatch);
        }
        self.spare = Some(Spare { bufs: spare, shape: None, color: None });
        Ok(self)
    }

    /// Keeps the covered pixels of the last frames in `frames`, for re-shading after a change of
    /// colour or light (see [`crate::render::frame_cache`]).
    pub fn with_frame_cache(mut self, frames: FrameCache<'b>) -> Self {
        self.frames = Some(frames);
        self
    }

    /// Keeps the rotated normals' Lambert bases and the irradiance in `cache`, so that a change of
    /// colour or light re-shades without recomputing them (see [`ShadingCache`]).
    pub fn with_shading_cache(mut self, cache: ShadingCache<'b>) -> Self {
        self.shading_cache = Some(cache);
        self
    }

    /// Brings the buffers up to date with `params` for a `width × height` image.
    pub fn update<I: TriIndex>(
        &mut self,
        model: &MorphableModel<'_, I>,
        params: &FitParams<KS, KC>,
        width: u32,
        height: u32,
    ) -> Result<(), FitError> {
        self.update_keeping(model, params, None, width, height)
    }

    /// [`Instance::update`] for a proposal from the chain's state `keep`: with spare buffers, the
    /// shape and colour instances of `keep` are the ones not overwritten.
    pub fn update_keeping<I: TriIndex>(
        &mut self,
        model: &MorphableModel<'_, I>,
        params: &FitParams<KS, KC>,
        keep: Option<&FitParams<KS, KC>>,
        width: u32,
        height: u32,
    ) -> Result<(), FitError> {
        if self.bufs.positions.len() != model.vertices() {
            return Err(FitError::LengthMismatch);
        }
        let shape = self.update_shape(model, params, keep.map(|k| &k.shape))?;
        let color = self.update_color(model, params, keep.map(|k| &k.color))?;
        let p = &params.pose;
        let shading = ShadingKey {
            shape,
            color,
            angles: [p.yaw.to_bits(), p.pitch.to_bits(), p.roll.to_bits()],
            light: params.light.coeffs.map(|c| c.map(f32::to_bits)),
        };
        if self.shading != Some(shading) {
            self.shading = None;
            match self.shading_cache.as_mut() {
                Some(c) => c.shade(self.bufs.albedos, color, self.bufs.normals, shape, &params.pose, &params.light, self.bufs.projected)?,
                None => shade_vertices(self.bufs.albedos, self.bufs.normals, &params.pose, &params.light, self.bufs.projected)?,
            }
            self.shading = Some(shading);
        }
        let geometry = GeometryKey::new(shape, &params.pose, params.focal, width, height);
        if self.geometry != Some(geometry) {
            self.geometry = None;
            project_vertices(self.bufs.positions, &params.pose, &params.camera(width, height), self.bufs.projected)?;
            self.geometry = Some(geometry);
        }
        Ok(())
    }

    /// The geometry key of `params` in a `width × height` image if its shape instance is kept.
    pub fn geometry_of(&self, params: &FitParams<KS, KC>, width: u32, height: u32) -> Option<GeometryKey> {
        let serial = serial_of(&self.shape_key, &params.shape)
            .or_else(|| self.spare.as_ref().and_then(|sp| serial_of(&sp.shape, &params.shape)))
            .or_else(|| serial_of(&self.prev_shape, &params.shape))?;
        Some(GeometryKey::new(serial, &params.pose, params.focal, width, height))
    }

    /// The shape instance of `params` in the current buffers; returns its serial.
    fn update_shape<I: TriIndex>(
        &mut self,
        model: &MorphableModel<'_, I>,
        params: &FitParams<KS, KC>,
        keep: Option<&heapless::Vec<f32, KS>>,
    ) -> Result<u64, FitError> {
        if let Some(s) = serial_of(&self.shape_key, &params.shape) {
            return Ok(s);
        }
        if let Some(sp) = self.spare.as_mut() {
            let wanted = serial_of(&sp.shape, &params.shape);
            // Swap when the spare holds the one wanted, or when the current one is to be kept
            // (the spare's buffers are then the ones overwritten).
            if wanted.is_some() || keep.is_some_and(|k| serial_of(&self.shape_key, k).is_some()) {
                core::mem::swap(&mut self.bufs.positions, &mut sp.bufs.positions);
                core::mem::swap(&mut self.bufs.normals, &mut sp.bufs.normals);
                core::mem::swap(&mut self.shape_key, &mut sp.shape);
            }
            if let Some(s) = wanted {
                return Ok(s);
            }
        }
        let old = self.shape_key.take();
        model.shape_instance(params.shape_coeffs(), self.bufs.positions)?;
        vertex_normals(self.bufs.positions, model.triangles(), self.bufs.normals)?;
        // The same coefficients give the same positions and normals: the same serial.
        let serial = match serial_of(&self.prev_shape, &params.shape) {
            Some(s) => s,
            None => {
                self.serial = self.serial.wrapping_add(1);
                self.serial
            }
        };
        if old.is_some() {
            self.prev_shape = old;
        }
        self.shape_key = Some((params.shape.clone(), serial));
        self.shape_updates = self.shape_updates.wrapping_add(1);
        Ok(serial)
    }

    /// The colour instance of `params` in the current buffers; returns its serial.
    fn update_color<I: TriIndex>(
        &mut self,
        model: &MorphableModel<'_, I>,
        params: &FitParams<KS, KC>,
        keep: Option<&heapless::Vec<f32, KC>>,
    ) -> Result<u64, FitError> {
        if let Some(s) = serial_of(&self.color_key, &params.color) {
            return Ok(s);
        }
        if let Some(sp) = self.spare.as_mut() {
            let wanted = serial_of(&sp.color, &params.color);
            if wanted.is_some() || keep.is_some_and(|k| serial_of(&self.color_key, k).is_some()) {
                core::mem::swap(&mut self.bufs.albedos, &mut sp.bufs.albedos);
                core::mem::swap(&mut self.color_key, &mut sp.color);
            }
            if let Some(s) = wanted {
                return Ok(s);
            }
        }
        self.color_key = None;
        model.color_instance(params.color_coeffs(), self.bufs.albedos)?;
        self.serial = self.serial.wrapping_add(1);
        self.color_key = Some((params.color.clone(), self.serial));
        self.color_updates = self.color_updates.wrapping_add(1);
        Ok(self.serial)
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

    /// The geometry the projected vertices are for (`None` before a successful update).
    pub fn geometry(&self) -> Option<GeometryKey> {
        self.geometry
    }

    /// The projected vertices and the frame cache, if one is attached (borrowed together).
    pub fn projected_and_frames(&mut self) -> (&[ProjectedVertex], Option<&mut FrameCache<'b>>) {
        (self.bufs.projected, self.frames.as_mut())
    }

    /// The last update's vertices, with the attached frame cache's memory lent as scratch
    /// ([`FrameCache::scratch`]: `None` without a compact cache; the cache forgets its frames).
    pub fn vertices_and_scratch(&mut self) -> (Vertices<'_>, Option<&mut [u16]>) {
        let b = &self.bufs;
        let vertices = Vertices { positions: b.positions, normals: b.normals, albedos: b.albedos };
        (vertices, self.frames.as_mut().and_then(FrameCache::scratch))
    }

    /// The attached frame cache's counters, if one is attached.
    pub fn frames(&self) -> Option<&FrameCache<'b>> {
        self.frames.as_ref()
    }

    /// Forgets the cache (the next update recomputes everything).
    pub fn invalidate(&mut self) {
        self.shape_key = None;
        self.prev_shape = None;
        self.color_key = None;
        if let Some(sp) = self.spare.as_mut() {
            sp.shape = None;
            sp.color = None;
        }
        self.shading = None;
        self.geometry = None;
        if let Some(f) = self.frames.as_mut() {
            f.clear();
        }
        if let Some(c) = self.shading_cache.as_mut() {
            c.clear();
        }
    }
}
