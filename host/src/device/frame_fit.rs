//! The landmark-free fit on the device (`gpmm device-fit BLOB IMAGE --init INIT`): the data
//! partition holds the blob, a fit job (`GPFF`: working side, seed, settings), the init file and
//! the camera frame (`gpmm_core::format::frame_fit`); the firmware finds the face, reads its
//! landmarks, cuts the working image around them and fits it. [`host_frame_fit`] runs the same
//! core path on the host (the core's finder and initializer, the core's crop
//! `gpmm_core::net::crop::crop_for_fit`, the core's standard fit on the blob); [`compare`] says
//! whether the device's detection and fit records are the host's to the bit.

use crate::detect::{DetectError, Detector, HOST_NET_SCRATCH};
use crate::device::detect::{self, DeviceDetectError, DeviceDetectReport};
use crate::device::fit::{self as dfit, host_fit_pixels, DeviceFitError, DeviceFitReport, DEVICE_KC, DEVICE_KS};
use crate::device::quantize::BlobBuf;
use gpmm_core::fit::CoveredPixels;
use gpmm_core::fit::{FitSettings, StandardFit};
use gpmm_core::format::fit_record::{self, DeviceCounts};
use gpmm_core::format::{frame_fit, FormatError};
use gpmm_core::net::crop::{crop_for_fit, fit_window};
use gpmm_core::net::face::{bounded_reading, find_face, read_landmarks, Detection};
use gpmm_core::net::face_box::{is_face, FaceBox};
use gpmm_core::net::resample::Window;
use gpmm_core::net::{NetError, NetScratch};
use gpmm_core::profile::DeviceProfile;
use image::RgbImage;
use serde::Serialize;

