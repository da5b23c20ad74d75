//! The device mesh (`GPDM`): one mesh instance plus the scene to render it in, read in place.
//!
//! The firmware renders it exactly as the host does from the same bytes (the render parity test).
//! Layout, version 1 (little-endian, no padding between fields; offsets in bytes):
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `GPDM` |
//! | 4 | 2 | version (`u16`, 1) |
//! | 6 | 2 | header size (`u16`, [`HEADER_BYTES`] = 168): where the positions start |
//! | 8 | 4 | vertex count `N` (`u32`, 1..=65,536) |
//! | 12 | 4 | triangle count `T` (`u32`, >= 1) |
//! | 16 | 2 | image width (`u16`, 1..=32,768) |
//! | 18 | 2 | image height (`u16`, 1..=32,768) |
//! | 20 | 24 | pose: yaw, pitch, roll (rad), translation x, y, z (mm), 6 × `f32` |
//! | 44 | 16 | camera: focal (px), principal x, y (px), near (mm), 4 × `f32` |
//! | 60 | 108 | SH light, 9 coefficients × (r, g, b), 27 × `f32`, coefficient-major |
//! | 168 | 12 N | positions `N × [f32; 3]` (mm) |
//! | 168 + 12 N | 12 N | albedo `N × [f32; 3]` (linear RGB) |
//! | 168 + 24 N | 6 T | triangles `T × [u16; 3]` (counter-clockwise seen from outside) |
//! | … | 0 or 2 | zero padding to 4 bytes |
//! | end − 4 | 4 | CRC-32 of every byte before it |
//!
//! Total [`encoded_len`]`(N, T)`; the cropped template (4,249 vertices, 8,352 triangles) takes
//! 152,260 bytes. [`parse`] checks magic, version, header size, counts, length, CRC, alignment and
//! every triangle index; the renderer refuses non-finite values.

use super::bytes::{check_crc, check_magic, Reader, Writer};
use super::FormatError;
use crate::geometry::Vec3;
use crate::render::light::SH_COEFFS;
use crate::render::raster::MAX_IMAGE_SIZE;
use crate::render::{Camera, Pose, ShLight};

/// Magic bytes.
pub const MAGIC: [u8; 4] = *b"GPDM";
/// The layout version written and read.
pub const VERSION: u16 = 1;
/// Bytes before the positions: fixed header (20) + pose (24) + camera (16) + light (108).
pub const HEADER_BYTES: usize = 168;
/// Most vertices (u16 indices).
pub const MAX_VERTICES: usize = 1 << 16;

/// What the device renders besides the mesh: image size, pose, camera and light.
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

/// A device mesh borrowed from its bytes (or from the caller's arrays, to write it).
#[derive(Debug, Clone, Copy)]
pub struct DeviceMeshView<'a> {
    /// Positions (mm).
    pub positions: &'a [Vec3],
    /// Albedo (linear RGB).
    pub albedo: &'a [Vec3],
    /// Triangles.
    pub triangles: &'a [[u16; 3]],
    /// The scene.
    pub scene: DeviceScene,
}

/// Whether `bytes` starts with the device mesh's magic.
pub fn is_device_mesh(bytes: &[u8]) -> bool {
    bytes.get(..4) == Some(&MAGIC[..])
}

/// Bytes of a device mesh with `n` vertices and `t` triangles.
pub const fn encoded_len(n: usize, t: usize) -> usize {
    (HEADER_BYTES + 24 * n + 6 * t).next_multiple_of(4) + 4
}

fn check_counts(n: usize, t: usize, width: u32, height: u32, max_vertices: usize) -> Result<(), FormatError> {
    if n == 0 || n > MAX_VERTICES {
        return Err(FormatError::BadField("vertex count"));
    }
    if n > max_vertices {
        return Err(FormatError::TooMany("vertices"));
    }
    if t == 0 || t > u32::MAX as usize / 8 {
        return Err(FormatError::BadField("triangle count"));
    }
    if width == 0 || width > MAX_IMAGE_SIZE {
        return Err(FormatError::BadField("image width"));
    }
    if height == 0 || height > MAX_IMAGE_SIZE {
        return Err(FormatError::BadField("image height"));
    }
    Ok(())
}

