//! Learning a model from unlabelled images (`gpmm learn`): the wake–sleep loop of the paper's
//! second half, without labels, landmark files or poses.
//!
//! One iteration, from the current model:
//! 1. **Start** ([`wake_image`]): the init file's finder and initializer read each image (and its
//!    mirror image with `mirror`): box, landmarks, pose.
//! 2. **Fit**: the landmark chain puts the model onto the initializer's points (their σ wider than a
//!    landmark file's, as `gpmm fit --init` sets it), the image chain fits everything to the pixels.
//! 3. **Quality control**: the silhouette of the start (the landmark chain's result) and of the fit
//!    must overlap by at least [`MIN_IOU`] (intersection over union, the paper's r₁ = 0.625, a
//!    ratio of areas that needs no conversion): a fit that ran off its start explains something
//!    other than the face the initializer saw and is rejected.
//! 4. **Model** ([`learned_model`]): the accepted fits' shapes and albedos (the image chain's
//!    posterior means, in the model's frame, so already aligned) are the examples of a PCA, the next
//!    model, in the template's topology with its landmarks.
//!
//! Not yet part of the loop: shape from shading (per-vertex detail beyond the model's subspace) and
//! retraining the initializer on the learned models; without the first, a learned model lies in
//! the span of its predecessor's leading components (its mean and covariance move, its span does not).

pub mod run;
pub mod shading;
pub mod silhouette;

use std::path::{Path, PathBuf};
use std::time::Instant;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::detect::Detector;
use crate::eval::models::pca::pca_model;
use crate::fit::{fit_prepared, prepare, FitOptions};
use crate::gp::model::{GpModel, LearningRecord};
use crate::mesh::Mesh;
use gpmm_core::net::face::Reading;

/// The least silhouette overlap (intersection over union) of a fit with its start (the paper's r₁).
pub const MIN_IOU: f64 = 0.625;
/// The least finder score taken as a face.
pub const MIN_SCORE: f32 = 0.05;

/// How a learning run fits its images.
#[derive(Debug, Clone)]
pub struct LearnSettings {
    /// Fit settings (the initializer's landmark σ included).
    pub fit: FitOptions,
    /// The least silhouette overlap of an accepted fit.
    pub min_iou: f64,
    /// Also fit each image's mirror image.
    pub mirror: bool,
}

/// What became of one image in one iteration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ImageRecord {
    /// The image file.
    pub image: String,
    /// Whether this is the image's mirror image.
    pub mirrored: bool,
    /// Whether the fit went into the next model.
    pub accepted: bool,
    /// Why not, when it did not.
    pub reason: Option<String>,
    /// Silhouette overlap of the fit with its start.
    pub iou: Option<f64>,
    /// The finder's score.
    pub score: Option<f32>,
    /// Per-channel colour RMSE of the fit over the pixels it covers.
    pub pixel_rmse: Option<f32>,
    /// Fitted yaw, pitch, roll (degrees).
    pub angles_deg: Option<[f32; 3]>,
    /// Seconds for this image.
    pub seconds: f64,
}

/// One image's outcome: its record and, when accepted, its reconstruction (model frame).
#[derive(Debug, Clone)]
pub struct Wake {
    /// The record.
    pub record: ImageRecord,
    /// The fitted shape and albedo, if accepted.
    pub reconstruction: Option<Mesh>,
}

/// Starts, fits and checks one image (its mirror image with `mirrored`); every failure becomes a
/// rejected record naming its cause, never an error of the run.
pub fn wake_image(model: &GpModel, init: &[u8], image: &Path, mirrored: bool, settings: &LearnSettings) -> Wake {
    let t0 = Instant::now();
    let mut record = ImageRecord {
        image: image.display().to_string(),
        mirrored,
        accepted: false,
        reason: None,
        iou: None,
        score: None,
        pixel_rmse: None,
        angles_deg: None,
        seconds: 0.0,
    };
    let reconstruction = match fit_and_check(model, init, image, mirrored, settings, &mut record) {
        Ok(mesh) => mesh,
        Err(reason) => {
            record.reason = Some(reason);
            None
        }
    };
    record.accepted = reconstruction.is_some();
    record.seconds = t0.elapsed().as_secs_f64();
    Wake { record, reconstruction }
}

