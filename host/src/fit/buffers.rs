//! The host-side memory of one fit: the model instance's per-vertex buffers and the caches the
//! core's [`Instance`] runs on, allocated in one place for `gpmm fit`, the Python package and the
//! host's run of a device fit.

use crate::render::FrameMemory;
use gpmm_core::error::FitError;
use gpmm_core::geometry::Vec3;
use gpmm_core::model::{Instance, InstanceBuffers, SpareBuffers};
use gpmm_core::render::frame_cache::{CompactBuffers, FrameCache};
use gpmm_core::render::light::SH_COEFFS;
use gpmm_core::render::shading::{ShadingBuffers, ShadingCache};
use gpmm_core::render::ProjectedVertex;

/// The frame cache's memory.
#[derive(Debug)]
enum Frames {
    /// Two full frames (the host's cache).
    Full(FrameMemory),
    /// One compact frame (the device's cache): a coverage bit per pixel, a triangle id per covered pixel.
    Compact { covered: Vec<u32>, triangles: Vec<u16> },
}

/// Owns every buffer of one fit's [`Instance`]; [`Self::instance`] lends them to the core.
#[derive(Debug)]
pub struct FitBuffers {
    vertices: usize,
    positions: Vec<Vec3>,
    albedos: Vec<Vec3>,
    normals: Vec<Vec3>,
    projected: Vec<ProjectedVertex>,
    /// Positions, normals and albedos of the spare instance (the host's proposals swap it in).
    spare: Option<[Vec<Vec3>; 3]>,
    /// The shading cache's Lambert bases and irradiances.
    shading: Option<(Vec<[f32; SH_COEFFS]>, Vec<Vec3>)>,
    frames: Frames,
}

impl FitBuffers {
    fn instance_only(vertices: usize, frames: Frames) -> Self {
        Self {
            vertices,
            positions: vec![[0.0; 3]; vertices],
            albedos: vec![[0.0; 3]; vertices],
            normals: vec![[0.0; 3]; vertices],
            projected: vec![ProjectedVertex::INVALID; vertices],
            spare: None,
            shading: None,
            frames,
        }
    }

    /// The host's fit of a model of `vertices` vertices to a `width × height` image: a spare
    /// instance, the shading cache and two full cached frames.
    pub fn host(vertices: usize, width: u32, height: u32) -> Self {
        Self {
            spare: Some([vec![[0.0; 3]; vertices], vec![[0.0; 3]; vertices], vec![[0.0; 3]; vertices]]),
            shading: Some((vec![[0.0; SH_COEFFS]; vertices], vec![[0.0; 3]; vertices])),
            ..Self::instance_only(vertices, Frames::Full(FrameMemory::new(width, height)))
        }
    }

    /// The device's fit run on the host, as the firmware runs it: the instance and one compact
    /// cached frame of a `width × height` image holding up to `cache_pixels` covered pixels.
    pub fn device(vertices: usize, width: u32, height: u32, cache_pixels: usize) -> Self {
        let covered = vec![0; (width as usize * height as usize).div_ceil(32)];
        Self::instance_only(vertices, Frames::Compact { covered, triangles: vec![0; cache_pixels] })
    }

    /// The core's instance over these buffers.
    pub fn instance<const KS: usize, const KC: usize>(&mut self) -> Result<Instance<'_, KS, KC>, FitError> {
        let n = self.vertices;
        let bufs = InstanceBuffers {
            positions: &mut self.positions,
            albedos: &mut self.albedos,
            normals: &mut self.normals,
            projected: &mut self.projected,
        };
        let mut inst = Instance::<KS, KC>::new(bufs, n)?;
        if let Some([positions, normals, albedos]) = &mut self.spare {
            inst = inst.with_spare(SpareBuffers { positions, normals, albedos })?;
        }
        inst = inst.with_frame_cache(match &mut self.frames {
            Frames::Full(memory) => memory.cache(),
            Frames::Compact { covered, triangles } => FrameCache::compact(CompactBuffers { covered, triangles }),
        });
        if let Some((basis, irradiance)) = &mut self.shading {
            inst = inst.with_shading_cache(ShadingCache::new(ShadingBuffers { basis, irradiance }, n)?);
        }
        Ok(inst)
    }
}
