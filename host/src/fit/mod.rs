//! Fitting a model to a photo (`gpmm fit`): crop around the landmarks, the core's landmark chain,
//! a least-squares light, the core's image chain; `fit.json`, `overlay.png` and `fit.ply`.
//!
//! Steps ([`fit_prepared`]; 2 to 5 are the core's [`standard_fit`], which the firmware runs too,
//! described step by step in `gpmm_core::fit::recipe`):
//! 1. The photo is cropped and resampled to `size × size` ([`crate::photo`]); the landmarks follow.
//! 2. Start ([`gpmm_core::fit::initial_guess`]): the scaled-orthographic pose of the mean face's
//!    landmarks, at [`gpmm_core::fit::StartSettings::nominal_distance_mm`] (the focal length
//!    follows from that distance).
//! 3. Landmark chain (`prior × landmarks`, no rendering), [`gpmm_core::fit::LandmarkSettings::steps`]
//!    steps on the pose (jaw contour σ × 3).
//! 4. The SH light of its best sample, solved in closed form (the "landmark-only result", the
//!    baseline of the pixel RMSE), then the start's shape solve (Gauss–Newton on the landmarks
//!    and the image).
//! 5. Image chain (`prior × landmarks × image`, delayed acceptance),
//!    [`gpmm_core::fit::ImageSettings::steps`] steps on pose, colour and light; its second half is
//!    summarized as the posterior ([`PosteriorSummary`]).
//!
//! Both chains run once each, reporting progress through the core's step callback. The
//! result is a deterministic function of the inputs, the settings and the seed: `fit.json` is
//! bit-identical across runs except for `seconds` and `timing` (omitted with `--no-timing`).

mod buffers;
mod observe;
mod options;
mod overrides;
mod posterior;
pub mod register;

use crate::gp::model::GpModel;
use crate::photo::calibration::{CalibrationError, LandmarkCalibration};
use crate::photo::pts::PtsError;
use crate::photo::{crop_box, crop_resize, CropBox, PhotoError};
use crate::render::{Background, HostRasterizer, ImageSink};
use gpmm_core::error::FitError;
use gpmm_core::fit::{standard_fit, CoveredPixels, TargetImage};
use gpmm_core::model::{FitParams, MorphableModel, MAX_LANDMARKS};
use gpmm_core::render::Cull;
use image::{RgbImage, Rgba, RgbaImage};
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::time::Instant;

pub use buffers::FitBuffers;
pub use gpmm_core::fit::FitSettings;
pub use options::{FitFlags, FitOptions};
pub use overrides::override_settings;
pub use posterior::PosteriorSummary;

/// Shape coefficient capacity of a fit (a model of higher rank is fitted in its first `KS` components).
pub const KS: usize = 200;
/// Colour coefficient capacity of a fit.
pub const KC: usize = 200;
/// The parameter vector of a host fit.
pub type Params = FitParams<KS, KC>;

