//! A learning run on disk: `DIR/model_N.gpmm` and `DIR/iteration_N/` per iteration, resumable
//! after the last complete iteration.
//!
//! `DIR/iteration_N/records.json` holds every image's record and the iteration's counts; it is
//! written last, after `model_N.gpmm` and the pictures, so an iteration with a records file is
//! complete and a rerun continues after it.
//!
//! With a development set ([`DevSet`]) each new model is measured against its predecessor and the
//! best so far there; every iteration runs (each from the latest model, as the paper's loop does)
//! and the run keeps the best.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::dev::{DevComparison, DevFigure, DevSet, DevTrack};
use super::{albedo_change_limit, counts, learned_model, wake, ImageRecord, LearnError, LearnSettings, Wake};
use crate::fit::FitOptions;
use crate::gp::model::{GpModel, LearningRecord};
use crate::gp::model_io;
use crate::render::figure::{sample_grid, save_png, shape_light};
use crate::render::{RenderSettings, View};

/// One iteration's summary and records (`records.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IterationFile {
    /// The iteration (1-based).
    pub iteration: u32,
    /// The model it started from.
    pub previous_model: String,
    /// The model it wrote.
    pub model: String,
    /// Images fitted (mirror images included).
    pub images: usize,
    /// Fits accepted.
    pub accepted: usize,
    /// Fits rejected by the silhouette overlap.
    pub rejected_overlap: usize,
    /// Fits rejected by shape from shading's albedo change.
    #[serde(default)]
    pub rejected_albedo: usize,
    /// The albedo change limit of this iteration (linear 0–1 colour), with shape from shading.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_albedo_change: Option<f32>,
    /// Images that could not be fitted.
    pub failed: usize,
    /// Wall-clock seconds of the iteration.
    pub seconds: f64,
    /// The model against its predecessor on the development set, when one was given.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub development: Option<DevComparison>,
    /// Every image.
    pub records: Vec<ImageRecord>,
}

/// What a run is given.
#[derive(Debug, Clone)]
pub struct RunPlan {
    /// The model the first iteration starts from.
    pub model: PathBuf,
    /// The init file (finder and initializer); `None` when the settings name a landmark directory.
    pub init: Option<PathBuf>,
    /// The images.
    pub images: Vec<PathBuf>,
    /// Output directory.
    pub out: PathBuf,
    /// Iterations in all (a rerun with more continues).
    pub iterations: u32,
    /// Fit settings and quality control.
    pub settings: LearnSettings,
    /// The fit the development check measures every model with: `gpmm fit`'s with the loop's
    /// points and their σ, as users fit the learned model (not the loop's own image-led fits).
    pub dev_fit: FitOptions,
    /// Parallel fits.
    pub jobs: usize,
}

