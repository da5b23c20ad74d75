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
//! 4. **Shape from shading** ([`shading`], unless turned off): per-vertex shape and albedo beyond
//!    the fit's instance (the image chain's posterior mean), spikes removed against each vertex's
//!    ring. Quality control (the paper's): the mean per-vertex albedo change must stay below
//!    `r₂ − n·r₃` (r₂ = 8, r₃ = 0.5, n = iterations done) in the paper's 0–255 colour units, that
//!    is [`albedo_change_limit`] `= (8 − 0.5 n) / 255` in this project's linear 0–1 albedo (the
//!    images' 8-bit values map to 0–1 by dividing by 255, so one paper unit is 1/255 here): a fit
//!    whose colours need more than that explains the image with something other than the face.
//! 5. **Model** ([`learned_model`]): the accepted reconstructions (the instance plus its detail, in
//!    the model's frame, so already aligned) are the examples of a PCA, the next model, in the
//!    template's topology with its landmarks.
//!
//! 6. **Development check** ([`dev`], when a set with known truth is given): the new model against its
//!    predecessor and the best so far on that set; the run keeps the best.
//! 7. **Retraining** (a call-out of [`run::run_with`]): the finder and initializer fine-tuned on every
//!    model so far; the next iteration starts from them.

pub mod dev;
pub mod landmarks;
pub mod run;
pub mod shading;
pub mod silhouette;

use std::path::{Path, PathBuf};
use std::time::Instant;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::detect::{choose_face, Detector, DEFAULT_MIN_SCORE};
use crate::eval::models::pca::{pca_beside, KeptCovariance};
use crate::fit::{fit_prepared, prepare, FitFlags, FitOptions, FitRunError, FitSettings};
use crate::gp::model::{GpModel, LearningRecord};
use crate::mesh::Mesh;
use gpmm_core::fit::TargetImage;
use gpmm_core::net::face::Reading;
use shading::{shape_from_shading, ShadingModel, ShadingSettings};

/// The least silhouette overlap (intersection over union) of a fit with its start (the paper's r₁).
pub const MIN_IOU: f64 = 0.625;
/// The paper's albedo-change threshold r₂ and its fall per iteration r₃, in 0–255 colour units.
pub const ALBEDO_CHANGE_PAPER: (f32, f32) = (8.0, 0.5);

/// The largest mean per-vertex albedo change (linear 0–1 colour) accepted after `done`
/// iterations: the paper's `r₂ − n·r₃` over 255 (never below zero).
pub fn albedo_change_limit(done: u32) -> f32 {
    let (r2, r3) = ALBEDO_CHANGE_PAPER;
    ((r2 - done as f32 * r3) / 255.0).max(0.0)
}

/// Image-chain steps of the loop's fits: the paper's n₂ (10,000 steps on every parameter).
pub const WAKE_IMAGE_STEPS: u32 = 10_000;

/// The fit settings the loop starts from (flags and `--set` change them): `gpmm fit`'s, with an
/// image chain of [`WAKE_IMAGE_STEPS`] steps that fits the shape as well. With `gpmm fit`'s chain
/// (shape from the landmarks and the start's solve alone) the mean of 180 fits stayed where the
/// model's mean was, exact points or not (docs/learning.md, "What moves the mean").
pub fn wake_fit_options() -> FitOptions {
    FitOptions { fit: FitSettings::DEFAULT.with_image_shape(WAKE_IMAGE_STEPS), ..FitOptions::DEFAULT }
}

/// The fit options of the loop and of its development check, from the same flags: the loop's
/// over [`wake_fit_options`], the check's over `gpmm fit`'s defaults (the learned model is
/// measured as users fit it).
pub fn loop_and_check_options(flags: &FitFlags) -> Result<(FitOptions, FitOptions), FitRunError> {
    Ok((flags.resolve_from(wake_fit_options())?, flags.resolve()?))
}

/// The share of the previous model's covariance a learned model keeps by default: on the
/// development set its fits identified 76.7 % of the probes (exact landmarks) where the template
/// model's identified 70.0 %, a model of the fits alone 17.2 % and a share of 1 72.8 %.
pub const DEFAULT_KEEP_VARIANCE: f64 = 0.5;