fn check_indices(triangles: &[[u16; 3]], n: usize) -> Result<(), FormatError> {
    if triangles.iter().flatten().any(|&i| usize::from(i) >= n) {
        return Err(FormatError::BadField("triangle index"));
    }
    Ok(())
}

/// Parses and validates the device mesh at the start of `bytes`, for buffers of `max_vertices`.
pub fn parse(bytes: &[u8], max_vertices: usize) -> Result<DeviceMeshView<'_>, FormatError> {
    check_magic(bytes, MAGIC)?;
    let mut r = Reader::new(bytes);
    r.take(4)?;
    let version = r.u16()?;
    if version != VERSION {
        return Err(FormatError::BadVersion { found: u32::from(version), supported: u32::from(VERSION) });
    }
    if usize::from(r.u16()?) != HEADER_BYTES {
        return Err(FormatError::BadField("header size"));
    }
    let n = r.u32()? as usize;
    let t = r.u32()? as usize;
    let width = u32::from(r.u16()?);
    let height = u32::from(r.u16()?);
    check_counts(n, t, width, height, max_vertices)?;
    let total = encoded_len(n, t);
    if bytes.len() < total {
        return Err(FormatError::Truncated { needed: total, available: bytes.len() });
    }
    check_crc(bytes, total - 4)?;
    let mut s = [0.0f32; 10 + 3 * SH_COEFFS];
    r.f32s(&mut s)?;
    let [yaw, pitch, roll, tx, ty, tz, focal, cx, cy, near, light @ ..] = s;
    let mut sh = ShLight::zero();
    for (c, v) in sh.coeffs.iter_mut().zip(light.chunks_exact(3)) {
        if let [r, g, b] = *v {
            *c = [r, g, b];
        }
    }
    let positions: &[Vec3] = r.slice(n)?;
    let albedo: &[Vec3] = r.slice(n)?;
    let triangles: &[[u16; 3]] = r.slice(t)?;
    check_indices(triangles, n)?;
    Ok(DeviceMeshView {
        positions,
        albedo,
        triangles,
        scene: DeviceScene {
            width,
            height,
            pose: Pose { yaw, pitch, roll, translation: [tx, ty, tz] },
            camera: Camera { focal, principal: [cx, cy], near },
            light: sh,
        },
    })
}

/// Writes `mesh` into `out` (at least [`encoded_len`] bytes); returns the bytes written.
pub fn write(mesh: &DeviceMeshView<'_>, out: &mut [u8]) -> Result<usize, FormatError> {
    let (n, t, s) = (mesh.positions.len(), mesh.triangles.len(), &mesh.scene);
    check_counts(n, t, s.width, s.height, MAX_VERTICES)?;
    if mesh.albedo.len() != n {
        return Err(FormatError::BadField("albedo count"));
    }
    check_indices(mesh.triangles, n)?;
    let mut w = Writer::new(out);
    w.bytes(&MAGIC)?;
    w.u16(VERSION)?;
    w.u16(HEADER_BYTES as u16)?;
    w.u32(n as u32)?;
    w.u32(t as u32)?;
    // Both sides are at most 2^15 (checked above).
    w.u16(s.width as u16)?;
    w.u16(s.height as u16)?;
    let (p, c) = (&s.pose, &s.camera);
    w.f32s([p.yaw, p.pitch, p.roll, p.translation[0], p.translation[1], p.translation[2]])?;
    w.f32s([c.focal, c.principal[0], c.principal[1], c.near])?;
    w.f32s(s.light.coeffs.iter().flatten().copied())?;
    w.f32s(mesh.positions.iter().chain(mesh.albedo).flatten().copied())?;
    for i in mesh.triangles.iter().flatten() {
        w.u16(*i)?;
    }
    w.align4()?;
    w.finish_crc()
}