/// Why a fit failed.
#[derive(Debug, thiserror::Error)]
pub enum FitRunError {
    /// The landmark file was refused.
    #[error(transparent)]
    Pts(#[from] PtsError),
    /// The photo was refused.
    #[error(transparent)]
    Photo(#[from] PhotoError),
    /// The landmarks could not be corrected with the detector calibration.
    #[error("{}: {error}", path.display())]
    Calibration {
        /// The landmark file.
        path: std::path::PathBuf,
        /// What went wrong.
        error: CalibrationError,
    },
    /// The detector calibration file could not be read (the error names the file).
    #[error(transparent)]
    CalibrationFile(CalibrationError),
    /// The settings are out of range.
    #[error("{0}")]
    Settings(String),
    /// The model cannot be fitted (no landmarks, inconsistent arrays).
    #[error("the model cannot be fitted: {0}")]
    Model(String),
    /// The core fitter refused its input.
    #[error("{stage}: the core fitter refused the input: {error}")]
    Core {
        /// Which stage.
        stage: &'static str,
        /// The core's error.
        error: FitError,
    },
}

fn core(stage: &'static str) -> impl Fn(FitError) -> FitRunError {
    move |error| FitRunError::Core { stage, error }
}

/// A photo cropped and resampled for fitting, with its landmarks in both images.
#[derive(Debug, Clone)]
pub struct Prepared {
    /// The working image (`size × size`).
    pub image: RgbImage,
    /// Landmarks in the working image (continuous pixel coordinates).
    pub landmarks: Vec<[f32; 2]>,
    /// The crop in the original image.
    pub crop: CropBox,
    /// The working pixels the photo covers (the rest of the crop lay past its edge).
    pub covered: CoveredPixels,
    /// Original image size.
    pub original_size: [u32; 2],
    /// Landmarks in the original image.
    pub original_landmarks: Vec<[f32; 2]>,
}

/// Crops `image` around `points` (original-image landmarks) and resamples it to `size × size`.
pub fn prepare(image: &RgbImage, points: &[[f32; 2]], size: u32) -> Result<Prepared, FitRunError> {
    let crop = crop_box(points, image.width(), image.height())?;
    Ok(Prepared {
        image: crop_resize(image, &crop, size),
        landmarks: points.iter().map(|p| crop.to_working(*p, size)).collect(),
        covered: crop.covered(size, image.width(), image.height()),
        crop,
        original_size: [image.width(), image.height()],
        original_landmarks: points.to_vec(),
    })
}

/// Proposal counts of one proposal kind.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct KindCounts {
    /// Times drawn.
    pub proposed: u64,
    /// Times it passed the prior-and-landmark stage.
    pub passed: u64,
    /// Times accepted.
    pub accepted: u64,
}

/// Counts per proposal kind name (`yaw`, `shape`, `light-solve`, ...).
pub type AcceptanceReport = BTreeMap<String, KindCounts>;

/// The result of [`fit_prepared`] (working-image units unless stated).
#[derive(Debug, Clone)]
pub struct Outcome {
    /// The best sample of the image chain (the fit).
    pub params: Params,
    /// The landmark-only result: the landmark chain's best sample with the least-squares light.
    pub landmark_params: Params,
    /// Landmark RMSE of the fit (px).
    pub landmark_rmse_px: f32,
    /// Landmark RMSE of the landmark-only result (px).
    pub landmark_rmse_after_landmark_chain_px: f32,
    /// Per-channel colour RMSE over covered pixels of the landmark-only result.
    pub pixel_rmse_after_landmark_chain: f32,
    /// Per-channel colour RMSE over covered pixels of the fit.
    pub pixel_rmse: f32,
    /// Log posterior of the fit (up to a constant).
    pub log_posterior: f32,
    /// Image log likelihood ratio of the fit (foreground against background).
    pub image_log_likelihood: f32,
    /// Landmark log likelihood of the fit.
    pub landmark_log_likelihood: f32,
    /// Pixels the fit covers.
    pub covered_pixels: u32,
    /// Landmark-chain counts.
    pub landmark_acceptance: AcceptanceReport,
    /// Image-chain counts.
    pub image_acceptance: AcceptanceReport,
    /// The image chain's posterior summary (its second half).
    pub posterior: PosteriorSummary,
    /// The fit's projected model landmarks.
    pub fitted_landmarks: Vec<[f32; 2]>,
    /// The fit rendered (transparent where the model does not cover).
    pub render: RgbaImage,
    /// Seconds in the landmark chain.
    pub landmark_seconds: f64,
    /// Seconds in the light solve and the image chain.
    pub image_seconds: f64,
}

/// Fits `model` to a prepared photo; `progress(phase, done, total)` reports steps per chain.
pub fn fit_prepared(
    model: &GpModel,
    prepared: &Prepared,
    settings: &FitOptions,
    progress: &mut dyn FnMut(&str, u64, u64),
) -> Result<Outcome, FitRunError> {
    settings.validate()?;
    let (w, h) = (settings.size, settings.size);
    if prepared.image.dimensions() != (w, h) {
        return Err(FitRunError::Settings(format!("the prepared image is {:?}, not {w}x{h}", prepared.image.dimensions())));
    }
    let n_lm = model.landmarks.len();
    if n_lm == 0 || n_lm > MAX_LANDMARKS {
        return Err(FitRunError::Model(format!("it has {n_lm} landmarks (1 to {MAX_LANDMARKS} are needed)")));
    }
    if prepared.landmarks.len() != n_lm {
        return Err(FitRunError::Settings(format!("{} target landmarks for a model with {n_lm}", prepared.landmarks.len())));
    }
    // The shape basis at the landmarks, contiguous: every shape proposal's landmark sums read it.
    let full = morphable(model)?;
    let mut landmark_fields = vec![0.0f32; full.shape_rank() * full.landmarks().len()];
    let mm = match full.landmark_fields(&mut landmark_fields) {
        Some(()) => full.with_landmark_fields(&landmark_fields).map_err(core("landmark fields"))?,
        None => full,
    };
    let core_settings = settings.core();
    let pixels: Vec<[u8; 3]> = prepared.image.pixels().map(|p| p.0).collect();
    let target = TargetImage::new(&pixels, w, h).and_then(|t| t.with_covered(prepared.covered)).map_err(core("target image"))?;
    let valid = vec![true; n_lm];
    let mut buffers = FitBuffers::host(mm.vertices(), w, h);
    let mut inst = buffers.instance::<KS, KC>().map_err(core("instance"))?;
    let mut raster: Box<HostRasterizer> = Box::new(HostRasterizer::new());
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(settings.seed);

    // One run of the core's standard fit; the observer reports progress, splits the time and
    // counts the proposals by name.
    let mut observer = observe::HostObserver::new(progress, core_settings.image.steps / 2);
    let result = standard_fit(&mm, target, &prepared.landmarks, &valid, &core_settings, &mut inst, &mut raster, &mut rng, &mut observer)
        .map_err(core("fit"))?;
    let landmark_seconds = observer.landmark_seconds;
    let image_seconds = observer.elapsed() - landmark_seconds;
    let posterior = PosteriorSummary::of(&observer.posterior);
    let (landmark_acceptance, image_acceptance) = (observer.landmark, observer.image);
    let best = result.image;
    let start = result.start;
    let start_eval = result.start_image;
    let fit = best.best;
    let img_eval = best.best_image.ok_or(FitRunError::Core { stage: "image chain", error: FitError::BadConfig })?;

    // The fit's render and landmarks.
    inst.update(&mm, &fit, w, h).map_err(core("final render"))?;
    let mut sink = ImageSink::new(w, h, Background::Transparent);
    raster.render(inst.projected(), mm.triangles(), w, h, Cull::Clockwise, &mut sink).map_err(|e| core("final render")(e.into()))?;
    let fitted_landmarks = project_landmarks(&mm, &fit, w, h)?;

    Ok(Outcome {
        params: fit,
        landmark_params: start,
        landmark_rmse_px: best.best_landmarks.rmse(),
        landmark_rmse_after_landmark_chain_px: result.start_landmarks.rmse(),
        pixel_rmse_after_landmark_chain: start_eval.rmse(),
        pixel_rmse: img_eval.rmse(),
        log_posterior: best.best_log_posterior,
        image_log_likelihood: img_eval.log_likelihood,
        landmark_log_likelihood: best.best_landmarks.log_likelihood,
        covered_pixels: img_eval.covered,
        landmark_acceptance,
        image_acceptance,
        posterior,
        fitted_landmarks,
        render: sink.into_image(),
        landmark_seconds,
        image_seconds,
    })
}

/// The core's view of a model.
pub fn morphable(model: &GpModel) -> Result<MorphableModel<'_>, FitRunError> {
    let shape_basis = model.shape.core_basis().map_err(|e| FitRunError::Model(format!("shape basis: {e}")))?;
    let color_basis = model.color.core_basis().map_err(|e| FitRunError::Model(format!("colour basis: {e}")))?;
    MorphableModel::new(&model.shape.mean, &model.color.mean, shape_basis, color_basis, &model.triangles, &model.landmarks)
        .map_err(|e| FitRunError::Model(format!("{e}")))
}

