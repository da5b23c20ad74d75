//! `gpmm bench-fit`: fits every image of a `gpmm synth` directory and compares with the truth.
//!
//! Every image goes through exactly the path of `gpmm fit` (its `.pts`, the crop, both chains);
//! images are fitted in parallel (rayon), each fit on one thread. Figures per image:
//! - |yaw|, |pitch|, |roll| error (degrees): fitted minus true Euler angles. Both are angles of
//!   the core's [`gpmm_core::render::Pose`] relative to a face frame built the same way from the iBUG
//!   landmarks (the template's in `gpmm build`, each ICT identity's in `gpmm synth`), so they are
//!   directly comparable; a residual offset comes from how the two faces' landmarks sit relative
//!   to their frames (e.g. a chin further forward tilts the chin → nose-bridge axis).
//! - landmark error: mean point-to-point distance between the fit's 68 projected landmarks and
//!   the true ones, in % of the true outer-eye-corner distance (iBUG 36-45), in the original image;
//! - pixel RMSE (per channel, covered pixels) of the landmark-only result (landmark chain plus
//!   least-squares light) and of the image chain's result;
//! - wall-clock seconds of the fit (crop and both chains).
//!
//! The landmarks are the set's exact ones (`NAME.pts` next to each image) or, with a landmark
//! directory, the files of the same name there (e.g. a real detector's). The summary also has a
//! row per true |yaw|: the median |yaw error| and the mean signed yaw error toward the profile
//! (negative: the fit turns the face toward frontal), beside the median pitch and roll errors.

use crate::eval::model_frame::{ModelFrame, ALIGNED_LANDMARKS};
use crate::eval::{ImageFitError, LandmarkSource};
use crate::fit::{fit_prepared, load_photo, FitOptions, Z50, Z90};
use crate::gp::model::GpModel;
use crate::synth::{read_truth, ImageTruth};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::time::Instant;

/// One image's figures.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct BenchImage {
    /// Image file name.
    pub image: String,
    /// True yaw, pitch, roll (degrees).
    pub truth_deg: [f32; 3],
    /// Fitted yaw, pitch, roll (degrees).
    pub fit_deg: [f32; 3],
    /// True yaw, pitch, roll in the model's frame (degrees; see [`crate::eval::model_frame`]).
    #[serde(default)]
    pub truth_model_frame_deg: Option<[f32; 3]>,
    /// Fitted yaw, pitch, roll of the fitted face's own iBUG frame (degrees; see
    /// [`crate::eval::model_frame::fit_in_face_frame`]): the rule the truth is defined by.
    #[serde(default)]
    pub fit_face_frame_deg: Option<[f32; 3]>,
    /// Landmark error in % of the inter-ocular (outer eye corner) distance.
    pub landmark_error_iod_pct: f32,
    /// Landmark error of the landmark-only result, in % of the inter-ocular distance.
    pub landmark_error_iod_pct_after_landmark_chain: f32,
    /// Pixel RMSE of the landmark-only result.
    pub pixel_rmse_after_landmark_chain: f32,
    /// Pixel RMSE of the fit.
    pub pixel_rmse: f32,
    /// Seconds of this fit.
    pub seconds: f64,
    /// Reported standard deviations of yaw, pitch and roll (degrees; fit.json's `posterior`).
    #[serde(default)]
    pub posterior_angles_sd_deg: [f32; 3],
    /// The image chain's own standard deviations of yaw, pitch and roll (degrees).
    #[serde(default)]
    pub posterior_chain_sd_deg: [f32; 3],
    /// The occlusion labels against the occluder's true footprint, where the set has one
    /// (`NAME.occluder.png`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub labels: Option<crate::eval::label_truth::LabelAgreement>,
    /// The image chain's mean yaw, pitch and roll over its second half, in the photo's camera as
    /// `fit_deg` (degrees).
    #[serde(default)]
    pub posterior_mean_deg: [f32; 3],
    /// The fitted face frame's origin (the rule `gpmm synth`'s translation follows: the landmark
    /// centroid on the mirror plane) minus the true translation, in the fit's camera (mm).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub translation_error_mm: Option<[f32; 3]>,
    /// Reported standard deviations of the translation (mm; fit.json's `posterior`).
    #[serde(default)]
    pub posterior_translation_sd_mm: [f32; 3],
}

/// Median and 90th percentile.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Stat {
    /// Median.
    pub median: f64,
    /// 90th percentile (linear interpolation).
    pub p90: f64,
}

/// The figures of the images of one true |yaw| (rounded to whole degrees).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct YawRow {
    /// True |yaw| (degrees, rounded).
    pub abs_yaw_deg: i32,
    /// Images in the row.
    pub images: usize,
    /// |yaw| error (degrees).
    pub yaw_error_deg: Stat,
    /// Mean of (fitted − true yaw) × sign(true yaw): negative when the fit turns toward frontal
    /// (0 for frontal images, where it is the plain mean signed error).
    pub mean_outward_yaw_error_deg: f64,
    /// Mean signed yaw error (fitted − true).
    pub mean_signed_yaw_error_deg: f64,
    /// |pitch| error (degrees).
    pub pitch_error_deg: Stat,
    /// |roll| error (degrees).
    pub roll_error_deg: Stat,
    /// |pitch − offset| (degrees), the offset being the median signed pitch error of the whole set
    /// (a constant offset is a frame convention between the face models, not a fitting error).
    pub pitch_error_centred_deg: Stat,
    /// |roll − offset| (degrees), the offset being the set's median signed roll error.
    pub roll_error_centred_deg: Stat,
}