/// What a run reports as it goes.
#[derive(Debug)]
pub enum RunEvent<'a> {
    /// An iteration was complete on disk and is kept.
    Reused(&'a IterationFile),
    /// Images of an iteration fitted so far.
    Fitting {
        /// The iteration.
        iteration: u32,
        /// Images fitted.
        done: usize,
        /// Images in all.
        total: usize,
    },
    /// Development images of an iteration fitted so far (`model`: the one being measured).
    Checking {
        /// The iteration.
        iteration: u32,
        /// The model file measured.
        model: &'a Path,
        /// Images fitted.
        done: usize,
        /// Images in all.
        total: usize,
    },
    /// An iteration finished.
    Finished(&'a IterationFile),
}

/// What a run leaves: every iteration's file and the model to use.
#[derive(Debug, Clone)]
pub struct RunOutcome {
    /// The iterations on disk, in order.
    pub iterations: Vec<IterationFile>,
    /// The model to use: the best on the development set (the start model if no iteration beat
    /// it), or the latest without one.
    pub kept: PathBuf,
}

impl RunOutcome {
    /// `DIR/model.gpmm`, the model a run with a development set keeps: a copy of [`Self::kept`].
    pub fn copy_kept(&self, out: &Path) -> Result<PathBuf, RunError> {
        let to = out.join("model.gpmm");
        std::fs::copy(&self.kept, &to).map_err(|error| RunError::Io { path: to.clone(), error })?;
        Ok(to)
    }
}

/// Why a run stopped.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// An input named on the command line (or in a call) is not an image or a directory of images.
    #[error("{}: {error}", path.display())]
    Input {
        /// The input.
        path: PathBuf,
        /// What is wrong with it.
        error: &'static str,
    },
    /// A file could not be read or written.
    #[error("{}: {error}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        error: std::io::Error,
    },
    /// A model could not be read or written.
    #[error(transparent)]
    Model(#[from] model_io::ModelIoError),
    /// An iteration's records could not be read back.
    #[error("{}: {error}", path.display())]
    Records {
        /// The file.
        path: PathBuf,
        /// Why.
        error: serde_json::Error,
    },
    /// An iteration made no model.
    #[error(transparent)]
    Learn(#[from] LearnError),
    /// A picture could not be drawn or written.
    #[error("{}: {error}", path.display())]
    Picture {
        /// The file.
        path: PathBuf,
        /// Why.
        error: String,
    },
    /// The development set could not be fitted or measured.
    #[error("development set: {error}")]
    Development {
        /// Why.
        error: crate::eval::EvalError,
    },
    /// A wake phase returned another number of images than it was given.
    #[error("iteration {iteration}: the fits returned {got} results for {expected} images")]
    Wakes {
        /// The iteration.
        iteration: u32,
        /// Results returned.
        got: usize,
        /// Images (and mirror images) given.
        expected: usize,
    },
    /// A call-out of the loop (a cluster's wake phase, the retraining) failed.
    #[error("iteration {iteration}: {error}")]
    Hook {
        /// The iteration.
        iteration: u32,
        /// Why.
        error: String,
    },
    /// The worker threads could not start.
    #[error("cannot start {jobs} threads: {error}")]
    Threads {
        /// Threads asked for.
        jobs: usize,
        /// Why.
        error: rayon::ThreadPoolBuildError,
    },
}

/// The image files a run is given: files as they are, directories' images (.png, .jpg, .jpeg,
/// .ppm; not searched recursively) in name order.
pub fn image_files(inputs: &[PathBuf]) -> Result<Vec<PathBuf>, RunError> {
    let is_image = |p: &Path| {
        p.extension().and_then(|e| e.to_str()).is_some_and(|e| ["png", "jpg", "jpeg", "ppm"].contains(&e.to_ascii_lowercase().as_str()))
    };
    let mut files = Vec::new();
    for input in inputs {
        if input.is_dir() {
            let listing = std::fs::read_dir(input).map_err(|error| RunError::Io { path: input.clone(), error })?;
            let mut found: Vec<PathBuf> = listing.filter_map(|e| e.ok().map(|e| e.path())).filter(|p| p.is_file() && is_image(p)).collect();
            found.sort();
            if found.is_empty() {
                return Err(RunError::Input { path: input.clone(), error: "no .png, .jpg or .ppm images in this directory" });
            }
            files.extend(found);
        } else if input.is_file() {
            files.push(input.clone());
        } else {
            return Err(RunError::Input { path: input.clone(), error: "no such image or directory" });
        }
    }
    Ok(files)
}

/// `DIR/model_N.gpmm`.
pub fn model_path(out: &Path, iteration: u32) -> PathBuf {
    out.join(format!("model_{iteration}.gpmm"))
}

/// `DIR/iteration_N`.
pub fn iteration_dir(out: &Path, iteration: u32) -> PathBuf {
    out.join(format!("iteration_{iteration}"))
}

/// What one iteration's wake phase is given: the model to fit (its file and its contents) and the
/// settings (the albedo limit of this iteration set).
#[derive(Debug, Clone, Copy)]
pub struct WakeJob<'a> {
    /// The iteration (1-based).
    pub iteration: u32,
    /// The model's file (the start model or `model_{iteration − 1}.gpmm`).
    pub model_path: &'a Path,
    /// The model.
    pub model: &'a GpModel,
    /// The init file's bytes the fits start from (`None` with landmark files).
    pub init: Option<&'a [u8]>,
    /// The settings.
    pub settings: &'a LearnSettings,
}

/// What retraining the finder and initializer after an iteration is given.
#[derive(Debug, Clone, Copy)]
pub struct RetrainJob<'a> {
    /// The iteration just done.
    pub iteration: u32,
    /// Every model so far: the start model and each iteration's, in order.
    pub models: &'a [PathBuf],
    /// The init file's bytes the iteration started from.
    pub init: &'a [u8],
}

