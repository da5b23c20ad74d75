//! `gpmm fit`'s file job: read the model, photo, landmarks and calibration, fit, and write
//! `fit.json`, `overlay.png` and `fit.ply`.

use super::error::FitRunError;
use super::input::{load_photo, Prepared};
use super::options::FitOptions;
use super::overlay::overlay;
use super::pipeline::{fit_prepared, Outcome};
use super::report::{report, FitReport, ReportInputs};
use crate::gp::model::GpModel;
use crate::photo::calibration::LandmarkCalibration;
use std::path::Path;
use std::time::Instant;

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
    write_fit_files(&model, &prepared, &outcome, &rep, &job.out_dir)?;
    Ok(rep)
}

/// Writes a fit's `fit.json` (`rep`), `overlay.png`, `spread.png` (how sure the fit is of each part
/// of the surface) and `fit.ply` into `dir` (created if needed), and for an occlusion-aware fit
/// `occlusion.png` (its labels on the photo, white: occluded).
pub fn write_fit_files(model: &GpModel, prepared: &Prepared, outcome: &Outcome, rep: &FitReport, dir: &Path) -> Result<(), FitFilesError> {
    let werr = |path: &Path, e: &dyn std::fmt::Display| FitFilesError::Write { path: path.to_path_buf(), message: e.to_string() };
    std::fs::create_dir_all(dir).map_err(|e| werr(dir, &e))?;
    let json_path = dir.join("fit.json");
    let text = serde_json::to_string_pretty(rep).map_err(|e| werr(&json_path, &e))?;
    std::fs::write(&json_path, text + "\n").map_err(|e| werr(&json_path, &e))?;
    let ov_path = dir.join("overlay.png");
    let ov =
        overlay(&prepared.image, &outcome.render, outcome.occlusion.as_ref().map(|o| &o.0), &prepared.landmarks, &outcome.fitted_landmarks);
    crate::render::figure::save_png_fast(&ov, &ov_path).map_err(|e| werr(&ov_path, &e))?;
    if let Some((labels, _)) = &outcome.occlusion {
        let occ_path = dir.join("occlusion.png");
        let photo = super::overlay::labels_in_photo(labels, &prepared.crop, prepared.original_size);
        photo.save(&occ_path).map_err(|e| werr(&occ_path, &e))?;
    }
    let vertex_sd = outcome.vertex_sd_mm(model)?;
    if !vertex_sd.is_empty() {
        let spread_path = dir.join("spread.png");
        let picture = super::spread_picture::spread_picture(model, &outcome.params, vertex_sd, &prepared.image)?;
        crate::render::figure::save_png_fast(&picture, &spread_path).map_err(|e| werr(&spread_path, &e))?;
    }
    let ply_path = dir.join("fit.ply");
    let mesh = model
        .instance(outcome.params.shape_coeffs(), outcome.params.color_coeffs())
        .map_err(|e| FitRunError::Model(format!("instance: {e}")))?;
    let attribution = model.metadata.template.attribution.clone().unwrap_or_default();
    let comments: Vec<&str> = if attribution.is_empty() { vec![] } else { vec![attribution.as_str()] };
    // Each vertex's spread along its normal rides along as its quality.
    let quality = (vertex_sd.len() == mesh.positions.len()).then_some(vertex_sd);
    crate::mesh::io::write_ply_with_quality(&ply_path, &mesh, quality, crate::mesh::io::PlyEncoding::BinaryLittleEndian, &comments)
        .map_err(|e| werr(&ply_path, &e))?;
    Ok(())
}