/// Which angles an error table compares: the fitted and the true yaw, pitch, roll of an image.
struct Angles<'a> {
    fit: &'a dyn Fn(&BenchImage) -> [f32; 3],
    truth: &'a dyn Fn(&BenchImage) -> [f32; 3],
}

impl Angles<'_> {
    /// The fit's pose against the truth in the identities' face frames.
    const PLAIN: Angles<'static> = Angles { fit: &|b| b.fit_deg, truth: &|b| b.truth_deg };

    /// Signed error (fitted − true) of angle `k` (0 yaw, 1 pitch, 2 roll).
    fn signed(&self, b: &BenchImage, k: usize) -> f64 {
        f64::from((self.fit)(b)[k] - (self.truth)(b)[k])
    }
}

/// Median signed (fitted − true) yaw, pitch and roll errors of `images` (degrees).
pub fn median_offsets(images: &[BenchImage]) -> [f64; 3] {
    median_offsets_of(images, &Angles::PLAIN)
}

/// Median signed errors of `images` (degrees) between the angles `angles` compares.
fn median_offsets_of(images: &[BenchImage], angles: &Angles<'_>) -> [f64; 3] {
    let signed = |k: usize| images.iter().map(|b| angles.signed(b, k)).collect::<Vec<_>>();
    [stat(&signed(0)).median, stat(&signed(1)).median, stat(&signed(2)).median]
}

/// One row per true |yaw|, in increasing order.
pub fn per_yaw(images: &[BenchImage]) -> Vec<YawRow> {
    per_yaw_of(images, &Angles::PLAIN)
}

/// One row per true |yaw| (of `truth_deg`: the rows stay those of the set), errors between the
/// angles `angles` compares.
fn per_yaw_of(images: &[BenchImage], angles: &Angles<'_>) -> Vec<YawRow> {
    let mut keys: Vec<i32> = images.iter().map(|b| b.truth_deg[0].abs().round() as i32).collect();
    keys.sort_unstable();
    keys.dedup();
    let offset = median_offsets_of(images, angles);
    keys.into_iter()
        .map(|k| {
            let row: Vec<&BenchImage> = images.iter().filter(|b| b.truth_deg[0].abs().round() as i32 == k).collect();
            let n = row.len().max(1) as f64;
            let err = |i: usize| row.iter().map(|b| angles.signed(b, i).abs()).collect::<Vec<_>>();
            let centred = |i: usize| row.iter().map(|b| (angles.signed(b, i) - offset[i]).abs()).collect::<Vec<_>>();
            let signed = |b: &&BenchImage| angles.signed(b, 0);
            let sign = |b: &&BenchImage| if b.truth_deg[0].abs() < 0.5 { 1.0 } else { f64::from(b.truth_deg[0].signum()) };
            YawRow {
                abs_yaw_deg: k,
                images: row.len(),
                yaw_error_deg: stat(&err(0)),
                mean_outward_yaw_error_deg: row.iter().map(|b| signed(b) * sign(b)).sum::<f64>() / n,
                mean_signed_yaw_error_deg: row.iter().map(signed).sum::<f64>() / n,
                pitch_error_deg: stat(&err(1)),
                roll_error_deg: stat(&err(2)),
                pitch_error_centred_deg: stat(&centred(1)),
                roll_error_centred_deg: stat(&centred(2)),
            }
        })
        .collect()
}

/// The JSON `gpmm bench-fit` prints.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BenchSummary {
    /// Images fitted.
    pub images: usize,
    /// Images whose fit failed (their errors are printed).
    pub failed: usize,
    /// The fit settings.
    pub settings: FitOptions,
    /// |yaw| error (degrees).
    pub yaw_error_deg: Stat,
    /// |pitch| error (degrees).
    pub pitch_error_deg: Stat,
    /// |roll| error (degrees).
    pub roll_error_deg: Stat,
    /// Mean signed yaw, pitch and roll error (degrees): a systematic offset between the frames.
    pub mean_signed_error_deg: [f64; 3],
    /// Median signed yaw, pitch and roll error (degrees): the offsets removed in the per-yaw
    /// `*_centred_deg` figures.
    pub median_signed_error_deg: [f64; 3],
    /// Landmark error after the image chain, % of the inter-ocular distance.
    pub landmark_error_iod_pct: Stat,
    /// Landmark error of the landmark-only result, % of the inter-ocular distance.
    pub landmark_error_iod_pct_after_landmark_chain: Stat,
    /// Pixel RMSE of the landmark-only result (landmark chain + least-squares light).
    pub pixel_rmse_after_landmark_chain: Stat,
    /// Pixel RMSE after the image chain.
    pub pixel_rmse_after_image_chain: Stat,
    /// Fraction of images where the image chain lowered the pixel RMSE.
    pub image_chain_lowered_rmse_fraction: f64,
    /// Per true |yaw|: yaw error, its bias toward frontal, pitch and roll errors.
    pub per_yaw: Vec<YawRow>,
    /// The same errors against the truth in the model's frame (`None` if it could not be made).
    pub model_frame: Option<ModelFrameSummary>,
    /// Why there is no `model_frame` (e.g. the set's ICT data is not where `truth.json` says).
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub model_frame_error: Option<String>,
    /// The fitted face's own iBUG frame against the truth (`None` if an image has none): the
    /// same rule on both sides, so identity-dependent frame tilts drop out.
    #[serde(default)]
    pub face_frame: Option<FrameErrors>,
    /// Where the landmarks came from: `exact` (the set's) or the landmark directory.
    pub landmarks: String,
    /// Median over the images of the reported standard deviation of yaw, pitch and roll
    /// (degrees), to set beside the errors above.
    #[serde(default)]
    pub median_posterior_angles_sd_deg: [f64; 3],
    /// How often the reported 50 % and 90 % intervals hold the truth.
    #[serde(default)]
    pub interval_coverage: Option<IntervalCoverage>,
    /// How often the translation's intervals hold the truth (`None` without them).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub translation_coverage: Option<TranslationCoverage>,
    /// Intersection over union of the occlusion labels and the occluders' true footprints over
    /// the face's pixels, where the set has them (`NAME.occluder.png`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub label_iou: Option<Stat>,
    /// Seconds per fit (each fit on one thread).
    pub seconds_per_fit: Stat,
    /// Wall-clock seconds of the whole benchmark.
    pub wall_seconds: f64,
    /// Threads used.
    pub jobs: usize,
}