/// [`project_landmarks`] for a [`GpModel`] and a square `size × size` image.
pub fn project_landmarks_of(model: &GpModel, params: &Params, size: u32) -> Result<Vec<[f32; 2]>, FitRunError> {
    project_landmarks(&morphable(model)?, params, size, size)
}

/// The model landmarks of `params` projected into a `width × height` image (NaN if behind the camera).
pub fn project_landmarks(mm: &MorphableModel<'_>, params: &Params, width: u32, height: u32) -> Result<Vec<[f32; 2]>, FitRunError> {
    let mut out = vec![[0.0f32; 2]; mm.landmarks().len()];
    let n = gpmm_core::fit::project_landmarks(mm, params, width, height, &mut out).map_err(core("landmarks"))?;
    out.truncate(n);
    Ok(out)
}

/// Root-mean-square distance between two point lists (px).
pub fn rmse(a: &[[f32; 2]], b: &[[f32; 2]]) -> f32 {
    let n = a.len().min(b.len()).max(1) as f32;
    let s: f32 = a.iter().zip(b).map(|(p, q)| (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sum();
    (s / n).sqrt()
}

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
        log_likelihood: o.image_log_likelihood + o.landmark_log_likelihood,
        log_densities: LogDensities { posterior: o.log_posterior, image: o.image_log_likelihood, landmarks: o.landmark_log_likelihood },
        acceptance: AcceptanceBoth { landmark_chain: o.landmark_acceptance.clone(), image_chain: o.image_acceptance.clone() },
        posterior: Some(o.posterior.clone()),
        fitted_landmarks: fitted,
        seconds,
        timing,
    }
}

