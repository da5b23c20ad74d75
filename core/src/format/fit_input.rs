//! The fit input (`GPFI`): what a camera and a landmark detector deliver on a board (the target
//! image and its landmarks) plus the seed and the whole fit settings, read in place.
//!
//! The settings travel as a postcard payload of the caller's settings type (the core's
//! `FitSettings` in practice), so every setting the host uses reaches the device.
//! Layout (little-endian; offsets in bytes; docs/formats.md keeps the history of versions):
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `GPFI` |
//! | 4 | 4 | version (`u32`, [`VERSION`]) |
//! | 8 | 4 | image width `W` |
//! | 12 | 4 | image height `H` |
//! | 16 | 4 | landmark count `L` |
//! | 20 | 4 | settings payload bytes `S` (at most [`SETTINGS_CAPACITY`]) |
//! | 24 | 8 | seed (`u64`) |
//! | 32 | 16 | pixels the photo covers: `x0, y0, x1, y1` (`u32`, half-open; [`CoveredPixels`]) |
//! | 48 | S | settings, postcard-encoded, zero padding to 4 bytes |
//! | … | 8 L | landmarks `[f32; 2]`, pixel coordinates (pixel centres at +0.5) |
//! | … | 3 W H | pixels, RGB8, row-major from the top-left, zero padding to 4 bytes |
//! | end − 4 | 4 | CRC-32 of every byte before it |

use super::bytes::{check_crc, Reader, Writer};
use super::FormatError;
use crate::geometry::CoveredPixels;
use serde::{de::DeserializeOwned, Serialize};

/// Magic bytes.
pub const MAGIC: [u8; 4] = *b"GPFI";
/// The layout version written and read.
pub const VERSION: u32 = 11;
/// Bytes before the settings payload.
pub const HEADER_BYTES: usize = 48;
/// Largest settings payload.
pub const SETTINGS_CAPACITY: usize = 1024;

/// A fit input borrowed from its bytes, with its settings decoded.
#[derive(Debug, Clone)]
pub struct FitInput<'a, S> {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Seed of the chains.
    pub seed: u64,
    /// The pixels the photo covers (the rest of the crop lay past its edge).
    pub covered: CoveredPixels,
    /// The fit settings.
    pub settings: S,
    /// Target landmarks (image pixels).
    pub landmarks: &'a [[f32; 2]],
    /// RGB8 pixels, row-major.
    pub pixels: &'a [[u8; 3]],
}

/// A buffer length that holds any fit input of this size (the writer says the exact length).
pub fn buffer_len(width: u32, height: u32, landmarks: usize) -> usize {
    HEADER_BYTES + SETTINGS_CAPACITY + 8 * landmarks + (3 * width as usize * height as usize).next_multiple_of(4) + 4
}

/// Writes a fit input into `out` (see [`buffer_len`]); returns the bytes written.
#[allow(clippy::too_many_arguments)]
pub fn write<S: Serialize>(
    out: &mut [u8],
    width: u32,
    height: u32,
    seed: u64,
    covered: CoveredPixels,
    settings: &S,
    landmarks: &[[f32; 2]],
    pixels: &[[u8; 3]],
) -> Result<usize, FormatError> {
    if width == 0 || height == 0 || pixels.len() != width as usize * height as usize {
        return Err(FormatError::BadField("image size"));
    }
    if !covered.fits(width, height) {
        return Err(FormatError::BadField("covered pixels"));
    }
    let room = out.len();
    let payload = out.get_mut(HEADER_BYTES..).ok_or(FormatError::BufferTooSmall { needed: buffer_len(width, height, landmarks.len()) })?;
    let cap = payload.len().min(SETTINGS_CAPACITY);
    let s = postcard::to_slice(settings, payload.get_mut(..cap).unwrap_or(&mut [])).map_err(|_| FormatError::Payload)?.len();
    let mut w = Writer::new(out);
    w.bytes(&MAGIC)?;
    w.u32(VERSION)?;
    w.u32(width)?;
    w.u32(height)?;
    w.u32(landmarks.len() as u32)?;
    w.u32(s as u32)?;
    w.u64(seed)?;
    for v in [covered.x0, covered.y0, covered.x1, covered.y1] {
        w.u32(v)?;
    }
    w.advance(s)?;
    w.align4()?;
    w.f32s(landmarks.iter().flatten().copied())?;
    for p in pixels {
        w.bytes(p)?;
    }
    w.align4()?;
    let len = w.position() + 4;
    if len > room {
        return Err(FormatError::BufferTooSmall { needed: len });
    }
    w.finish_crc()
}

