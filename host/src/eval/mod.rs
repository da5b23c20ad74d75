//! The paper's evaluation on synthetic faces: recognition across yaw ([`recognition`]) and
//! specificity / generalization / compactness ([`specgen`]) of the models it compares
//! ([`models`]: the template kernels, the multi-scan KDE, the PCA baseline and the generating world
//! as an upper bound), with line plots ([`plot`]), and fits scored against a synthetic set's truth
//! ([`bench_fit`]).
//!
//! Multi-PIE (the paper's recognition data) is not available, so the protocol runs on images
//! rendered by `gpmm synth` ([`crate::synth`]) from the ICT-FaceKit identity model: a real face
//! model made by others, which none of the evaluated models is built from (except the upper bound,
//! on purpose).

pub mod bench_fit;
pub mod label_truth;
pub mod model_frame;
pub mod models;
pub mod plot;
pub mod recognition;
pub mod reconstruction;
pub mod specgen;

use std::path::{Path, PathBuf};

/// Why an evaluation could not run; every file error names its file.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// A file or directory could not be read, written or created.
    #[error("{}: {action}: {error}", path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// What was being done.
        action: &'static str,
        /// The underlying error.
        error: std::io::Error,
    },
    /// A model file could not be read or written.
    #[error(transparent)]
    ModelFile(#[from] crate::gp::model_io::ModelIoError),
    /// The synthetic world or a `gpmm synth` directory could not be read.
    #[error(transparent)]
    Synth(#[from] crate::synth::SynthError),
    /// A template or scan could not be imported.
    #[error(transparent)]
    Template(#[from] crate::mesh::template::TemplateError),
    /// A mesh could not be written.
    #[error(transparent)]
    Mesh(#[from] crate::mesh::io::MeshIoError),
    /// A registration failed.
    #[error(transparent)]
    Register(#[from] crate::fit::register::RegisterError),
    /// A chart could not be drawn.
    #[error(transparent)]
    Plot(#[from] plot::PlotError),
    /// A PNG figure could not be written.
    #[error("{}: cannot write: {error}", path.display())]
    Png {
        /// The file.
        path: PathBuf,
        /// Why.
        error: image::ImageError,
    },
    /// A detector calibration file could not be read (the error names the file).
    #[error(transparent)]
    Calibration(#[from] crate::photo::calibration::CalibrationError),
    /// The fit settings are out of range.
    #[error(transparent)]
    Settings(#[from] crate::fit::FitRunError),
    /// A kernel name is not one of the nine.
    #[error(transparent)]
    Kernel(#[from] crate::gp::kernel::UnknownKernel),
    /// Something could not be written as JSON.
    #[error("{what}: {error}")]
    Json {
        /// What was written.
        what: &'static str,
        /// Why it failed.
        error: serde_json::Error,
    },
    /// A directory is not a `gpmm synth` directory.
    #[error("{} not found: is {} a `gpmm synth` directory?", dir.join("truth.json").display(), dir.display())]
    NotASynthDir {
        /// The directory.
        dir: PathBuf,
    },
    /// A synth directory has no yaw-0 images to make the gallery of.
    #[error("{}: no yaw-0 images, so no gallery (render with --yaws 0,...)", .0.display())]
    NoGallery(PathBuf),
    /// A synth directory has only yaw-0 images, so no probes.
    #[error("{}: only yaw-0 images, so no probes", .0.display())]
    NoProbes(PathBuf),
    /// A model file lacks the 68 iBUG landmarks an evaluation needs.
    #[error("{}: the model has {count} landmarks; recognition needs the 68 iBUG landmarks", path.display())]
    ModelLandmarks {
        /// The model file.
        path: PathBuf,
        /// Its landmark count.
        count: usize,
    },
    /// The worker threads could not be started.
    #[error("cannot start {jobs} threads: {error}")]
    Threads {
        /// The threads asked for.
        jobs: usize,
        /// Why.
        error: rayon::ThreadPoolBuildError,
    },
    /// The input does not allow the evaluation (e.g. no gallery images, a model without landmarks).
    #[error("{0}")]
    Invalid(String),
}

/// Why one image of a synthetic set could not be fitted: the image, then the fit's error.
#[derive(Debug, thiserror::Error)]
#[error("{image}: {error}")]
pub struct ImageFitError {
    /// The image's file name.
    pub image: String,
    /// Why its fit failed.
    pub error: crate::fit::FitRunError,
}

impl ImageFitError {
    /// A map from the fit's error to this one, naming `image`.
    pub(crate) fn naming(image: &str) -> impl FnOnce(crate::fit::FitRunError) -> Self + '_ {
        move |error| Self { image: image.to_string(), error }
    }
}

/// `EvalError::Io` for `path`.
pub(crate) fn io_err<'a>(path: &'a Path, action: &'static str) -> impl FnOnce(std::io::Error) -> EvalError + 'a {
    move |error| EvalError::Io { path: path.to_path_buf(), action, error }
}

/// Writes `text` to `path`, naming the file on failure.
pub(crate) fn write_text(path: &Path, text: &str) -> Result<(), EvalError> {
    std::fs::write(path, text).map_err(io_err(path, "cannot write"))
}

/// Creates a directory (and its parents), naming it on failure.
pub(crate) fn create_dir(path: &Path) -> Result<(), EvalError> {
    std::fs::create_dir_all(path).map_err(io_err(path, "cannot create the directory"))
}

/// Writes a PNG figure, naming the file on failure.
pub(crate) fn save_png(image: &image::RgbaImage, path: &Path) -> Result<(), EvalError> {
    crate::render::figure::save_png(image, path).map_err(|error| EvalError::Png { path: path.to_path_buf(), error })
}

/// The Wilson score interval of `successes` out of `trials` at the normal quantile `z` (1.96 for 95 %).
///
/// Returns `(low, high)` as fractions in \[0, 1\]; `(0, 1)` when there are no trials.
pub fn wilson_interval(successes: usize, trials: usize, z: f64) -> (f64, f64) {
    if trials == 0 {
        return (0.0, 1.0);
    }
    let n = trials as f64;
    let p = successes.min(trials) as f64 / n;
    let z2 = z * z;
    let denom = 1.0 + z2 / n;
    let centre = (p + z2 / (2.0 * n)) / denom;
    let half = z * (p * (1.0 - p) / n + z2 / (4.0 * n * n)).sqrt() / denom;
    ((centre - half).max(0.0), (centre + half).min(1.0))
}

/// Cosine similarity of two vectors (0 if either is zero; the shorter is zero-padded).
pub fn cosine(a: &[f32], b: &[f32]) -> f64 {
    let (mut ab, mut aa, mut bb) = (0.0f64, 0.0f64, 0.0f64);
    for k in 0..a.len().max(b.len()) {
        let x = f64::from(a.get(k).copied().unwrap_or(0.0));
        let y = f64::from(b.get(k).copied().unwrap_or(0.0));
        ab += x * y;
        aa += x * x;
        bb += y * y;
    }
    if aa > 0.0 && bb > 0.0 {
        ab / (aa.sqrt() * bb.sqrt())
    } else {
        0.0
    }
}

/// Where a synthetic set's fits read their landmarks: the set's exact `.pts` or the files of the
/// same names in another directory (e.g. a detector's), optionally corrected with a detector
/// calibration.
#[derive(Debug, Clone, Default)]
pub struct LandmarkSource {
    /// Directory of the landmark files (`None`: the set's own, exact ones).
    pub dir: Option<PathBuf>,
    /// The calibration file and its contents (`None`: the points as read).
    pub calibration: Option<(PathBuf, crate::photo::calibration::LandmarkCalibration)>,
}

impl LandmarkSource {
    /// Landmarks from `dir` (or the set's), corrected with the calibration file `calibration` if given.
    pub fn new(dir: Option<PathBuf>, calibration: Option<&Path>) -> Result<Self, EvalError> {
        let calibration = match calibration {
            Some(p) => Some((p.to_path_buf(), crate::photo::calibration::LandmarkCalibration::read(p)?)),
            None => None,
        };
        Ok(Self { dir, calibration })
    }

    /// The landmark file of an image whose own file is `set_dir/file`.
    pub fn file(&self, set_dir: &Path, file: &str) -> PathBuf {
        self.dir.as_deref().unwrap_or(set_dir).join(file)
    }

    /// The calibration to correct the points with.
    pub fn calibration(&self) -> Option<&crate::photo::calibration::LandmarkCalibration> {
        self.calibration.as_ref().map(|(_, c)| c)
    }

    /// "exact", or the directory, with the calibration file if any (for reports and cache keys).
    pub fn describe(&self) -> String {
        let base = self.dir.as_ref().map_or_else(|| "exact".to_string(), |d| d.display().to_string());
        match &self.calibration {
            Some((p, _)) => format!("{base}, calibrated with {}", p.display()),
            None => base,
        }
    }
}

/// SHA-256 of a file's bytes, hex (identifies a model in the fit cache).
pub fn file_sha256(path: &Path) -> Result<String, EvalError> {
    use sha2::{Digest, Sha256};
    let bytes = std::fs::read(path).map_err(io_err(path, "cannot read"))?;
    Ok(Sha256::digest(&bytes).iter().map(|b| format!("{b:02x}")).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wilson_matches_known_values() {
        // 44 of 50: the Wilson 95 % interval is about [0.762, 0.944].
        let (lo, hi) = wilson_interval(44, 50, 1.96);
        assert!((lo - 0.7624).abs() < 2e-3 && (hi - 0.9437).abs() < 2e-3, "{lo} {hi}");
        let (lo, hi) = wilson_interval(0, 10, 1.96);
        assert!(lo == 0.0 && (hi - 0.2775).abs() < 2e-3, "{hi}");
        let (lo, hi) = wilson_interval(10, 10, 1.96);
        assert!(hi == 1.0 && (lo - 0.7225).abs() < 2e-3, "{lo}");
        assert_eq!(wilson_interval(0, 0, 1.96), (0.0, 1.0));
    }

    #[test]
    fn cosine_of_parallel_and_orthogonal_vectors() {
        assert!((cosine(&[1.0, 2.0], &[2.0, 4.0]) - 1.0).abs() < 1e-12);
        assert!(cosine(&[1.0, 0.0], &[0.0, 3.0]).abs() < 1e-12);
        assert!((cosine(&[1.0, 1.0], &[-1.0, -1.0]) + 1.0).abs() < 1e-12);
        assert_eq!(cosine(&[0.0; 3], &[1.0; 3]), 0.0);
    }
}
