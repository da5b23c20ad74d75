//! The interim device mesh: a mesh plus the scene to render it in, for the firmware's data partition.
//!
//! A simple little-endian file that the firmware reads in place from flash (the full quantized
//! model blob comes later). It carries one mesh instance (f32 positions in mm, f32 linear-RGB
//! albedo, u16 triangle indices) and a scene (image size, pose, camera, SH light), so that the
//! firmware renders exactly the frame the host renders from the same file.
//!
//! The layout is `gpmm_core::format::device_mesh`'s (documented there and in docs/formats.md):
//! the same code writes it here and reads it on the firmware.

use std::path::Path;

use gpmm_core::checksum::FrameChecksum;
use gpmm_core::format::device_mesh::{self, DeviceMeshView};
use gpmm_core::geometry::Vec3;
use gpmm_core::render::{vertex_stage, Camera, Cull, FrameStats, Pose, ProjectedVertex, ShLight, TileRasterizer};

use crate::gp::model::GpModel;
use crate::mesh::Mesh;

pub use gpmm_core::format::device_mesh::{encoded_len as file_len, DeviceScene, HEADER_BYTES, MAGIC, MAX_VERTICES, VERSION};

/// Largest image side the rasterizer accepts.
pub const MAX_IMAGE_SIDE: u32 = gpmm_core::render::raster::MAX_IMAGE_SIZE;

/// Errors writing or reading a device mesh.
#[derive(Debug, thiserror::Error)]
pub enum DeviceMeshError {
    /// More than [`MAX_VERTICES`] vertices, no vertex or no triangle.
    #[error("{0} vertices: a device mesh holds 1..=65536 (u16 indices)")]
    VertexCount(usize),
    /// A mesh without triangles.
    #[error("the mesh has no triangles")]
    NoTriangles,
    /// Positions and colours differ in length, or a triangle index is out of range.
    #[error("inconsistent mesh: {0}")]
    Inconsistent(&'static str),
    /// Image width or height is 0 or above [`MAX_IMAGE_SIDE`].
    #[error("image size {0}x{1} out of range (1..=32768)")]
    ImageSize(u32, u32),
    /// The bytes are not a device mesh (the message says which check failed).
    #[error("not a valid device mesh: {0}")]
    Format(String),
    /// The model could not produce its mean instance.
    #[error("model instance: {0}")]
    Model(gpmm_core::model::ModelError),
    /// The renderer refused the mesh or scene.
    #[error("render: {0}")]
    Render(String),
    /// Reading or writing the file failed.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: String,
        /// The I/O error.
        error: std::io::Error,
    },
}

/// The smoke-test scene for a `size × size` image: the face 650 mm away, turned 0.35 rad toward the
/// image right and tilted 0.1 rad down, a 24° field of view, ambient 0.6 + diffuse 0.5 from the upper left.
pub fn smoke_test_scene(size: u32) -> DeviceScene {
    let focal = Camera::focal_from_fov(size, 24f32.to_radians());
    DeviceScene {
        width: size,
        height: size,
        pose: Pose { yaw: 0.35, pitch: 0.1, roll: 0.0, translation: [0.0, 0.0, -650.0] },
        camera: Camera::centered(size, size, focal),
        light: ShLight::from_ambient_diffuse([0.6; 3], [0.5, 0.45, 0.4], [-0.4, 0.5, 0.77]),
    }
}

/// A mesh instance with its scene, as stored in the file (f32 values, u16 indices).
#[derive(Debug, Clone, PartialEq)]
pub struct DeviceMesh {
    /// Positions in mm.
    pub positions: Vec<Vec3>,
    /// Albedo, linear RGB.
    pub albedo: Vec<Vec3>,
    /// Triangles (counter-clockwise seen from outside).
    pub triangles: Vec<[u16; 3]>,
    /// The scene to render it in.
    pub scene: DeviceScene,
}

