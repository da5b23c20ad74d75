//! `gpmm learn`: a model learned from unlabelled images.

use crate::fit::FitSettingsArgs;
use crate::progress::{bar_style, note};
use crate::training_photos::TrainingPhotos;
use anyhow::{bail, Context, Result};
use clap::Args;
use gpmm_host::gp::model::GpModel;
use gpmm_host::gp::model_io;
use gpmm_host::learn::dev::{DevPoints, DevSet};
use gpmm_host::learn::run::{image_files, iteration_dir, local_wake, run_with, Hooks, Retrain, RetrainJob, RunError, RunEvent, RunPlan};
use gpmm_host::learn::shading::ShadingSettings;
use gpmm_host::learn::{albedo_change_limit, LearnSettings, MIN_IOU};
use gpmm_train::scene::head::HeadContext;
use indicatif::ProgressBar;
use std::path::{Path, PathBuf};

/// Arguments of `gpmm learn`.
#[derive(Debug, Args)]
pub struct LearnArgs {
    /// The model to start from (e.g. `gpmm build`'s).
    pub model: PathBuf,
    /// Images, or directories of images (.png, .jpg, .jpeg, .ppm; not searched recursively).
    #[arg(required = true, num_args = 1..)]
    pub images: Vec<PathBuf>,
    /// Init file (`gpmm train-init`): its finder and initializer start every fit.
    #[arg(long, value_name = "INIT", required_unless_present = "landmarks_dir")]
    pub init: Option<PathBuf>,
    /// Start every fit from landmark files instead of the init file: `DIR/STEM.pts` for each image
    /// `STEM.png` (iBUG-68, 0-based; a detector's, for users who have one). Mirror images get the
    /// points mirrored.
    #[arg(long, value_name = "DIR")]
    pub landmarks_dir: Option<PathBuf>,
    /// Learn where the --landmarks-dir points lie on the model: in each accepted fit, the vertex
    /// each point lands on (within 20 mm of its landmark); each new model takes the vertices the
    /// fits agree on, so that the detector that made the points fits it without bending its shape
    /// to another convention.
    #[arg(long, requires = "landmarks_dir")]
    pub learn_landmarks: bool,
    /// Output directory: model_N.gpmm and iteration_N/ (records.json, samples.png,
    /// reconstructions.png) per iteration; a rerun continues after the last complete iteration.
    #[arg(short, long, value_name = "DIR")]
    pub output: PathBuf,
    /// Iterations in all (default 5; 1 with --quick).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..=100))]
    pub iterations: Option<u32>,
    /// Also fit each image's mirror image (twice the examples; the learned model leans less to one side).
    #[arg(long)]
    pub mirror: bool,
    /// The least overlap (intersection over union) of a fit's silhouette with its start's for the
    /// fit to be used.
    #[arg(long, value_name = "IOU", default_value_t = MIN_IOU)]
    pub min_iou: f64,
    /// Landmark σ of the initializer's landmarks (fraction of the fit's image side; landmark files
    /// from --landmarks-dir take --landmark-sigma, as `gpmm fit --landmarks` does).
    #[arg(long, value_name = "FRACTION", default_value_t = gpmm_host::detect::INIT_LANDMARK_SIGMA)]
    pub init_landmark_sigma: f32,
    /// Add to each kept fit the per-vertex shape and albedo detail its image shows beyond the
    /// model (shape from shading, the paper's third step), and reject images whose albedo had to
    /// change too much. Off by default: as it stands it makes the learned models' fits worse
    /// (docs/learning.md).
    #[arg(long)]
    pub shape_from_shading: bool,
    /// A development set with known truth (a `gpmm synth` set, or one made from it, with its
    /// truth.json): after each iteration the new model and its predecessor fit its images as
    /// `gpmm fit` fits them, from the loop's kind of points (the init file's, or
    /// --dev-landmarks-dir), and are measured against the true faces; every iteration runs, each
    /// says whether it beat its predecessor and the best so far, and DIR/model.gpmm is the best.
    #[arg(long, value_name = "SET")]
    pub dev: Option<PathBuf>,
    /// Landmark files of the --dev images, when the loop reads landmark files (--landmarks-dir).
    #[arg(long, value_name = "DIR", requires = "dev")]
    pub dev_landmarks_dir: Option<PathBuf>,
    /// Use the first N identities of --dev (default: all).
    #[arg(long, value_name = "N", requires = "dev")]
    pub dev_identities: Option<usize>,
    /// The development check also identifies its probes from the same fits (rank-1, gallery at
    /// yaw 0): a model whose fits come closer but whose rank-1 falls more than this many
    /// percentage points below the model it is compared with does not count as better.
    #[arg(long, value_name = "POINTS", default_value_t = 100.0 * gpmm_host::learn::dev::DEFAULT_MAX_RANK1_DROP, requires = "dev")]
    pub dev_max_identity_drop: f64,
    /// Data directory: the true faces' source for --dev, the template head for --retrain-init
    /// (default: $GPMM_DATA or ../shared/data).
    #[arg(long, value_name = "DIR")]
    pub data: Option<PathBuf>,
    /// Retrain the init file's finder and initializer after each iteration: fine-tune the networks
    /// it started from for CHUNKS chunks of renders of every model so far (the start model and each
    /// iteration's, drawn alike), as `gpmm train-init MODELS --from INIT --chunks CHUNKS` does; the
    /// next iteration starts from it (DIR/iteration_N/init.init, its validation in init.json). An
    /// init file trained on real photos needs them again (--backgrounds and the options beside it,
    /// as it was trained): renders alone make its finder forget them.
    #[arg(long, value_name = "CHUNKS", requires = "init", conflicts_with = "landmarks_dir")]
    pub retrain_init: Option<usize>,
    /// Template directory whose head, neck and ears are put around the faces the initializer is
    /// retrained on (default: the data directory's template).
    #[arg(long, value_name = "DIR", requires = "retrain_init")]
    pub head: Option<PathBuf>,
    /// Share of the previous model's covariance the learned model keeps beside its fits' (0: the
    /// fits' PCA alone, which loses variance with every iteration, each fit being drawn toward the
    /// model it was fitted with, and with it the faces' identity: docs/learning.md).
    #[arg(long, value_name = "F", default_value_t = gpmm_host::learn::DEFAULT_KEEP_VARIANCE)]
    pub keep_variance: f64,
    /// Parallel fits (default: all cores).
    #[arg(long, value_name = "J")]
    pub jobs: Option<usize>,
    /// A smoke run: one iteration of short fits (1500 landmark, 40 image steps unless given).
    #[arg(long)]
    pub quick: bool,
    /// Fit settings: `gpmm fit`'s, but for an image chain of
    /// [`gpmm_host::learn::WAKE_IMAGE_STEPS`] steps that fits the shape as well
    /// (`--set proposals.image.shape=0 --image-steps 600` fits as `gpmm fit` does).
    #[command(flatten)]
    pub settings: FitSettingsArgs,
    /// Real photos the retraining shows beside the renders, as `gpmm train-init` takes them; with
    /// photos of people its face check is fitted again on them after each retraining.
    #[command(flatten, next_help_heading = "Real photos in the retraining (with --retrain-init)")]
    pub photos: TrainingPhotos,
}

