//! The landmark-free start on the device (`gpmm device-detect`): a photo made into the camera
//! frame a device would get, the data partition (the init file, then the frame:
//! `gpmm_core::format::detection`), the firmware run under QEMU, and its detection record read
//! back. [`host_detect`] runs the same core code on the host; [`compare`] says whether the two
//! agree to the bit.

use crate::detect::{DetectError, Detector};
use crate::device::fit::{figure, run_firmware, tagged_hex, DeviceFitError};
use gpmm_core::format::detection::{self, DetectCounts, DetectionFigures, Frame};
use gpmm_core::format::FormatError;
use gpmm_core::net::face::{bounded_reading, find_face, read_landmarks, record_parts, Detection};
use gpmm_core::net::face_box::{is_face, FaceBox};
use gpmm_core::net::NetScratch;
use gpmm_core::profile::DeviceProfile;
use image::RgbImage;
use serde::Serialize;
use std::path::Path;

/// The frame a device's camera gives by default (QQVGA): width.
pub const DEFAULT_FRAME_WIDTH: u32 = 160;
/// The default frame's height.
pub const DEFAULT_FRAME_HEIGHT: u32 = 120;

/// Why a device detection failed.
#[derive(Debug, thiserror::Error)]
pub enum DeviceDetectError {
    /// The init file was refused.
    #[error(transparent)]
    Init(#[from] DetectError),
    /// The frame could not be written.
    #[error("the detection frame could not be written: {0}")]
    Frame(FormatError),
    /// The partition does not fit.
    #[error("the data partition needs {need} bytes (init file + frame); the {profile} partition holds {have}")]
    TooLarge {
        /// Bytes needed.
        need: usize,
        /// Bytes available.
        have: usize,
        /// Profile name.
        profile: &'static str,
    },
    /// Running the firmware or reading its log failed.
    #[error(transparent)]
    Firmware(#[from] DeviceFitError),
    /// The firmware's detection record is malformed.
    #[error("the firmware's detection record is malformed: {0}")]
    Record(FormatError),
}

/// Where a frame lies in the photo it was cut from: photo px = frame px × `scale` + `offset`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FrameMapping {
    /// Photo pixels per frame pixel.
    pub scale: f32,
    /// Photo position of the frame's top-left corner.
    pub offset: [f32; 2],
}

impl FrameMapping {
    /// A frame position in the photo.
    pub fn to_photo(&self, p: [f32; 2]) -> [f32; 2] {
        [p[0] * self.scale + self.offset[0], p[1] * self.scale + self.offset[1]]
    }
}

/// The `width × height` frame a camera aimed at `photo` would give: the photo scaled to cover the
/// frame (aspect ratio kept, bilinear), the overhanging sides cut off equally.
pub fn camera_frame(photo: &RgbImage, width: u32, height: u32) -> (RgbImage, FrameMapping) {
    let (pw, ph) = photo.dimensions();
    let s = (width as f32 / pw as f32).max(height as f32 / ph as f32);
    let (sw, sh) = (((pw as f32 * s).round() as u32).max(width), ((ph as f32 * s).round() as u32).max(height));
    let scaled = image::imageops::resize(photo, sw, sh, image::imageops::FilterType::Triangle);
    let (x0, y0) = ((sw - width) / 2, (sh - height) / 2);
    let frame = image::imageops::crop_imm(&scaled, x0, y0, width, height).to_image();
    let (kx, ky) = (pw as f32 / sw as f32, ph as f32 / sh as f32);
    (frame, FrameMapping { scale: 0.5 * (kx + ky), offset: [x0 as f32 * kx, y0 as f32 * ky] })
}

/// The frame section (`GPDF`) for `frame` with the detector's settings.
pub fn frame_bytes(frame: &RgbImage, min_score: f32, refine: u32) -> Result<Vec<u8>, DeviceDetectError> {
    let (width, height) = frame.dimensions();
    let f = Frame { width, height, min_score, refine, rgb: frame.as_raw() };
    let mut out = vec![0u8; detection::frame_len(width, height)];
    let n = detection::write_frame(&mut out, &f).map_err(DeviceDetectError::Frame)?;
    out.truncate(n);
    Ok(out)
}

/// The data partition: the init file, zero padding to 16 bytes, the frame; refused if larger
/// than `profile`'s partition.
pub fn partition_bytes(init: &[u8], frame: &[u8], profile: &DeviceProfile) -> Result<Vec<u8>, DeviceDetectError> {
    let mut p = init.to_vec();
    p.resize(detection::frame_offset(init.len()), 0);
    p.extend_from_slice(frame);
    if p.len() > profile.partition_bytes {
        return Err(DeviceDetectError::TooLarge { need: p.len(), have: profile.partition_bytes, profile: profile.name });
    }
    Ok(p)
}

/// The host's run of the device's detection: the finder's box, and the detection if its score
/// reaches `min_score` (the core's `find_face` and `read_landmarks` with the device's
/// [`bounded_reading`], as the firmware runs them).
pub fn host_detect(
    init: &mut Detector,
    frame: &RgbImage,
    min_score: f32,
    refine: u32,
) -> Result<(FaceBox, Option<Detection>), DeviceDetectError> {
    let (w, h) = (frame.width() as usize, frame.height() as usize);
    let file = init.file().map_err(DetectError::Run)?;
    let mut scratch: Box<NetScratch<{ crate::detect::HOST_NET_SCRATCH }>> = Box::default();
    let face = find_face(&file, frame.as_raw(), w, h, &mut scratch).map_err(DetectError::Run)?;
    if !is_face(&face, min_score) {
        return Ok((face, None));
    }
    let reading = bounded_reading(&face, refine as usize, file.landmarks);
    let det = read_landmarks(&file, frame.as_raw(), w, h, face, reading, &mut scratch).map_err(DetectError::Run)?;
    Ok((face, Some(det)))
}

/// Record bytes for a detection with `counts` (the host's run gets the device's counts, so two
/// records are byte-identical exactly when the detections are bit-identical).
pub fn record_bytes(face: &FaceBox, det: Option<&Detection>, counts: &DetectCounts) -> Result<Vec<u8>, FormatError> {
    let (figures, lm, light) = record_parts(face, det);
    let mut out = vec![0u8; detection::record_len(lm.len(), light.len())];
    let n = detection::write_record(&mut out, &figures, counts, lm, light)?;
    out.truncate(n);
    Ok(out)
}

/// What the firmware reported (the JSON of `gpmm device-detect`).
#[derive(Debug, Clone, Serialize)]
pub struct DeviceDetectReport {
    /// Device profile.
    pub profile: String,
    /// The box, the pose and whether a face was found.
    pub detection: DetectionFigures,
    /// Landmarks in the frame (px).
    pub landmarks_px: Vec<[f32; 2]>,
    /// Light values as the initializer reads them.
    pub light: Vec<f32>,
    /// The device's counts (instructions of the finder and the initializer, stack, sizes).
    pub counts: DetectCounts,
    /// Instructions of the finder and the initializer together.
    pub instructions_networks: u64,
    /// Seconds of the whole detection at 168 MHz, one instruction per cycle.
    pub seconds_at_168mhz: f64,
    /// Flash used by the program (text + data), bytes.
    pub flash_bytes: u64,
    /// Static RAM (data + bss), bytes.
    pub ram_static_bytes: u64,
    /// Static RAM + the stack peak of the whole run.
    pub ram_total_bytes: u64,
    /// The profile's RAM.
    pub ram_budget_bytes: u64,
    /// The record as the firmware logged it.
    #[serde(skip)]
    pub record: Vec<u8>,
}

/// Reads the report out of the firmware's `GPDR` lines and run.sh's `GPMM_FIGURES` line.
pub fn parse_report(profile: &str, log: &str) -> Result<DeviceDetectReport, DeviceDetectError> {
    let record = tagged_hex(log, "GPDR ").ok_or(DeviceFitError::Missing("detection record (GPDR lines)"))?;
    let r = detection::parse_record(&record).map_err(DeviceDetectError::Record)?;
    let lm: Vec<f32> = r.landmarks.iter().collect();
    let c = r.counts;
    let ram_static_bytes = figure(log, "ram_static_bytes")?;
    let stack = u64::from(c.stack_peak_bytes).max(figure(log, "stack_peak_bytes").unwrap_or(0));
    Ok(DeviceDetectReport {
        profile: profile.to_string(),
        detection: r.figures,
        landmarks_px: lm.chunks_exact(2).map(|p| [p[0], p[1]]).collect(),
        light: r.light.iter().collect(),
        counts: c,
        instructions_networks: c.instructions_finder + c.instructions_initializer,
        seconds_at_168mhz: c.instructions_total as f64 / 168e6,
        flash_bytes: figure(log, "flash_bytes")?,
        ram_static_bytes,
        ram_total_bytes: ram_static_bytes + stack,
        ram_budget_bytes: figure(log, "ram_budget_bytes")?,
        record,
    })
}

/// How the host's detection compares with the device's.
#[derive(Debug, Clone, Serialize)]
pub struct Parity {
    /// Every value (found, box, score, angles, landmarks, light) has the same bits.
    pub bit_identical: bool,
    /// Largest distance between a host and a device landmark (px; 0 when both found none).
    pub max_landmark_difference_px: f32,
    /// The host's box and pose.
    pub host: DetectionFigures,
}

/// Compares the device's report with the host's run on the same frame.
pub fn compare(report: &DeviceDetectReport, face: &FaceBox, det: Option<&Detection>) -> Result<Parity, FormatError> {
    let host = record_bytes(face, det, &report.counts)?;
    let figures = detection::parse_record(&host)?.figures;
    let host_lm = det.map_or(&[][..], |d| &d.landmarks[..]);
    let max = if host_lm.len() == report.landmarks_px.len() {
        host_lm.iter().zip(&report.landmarks_px).map(|(p, q)| (p[0] - q[0]).hypot(p[1] - q[1])).fold(0.0f32, f32::max)
    } else {
        f32::INFINITY
    };
    Ok(Parity { bit_identical: host == report.record, max_landmark_difference_px: max, host: figures })
}

/// Writes the partition to `path` and runs the firmware on it (`run.sh --profile P --data FILE`).
pub fn run_detection(profile: &str, partition: &[u8], path: &Path, timeout_s: u32) -> Result<DeviceDetectReport, DeviceDetectError> {
    std::fs::write(path, partition).map_err(|e| DeviceFitError::Io(path.display().to_string(), e))?;
    let log = run_firmware(profile, path, timeout_s)?;
    parse_report(profile, &log)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_camera_frame_keeps_the_aspect_ratio_and_maps_back() {
        let photo = RgbImage::from_fn(400, 400, |x, y| image::Rgb([(x / 2) as u8, (y / 2) as u8, 7]));
        let (frame, map) = camera_frame(&photo, 160, 120);
        assert_eq!(frame.dimensions(), (160, 120));
        // 400 -> 160 wide: 2.5 photo px per frame px; 160 rows scaled, 20 cut at the top.
        assert_eq!(map, FrameMapping { scale: 2.5, offset: [0.0, 50.0] });
        assert_eq!(map.to_photo([80.0, 60.0]), [200.0, 200.0]);
        let p = frame.get_pixel(80, 60).0;
        assert!((i32::from(p[0]) - 100).abs() <= 2 && (i32::from(p[1]) - 100).abs() <= 2, "{p:?}");
    }

    #[test]
    fn the_record_is_read_back_from_hex_lines() {
        let face = FaceBox { cx: 80.0, cy: 60.0, size: 30.0, score: 0.25, looks: 1 };
        let counts = DetectCounts { instructions_finder: 5, instructions_total: 9, stack_peak_bytes: 100, ..DetectCounts::default() };
        let rec = record_bytes(&face, None, &counts).unwrap();
        let hex: String = rec.iter().map(|b| format!("{b:02x}")).collect();
        let log = format!(
            "INFO  GPDR {}\nINFO  GPDR {}\nGPMM_FIGURES {{\"flash_bytes\": 1, \"ram_static_bytes\": 200, \"ram_budget_bytes\": 300, \"stack_peak_bytes\": 120}}",
            &hex[..40],
            &hex[40..]
        );
        let r = parse_report("m4f", &log).unwrap();
        assert!(!r.detection.found);
        assert_eq!((r.detection.score, r.counts.instructions_finder, r.ram_total_bytes), (0.25, 5, 320));
        assert!(compare(&r, &face, None).unwrap().bit_identical);
        let moved = FaceBox { cx: f32::from_bits(80f32.to_bits() + 1), ..face };
        assert!(!compare(&r, &moved, None).unwrap().bit_identical, "one ulp is a difference");
        let bad = log.replacen("GPDR 4750", "GPDR 4751", 1);
        assert!(matches!(parse_report("m4f", &bad), Err(DeviceDetectError::Record(_))));
    }
}