/// Reads and checks the fit input at the start of `bytes` (more bytes may follow), for images
/// of at most `max_side` pixels a side and at most `max_landmarks` landmarks.
///
/// # Examples
///
/// A fit input written by [`write()`] and read back; a size over the reader's limits and a
/// changed byte are refused:
///
/// ```
/// use gpmm_core::fit::FitSettings;
/// use gpmm_core::format::{fit_input, FormatError};
/// use gpmm_core::geometry::CoveredPixels;
///
/// // A 4 × 2 image, two landmarks and the default settings with shorter chains.
/// let pixels: Vec<[u8; 3]> = (0u8..8).map(|i| [30 * i, 100, 200]).collect();
/// let landmarks = [[0.5f32, 0.5], [3.5, 1.5]];
/// let settings = FitSettings::DEFAULT.with_steps(500, 50);
/// // Read in place: the landmarks are `f32`, so the buffer is 4-byte aligned (`u32` words).
/// let mut words = vec![0u32; fit_input::buffer_len(4, 2, 2).div_ceil(4)];
/// let bytes: &mut [u8] = bytemuck::cast_slice_mut(&mut words);
/// let n = fit_input::write(bytes, 4, 2, 7, CoveredPixels::whole(4, 2), &settings, &landmarks, &pixels)?;
///
/// let input: fit_input::FitInput<'_, FitSettings> = fit_input::parse(&bytes[..n], 128, 68)?;
/// assert_eq!((input.width, input.height, input.seed, input.settings), (4, 2, 7, settings));
/// assert_eq!((input.landmarks, input.pixels), (&landmarks[..], &pixels[..]));
/// let narrow = fit_input::parse::<FitSettings>(&bytes[..n], 2, 68);
/// assert_eq!(narrow.unwrap_err(), FormatError::BadField("image width"));
///
/// // The last pixel's blue byte changed (the CRC-32 follows it): refused, not read.
/// bytes[n - 5] ^= 0x01;
/// assert!(matches!(fit_input::parse::<FitSettings>(&bytes[..n], 128, 68), Err(FormatError::Crc { .. })));
/// # Ok::<(), FormatError>(())
/// ```
pub fn parse<S: DeserializeOwned>(bytes: &[u8], max_side: u32, max_landmarks: usize) -> Result<FitInput<'_, S>, FormatError> {
    let mut r = Reader::after_header(bytes, MAGIC, VERSION)?;
    let (width, height, count, s) = (r.u32()?, r.u32()?, r.u32()? as usize, r.u32()? as usize);
    let seed = r.u64()?;
    let covered = CoveredPixels { x0: r.u32()?, y0: r.u32()?, x1: r.u32()?, y1: r.u32()? };
    if width == 0 || width > max_side {
        return Err(FormatError::BadField("image width"));
    }
    if height == 0 || height > max_side {
        return Err(FormatError::BadField("image height"));
    }
    if count == 0 || count > max_landmarks {
        return Err(FormatError::BadField("landmark count"));
    }
    if s > SETTINGS_CAPACITY {
        return Err(FormatError::BadField("settings size"));
    }
    if !covered.fits(width, height) {
        return Err(FormatError::BadField("covered pixels"));
    }
    let body = HEADER_BYTES + s.next_multiple_of(4) + 8 * count + (3 * width as usize * height as usize).next_multiple_of(4);
    check_crc(bytes, body)?;
    let settings = postcard::from_bytes(r.take(s)?).map_err(|_| FormatError::Payload)?;
    r.align4()?;
    let landmarks = r.slice(count)?;
    let pixels = r.slice(width as usize * height as usize)?;
    Ok(FitInput { width, height, seed, covered, settings, landmarks, pixels })
}
