//! The face finder and the initializer read from an init file and run on an image through the
//! core ([`Detector`]), and measured on images with reference landmarks ([`eval`]). Training
//! them and writing init files is the `gpmm-train` crate's job.

pub mod check;
pub mod check_fit;
pub mod eval;
pub mod for_fit;
pub mod photos;
pub mod provenance;
pub mod record;
pub mod shipped;

use check::FaceCheck;
use gpmm_core::format::init_file::InitFile;
use gpmm_core::net::agreement::ReadingAgreement;
use gpmm_core::net::face::{detect, read_landmarks, read_landmarks_measured, Detection, Reading};
use gpmm_core::net::face_box::FaceBox;
use gpmm_core::net::scan::{scan_faces, smallest_listed};
use gpmm_core::net::{NetError, NetScratch};
use image::RgbImage;
use std::path::{Path, PathBuf};

/// Bytes of each activation buffer the host gives the networks.
pub const HOST_NET_SCRATCH: usize = 64 * 1024;

/// Most faces a scan of a photo reports ([`Detector::scan_all`]): a group photo has more than the
/// core's [`gpmm_core::net::face::MAX_FACES`] for a camera frame.
pub const PHOTO_MAX_FACES: usize = 32;

/// Landmark σ (fraction of the fit's image side) for landmarks read by the initializer: the
/// core's one definition, which `gpmm fit --init` and `gpmm device-fit --init` both default to.
pub use gpmm_core::fit::INIT_LANDMARK_SIGMA;

/// Why an init file could not be read or its networks run.
#[derive(Debug, thiserror::Error)]
pub enum DetectError {
    /// The file could not be read or written.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The IO error.
        error: std::io::Error,
    },
    /// The bytes are not a valid init file.
    #[error("{path}: not a valid init file: {error}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What the core's reader refused.
        error: NetError,
    },
    /// The file's face check (its metadata) is not readable.
    #[error("{path}: {error}")]
    Check {
        /// The file.
        path: PathBuf,
        /// What was wrong.
        error: check::CheckError,
    },
    /// A run of the networks failed.
    #[error("the face networks refused the image: {0}")]
    Run(NetError),
}

/// A scan's faces split by the face check ([`Detector::scan_split`]).
#[derive(Debug, Clone, Default)]
pub struct CheckedFaces {
    /// The faces that pass the check (every face without one); best first.
    pub kept: Vec<Detection>,
    /// The faces whose reading failed the check; best first.
    pub refused: Vec<Detection>,
}

/// The finder and the initializer of an init file, loaded into a 4-aligned buffer with scratch
/// for their runs (a clone has its own scratch, for another thread).
#[derive(Debug, Clone)]
pub struct Detector {
    words: Vec<u32>,
    len: usize,
    scratch: Box<NetScratch<HOST_NET_SCRATCH>>,
    check: Option<FaceCheck>,
    every_size: bool,
}

impl Detector {
    /// Reads and validates an init file.
    pub fn load(path: &Path) -> Result<Self, DetectError> {
        let bytes = std::fs::read(path).map_err(|error| DetectError::Io { path: path.to_owned(), error })?;
        let detector = Self::from_bytes(&bytes).map_err(|error| DetectError::Invalid { path: path.to_owned(), error })?;
        let metadata = detector.file().map(|f| f.metadata).unwrap_or("");
        FaceCheck::from_metadata(metadata).map_err(|error| DetectError::Check { path: path.to_owned(), error })?;
        Ok(detector)
    }

    /// Validates init-file bytes (copied into an aligned buffer).
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, NetError> {
        let mut words = vec![0u32; bytes.len().div_ceil(4)];
        bytemuck::cast_slice_mut::<u32, u8>(&mut words)[..bytes.len()].copy_from_slice(bytes);
        let mut model = Self { words, len: bytes.len(), scratch: Box::new(NetScratch::new()), check: None, every_size: false };
        let file = model.file()?;
        if file.scratch_bytes() > HOST_NET_SCRATCH {
            return Err(NetError::ScratchTooSmall { needed: file.scratch_bytes() });
        }
        // A check that cannot be read is reported by `load`; here the file is used without it.
        model.check = FaceCheck::from_metadata(file.metadata).ok().flatten();
        Ok(model)
    }

    /// The file's face check ([`check`]), if it has one and it is in use.
    pub fn check(&self) -> Option<&FaceCheck> {
        self.check.as_ref()
    }

    /// The least finder score a command takes as a face with this file by default: a file with a
    /// face check was trained on real photos (as the shipped start was) and gets
    /// [`PHOTO_MIN_SCORE`], any other [`DEFAULT_MIN_SCORE`].
    pub fn advised_min_score(&self) -> f32 {
        if self.check.is_some() {
            PHOTO_MIN_SCORE
        } else {
            DEFAULT_MIN_SCORE
        }
    }