/// How a learning run fits its images (serializable, so that workers elsewhere fit alike).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LearnSettings {
    /// Fit settings (the initializer's landmark σ included).
    pub fit: FitOptions,
    /// The least silhouette overlap of an accepted fit.
    pub min_iou: f64,
    /// Also fit each image's mirror image.
    pub mirror: bool,
    /// Shape from shading after each accepted fit (`None`: the fitted instance alone).
    pub shading: Option<ShadingSettings>,
    /// The largest mean per-vertex albedo change of shape from shading an accepted image may have
    /// (linear 0–1 colour; a run sets it to [`albedo_change_limit`] of the iterations done).
    pub max_albedo_change: f32,
    /// Read each image's start points from `DIR/STEM.pts` (a detector's, or any other source)
    /// instead of the init file's initializer; a mirror image's points are mirrored with it.
    pub landmarks_dir: Option<PathBuf>,
    /// The share of the previous model's covariance the learned model keeps beside its fits' (0:
    /// the fits' PCA alone; see [`crate::eval::models::pca::pca_beside`]).
    pub keep_variance: f64,
    /// Learn where the landmark files' points lie on the model: each iteration's model takes the
    /// landmark vertices its accepted fits agree on ([`landmarks`]; needs `landmarks_dir`).
    #[serde(default)]
    pub learn_landmarks: bool,
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
    /// Shape from shading's mean per-vertex albedo change over the vertices it saw (linear 0–1
    /// colour; ×255 for the paper's units).
    #[serde(default)]
    pub albedo_change: Option<f32>,
    /// Shape from shading's mean absolute height over the vertices it saw (mm).
    #[serde(default)]
    pub detail_mm: Option<f32>,
    /// The vertex each of the image's points lands on in the fit (with `learn_landmarks`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub landmark_hits: Option<Vec<Option<u32>>>,
    /// Vertices shape from shading saw.
    #[serde(default)]
    pub detail_vertices: Option<usize>,
    /// Seconds for this image.
    pub seconds: f64,
}

