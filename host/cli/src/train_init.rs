//! `gpmm train-init`: the face finder and initializer trained on renders of a model or a mixture
//! of models, from random weights or from an init file's networks (fine-tuning).

use crate::progress::{bar_style, note};
use crate::training_photos::TrainingPhotos;
use anyhow::{bail, Context, Result};
use clap::Args;
use gpmm_core::model::ibug::IBUG68_POINTS;
use gpmm_host::gp::model_io;
use gpmm_train::scene::head::HeadContext;
use gpmm_train::scene::{FaceModel, Openings, SceneSource};
use gpmm_train::train::{check_mixture, FINE_TUNE_LR_SHARE};
use gpmm_train::TrainError;
use indicatif::ProgressBar;
use std::num::NonZeroUsize;
use std::path::{Path, PathBuf};

/// Help heading of the `gpmm train-init` options that each turn off a default of the training,
/// to measure what that default brings.
const COMPARISONS: &str = "Comparisons (each turns off a default)";

/// Arguments of `gpmm train-init`.
#[derive(Debug, Args)]
pub struct TrainInitArgs {
    /// Model files (.gpmm) whose renders the networks learn from (their landmark vertices are the
    /// labels). With several, each scene's face comes from one of them, picked uniformly for the
    /// seed and the scene; all must have the first one's vertices and landmarks (models made from
    /// one template: the template model and `gpmm learn`'s), and the head is fitted to the first.
    #[arg(value_name = "MODEL", required = true, num_args = 1..)]
    pub models: Vec<PathBuf>,
    /// Output init file.
    #[arg(short, long, value_name = "INIT")]
    pub output: PathBuf,
    /// Seed of the scenes, the weights and the order (the same seed gives the same file).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// A few seconds of training on a few dozen scenes (for tests: the networks learn little).
    #[arg(long)]
    pub quick: bool,
    /// Chunks of fresh scenes (default training: 40 of 2048 scenes, 3 passes each, about 30 minutes
    /// on 2 cores; with --from: 4). With --from, 0 only re-calibrates and re-quantizes its networks
    /// (and validates them on these models' scenes).
    #[arg(long, value_name = "N")]
    pub chunks: Option<usize>,
    /// Init file whose finder and initializer the training starts from (fine-tuning) instead of
    /// random weights; they must have this training's architecture and the models' landmarks.
    #[arg(long, value_name = "INIT")]
    pub from: Option<PathBuf>,
    /// Peak learning rate of the cosine schedule (default 0.002; with --from a quarter of it).
    #[arg(long, value_name = "LR")]
    pub lr: Option<f64>,
    /// The finder's passes over each chunk (each pass shows every scene of the chunk once more,
    /// in a new order; default 3).
    #[arg(long, value_name = "N")]
    pub passes: Option<NonZeroUsize>,
    /// The initializer's passes over each chunk (default: as many as the finder's).
    #[arg(long, value_name = "N")]
    pub init_passes: Option<NonZeroUsize>,
    /// Never show the initializer a mirrored crop (by default its second pass over each chunk sees
    /// the crops flipped left-right with mirrored labels, when the model has the 68 iBUG
    /// landmarks whose pairs say what a mirror swaps).
    #[arg(long, help_heading = COMPARISONS)]
    pub no_mirror: bool,
    /// Write a picture grid of training scenes (what the networks see: rendered scenes, real faces
    /// when some backgrounds are photos of people, face-free frames) to this PNG.
    #[arg(long, value_name = "PNG")]
    pub preview: Option<PathBuf>,
    /// Template directory (one .ply and landmarks_ibug68.json) whose whole head, neck and ears are
    /// put around the model's faces; it must be the scan the model was built from. Default: the
    /// data directory's template ($GPMM_DATA or ../shared/data).
    #[arg(long, value_name = "DIR")]
    pub head: Option<PathBuf>,
    /// Render the model's faces alone on the backgrounds, with no head around them.
    #[arg(long, conflicts_with = "head")]
    pub no_head: bool,
    /// Leave the scan's shut eyes shut in every scene (by default most scenes get open eyes
    /// painted on, with the lid landmarks on the painted lids).
    #[arg(long, help_heading = COMPARISONS)]
    pub shut_eyes: bool,
    /// Leave the heads around the faces undressed: bald busts with bare shoulders, as the
    /// template is (by default most heads get fuller hair standing off the skull, some long hair
    /// hanging behind, and clothes over the shoulders with a torso down to the frame's edge;
    /// without them the finder's box on photos of people came out about twice the face).
    #[arg(long, help_heading = COMPARISONS)]
    pub undressed: bool,
    /// Show every frame with its camera's look alone (by default half of all frames, renders, real
    /// faces and face-free views alike, get a random photographic look: a tenth of all frames in
    /// black and white, the rest with contrast, brightness, saturation and a colour cast drawn
    /// anew).
    #[arg(long, help_heading = COMPARISONS)]
    pub plain_looks: bool,
    /// Draw nothing over the faces (by default a tenth of the faces, rendered and real, wear dark
    /// glasses and one in twenty a face mask, drawn from their 68 points).
    #[arg(long, help_heading = COMPARISONS)]
    pub no_occluders: bool,
    /// Real photos in the scenes.
    #[command(flatten, next_help_heading = "Real photos")]
    pub photos: TrainingPhotos,
    /// Do not fit the face check: by default, when --backgrounds holds photos of people, the
    /// trained file's finder scans every --backgrounds photo and a check of its readings is fitted
    /// and written into the file's metadata, as `gpmm check-init` does (about a minute).
    #[arg(long, requires = "backgrounds", help_heading = COMPARISONS)]
    pub no_face_check: bool,
}