/// Why a landmark-free device fit could not be prepared, run or compared.
#[derive(Debug, thiserror::Error)]
pub enum FrameFitError {
    /// Running the firmware or reading its fit record failed.
    #[error(transparent)]
    Fit(#[from] DeviceFitError),
    /// Writing the frame or reading the detection record failed.
    #[error(transparent)]
    Detect(#[from] DeviceDetectError),
    /// The init file was refused.
    #[error(transparent)]
    Init(#[from] DetectError),
    /// The core's networks or crop refused the frame on the host.
    #[error("the host's run of the landmark-free start refused the frame: {0}")]
    Net(NetError),
    /// The fit job could not be written.
    #[error("the landmark-free fit job could not be written: {0}")]
    Job(FormatError),
    /// A record could not be rewritten with the host's values.
    #[error("the host's record could not be written: {0}")]
    Record(FormatError),
    /// The working side is out of the profile's range.
    #[error("working side {side} px is out of range: the {profile} firmware fits {min}..={max} px")]
    Side {
        /// The side asked for.
        side: u32,
        /// Profile name.
        profile: &'static str,
        /// Smallest side.
        min: u32,
        /// The profile's largest side.
        max: u32,
    },
    /// The init file and the model read different landmarks.
    #[error("the init file reads {init} landmarks but the model blob has {model}: they do not belong together")]
    Landmarks {
        /// The initializer's landmarks.
        init: usize,
        /// The model's landmarks.
        model: usize,
    },
    /// The partition does not fit.
    #[error(
        "the data partition needs {need} bytes (blob + fit job + init file + frame); the {profile} partition holds {have} (make room with a smaller blob: `gpmm quantize --bits 8` or lower --rank-shape/--rank-color; the m7's partition is 1 MiB)"
    )]
    TooLarge {
        /// Bytes needed.
        need: usize,
        /// Bytes available.
        have: usize,
        /// Profile name.
        profile: &'static str,
    },
}

/// Checks a working side against `profile`'s landmark-free fit.
pub fn check_side(side: u32, profile: &DeviceProfile) -> Result<(), FrameFitError> {
    if (frame_fit::MIN_SIDE..=profile.frame_fit_side).contains(&side) {
        Ok(())
    } else {
        Err(FrameFitError::Side { side, profile: profile.name, min: frame_fit::MIN_SIDE, max: profile.frame_fit_side })
    }
}

/// The job section (`GPFF`): working side, seed, settings.
pub fn job_bytes(side: u32, seed: u64, settings: &FitSettings) -> Result<Vec<u8>, FrameFitError> {
    let mut out = vec![0u8; frame_fit::buffer_len()];
    let n = frame_fit::write(&mut out, side, seed, settings).map_err(FrameFitError::Job)?;
    out.truncate(n);
    Ok(out)
}

/// The data partition: blob, job, init file, frame, each at the next 16-byte boundary; refused if
/// larger than `profile`'s partition.
pub fn partition_bytes(blob: &[u8], job: &[u8], init: &[u8], frame: &[u8], profile: &DeviceProfile) -> Result<Vec<u8>, FrameFitError> {
    let mut p = Vec::new();
    for section in [blob, job, init, frame] {
        p.resize(frame_fit::next_section(p.len()), 0);
        p.extend_from_slice(section);
    }
    if p.len() > profile.partition_bytes {
        return Err(FrameFitError::TooLarge { need: p.len(), have: profile.partition_bytes, profile: profile.name });
    }
    Ok(p)
}

/// The crop and fit of a found face on the host.
#[derive(Debug, Clone)]
pub struct HostCropFit {
    /// The crop in the frame (working px → frame px).
    pub window: Window,
    /// The detected landmarks in the working image (the landmark term's targets).
    pub working_landmarks: Vec<[f32; 2]>,
    /// The fit.
    pub fit: StandardFit<DEVICE_KS, DEVICE_KC>,
    /// The fit's landmarks in the working image (px).
    pub fitted_landmarks: Vec<[f32; 2]>,
    /// The fit's pose spread from the landmarks, as the firmware records it.
    pub spread: Option<gpmm_core::fit::PoseSpread>,
}

/// The host's run of the device's landmark-free fit.
#[derive(Debug, Clone)]
pub struct HostFrameFit {
    /// The finder's box.
    pub face: FaceBox,
    /// The initializer's reading, if the box counts as a face.
    pub detection: Option<Detection>,
    /// The crop and the fit, if a face was found.
    pub fitted: Option<HostCropFit>,
}

/// Runs the device's path on the host: finder, initializer (`refine` more passes, bounded as the
/// device bounds them: [`bounded_reading`]) if the score
/// reaches `min_score`, the core's crop to `side × side` and the core's standard fit on the blob.
#[allow(clippy::too_many_arguments)]
pub fn host_frame_fit(
    blob: &BlobBuf,
    init: &Detector,
    frame: &RgbImage,
    min_score: f32,
    refine: u32,
    side: u32,
    settings: &FitSettings,
    seed: u64,
) -> Result<HostFrameFit, FrameFitError> {
    let file = init.file().map_err(FrameFitError::Net)?;
    let (w, h) = (frame.width() as usize, frame.height() as usize);
    let mut scratch: Box<NetScratch<HOST_NET_SCRATCH>> = Box::default();
    let face = find_face(&file, frame.as_raw(), w, h, &mut scratch).map_err(FrameFitError::Net)?;
    if !is_face(&face, min_score) {
        return Ok(HostFrameFit { face, detection: None, fitted: None });
    }
    let reading = bounded_reading(&face, refine as usize, file.landmarks);
    let det = read_landmarks(&file, frame.as_raw(), w, h, face, reading, &mut scratch).map_err(FrameFitError::Net)?;
    let s = side as usize;
    let (mut pixels, mut working) = (vec![[0u8; 3]; s * s], vec![[0.0f32; 2]; det.landmarks.len()]);
    let window = crop_for_fit(frame.as_raw(), w, h, &det.landmarks, s, &mut pixels, &mut working).map_err(FrameFitError::Net)?;
    let covered = CoveredPixels::of_crop(window.x0, window.y0, window.step, side, w as u32, h as u32);
    let (fit, fitted_landmarks) = host_fit_pixels(blob, &pixels, side, side, covered, &working, settings, seed)?;
    let spread = super::fit::device_pose_spread(blob, &fit, &working, side, side)?;
    Ok(HostFrameFit {
        face,
        detection: Some(det),
        fitted: Some(HostCropFit { window, working_landmarks: working, fit, fitted_landmarks, spread }),
    })
}

/// The crop as reported: where the working image lies in the frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CropReport {
    /// Working side (px).
    pub side: u32,
    /// Frame position of the working image's top-left corner.
    pub origin_frame_px: [f32; 2],
    /// Frame pixels per working pixel.
    pub frame_px_per_working_px: f32,
    /// The device's instructions for the crop (resampling and the landmarks' mapping).
    pub instructions: u64,
}

