//! `gpmm calibrate-landmarks`: learn a detector's systematic offsets from images with known landmarks.

use anyhow::{bail, Context, Result};
use clap::Args;
use gpmm_host::photo::calibration::{LandmarkCalibration, MAX_DEGREE};
use gpmm_host::photo::pts::read_pts;
use std::path::PathBuf;

/// Arguments of `gpmm calibrate-landmarks`.
#[derive(Debug, Args)]
pub struct CalibrateArgs {
    /// Directory of the detector's iBUG-68 `.pts` files (one per image).
    #[arg(long, value_name = "DIR")]
    pub detected: PathBuf,
    /// Directory of the true landmarks: a `.pts` of the same name for every detected file (e.g.
    /// the `gpmm synth` set or the rendered set the detector ran on).
    #[arg(long, value_name = "DIR")]
    pub exact: PathBuf,
    /// Degree of the offsets' polynomial in the face's turn (0: one constant offset per point;
    /// 2 follows how the offsets change from frontal to 45°).
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u64).range(0..=MAX_DEGREE as u64))]
    pub degree: u64,
    /// What the calibration belongs to (written into the file), e.g. the detector and its mapping.
    #[arg(long, default_value = "unnamed detector")]
    pub detector: String,
    /// Output calibration file (JSON).
    #[arg(short, long, value_name = "FILE")]
    pub output: PathBuf,
}

/// Runs `gpmm calibrate-landmarks`.
pub fn calibrate(a: CalibrateArgs) -> Result<()> {
    let mut names: Vec<PathBuf> = std::fs::read_dir(&a.detected)
        .with_context(|| format!("cannot read the directory {}", a.detected.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "pts"))
        .collect();
    names.sort();
    if names.is_empty() {
        bail!("{}: no .pts files", a.detected.display());
    }
    let mut pairs = Vec::with_capacity(names.len());
    for d in &names {
        let name = d.file_name().unwrap_or_default();
        let e = a.exact.join(name);
        if !e.is_file() {
            bail!("{}: no true landmarks for it ({} does not exist)", d.display(), e.display());
        }
        pairs.push((read_pts(&e, false)?.points, read_pts(d, false)?.points));
    }
    let cal = LandmarkCalibration::learn(&pairs, a.degree as usize, &a.detector)?;
    cal.write(&a.output)?;
    eprintln!(
        "learned from {} images: median RMS detected -> true {:.2} px, after correction {:.2} px; wrote {}",
        cal.training.images,
        cal.training.median_rms_px_before,
        cal.training.median_rms_px_after,
        a.output.display()
    );
    println!("{}", serde_json::to_string_pretty(&cal.training)?);
    Ok(())
}
