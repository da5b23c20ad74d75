//! The interim device mesh: a mesh plus the scene to render it in, for the firmware's data partition.
//!
//! A simple little-endian file that the firmware reads in place from flash (the full quantized
//! model blob comes later). It carries one mesh instance (f32 positions in mm, f32 linear-RGB
//! albedo, u16 triangle indices) and a scene (image size, pose, camera, SH light), so that the
//! firmware renders exactly the frame the host renders from the same file.
//!
//! Layout, version 1 (all fields little-endian, no padding between fields; offsets in bytes):
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `b"GPDM"` |
//! | 4 | 2 | version (`u16`, 1) |
//! | 6 | 2 | header size in bytes (`u16`, [`HEADER_BYTES`] = 168): where the positions start |
//! | 8 | 4 | vertex count `N` (`u32`, 1..=65,536) |
//! | 12 | 4 | triangle count `T` (`u32`, >= 1) |
//! | 16 | 2 | image width in pixels (`u16`, 1..=32,768) |
//! | 18 | 2 | image height in pixels (`u16`, 1..=32,768) |
//! | 20 | 24 | pose: yaw, pitch, roll (radians), translation x, y, z (mm), 6 × `f32` ([`gpmm_core::Pose`]) |
//! | 44 | 16 | camera: focal length (px), principal point x, y (px), near plane (mm), 4 × `f32` ([`gpmm_core::Camera`]) |
//! | 60 | 108 | SH light: 9 coefficients × (r, g, b), 27 × `f32`, coefficient-major ([`gpmm_core::ShLight`]) |
//! | 168 | 12 N | positions, `N × [f32; 3]` (mm, model space) |
//! | 168 + 12 N | 12 N | albedo, `N × [f32; 3]` (linear RGB in [0, 1]) |
//! | 168 + 24 N | 6 T | triangles, `T × [u16; 3]` (counter-clockwise seen from outside) |
//! | 168 + 24 N + 6 T | 0 or 2 | zero padding to a multiple of 4 |
//! | end − 4 | 4 | CRC-32 (zlib's, [`gpmm_core::crc32`]) of every byte before it |
//!
//! Total: `168 + 24 N + 6 T (+ 2 if T is odd) + 4` bytes; the cropped template (4,249 vertices,
//! 8,352 triangles) takes 152,260 bytes, well inside the `m4f` data partition (512 KiB). Every
//! section starts 4-byte aligned, so a reader on a little-endian machine can use the arrays in
//! place when the file itself is 4-byte aligned (the firmware's partition is). Readers check the
//! magic, version, header size, counts against the file length, the CRC, and that every triangle
//! index is below `N`; the renderer additionally refuses non-finite values.

use std::path::Path;

use gpmm_core::checksum::{crc32, FrameChecksum};
use gpmm_core::light::SH_COEFFS;
use gpmm_core::{vertex_stage, Camera, Cull, FrameStats, Pose, ProjectedVertex, ShLight, TileRasterizer, Vec3};

use crate::gp::model::GpModel;
use crate::mesh::template::Mesh;

/// File magic: the first 4 bytes.
pub const MAGIC: [u8; 4] = *b"GPDM";
/// Layout version written and accepted.
pub const VERSION: u16 = 1;
/// Bytes before the positions: fixed header (20) + pose (24) + camera (16) + light (108).
pub const HEADER_BYTES: usize = 168;
/// Largest vertex count (u16 indices).
pub const MAX_VERTICES: usize = 1 << 16;
/// Largest image side the rasterizer accepts.
pub const MAX_IMAGE_SIDE: u32 = gpmm_core::raster::MAX_IMAGE_SIZE;

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
    Format(&'static str),
    /// The model could not produce its mean instance.
    #[error("model instance: {0:?}")]
    Model(gpmm_core::ModelError),
    /// The renderer refused the mesh or scene.
    #[error("render: {0}")]
    Render(String),
    /// Reading or writing the file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The I/O error.
        source: std::io::Error,
    },
}