/// Retrains the finder and initializer (see [`Hooks::retrain`]).
pub type Retrain<'a> = dyn Fn(RetrainJob<'_>) -> Result<Vec<u8>, RunError> + 'a;

/// What the loop calls out to: who fits the images, who retrains the initializer, who hears
/// of progress.
pub struct Hooks<'a> {
    /// Fits one iteration's images (this machine's threads, or a cluster).
    pub wake_all: &'a dyn Fn(WakeJob<'_>) -> Result<Vec<Wake>, RunError>,
    /// Retrains the finder and initializer on the models so far after each iteration and
    /// returns the new init file's bytes (`None`: the init file stays the same).
    pub retrain: Option<&'a Retrain<'a>>,
    /// Progress.
    pub events: &'a (dyn Fn(RunEvent<'_>) + Sync),
}

/// `DIR/iteration_N/init.init`: the init file retrained after iteration N.
pub fn retrained_init_path(out: &Path, iteration: u32) -> PathBuf {
    iteration_dir(out, iteration).join("init.init")
}

/// The wake phase on this machine's threads (`plan.jobs`), as [`wake`] runs it.
pub fn local_wake<'a>(
    plan: &'a RunPlan,
    events: &'a (dyn Fn(RunEvent<'_>) + Sync),
) -> impl Fn(WakeJob<'_>) -> Result<Vec<Wake>, RunError> + 'a {
    move |job: WakeJob<'_>| {
        let iteration = job.iteration;
        let progress = |d, t| events(RunEvent::Fitting { iteration, done: d, total: t });
        wake(job.model, job.init, &plan.images, job.settings, plan.jobs, &progress)
            .map_err(|error| RunError::Threads { jobs: plan.jobs, error })
    }
}