/// Pose errors against the truth in the model's frame ([`crate::eval::model_frame`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelFrameSummary {
    /// How the truth was put into the model's frame, in words.
    pub alignment: String,
    /// The alignment rotation's yaw, pitch, roll at the images' poses (median over the images, degrees).
    pub median_alignment_deg: [f64; 3],
    /// |yaw| error (degrees).
    pub yaw_error_deg: Stat,
    /// Median signed yaw, pitch and roll error (degrees): the offsets removed in the `*_centred_deg` figures.
    pub median_signed_error_deg: [f64; 3],
    /// Per true |yaw| (rows of the set's truth): the errors against the truth in the model's frame.
    pub per_yaw: Vec<YawRow>,
}

/// Pose errors of the fitted face's own iBUG frame against the truth
/// ([`crate::eval::model_frame::fit_in_face_frame`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameErrors {
    /// |yaw| error (degrees).
    pub yaw_error_deg: Stat,
    /// Median signed yaw, pitch and roll error (degrees): the offsets removed in the `*_centred_deg` figures.
    pub median_signed_error_deg: [f64; 3],
    /// Per true |yaw|.
    pub per_yaw: Vec<YawRow>,
}

/// Why the benchmark could not run.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// `truth.json` could not be read.
    #[error(transparent)]
    Truth(#[from] crate::synth::SynthError),
    /// The directory holds no images.
    #[error("{0}: truth.json lists no images")]
    Empty(String),
    /// Every fit failed.
    #[error("every fit failed; the first error: {0}")]
    AllFailed(String),
    /// The thread pool.
    #[error("cannot start {0} threads: {1}")]
    Threads(usize, String),
}

/// Median and 90th percentile of `v` (0 if empty).
pub fn stat(v: &[f64]) -> Stat {
    let mut s: Vec<f64> = v.iter().copied().filter(|x| !x.is_nan()).collect();
    s.sort_by(f64::total_cmp);
    let q = |f: f64| -> f64 {
        if s.is_empty() {
            return 0.0;
        }
        let pos = f * (s.len() - 1) as f64;
        let (i, t) = (pos.floor() as usize, pos - pos.floor());
        let a = s.get(i).copied().unwrap_or(0.0);
        let b = s.get(i + 1).copied().unwrap_or(a);
        a + t * (b - a)
    };
    Stat { median: q(0.5), p90: q(0.9) }
}

fn iod_error(fit: &[[f32; 2]], truth: &[[f32; 2]]) -> f32 {
    let (Some(a), Some(b)) = (truth.get(36), truth.get(45)) else { return f32::NAN };
    let iod = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt();
    let n = fit.len().min(truth.len()).max(1) as f32;
    let mean: f32 = fit.iter().zip(truth).map(|(p, q)| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt()).sum::<f32>() / n;
    100.0 * mean / iod
}