/// Runs `gpmm learn`.
pub fn learn(a: LearnArgs) -> Result<()> {
    if !(a.min_iou.is_finite() && (0.0..=1.0).contains(&a.min_iou)) {
        bail!("--min-iou {}: an overlap is between 0 and 1", a.min_iou);
    }
    if !(a.keep_variance.is_finite() && a.keep_variance >= 0.0) {
        bail!("--keep-variance {}: a share of a covariance is 0 or more", a.keep_variance);
    }
    if a.retrain_init == Some(0) {
        bail!("--retrain-init 0 trains nothing; leave it out to keep the init file");
    }
    if !a.photos.backgrounds.is_empty() && a.retrain_init.is_none() {
        bail!("--backgrounds are shown to the retraining of the init file: give --retrain-init CHUNKS");
    }
    let images = image_files(&a.images)?;
    let mut flags = a.settings.flags();
    // The initializer's points are fitted as `gpmm fit --init` fits them; landmark files as
    // `gpmm fit --landmarks` does (a detector's visible outline, the fit's own σ).
    flags.initializer_sigma = a.landmarks_dir.is_none().then_some(a.init_landmark_sigma);
    if a.quick {
        if a.settings.landmark_steps == gpmm_host::fit::FitOptions::DEFAULT.fit.landmarks.steps {
            flags.landmark_steps = Some(1500);
        }
        flags.image_steps = flags.image_steps.or(Some(40));
    }
    let (fit, dev_fit) = gpmm_host::learn::loop_and_check_options(&flags)?;
    let jobs = a.jobs.unwrap_or_else(|| std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1)).max(1);
    let plan = RunPlan {
        model: a.model.clone(),
        init: if a.landmarks_dir.is_some() { None } else { a.init.clone() },
        images,
        out: a.output.clone(),
        iterations: a.iterations.unwrap_or(if a.quick { 1 } else { 5 }),
        settings: LearnSettings {
            fit,
            min_iou: a.min_iou,
            mirror: a.mirror,
            shading: a.shape_from_shading.then_some(ShadingSettings::DEFAULT),
            max_albedo_change: albedo_change_limit(0),
            landmarks_dir: a.landmarks_dir.clone(),
            keep_variance: a.keep_variance,
            learn_landmarks: a.learn_landmarks,
        },
        dev_fit,
        jobs,
    };
    let backgrounds = a.photos.load()?;
    // The same options for every retraining, checked before the development set is read.
    let mut opts = if a.quick {
        gpmm_train::TrainOptions::quick(plan.settings.fit.seed)
    } else {
        gpmm_train::TrainOptions::fine_tuning(plan.settings.fit.seed)
    };
    opts.chunks = a.retrain_init.unwrap_or(0);
    a.photos.set_options(&mut opts)?;
    let mut dev = match &a.dev {
        Some(dir) => {
            let pb = crate::progress::spinner(&format!("{}: finding the development faces", dir.display()));
            let data = a.data.clone().unwrap_or_else(gpmm_host::data::default_data_dir);
            let work = a.output.join("development");
            let bytes = match (&a.landmarks_dir, &a.init) {
                (None, Some(init)) => Some(std::fs::read(init).with_context(|| format!("cannot read {}", init.display()))?),
                _ => None,
            };
            let points = DevPoints::like_the_loop(a.landmarks_dir.as_deref(), a.dev_landmarks_dir.as_deref(), bytes.as_deref())
                .map_err(|e| anyhow::anyhow!("--dev: {e} (--dev-landmarks-dir)"))?;
            if !(0.0..=100.0).contains(&a.dev_max_identity_drop) {
                anyhow::bail!("--dev-max-identity-drop {}: percentage points from 0 to 100", a.dev_max_identity_drop);
            }
            let d = DevSet::prepare(dir, a.dev_identities, &data, points, &work)?.with_max_rank1_drop(a.dev_max_identity_drop / 100.0);
            pb.finish_and_clear();
            if d.unfound > 0 {
                eprintln!("{}: no face found in {} development images; they are left out", dir.display(), d.unfound);
            }
            Some(d)
        }
        None => None,
    };
    eprintln!(
        "{} images{}, {} iterations, {} threads -> {}",
        plan.images.len(),
        if a.mirror { " and their mirror images" } else { "" },
        plan.iterations,
        jobs,
        plan.out.display()
    );
    let bar = ProgressBar::new(0);
    bar.set_style(bar_style("{bar:30} {pos}/{len} fits ({msg}) [{elapsed}]"));
    let events = |e: RunEvent<'_>| match e {
        RunEvent::Reused(f) => {
            note(&bar, format!("iteration {}: complete on disk ({} of {} accepted), reused", f.iteration, f.accepted, f.images));
            if let Some(c) = &f.development {
                note(&bar, development_line(f.iteration, c));
            }
        }
        RunEvent::Fitting { iteration, done, total } => {
            bar.set_message(format!("iteration {iteration}"));
            bar.set_length(total as u64);
            bar.set_position(done as u64);
        }
        RunEvent::Checking { iteration, model, done, total } => {
            bar.set_message(format!("iteration {iteration}: development fits of {}", model.display()));
            bar.set_length(total as u64);
            bar.set_position(done as u64);
        }
        RunEvent::Finished(f) => {
            note(
                &bar,
                format!(
                    "iteration {}: {} of {} fits accepted, {} rejected by their silhouette, {} by their albedo change, {} failed ({:.0} s) -> {}",
                    f.iteration, f.accepted, f.images, f.rejected_overlap, f.rejected_albedo, f.failed, f.seconds, f.model
                ),
            );
            if let Some(c) = &f.development {
                note(&bar, development_line(f.iteration, c));
            }
        }
    };
    let head = match a.retrain_init {
        Some(_) => Some(retraining_head(&plan.model, a.head.as_deref(), a.data.as_deref())?),
        None => None,
    };
    let retrain = |job: RetrainJob<'_>| -> Result<Vec<u8>, RunError> {
        let failed = |error: String| RunError::Hook { iteration: job.iteration, error };
        let models = job.models.iter().map(|p| model_io::load(p)).collect::<Result<Vec<_>, _>>()?;
        let refs: Vec<&GpModel> = models.iter().collect();
        let progress = |p: gpmm_train::train::Progress| {
            if let gpmm_train::train::Progress::Step { done, total, .. } = p {
                bar.set_message(format!("iteration {}: retraining the initializer on {} models", job.iteration, refs.len()));
                bar.set_length(total as u64);
                bar.set_position(done as u64);
            }
        };
        let (bytes, report) = gpmm_train::fine_tune(&refs, head.as_ref(), backgrounds.as_ref(), job.init, &opts, progress)
            .map_err(|e| failed(format!("retraining the initializer: {e}")))?;
        let bytes = match &backgrounds {
            Some(b) => a.photos.with_face_check(bytes, b, &bar).map_err(|e| failed(format!("the retrained file's face check: {e}")))?,
            None => bytes,
        };
        let path = iteration_dir(&plan.out, job.iteration).join("init.json");
        let text = serde_json::to_string_pretty(&report).map_err(|e| failed(e.to_string()))?;
        std::fs::write(&path, text + "\n").map_err(|error| RunError::Io { path: path.clone(), error })?;
        note(&bar, format!("iteration {}: initializer retrained ({} chunks): found {:.1} %, landmark error {:.3} of the eye distance on its validation renders", job.iteration, opts.chunks, 100.0 * report.found, report.median_landmark_error));
        Ok(bytes)
    };
    let local = local_wake(&plan, &events);
    let hooks = Hooks { wake_all: &local, retrain: a.retrain_init.is_some().then_some(&retrain as &Retrain<'_>), events: &events };
    let outcome = run_with(&plan, dev.as_mut(), &hooks)?;
    bar.finish_and_clear();
    if dev.is_some() {
        let to = outcome.copy_kept(&a.output).with_context(|| format!("cannot copy {}", outcome.kept.display()))?;
        eprintln!("kept {}, the best on the development set (copied to {})", outcome.kept.display(), to.display());
        // The init file retrained after the kept iteration learned that model (and those before it).
        let paired = (1..=plan.iterations).find(|&n| gpmm_host::learn::run::model_path(&plan.out, n) == outcome.kept);
        if let Some(init) = paired.map(|n| gpmm_host::learn::run::retrained_init_path(&plan.out, n)).filter(|p| p.is_file()) {
            eprintln!("its init file: {} (retrained after that iteration)", init.display());
        }
        println!("{}", to.display());
    } else if let Some(last) = outcome.iterations.last() {
        println!("{}", last.model);
    }
    Ok(())
}

/// One line on an iteration's development check: both figures and the best model so far.
fn development_line(iteration: u32, c: &gpmm_host::learn::dev::DevComparison) -> String {
    let rank1 = |r: Option<f64>| r.map_or_else(String::new, |r| format!(", rank-1 {:.1} %", 100.0 * r));
    let best = format!("the best stays {} ({:.3} mm{})", c.best_model, c.best_median_mm, rank1(c.best_rank1));
    let verdict = match (c.better, c.best, c.closer) {
        (_, true, _) => "better, the best so far".to_string(),
        (true, false, _) => format!("better than its predecessor; {best}"),
        (false, _, true) => format!("closer, but it tells the identities apart less well: not better; {best}"),
        (false, _, false) => format!("worse; {best}"),
    };
    format!(
        "iteration {iteration}: development median {:.3} mm (mean {:.3}{}) against {:.3} mm (mean {:.3}{}) before: {verdict}",
        c.learned.median_mm,
        c.learned.mean_mm,
        rank1(c.learned.rank1),
        c.previous.median_mm,
        c.previous.mean_mm,
        rank1(c.previous.rank1)
    )
}

/// The head put around the faces the initializer is retrained on: the template directory's (as
/// `gpmm train-init` loads it), fitted to the start model.
fn retraining_head(model: &Path, head: Option<&Path>, data: Option<&Path>) -> Result<HeadContext> {
    let dir = head
        .map(Path::to_path_buf)
        .unwrap_or_else(|| gpmm_host::data::template_dir(&data.map(Path::to_path_buf).unwrap_or_else(gpmm_host::data::default_data_dir)));
    let (mesh, landmarks) = crate::train_init::template_files(&dir)
        .with_context(|| format!("retraining puts the faces on a head from a template directory: pass --head DIR ({})", dir.display()))?;
    let start = model_io::load(model)?;
    Ok(HeadContext::load(&start, &mesh, &landmarks)?)
}
