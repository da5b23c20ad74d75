//! The fit on the device (`gpmm device-fit`): the data partition for the firmware (model blob,
//! then a fit input: the working image, its landmarks, seed and step counts), the firmware run
//! under QEMU through `firmware-sim/run.sh`, and its decoded log read back into a report.
//!
//! The same inputs can be fitted on the host with [`host_fit`], which runs the core's
//! `standard_fit` on the blob exactly as the firmware does (same coefficient capacities): the
//! parity test compares the two.
//!
//! The fit-input layout is documented in `firmware-sim/src/fit_input.rs` and its README.

use crate::device::quantize::BlobBuf;
use crate::fit::{FitBuffers, Prepared};
use gpmm_core::error::FitError;
use gpmm_core::fit::{project_landmarks, standard_fit, CoveredPixels, FitSettings, OcclusionMask, RankSettings, StandardFit, TargetImage};
use gpmm_core::format::{fit_input, fit_record, FormatError};
use gpmm_core::profile::{DeviceProfile, M4F};
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Shape coefficient capacity of the host's run of a device fit: the m4f profile's. The capacity
/// does not change the fit (only the leading `rank` coefficients are ever drawn or read), and
/// [`device_settings`] caps the ranks at it, so the host uses one capacity for both profiles.
pub const DEVICE_KS: usize = M4F.shape_capacity;
/// Colour coefficient capacity of the host's run of a device fit.
pub const DEVICE_KC: usize = M4F.color_capacity;
/// The devices' renderer (the profile's tile and bin sizes): the image likelihood sums in the
/// same order as on the device.
pub type DeviceRasterizer = gpmm_core::render::TileRasterizer<{ M4F.tile }, { M4F.tile }, { M4F.bin }>;