/// Fits one synthetic image (the `gpmm fit` path) and compares with its truth. Its landmarks are
/// its `.pts` file in `dir`, or the file of the same name in `landmarks.dir` (corrected with its calibration).
pub fn bench_one(
    model: &GpModel,
    dir: &Path,
    truth: &ImageTruth,
    settings: &FitOptions,
    landmarks: &LandmarkSource,
    frame: Option<&ModelFrame>,
) -> Result<BenchImage, ImageFitError> {
    let t0 = Instant::now();
    let pts = landmarks.file(dir, &truth.landmarks_file);
    let prepared = load_photo(model, &dir.join(&truth.image), &pts, false, settings.size, landmarks.calibration())
        .map_err(ImageFitError::naming(&truth.image))?;
    let o = fit_prepared(model, &prepared, settings, &mut |_, _, _| {}).map_err(ImageFitError::naming(&truth.image))?;
    let seconds = t0.elapsed().as_secs_f64();
    let size = settings.size;
    let fitted: Vec<[f32; 2]> = o.fitted_landmarks.iter().map(|p| prepared.crop.to_original(*p, size)).collect();
    let shape_only = crate::fit::project_landmarks_of(model, &o.landmark_params, size).map_err(ImageFitError::naming(&truth.image))?;
    let lm_only: Vec<[f32; 2]> = shape_only.iter().map(|p| prepared.crop.to_original(*p, size)).collect();
    let p = &o.params.pose;
    let in_photo = |angles: [f32; 3]| {
        crate::photo::pose_in_photo_frame(
            angles,
            o.params.focal,
            &prepared.crop,
            size,
            // The set's camera: its principal point is the frame's centre unless the frame was
            // widened around the face (tests/realistic/make_set.py --wide).
            truth.principal_px,
        )
        .map(f32::to_degrees)
    };
    let face_frame = crate::eval::model_frame::fit_in_face_frame(model, o.params.shape_coeffs(), [p.yaw, p.pitch, p.roll]);
    let translation_error_mm = translation_error(model, &o.params, &prepared.crop, size, truth).ok();
    let labels = match crate::eval::label_truth::truth_file(dir, &truth.image) {
        Some(path) => {
            let read = |e: image::ImageError| crate::photo::PhotoError::Read { path: path.clone(), message: e.to_string() };
            let footprint = image::open(&path).map_err(|e| ImageFitError::naming(&truth.image)(read(e).into()))?.to_luma8();
            let mask = o.occlusion.as_ref().map(|m| &m.0);
            Some(crate::eval::label_truth::label_agreement(mask, &o.render, &prepared.crop, size, &footprint))
        }
        None => None,
    };
    Ok(BenchImage {
        image: truth.image.clone(),
        truth_deg: [truth.yaw_deg, truth.pitch_deg, truth.roll_deg],
        // The fit's pose is relative to the crop's centre as optical axis; the truth is the photo camera's.
        truth_model_frame_deg: frame.map(|f| f.truth_in_model_frame([truth.yaw_deg, truth.pitch_deg, truth.roll_deg])),
        fit_deg: in_photo([p.yaw, p.pitch, p.roll]),
        fit_face_frame_deg: face_frame.ok().map(in_photo),
        landmark_error_iod_pct: iod_error(&fitted, &truth.landmarks),
        landmark_error_iod_pct_after_landmark_chain: iod_error(&lm_only, &truth.landmarks),
        pixel_rmse_after_landmark_chain: o.pixel_rmse_after_landmark_chain,
        pixel_rmse: o.pixel_rmse,
        seconds,
        posterior_angles_sd_deg: o.posterior.angles_sd_deg,
        posterior_chain_sd_deg: o.posterior.angles_chain_sd_deg,
        labels,
        posterior_mean_deg: in_photo(o.posterior.angles_mean_deg.map(f32::to_radians)),
        translation_error_mm,
        posterior_translation_sd_mm: o.posterior.translation_sd_mm,
    })
}

/// The fitted face frame's origin minus the true translation, both in the fit's camera (mm): the
/// origin of the fitted shape's iBUG frame moved by the fitted pose, against the truth's
/// translation turned from the photo's camera into the fit's ([`crate::photo::crop_axis_rotation`]).
fn translation_error(
    model: &GpModel,
    params: &crate::fit::Params,
    crop: &crate::photo::CropBox,
    size: u32,
    truth: &ImageTruth,
) -> Result<[f32; 3], crate::eval::model_frame::FrameError> {
    let lm = crate::eval::model_frame::fitted_landmarks(model, params.shape_coeffs())?;
    let frame = crate::mesh::template::ibug_frame(&lm).map_err(crate::eval::model_frame::FrameError::Frame)?;
    let origin = params.pose.transform_point(frame.center.map(|v| v as f32));
    let q = crate::photo::crop_axis_rotation(params.focal, crop, size, truth.principal_px);
    let t = truth.translation_mm.map(f64::from);
    // Qᵀ t: the photo camera's point in the fit's camera.
    let true_in_fit: [f64; 3] = core::array::from_fn(|j| (0..3).map(|i| q[i][j] * t[i]).sum());
    Ok(core::array::from_fn(|k| origin[k] - true_in_fit[k] as f32))
}

/// The errors against the truth in the model's frame, if every image has it.
fn model_frame_summary(images: &[BenchImage]) -> Option<ModelFrameSummary> {
    if images.iter().any(|b| b.truth_model_frame_deg.is_none()) {
        return None;
    }
    let truth = |b: &BenchImage| b.truth_model_frame_deg.unwrap_or(b.truth_deg);
    let angles = Angles { fit: &|b| b.fit_deg, truth: &truth };
    let align = |k: usize| images.iter().map(|b| f64::from(truth(b)[k] - b.truth_deg[k])).collect::<Vec<_>>();
    Some(ModelFrameSummary {
        alignment: format!(
            "least-squares rotation of the model's mean inner landmarks (iBUG {}-{}) onto the world's mean face's",
            ALIGNED_LANDMARKS.start,
            ALIGNED_LANDMARKS.end - 1
        ),
        median_alignment_deg: [stat(&align(0)).median, stat(&align(1)).median, stat(&align(2)).median],
        yaw_error_deg: stat(&images.iter().map(|b| angles.signed(b, 0).abs()).collect::<Vec<_>>()),
        median_signed_error_deg: median_offsets_of(images, &angles),
        per_yaw: per_yaw_of(images, &angles),
    })
}

