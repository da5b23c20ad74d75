//! What the evaluations that fit or build models share: model selection, fit settings, the
//! factory of built models, the world of a set and the command line a report records.

use anyhow::Result;
use clap::Args;
use gpmm_host::gp::kernel::ModelKernel;
use std::path::{Path, PathBuf};

/// Where the fits of a set's images take their landmarks from.
#[derive(Debug, Args)]
pub struct EvalLandmarkArgs {
    /// Fit with the landmark files of DIR (same names as the set's `.pts`, e.g. a detector's)
    /// instead of the exact ones; the identities and yaws stay the set's.
    #[arg(long, value_name = "DIR")]
    pub landmarks_dir: Option<PathBuf>,
    /// Correct the landmarks with this detector calibration (`gpmm calibrate-landmarks`: the
    /// detector's systematic, view-dependent offsets learned on renders) before fitting.
    #[arg(long, value_name = "FILE")]
    pub landmark_calibration: Option<PathBuf>,
}

impl EvalLandmarkArgs {
    /// The landmark source these name (the calibration read and checked).
    pub fn source(&self) -> Result<gpmm_host::eval::LandmarkSource> {
        Ok(gpmm_host::eval::LandmarkSource::new(self.landmarks_dir.clone(), self.landmark_calibration.as_deref())?)
    }
}

/// Model selection and building options shared by the evaluations.
#[derive(Debug, Args)]
pub struct EvalModelArgs {
    /// Model files to evaluate (label: the file name without extension).
    #[arg(long = "model", value_name = "MODEL", num_args = 1..)]
    pub models: Vec<PathBuf>,
    /// Build these kernels from the template: `all` or a comma-separated list (e.g. symmetric-full,standard-rgb).
    #[arg(long, value_name = "LIST")]
    pub kernels: Option<String>,
    /// Build these kernels around the world's mean face (ICT neutral with the transferred template
    /// albedo; the paper's setting, which builds around the BFM mean): `all` or a comma-separated list.
    #[arg(long, value_name = "LIST")]
    pub mean_face_kernels: Option<String>,
    /// Include the generating world itself as a model (an upper bound).
    #[arg(long)]
    pub upper_bound: bool,
    /// Include a PCA model of N training identities of the world.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(2..=1000))]
    pub pca: Option<u64>,
    /// Data directory with `template/lee-perry-smith` and `ict` (default: $GPMM_DATA or ../shared/data).
    #[arg(long, value_name = "DIR")]
    pub data: Option<PathBuf>,
    /// Where built models are cached (default: OUT/models).
    #[arg(long, value_name = "DIR")]
    pub model_dir: Option<PathBuf>,
    /// Simplify template and scans to at most N vertices before building (default: keep all; 600 with --quick).
    #[arg(long, value_name = "N")]
    pub vertices: Option<usize>,
    /// Shape and colour rank of built GP models (default 200; 20 with --quick).
    #[arg(long, value_name = "K")]
    pub rank: Option<usize>,
    /// Nyström points of built GP models (default 2000; 300 with --quick).
    #[arg(long, value_name = "M")]
    pub nystrom_points: Option<usize>,
    /// A fast smoke run for CI: few identities, small models, short chains.
    #[arg(long)]
    pub quick: bool,
}

/// Fit settings of the evaluations that fit every image of a set (`recognition`, `reconstruction`).
#[derive(Debug, Args)]
pub struct EvalFitArgs {
    /// Working image side of the fits (pixels).
    #[arg(long, default_value_t = gpmm_host::fit::FitOptions::DEFAULT.size, value_parser = clap::value_parser!(u32).range(16..=1024))]
    pub size: u32,
    /// Landmark-chain steps per fit (default 5000; 1500 with --quick).
    #[arg(long, value_name = "N")]
    pub landmark_steps: Option<u32>,
    /// Image-chain steps per fit (default 600; 40 with --quick).
    #[arg(long, value_name = "N")]
    pub image_steps: Option<u32>,
    /// Shape components fitted (and compared by recognition): 50, as the paper's fit script (`gpmm fit` fits 200
    /// for the best landmark fit, but components past ~50 are not determined by a 128-pixel
    /// image and add noise to the cosine).
    #[arg(long, default_value_t = RECOGNITION_SHAPE_RANK, value_name = "K")]
    pub shape_rank: usize,
    /// Colour components fitted.
    #[arg(long, default_value_t = gpmm_host::fit::FitOptions::DEFAULT.fit.ranks.color, value_name = "K")]
    pub color_rank: usize,
    /// Parallel fits (default: all cores).
    #[arg(long, value_name = "J")]
    pub jobs: Option<usize>,
    /// Any other fit setting by its path in fit.json's `settings` (repeatable), as on `gpmm fit`,
    /// e.g. `--set landmarks.student_t=4` (part of the fit cache's key).
    #[arg(long = "set", value_name = "PATH=VALUE")]
    pub overrides: Vec<String>,
}

