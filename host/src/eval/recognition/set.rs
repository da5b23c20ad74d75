//! The images of a `gpmm synth` directory that an evaluation fits: the selected identities, their
//! truth and where their landmarks are read from.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use crate::eval::{file_sha256, EvalError, LandmarkSource};
use crate::synth::{read_truth, ImageTruth, SynthOptions};

/// The selected images of a synth directory: identities `0..` up to `limit`, gallery at yaw 0.
pub struct SynthSet {
    /// The directory.
    pub dir: PathBuf,
    /// Its seed.
    pub seed: u64,
    /// SHA-256 of `truth.json`.
    pub truth_sha256: String,
    /// Selected images (identity-major).
    pub images: Vec<ImageTruth>,
    /// Selected identities.
    pub identities: Vec<usize>,
    /// The world options used to render them.
    pub options: SynthOptions,
    /// Where the landmarks are read from (the set's exact `.pts` unless told otherwise).
    pub landmarks: LandmarkSource,
}

impl SynthSet {
    /// Reads `dir/truth.json` and keeps the first `limit` identities that have a yaw-0 image.
    pub fn load(dir: &Path, limit: Option<usize>) -> Result<Self, EvalError> {
        let truth_path = dir.join("truth.json");
        if !truth_path.is_file() {
            return Err(EvalError::NotASynthDir { dir: dir.to_path_buf() });
        }
        let truth = read_truth(&truth_path)?;
        let with_gallery: BTreeSet<usize> = truth.images.iter().filter(|t| t.yaw_deg == 0.0).map(|t| t.identity).collect();
        if with_gallery.is_empty() {
            return Err(EvalError::NoGallery(dir.to_path_buf()));
        }
        let identities: Vec<usize> = with_gallery.into_iter().take(limit.unwrap_or(usize::MAX)).collect();
        let keep: BTreeSet<usize> = identities.iter().copied().collect();
        let images: Vec<ImageTruth> = truth.images.into_iter().filter(|t| keep.contains(&t.identity)).collect();
        if images.iter().all(|t| t.yaw_deg == 0.0) {
            return Err(EvalError::NoProbes(dir.to_path_buf()));
        }
        Ok(Self {
            dir: dir.to_path_buf(),
            seed: truth.seed,
            truth_sha256: file_sha256(&truth_path)?,
            images,
            identities,
            options: truth.options,
            landmarks: LandmarkSource::default(),
        })
    }

    /// The same set, fitted with the landmarks of `landmarks` instead of the exact ones.
    pub fn with_landmarks(self, landmarks: LandmarkSource) -> Self {
        Self { landmarks, ..self }
    }

    /// The selected images as identification sees them.
    pub fn labeled_images(&self) -> Vec<LabeledImage<'_>> {
        self.images.iter().map(|t| LabeledImage { image: &t.image, identity: t.identity, yaw_deg: t.yaw_deg }).collect()
    }

    /// The probe yaws (all but 0, ascending).
    pub fn probe_yaws(&self) -> Vec<f32> {
        let mut y: Vec<f32> = self.images.iter().map(|t| t.yaw_deg).filter(|&y| y != 0.0).collect();
        y.sort_by(f32::total_cmp);
        y.dedup();
        y
    }
}

/// An image as identification sees it: its file name, true identity and yaw (yaw 0: the gallery).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LabeledImage<'a> {
    /// Image file name (the key of its fits).
    pub image: &'a str,
    /// True identity.
    pub identity: usize,
    /// Yaw (degrees).
    pub yaw_deg: f32,
}