/// The errors of the fitted face's own frame against the truth, if every image has it.
fn face_frame_summary(images: &[BenchImage]) -> Option<FrameErrors> {
    if images.iter().any(|b| b.fit_face_frame_deg.is_none()) {
        return None;
    }
    let angles = Angles { fit: &|b| b.fit_face_frame_deg.unwrap_or(b.fit_deg), truth: &|b| b.truth_deg };
    Some(FrameErrors {
        yaw_error_deg: stat(&images.iter().map(|b| angles.signed(b, 0).abs()).collect::<Vec<_>>()),
        median_signed_error_deg: median_offsets_of(images, &angles),
        per_yaw: per_yaw_of(images, &angles),
    })
}

/// Runs the benchmark on `dir` (a `gpmm synth` output): the first `limit` images, `jobs` threads,
/// landmarks from `landmarks` (the set's exact ones, or another directory's, maybe calibrated).
/// `progress(done, total)` is called after each image; failed fits are returned as messages.
#[allow(clippy::too_many_arguments)]
pub fn bench(
    model: &GpModel,
    dir: &Path,
    settings: &FitOptions,
    landmarks: &LandmarkSource,
    limit: Option<usize>,
    jobs: usize,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<(BenchSummary, Vec<BenchImage>, Vec<String>), BenchError> {
    settings.validate().map_err(|e| BenchError::AllFailed(e.to_string()))?;
    let truth = read_truth(&dir.join("truth.json"))?;
    let mut images = truth.images;
    if let Some(l) = limit {
        images.truncate(l);
    }
    if images.is_empty() {
        return Err(BenchError::Empty(dir.display().to_string()));
    }
    let frame = ModelFrame::new(model, &truth.options);
    let jobs = jobs.max(1);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(jobs).build().map_err(|e| BenchError::Threads(jobs, e.to_string()))?;
    let total = images.len();
    let done = std::sync::atomic::AtomicUsize::new(0);
    let t0 = Instant::now();
    let results: Vec<Result<BenchImage, ImageFitError>> = pool.install(|| {
        images
            .par_iter()
            .map(|t| {
                let r = bench_one(model, dir, t, settings, landmarks, frame.as_ref().ok());
                let d = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
                progress(d, total);
                r
            })
            .collect()
    });
    let wall_seconds = t0.elapsed().as_secs_f64();
    let mut ok = Vec::new();
    let mut errors = Vec::new();
    for r in results {
        match r {
            Ok(b) => ok.push(b),
            Err(e) => errors.push(e.to_string()),
        }
    }
    if ok.is_empty() {
        return Err(BenchError::AllFailed(errors.first().cloned().unwrap_or_default()));
    }
    let col = |f: &dyn Fn(&BenchImage) -> f64| ok.iter().map(f).collect::<Vec<f64>>();
    let err = |k: usize| col(&|b: &BenchImage| f64::from((b.fit_deg[k] - b.truth_deg[k]).abs()));
    let signed = |k: usize| ok.iter().map(|b| f64::from(b.fit_deg[k] - b.truth_deg[k])).sum::<f64>() / ok.len() as f64;
    let lowered = ok.iter().filter(|b| b.pixel_rmse < b.pixel_rmse_after_landmark_chain).count() as f64 / ok.len() as f64;
    let summary = BenchSummary {
        images: ok.len(),
        failed: errors.len(),
        settings: *settings,
        yaw_error_deg: stat(&err(0)),
        pitch_error_deg: stat(&err(1)),
        roll_error_deg: stat(&err(2)),
        mean_signed_error_deg: [signed(0), signed(1), signed(2)],
        median_signed_error_deg: median_offsets(&ok),
        landmark_error_iod_pct: stat(&col(&|b| f64::from(b.landmark_error_iod_pct))),
        landmark_error_iod_pct_after_landmark_chain: stat(&col(&|b| f64::from(b.landmark_error_iod_pct_after_landmark_chain))),
        pixel_rmse_after_landmark_chain: stat(&col(&|b| f64::from(b.pixel_rmse_after_landmark_chain))),
        pixel_rmse_after_image_chain: stat(&col(&|b| f64::from(b.pixel_rmse))),
        image_chain_lowered_rmse_fraction: lowered,
        per_yaw: per_yaw(&ok),
        model_frame: frame.as_ref().ok().and_then(|_| model_frame_summary(&ok)),
        model_frame_error: frame.err().map(|e| e.to_string()),
        face_frame: face_frame_summary(&ok),
        landmarks: landmarks.describe(),
        median_posterior_angles_sd_deg: [0, 1, 2].map(|k| stat(&col(&|b| f64::from(b.posterior_angles_sd_deg[k]))).median),
        interval_coverage: interval_coverage(&ok),
        translation_coverage: translation_coverage(&ok),
        label_iou: ok.iter().any(|b| b.labels.is_some()).then(|| stat(&col(&|b| b.labels.map_or(f64::NAN, |l| f64::from(l.iou))))),
        seconds_per_fit: stat(&col(&|b| b.seconds)),
        wall_seconds,
        jobs,
    };
    Ok((summary, ok, errors))
}

// How often a fit's reported intervals of yaw, pitch and roll hold the truth: the honesty of its
// posterior, beside the size of its errors.

/// The share of images whose 50 % and 90 % intervals (posterior mean ± z · sd) hold the truth,
/// per angle, after the set's median signed error of the posterior mean is removed (the model's
/// frontal is not the identities').
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IntervalCoverage {
    /// The truth compared with: `model frame` (the truth in the model's frame) or `camera`.
    pub truth: String,
    /// The median signed error of the posterior mean removed (degrees).
    pub median_signed_error_deg: [f64; 3],
    /// Median |error| of the posterior mean after that (degrees).
    pub median_abs_error_deg: [f64; 3],
    /// Median reported standard deviation (degrees).
    pub median_sd_deg: [f64; 3],
    /// Share of images whose 50 % interval holds the truth (ideal 0.5).
    pub covered_50: [f64; 3],
    /// Share of images whose 90 % interval holds the truth (ideal 0.9).
    pub covered_90: [f64; 3],
    /// The same for intervals of the image chain's own spread alone (far too narrow).
    pub chain_covered_90: [f64; 3],
    /// The reliability diagram's points: per nominal level (the share a central interval should
    /// hold), the shares of yaw, pitch and roll it held: `[level, yaw, pitch, roll]`.
    #[serde(default)]
    pub reliability: Vec<[f64; 4]>,
}

/// Nominal levels of the reliability diagram and their standard normal quantiles
/// (`Φ⁻¹((1 + level) / 2)`).
const LEVELS: [(f64, f64); 11] = [
    (0.1, 0.125_66),
    (0.2, 0.253_35),
    (0.3, 0.385_32),
    (0.4, 0.524_40),
    (0.5, Z50 as f64),
    (0.6, 0.841_62),
    (0.7, 1.036_43),
    (0.8, 1.281_55),
    (0.9, Z90 as f64),
    (0.95, 1.959_96),
    (0.99, 2.575_83),
];

/// The reliability diagram of `c`: the share of images whose interval held the truth against
/// the share it should hold, per angle, and the diagonal a calibrated fit follows.
pub fn reliability_chart(c: &IntervalCoverage) -> Result<image::RgbaImage, crate::eval::plot::PlotError> {
    use crate::eval::plot::{line_chart, Chart, Series};
    let line = |label: &str, k: usize| Series {
        label: label.into(),
        points: c.reliability.iter().map(|r| (100.0 * r[0], 100.0 * r[k])).collect(),
        intervals: Vec::new(),
    };
    let ideal = Series { label: "calibrated".into(), points: vec![(0.0, 0.0), (100.0, 100.0)], intervals: Vec::new() };
    let chart = Chart {
        title: format!("Pose intervals: how often they hold the truth ({})", c.truth),
        x_label: "nominal level of the central interval (%)".into(),
        y_label: "images whose interval holds the truth (%)".into(),
        log_x: false,
        y_range: Some((0.0, 100.0)),
        series: vec![line("yaw", 1), line("pitch", 2), line("roll", 3), ideal],
    };
    line_chart(&chart, 640, 480)
}

/// How often the translation's intervals (fit ± z · sd, per axis of the fit's camera) hold the
/// truth, after the set's median signed error of each axis is removed (the two faces' frames put
/// their origins differently).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TranslationCoverage {
    /// The median signed error removed (mm).
    pub median_signed_error_mm: [f64; 3],
    /// Median |error| after that (mm).
    pub median_abs_error_mm: [f64; 3],
    /// Median reported standard deviation (mm).
    pub median_sd_mm: [f64; 3],
    /// Share of images whose 50 % interval holds the truth (ideal 0.5).
    pub covered_50: [f64; 3],
    /// Share of images whose 90 % interval holds the truth (ideal 0.9).
    pub covered_90: [f64; 3],
}

