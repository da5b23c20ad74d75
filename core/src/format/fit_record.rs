//! The fit record (`GPFR`): a fit's result as the device reports it, read back by the host with
//! this same code (the firmware logs it as hex; `gpmm device-fit` decodes it).
//!
//! Layout, version 2 (little-endian, 4-byte fields; offsets in bytes):
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `GPFR` |
//! | 4 | 4 | version (`u32`, 2) |
//! | 8 | 4 | shape coefficients `Ks` |
//! | 12 | 4 | colour coefficients `Kc` |
//! | 16 | 4 | landmarks `L` |
//! | 20 | 88 | [`FitFigures`]: 14 × `f32`, `u32` covered pixels, then the pose's spread from the landmarks: 7 × `f32` |
//! | 108 | 104 | [`DeviceCounts`]: 8 × `u64` instructions, then 10 × `u32` |
//! | 212 | 108 | SH light, 9 × (r, g, b) `f32` |
//! | 320 | 4 (Ks + Kc + 2 L) | shape, colour coefficients, landmarks `[f32; 2]` (image px) |
//! | end − 4 | 4 | CRC-32 of every byte before it |
//!
//! Version 1 had no pose spread (its figures were 60 bytes); it is not read.

use super::bytes::{check_crc, Reader, Writer};
use super::FormatError;
use crate::render::light::SH_COEFFS;
use crate::render::ShLight;

/// Magic bytes.
pub const MAGIC: [u8; 4] = *b"GPFR";
/// The layout version written and read.
pub const VERSION: u32 = 2;
/// Bytes before the light.
const FIXED_BYTES: usize = 20 + 88 + 104;
/// Bytes before the coefficient arrays.
pub const HEADER_BYTES: usize = FIXED_BYTES + 12 * SH_COEFFS;

/// The fit's figures: pose, camera and how well it explains the image and the landmarks.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct FitFigures {
    /// Yaw (radians).
    pub yaw: f32,
    /// Pitch (radians).
    pub pitch: f32,
    /// Roll (radians).
    pub roll: f32,
    /// Focal length (px).
    pub focal: f32,
    /// Translation (mm).
    pub translation: [f32; 3],
    /// Best log posterior of the image chain.
    pub log_posterior: f32,
    /// Image log-likelihood ratio of the fit.
    pub log_likelihood: f32,
    /// Landmark log-likelihood of the fit.
    pub landmark_log_likelihood: f32,
    /// Landmark RMSE (px).
    pub landmark_rmse_px: f32,
    /// Colour RMSE over the covered pixels.
    pub pixel_rmse: f32,
    /// Acceptance rate of the landmark chain.
    pub acceptance_landmark_chain: f32,
    /// Acceptance rate of the image chain.
    pub acceptance_image_chain: f32,
    /// Pixels the fitted model covers.
    pub covered_pixels: u32,
    /// The pose's spread from the landmarks ([`crate::fit::pose_spread`], before any calibration
    /// factor): standard deviations of yaw, pitch, roll (radians); zero when not measured.
    pub angles_sd: [f32; 3],
    /// Its standard deviations of the translation (mm); zero when not measured.
    pub translation_sd: [f32; 3],
    /// The landmarks' residual σ it is scaled by (px); zero when not measured.
    pub landmark_residual_px: f32,
}

/// Where the device's instructions went, and what it was given.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct DeviceCounts {
    /// Instructions to parse the blob and the fit input.
    pub instructions_parse: u64,
    /// Instructions of the landmark chain.
    pub instructions_landmark_chain: u64,
    /// Instructions of the start's light solve and first render.
    pub instructions_light_and_start: u64,
    /// Instructions of the image chain.
    pub instructions_image_chain: u64,
    /// Landmark-chain instructions per step.
    pub instructions_per_landmark_step: u64,
    /// Image-chain instructions per step.
    pub instructions_per_image_step: u64,
    /// Instructions of the whole fit (after parsing).
    pub instructions_fit: u64,
    /// Instructions from reading the partition to the end of the fit.
    pub instructions_total: u64,
    /// Shape-instance recomputations.
    pub shape_updates: u32,
    /// Colour-instance recomputations.
    pub color_updates: u32,
    /// Stack high-water mark after the fit (bytes).
    pub stack_peak_bytes: u32,
    /// The blob's bytes.
    pub blob_bytes: u32,
    /// The data partition's bytes.
    pub partition_bytes: u32,
    /// Model vertices.
    pub model_vertices: u32,
    /// Model triangles.
    pub model_triangles: u32,
    /// Bits per basis value in the blob.
    pub bits: u32,
    /// Image width.
    pub image_width: u32,
    /// Image height.
    pub image_height: u32,
}

/// `f32`s stored little-endian in a record, read one by one (no alignment needed).
#[derive(Debug, Clone, Copy)]
pub struct F32s<'a>(&'a [u8]);

impl<'a> F32s<'a> {
    /// The values in `bytes` (4 each, little-endian).
    pub(crate) const fn new(bytes: &'a [u8]) -> Self {
        Self(bytes)
    }

    /// Number of values.
    pub fn len(&self) -> usize {
        self.0.len() / 4
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.0.len() < 4
    }

    /// The values in order.
    pub fn iter(&self) -> impl Iterator<Item = f32> + 'a {
        self.0.chunks_exact(4).filter_map(|c| c.try_into().ok().map(f32::from_le_bytes))
    }
}

