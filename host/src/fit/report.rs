//! `fit.json`: its schema ([`FitReport`]) and how a fit's outcome fills it ([`report`]).

use super::input::Prepared;
use super::observe::AcceptanceReport;
use super::options::FitOptions;
use super::pipeline::{rmse, Outcome};
use super::posterior::PosteriorSummary;
use crate::gp::model::GpModel;
use crate::photo::CropBox;
use gpmm_core::fit::FitSettings;
use serde::{Deserialize, Serialize};

/// Wall-clock figures of a fit (the only non-deterministic part of `fit.json`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Timing {
    /// Seconds in the landmark chain.
    pub landmark_chain_seconds: f64,
    /// Seconds in the light solve and the image chain.
    pub image_chain_seconds: f64,
    /// Microseconds per landmark step.
    pub landmark_step_us: f64,
    /// Milliseconds per image step.
    pub image_step_ms: f64,
}

/// Log densities of the fit.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LogDensities {
    /// Log posterior (prior + landmarks + image), up to a constant.
    pub posterior: f32,
    /// Image log likelihood ratio (foreground against the background model).
    pub image: f32,
    /// Landmark log likelihood (no normalization constant).
    pub landmarks: f32,
}

/// Acceptance counts of both chains.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AcceptanceBoth {
    /// The landmark chain.
    pub landmark_chain: AcceptanceReport,
    /// The image chain.
    pub image_chain: AcceptanceReport,
}

/// The content of `fit.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FitReport {
    /// Always `gpmm-fit`.
    pub format: String,
    /// Format version (1).
    pub version: u32,
    /// Model file as given.
    pub model: String,
    /// The model's kernel.
    pub model_kernel: String,
    /// The model's vertices.
    pub model_vertices: usize,
    /// The model's shape and colour ranks.
    pub model_ranks: [usize; 2],
    /// Shape and colour components fitted.
    pub fitted_ranks: [usize; 2],
    /// Image file as given.
    pub image: String,
    /// Landmark file as given.
    pub landmarks_file: String,
    /// The detector calibration the landmarks were corrected with (absent: none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub landmark_calibration: Option<String>,
    /// Every setting of the fit (as `gpmm fit --set` names them; absent in older files).
    #[serde(default)]
    pub settings: FitSettings,
    /// Whether the landmark file was read as 1-based.
    pub pts_one_based: bool,
    /// Original image width and height.
    pub image_size: [u32; 2],
    /// The crop in the original image.
    pub crop: CropBox,
    /// The share of the crop outside the photo (0 to 1; those pixels are left out of the fit).
    #[serde(default)]
    pub crop_outside_fraction: f32,
    /// Working image side.
    pub working_size: u32,
    /// Seed.
    pub seed: u64,
    /// Landmark-chain steps.
    pub landmark_steps: u32,
    /// Image-chain steps.
    pub image_steps: u32,
    /// Yaw (degrees; positive turns the face toward the image right).
    pub yaw_deg: f32,
    /// Pitch (degrees; positive tilts the nose down).
    pub pitch_deg: f32,
    /// Roll (degrees; positive is counter-clockwise in the image).
    pub roll_deg: f32,
    /// Yaw, pitch and roll (degrees) in the photo's camera frame, its principal point at the photo's
    /// centre (`yaw_deg` etc. take the crop's centre as the optical axis; they differ by the angle
    /// at which the camera sees the face off its axis: [`crate::photo::pose_in_photo_frame`]).
    pub photo_pose_deg: [f32; 3],
    /// Translation (mm, camera space of the working image).
    pub translation_mm: [f32; 3],
    /// Focal length (working-image pixels).
    pub focal_px: f32,
    /// SH light `[9][3]` (camera space).
    pub light: [[f32; 3]; 9],
    /// Shape coefficients.
    pub shape: Vec<f32>,
    /// Colour coefficients.
    pub color: Vec<f32>,
    /// Landmark RMSE of the fit in working-image pixels.
    pub landmark_rmse_px: f32,
    /// Landmark RMSE of the fit in original-image pixels.
    pub landmark_rmse_original_px: f32,
    /// Landmark RMSE of the landmark-only result (working pixels).
    pub landmark_rmse_after_landmark_chain_px: f32,
    /// Per-channel colour RMSE on covered pixels, landmark-only result (with least-squares light).
    pub pixel_rmse_after_landmark_chain: f32,
    /// Per-channel colour RMSE on covered pixels, the fit.
    pub pixel_rmse: f32,
    /// Pixels the fit covers in the working image.
    pub covered_pixels: u32,
    /// Fraction of the face's working pixels labelled occluded (absent without occlusion rounds,
    /// `occlusion.rounds` 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub occluded_fraction: Option<f32>,
    /// Landmark + image log likelihood of the fit.
    pub log_likelihood: f32,
    /// The log densities separately.
    pub log_densities: LogDensities,
    /// Per proposal kind: proposed, passed the prior-and-landmark stage, accepted.
    pub acceptance: AcceptanceBoth,
    /// The image chain's posterior summary (absent in older files).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub posterior: Option<PosteriorSummary>,
    /// The fit's landmarks in the original image.
    pub fitted_landmarks: Vec<[f32; 2]>,
    /// Total wall-clock seconds of crop and fit (absent with `--no-timing`; not deterministic).
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub seconds: Option<f64>,
    /// Per-stage timing (absent with `--no-timing`; not deterministic).
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub timing: Option<Timing>,
}

