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
use crate::fit::{FitSettings, Prepared};
use gpmm_core::checksum::crc32;
use gpmm_core::fit::{project_landmarks, standard_fit, FitError, Instance, InstanceBuffers, StandardFit, TargetImage};
use gpmm_core::ProjectedVertex;
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Shape coefficient capacity of the firmware's fit on `m4f` (`firmware-sim/src/fit.rs`, `KS`;
/// `m7` has 100). The capacity does not change the fit: only the leading `rank` coefficients are
/// ever drawn or read, so the host uses one capacity for both profiles.
pub const DEVICE_KS: usize = 64;
/// Colour coefficient capacity of the firmware's fit (`KC`).
pub const DEVICE_KC: usize = 64;
/// The firmware's renderer (`firmware-sim/src/main.rs`, `Rasterizer`): the same tile size and bin,
/// so the image likelihood is summed in the same order as on the device.
pub type DeviceRasterizer = gpmm_core::TileRasterizer<32, 32, 2048>;
/// Magic of the fit input.
pub const FIT_INPUT_MAGIC: [u8; 4] = *b"GPFI";
/// Version of the fit-input layout.
pub const FIT_INPUT_VERSION: u32 = 1;

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
    /// The core refused the fit on the host.
    #[error("the core fitter refused the input on the host: {0:?}")]
    Core(FitError),
    /// The blob was refused.
    #[error("the model blob was refused: {0}")]
    Blob(String),
}

/// The fit input section (see `firmware-sim/src/fit_input.rs`): `prepared`'s working image and
/// landmarks, the step counts, ranks and landmark σ of `settings`, and `seed`.
pub fn fit_input_bytes(prepared: &Prepared, settings: &FitSettings) -> Vec<u8> {
    let (w, h) = prepared.image.dimensions();
    let mut b = Vec::new();
    b.extend_from_slice(&FIT_INPUT_MAGIC);
    for v in [FIT_INPUT_VERSION, w, h, prepared.landmarks.len() as u32, settings.landmark_steps, settings.image_steps] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    for v in [settings.shape_rank.min(DEVICE_KS), settings.color_rank.min(DEVICE_KC)] {
        b.extend_from_slice(&(v as u32).to_le_bytes());
    }
    b.extend_from_slice(&settings.seed.to_le_bytes());
    b.extend_from_slice(&settings.landmark_sigma.to_le_bytes());
    for p in &prepared.landmarks {
        b.extend_from_slice(&p[0].to_le_bytes());
        b.extend_from_slice(&p[1].to_le_bytes());
    }
    b.extend_from_slice(prepared.image.as_raw());
    while !b.len().is_multiple_of(4) {
        b.push(0);
    }
    let crc = crc32(&b);
    b.extend_from_slice(&crc.to_le_bytes());
    b
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
/// firmware's coefficient capacities, settings and seed. Returns the fit and its landmarks (px).
pub fn host_fit(
    blob: &BlobBuf,
    prepared: &Prepared,
    settings: &FitSettings,
) -> Result<(StandardFit<DEVICE_KS, DEVICE_KC>, Vec<[f32; 2]>), DeviceFitError> {
    let view = blob.view().map_err(|e| DeviceFitError::Blob(e.to_string()))?;
    let model = view.morphable().map_err(DeviceFitError::Core)?;
    let (w, h) = prepared.image.dimensions();
    let pixels: Vec<[u8; 3]> = prepared.image.pixels().map(|p| p.0).collect();
    let image = TargetImage::new(&pixels, w, h).map_err(DeviceFitError::Core)?;
    let n = model.vertices();
    let (mut pos, mut alb, mut nor, mut proj) =
        (vec![[0.0f32; 3]; n], vec![[0.0f32; 3]; n], vec![[0.0f32; 3]; n], vec![ProjectedVertex::INVALID; n]);
    let mut inst = Instance::<DEVICE_KS, DEVICE_KC>::new(
        InstanceBuffers { positions: &mut pos, albedos: &mut alb, normals: &mut nor, projected: &mut proj },
        n,
    )
    .map_err(DeviceFitError::Core)?;
    let mut raster: Box<DeviceRasterizer> = Box::new(DeviceRasterizer::new());
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(settings.seed);
    let core_settings = gpmm_core::fit::FitSettings {
        shape_rank: settings.shape_rank.min(DEVICE_KS),
        color_rank: settings.color_rank.min(DEVICE_KC),
        ..settings.core()
    };
    let valid = vec![true; prepared.landmarks.len()];
    let fit = standard_fit(&model, image, &prepared.landmarks, &valid, &core_settings, &mut inst, &mut raster, &mut rng, &mut |_, _, _| {})
        .map_err(DeviceFitError::Core)?;
    let mut lm = vec![[0.0f32; 2]; model.landmarks().len()];
    let k = project_landmarks(&model, fit.params(), w, h, &mut lm).map_err(DeviceFitError::Core)?;
    lm.truncate(k);
    Ok((fit, lm))
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
    let dir = firmware_dir()?;
    let out = Command::new("bash")
        .arg(dir.join("run.sh"))
        .args(["--profile", profile, "--timeout", &timeout_s.to_string(), "--data"])
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

/// The value of `key=` in the decoded log: the text after `key=` up to the next space, or the
/// bracketed list that starts there.
fn raw_value<'a>(log: &'a str, key: &str) -> Option<&'a str> {
    let pat = format!("{key}=");
    let mut found = None;
    for line in log.lines() {
        let mut rest = line;
        while let Some(i) = rest.find(&pat) {
            let before_ok = i == 0 || rest[..i].ends_with(' ');
            let after = &rest[i + pat.len()..];
            if before_ok {
                let v = if after.starts_with('[') {
                    let mut depth = 0usize;
                    let end = after
                        .char_indices()
                        .find(|&(_, c)| {
                            match c {
                                '[' => depth += 1,
                                ']' => depth = depth.saturating_sub(1),
                                _ => {}
                            }
                            depth == 0
                        })
                        .map_or(after.len(), |(j, _)| j + 1);
                    &after[..end]
                } else {
                    after.split(' ').next().unwrap_or("")
                };
                found = Some(v);
            }
            rest = after;
        }
    }
    found
}