/// The body of [`wake_image`]: the reconstruction if accepted, `None` if rejected by the overlap
/// (the record says so), or the reason it could not be fitted.
fn fit_and_check(
    model: &GpModel,
    init: &[u8],
    image: &Path,
    mirrored: bool,
    settings: &LearnSettings,
    record: &mut ImageRecord,
) -> Result<Option<Mesh>, String> {
    let mut photo = crate::photo::load_rgb(image).map_err(|e| e.to_string())?;
    if mirrored {
        image::imageops::flip_horizontal_in_place(&mut photo);
    }
    let mut detector = Detector::from_bytes(init).map_err(|e| format!("init file: {e}"))?;
    let detection = detector.detect(&photo, MIN_SCORE, Reading::DEFAULT).map_err(|e| e.to_string())?;
    let Some(det) = detection else { return Err("no face found".into()) };
    record.score = Some(det.face.score);
    let (points, _) = crate::photo::pts::within_margin(&det.landmarks, photo.width(), photo.height());
    let prepared = prepare(&photo, &points, settings.fit.size).map_err(|e| e.to_string())?;
    let outcome = fit_prepared(model, &prepared, &settings.fit, &mut |_, _, _| {}).map_err(|e| e.to_string())?;
    let start = silhouette::render_params(model, &outcome.landmark_params, &settings.fit).map_err(|e| e.to_string())?;
    let overlap = silhouette::iou(&silhouette::coverage(&start), &silhouette::coverage(&outcome.render));
    record.iou = Some(overlap);
    record.pixel_rmse = Some(outcome.pixel_rmse);
    let pose = outcome.params.pose;
    record.angles_deg = Some([pose.yaw, pose.pitch, pose.roll].map(f32::to_degrees));
    if overlap < settings.min_iou {
        record.reason = Some(format!("the fit's silhouette overlaps its start's by {overlap:.3}, below {:.3}", settings.min_iou));
        return Ok(None);
    }
    let mean = outcome.posterior.mean_params(&outcome.params);
    let mesh = model.instance(mean.shape_coeffs(), mean.color_coeffs()).map_err(|e| e.to_string())?;
    Ok(Some(mesh))
}

/// Every image (and mirror image) of one iteration, in parallel on `jobs` threads, in input order;
/// `progress(done, total)` after each.
pub fn wake(
    model: &GpModel,
    init: &[u8],
    images: &[PathBuf],
    settings: &LearnSettings,
    jobs: usize,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Vec<Wake>, rayon::ThreadPoolBuildError> {
    let views: Vec<(&PathBuf, bool)> =
        images.iter().flat_map(|p| std::iter::once((p, false)).chain(settings.mirror.then_some((p, true)))).collect();
    let pool = rayon::ThreadPoolBuilder::new().num_threads(jobs.max(1)).build()?;
    let done = std::sync::atomic::AtomicUsize::new(0);
    Ok(pool.install(|| {
        views
            .par_iter()
            .map(|(p, m)| {
                let w = wake_image(model, init, p, *m, settings);
                progress(done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1, views.len());
                w
            })
            .collect()
    }))
}

/// Why an iteration made no model.
#[derive(Debug, thiserror::Error)]
pub enum LearnError {
    /// Fewer than two fits were accepted: no covariance to learn.
    #[error("iteration {iteration}: {accepted} of {images} fits accepted; a model needs at least 2 (see the per-image records for why)")]
    TooFewAccepted {
        /// The iteration.
        iteration: u32,
        /// Fits accepted.
        accepted: usize,
        /// Images fitted.
        images: usize,
    },
    /// The PCA failed.
    #[error(transparent)]
    Pca(#[from] crate::eval::EvalError),
}

/// The next model: the PCA of the accepted reconstructions of `wakes`, in `previous`'s topology
/// with its landmarks, its template's provenance and attribution, and a record of the iteration.
pub fn learned_model(previous: &GpModel, wakes: &[Wake], record: LearningRecord) -> Result<GpModel, LearnError> {
    let examples: Vec<Mesh> = wakes.iter().filter_map(|w| w.reconstruction.clone()).collect();
    if examples.len() < 2 {
        return Err(LearnError::TooFewAccepted { iteration: record.iteration, accepted: examples.len(), images: wakes.len() });
    }
    let source = format!("learned by gpmm learn (iteration {}) from {} of {} images", record.iteration, record.accepted, record.images);
    let attribution = previous.metadata.template.attribution.clone().unwrap_or_default();
    let mut model = pca_model(&examples, &previous.triangles, &previous.landmarks, "learned", &source, &attribution)?;
    model.metadata.template = previous.metadata.template.clone();
    model.metadata.landmark_scheme = previous.metadata.landmark_scheme.clone();
    model.metadata.units = previous.metadata.units.clone();
    model.metadata.learning = Some(record);
    Ok(model)
}

/// Counts of an iteration's records: (accepted, rejected by overlap, failed).
pub fn counts(records: &[ImageRecord]) -> (usize, usize, usize) {
    let accepted = records.iter().filter(|r| r.accepted).count();
    let overlap = records.iter().filter(|r| !r.accepted && r.iou.is_some()).count();
    (accepted, overlap, records.len() - accepted - overlap)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(accepted: bool, iou: Option<f64>) -> ImageRecord {
        ImageRecord {
            image: "a.png".into(),
            mirrored: false,
            accepted,
            reason: None,
            iou,
            score: None,
            pixel_rmse: None,
            angles_deg: None,
            seconds: 0.0,
        }
    }

    #[test]
    fn counts_split_accepted_overlap_and_failed() {
        let r = [record(true, Some(0.9)), record(false, Some(0.3)), record(false, None), record(true, Some(0.7))];
        assert_eq!(counts(&r), (2, 1, 1));
    }
}