/// Why a device fit failed.
#[derive(Debug, thiserror::Error)]
pub enum DeviceFitError {
    /// The firmware directory was not found.
    #[error("the firmware sources are not at {0} (set GPMM_FIRMWARE_DIR to the firmware-sim directory of a gpmm checkout)")]
    NoFirmware(PathBuf),
    /// The partition does not fit.
    #[error("the data partition needs {need} bytes (blob + fit input); the {profile} partition holds {have}")]
    TooLarge {
        /// Bytes needed.
        need: usize,
        /// Bytes available.
        have: usize,
        /// Profile name.
        profile: &'static str,
    },
    /// Reading or writing a file failed.
    #[error("{0}: {1}")]
    Io(String, std::io::Error),
    /// The firmware run failed.
    #[error("the firmware run failed ({status}):\n{log}")]
    Run {
        /// Exit status.
        status: String,
        /// The end of its output.
        log: String,
    },
    /// The log lacks a figure.
    #[error("the firmware log has no {0}")]
    Missing(&'static str),
    /// The firmware's fit record is malformed.
    #[error("the firmware's fit record is malformed: {0}")]
    Record(FormatError),
    /// The fit input could not be written.
    #[error("the fit input could not be written: {0}")]
    Input(FormatError),
    /// The core refused the fit on the host.
    #[error("the core fitter refused the input on the host: {0}")]
    Core(FitError),
    /// The blob was refused.
    #[error("the model blob was refused: {0}")]
    Blob(String),
}

/// `settings` as a device of `profile` runs them: the ranks capped at the coefficient capacities
/// of both the device and the host's run of it. The start's shape solve runs as on the host (its
/// depth grid in the frame cache's memory, [`gpmm_core::fit::solve::shape::DEPTH_CELLS`]).
pub fn device_settings(settings: &FitSettings, profile: &DeviceProfile) -> FitSettings {
    let ranks = RankSettings {
        shape: settings.ranks.shape.min(profile.shape_capacity).min(DEVICE_KS),
        color: settings.ranks.color.min(profile.color_capacity).min(DEVICE_KC),
    };
    FitSettings { ranks, ..*settings }
}

/// `settings` as a device of `profile` runs them in the landmark-free fit (`gpmm device-fit
/// --init`): [`device_settings`] without the start's shape solve, whose stack does not fit beside
/// the camera frame's crop on the m4f; the chains fit the shape instead
/// ([`FitSettings::without_shape_solve`]).
pub fn frame_fit_settings(settings: &FitSettings, profile: &DeviceProfile) -> FitSettings {
    device_settings(settings, profile).without_shape_solve()
}

/// The fit input section (`gpmm_core::format::fit_input`): `prepared`'s working image, the
/// pixels of it the photo covers and its landmarks, the whole `settings` and `seed`.
pub fn fit_input_bytes(prepared: &Prepared, settings: &FitSettings, seed: u64) -> Result<Vec<u8>, DeviceFitError> {
    let (w, h) = prepared.image.dimensions();
    let pixels: Vec<[u8; 3]> = prepared.image.pixels().map(|p| p.0).collect();
    let mut out = vec![0u8; fit_input::buffer_len(w, h, prepared.landmarks.len())];
    let n =
        fit_input::write(&mut out, w, h, seed, prepared.covered, settings, &prepared.landmarks, &pixels).map_err(DeviceFitError::Input)?;
    out.truncate(n);
    Ok(out)
}

/// The data partition: the blob, zero padding to 16 bytes, the fit input.
pub fn partition_bytes(blob: &[u8], input: &[u8]) -> Vec<u8> {
    let mut p = blob.to_vec();
    while !p.len().is_multiple_of(16) {
        p.push(0);
    }
    p.extend_from_slice(input);
    p
}

/// The host's run of the firmware's fit: the core's standard fit on the blob, with the
/// firmware's coefficient capacities, `settings` (see [`device_settings`]) and seed. Returns the
/// fit and its landmarks (px).
pub fn host_fit(
    blob: &BlobBuf,
    prepared: &Prepared,
    settings: &FitSettings,
    seed: u64,
) -> Result<(StandardFit<DEVICE_KS, DEVICE_KC>, Vec<[f32; 2]>), DeviceFitError> {
    let (w, h) = prepared.image.dimensions();
    let pixels: Vec<[u8; 3]> = prepared.image.pixels().map(|p| p.0).collect();
    host_fit_pixels(blob, &pixels, w, h, prepared.covered, &prepared.landmarks, settings, seed)
}

/// [`host_fit`] on a working image given as pixels (`w × h`, row-major), the pixels of it the
/// photo covers and its landmarks (px).
#[allow(clippy::too_many_arguments)]
pub fn host_fit_pixels(
    blob: &BlobBuf,
    pixels: &[[u8; 3]],
    w: u32,
    h: u32,
    covered: CoveredPixels,
    landmarks: &[[f32; 2]],
    settings: &FitSettings,
    seed: u64,
) -> Result<(StandardFit<DEVICE_KS, DEVICE_KC>, Vec<[f32; 2]>), DeviceFitError> {
    let view = blob.view().map_err(|e| DeviceFitError::Blob(e.to_string()))?;
    let model = view.morphable().map_err(DeviceFitError::Core)?;
    let image = TargetImage::new(pixels, w, h).and_then(|t| t.with_covered(covered)).map_err(DeviceFitError::Core)?;
    // The firmware's compact frame cache, the same size (the fit is the same with or without it).
    let mut buffers = FitBuffers::device(model.vertices(), w, h, M4F.frame_cache_pixels);
    let mut inst = buffers.instance::<DEVICE_KS, DEVICE_KC>().map_err(DeviceFitError::Core)?;
    let mut raster: Box<DeviceRasterizer> = Box::new(DeviceRasterizer::new());
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let valid = vec![true; landmarks.len()];
    let mut mask: Box<OcclusionMask<{ M4F.pixel_words() }>> = Box::default();
    let fit = standard_fit(&model, image, landmarks, &valid, settings, &mut inst, &mut raster, &mut mask, &mut rng, &mut |_, _, _| {})
        .map_err(DeviceFitError::Core)?;
    let mut lm = vec![[0.0f32; 2]; model.landmarks().len()];
    let k = project_landmarks(&model, fit.params(), w, h, &mut lm).map_err(DeviceFitError::Core)?;
    lm.truncate(k);
    Ok((fit, lm))
}

/// The pose's spread of a device fit from its target `landmarks` in a `w × h` working image, as the
/// firmware computes it after the fit for its record (`None` when the landmarks do not determine
/// the pose).
pub fn device_pose_spread(
    blob: &BlobBuf,
    fit: &StandardFit<DEVICE_KS, DEVICE_KC>,
    landmarks: &[[f32; 2]],
    w: u32,
    h: u32,
) -> Result<Option<gpmm_core::fit::PoseSpread>, DeviceFitError> {
    let view = blob.view().map_err(|e| DeviceFitError::Blob(e.to_string()))?;
    let model = view.morphable().map_err(DeviceFitError::Core)?;
    let valid = vec![true; landmarks.len()];
    let target = gpmm_core::fit::LandmarkTarget::new(landmarks, &valid, 1.0).map_err(DeviceFitError::Core)?;
    Ok(gpmm_core::fit::pose_spread(&model, fit.params(), &target, w, h).ok())
}

/// What the firmware reported (the JSON of `gpmm device-fit`).
#[derive(Debug, Clone, Serialize)]
pub struct DeviceFitReport {
    /// Device profile.
    pub profile: String,
    /// Flash used by the program (text + data), bytes.
    pub flash_bytes: u64,
    /// The blob's bytes in the data partition.
    pub blob_bytes: u64,
    /// Flash used in all: program + data partition content.
    pub flash_total_bytes: u64,
    /// The profile's flash.
    pub flash_budget_bytes: u64,
    /// Static RAM (data + bss), bytes.
    pub ram_static_bytes: u64,
    /// Measured stack high-water mark, bytes.
    pub stack_peak_bytes: u64,
    /// Static RAM + stack peak.
    pub ram_total_bytes: u64,
    /// The profile's RAM.
    pub ram_budget_bytes: u64,
    /// Instructions from reading the partition to the end of the fit.
    pub instructions_total: u64,
    /// Instructions of the landmark chain.
    pub instructions_landmark_chain: u64,
    /// Instructions of the start's least-squares light and first render.
    pub instructions_light_and_start: u64,
    /// Instructions of the image chain.
    pub instructions_image_chain: u64,
    /// Image-chain instructions per step.
    pub instructions_per_image_step: u64,
    /// Landmark-chain instructions per step.
    pub instructions_per_landmark_step: u64,
    /// Instructions to parse the blob and the fit input.
    pub instructions_parse: u64,
    /// Instructions of the fit itself (after parsing).
    pub instructions_fit: u64,
    /// Shape-instance recomputations on the device.
    pub shape_updates: u32,
    /// Colour-instance recomputations on the device.
    pub color_updates: u32,
    /// Seconds at 168 MHz, assuming one instruction per cycle.
    pub seconds_at_168mhz: f64,
    /// Fitted yaw (degrees).
    pub yaw_deg: f32,
    /// Fitted pitch (degrees).
    pub pitch_deg: f32,
    /// Fitted roll (degrees).
    pub roll_deg: f32,
    /// Focal length (px).
    pub focal_px: f32,
    /// Standard deviations of yaw, pitch and roll from the landmarks the fit could not reach,
    /// calibrated as a host fit's (degrees; docs/intervals.md; zero when not measured).
    #[serde(default)]
    pub angles_sd_deg: [f32; 3],
    /// The central 90 % interval of yaw, pitch and roll (degrees): fit ± 1.645 sd.
    #[serde(default)]
    pub angles_interval_90_deg: [[f32; 2]; 3],
    /// Standard deviations of the translation, calibrated as a host fit's (mm).
    #[serde(default)]
    pub translation_sd_mm: [f32; 3],
    /// The landmarks' residual σ the spread is scaled by (working-image px).
    #[serde(default)]
    pub landmark_residual_px: f32,
    /// Best log posterior.
    pub log_posterior: f32,
    /// Image log-likelihood ratio of the fit.
    pub log_likelihood: f32,
    /// Landmark RMSE of the fit (working-image px).
    pub landmark_rmse_px: f32,
    /// Colour RMSE over covered pixels.
    pub pixel_rmse: f32,
    /// Acceptance rate of the landmark chain.
    pub acceptance_landmark_chain: f32,
    /// Acceptance rate of the image chain.
    pub acceptance_image_chain: f32,
    /// Fitted shape coefficients.
    pub shape: Vec<f32>,
    /// Fitted colour coefficients.
    pub color: Vec<f32>,
    /// Fitted SH light, 9 × (r, g, b).
    pub light: Vec<[f32; 3]>,
    /// The fitted 68 landmarks in the working image (px).
    pub landmarks_px: Vec<[f32; 2]>,
    /// The same in the original photo (px), when known.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub landmarks_original_px: Option<Vec<[f32; 2]>>,
}

/// The firmware-sim directory: `$GPMM_FIRMWARE_DIR`, else the one of this source checkout.
pub fn firmware_dir() -> Result<PathBuf, DeviceFitError> {
    let dir = std::env::var_os("GPMM_FIRMWARE_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../firmware-sim"));
    if dir.join("run.sh").is_file() {
        Ok(dir)
    } else {
        Err(DeviceFitError::NoFirmware(dir))
    }
}

