//! The interim device mesh in the data partition: a mesh instance plus its scene, read in place.
//!
//! The layout is written by `gpmm_host::device_mesh` and documented there and in README.md:
//! a 168-byte header (magic `GPDM`, version 1, header size, vertex count `N`, triangle count
//! `T`, image width and height, pose, camera, 9×3 SH light), then `N × [f32; 3]` positions,
//! `N × [f32; 3]` albedo, `T × [u16; 3]` triangles, zero padding to 4 bytes and a CRC-32 of
//! everything before it. All little-endian, every section 4-byte aligned.
//!
//! [`parse`] checks everything it can before anything is used (magic, version, header size,
//! counts against the partition and the firmware's buffers, CRC, alignment) and returns an
//! error, never panics; index ranges and non-finite values are checked by the core's vertex
//! stage and rasterizer.

use gpmm_core::checksum::crc32;
use gpmm_core::light::SH_COEFFS;
use gpmm_core::{Camera, Pose, ShLight, Vec3};

#[cfg(target_endian = "big")]
compile_error!("the device mesh is little-endian and read in place");

/// File magic.
const MAGIC: [u8; 4] = *b"GPDM";
/// Layout version this firmware reads.
const VERSION: u16 = 1;
/// Bytes before the positions.
const HEADER_BYTES: usize = 168;
/// Scene floats after the 20-byte fixed header: pose 6, camera 4, light 27.
const SCENE_FLOATS: usize = 6 + 4 + 3 * SH_COEFFS;

/// Whether `part` starts with the device mesh's magic (anything else is read as a model blob).
pub fn is_device_mesh(part: &[u8]) -> bool {
    part.get(..4) == Some(&MAGIC[..])
}

/// Why the partition's content was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum MeshError {
    /// Not the `GPDM` magic.
    BadMagic,
    /// A version this firmware does not read.
    BadVersion,
    /// Header size field is not 168.
    BadHeaderSize,
    /// Zero vertices or triangles.
    Empty,
    /// More vertices than the firmware's buffers hold.
    TooManyVertices,
    /// The counts imply more bytes than the partition holds.
    Truncated,
    /// The CRC-32 does not match.
    Crc,
    /// A section is not aligned for in-place reading.
    Misaligned,
}

/// A device mesh and its scene, borrowed from the partition.
pub struct DeviceMesh<'a> {
    /// Positions (mm).
    pub positions: &'a [Vec3],
    /// Albedo (linear RGB).
    pub albedo: &'a [Vec3],
    /// Triangles.
    pub triangles: &'a [[u16; 3]],
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Model pose.
    pub pose: Pose,
    /// Camera.
    pub camera: Camera,
    /// SH light.
    pub light: ShLight,
}

/// Element types every bit pattern of which is a valid value (no padding, no invalid values).
trait Plain: Sized {}
impl Plain for [f32; 3] {}
impl Plain for [u16; 3] {}

/// `bytes` as a slice of `T`, if it is aligned and a whole number of elements.
fn cast<T: Plain>(bytes: &[u8]) -> Option<&[T]> {
    // SAFETY: `T: Plain` is an array of f32 or u16: any bytes are a valid value and it has no
    // padding; `align_to` only yields properly aligned elements inside `bytes`.
    let (head, mid, tail) = unsafe { bytes.align_to::<T>() };
    (head.is_empty() && tail.is_empty()).then_some(mid)
}

fn u16_at(b: &[u8], o: usize) -> Option<u16> {
    Some(u16::from_le_bytes(b.get(o..o.checked_add(2)?)?.try_into().ok()?))
}

fn u32_at(b: &[u8], o: usize) -> Option<u32> {
    Some(u32::from_le_bytes(b.get(o..o.checked_add(4)?)?.try_into().ok()?))
}

/// Parses and validates the device mesh at the start of `part`, for buffers of `max_vertices`.
pub fn parse(part: &[u8], max_vertices: usize) -> Result<DeviceMesh<'_>, MeshError> {
    if part.get(..4) != Some(&MAGIC[..]) {
        return Err(MeshError::BadMagic);
    }
    if u16_at(part, 4).ok_or(MeshError::Truncated)? != VERSION {
        return Err(MeshError::BadVersion);
    }
    if usize::from(u16_at(part, 6).ok_or(MeshError::Truncated)?) != HEADER_BYTES {
        return Err(MeshError::BadHeaderSize);
    }
    let n = u32_at(part, 8).ok_or(MeshError::Truncated)? as usize;
    let t = u32_at(part, 12).ok_or(MeshError::Truncated)? as usize;
    let width = u32::from(u16_at(part, 16).ok_or(MeshError::Truncated)?);
    let height = u32::from(u16_at(part, 18).ok_or(MeshError::Truncated)?);
    if n == 0 || t == 0 {
        return Err(MeshError::Empty);
    }
    if n > max_vertices {
        return Err(MeshError::TooManyVertices);
    }
    // Lengths in u64-free checked arithmetic: a garbage count cannot wrap.
    let tri_start = n.checked_mul(24).and_then(|v| v.checked_add(HEADER_BYTES)).ok_or(MeshError::Truncated)?;
    let tri_end = t.checked_mul(6).and_then(|v| v.checked_add(tri_start)).ok_or(MeshError::Truncated)?;
    let body = tri_end.checked_next_multiple_of(4).ok_or(MeshError::Truncated)?;
    let total = body.checked_add(4).ok_or(MeshError::Truncated)?;
    let file = part.get(..total).ok_or(MeshError::Truncated)?;
    let stored = u32_at(file, body).ok_or(MeshError::Truncated)?;
    if crc32(file.get(..body).ok_or(MeshError::Truncated)?) != stored {
        return Err(MeshError::Crc);
    }

    let mut s = [0.0f32; SCENE_FLOATS];
    for (k, v) in s.iter_mut().enumerate() {
        *v = f32::from_bits(u32_at(file, 20 + 4 * k).ok_or(MeshError::Truncated)?);
    }
    let [yaw, pitch, roll, tx, ty, tz, focal, cx, cy, near, light @ ..] = s;
    let mut sh = ShLight::zero();
    for (c, v) in sh.coeffs.iter_mut().zip(light.chunks_exact(3)) {
        if let [r, g, b] = *v {
            *c = [r, g, b];
        }
    }

    let section = |a: usize, b: usize| file.get(a..b).ok_or(MeshError::Truncated);
    let pos_end = HEADER_BYTES + 12 * n; // < tri_start, checked above
    let positions = cast::<Vec3>(section(HEADER_BYTES, pos_end)?).ok_or(MeshError::Misaligned)?;
    let albedo = cast::<Vec3>(section(pos_end, tri_start)?).ok_or(MeshError::Misaligned)?;
    let triangles = cast::<[u16; 3]>(section(tri_start, tri_end)?).ok_or(MeshError::Misaligned)?;
    Ok(DeviceMesh {
        positions,
        albedo,
        triangles,
        width,
        height,
        pose: Pose { yaw, pitch, roll, translation: [tx, ty, tz] },
        camera: Camera { focal, principal: [cx, cy], near },
        light: sh,
    })
}