/// Three values' errors against their reported spreads over a set: the set's median signed error
/// of each (removed: a frame convention, not a fitting error), and each item's |error| after it.
struct CentredErrors {
    offset: [f64; 3],
    centred: Vec<[f64; 3]>,
}

impl CentredErrors {
    /// The errors `signed` (fitted − true per item; `None` without items).
    fn of(signed: &[[f64; 3]]) -> Option<Self> {
        if signed.is_empty() {
            return None;
        }
        let offset: [f64; 3] = core::array::from_fn(|k| stat(&signed.iter().map(|e| e[k]).collect::<Vec<_>>()).median);
        let centred = signed.iter().map(|e| core::array::from_fn(|k| (e[k] - offset[k]).abs())).collect();
        Some(Self { offset, centred })
    }

    /// The share of items whose value `k` lies within `z` of their standard deviations `sd`.
    fn share(&self, sd: &[[f32; 3]], k: usize, z: f64) -> f64 {
        self.centred.iter().zip(sd).filter(|(e, s)| e[k] <= z * f64::from(s[k])).count() as f64 / self.centred.len() as f64
    }

    /// The median |error| after the offset, per value.
    fn median_abs(&self) -> [f64; 3] {
        core::array::from_fn(|k| stat(&self.centred.iter().map(|e| e[k]).collect::<Vec<_>>()).median)
    }
}

/// The median of each of three values over `rows`.
fn medians(rows: &[[f32; 3]]) -> [f64; 3] {
    core::array::from_fn(|k| stat(&rows.iter().map(|r| f64::from(r[k])).collect::<Vec<_>>()).median)
}