/// Runs the loop with its fits on this machine's threads and no retraining: [`run_with`].
pub fn run(plan: &RunPlan, dev: Option<&mut DevSet>, events: &(dyn Fn(RunEvent<'_>) + Sync)) -> Result<RunOutcome, RunError> {
    let local = local_wake(plan, events);
    run_with(plan, dev, &Hooks { wake_all: &local, retrain: None, events })
}

/// Runs the loop: every complete iteration on disk is kept, the others are run, each iteration's
/// images (and mirror images, in [`wake`]'s order) fitted by `hooks.wake_all` (on this machine, or
/// on a cluster), each from the latest model; with `dev`, each new model is compared with its
/// predecessor and the best so far, and the run keeps the best; with `hooks.retrain`, the init file
/// is retrained after each iteration (`DIR/iteration_N/init.init`, reused by a rerun) and the next
/// iteration starts from it.
pub fn run_with(plan: &RunPlan, mut dev: Option<&mut DevSet>, hooks: &Hooks<'_>) -> Result<RunOutcome, RunError> {
    let Hooks { wake_all, retrain, events } = *hooks;
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |error| RunError::Io { path, error }
    };
    std::fs::create_dir_all(&plan.out).map_err(io(&plan.out))?;
    let mut init_path = plan.init.clone();
    let mut init = match &plan.init {
        Some(path) => Some(std::fs::read(path).map_err(io(path))?),
        None => None,
    };
    let mut models = vec![plan.model.clone()];
    let mut previous_path = plan.model.clone();
    let mut model = model_io::load(&plan.model)?;
    let mut done = Vec::new();
    let mut track = DevTrack::default();
    let figure = |dev: &DevSet, iteration: u32, path: &Path| -> Result<DevFigure, RunError> {
        let progress = |d, t| events(RunEvent::Checking { iteration, model: path, done: d, total: t });
        // The fit cache's file name: the start model may share its stem with a learned one.
        let label = if path == plan.model {
            "start".to_string()
        } else {
            path.file_stem().map_or_else(String::new, |s| s.to_string_lossy().into_owned())
        };
        dev.figure(path, &label, &plan.dev_fit, plan.jobs, &progress).map_err(|error| RunError::Development { error })
    };
    for iteration in 1..=plan.iterations {
        let dir = iteration_dir(&plan.out, iteration);
        let records_path = dir.join("records.json");
        let next_path = model_path(&plan.out, iteration);
        let reused = records_path.is_file() && next_path.is_file();
        let (file, next) = if reused {
            let text = std::fs::read_to_string(&records_path).map_err(io(&records_path))?;
            let file: IterationFile =
                serde_json::from_str(&text).map_err(|error| RunError::Records { path: records_path.clone(), error })?;
            events(RunEvent::Reused(&file));
            match &file.development {
                Some(c) => track.reuse(c, &previous_path, &next_path),
                // Measured without a development set: its model stands unmeasured.
                None => track.forget(),
            }
            let next = model_io::load(&next_path)?;
            (file, next)
        } else {
            let t0 = std::time::Instant::now();
            // The paper's albedo-change limit tightens with the iterations done.
            let settings = LearnSettings { max_albedo_change: albedo_change_limit(iteration - 1), ..plan.settings.clone() };
            let max_albedo_change = settings.shading.is_some().then_some(settings.max_albedo_change);
            let wakes =
                wake_all(WakeJob { iteration, model_path: &previous_path, model: &model, init: init.as_deref(), settings: &settings })?;
            let expected = super::views(&plan.images, settings.mirror).len();
            if wakes.len() != expected {
                return Err(RunError::Wakes { iteration, got: wakes.len(), expected });
            }
            let records: Vec<ImageRecord> = wakes.iter().map(|w| w.record.clone()).collect();
            let c = counts(&records);
            let record = LearningRecord {
                iteration,
                previous_model: previous_path.display().to_string(),
                init: match (&plan.settings.landmarks_dir, &init_path) {
                    (Some(dir), _) => format!("landmark files in {}", dir.display()),
                    (None, Some(path)) => path.display().to_string(),
                    (None, None) => String::new(),
                },
                images: records.len(),
                accepted: c.accepted,
                rejected_overlap: c.rejected_overlap,
                rejected_albedo: c.rejected_albedo,
                failed: c.failed,
                min_iou: plan.settings.min_iou,
                max_albedo_change,
                seed: plan.settings.fit.seed,
                image_steps: Some(plan.settings.fit.fit.image.steps),
                image_shape_share: Some(plan.settings.fit.fit.proposals.image.shape),
                landmarks_moved: None,
            };
            std::fs::create_dir_all(&dir).map_err(io(&dir))?;
            let learned_landmarks = plan.settings.learn_landmarks.then(|| {
                let hits: Vec<&[Option<u32>]> =
                    wakes.iter().filter(|w| w.reconstruction.is_some()).filter_map(|w| w.record.landmark_hits.as_deref()).collect();
                super::landmarks::agreed_landmarks(&model.shape.mean, &model.landmarks, &hits)
            });
            let record = LearningRecord {
                landmarks_moved: learned_landmarks.as_ref().map(|l| l.iter().zip(&model.landmarks).filter(|(a, b)| a != b).count()),
                ..record
            };
            let next = learned_model(&model, &wakes, plan.settings.keep_variance, learned_landmarks.as_deref(), record)?;
            model_io::save(&next, &next_path)?;
            write_samples(&next, &dir.join("samples.png"))?;
            write_reconstructions(&next, &wakes, &dir.join("reconstructions.png"))?;
            let development = match dev.as_deref() {
                Some(d) => Some(track.compare(d.dir(), &previous_path, &next_path, d.max_rank1_drop, &|p: &Path| figure(d, iteration, p))?),
                None => None,
            };
            let file = IterationFile {
                iteration,
                previous_model: previous_path.display().to_string(),
                model: next_path.display().to_string(),
                images: records.len(),
                accepted: c.accepted,
                rejected_overlap: c.rejected_overlap,
                rejected_albedo: c.rejected_albedo,
                max_albedo_change,
                failed: c.failed,
                seconds: t0.elapsed().as_secs_f64(),
                development,
                records,
            };
            let text = serde_json::to_string_pretty(&file).map_err(|error| RunError::Records { path: records_path.clone(), error })?;
            std::fs::write(&records_path, text + "\n").map_err(io(&records_path))?;
            events(RunEvent::Finished(&file));
            (file, next)
        };
        done.push(file);
        model = next;
        previous_path = next_path;
        models.push(previous_path.clone());
        if let (Some(retrain), Some(current)) = (retrain, init.as_deref()) {
            let path = retrained_init_path(&plan.out, iteration);
            // A reused iteration's retraining is on disk too (written after its records); a new
            // iteration's file, if any, is a leftover of another run.
            let bytes = match std::fs::read(&path) {
                Ok(bytes) if reused => bytes,
                _ => retrain_and_save(retrain, iteration, &models, current, &path)?,
            };
            repoint(dev.as_deref_mut(), &bytes, iteration, &mut track)?;
            init = Some(bytes);
            init_path = Some(path);
        }
    }
    let kept = track.best().map_or(previous_path, Path::to_path_buf);
    Ok(RunOutcome { iterations: done, kept })
}

/// Picture settings of the learning run's figures: small cells, light that shows shape.
fn figure_settings() -> RenderSettings {
    RenderSettings { width: 112, height: 112, light: shape_light(), ..RenderSettings::default() }
}

/// The model's mean and samples at ±2σ of its first components, frontal and at 45°.
fn write_samples(model: &GpModel, path: &Path) -> Result<(), RunError> {
    let picture_error = |error: String| RunError::Picture { path: path.to_path_buf(), error };
    let rank = model.shape.rank();
    let mut meshes = vec![model.instance(&[], &[]).map_err(|e| picture_error(e.to_string()))?];
    let mut labels = vec!["mean".to_string()];
    for k in 0..rank.min(3) {
        for sign in [2.0f32, -2.0] {
            let mut c = vec![0.0; k + 1];
            c[k] = sign;
            meshes.push(model.instance(&c, &[]).map_err(|e| picture_error(e.to_string()))?);
            labels.push(format!("{}:{sign:+}", k + 1));
        }
    }
    let views = [View::FRONTAL, View::yaw(45.0)];
    let grid = sample_grid(model, &meshes, &labels, &views, &figure_settings()).map_err(|e| picture_error(e.to_string()))?;
    save_png(&grid, path).map_err(|e| picture_error(e.to_string()))
}

/// The first eight accepted reconstructions (shape and albedo), frontal and at 45° (which images
/// were rejected, and why, is in the records).
fn write_reconstructions(model: &GpModel, wakes: &[Wake], path: &Path) -> Result<(), RunError> {
    let picture_error = |error: String| RunError::Picture { path: path.to_path_buf(), error };
    let accepted: Vec<&Wake> = wakes.iter().filter(|w| w.reconstruction.is_some()).take(8).collect();
    let meshes: Vec<crate::mesh::Mesh> = accepted.iter().filter_map(|w| w.reconstruction.clone()).collect();
    // Cells are numbered in the records' order (an "m" marks a mirror image): names do not fit.
    let labels: Vec<String> = wakes
        .iter()
        .enumerate()
        .filter(|(_, w)| w.reconstruction.is_some())
        .take(8)
        .map(|(i, w)| format!("#{}{}", i + 1, if w.record.mirrored { "m" } else { "" }))
        .collect();
    let views = [View::FRONTAL, View::yaw(45.0)];
    let grid = sample_grid(model, &meshes, &labels, &views, &figure_settings()).map_err(|e| picture_error(e.to_string()))?;
    save_png(&grid, path).map_err(|e| picture_error(e.to_string()))
}

/// Retrains through `retrain` and writes the new init file to `path` (its iteration directory).
fn retrain_and_save(retrain: &Retrain<'_>, iteration: u32, models: &[PathBuf], init: &[u8], path: &Path) -> Result<Vec<u8>, RunError> {
    let bytes = retrain(RetrainJob { iteration, models, init })?;
    std::fs::write(path, &bytes).map_err(|error| RunError::Io { path: path.to_path_buf(), error })?;
    Ok(bytes)
}

/// After a retraining the development images start from the new init file's points, so every
/// figure measured from the old points is measured again.
fn repoint(dev: Option<&mut DevSet>, init: &[u8], iteration: u32, track: &mut DevTrack) -> Result<(), RunError> {
    if let Some(d) = dev {
        d.repoint(init, &format!("points-{iteration}")).map_err(|error| RunError::Development { error })?;
        track.forget();
    }
    Ok(())
}
