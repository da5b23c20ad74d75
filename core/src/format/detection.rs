//! A detection job and its result: the camera frame a device runs the landmark-free start on
//! (`GPDF`, placed after the init file in the data partition) and the detection it reports
//! (`GPDR`, logged by the firmware as hex lines and read back by the host with this same code).
//!
//! Frame layout, version 1 (little-endian; offsets in bytes):
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `GPDF` |
//! | 4 | 4 | version (`u32`, 1) |
//! | 8 | 4 | width `W` (1..=[`MAX_FRAME_SIDE`]) |
//! | 12 | 4 | height `H` (1..=[`MAX_FRAME_SIDE`]) |
//! | 16 | 4 | minimum finder score (`f32`, 0..=1; below it no face is read) |
//! | 20 | 4 | refinement passes of the initializer (`u32`, 0..=[`MAX_REFINE`]) |
//! | 24 | 3 W H | pixels, RGB8, row-major from the top-left, zero padding to 4 bytes |
//! | end − 4 | 4 | CRC-32 of every byte before it |
//!
//! Record layout, version 1:
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `GPDR` |
//! | 4 | 4 | version (`u32`, 1) |
//! | 8 | 4 | found (`u32`, 0 or 1) |
//! | 12 | 4 | landmarks `L` (0..=68; 0 when nothing was found) |
//! | 16 | 4 | light values `K` (0..=27; 0 when nothing was found) |
//! | 20 | 28 | [`DetectionFigures`]: box centre x, y, size (px), score, yaw, pitch, roll: 7 × `f32` |
//! | 48 | 72 | [`DetectCounts`]: 4 × `u64` instructions, then 10 × `u32` |
//! | 120 | 8 L | landmarks `[f32; 2]` (frame px) |
//! | … | 4 K | light values |
//! | end − 4 | 4 | CRC-32 of every byte before it |

use super::bytes::{check_crc, Reader, Writer};
use super::fit_record::F32s;
use super::FormatError;

/// Magic of the frame.
pub const FRAME_MAGIC: [u8; 4] = *b"GPDF";
/// Magic of the record.
pub const RECORD_MAGIC: [u8; 4] = *b"GPDR";
/// The layout version of both, written and read.
pub const VERSION: u32 = 1;
/// Bytes of the frame before its pixels.
pub const FRAME_HEADER_BYTES: usize = 24;
/// Largest frame side.
pub const MAX_FRAME_SIDE: u32 = 4096;
/// Most refinement passes a frame may ask for.
pub const MAX_REFINE: u32 = 8;
/// Most landmarks a record holds.
pub const MAX_RECORD_LANDMARKS: usize = 68;
/// Most light values a record holds.
pub const MAX_RECORD_LIGHT: usize = 27;
/// Bytes of the record before its arrays.
pub const RECORD_HEADER_BYTES: usize = 20 + 28 + 72;
/// Where the frame starts after an init file of `init_len` bytes in the data partition.
pub const fn frame_offset(init_len: usize) -> usize {
    init_len.next_multiple_of(16)
}

/// A frame borrowed from its bytes.
#[derive(Debug, Clone, Copy)]
pub struct Frame<'a> {
    /// Width (px).
    pub width: u32,
    /// Height (px).
    pub height: u32,
    /// Finder score below which no face is read.
    pub min_score: f32,
    /// Extra passes of the initializer on re-centred crops.
    pub refine: u32,
    /// RGB8 pixels, row-major, `3 W H` bytes.
    pub rgb: &'a [u8],
}

/// Bytes of a frame of this size.
pub const fn frame_len(width: u32, height: u32) -> usize {
    FRAME_HEADER_BYTES + (3 * width as usize * height as usize).next_multiple_of(4) + 4
}

/// Writes a frame into `out` (at least [`frame_len`] bytes); returns the bytes written.
pub fn write_frame(out: &mut [u8], frame: &Frame<'_>) -> Result<usize, FormatError> {
    check_frame_header(frame.width, frame.height, frame.min_score, frame.refine)?;
    if frame.rgb.len() != 3 * frame.width as usize * frame.height as usize {
        return Err(FormatError::BadField("pixel count"));
    }
    let mut w = Writer::new(out);
    w.bytes(&FRAME_MAGIC)?;
    w.u32(VERSION)?;
    w.u32(frame.width)?;
    w.u32(frame.height)?;
    w.f32(frame.min_score)?;
    w.u32(frame.refine)?;
    w.bytes(frame.rgb)?;
    w.align4()?;
    w.finish_crc()
}

fn check_frame_header(width: u32, height: u32, min_score: f32, refine: u32) -> Result<(), FormatError> {
    if width == 0 || width > MAX_FRAME_SIDE {
        return Err(FormatError::BadField("frame width"));
    }
    if height == 0 || height > MAX_FRAME_SIDE {
        return Err(FormatError::BadField("frame height"));
    }
    if !(0.0..=1.0).contains(&min_score) {
        return Err(FormatError::BadField("minimum score"));
    }
    if refine > MAX_REFINE {
        return Err(FormatError::BadField("refinement passes"));
    }
    Ok(())
}

/// Reads and checks the frame at the start of `bytes` (more bytes may follow).
pub fn parse_frame(bytes: &[u8]) -> Result<Frame<'_>, FormatError> {
    let mut r = Reader::after_header(bytes, FRAME_MAGIC, VERSION)?;
    let (width, height, min_score, refine) = (r.u32()?, r.u32()?, r.f32()?, r.u32()?);
    check_frame_header(width, height, min_score, refine)?;
    check_crc(bytes, frame_len(width, height) - 4)?;
    let rgb = r.take(3 * width as usize * height as usize)?;
    Ok(Frame { width, height, min_score, refine, rgb })
}