/// The coverage of `images`' translation intervals (`None` without errors or reported spreads).
pub fn translation_coverage(images: &[BenchImage]) -> Option<TranslationCoverage> {
    let (signed, sd): (Vec<[f64; 3]>, Vec<[f32; 3]>) = images
        .iter()
        .filter_map(|b| b.translation_error_mm.map(|e| (e.map(f64::from), b.posterior_translation_sd_mm)))
        .filter(|(_, sd)| sd.iter().all(|s| *s > 0.0))
        .unzip();
    let c = CentredErrors::of(&signed)?;
    Some(TranslationCoverage {
        median_signed_error_mm: c.offset,
        median_abs_error_mm: c.median_abs(),
        median_sd_mm: medians(&sd),
        covered_50: core::array::from_fn(|k| c.share(&sd, k, f64::from(Z50))),
        covered_90: core::array::from_fn(|k| c.share(&sd, k, f64::from(Z90))),
    })
}

/// The coverage of `images`' intervals (`None` without images or reported spreads).
pub fn interval_coverage(images: &[BenchImage]) -> Option<IntervalCoverage> {
    let model_frame = images.iter().all(|b| b.truth_model_frame_deg.is_some());
    let truth = |b: &BenchImage| if model_frame { b.truth_model_frame_deg.unwrap_or(b.truth_deg) } else { b.truth_deg };
    let usable: Vec<&BenchImage> = images.iter().filter(|b| b.posterior_angles_sd_deg.iter().all(|s| *s > 0.0)).collect();
    let signed: Vec<[f64; 3]> = usable.iter().map(|b| core::array::from_fn(|k| f64::from(b.posterior_mean_deg[k] - truth(b)[k]))).collect();
    let c = CentredErrors::of(&signed)?;
    let sd: Vec<[f32; 3]> = usable.iter().map(|b| b.posterior_angles_sd_deg).collect();
    let chain: Vec<[f32; 3]> = usable.iter().map(|b| b.posterior_chain_sd_deg).collect();
    let share = |k: usize, z: f64| c.share(&sd, k, z);
    Some(IntervalCoverage {
        truth: if model_frame { "model frame" } else { "camera" }.into(),
        median_signed_error_deg: c.offset,
        median_abs_error_deg: c.median_abs(),
        median_sd_deg: medians(&sd),
        covered_50: core::array::from_fn(|k| share(k, f64::from(Z50))),
        covered_90: core::array::from_fn(|k| share(k, f64::from(Z90))),
        chain_covered_90: core::array::from_fn(|k| c.share(&chain, k, f64::from(Z90))),
        reliability: LEVELS.iter().map(|&(level, z)| [level, share(0, z), share(1, z), share(2, z)]).collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn translation_intervals_hold_what_their_width_covers_after_the_sets_offset() {
        // Errors 10 + (−3 … 3) mm on x, sd 1: the offset 10 goes, |error| ≤ 1.645 for 3 of 7.
        let img = |e: f32, sd: f32| BenchImage {
            translation_error_mm: Some([10.0 + e, e, 100.0 + e]),
            posterior_translation_sd_mm: [sd, sd, sd],
            ..BenchImage::default()
        };
        let images: Vec<BenchImage> = (-3..=3).map(|e| img(e as f32, 1.0)).collect();
        let c = translation_coverage(&images).expect("coverage");
        assert!((c.median_signed_error_mm[0] - 10.0).abs() < 1e-9 && (c.median_signed_error_mm[2] - 100.0).abs() < 1e-9, "{c:?}");
        assert!((c.covered_90[0] - 3.0 / 7.0).abs() < 1e-9 && (c.covered_50[1] - 1.0 / 7.0).abs() < 1e-9, "{c:?}");
        // Wider intervals hold more; no spreads, no coverage.
        let wide: Vec<BenchImage> = (-3..=3).map(|e| img(e as f32, 2.0)).collect();
        assert!(translation_coverage(&wide).expect("coverage").covered_90[0] > c.covered_90[0]);
        assert_eq!(translation_coverage(&[img(1.0, 0.0)]), None);
        assert_eq!(translation_coverage(&[BenchImage::default()]), None);
    }

    #[test]
    fn stat_interpolates() {
        let s = stat(&[3.0, 1.0, 2.0, 4.0, 5.0]);
        assert_eq!(s.median, 3.0);
        assert!((s.p90 - 4.6).abs() < 1e-9);
        assert_eq!(stat(&[]).median, 0.0);
    }

    #[test]
    fn per_yaw_rows_measure_the_pull_toward_frontal() {
        let img = |t: f32, f: f32| BenchImage {
            image: String::new(),
            truth_deg: [t, 1.0, 0.0],
            fit_deg: [f, 2.0, 0.5],
            truth_model_frame_deg: None,
            ..BenchImage::default()
        };
        // ±45 fitted as ±41: 4° toward frontal on both sides, no plain signed mean.
        let rows = per_yaw(&[img(45.0, 41.0), img(-45.0, -41.0), img(0.0, 0.5), img(15.0, 16.0)]);
        assert_eq!(rows.iter().map(|r| r.abs_yaw_deg).collect::<Vec<_>>(), [0, 15, 45]);
        let r45 = &rows[2];
        assert_eq!(r45.images, 2);
        assert!((r45.mean_outward_yaw_error_deg + 4.0).abs() < 1e-9 && r45.mean_signed_yaw_error_deg.abs() < 1e-9);
        assert!((r45.yaw_error_deg.median - 4.0).abs() < 1e-9 && (r45.pitch_error_deg.median - 1.0).abs() < 1e-9);
        assert!((rows[1].mean_outward_yaw_error_deg - 1.0).abs() < 1e-9);
        assert_eq!(model_frame_summary(&[img(45.0, 41.0)]), None, "no model-frame truth, no summary");
    }

    #[test]
    fn model_frame_rows_keep_the_sets_yaws_and_measure_against_the_moved_truth() {
        // The model's frame is turned by +1° yaw and +4° pitch against the identities': a fit
        // that lands there has no error in it, and the rows are still the set's |yaw| 45 and 0.
        let img = |t: f32| BenchImage {
            image: String::new(),
            truth_deg: [t, 0.0, 0.0],
            fit_deg: [t + 1.0, 4.0, 0.0],
            truth_model_frame_deg: Some([t + 1.0, 4.0, 0.0]),
            ..BenchImage::default()
        };
        let images = [img(45.0), img(-45.0), img(0.0)];
        let m = model_frame_summary(&images).expect("every image has the model-frame truth");
        assert_eq!(m.per_yaw.iter().map(|r| r.abs_yaw_deg).collect::<Vec<_>>(), [0, 45]);
        assert!(m.per_yaw.iter().all(|r| r.yaw_error_deg.median.abs() < 1e-6 && r.pitch_error_deg.median.abs() < 1e-6));
        assert!((m.median_alignment_deg[0] - 1.0).abs() < 1e-6 && (m.median_alignment_deg[1] - 4.0).abs() < 1e-6);
        // Against the identities' frames the same fits are 1° off in yaw.
        assert!(per_yaw(&images).iter().all(|r| (r.yaw_error_deg.median - 1.0).abs() < 1e-6));
        assert_eq!(face_frame_summary(&images), None, "no fitted face frame, no summary");
        // The fitted face's own frame is compared with the plain truth: here 2° of pitch off.
        let own: Vec<BenchImage> =
            images.iter().map(|b| BenchImage { fit_face_frame_deg: Some([b.truth_deg[0], 2.0, 0.0]), ..b.clone() }).collect();
        let f = face_frame_summary(&own).expect("every image has its face frame");
        assert_eq!(f.per_yaw.iter().map(|r| r.abs_yaw_deg).collect::<Vec<_>>(), [0, 45]);
        assert!(f.per_yaw.iter().all(|r| r.yaw_error_deg.median.abs() < 1e-6 && (r.pitch_error_deg.median - 2.0).abs() < 1e-6));
        assert!((f.median_signed_error_deg[1] - 2.0).abs() < 1e-6);
    }

    fn image(mean: f32, sd: f32) -> BenchImage {
        BenchImage {
            image: String::new(),
            truth_deg: [10.0, 0.0, 0.0],
            fit_deg: [mean, 0.0, 0.0],
            posterior_angles_sd_deg: [sd, 1.0, 1.0],
            posterior_chain_sd_deg: [sd / 10.0, 0.1, 0.1],
            posterior_mean_deg: [mean, 0.0, 0.0],
            ..BenchImage::default()
        }
    }

    #[test]
    fn coverage_counts_the_intervals_that_hold_the_truth_after_the_median_offset() {
        // Errors (after the median offset of +2) of 0, ±0.5, ±1, ±3 with sd 1: the 50 % interval
        // (±0.674) holds 3 of 7, the 90 % (±1.645) 5 of 7.
        let errs = [0.0f32, 0.5, -0.5, 1.0, -1.0, 3.0, -3.0];
        let images: Vec<BenchImage> = errs.iter().map(|e| image(12.0 + e, 1.0)).collect();
        let c = interval_coverage(&images).expect("coverage");
        assert_eq!(c.truth, "camera");
        assert!((c.median_signed_error_deg[0] - 2.0).abs() < 1e-6);
        assert!((c.covered_50[0] - 3.0 / 7.0).abs() < 1e-9 && (c.covered_90[0] - 5.0 / 7.0).abs() < 1e-9, "{c:?}");
        // Pitch and roll sit on the truth: every interval holds it.
        assert_eq!((c.covered_50[1], c.covered_90[2]), (1.0, 1.0));
        // The reliability diagram's 50 % point is the 50 % coverage; its chart draws.
        let half = c.reliability.iter().find(|r| r[0] == 0.5).expect("the 50 % level");
        assert_eq!(half[1], c.covered_50[0]);
        assert!(c.reliability.windows(2).all(|w| w[0][1] <= w[1][1]), "wider intervals hold more");
        let chart = reliability_chart(&c).expect("chart");
        assert_eq!(chart.dimensions(), (640, 480));
        // A tenth of the spread holds only the image on the offset.
        assert!((c.chain_covered_90[0] - 1.0 / 7.0).abs() < 1e-9, "{c:?}");
        // Twice the spread holds more.
        let wide: Vec<BenchImage> = errs.iter().map(|e| image(12.0 + e, 2.0)).collect();
        assert!(interval_coverage(&wide).expect("coverage").covered_90[0] > c.covered_90[0]);
        // Without spreads there is nothing to say.
        assert_eq!(interval_coverage(&[image(1.0, 0.0)]), None);
    }
}
