//! `gpmm check-init`: learn an init file's face check from photos with known faces.

use anyhow::{Context, Result};
use clap::Args;
use gpmm_core::net::face::Reading;
use gpmm_host::detect::check::{FaceCheck, KEPT_FACE_SHARE};
use gpmm_host::detect::check_fit::{fit_check, with_metadata, FIT_MIN_SCORE};
use gpmm_host::detect::{Detector, PHOTO_MIN_SCORE};
use std::path::{Path, PathBuf};

/// Arguments of `gpmm check-init`.
#[derive(Debug, Args)]
pub struct CheckInitArgs {
    /// Init file from `gpmm train-init`.
    pub init: PathBuf,
    /// A folder of photos: a photo with a STEM.faces.json has those known faces (docs/formats.md),
    /// one without is face-free, as `train-init --backgrounds` reads folders (e.g. the folders the
    /// init file was trained on). Repeat for several folders.
    #[arg(long, value_name = "DIR", required = true)]
    pub photos: Vec<PathBuf>,
    /// Where to write the init file with its check (the networks unchanged).
    #[arg(short, long, value_name = "INIT")]
    pub output: PathBuf,
    /// Share of the photos' known faces the check keeps (its threshold).
    #[arg(long, default_value_t = KEPT_FACE_SHARE)]
    pub kept_share: f64,
    /// Smallest face (px) the scan looks for, as `gpmm detect --smallest-face`.
    #[arg(long, value_name = "PX", default_value_t = gpmm_host::detect::DEFAULT_SMALLEST_FACE)]
    pub smallest_face: f32,
}

/// Runs `gpmm check-init`.
pub fn check_init(a: CheckInitArgs) -> Result<()> {
    if !(a.kept_share > 0.0 && a.kept_share <= 1.0) {
        anyhow::bail!("--kept-share must lie in (0, 1], got {}", a.kept_share);
    }
    let mut detector = Detector::load(&a.init)?;
    detector.set_check(None);
    let dirs: Vec<&Path> = a.photos.iter().map(PathBuf::as_path).collect();
    let total: usize = dirs.iter().map(|d| gpmm_host::detect::photos::list_photos(d).map(|v| v.len())).sum::<Result<usize, _>>()?;
    if total == 0 {
        anyhow::bail!(
            "no photo with a STEM.faces.json in {}",
            a.photos.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ")
        );
    }
    let pb = crate::progress::counter(total, "photos scanned");
    let progress = |done: usize, _: usize| pb.set_position(done as u64);
    let check = fit_check(&detector, &dirs, a.smallest_face, Reading::DEFAULT, a.kept_share, &progress)?;
    pb.finish_and_clear();
    let file = detector.file().with_context(|| format!("{}: not a valid init file", a.init.display()))?;
    let metadata = check.into_metadata(file.metadata)?;
    let bytes = with_metadata(detector.bytes(), &metadata).with_context(|| format!("{}: cannot rewrite", a.init.display()))?;
    std::fs::write(&a.output, bytes).with_context(|| format!("cannot write {}", a.output.display()))?;
    report(&check);
    eprintln!(
        "wrote {} (fitted on boxes scoring {FIT_MIN_SCORE} or more; with its check, its faces count from a score of {PHOTO_MIN_SCORE} by default)",
        a.output.display()
    );
    Ok(())
}

/// Prints the check as JSON.
fn report(check: &FaceCheck) {
    println!("{}", serde_json::to_string_pretty(check).unwrap_or_default());
}