/// Runs `gpmm train-init`.
pub fn train_init(a: TrainInitArgs) -> Result<()> {
    let models = a.models.iter().map(|p| model_io::load(p)).collect::<Result<Vec<_>, _>>()?;
    let refs: Vec<&gpmm_host::gp::model::GpModel> = models.iter().collect();
    check_mixture(&refs).map_err(|e| match e {
        TrainError::Mixture { index, error } => anyhow::anyhow!("{}: {error}", a.models[index].display()),
        e => anyhow::anyhow!("{e}"),
    })?;
    let (model, first) = (&models[0], &a.models[0]);
    let mut opts = match (a.quick, a.from.is_some()) {
        (true, _) => gpmm_train::TrainOptions::quick(a.seed),
        (false, false) => gpmm_train::TrainOptions::full(a.seed),
        (false, true) => gpmm_train::TrainOptions::fine_tuning(a.seed),
    };
    if a.from.is_some() {
        opts.lr = gpmm_train::TrainOptions::full(a.seed).lr * FINE_TUNE_LR_SHARE;
    }
    if let Some(lr) = a.lr {
        if !(lr.is_finite() && lr > 0.0) {
            bail!("--lr {lr} is not a positive learning rate");
        }
        opts.lr = lr;
    }
    // Zero passes are refused by the argument parser (`NonZeroUsize`), zero chunks here.
    if a.chunks == Some(0) && a.from.is_none() {
        bail!("--chunks 0 trains nothing: it only re-quantizes the networks of --from INIT");
    }
    opts.chunks = a.chunks.unwrap_or(opts.chunks);
    opts.passes = a.passes.map_or(opts.passes, NonZeroUsize::get);
    opts.init_passes = a.init_passes.or(a.passes).map_or(opts.init_passes, NonZeroUsize::get);
    if a.no_mirror {
        opts.mirror = false;
    } else if opts.mirror && model.landmarks.len() != IBUG68_POINTS {
        eprintln!("{}: {} landmarks, not the 68 iBUG ones: no mirrored crops", first.display(), model.landmarks.len());
        opts.mirror = false;
    }
    opts.ranges.open_eyes = !a.shut_eyes;
    opts.ranges.dressed = !a.undressed;
    if a.plain_looks {
        opts.ranges.look_share = 0.0;
    }
    opts.ranges.occluders = !a.no_occluders;
    let head = if a.no_head {
        None
    } else {
        let dir = a.head.clone().unwrap_or_else(|| gpmm_host::data::template_dir(&gpmm_host::data::default_data_dir()));
        let (mesh, landmarks) = template_files(&dir).with_context(|| {
            format!("the head around the faces comes from a template directory: pass --head DIR or --no-head ({})", dir.display())
        })?;
        let head = HeadContext::load(model, &mesh, &landmarks)?;
        eprintln!("head: {} vertices from {}", head.vertices(), mesh.display());
        Some(head)
    };
    if a.photos.scan_mistakes && a.from.is_none() {
        bail!("--scan-mistakes looks for the mistakes of the finder being fine-tuned: give --from INIT");
    }
    a.photos.set_options(&mut opts)?;
    let backgrounds = a.photos.load()?;
    let from = match &a.from {
        Some(path) => Some(std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?),
        None => None,
    };
    if let Some(path) = &a.preview {
        let openings: Vec<Openings> = models.iter().map(|m| Openings::of_model(m, &opts.ranges)).collect();
        let faces: Vec<FaceModel<'_>> = models.iter().zip(&openings).map(|(model, openings)| FaceModel { model, openings }).collect();
        let source = SceneSource { faces: &faces, head: head.as_ref(), ranges: &opts.ranges, backgrounds: backgrounds.as_ref() };
        let grid = gpmm_train::preview::preview(source, opts.seed);
        gpmm_host::render::figure::save_png(&image::DynamicImage::ImageRgb8(grid).to_rgba8(), path)
            .with_context(|| format!("cannot write {}", path.display()))?;
        eprintln!("wrote {}", path.display());
    }
    let bar = ProgressBar::new(opts.steps() as u64);
    bar.set_style(bar_style("{bar:30} {pos}/{len} steps ({msg}) [{elapsed} / ~{duration}]"));
    let progress = |p| match p {
        gpmm_train::train::Progress::Rendering { chunk } => bar.set_message(format!("rendering chunk {}/{}", chunk + 1, opts.chunks)),
        gpmm_train::train::Progress::Step { done, finder, initializer, .. } => {
            bar.set_position(done as u64);
            bar.set_message(format!("loss {finder:.3} / {initializer:.3}"));
        }
        gpmm_train::train::Progress::Scanning => bar.set_message("scanning the backgrounds for the finder's mistakes".to_string()),
        gpmm_train::train::Progress::Validating => bar.set_message("quantizing and validating".to_string()),
    };
    let (bytes, report) =
        gpmm_train::train_on(&refs, head.as_ref(), backgrounds.as_ref(), from.as_deref(), &opts, progress).map_err(|e| {
            match (e, &a.from) {
                (TrainError::Start { error }, Some(path)) => anyhow::anyhow!("cannot fine-tune from {}: {error}", path.display()),
                (e, _) => anyhow::anyhow!("cannot train on {}: {e}", first.display()),
            }
        })?;
    let bytes = match &backgrounds {
        Some(b) if !a.no_face_check => a.photos.with_face_check(bytes, b, &bar)?,
        _ => bytes,
    };
    let bytes = with_provenance(bytes, &a.models, &models, &a.photos.backgrounds)?;
    bar.finish_and_clear();
    std::fs::write(&a.output, &bytes).with_context(|| format!("cannot write {}", a.output.display()))?;
    note(&bar, format!("wrote {} ({} bytes)", a.output.display(), bytes.len()));
    println!("{}", serde_json::to_string_pretty(&report)?);
    Ok(())
}