/// A fit record: written by [`write()`] from the caller's arrays, read by [`parse`] as a view.
#[derive(Debug, Clone, Copy)]
pub struct FitRecord<'a> {
    /// The figures.
    pub figures: FitFigures,
    /// The device's counts.
    pub counts: DeviceCounts,
    /// The fitted light.
    pub light: ShLight,
    /// Shape coefficients.
    pub shape: F32s<'a>,
    /// Colour coefficients.
    pub color: F32s<'a>,
    /// Fitted landmarks, x and y interleaved (image px).
    pub landmarks: F32s<'a>,
}

/// Bytes of a record with these counts.
pub const fn encoded_len(shape: usize, color: usize, landmarks: usize) -> usize {
    HEADER_BYTES + 4 * (shape + color + 2 * landmarks) + 4
}

/// Writes a record into `out` (at least [`encoded_len`] bytes); returns the bytes written.
pub fn write(
    out: &mut [u8],
    figures: &FitFigures,
    counts: &DeviceCounts,
    light: &ShLight,
    shape: &[f32],
    color: &[f32],
    landmarks: &[[f32; 2]],
) -> Result<usize, FormatError> {
    let mut w = Writer::new(out);
    w.bytes(&MAGIC)?;
    w.u32(VERSION)?;
    for n in [shape.len(), color.len(), landmarks.len()] {
        w.u32(u32::try_from(n).map_err(|_| FormatError::BadField("count"))?)?;
    }
    let f = figures;
    w.f32s([f.yaw, f.pitch, f.roll, f.focal, f.translation[0], f.translation[1], f.translation[2]])?;
    w.f32s([f.log_posterior, f.log_likelihood, f.landmark_log_likelihood, f.landmark_rmse_px, f.pixel_rmse])?;
    w.f32s([f.acceptance_landmark_chain, f.acceptance_image_chain])?;
    w.u32(f.covered_pixels)?;
    w.f32s(f.angles_sd.iter().chain(&f.translation_sd).copied().chain([f.landmark_residual_px]))?;
    let c = counts;
    for v in [
        c.instructions_parse,
        c.instructions_landmark_chain,
        c.instructions_light_and_start,
        c.instructions_image_chain,
        c.instructions_per_landmark_step,
        c.instructions_per_image_step,
        c.instructions_fit,
        c.instructions_total,
    ] {
        w.u64(v)?;
    }
    for v in [
        c.shape_updates,
        c.color_updates,
        c.stack_peak_bytes,
        c.blob_bytes,
        c.partition_bytes,
        c.model_vertices,
        c.model_triangles,
        c.bits,
        c.image_width,
        c.image_height,
    ] {
        w.u32(v)?;
    }
    w.f32s(light.coeffs.iter().flatten().copied())?;
    w.f32s(shape.iter().chain(color).chain(landmarks.iter().flatten()).copied())?;
    w.finish_crc()
}

/// Reads and checks the record at the start of `bytes`.
pub fn parse(bytes: &[u8]) -> Result<FitRecord<'_>, FormatError> {
    let mut r = Reader::after_header(bytes, MAGIC, VERSION)?;
    let (ks, kc, l) = (r.u32()? as usize, r.u32()? as usize, r.u32()? as usize);
    if ks > 1 << 16 || kc > 1 << 16 || l > 1 << 16 {
        return Err(FormatError::BadField("count"));
    }
    check_crc(bytes, encoded_len(ks, kc, l) - 4)?;
    let mut v = [0.0f32; 14];
    r.f32s(&mut v)?;
    let [yaw, pitch, roll, focal, tx, ty, tz, log_posterior, log_likelihood, landmark_log_likelihood, landmark_rmse_px, pixel_rmse, acc_l, acc_i] =
        v;
    let figures = FitFigures {
        yaw,
        pitch,
        roll,
        focal,
        translation: [tx, ty, tz],
        log_posterior,
        log_likelihood,
        landmark_log_likelihood,
        landmark_rmse_px,
        pixel_rmse,
        acceptance_landmark_chain: acc_l,
        acceptance_image_chain: acc_i,
        covered_pixels: r.u32()?,
        angles_sd: [r.f32()?, r.f32()?, r.f32()?],
        translation_sd: [r.f32()?, r.f32()?, r.f32()?],
        landmark_residual_px: r.f32()?,
    };
    let counts = DeviceCounts {
        instructions_parse: r.u64()?,
        instructions_landmark_chain: r.u64()?,
        instructions_light_and_start: r.u64()?,
        instructions_image_chain: r.u64()?,
        instructions_per_landmark_step: r.u64()?,
        instructions_per_image_step: r.u64()?,
        instructions_fit: r.u64()?,
        instructions_total: r.u64()?,
        shape_updates: r.u32()?,
        color_updates: r.u32()?,
        stack_peak_bytes: r.u32()?,
        blob_bytes: r.u32()?,
        partition_bytes: r.u32()?,
        model_vertices: r.u32()?,
        model_triangles: r.u32()?,
        bits: r.u32()?,
        image_width: r.u32()?,
        image_height: r.u32()?,
    };
    let mut light = ShLight::zero();
    for c in light.coeffs.iter_mut() {
        for x in c.iter_mut() {
            *x = r.f32()?;
        }
    }
    let shape = F32s(r.take(4 * ks)?);
    let color = F32s(r.take(4 * kc)?);
    let landmarks = F32s(r.take(8 * l)?);
    Ok(FitRecord { figures, counts, light, shape, color, landmarks })
}