/// Where the inputs of a report came from.
#[derive(Debug, Clone)]
pub struct ReportInputs<'a> {
    /// Model file as given.
    pub model_path: &'a str,
    /// Image file as given.
    pub image_path: &'a str,
    /// Landmark file as given.
    pub pts_path: &'a str,
    /// Whether the landmarks were read 1-based.
    pub pts_one_based: bool,
    /// The detector calibration file as given, if the landmarks were corrected with one.
    pub landmark_calibration: Option<&'a str>,
}

/// Builds `fit.json`'s content; `seconds` is the total wall time (None: no timing fields).
pub fn report(
    model: &GpModel,
    inputs: &ReportInputs<'_>,
    prepared: &Prepared,
    settings: &FitOptions,
    o: &Outcome,
    seconds: Option<f64>,
) -> FitReport {
    let p = &o.params;
    let size = settings.size;
    let fitted: Vec<[f32; 2]> = o.fitted_landmarks.iter().map(|q| prepared.crop.to_original(*q, size)).collect();
    let timing = seconds.map(|_| Timing {
        landmark_chain_seconds: o.landmark_seconds,
        image_chain_seconds: o.image_seconds,
        landmark_step_us: o.landmark_seconds * 1e6 / f64::from(settings.fit.landmarks.steps.max(1)),
        image_step_ms: o.image_seconds * 1e3 / f64::from(settings.fit.image.steps.max(1)),
    });
    FitReport {
        format: "gpmm-fit".into(),
        version: 1,
        model: inputs.model_path.to_string(),
        model_kernel: model.metadata.kernel.clone(),
        model_vertices: model.vertices(),
        model_ranks: [model.shape.rank(), model.color.rank()],
        fitted_ranks: [p.shape_len(), p.color_len()],
        image: inputs.image_path.to_string(),
        landmarks_file: inputs.pts_path.to_string(),
        landmark_calibration: inputs.landmark_calibration.map(str::to_string),
        settings: settings.fit,
        pts_one_based: inputs.pts_one_based,
        image_size: prepared.original_size,
        crop: prepared.crop,
        crop_outside_fraction: prepared.crop.outside_fraction(prepared.original_size[0], prepared.original_size[1]),
        working_size: size,
        seed: settings.seed,
        landmark_steps: settings.fit.landmarks.steps,
        image_steps: settings.fit.image.steps,
        yaw_deg: p.pose.yaw.to_degrees(),
        pitch_deg: p.pose.pitch.to_degrees(),
        roll_deg: p.pose.roll.to_degrees(),
        photo_pose_deg: crate::photo::pose_in_photo_frame(
            [p.pose.yaw, p.pose.pitch, p.pose.roll],
            p.focal,
            &prepared.crop,
            size,
            prepared.original_size.map(|s| s as f32 * 0.5),
        )
        .map(f32::to_degrees),
        translation_mm: p.pose.translation,
        focal_px: p.focal,
        light: p.light.coeffs,
        shape: p.shape_coeffs().to_vec(),
        color: p.color_coeffs().to_vec(),
        landmark_rmse_px: o.landmark_rmse_px,
        landmark_rmse_original_px: rmse(&fitted, &prepared.original_landmarks),
        landmark_rmse_after_landmark_chain_px: o.landmark_rmse_after_landmark_chain_px,
        pixel_rmse_after_landmark_chain: o.pixel_rmse_after_landmark_chain,
        pixel_rmse: o.pixel_rmse,
        covered_pixels: o.covered_pixels,
        occluded_fraction: o.occlusion.as_ref().map(|o| o.1),
        log_likelihood: o.image_log_likelihood + o.landmark_log_likelihood,
        log_densities: LogDensities { posterior: o.log_posterior, image: o.image_log_likelihood, landmarks: o.landmark_log_likelihood },
        acceptance: AcceptanceBoth { landmark_chain: o.landmark_acceptance.clone(), image_chain: o.image_acceptance.clone() },
        posterior: Some(o.posterior.clone().with_vertex_spread(o.vertex_sd_mm(model).unwrap_or(&[]))),
        fitted_landmarks: fitted,
        seconds,
        timing,
    }
}