/// Upscaling of the overlay panels (nearest neighbour).
pub const OVERLAY_SCALE: u32 = 3;
/// Colour of the target landmarks in the overlay (green dots).
pub const TARGET_COLOR: Rgba<u8> = Rgba([40, 230, 60, 255]);
/// Colour of the fitted landmarks in the overlay (red crosses).
pub const FITTED_COLOR: Rgba<u8> = Rgba([255, 40, 40, 255]);

/// `input crop | rendered fit | 50 % blend`, each upscaled by [`OVERLAY_SCALE`], target landmarks
/// as green dots and fitted ones as red crosses on the first and last panel, labels on top.
pub fn overlay(crop: &RgbImage, render: &RgbaImage, target: &[[f32; 2]], fitted: &[[f32; 2]]) -> RgbaImage {
    let (w, h) = crop.dimensions();
    let s = OVERLAY_SCALE;
    let (pw, ph) = (w * s, h * s);
    let (gap, header) = (4u32, 14u32);
    let bg = Rgba([24, 24, 24, 255]);
    let mut out = RgbaImage::from_pixel(3 * pw + 4 * gap, ph + header + gap, bg);
    let panel = |i: u32| (gap + i * (pw + gap), header);
    for y in 0..ph {
        for x in 0..pw {
            let c = crop.get_pixel(x / s, y / s).0;
            let r = render.get_pixel(x / s, y / s).0;
            let covered = r[3] > 0;
            let ren = if covered { Rgba([r[0], r[1], r[2], 255]) } else { Rgba([0, 0, 0, 255]) };
            let blend = if covered {
                let avg = |k: usize| (u16::from(c[k]) + u16::from(r[k])).div_ceil(2) as u8;
                Rgba([avg(0), avg(1), avg(2), 255])
            } else {
                Rgba([c[0], c[1], c[2], 255])
            };
            for (i, px) in [Rgba([c[0], c[1], c[2], 255]), ren, blend].into_iter().enumerate() {
                let (ox, oy) = panel(i as u32);
                out.put_pixel(ox + x, oy + y, px);
            }
        }
    }
    let ink = Rgba([230, 230, 230, 255]);
    for (i, label) in ["input", "fit", "blend"].iter().enumerate() {
        let (ox, _) = panel(i as u32);
        crate::render::figure::draw_text(&mut out, ox, 3, label, 1, ink);
    }
    for i in [0u32, 2] {
        let (ox, oy) = panel(i);
        let to = |p: &[f32; 2]| -> Option<(i64, i64)> {
            let (x, y) = (p[0] * s as f32, p[1] * s as f32);
            (x.is_finite() && y.is_finite() && x >= 0.0 && y >= 0.0 && x < pw as f32 && y < ph as f32)
                .then(|| (i64::from(ox) + x as i64, i64::from(oy) + y as i64))
        };
        for p in target.iter().filter_map(to) {
            for dy in -2..=2 {
                for dx in -2..=2 {
                    if dx * dx + dy * dy <= 5 {
                        put(&mut out, p.0 + dx, p.1 + dy, TARGET_COLOR);
                    }
                }
            }
        }
        for p in fitted.iter().filter_map(to) {
            for d in -3..=3 {
                for t in 0..2 {
                    put(&mut out, p.0 + d + t, p.1 + d, FITTED_COLOR);
                    put(&mut out, p.0 + d + t, p.1 - d, FITTED_COLOR);
                }
            }
        }
    }
    out
}