/// What the detector found: the finder's box and the initializer's pose.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct DetectionFigures {
    /// Whether the finder's score reached the frame's minimum (else nothing else is meaningful).
    pub found: bool,
    /// Box centre, x (frame px).
    pub cx: f32,
    /// Box centre, y (frame px).
    pub cy: f32,
    /// Box side (frame px).
    pub size: f32,
    /// The finder's score, 0..1.
    pub score: f32,
    /// Yaw, pitch, roll (radians).
    pub angles: [f32; 3],
}

/// Where the device's instructions went, and what it was given.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct DetectCounts {
    /// Instructions to parse the init file and the frame.
    pub instructions_parse: u64,
    /// Instructions of the finder (letterboxing the frame included).
    pub instructions_finder: u64,
    /// Instructions of the initializer, every pass (cutting the crops included).
    pub instructions_initializer: u64,
    /// Instructions from reading the partition to the end of the detection.
    pub instructions_total: u64,
    /// Stack high-water mark after the detection (bytes).
    pub stack_peak_bytes: u32,
    /// Bytes of each of the two activation buffers the device gave the networks.
    pub scratch_bytes: u32,
    /// Bytes of each buffer the init file's networks need.
    pub scratch_needed_bytes: u32,
    /// The init file's bytes.
    pub init_bytes: u32,
    /// The data partition's bytes.
    pub partition_bytes: u32,
    /// Multiply-accumulates of one finder run.
    pub finder_macs: u32,
    /// Multiply-accumulates of one initializer run.
    pub initializer_macs: u32,
    /// Initializer runs (1 + refinement passes; 0 when nothing was found).
    pub initializer_runs: u32,
    /// Frame width.
    pub frame_width: u32,
    /// Frame height.
    pub frame_height: u32,
}

/// A detection record: written by [`write_record`], read by [`parse_record`] as a view.
#[derive(Debug, Clone, Copy)]
pub struct DetectionRecord<'a> {
    /// The box and the pose.
    pub figures: DetectionFigures,
    /// The device's counts.
    pub counts: DetectCounts,
    /// Landmarks, x and y interleaved (frame px).
    pub landmarks: F32s<'a>,
    /// Light values as the initializer reads them.
    pub light: F32s<'a>,
}

/// Bytes of a record with these counts.
pub const fn record_len(landmarks: usize, light: usize) -> usize {
    RECORD_HEADER_BYTES + 4 * (2 * landmarks + light) + 4
}

/// Writes a record into `out` (at least [`record_len`] bytes); returns the bytes written.
pub fn write_record(
    out: &mut [u8],
    figures: &DetectionFigures,
    counts: &DetectCounts,
    landmarks: &[[f32; 2]],
    light: &[f32],
) -> Result<usize, FormatError> {
    if landmarks.len() > MAX_RECORD_LANDMARKS {
        return Err(FormatError::TooMany("landmarks"));
    }
    if light.len() > MAX_RECORD_LIGHT {
        return Err(FormatError::TooMany("light values"));
    }
    let mut w = Writer::new(out);
    w.bytes(&RECORD_MAGIC)?;
    w.u32(VERSION)?;
    w.u32(u32::from(figures.found))?;
    w.u32(landmarks.len() as u32)?;
    w.u32(light.len() as u32)?;
    let f = figures;
    w.f32s([f.cx, f.cy, f.size, f.score, f.angles[0], f.angles[1], f.angles[2]])?;
    let c = counts;
    for v in [c.instructions_parse, c.instructions_finder, c.instructions_initializer, c.instructions_total] {
        w.u64(v)?;
    }
    for v in [
        c.stack_peak_bytes,
        c.scratch_bytes,
        c.scratch_needed_bytes,
        c.init_bytes,
        c.partition_bytes,
        c.finder_macs,
        c.initializer_macs,
        c.initializer_runs,
        c.frame_width,
        c.frame_height,
    ] {
        w.u32(v)?;
    }
    w.f32s(landmarks.iter().flatten().chain(light).copied())?;
    w.finish_crc()
}

/// Reads and checks the record at the start of `bytes`.
pub fn parse_record(bytes: &[u8]) -> Result<DetectionRecord<'_>, FormatError> {
    let mut r = Reader::after_header(bytes, RECORD_MAGIC, VERSION)?;
    let found = match r.u32()? {
        0 => false,
        1 => true,
        _ => return Err(FormatError::BadField("found")),
    };
    let (l, k) = (r.u32()? as usize, r.u32()? as usize);
    if l > MAX_RECORD_LANDMARKS {
        return Err(FormatError::BadField("landmark count"));
    }
    if k > MAX_RECORD_LIGHT {
        return Err(FormatError::BadField("light count"));
    }
    check_crc(bytes, record_len(l, k) - 4)?;
    let mut v = [0.0f32; 7];
    r.f32s(&mut v)?;
    let [cx, cy, size, score, yaw, pitch, roll] = v;
    let figures = DetectionFigures { found, cx, cy, size, score, angles: [yaw, pitch, roll] };
    let counts = DetectCounts {
        instructions_parse: r.u64()?,
        instructions_finder: r.u64()?,
        instructions_initializer: r.u64()?,
        instructions_total: r.u64()?,
        stack_peak_bytes: r.u32()?,
        scratch_bytes: r.u32()?,
        scratch_needed_bytes: r.u32()?,
        init_bytes: r.u32()?,
        partition_bytes: r.u32()?,
        finder_macs: r.u32()?,
        initializer_macs: r.u32()?,
        initializer_runs: r.u32()?,
        frame_width: r.u32()?,
        frame_height: r.u32()?,
    };
    let landmarks = F32s::new(r.take(8 * l)?);
    let light = F32s::new(r.take(4 * k)?);
    Ok(DetectionRecord { figures, counts, landmarks, light })
}