/// Runs the firmware (`run.sh --profile P --data FILE`) and returns its decoded log (stdout).
pub fn run_firmware(profile: &str, partition: &Path, timeout_s: u32) -> Result<String, DeviceFitError> {
    run_firmware_on(profile, "mps2", partition, timeout_s)
}

/// Runs the firmware linked for memory map `map` (`gpmm_core::profile`: `mps2`, or
/// `netduinoplus2`, QEMU's STM32F405) and returns its decoded log (stdout).
pub fn run_firmware_on(profile: &str, map: &str, partition: &Path, timeout_s: u32) -> Result<String, DeviceFitError> {
    let dir = firmware_dir()?;
    let out = Command::new("bash")
        .arg(dir.join("run.sh"))
        .args(["--profile", profile, "--map", map, "--timeout", &timeout_s.to_string(), "--data"])
        .arg(partition)
        .output()
        .map_err(|e| DeviceFitError::Io(dir.join("run.sh").display().to_string(), e))?;
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    if !out.status.success() {
        let stderr = String::from_utf8_lossy(&out.stderr);
        let tail = |s: &str| s.lines().rev().take(15).collect::<Vec<_>>().into_iter().rev().collect::<Vec<_>>().join("\n");
        return Err(DeviceFitError::Run { status: out.status.to_string(), log: format!("{}\n{}", tail(&stdout), tail(&stderr)) });
    }
    Ok(stdout)
}