impl DeviceMesh {
    /// From a template-style mesh (f64 values are rounded to f32).
    pub fn from_mesh(mesh: &Mesh, scene: DeviceScene) -> Result<Self, DeviceMeshError> {
        let f = |v: &[f64; 3]| v.map(|x| x as f32);
        let n = mesh.positions.len();
        if mesh.colors.len() != n {
            return Err(DeviceMeshError::Inconsistent("positions and colours differ in length"));
        }
        if n == 0 || n > MAX_VERTICES {
            return Err(DeviceMeshError::VertexCount(n));
        }
        let mut triangles = Vec::with_capacity(mesh.triangles.len());
        for t in &mesh.triangles {
            if t.iter().any(|&i| i as usize >= n) {
                return Err(DeviceMeshError::Inconsistent("triangle index out of range"));
            }
            // n <= 65,536, so every index fits u16.
            triangles.push(t.map(|i| i as u16));
        }
        let m = Self { positions: mesh.positions.iter().map(f).collect(), albedo: mesh.colors.iter().map(f).collect(), triangles, scene };
        m.check()?;
        Ok(m)
    }

    /// The model's mean instance (all coefficients zero).
    pub fn from_model(model: &GpModel, scene: DeviceScene) -> Result<Self, DeviceMeshError> {
        let mesh = model.instance(&[], &[]).map_err(DeviceMeshError::Model)?;
        Self::from_mesh(&mesh, scene)
    }

    fn check(&self) -> Result<(), DeviceMeshError> {
        let n = self.positions.len();
        if n == 0 || n > MAX_VERTICES {
            return Err(DeviceMeshError::VertexCount(n));
        }
        if self.albedo.len() != n {
            return Err(DeviceMeshError::Inconsistent("positions and albedo differ in length"));
        }
        if self.triangles.is_empty() {
            return Err(DeviceMeshError::NoTriangles);
        }
        if self.triangles.iter().any(|t| t.iter().any(|&i| usize::from(i) >= n)) {
            return Err(DeviceMeshError::Inconsistent("triangle index out of range"));
        }
        let (w, h) = (self.scene.width, self.scene.height);
        if w == 0 || h == 0 || w > MAX_IMAGE_SIDE || h > MAX_IMAGE_SIDE {
            return Err(DeviceMeshError::ImageSize(w, h));
        }
        Ok(())
    }

    /// The file's size in bytes.
    pub fn byte_len(&self) -> usize {
        file_len(self.positions.len(), self.triangles.len())
    }

    /// The file's bytes (the core's writer).
    pub fn to_bytes(&self) -> Result<Vec<u8>, DeviceMeshError> {
        self.check()?;
        let view = DeviceMeshView { positions: &self.positions, albedo: &self.albedo, triangles: &self.triangles, scene: self.scene };
        let mut b = vec![0u8; self.byte_len()];
        let n = device_mesh::write(&view, &mut b).map_err(|e| DeviceMeshError::Format(e.to_string()))?;
        b.truncate(n);
        Ok(b)
    }

    /// Parses and validates a file (the core's reader, on an aligned copy).
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, DeviceMeshError> {
        let mut words = vec![0u32; bytes.len().div_ceil(4)];
        bytemuck::cast_slice_mut::<u32, u8>(&mut words)[..bytes.len()].copy_from_slice(bytes);
        let aligned = &bytemuck::cast_slice::<u32, u8>(&words)[..bytes.len()];
        let v = device_mesh::parse(aligned, MAX_VERTICES).map_err(|e| DeviceMeshError::Format(e.to_string()))?;
        if bytes.len() != file_len(v.positions.len(), v.triangles.len()) {
            return Err(DeviceMeshError::Format("the file is longer than its vertex and triangle counts say".into()));
        }
        let m = Self { positions: v.positions.to_vec(), albedo: v.albedo.to_vec(), triangles: v.triangles.to_vec(), scene: v.scene };
        m.check()?;
        Ok(m)
    }

