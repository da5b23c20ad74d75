//! The fit input in the data partition, after the model blob: what a camera and a landmark
//! detector would deliver on a board (the target image and its 68 landmarks), plus the seed
//! and step counts of the fit. Read in place.
//!
//! Layout (written by `gpmm_host::device_fit`, documented in README.md; little-endian, at the
//! first 16-byte boundary after the blob, every field 4-byte aligned):
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `GPFI` |
//! | 4 | 4 | version (1) |
//! | 8 | 4 | image width `W` |
//! | 12 | 4 | image height `H` |
//! | 16 | 4 | landmark count `L` |
//! | 20 | 4 | landmark-chain steps |
//! | 24 | 4 | image-chain steps |
//! | 28 | 4 | shape components fitted |
//! | 32 | 4 | colour components fitted |
//! | 36 | 8 | seed (u64) |
//! | 44 | 4 | landmark σ as a fraction of the image side (f32) |
//! | 48 | 8·L | landmarks, `[f32; 2]` pixel coordinates (pixel centres at +0.5) |
//! | 48 + 8·L | 3·W·H | pixels, RGB8, row-major from the top-left, zero-padded to 4 bytes |
//! | end − 4 | 4 | CRC-32 of every byte before it |

use gpmm_core::checksum::crc32;

/// Section magic.
const MAGIC: [u8; 4] = *b"GPFI";
/// Layout version this firmware reads.
const VERSION: u32 = 1;
/// Bytes before the landmarks.
const HEADER_BYTES: usize = 48;

/// Why the fit input was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum InputError {
    /// Not the `GPFI` magic (or no fit input after the blob).
    BadMagic,
    /// A version this firmware does not read.
    BadVersion,
    /// Zero or oversized image or landmark count.
    BadSize,
    /// The sizes imply more bytes than the partition holds.
    Truncated,
    /// The CRC-32 does not match.
    Crc,
    /// The landmarks are not 4-byte aligned.
    Misaligned,
}

/// The fit input, borrowed from the partition.
pub struct FitInput<'a> {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Target landmarks (working-image pixels).
    pub landmarks: &'a [[f32; 2]],
    /// RGB8 pixels, row-major.
    pub pixels: &'a [[u8; 3]],
    /// Landmark-chain steps.
    pub landmark_steps: u32,
    /// Image-chain steps.
    pub image_steps: u32,
    /// Shape components fitted.
    pub shape_rank: u32,
    /// Colour components fitted.
    pub color_rank: u32,
    /// Seed of the chains.
    pub seed: u64,
    /// Landmark σ (fraction of the image side).
    pub landmark_sigma: f32,
}

fn u32_at(b: &[u8], at: usize) -> Result<u32, InputError> {
    let w: [u8; 4] = b.get(at..at + 4).and_then(|s| s.try_into().ok()).ok_or(InputError::Truncated)?;
    Ok(u32::from_le_bytes(w))
}

/// Reads and checks the fit input at the start of `bytes` (the rest of the partition may follow).
pub fn parse(bytes: &[u8], max_side: u32, max_landmarks: usize) -> Result<FitInput<'_>, InputError> {
    if bytes.get(..4) != Some(&MAGIC[..]) {
        return Err(InputError::BadMagic);
    }
    if u32_at(bytes, 4)? != VERSION {
        return Err(InputError::BadVersion);
    }
    let (width, height, count) = (u32_at(bytes, 8)?, u32_at(bytes, 12)?, u32_at(bytes, 16)? as usize);
    if width == 0 || height == 0 || width > max_side || height > max_side || count == 0 || count > max_landmarks {
        return Err(InputError::BadSize);
    }
    let pixel_bytes = 3 * width as usize * height as usize;
    let lm_end = HEADER_BYTES + 8 * count;
    let px_end = lm_end + pixel_bytes;
    let body = (px_end + 3) & !3;
    let total = body + 4;
    let all = bytes.get(..total).ok_or(InputError::Truncated)?;
    let head = all.get(..body).ok_or(InputError::Truncated)?;
    if crc32(head) != u32_at(all, body)? {
        return Err(InputError::Crc);
    }
    let lm_bytes = all.get(HEADER_BYTES..lm_end).ok_or(InputError::Truncated)?;
    let landmarks: &[[f32; 2]] = bytemuck::try_cast_slice(lm_bytes).map_err(|_| InputError::Misaligned)?;
    let px_bytes = all.get(lm_end..px_end).ok_or(InputError::Truncated)?;
    let pixels: &[[u8; 3]] = bytemuck::try_cast_slice(px_bytes).map_err(|_| InputError::Truncated)?;
    let seed = u64::from(u32_at(all, 36)?) | (u64::from(u32_at(all, 40)?) << 32);
    Ok(FitInput {
        width,
        height,
        landmarks,
        pixels,
        landmark_steps: u32_at(all, 20)?,
        image_steps: u32_at(all, 24)?,
        shape_rank: u32_at(all, 28)?,
        color_rank: u32_at(all, 32)?,
        seed,
        landmark_sigma: f32::from_bits(u32_at(all, 44)?),
    })
}