/// The fit record the firmware logged as `GPFR <hex>` lines, as bytes.
pub fn record_bytes(log: &str) -> Result<Vec<u8>, DeviceFitError> {
    if !log.lines().any(|l| l.contains("GPFR ")) {
        return Err(DeviceFitError::Missing("fit record (GPFR lines)"));
    }
    tagged_hex(log, "GPFR ").ok_or(DeviceFitError::Missing("well-formed fit record (hex digits)"))
}

/// The bytes a firmware logged as hex after `tag` on its lines, joined (`None` if there are no
/// such lines or they are not whole bytes of hex digits).
pub fn tagged_hex(log: &str, tag: &str) -> Option<Vec<u8>> {
    let hex: String = log.lines().filter_map(|l| l.split_once(tag).map(|(_, h)| h.trim())).collect();
    let digits: Option<Vec<u8>> = hex.chars().map(|c| c.to_digit(16).map(|d| d as u8)).collect();
    let digits = digits.filter(|d| !d.is_empty() && d.len() % 2 == 0)?;
    Some(digits.chunks_exact(2).map(|p| p[0] << 4 | p[1]).collect())
}

/// Reads the report out of the firmware's fit record and the `GPMM_FIGURES` line of `run.sh`.
pub fn parse_report(profile: &str, log: &str) -> Result<DeviceFitReport, DeviceFitError> {
    let bytes = record_bytes(log)?;
    let r = fit_record::parse(&bytes).map_err(DeviceFitError::Record)?;
    let (f, c) = (r.figures, r.counts);
    let flash_bytes: u64 = figure(log, "flash_bytes")?;
    let ram_static_bytes: u64 = figure(log, "ram_static_bytes")?;
    let flash_code_budget: u64 = figure(log, "flash_code_budget_bytes")?;
    let ram_budget_bytes: u64 = figure(log, "ram_budget_bytes")?;
    // The record's peak is taken after the fit; the firmware's last line covers the whole run.
    let stack_peak_bytes = u64::from(c.stack_peak_bytes).max(figure(log, "stack_peak_bytes").unwrap_or(0));
    let blob_bytes = u64::from(c.blob_bytes);
    let lm: Vec<f32> = r.landmarks.iter().collect();
    let spread = gpmm_core::fit::PoseSpread {
        angles_sd: f.angles_sd,
        translation_sd: f.translation_sd,
        residual_sigma_px: f.landmark_residual_px,
        landmarks: 0,
    };
    let angles_deg = [f.yaw, f.pitch, f.roll].map(f32::to_degrees);
    let angles_sd_deg = crate::fit::calibrated_angles_sd_deg(&spread);
    Ok(DeviceFitReport {
        profile: profile.to_string(),
        flash_bytes,
        blob_bytes,
        flash_total_bytes: flash_bytes + blob_bytes,
        flash_budget_bytes: flash_code_budget + u64::from(c.partition_bytes),
        ram_static_bytes,
        stack_peak_bytes,
        ram_total_bytes: ram_static_bytes + stack_peak_bytes,
        ram_budget_bytes,
        instructions_total: c.instructions_total,
        instructions_landmark_chain: c.instructions_landmark_chain,
        instructions_light_and_start: c.instructions_light_and_start,
        instructions_image_chain: c.instructions_image_chain,
        instructions_per_image_step: c.instructions_per_image_step,
        instructions_per_landmark_step: c.instructions_per_landmark_step,
        instructions_parse: c.instructions_parse,
        instructions_fit: c.instructions_fit,
        shape_updates: c.shape_updates,
        color_updates: c.color_updates,
        seconds_at_168mhz: c.instructions_total as f64 / 168e6,
        yaw_deg: f.yaw.to_degrees(),
        pitch_deg: f.pitch.to_degrees(),
        roll_deg: f.roll.to_degrees(),
        focal_px: f.focal,
        angles_sd_deg,
        angles_interval_90_deg: crate::fit::central_intervals(angles_deg, angles_sd_deg, crate::fit::Z90),
        translation_sd_mm: crate::fit::calibrated_translation_sd_mm(&spread),
        landmark_residual_px: f.landmark_residual_px,
        log_posterior: f.log_posterior,
        log_likelihood: f.log_likelihood,
        landmark_rmse_px: f.landmark_rmse_px,
        pixel_rmse: f.pixel_rmse,
        acceptance_landmark_chain: f.acceptance_landmark_chain,
        acceptance_image_chain: f.acceptance_image_chain,
        shape: r.shape.iter().collect(),
        color: r.color.iter().collect(),
        light: r.light.coeffs.to_vec(),
        landmarks_px: lm.chunks_exact(2).map(|c| [c[0], c[1]]).collect(),
        landmarks_original_px: None,
    })
}