fn number<T: std::str::FromStr>(log: &str, key: &'static str) -> Result<T, DeviceFitError> {
    raw_value(log, key).and_then(|v| v.trim_end_matches([',', ';']).parse().ok()).ok_or(DeviceFitError::Missing(key))
}

fn floats(log: &str, key: &'static str) -> Result<Vec<f32>, DeviceFitError> {
    let v = raw_value(log, key).ok_or(DeviceFitError::Missing(key))?;
    v.split(|c: char| c == '[' || c == ']' || c == ',' || c.is_whitespace())
        .filter(|t| !t.is_empty())
        .map(|t| t.parse::<f32>().map_err(|_| DeviceFitError::Missing(key)))
        .collect()
}

/// Reads the report out of the decoded log and the `GPMM_FIGURES` line of `run.sh`.
pub fn parse_report(profile: &str, log: &str) -> Result<DeviceFitReport, DeviceFitError> {
    let flash_bytes: u64 = figure(log, "flash_bytes")?;
    let ram_static_bytes: u64 = figure(log, "ram_static_bytes")?;
    let stack_peak_bytes: u64 = number(log, "stack_peak_bytes")?;
    let flash_code_budget: u64 = figure(log, "flash_code_budget_bytes")?;
    let ram_budget_bytes: u64 = figure(log, "ram_budget_bytes")?;
    let blob_bytes: u64 = number(log, "blob_bytes")?;
    let partition: u64 = number(log, "data_partition_bytes")?;
    let instructions_total: u64 = number(log, "instructions_total")?;
    let lm: Vec<f32> = floats(log, "fit_landmarks_px")?;
    Ok(DeviceFitReport {
        profile: profile.to_string(),
        flash_bytes,
        blob_bytes,
        flash_total_bytes: flash_bytes + blob_bytes,
        flash_budget_bytes: flash_code_budget + partition,
        ram_static_bytes,
        stack_peak_bytes,
        ram_total_bytes: ram_static_bytes + stack_peak_bytes,
        ram_budget_bytes,
        instructions_total,
        instructions_landmark_chain: number(log, "instructions_landmark_chain")?,
        instructions_light_and_start: number(log, "instructions_light_and_start")?,
        instructions_image_chain: number(log, "instructions_image_chain")?,
        instructions_per_image_step: number(log, "instructions_per_image_step")?,
        instructions_per_landmark_step: number(log, "instructions_per_landmark_step")?,
        seconds_at_168mhz: instructions_total as f64 / 168e6,
        yaw_deg: number(log, "yaw_deg")?,
        pitch_deg: number(log, "pitch_deg")?,
        roll_deg: number(log, "roll_deg")?,
        focal_px: number(log, "focal_px")?,
        log_posterior: number(log, "log_posterior")?,
        log_likelihood: number(log, "log_likelihood")?,
        landmark_rmse_px: number(log, "landmark_rmse_px")?,
        pixel_rmse: number(log, "pixel_rmse")?,
        acceptance_landmark_chain: number(log, "acceptance_landmark_chain")?,
        acceptance_image_chain: number(log, "acceptance_image_chain")?,
        shape: floats(log, "fit_shape")?,
        color: floats(log, "fit_color")?,
        landmarks_px: lm.chunks_exact(2).map(|c| [c[0], c[1]]).collect(),
        landmarks_original_px: None,
    })
}

/// A figure from run.sh's `GPMM_FIGURES {json}` line.
fn figure(log: &str, key: &'static str) -> Result<u64, DeviceFitError> {
    let line = log.lines().find_map(|l| l.strip_prefix("GPMM_FIGURES ")).ok_or(DeviceFitError::Missing("GPMM_FIGURES line"))?;
    let v: serde_json::Value = serde_json::from_str(line).map_err(|_| DeviceFitError::Missing("GPMM_FIGURES line"))?;
    v.get(key).and_then(|x| x.as_u64().or_else(|| x.as_str().and_then(|s| s.parse().ok()))).ok_or(DeviceFitError::Missing(key))
}

/// The profile's working image side.
pub fn profile_image_size(profile: &str) -> u32 {
    if profile == "m7" {
        256
    } else {
        128
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_values_are_found_with_lists() {
        let log = "INFO  yaw_deg=1.5 pitch_deg=-2\nINFO  fit_landmarks_px=[[1.0, 2.5], [3.0, -4.0]]\nINFO  instructions_total=123\n";
        assert_eq!(number::<f32>(log, "yaw_deg").unwrap(), 1.5);
        assert_eq!(number::<f32>(log, "pitch_deg").unwrap(), -2.0);
        assert_eq!(number::<u64>(log, "instructions_total").unwrap(), 123);
        assert_eq!(floats(log, "fit_landmarks_px").unwrap(), vec![1.0, 2.5, 3.0, -4.0]);
        assert!(number::<f32>(log, "roll_deg").is_err());
        // A key that is the suffix of another is not confused with it.
        assert!(number::<f32>("INFO  xyaw_deg=3", "yaw_deg").is_err());
    }
}