fn put(img: &mut RgbaImage, x: i64, y: i64, c: Rgba<u8>) {
    if x >= 0 && y >= 0 && x < i64::from(img.width()) && y < i64::from(img.height()) {
        img.put_pixel(x as u32, y as u32, c);
    }
}

/// Inputs of [`fit_files`] (what `gpmm fit` is given).
#[derive(Debug, Clone)]
pub struct FitJob {
    /// Model file.
    pub model: std::path::PathBuf,
    /// Photo (PNG, JPEG or PPM).
    pub image: std::path::PathBuf,
    /// Landmark file (iBUG `.pts`).
    pub landmarks: std::path::PathBuf,
    /// Read the landmark file as 1-based.
    pub pts_one_based: bool,
    /// A detector calibration (`gpmm calibrate-landmarks`) to correct the landmarks with.
    pub landmark_calibration: Option<std::path::PathBuf>,
    /// Fit settings.
    pub settings: FitOptions,
    /// Output directory (created if needed).
    pub out_dir: std::path::PathBuf,
    /// Record timing in `fit.json`.
    pub timing: bool,
}

/// Why [`fit_files`] failed.
#[derive(Debug, thiserror::Error)]
pub enum FitFilesError {
    /// The model file.
    #[error(transparent)]
    ModelFile(#[from] crate::gp::model_io::ModelIoError),
    /// The fit.
    #[error(transparent)]
    Fit(#[from] FitRunError),
    /// An output file.
    #[error("{}: cannot write: {message}", path.display())]
    Write {
        /// The file.
        path: std::path::PathBuf,
        /// What went wrong.
        message: String,
    },
}

/// Loads a photo and its landmarks, checked against the model (count, inside the image), and
/// prepares it; with a detector `calibration` the landmarks are corrected first (and kept inside
/// the image).
pub fn load_photo(
    model: &GpModel,
    image: &std::path::Path,
    landmarks: &std::path::Path,
    one_based: bool,
    size: u32,
    calibration: Option<&LandmarkCalibration>,
) -> Result<Prepared, FitRunError> {
    check_landmarks(model)?;
    let pts = crate::photo::pts::read_pts(landmarks, one_based)?;
    let photo = crate::photo::load_rgb(image)?;
    pts.check(landmarks, model.landmarks.len(), &model.metadata.landmark_scheme, photo.width(), photo.height(), one_based)?;
    let points = match calibration {
        None => pts.points,
        Some(c) => c
            .correct_in_image(&pts.points, photo.width() as f32, photo.height() as f32)
            .map_err(|error| FitRunError::Calibration { path: landmarks.to_path_buf(), error })?,
    };
    prepare(&photo, &points, size)
}

/// Refuses a model without landmarks (e.g. a statismo import without usable ones) before any
/// photo is read, with a message that says what to do.
pub fn check_landmarks(model: &GpModel) -> Result<(), FitRunError> {
    if model.landmarks.is_empty() {
        return Err(FitRunError::Model(
            "it has 0 landmarks (a model imported from .h5 needs them: gpmm import-h5 --landmarks FILE.json)".into(),
        ));
    }
    Ok(())
}

/// Checks in-memory landmarks (`name` stands for their source in messages) against the model and
/// the photo as a landmark file is checked, prepares the photo and fits: what `gpmm fit` does
/// after reading its files, for callers that hold the image and points already (the Python package).
///
/// # Example
///
/// A model built from a tiny closed mesh (no data files) fitted to its own mean face, rendered,
/// with its four landmarks where the render puts them:
///
/// ```
/// use gpmm_host::fit::{fit_image, FitFlags};
/// use gpmm_host::gp::kernel::ModelKernel;
/// use gpmm_host::gp::lowrank::{NystromOptions, RankSpec};
/// use gpmm_host::gp::model::{build_model, BuildOptions};
/// use gpmm_host::mesh::template::{Mesh, Provenance, Template};
/// use gpmm_host::render::{render_model, RenderSettings, View};
///
/// // An octahedron, 120 × 160 × 100 mm, each face cut in four twice; landmarks at its corners.
/// let mut positions = vec![[60.0, 0.0, 0.0], [-60.0, 0.0, 0.0], [0.0, 80.0, 0.0], [0.0, -80.0, 0.0], [0.0, 0.0, 50.0], [0.0, 0.0, -50.0]];
/// let mut triangles: Vec<[u32; 3]> = vec![[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]];
/// for _ in 0..2 {
///     let mut midpoints = std::collections::HashMap::new();
///     let mut next = Vec::new();
///     for t in &triangles {
///         let mut mid = |a: u32, b: u32| -> u32 {
///             *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
///                 let (p, q): ([f64; 3], [f64; 3]) = (positions[a as usize], positions[b as usize]);
///                 positions.push([(p[0] + q[0]) / 2.0, (p[1] + q[1]) / 2.0, (p[2] + q[2]) / 2.0]);
///                 (positions.len() - 1) as u32
///             })
///         };
///         let (ab, bc, ca) = (mid(t[0], t[1]), mid(t[1], t[2]), mid(t[2], t[0]));
///         next.extend([[t[0], ab, ca], [ab, t[1], bc], [ca, bc, t[2]], [ab, bc, ca]]);
///     }
///     triangles = next;
/// }
/// let colors = positions.iter().map(|p| [0.6 + p[0] / 300.0, 0.45, 0.35]).collect();
/// let template = Template {
///     mesh: Mesh { positions, colors, triangles },
///     landmarks: vec![0, 1, 2, 3],
///     scheme: "corners".into(),
///     provenance: Provenance { source: "octahedron".into(), scale_mm_per_unit: 1.0, ..Default::default() },
/// };
/// let build = BuildOptions {
///     kernel: ModelKernel::SymmetricFull,
///     hyperparameters: Default::default(),
///     rank_shape: RankSpec::Count(8),
///     rank_color: RankSpec::Count(4),
///     nystrom: NystromOptions { points: 60, ..Default::default() },
/// };
/// let model = build_model(&template, &build, |_, _, _| {});
///
/// // The photo: the mean face rendered at 128 × 128 (x right, y up: the top corner near the top).
/// let settings = RenderSettings { width: 128, height: 128, ..RenderSettings::default() };
/// let render = render_model(&model, &[], &[], View::default(), &settings)?;
/// let photo = image::DynamicImage::ImageRgba8(render).to_rgb8();
/// let landmarks = [[104.0, 64.0], [24.0, 64.0], [64.0, 11.0], [64.0, 117.0]];
///
/// // Short chains on a 64 × 64 working image: what the user gave, resolved into the options once.
/// let flags = FitFlags { size: Some(64), landmark_steps: Some(300), image_steps: Some(20), ..FitFlags::default() };
/// let options = flags.resolve()?;
/// let (prepared, outcome) = fit_image(&model, &photo, &landmarks, "corners", &options, &mut |_, _, _| {})?;
/// assert_eq!(prepared.image.dimensions(), (64, 64));
/// assert_eq!(outcome.fitted_landmarks.len(), 4);
/// assert!(outcome.pixel_rmse.is_finite() && outcome.landmark_rmse_px.is_finite());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn fit_image(
    model: &GpModel,
    photo: &RgbImage,
    points: &[[f32; 2]],
    name: &str,
    settings: &FitOptions,
    progress: &mut dyn FnMut(&str, u64, u64),
) -> Result<(Prepared, Outcome), FitRunError> {
    settings.validate()?;
    check_landmarks(model)?;
    let path = std::path::Path::new(name);
    if let Some(i) = points.iter().position(|p| !(p[0].is_finite() && p[1].is_finite())) {
        return Err(FitRunError::Settings(format!("{name}: landmark {i} is not finite")));
    }
    let pts = crate::photo::pts::Pts { points: points.to_vec(), lines: (1..=points.len()).collect() };
    pts.check(path, model.landmarks.len(), &model.metadata.landmark_scheme, photo.width(), photo.height(), true)?;
    let prepared = prepare(photo, points, settings.size)?;
    let outcome = fit_prepared(model, &prepared, settings, progress)?;
    Ok((prepared, outcome))
}

/// `gpmm fit`: loads everything, fits and writes `fit.json`, `overlay.png` and `fit.ply` into the output directory.
pub fn fit_files(job: &FitJob, progress: &mut dyn FnMut(&str, u64, u64)) -> Result<FitReport, FitFilesError> {
    job.settings.validate()?;
    let model = crate::gp::model_io::load(&job.model)?;
    let t0 = Instant::now();
    let calibration = match &job.landmark_calibration {
        Some(path) => Some(LandmarkCalibration::read(path).map_err(FitRunError::CalibrationFile)?),
        None => None,
    };
    let prepared = load_photo(&model, &job.image, &job.landmarks, job.pts_one_based, job.settings.size, calibration.as_ref())?;
    let outcome = fit_prepared(&model, &prepared, &job.settings, progress)?;
    let seconds = t0.elapsed().as_secs_f64();
    let calibration_name = job.landmark_calibration.as_ref().map(|p| p.display().to_string());
    let inputs = ReportInputs {
        model_path: &job.model.display().to_string(),
        image_path: &job.image.display().to_string(),
        pts_path: &job.landmarks.display().to_string(),
        pts_one_based: job.pts_one_based,
        landmark_calibration: calibration_name.as_deref(),
    };
    let rep = report(&model, &inputs, &prepared, &job.settings, &outcome, job.timing.then_some(seconds));
    let dir = &job.out_dir;
    let werr =
        |path: &std::path::Path, e: &dyn std::fmt::Display| FitFilesError::Write { path: path.to_path_buf(), message: e.to_string() };
    std::fs::create_dir_all(dir).map_err(|e| werr(dir, &e))?;
    let json_path = dir.join("fit.json");
    let text = serde_json::to_string_pretty(&rep).map_err(|e| werr(&json_path, &e))?;
    std::fs::write(&json_path, text + "\n").map_err(|e| werr(&json_path, &e))?;
    let ov_path = dir.join("overlay.png");
    let ov = overlay(&prepared.image, &outcome.render, &prepared.landmarks, &outcome.fitted_landmarks);
    crate::render::figure::save_png(&ov, &ov_path).map_err(|e| werr(&ov_path, &e))?;
    let ply_path = dir.join("fit.ply");
    let mesh = model
        .instance(outcome.params.shape_coeffs(), outcome.params.color_coeffs())
        .map_err(|e| FitRunError::Model(format!("instance: {e}")))?;
    let attribution = model.metadata.template.attribution.clone().unwrap_or_default();
    let comments: Vec<&str> = if attribution.is_empty() { vec![] } else { vec![attribution.as_str()] };
    crate::mesh::io::write_ply_with(&ply_path, &mesh, crate::mesh::io::PlyEncoding::BinaryLittleEndian, &comments)
        .map_err(|e| werr(&ply_path, &e))?;
    Ok(rep)
}