/// What the firmware renders besides the mesh: image size, pose, camera and light.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DeviceScene {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Model pose.
    pub pose: Pose,
    /// Pinhole camera.
    pub camera: Camera,
    /// Spherical-harmonics light (camera space).
    pub light: ShLight,
}

impl DeviceScene {
    /// The smoke-test scene for a `size × size` image: the face 650 mm away, turned 0.35 rad toward the
    /// image right and tilted 0.1 rad down, a 24° field of view, ambient 0.6 + diffuse 0.5 from the upper left.
    pub fn smoke_test(size: u32) -> Self {
        let focal = Camera::focal_from_fov(size, 24f32.to_radians());
        Self {
            width: size,
            height: size,
            pose: Pose { yaw: 0.35, pitch: 0.1, roll: 0.0, translation: [0.0, 0.0, -650.0] },
            camera: Camera::centered(size, size, focal),
            light: ShLight::from_ambient_diffuse([0.6; 3], [0.5, 0.45, 0.4], [-0.4, 0.5, 0.77]),
        }
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

    /// The file's bytes (layout in the module docs).
    pub fn to_bytes(&self) -> Result<Vec<u8>, DeviceMeshError> {
        self.check()?;
        let s = &self.scene;
        let mut b = Vec::with_capacity(self.byte_len());
        b.extend_from_slice(&MAGIC);
        b.extend_from_slice(&VERSION.to_le_bytes());
        b.extend_from_slice(&(HEADER_BYTES as u16).to_le_bytes());
        b.extend_from_slice(&(self.positions.len() as u32).to_le_bytes());
        b.extend_from_slice(&(self.triangles.len() as u32).to_le_bytes());
        b.extend_from_slice(&(s.width as u16).to_le_bytes());
        b.extend_from_slice(&(s.height as u16).to_le_bytes());
        let p = &s.pose;
        let c = &s.camera;
        let scene_floats = [p.yaw, p.pitch, p.roll, p.translation[0], p.translation[1], p.translation[2]]
            .into_iter()
            .chain([c.focal, c.principal[0], c.principal[1], c.near])
            .chain(s.light.coeffs.iter().flatten().copied());
        for x in scene_floats {
            b.extend_from_slice(&x.to_le_bytes());
        }
        debug_assert_eq!(b.len(), HEADER_BYTES);
        for x in self.positions.iter().chain(&self.albedo).flatten() {
            b.extend_from_slice(&x.to_le_bytes());
        }
        for i in self.triangles.iter().flatten() {
            b.extend_from_slice(&i.to_le_bytes());
        }
        while b.len() % 4 != 0 {
            b.push(0);
        }
        let crc = crc32(&b);
        b.extend_from_slice(&crc.to_le_bytes());
        debug_assert_eq!(b.len(), self.byte_len());
        Ok(b)
    }

    /// Parses and validates a file (every check of the module docs).
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, DeviceMeshError> {
        use DeviceMeshError::Format;
        let u16_at = |o: usize| bytes.get(o..o + 2).map(|s| u16::from_le_bytes([s[0], s[1]]));
        let u32_at = |o: usize| bytes.get(o..o + 4).map(|s| u32::from_le_bytes([s[0], s[1], s[2], s[3]]));
        let f32_at = |o: usize| u32_at(o).map(f32::from_bits);
        if bytes.get(..4) != Some(&MAGIC[..]) {
            return Err(Format("bad magic"));
        }
        if u16_at(4) != Some(VERSION) {
            return Err(Format("unsupported version"));
        }
        if u16_at(6) != Some(HEADER_BYTES as u16) {
            return Err(Format("bad header size"));
        }
        let n = u32_at(8).ok_or(Format("truncated header"))? as usize;
        let t = u32_at(12).ok_or(Format("truncated header"))? as usize;
        let width = u32::from(u16_at(16).ok_or(Format("truncated header"))?);
        let height = u32::from(u16_at(18).ok_or(Format("truncated header"))?);
        if n == 0 || n > MAX_VERTICES || t == 0 || t > u32::MAX as usize / 8 {
            return Err(Format("vertex or triangle count out of range"));
        }
        if bytes.len() != file_len(n, t) {
            return Err(Format("length does not match the vertex and triangle counts"));
        }
        let body = bytes.len() - 4;
        if u32_at(body) != Some(crc32(&bytes[..body])) {
            return Err(Format("CRC mismatch"));
        }
        let floats = |start: usize, count: usize| -> Vec<f32> { (0..count).filter_map(|k| f32_at(start + 4 * k)).collect() };
        let sc = floats(20, 6 + 4 + 3 * SH_COEFFS);
        let mut light = ShLight::zero();
        for (c, v) in light.coeffs.iter_mut().zip(sc[10..].chunks_exact(3)) {
            *c = [v[0], v[1], v[2]];
        }
        let scene = DeviceScene {
            width,
            height,
            pose: Pose { yaw: sc[0], pitch: sc[1], roll: sc[2], translation: [sc[3], sc[4], sc[5]] },
            camera: Camera { focal: sc[6], principal: [sc[7], sc[8]], near: sc[9] },
            light,
        };
        let vec3s = |start: usize| -> Vec<Vec3> { floats(start, 3 * n).chunks_exact(3).map(|v| [v[0], v[1], v[2]]).collect() };
        let positions = vec3s(HEADER_BYTES);
        let albedo = vec3s(HEADER_BYTES + 12 * n);
        let tstart = HEADER_BYTES + 24 * n;
        let triangles = (0..t).map(|k| [0, 1, 2].map(|j| u16_at(tstart + 6 * k + 2 * j).unwrap_or(u16::MAX))).collect();
        let m = Self { positions, albedo, triangles, scene };
        m.check().map_err(|_| Format("triangle index out of range or bad image size"))?;
        Ok(m)
    }

    /// Writes the file.
    pub fn write(&self, path: &Path) -> Result<(), DeviceMeshError> {
        let bytes = self.to_bytes()?;
        std::fs::write(path, bytes).map_err(|source| DeviceMeshError::Io { path: path.display().to_string(), source })
    }

    /// Reads and validates a file.
    pub fn read(path: &Path) -> Result<Self, DeviceMeshError> {
        let bytes = std::fs::read(path).map_err(|source| DeviceMeshError::Io { path: path.display().to_string(), source })?;
        Self::from_bytes(&bytes)
    }

    /// Renders the frame with the core (the firmware's code path, any tile size) into a [`FrameChecksum`].
    pub fn render_checksum(&self) -> Result<(FrameChecksum, FrameStats), DeviceMeshError> {
        let s = &self.scene;
        let mut normals = vec![[0.0f32; 3]; self.positions.len()];
        let mut projected = vec![ProjectedVertex::INVALID; self.positions.len()];
        vertex_stage(&self.positions, &self.albedo, &self.triangles, &s.pose, &s.camera, &s.light, &mut normals, &mut projected)
            .map_err(|e| DeviceMeshError::Render(format!("{e:?}")))?;
        let mut sum = FrameChecksum::new();
        let stats = TileRasterizer::<32, 32, 4096>::new()
            .render(&projected, &self.triangles, s.width, s.height, Cull::Clockwise, &mut sum)
            .map_err(|e| DeviceMeshError::Render(format!("{e:?}")))?;
        Ok((sum, stats))
    }
}

/// File size for `n` vertices and `t` triangles.
pub fn file_len(n: usize, t: usize) -> usize {
    let body = HEADER_BYTES + 24 * n + 6 * t;
    body.next_multiple_of(4) + 4
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
        let m = DeviceMesh::from_mesh(&quad(), DeviceScene::smoke_test(128)).unwrap();
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
        let b = DeviceMesh::from_mesh(&quad(), DeviceScene::smoke_test(64)).unwrap().to_bytes().unwrap();
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
        let crc = crc32(&c[..body]);
        c[body..].copy_from_slice(&crc.to_le_bytes());
        assert!(matches!(DeviceMesh::from_bytes(&c), Err(DeviceMeshError::Format(_))));
        let mut bad = quad();
        bad.triangles.push([0, 1, 7]);
        assert!(DeviceMesh::from_mesh(&bad, DeviceScene::smoke_test(64)).is_err());
    }
}
