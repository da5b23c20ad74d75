//! The real photos a training of the finder and initializer learns from: the options that
//! `gpmm train-init` and `gpmm learn --retrain-init` share, and the face check fitted on them.

use crate::progress::note;
use anyhow::{bail, Result};
use clap::Args;
use gpmm_train::scene::backgrounds::Backgrounds;
use gpmm_train::TrainOptions;
use indicatif::ProgressBar;
use std::path::{Path, PathBuf};

/// Real photographs in a training's scenes.
#[derive(Debug, Clone, Args)]
pub struct TrainingPhotos {
    /// Folder of photos (.jpg/.png) to draw some scenes over, and to cut face-free frames from
    /// that the finder learns as "no face" (the hardest of several candidates, by the finder's own
    /// score, each chunk); repeat for several folders. A photo with a STEM.faces.json beside it
    /// (the real-photo set format) is a photo of people: no cut touches its faces, so its hands,
    /// clothes and rooms are learned as background, and its faces are shown to the finder as
    /// faces (--photo-faces). `tests/realphotos/backgrounds.py` makes a folder from Debian's
    /// wallpaper packages, `tests/realphotos/make_pool.py` one of people from face projects'
    /// example photos. When they hold photos of people, a face check is fitted on them at the
    /// end (`gpmm check-init`). Default: procedural backgrounds only.
    #[arg(long, value_name = "DIR")]
    pub backgrounds: Vec<PathBuf>,
    /// Fraction of scenes drawn over a photo of --backgrounds (the rest over procedural ones).
    #[arg(long, value_name = "F", default_value_t = 0.5, requires = "backgrounds")]
    pub background_share: f64,
    /// Face-free frames per scene with --backgrounds.
    #[arg(long, value_name = "F", requires = "backgrounds")]
    pub face_free: Option<f64>,
    /// Real faces (from photos of people among --backgrounds) per scene in both networks'
    /// batches (default 0.25): the finder learns them as faces, the initializer their reference
    /// points (their pose and light are unknown, so those it learns from renders only).
    #[arg(long, value_name = "F", requires = "backgrounds")]
    pub photo_faces: Option<f64>,
    /// The initializer learns from rendered faces only, not the real faces' reference points
    /// (those points carry the reference detector's habits: a model learned from fits that start
    /// from them identified fewer faces, docs/learning.md).
    #[arg(long, requires = "backgrounds")]
    pub no_photo_points: bool,
    /// Fine-tuning: the finder being fine-tuned first scans every --backgrounds photo as `gpmm
    /// detect` scans a photo (score 0.5 and up, faces down to 32 px), and each box it keeps on a
    /// face-free part (on a photo of people, touching none of its known faces) is shown as "no
    /// face" at three zooms and mirrored (2 in a batch of 64 scenes): the scan's own mistakes on
    /// small windows, which random views of the photos rarely show it (docs/real-photos.md)
    #[arg(long, requires = "backgrounds")]
    pub scan_mistakes: bool,
}

impl TrainingPhotos {
    /// Sets `opts`' photo options from these; an error names an option out of range.
    pub fn set_options(&self, opts: &mut TrainOptions) -> Result<()> {
        if !(0.0..=1.0).contains(&self.background_share) {
            bail!("--background-share {} is not a fraction from 0 to 1", self.background_share);
        }
        opts.face_free = self.face_free.unwrap_or(opts.face_free);
        if !(0.0..=1.0).contains(&opts.face_free) {
            bail!("--face-free {} is not a fraction from 0 to 1", opts.face_free);
        }
        opts.photo_faces = self.photo_faces.unwrap_or(opts.photo_faces);
        if !(0.0..=1.0).contains(&opts.photo_faces) {
            bail!("--photo-faces {} is not a fraction from 0 to 1", opts.photo_faces);
        }
        opts.photo_points = !self.no_photo_points;
        opts.scan_mistakes = self.scan_mistakes.then(gpmm_train::mistakes::MistakeScan::default);
        Ok(())
    }

    /// The --backgrounds folders, loaded, with a line saying what they hold; `None` without them.
    pub fn load(&self) -> Result<Option<Backgrounds>> {
        if self.backgrounds.is_empty() {
            return Ok(None);
        }
        let dirs: Vec<&Path> = self.backgrounds.iter().map(PathBuf::as_path).collect();
        let b = Backgrounds::load_all(&dirs, self.background_share)?;
        let names: Vec<String> = dirs.iter().map(|d| d.display().to_string()).collect();
        eprintln!(
            "backgrounds: {} photos from {}, {} of them of people with {} known faces",
            b.len(),
            names.join(", "),
            b.people_photos(),
            b.faces()
        );
        Ok(Some(b))
    }

    /// `bytes` (a trained init file) with a face check fitted on the --backgrounds photos
    /// ([`gpmm_host::detect::check_fit::fit_check`]) when `backgrounds` holds photos of people;
    /// unchanged otherwise, or with a note when too few boxes were found to fit one.
    pub fn with_face_check(&self, bytes: Vec<u8>, backgrounds: &Backgrounds, bar: &ProgressBar) -> Result<Vec<u8>> {
        use gpmm_host::detect::check::{CheckError, KEPT_FACE_SHARE};
        use gpmm_host::detect::check_fit::{fit_check, with_metadata, CheckFitError};
        if backgrounds.people_photos() == 0 {
            return Ok(bytes);
        }
        bar.set_message("fitting the face check on the backgrounds".to_string());
        let detector = gpmm_host::detect::Detector::from_bytes(&bytes).map_err(|e| anyhow::anyhow!("the trained file: {e}"))?;
        let dirs: Vec<&Path> = self.backgrounds.iter().map(PathBuf::as_path).collect();
        let smallest = gpmm_host::detect::DEFAULT_SMALLEST_FACE;
        let reading = gpmm_core::net::face::Reading::DEFAULT;
        match fit_check(&detector, &dirs, smallest, reading, KEPT_FACE_SHARE, &|_, _| {}) {
            Ok(check) => {
                let file = detector.file().map_err(|e| anyhow::anyhow!("the trained file: {e}"))?;
                let metadata = check.into_metadata(file.metadata)?;
                note(bar, format!("face check: fitted on {} known faces and {} other boxes", check.faces, check.others));
                with_metadata(&bytes, &metadata).map_err(|e| anyhow::anyhow!("the trained file with its face check: {e}"))
            }
            Err(CheckFitError::Check(e @ (CheckError::TooFew { .. } | CheckError::NoMirror(_)))) => {
                note(bar, format!("no face check: {e}"));
                Ok(bytes)
            }
            Err(e) => Err(e.into()),
        }
    }
}