    /// Writes the file.
    pub fn write(&self, path: &Path) -> Result<(), DeviceMeshError> {
        let bytes = self.to_bytes()?;
        std::fs::write(path, bytes).map_err(|error| DeviceMeshError::Io { path: path.display().to_string(), error })
    }

    /// Reads and validates a file.
    pub fn read(path: &Path) -> Result<Self, DeviceMeshError> {
        let bytes = std::fs::read(path).map_err(|error| DeviceMeshError::Io { path: path.display().to_string(), error })?;
        Self::from_bytes(&bytes)
    }

    /// Renders the frame with the core (the firmware's code path, any tile size) into a [`FrameChecksum`].
    pub fn render_checksum(&self) -> Result<(FrameChecksum, FrameStats), DeviceMeshError> {
        let s = &self.scene;
        let mut normals = vec![[0.0f32; 3]; self.positions.len()];
        let mut projected = vec![ProjectedVertex::INVALID; self.positions.len()];
        vertex_stage(&self.positions, &self.albedo, &self.triangles, &s.pose, &s.camera, &s.light, &mut normals, &mut projected)
            .map_err(|e| DeviceMeshError::Render(e.to_string()))?;
        let mut sum = FrameChecksum::new();
        let stats = TileRasterizer::<32, 32, 4096>::new()
            .render(&projected, &self.triangles, s.width, s.height, Cull::Clockwise, &mut sum)
            .map_err(|e| DeviceMeshError::Render(e.to_string()))?;
        Ok((sum, stats))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad() -> Mesh {
        Mesh {
            positions: vec![[-50.0, -50.0, 0.0], [50.0, -50.0, 0.0], [50.0, 50.0, 0.0], [-50.0, 50.0, 0.0], [0.0, 0.0, 30.0]],
            colors: vec![[0.9, 0.2, 0.1], [0.1, 0.8, 0.2], [0.2, 0.3, 0.9], [0.5, 0.5, 0.5], [1.0, 1.0, 1.0]],
            triangles: vec![[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4], [0, 3, 2]],
        }
    }

    #[test]
    fn round_trip_and_size() {
        let m = DeviceMesh::from_mesh(&quad(), smoke_test_scene(128)).unwrap();
        let b = m.to_bytes().unwrap();
        assert_eq!(b.len(), file_len(5, 5));
        assert_eq!(b.len(), 168 + 24 * 5 + 30 + 2 + 4);
        assert_eq!(&b[..4], b"GPDM");
        assert_eq!(DeviceMesh::from_bytes(&b).unwrap(), m);
        assert_eq!(file_len(4249, 8352), 152_260);
        let (sum, stats) = m.render_checksum().unwrap();
        assert!(sum.covered > 1000, "{sum:?}");
        assert_eq!(sum.covered, stats.covered_pixels);
    }

    #[test]
    fn garbage_is_an_error() {
        let b = DeviceMesh::from_mesh(&quad(), smoke_test_scene(64)).unwrap().to_bytes().unwrap();
        for cut in [0, 3, 20, 100, b.len() - 1] {
            assert!(DeviceMesh::from_bytes(&b[..cut]).is_err(), "truncated at {cut}");
        }
        for i in (0..b.len()).step_by(7) {
            let mut c = b.clone();
            c[i] ^= 0x10;
            assert!(DeviceMesh::from_bytes(&c).is_err(), "flipped byte {i}");
        }
        // A bad index with a valid CRC is still refused.
        let mut c = b.clone();
        let t0 = HEADER_BYTES + 24 * 5;
        c[t0..t0 + 2].copy_from_slice(&9u16.to_le_bytes());
        let body = c.len() - 4;
        let crc = gpmm_core::checksum::crc32(&c[..body]);
        c[body..].copy_from_slice(&crc.to_le_bytes());
        assert!(matches!(DeviceMesh::from_bytes(&c), Err(DeviceMeshError::Format(_))));
        let mut bad = quad();
        bad.triangles.push([0, 1, 7]);
        assert!(DeviceMesh::from_mesh(&bad, smoke_test_scene(64)).is_err());
    }
}
