//! The landmark-free fit job (`GPFF`): a device fits a face it finds itself in a camera frame.
//! The data partition then holds four sections, each at the first 16-byte boundary after the
//! previous one ([`next_section`]):
//!
//! 1. the model blob (`GPMB`, docs/blob-format.md);
//! 2. this job: the fit's working side, the seed and the whole fit settings (postcard);
//! 3. the init file (`GPMI`, docs/init-format.md): the finder and the initializer;
//! 4. the camera frame (`GPDF`, [`super::detection`]) with the detector's minimum score and passes.
//!
//! The firmware tells this from a fit with landmarks by the four bytes after the blob (`GPFF`
//! here, `GPFI` there). Job layout, version 1 (little-endian; offsets in bytes):
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `GPFF` |
//! | 4 | 4 | version (`u32`, 1) |
//! | 8 | 4 | working image side `S` (px, 16..=the device's `frame_fit_side`) |
//! | 12 | 4 | settings payload bytes `P` (at most [`SETTINGS_CAPACITY`]) |
//! | 16 | 8 | seed (`u64`) |
//! | 24 | P | settings, postcard-encoded, zero padding to 4 bytes |
//! | end − 4 | 4 | CRC-32 of every byte before it |

use super::bytes::{check_crc, Reader, Writer};
use super::fit_input::SETTINGS_CAPACITY;
use super::FormatError;
use serde::{de::DeserializeOwned, Serialize};

/// Magic bytes.
pub const MAGIC: [u8; 4] = *b"GPFF";
/// The layout version written and read.
pub const VERSION: u32 = 5;
/// Bytes before the settings payload.
pub const HEADER_BYTES: usize = 24;
/// Smallest working side.
pub const MIN_SIDE: u32 = 16;

/// Where the next section starts after one that ends at `end` (the partition's 16-byte rule).
pub const fn next_section(end: usize) -> usize {
    end.next_multiple_of(16)
}

/// A job read from its bytes.
#[derive(Debug, Clone)]
pub struct FrameFitJob<S> {
    /// Side of the square working image the crop is resampled to (px).
    pub side: u32,
    /// Seed of the chains.
    pub seed: u64,
    /// The fit settings (the landmark σ is the initializer's, `fit::INIT_LANDMARK_SIGMA` by default).
    pub settings: S,
    /// Bytes of the job, CRC included.
    pub len: usize,
}

/// A buffer length that holds any job (the writer says the exact length).
pub const fn buffer_len() -> usize {
    HEADER_BYTES + SETTINGS_CAPACITY + 4
}

/// Writes a job into `out` (see [`buffer_len`]); returns the bytes written.
pub fn write<S: Serialize>(out: &mut [u8], side: u32, seed: u64, settings: &S) -> Result<usize, FormatError> {
    if side < MIN_SIDE {
        return Err(FormatError::BadField("working side"));
    }
    let payload = out.get_mut(HEADER_BYTES..).ok_or(FormatError::BufferTooSmall { needed: buffer_len() })?;
    let cap = payload.len().min(SETTINGS_CAPACITY);
    let s = postcard::to_slice(settings, payload.get_mut(..cap).unwrap_or(&mut [])).map_err(|_| FormatError::Payload)?.len();
    let mut w = Writer::new(out);
    w.bytes(&MAGIC)?;
    w.u32(VERSION)?;
    w.u32(side)?;
    w.u32(s as u32)?;
    w.u64(seed)?;
    w.advance(s)?;
    w.align4()?;
    w.finish_crc()
}

/// Reads and checks the job at the start of `bytes` (more bytes may follow), for working sides of
/// at most `max_side` pixels.
pub fn parse<S: DeserializeOwned>(bytes: &[u8], max_side: u32) -> Result<FrameFitJob<S>, FormatError> {
    let mut r = Reader::after_header(bytes, MAGIC, VERSION)?;
    let (side, s, seed) = (r.u32()?, r.u32()? as usize, r.u64()?);
    if !(MIN_SIDE..=max_side).contains(&side) {
        return Err(FormatError::BadField("working side"));
    }
    if s > SETTINGS_CAPACITY {
        return Err(FormatError::BadField("settings size"));
    }
    let body = HEADER_BYTES + s.next_multiple_of(4);
    check_crc(bytes, body)?;
    let settings = postcard::from_bytes(r.take(s)?).map_err(|_| FormatError::Payload)?;
    Ok(FrameFitJob { side, seed, settings, len: body + 4 })
}