/// What the firmware reported: the detection, and the crop and the fit if it found a face.
#[derive(Debug, Clone, Serialize)]
pub struct DeviceFrameFitReport {
    /// The detection (box, landmarks in frame px, its counts and the run's RAM).
    pub detection: DeviceDetectReport,
    /// The crop, if a face was found.
    pub crop: Option<CropReport>,
    /// The fit, if a face was found (landmarks in working px).
    pub fit: Option<DeviceFitReport>,
    /// The fit's landmarks in the frame (px).
    pub fitted_landmarks_frame_px: Option<Vec<[f32; 2]>>,
    /// Instructions of the three stages: detection (finder + initializer), crop, fit.
    pub stage_instructions: StageInstructions,
    /// The fit record as the firmware logged it.
    #[serde(skip)]
    pub fit_record: Option<Vec<u8>>,
}

/// The device's instructions per stage.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct StageInstructions {
    /// Parsing blob, job, init file and frame.
    pub parse: u64,
    /// Finder and initializer (every pass).
    pub detection: u64,
    /// The crop.
    pub crop: u64,
    /// The standard fit.
    pub fit: u64,
    /// Everything from reading the partition to the fit's end (logging left out).
    pub total: u64,
}

/// Reads the report out of the firmware's log (`GPDR` and, if a face was found, `GPFR` lines,
/// the crop's figures and run.sh's `GPMM_FIGURES`).
pub fn parse_report(profile: &str, log: &str) -> Result<DeviceFrameFitReport, FrameFitError> {
    let detection = detect::parse_report(profile, log)?;
    let dc = detection.counts;
    let mut stages = StageInstructions {
        parse: dc.instructions_parse,
        detection: dc.instructions_finder + dc.instructions_initializer,
        total: dc.instructions_total,
        ..StageInstructions::default()
    };
    if !detection.detection.found {
        return Ok(DeviceFrameFitReport {
            detection,
            crop: None,
            fit: None,
            fitted_landmarks_frame_px: None,
            stage_instructions: stages,
            fit_record: None,
        });
    }
    let record = dfit::record_bytes(log)?;
    let side = fit_record::parse(&record).map_err(DeviceFitError::Record)?.counts.image_width;
    let fit = dfit::parse_report(profile, log)?;
    let (w, h) = (dc.frame_width as usize, dc.frame_height as usize);
    // The crop's window follows from the detected landmarks (the same core routine as the device's).
    let window = fit_window(&detection.landmarks_px, w, h, side as usize).ok_or(FrameFitError::Net(NetError::DegenerateLandmarks))?;
    let crop = CropReport {
        side,
        origin_frame_px: [window.x0, window.y0],
        frame_px_per_working_px: window.step,
        instructions: dfit::figure(log, "crop_instructions")?,
    };
    stages.crop = crop.instructions;
    stages.fit = fit.instructions_fit;
    stages.total = fit.instructions_total;
    let frame_lm = fit.landmarks_px.iter().map(|p| window.to_source(p[0], p[1]).into()).collect();
    Ok(DeviceFrameFitReport {
        detection,
        crop: Some(crop),
        fit: Some(fit),
        fitted_landmarks_frame_px: Some(frame_lm),
        stage_instructions: stages,
        fit_record: Some(record),
    })
}

/// RAM of a landmark-free device fit, per stage (the firmware repaints the stack after the
/// detection, so the fit record's peak is the crop's and the fit's alone).
#[derive(Debug, Clone, Copy, Serialize)]
pub struct FrameFitRam {
    /// Statics (data + bss).
    pub static_bytes: u64,
    /// Stack peak of the detection (its scratch included).
    pub detection_stack_bytes: u64,
    /// Stack peak of the crop and the fit (the working image included); 0 without a face.
    pub fit_stack_bytes: u64,
    /// Statics + the larger peak.
    pub total_bytes: u64,
    /// The profile's RAM.
    pub budget_bytes: u64,
}