impl EvalFitArgs {
    /// The fit's flags (--quick shortens only the chains it is not told about).
    pub fn flags(&self, quick: bool) -> gpmm_host::fit::FitFlags {
        gpmm_host::fit::FitFlags {
            size: Some(self.size),
            landmark_steps: self.landmark_steps.or(quick.then_some(1500)),
            image_steps: self.image_steps.or(quick.then_some(40)),
            shape_rank: Some(self.shape_rank),
            color_rank: Some(self.color_rank),
            overrides: self.overrides.clone(),
            ..gpmm_host::fit::FitFlags::default()
        }
    }

    /// Parallel fits: --jobs, else all cores.
    pub fn jobs(&self) -> usize {
        self.jobs.unwrap_or_else(|| std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1)).max(1)
    }
}

/// Shape components of a recognition fit (the paper's 50).
pub const RECOGNITION_SHAPE_RANK: usize = 50;

/// This process's command line, arguments with spaces quoted (recorded in the reports).
pub fn command_line() -> String {
    std::env::args().map(|a| if a.contains(' ') { format!("'{a}'") } else { a }).collect::<Vec<_>>().join(" ")
}

/// The factory that builds (or reuses) the selected models under OUT/models.
pub fn eval_factory(m: &EvalModelArgs, out: &Path, world: gpmm_host::synth::SynthOptions) -> gpmm_host::eval::models::ModelFactory {
    use gpmm_host::eval::models::{GpBuild, ModelFactory};
    let q = m.quick;
    let build = GpBuild {
        vertices: m.vertices.or(q.then_some(600)),
        rank: m.rank.unwrap_or(if q { 20 } else { 200 }).max(1),
        nystrom_points: m.nystrom_points.unwrap_or(if q { 300 } else { 2000 }).max(1),
        ..GpBuild::default()
    };
    let data = m.data.clone().unwrap_or_else(gpmm_host::data::default_data_dir);
    let dir = m.model_dir.clone().unwrap_or_else(|| out.join("models"));
    let mut f = ModelFactory::new(&dir, &data, build, world);
    if q {
        f.color_samples = 40;
    }
    f
}

/// Kernels named by a list: `all` or comma-separated names (none when absent).
fn kernel_list(list: Option<&str>) -> Result<Vec<ModelKernel>> {
    Ok(match list.map(str::trim) {
        None => Vec::new(),
        Some(s) if s.eq_ignore_ascii_case("all") => ModelKernel::ALL.to_vec(),
        Some(s) => s.split(',').map(|k| k.trim().parse::<ModelKernel>()).collect::<Result<Vec<_>, _>>()?,
    })
}

/// The models a command line selects.
pub fn eval_selection(m: &EvalModelArgs) -> Result<gpmm_host::eval::models::ModelSelection> {
    Ok(gpmm_host::eval::models::ModelSelection {
        files: m.models.clone(),
        kernels: kernel_list(m.kernels.as_deref())?,
        mean_face_kernels: kernel_list(m.mean_face_kernels.as_deref())?,
        upper_bound: m.upper_bound,
        pca: m.pca.map(|n| n as usize),
        kde: None,
    })
}

/// The synthetic world of a set: its seed, identity scale and modes, over the data directory.
pub fn eval_world(data: Option<&Path>, seed: u64, scale: f32, modes: Option<usize>) -> gpmm_host::synth::SynthOptions {
    let data = data.map(Path::to_path_buf).unwrap_or_else(gpmm_host::data::default_data_dir);
    gpmm_host::synth::SynthOptions { seed, identity_scale: scale, modes, ..gpmm_host::synth::SynthOptions::with_data_dir(&data) }
}

/// What an evaluation on a `gpmm synth` set starts from: the set with its landmarks, the models
/// the command line selects and the factory that builds them.
pub struct SynthEvaluation {
    /// The set's selected identities and images, their landmarks read as the flags say.
    pub set: gpmm_host::eval::recognition::SynthSet,
    /// The selected models (a command adds its defaults).
    pub selection: gpmm_host::eval::models::ModelSelection,
    /// Builds (or reuses) the models under the output directory, in the set's world.
    pub factory: gpmm_host::eval::models::ModelFactory,
}

/// Starts an evaluation on the set in `synth` (its first `identities`, all when `None`): checks
/// that the directory exists (the message suggests `gpmm synth --count {count}`), reads the
/// landmark source and the set, and selects the models.
pub fn start_on_synth(
    synth: &Path,
    count: usize,
    identities: Option<usize>,
    landmarks: &EvalLandmarkArgs,
    models: &EvalModelArgs,
    out: &Path,
) -> Result<SynthEvaluation> {
    use gpmm_host::eval::recognition::SynthSet;
    if !synth.is_dir() {
        anyhow::bail!("synth directory {} not found (make one with `gpmm synth --count {count} --seed 1 -o DIR`)", synth.display());
    }
    let landmarks = landmarks.source()?;
    let set = SynthSet::load(synth, identities)?.with_landmarks(landmarks);
    let selection = eval_selection(models)?;
    let world = eval_world(models.data.as_deref(), set.options.seed, set.options.identity_scale, set.options.modes);
    let factory = eval_factory(models, out, world);
    Ok(SynthEvaluation { set, selection, factory })
}