/// `bytes` (a trained init file) with what it was trained for and on in its metadata: each model
/// file's SHA-256, kernel and landmark count, and each --backgrounds folder's sources
/// ([`gpmm_host::detect::provenance`]).
fn with_provenance(bytes: Vec<u8>, paths: &[PathBuf], models: &[gpmm_host::gp::model::GpModel], folders: &[PathBuf]) -> Result<Vec<u8>> {
    use gpmm_host::detect::provenance;
    let trained_for = paths
        .iter()
        .zip(models)
        .map(|(path, m)| provenance::model_entry(path, &m.metadata.kernel, m.landmarks.len()))
        .collect::<Result<Vec<_>, _>>()?;
    let sets = folders
        .iter()
        .map(|dir| provenance::photo_set_entry(dir, gpmm_host::detect::photos::list_photos(dir).map_or(0, |p| p.len())))
        .collect::<Result<Vec<_>, _>>()?;
    let file = gpmm_core::format::init_file::InitFile::parse(&bytes).map_err(|e| anyhow::anyhow!("the trained file: {e}"))?;
    let metadata = provenance::with_provenance(file.metadata, trained_for, sets)?;
    gpmm_host::detect::check_fit::with_metadata(&bytes, &metadata).map_err(|e| anyhow::anyhow!("the trained file with its provenance: {e}"))
}

/// The mesh (the directory's only .ply) and `landmarks_ibug68.json` of a template directory.
pub(crate) fn template_files(dir: &Path) -> Result<(PathBuf, PathBuf)> {
    let entries = std::fs::read_dir(dir).with_context(|| format!("cannot read the directory {}", dir.display()))?;
    let plys: Vec<PathBuf> =
        entries.filter_map(|e| e.ok().map(|e| e.path())).filter(|p| p.extension().is_some_and(|x| x.eq_ignore_ascii_case("ply"))).collect();
    let [mesh] = plys.as_slice() else {
        bail!("{} holds {} .ply files; a template directory holds exactly one", dir.display(), plys.len());
    };
    let landmarks = dir.join("landmarks_ibug68.json");
    if !landmarks.is_file() {
        bail!("{} is missing", landmarks.display());
    }
    Ok((mesh.clone(), landmarks))
}