    /// Scans list faces of every size (`true`; for a command that picks one face by its own rule,
    /// as `gpmm learn`), or none read smaller than the photo rule's
    /// [`gpmm_core::net::scan::smallest_listed`] (the default).
    pub fn list_every_size(&mut self, every_size: bool) {
        self.every_size = every_size;
    }

    /// Uses `check` for photos' faces instead of the file's (`None`: no check).
    pub fn set_check(&mut self, check: Option<FaceCheck>) {
        self.check = check;
    }

    /// The file's bytes.
    pub fn bytes(&self) -> &[u8] {
        &bytemuck::cast_slice::<u32, u8>(&self.words)[..self.len]
    }

    /// The parsed file.
    pub fn file(&self) -> Result<InitFile<'_>, NetError> {
        InitFile::parse(self.bytes())
    }

    /// Finds and reads the face in `image` as `reading` says; `None` if the finder's score is
    /// below `min_score`.
    pub fn detect(&mut self, image: &RgbImage, min_score: f32, reading: Reading) -> Result<Option<Detection>, DetectError> {
        let (file, scratch) = self.parts()?;
        let (w, h) = image.dimensions();
        detect(&file, image.as_raw(), w as usize, h as usize, min_score, reading, scratch).map_err(DetectError::Run)
    }

    /// Finds every face in a photo whose finder score reaches `min_score`, scanning windows at
    /// several scales for faces down to `smallest_face` pixels ([`gpmm_core::net::scan`]), and
    /// reads each as `reading` says; best first. With a face check ([`Detector::check`]), a face
    /// whose reading fails it is left out.
    pub fn scan_all(
        &mut self,
        image: &RgbImage,
        min_score: f32,
        smallest_face: f32,
        reading: Reading,
    ) -> Result<Vec<Detection>, DetectError> {
        self.scan_checked(image, (min_score, smallest_face), reading, false)
    }

    /// The faces a command that fits one face chooses from (`gpmm fit --init`, `learn`):
    /// [`Detector::scan_all`]'s, or, when the face check leaves none, every face the finder found
    /// (the image was given as a face's; a true face the check refuses is better fitted than
    /// none).
    pub fn scan_for_fit(
        &mut self,
        image: &RgbImage,
        min_score: f32,
        smallest_face: f32,
        reading: Reading,
    ) -> Result<Vec<Detection>, DetectError> {
        self.scan_checked(image, (min_score, smallest_face), reading, true)
    }

    /// [`Detector::scan_all`]'s faces and, apart, those the face check refused (so a command can
    /// say that boxes were found but their readings failed the check); each list best first.
    pub fn scan_split(
        &mut self,
        image: &RgbImage,
        min_score: f32,
        smallest_face: f32,
        reading: Reading,
    ) -> Result<CheckedFaces, DetectError> {
        let check = self.check;
        let found = self.scan_measured(image, min_score, smallest_face, reading)?;
        let (kept, refused): (Vec<_>, Vec<_>) =
            found.into_iter().partition(|(det, a)| check.is_none_or(|c| c.passes(det.face.score, a.as_ref())));
        let faces = |list: Vec<(Detection, Option<ReadingAgreement>)>| list.into_iter().map(|(det, _)| det).collect();
        Ok(CheckedFaces { kept: faces(kept), refused: faces(refused) })
    }

    /// [`Detector::scan_measured`]'s faces that pass the face check; all of them if there is no
    /// check, or if none passes and `all_if_none`.
    fn scan_checked(
        &mut self,
        image: &RgbImage,
        (min_score, smallest_face): (f32, f32),
        reading: Reading,
        all_if_none: bool,
    ) -> Result<Vec<Detection>, DetectError> {
        let CheckedFaces { kept, refused } = self.scan_split(image, min_score, smallest_face, reading)?;
        Ok(if all_if_none && kept.is_empty() { refused } else { kept })
    }

    /// [`Detector::scan_all`]'s faces before the face check, each with how well its reading
    /// agrees with its mirror image and the box (`None` without the mirrored reading).
    pub fn scan_measured(
        &mut self,
        image: &RgbImage,
        min_score: f32,
        smallest_face: f32,
        reading: Reading,
    ) -> Result<Vec<(Detection, Option<ReadingAgreement>)>, DetectError> {
        let faces = self.scan_boxes(image, min_score, smallest_face)?;
        let (file, scratch) = self.parts()?;
        let (w, h) = (image.width() as usize, image.height() as usize);
        let mut out = Vec::with_capacity(faces.len());
        for face in faces {
            out.push(read_landmarks_measured(&file, image.as_raw(), w, h, face, reading, scratch).map_err(DetectError::Run)?);
        }
        Ok(out)
    }

    /// The boxes of [`Detector::scan_all`]'s faces, unread (the finder only); best first.
    pub fn scan_boxes(&mut self, image: &RgbImage, min_score: f32, smallest_face: f32) -> Result<Vec<FaceBox>, DetectError> {
        let listed = if self.every_size { 0.0 } else { smallest_listed(smallest_face) };
        let (file, scratch) = self.parts()?;
        let (w, h) = (image.width() as usize, image.height() as usize);
        let faces =
            scan_faces::<HOST_NET_SCRATCH, PHOTO_MAX_FACES>(&file, image.as_raw(), w, h, min_score, (smallest_face, listed), scratch)
                .map_err(DetectError::Run)?;
        Ok(faces.into_iter().collect())
    }

    /// Reads the face in a given box (no finder run), as `reading` says.
    pub fn read_at(&mut self, image: &RgbImage, face: FaceBox, reading: Reading) -> Result<Detection, DetectError> {
        let (file, scratch) = self.parts()?;
        let (w, h) = image.dimensions();
        read_landmarks(&file, image.as_raw(), w as usize, h as usize, face, reading, scratch).map_err(DetectError::Run)
    }

    /// The parsed file and the scratch its networks run in.
    fn parts(&mut self) -> Result<(InitFile<'_>, &mut NetScratch<HOST_NET_SCRATCH>), DetectError> {
        let bytes = bytemuck::cast_slice::<u32, u8>(&self.words).get(..self.len).unwrap_or(&[]);
        Ok((InitFile::parse(bytes).map_err(DetectError::Run)?, &mut self.scratch))
    }
}