/// A figure from run.sh's `GPMM_FIGURES {json}` line.
pub fn figure(log: &str, key: &'static str) -> Result<u64, DeviceFitError> {
    let line = log.lines().find_map(|l| l.strip_prefix("GPMM_FIGURES ")).ok_or(DeviceFitError::Missing("GPMM_FIGURES line"))?;
    let v: serde_json::Value = serde_json::from_str(line).map_err(|_| DeviceFitError::Missing("GPMM_FIGURES line"))?;
    v.get(key).and_then(|x| x.as_u64().or_else(|| x.as_str().and_then(|s| s.parse().ok()))).ok_or(DeviceFitError::Missing(key))
}

#[cfg(test)]
mod tests {
    use super::*;
    use gpmm_core::format::fit_record::{DeviceCounts, FitFigures};
    use gpmm_core::render::ShLight;

    #[test]
    fn the_record_is_read_back_from_hex_lines() {
        let figures = FitFigures {
            yaw: 0.5,
            covered_pixels: 77,
            angles_sd: [0.01, 0.02, 0.005],
            translation_sd: [0.5, 0.5, 3.0],
            landmark_residual_px: 1.5,
            ..FitFigures::default()
        };
        let counts =
            DeviceCounts { instructions_total: 123_456_789, stack_peak_bytes: 4096, partition_bytes: 1000, ..DeviceCounts::default() };
        let mut rec = vec![0u8; fit_record::encoded_len(2, 1, 1)];
        fit_record::write(&mut rec, &figures, &counts, &ShLight::frontal(), &[1.0, 2.0], &[3.0], &[[4.0, 5.0]]).unwrap();
        let hex: Vec<String> = rec.chunks(50).map(|c| c.iter().map(|b| format!("{b:02x}")).collect()).collect();
        let mut log = String::from("INFO  gpmm-firmware-sim 0.1.0 profile=m4f\n");
        for h in &hex {
            log.push_str(&format!("INFO  GPFR {h}\n"));
        }
        log.push_str(
            r#"GPMM_FIGURES {"flash_bytes": 100, "ram_static_bytes": 200, "flash_code_budget_bytes": 512, "ram_budget_bytes": 192}"#,
        );
        let r = parse_report("m4f", &log).unwrap();
        assert_eq!((r.instructions_total, r.stack_peak_bytes, r.flash_budget_bytes, r.ram_total_bytes), (123_456_789, 4096, 1512, 4296));
        // The pose's spread, calibrated as a host fit's: the yaw interval around the fitted yaw.
        let spread = gpmm_core::fit::PoseSpread {
            angles_sd: figures.angles_sd,
            translation_sd: figures.translation_sd,
            residual_sigma_px: 1.5,
            landmarks: 0,
        };
        assert_eq!((r.angles_sd_deg, r.landmark_residual_px), (crate::fit::calibrated_angles_sd_deg(&spread), 1.5));
        let [lo, hi] = r.angles_interval_90_deg[0];
        assert!(lo < r.yaw_deg && r.yaw_deg < hi && ((hi - lo) - 2.0 * crate::fit::Z90 * r.angles_sd_deg[0]).abs() < 1e-3, "{lo} {hi}");
        assert!(r.translation_sd_mm[2] > r.translation_sd_mm[0]);
        assert_eq!((r.shape.clone(), r.color.clone(), r.landmarks_px.clone()), (vec![1.0, 2.0], vec![3.0], vec![[4.0, 5.0]]));
        assert!((r.yaw_deg - 0.5f32.to_degrees()).abs() < 1e-4);
        // One flipped digit: the CRC refuses the record.
        let bad = log.replacen("GPFR 4750", "GPFR 4751", 1);
        assert!(matches!(parse_report("m4f", &bad), Err(DeviceFitError::Record(_))));
        assert!(matches!(parse_report("m4f", "INFO nothing"), Err(DeviceFitError::Missing(_))));
    }
}