impl DeviceFrameFitReport {
    /// The run's RAM, per stage.
    pub fn ram(&self) -> FrameFitRam {
        let d = &self.detection;
        let detection_stack_bytes = u64::from(d.counts.stack_peak_bytes);
        let fit_stack_bytes = self.fit.as_ref().map_or(0, |f| f.stack_peak_bytes);
        FrameFitRam {
            static_bytes: d.ram_static_bytes,
            detection_stack_bytes,
            fit_stack_bytes,
            total_bytes: d.ram_static_bytes + detection_stack_bytes.max(fit_stack_bytes),
            budget_bytes: d.ram_budget_bytes,
        }
    }
}

/// Fit-record bytes of the host's fit with the device's `counts` (byte-identical to the device's
/// record exactly when the fits are bit-identical).
pub fn fit_record_bytes(
    fit: &StandardFit<DEVICE_KS, DEVICE_KC>,
    spread: Option<&gpmm_core::fit::PoseSpread>,
    landmarks: &[[f32; 2]],
    counts: &DeviceCounts,
) -> Result<Vec<u8>, FormatError> {
    let p = fit.params();
    let mut out = vec![0u8; fit_record::encoded_len(DEVICE_KS, DEVICE_KC, landmarks.len())];
    let n = fit_record::write(&mut out, &fit.record_figures(spread), counts, &p.light, p.shape_coeffs(), p.color_coeffs(), landmarks)?;
    out.truncate(n);
    Ok(out)
}

/// How the host's run compares with the device's.
#[derive(Debug, Clone, Serialize)]
pub struct FrameFitParity {
    /// The detection records are byte-identical (box, score, pose, landmarks, light).
    pub detection_bit_identical: bool,
    /// The fit records are byte-identical (every figure, coefficient, light value and landmark),
    /// or neither side fitted (no face).
    pub fit_bit_identical: bool,
    /// Both sides found a face, or neither did.
    pub same_outcome: bool,
    /// Largest distance between a host and a device fitted landmark (working px; 0 without a fit).
    pub max_fitted_landmark_difference_px: f32,
}

/// Compares the device's report with the host's run on the same frame.
pub fn compare(report: &DeviceFrameFitReport, host: &HostFrameFit) -> Result<FrameFitParity, FrameFitError> {
    let det = detect::compare(&report.detection, &host.face, host.detection.as_ref()).map_err(FrameFitError::Record)?;
    let (fit_identical, diff, same) = match (&report.fit, &report.fit_record, &host.fitted) {
        (Some(dev), Some(record), Some(h)) => {
            let counts = fit_record::parse(record).map_err(FrameFitError::Record)?.counts;
            let mine = fit_record_bytes(&h.fit, h.spread.as_ref(), &h.fitted_landmarks, &counts).map_err(FrameFitError::Record)?;
            let d = if dev.landmarks_px.len() == h.fitted_landmarks.len() {
                dev.landmarks_px.iter().zip(&h.fitted_landmarks).map(|(p, q)| (p[0] - q[0]).hypot(p[1] - q[1])).fold(0.0f32, f32::max)
            } else {
                f32::INFINITY
            };
            (&mine == record, d, true)
        }
        (None, _, None) => (true, 0.0, true),
        _ => (false, f32::INFINITY, false),
    };
    Ok(FrameFitParity {
        detection_bit_identical: det.bit_identical,
        fit_bit_identical: fit_identical,
        same_outcome: same,
        max_fitted_landmark_difference_px: diff,
    })
}

/// The detection frame section for `frame` (the same `GPDF` as `gpmm device-detect`'s).
pub fn frame_section(frame: &RgbImage, min_score: f32, refine: u32) -> Result<Vec<u8>, FrameFitError> {
    Ok(detect::frame_bytes(frame, min_score, refine)?)
}

/// Checks that the init file's initializer reads as many landmarks as the model has.
pub fn check_landmarks(init: &Detector, model_landmarks: usize) -> Result<(), FrameFitError> {
    let n = init.file().map_err(FrameFitError::Net)?.landmarks;
    if n == model_landmarks {
        Ok(())
    } else {
        Err(FrameFitError::Landmarks { init: n, model: model_landmarks })
    }
}