impl ImageRecord {
    /// The record of `image` (mirrored or not) before anything was done with it: not accepted,
    /// no reason, no figures.
    fn unfitted(image: &Path, mirrored: bool) -> Self {
        Self {
            image: image.display().to_string(),
            mirrored,
            accepted: false,
            reason: None,
            iou: None,
            score: None,
            pixel_rmse: None,
            angles_deg: None,
            albedo_change: None,
            detail_mm: None,
            landmark_hits: None,
            detail_vertices: None,
            seconds: 0.0,
        }
    }
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
/// `shading`: the model prepared for shape from shading (when `settings.shading` is set).
pub fn wake_image(
    model: &GpModel,
    shading: Option<&ShadingModel<'_>>,
    init: Option<&[u8]>,
    image: &Path,
    mirrored: bool,
    settings: &LearnSettings,
) -> Wake {
    let t0 = Instant::now();
    let mut record = ImageRecord::unfitted(image, mirrored);
    let reconstruction = match fit_and_check(model, shading, init, image, mirrored, settings, &mut record) {
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
    shading: Option<&ShadingModel<'_>>,
    init: Option<&[u8]>,
    image: &Path,
    mirrored: bool,
    settings: &LearnSettings,
    record: &mut ImageRecord,
) -> Result<Option<Mesh>, String> {
    let mut photo = crate::photo::load_rgb(image).map_err(|e| e.to_string())?;
    if mirrored {
        image::imageops::flip_horizontal_in_place(&mut photo);
    }
    let points = match (&settings.landmarks_dir, init) {
        (Some(dir), _) => file_points(dir, image, &photo, mirrored)?,
        (None, Some(init)) => {
            let mut detector = Detector::from_bytes(init).map_err(|e| format!("init file: {e}"))?;
            let (points, score) = start_points(&mut detector, &photo)?;
            record.score = Some(score);
            points
        }
        (None, None) => return Err("neither an init file nor a landmark directory gives the start points".into()),
    };
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
    if settings.learn_landmarks && settings.landmarks_dir.is_some() {
        let camera = mean.camera(prepared.image.width(), prepared.image.height());
        let hits = landmarks::landmark_hits(
            &mesh,
            &mean.pose,
            &camera,
            &model.shape.mean,
            &model.landmarks,
            &prepared.landmarks,
            landmarks::LANDMARK_SEARCH_MM,
        );
        record.landmark_hits = Some(hits);
    }
    let (Some(sm), Some(sfs)) = (shading, settings.shading.as_ref()) else { return Ok(Some(mesh)) };
    let pixels: Vec<[u8; 3]> = prepared.image.pixels().map(|p| p.0).collect();
    let target = TargetImage::new(&pixels, settings.fit.size, settings.fit.size)
        .and_then(|t| t.with_covered(prepared.covered))
        .map_err(|e| format!("shape from shading: {e}"))?;
    let detail = shape_from_shading(sm, &mean, &target, sfs).map_err(|e| format!("shape from shading: {e}"))?.despiked(sm.neighbours());
    let change = detail.mean_albedo_change();
    record.albedo_change = Some(change);
    record.detail_mm = Some(detail.mean_height());
    record.detail_vertices = Some(detail.seen_count());
    if change > settings.max_albedo_change {
        record.reason = Some(format!(
            "shape from shading changed the albedo by {:.2}/255 per vertex on average, above {:.2}/255",
            change * 255.0,
            settings.max_albedo_change * 255.0
        ));
        return Ok(None);
    }
    Ok(Some(detail.applied_to(&mesh)))
}

/// The smallest face (px) the loop's scan of a photo looks for: it fits one face per photo, the
/// most prominent, and a deeper scan offers it more small faces to choose from (on the 96-photo
/// pool, a development median of 1.453 mm after one iteration; scanning to 32 px, 1.477 mm).
pub const LEARN_SMALLEST_FACE: f32 = 96.0;

/// The start of a fit without a landmark file: the face `gpmm fit --init` takes in `photo` (a
/// photo is scanned for faces down to [`LEARN_SMALLEST_FACE`] px, [`choose_face`] picks one) and
/// the initializer's points on it (those beyond the fit's margin moved onto the frame), with its
/// score.
pub fn start_points(detector: &mut Detector, photo: &image::RgbImage) -> Result<(Vec<[f32; 2]>, f32), String> {
    // The loop picks its face by its own rule ([`choose_face`]) among faces of every size.
    detector.list_every_size(true);
    let faces = detector.scan_for_fit(photo, DEFAULT_MIN_SCORE, LEARN_SMALLEST_FACE, Reading::DEFAULT).map_err(|e| e.to_string())?;
    let Some(det) = choose_face(&faces, None).and_then(|i| faces.get(i)) else { return Err("no face found".into()) };
    let (points, _) = crate::photo::pts::within_margin(&det.landmarks, photo.width(), photo.height());
    Ok((points, det.face.score))
}

/// The points of `image` in `dir/STEM.pts` (iBUG-68, 0-based, checked against `photo`), mirrored
/// with the image when `mirrored` (x → width − x, each point swapped with its iBUG partner).
fn file_points(dir: &Path, image: &Path, photo: &image::RgbImage, mirrored: bool) -> Result<Vec<[f32; 2]>, String> {
    use gpmm_core::model::ibug::{mirrored_ibug68, IBUG68_POINTS};
    let stem = image.file_stem().ok_or_else(|| format!("{}: no file name", image.display()))?;
    let path = dir.join(stem).with_extension("pts");
    let pts = crate::photo::pts::read_pts(&path, false).map_err(|e| e.to_string())?;
    pts.check(&path, IBUG68_POINTS, "ibug68", photo.width(), photo.height(), false).map_err(|e| e.to_string())?;
    if !mirrored {
        return Ok(pts.points);
    }
    Ok(mirrored_ibug68(&pts.points, photo.width() as f32).collect())
}

/// Every image (and mirror image) of one iteration, in parallel on `jobs` threads, in input order;
/// `progress(done, total)` after each.
pub fn wake(
    model: &GpModel,
    init: Option<&[u8]>,
    images: &[PathBuf],
    settings: &LearnSettings,
    jobs: usize,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Vec<Wake>, rayon::ThreadPoolBuildError> {
    let ranks = settings.fit.core().ranks;
    // A model whose bases cannot be prepared fails every image alike, each record saying why.
    let shading = settings.shading.as_ref().map(|sfs| ShadingModel::new(model, ranks.shape, ranks.color, sfs).map_err(|e| e.to_string()));
    let views = views(images, settings.mirror);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(jobs.max(1)).build()?;
    let done = std::sync::atomic::AtomicUsize::new(0);
    Ok(pool.install(|| {
        views
            .par_iter()
            .map(|(p, m)| {
                let w = match &shading {
                    Some(Err(e)) => Wake::failed(p, *m, format!("shape from shading: {e}")),
                    Some(Ok(sm)) => wake_image(model, Some(sm), init, p, *m, settings),
                    None => wake_image(model, None, init, p, *m, settings),
                };
                progress(done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1, views.len());
                w
            })
            .collect()
    }))
}

/// The views an iteration fits, in the order of its records: each image, then (with `mirror`)
/// its mirror image.
pub fn views(images: &[PathBuf], mirror: bool) -> Vec<(&PathBuf, bool)> {
    images.iter().flat_map(|p| std::iter::once((p, false)).chain(mirror.then_some((p, true)))).collect()
}

impl Wake {
    /// The outcome of a view that could not be fitted, for `reason` (e.g. a cluster's task that failed).
    pub fn failed(image: &Path, mirrored: bool, reason: String) -> Self {
        let record = ImageRecord { reason: Some(reason), ..ImageRecord::unfitted(image, mirrored) };
        Self { record, reconstruction: None }
    }
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
/// with its landmarks (or `landmarks`, learned ones), its template's provenance and attribution,
/// and a record of the iteration.
pub fn learned_model(
    previous: &GpModel,
    wakes: &[Wake],
    keep_variance: f64,
    landmarks: Option<&[u32]>,
    record: LearningRecord,
) -> Result<GpModel, LearnError> {
    let examples: Vec<Mesh> = wakes.iter().filter_map(|w| w.reconstruction.clone()).collect();
    if examples.len() < 2 {
        return Err(LearnError::TooFewAccepted { iteration: record.iteration, accepted: examples.len(), images: wakes.len() });
    }
    let source = format!("learned by gpmm learn (iteration {}) from {} of {} images", record.iteration, record.accepted, record.images);
    let attribution = previous.metadata.template.attribution.clone().unwrap_or_default();
    // At most as many components as the predecessor has (or the examples give, without it).
    let kept =
        (keep_variance > 0.0).then_some(KeptCovariance { model: previous, share: keep_variance, max_rank: previous.shape.rank().max(2) });
    let landmarks = landmarks.unwrap_or(&previous.landmarks);
    let mut model = pca_beside(&examples, kept, &previous.triangles, landmarks, "learned", &source, &attribution)?;
    model.metadata.template = previous.metadata.template.clone();
    model.metadata.landmark_scheme = previous.metadata.landmark_scheme.clone();
    model.metadata.units = previous.metadata.units.clone();
    model.metadata.learning = Some(record);
    Ok(model)
}

/// How an iteration's images fared.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Counts {
    /// Accepted into the next model.
    pub accepted: usize,
    /// Rejected by the silhouette overlap.
    pub rejected_overlap: usize,
    /// Rejected by shape from shading's albedo change.
    pub rejected_albedo: usize,
    /// Not fitted (unreadable, no face found, fit error).
    pub failed: usize,
}

/// Counts of an iteration's records.
pub fn counts(records: &[ImageRecord]) -> Counts {
    let accepted = records.iter().filter(|r| r.accepted).count();
    let rejected_albedo = records.iter().filter(|r| !r.accepted && r.albedo_change.is_some()).count();
    let rejected_overlap = records.iter().filter(|r| !r.accepted && r.iou.is_some() && r.albedo_change.is_none()).count();
    Counts { accepted, rejected_overlap, rejected_albedo, failed: records.len() - accepted - rejected_overlap - rejected_albedo }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(accepted: bool, iou: Option<f64>, albedo_change: Option<f32>) -> ImageRecord {
        ImageRecord {
            image: "a.png".into(),
            mirrored: false,
            accepted,
            reason: None,
            iou,
            score: None,
            pixel_rmse: None,
            angles_deg: None,
            albedo_change,
            detail_mm: None,
            landmark_hits: None,
            detail_vertices: None,
            seconds: 0.0,
        }
    }

    #[test]
    fn counts_split_accepted_overlap_and_failed() {
        let r = [
            record(true, Some(0.9), Some(0.01)),
            record(false, Some(0.3), None),
            record(false, None, None),
            record(true, Some(0.7), None),
            record(false, Some(0.8), Some(0.2)),
        ];
        assert_eq!(counts(&r), Counts { accepted: 2, rejected_overlap: 1, rejected_albedo: 1, failed: 1 });
    }

    #[test]
    fn the_loops_fits_move_the_shape_by_the_image() {
        let (o, d) = (wake_fit_options(), FitOptions::DEFAULT);
        assert_eq!(o.fit.image.steps, WAKE_IMAGE_STEPS);
        assert!(o.fit.proposals.image.shape > 0.0 && d.fit.proposals.image.shape == 0.0);
        // Everything else is `gpmm fit`'s.
        assert_eq!(
            (o.size, o.seed, o.fit.landmarks, o.fit.start, o.fit.ranks),
            (d.size, d.seed, d.fit.landmarks, d.fit.start, d.fit.ranks)
        );
    }

    #[test]
    fn the_check_fits_as_gpmm_fit_does_under_the_same_flags() {
        assert_eq!(loop_and_check_options(&FitFlags::default()).unwrap(), (wake_fit_options(), FitOptions::DEFAULT));
        let flags = FitFlags { seed: Some(3), ..FitFlags::default() };
        let (wake, check) = loop_and_check_options(&flags).unwrap();
        assert_eq!((wake.seed, check.seed), (3, 3));
        assert_eq!((wake.fit.image.steps, check.fit.image.steps), (WAKE_IMAGE_STEPS, FitOptions::DEFAULT.fit.image.steps));
    }

    #[test]
    fn the_albedo_limit_is_the_papers_in_linear_colour() {
        assert!((albedo_change_limit(0) - 8.0 / 255.0).abs() < 1e-7);
        assert!((albedo_change_limit(4) - 6.0 / 255.0).abs() < 1e-7);
        assert_eq!(albedo_change_limit(40), 0.0);
    }
}