/// The smallest face (px) a scan of a photo looks for by default ([`Detector::scan_all`]). Chosen
/// at minimum score 0.9 on photos of people the finder of the recipe's training never saw (the
/// pool's photos beyond its first four repositories: 232 photos, 316 faces of 64 px and more, 170
/// of 32–64 px) and on the real-photo development set, with each window's face confirmed by a
/// closer look: 32 px finds 266 and 98 of them (dev 13 of 16, 0.09 false positives per face-free
/// photo), 48 px 252 and 69 (dev 11), 96 px 170 and 6 (dev 12). Without the confirming look,
/// smaller sizes added windows whose false positives outscored true faces.
pub const DEFAULT_SMALLEST_FACE: f32 = 32.0;

/// The least finder score advised for faces of real photos (`--min-score`): on photos no training
/// saw it kept false positives at 0.05 per face-free photo with the face check, where 0.5 gave
/// 0.025–0.125 from one training to the next (docs/real-photos.md).
pub const PHOTO_MIN_SCORE: f32 = 0.9;

/// The least finder score a command takes as a face by default (`gpmm detect`, `fit --init`,
/// `learn`).
pub const DEFAULT_MIN_SCORE: f32 = 0.05;

/// The share of the best face's finder score a face needs for [`choose_face`] to take it for
/// being larger. On the realistic development set the largest face above the minimum score was a
/// weak false positive in 120 of 210 renders; the largest within 0.95 of the best score is the
/// true face in all 210 (0.9: 207), as the best-scored face is
/// (`tests/realistic/chosen_face.py SET --init INIT`).
pub const LARGEST_AMONG_SCORE_SHARE: f32 = 0.95;

/// Which face of several a command takes: `index` if it names one (the order
/// [`Detector::scan_all`] gives, from 0), else the largest of the faces scoring at least
/// [`LARGEST_AMONG_SCORE_SHARE`] of the best one (the finder's near-ties; the earliest on equal
/// sizes); `None` if there is no such face.
pub fn choose_face(faces: &[Detection], index: Option<usize>) -> Option<usize> {
    match index {
        Some(i) => (i < faces.len()).then_some(i),
        None => {
            let best = faces.iter().map(|d| d.face.score).fold(f32::NEG_INFINITY, f32::max);
            let near_best = |d: &Detection| d.face.score >= LARGEST_AMONG_SCORE_SHARE * best;
            let candidates = faces.iter().enumerate().filter(|(_, d)| near_best(d));
            candidates.max_by(|(a, da), (b, db)| da.face.size.total_cmp(&db.face.size).then(b.cmp(a))).map(|(i, _)| i)
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn found(score: f32, size: f32) -> Detection {
        let face = FaceBox { cx: 0.0, cy: 0.0, size, score, looks: 1 };
        Detection { face, landmarks: Default::default(), angles: [0.0; 3], light: Default::default() }
    }

    #[test]
    fn the_largest_of_the_near_best_faces_is_chosen_not_a_large_weak_one() {
        // Best first, as the finder lists them: a large weak box, a near-tie that is larger.
        let faces = [found(0.98, 100.0), found(0.95, 140.0), found(0.2, 400.0)];
        assert_eq!(choose_face(&faces, None), Some(1));
        // Without a near-tie the best face is taken, however large the weak one.
        let faces = [found(0.98, 100.0), found(0.5, 400.0)];
        assert_eq!(choose_face(&faces, None), Some(0));
        // An index is taken as given, and checked.
        assert_eq!(choose_face(&faces, Some(1)), Some(1));
        assert_eq!(choose_face(&faces, Some(2)), None);
        assert_eq!(choose_face(&[], None), None);
    }
}
