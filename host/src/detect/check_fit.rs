//! Fitting an init file's face check ([`super::check::FaceCheck`]) on real-photo sets, and writing
//! the init file with it (`gpmm check-init`).

use super::check::{features, CheckError, FaceCheck};
use super::photos::{list_photos, on_each_photo, score_image};
use super::{DetectError, Detector};
use gpmm_core::format::init_file::{write_init_file, InitFile};
use gpmm_core::net::face::Reading;
use gpmm_core::net::NetError;
use std::path::Path;

/// The least finder score of the boxes a check is fitted on (it is meant for boxes scoring as much).
pub const FIT_MIN_SCORE: f32 = 0.5;

/// Why a check could not be fitted.
#[derive(Debug, thiserror::Error)]
pub enum CheckFitError {
    /// A photo, its faces file or the networks failed.
    #[error(transparent)]
    Detect(#[from] DetectError),
    /// The regression failed.
    #[error(transparent)]
    Check(#[from] CheckError),
}

/// The boxes the finder gives at [`FIT_MIN_SCORE`] on every photo of the folders `dirs` (a photo
/// with a `STEM.faces.json` has those faces, one without is face-free, as `gpmm train-init
/// --backgrounds` reads folders), scanned down to `smallest_face` px and read as `reading` (with
/// the mirrored reading), before any check: each box's features and whether it is one of the
/// photo's known faces (intersection over union ≥ 0.5). Boxes on no known face, faces the
/// reference missed among them, count as false faces. `progress(done, total)` after each photo.
pub fn check_samples(
    detector: &Detector,
    dirs: &[&Path],
    smallest_face: f32,
    reading: Reading,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Vec<([f64; 4], bool)>, DetectError> {
    let mut photos = Vec::new();
    for dir in dirs {
        photos.extend(list_photos(dir)?);
    }
    let per_photo = on_each_photo(detector, photos, progress, |detector, _, faces, image| {
        let found = detector.scan_measured(image, FIT_MIN_SCORE, smallest_face, reading)?;
        let dets: Vec<_> = found.iter().map(|(d, _)| d.clone()).collect();
        let scored = score_image(String::new(), &faces, &dets);
        let samples: Vec<([f64; 4], bool)> = found
            .iter()
            .zip(&scored.detections)
            .filter_map(|((d, a), s)| a.filter(|a| a.is_finite()).map(|a| (features(d.face.score, &a), s.matched.is_some())))
            .collect();
        Ok(samples)
    })?;
    Ok(per_photo.into_iter().flatten().collect())
}

/// The init file `bytes` with `metadata` in place of its own (networks and header unchanged).
pub fn with_metadata(bytes: &[u8], metadata: &str) -> Result<Vec<u8>, NetError> {
    let file = InitFile::parse(bytes)?;
    let (f, i) = (file.finder.bytes(), file.initializer.bytes());
    let mut out = vec![0u8; bytes.len() + metadata.len() + 64];
    let light = u16::try_from(file.light).map_err(|_| NetError::Layer("light count"))?;
    let landmarks = u16::try_from(file.landmarks).map_err(|_| NetError::Layer("landmark count"))?;
    let len = write_init_file(&mut out, f, i, file.crop_margin, landmarks, light, metadata)?;
    out.truncate(len);
    InitFile::parse(&out)?;
    Ok(out)
}

/// Fits a face check on the real-photo sets `dirs` ([`check_samples`]), keeping `kept_share` of
/// their known faces.
pub fn fit_check(
    detector: &Detector,
    dirs: &[&Path],
    smallest_face: f32,
    reading: Reading,
    kept_share: f64,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<FaceCheck, CheckFitError> {
    let landmarks = detector.file().map_err(DetectError::Run)?.landmarks;
    if landmarks != gpmm_core::model::ibug::IBUG68_POINTS {
        return Err(CheckError::NoMirror(landmarks).into());
    }
    let samples = check_samples(detector, dirs, smallest_face, reading, progress)?;
    Ok(FaceCheck::fit(&samples, kept_share)?)
}
