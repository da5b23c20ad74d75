//! Each learned model against its predecessor on a development set whose true faces are known: a
//! `gpmm synth` set, or a set made from one, with its `truth.json`.
//!
//! The development images are fitted as the loop fits its own images: the same start points (the
//! init file's finder and initializer, or landmark files when the loop reads those) and the same fit
//! settings. Each fit is measured against its true face as `gpmm eval reconstruction` measures it
//! (similarity alignment, scan-to-mesh distance); the median over all measured vertices decides. A
//! model that is not better than its predecessor is not kept and the loop stops.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::start_points;
use crate::detect::Detector;
use crate::eval::models::scans::EvalWorld;
use crate::eval::recognition::{Row, SynthSet};
use crate::eval::reconstruction::report::{evaluate, Progress};
use crate::eval::{EvalError, LandmarkSource};
use crate::fit::FitOptions;
use crate::synth::SynthOptions;

/// The development set prepared for the loop: its images' start points and its true faces.
pub struct DevSet {
    /// The set, its landmarks read from the start points.
    set: SynthSet,
    /// The world that rendered it (the true faces).
    world: EvalWorld,
    /// The work directory: `points/` (with an init file) and the fit cache `fits/`.
    work: PathBuf,
    /// Images the finder found no face in (their fits fail and are left out).
    pub unfound: usize,
}

/// Where the development images' start points come from: as the loop's own.
#[derive(Debug, Clone, Copy)]
pub enum DevPoints<'a> {
    /// The init file's finder and initializer (its bytes).
    Init(&'a [u8]),
    /// Landmark files `DIR/STEM.pts`.
    Files(&'a Path),
}

/// One model's figures on the development set.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DevFigure {
    /// The model file.
    pub model: String,
    /// Median scan-to-mesh distance of the fits over all measured vertices (mm).
    pub median_mm: f64,
    /// Their mean (mm).
    pub mean_mm: f64,
    /// Images measured.
    pub fits: usize,
    /// Images whose fit failed.
    pub failed: usize,
}

/// An iteration's model against its predecessor's.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DevComparison {
    /// The development set's directory.
    pub set: String,
    /// The model the iteration started from.
    pub previous: DevFigure,
    /// The model it made.
    pub learned: DevFigure,
    /// Whether the learned model is kept (its median below its predecessor's).
    pub kept: bool,
}

impl DevComparison {
    /// Compares `learned` with `previous`: kept when its median error is lower.
    pub fn new(set: &Path, previous: DevFigure, learned: DevFigure) -> Self {
        let kept = learned.median_mm < previous.median_mm;
        Self { set: set.display().to_string(), previous, learned, kept }
    }
}

impl DevSet {
    /// Reads the set at `dir` (its first `identities`, all if `None`) and the true faces from the data
    /// directory `data`; with an init file, writes its start points of every image to `work/points`.
    pub fn prepare(dir: &Path, identities: Option<usize>, data: &Path, points: DevPoints<'_>, work: &Path) -> Result<Self, EvalError> {
        let set = SynthSet::load(dir, identities)?;
        let (points, unfound) = match points {
            DevPoints::Init(init) => {
                let out = work.join("points");
                let unfound = write_start_points(&set, init, &out)?;
                (out, unfound)
            }
            DevPoints::Files(d) => (d.to_path_buf(), 0),
        };
        let options = SynthOptions {
            seed: set.options.seed,
            identity_scale: set.options.identity_scale,
            modes: set.options.modes,
            ..SynthOptions::with_data_dir(data)
        };
        let world = EvalWorld::load(&options)?;
        let set = set.with_landmarks(LandmarkSource::new(Some(points), None)?);
        Ok(Self { set, world, work: work.to_path_buf(), unfound })
    }

    /// Starts the development images from `init`'s points from now on, written to `work/NAME`
    /// (a directory per init file: the fit cache knows points by their directory).
    pub fn repoint(&mut self, init: &[u8], name: &str) -> Result<(), EvalError> {
        let out = self.work.join(name);
        self.unfound = write_start_points(&self.set, init, &out)?;
        self.set.landmarks = LandmarkSource::new(Some(out), None)?;
        Ok(())
    }

    /// The development set's directory.
    pub fn dir(&self) -> &Path {
        &self.set.dir
    }

    /// Fits `model` (cached under `label`) with `settings` on every image and measures the fits.
    pub fn figure(
        &self,
        model: &Path,
        label: &str,
        settings: &FitOptions,
        jobs: usize,
        progress: &(dyn Fn(usize, usize) + Sync),
    ) -> Result<DevFigure, EvalError> {
        let row = Row { label: label.into(), description: String::new(), components: vec![(label.into(), model.to_path_buf())] };
        let on = |p: Progress<'_>| {
            if let Progress::Fitting(_, d, t) = p {
                progress(d, t)
            }
        };
        let rows = evaluate(std::slice::from_ref(&row), &self.set, &self.world, settings, jobs, &self.work, &on)?;
        let r = rows.into_iter().next().ok_or_else(|| EvalError::Invalid("no development result".into()))?;
        let overall =
            r.overall().ok_or_else(|| EvalError::Invalid(format!("{}: no development image could be fitted", model.display())))?;
        Ok(DevFigure {
            model: model.display().to_string(),
            median_mm: overall.fit.median_mm,
            mean_mm: overall.fit.mean_mm,
            fits: r.fits,
            failed: r.failures.len(),
        })
    }
}

/// Writes the init file's start points of every image of `set` to `out` (`STEM.pts`); returns how
/// many images had no face.
fn write_start_points(set: &SynthSet, init: &[u8], out: &Path) -> Result<usize, EvalError> {
    std::fs::create_dir_all(out).map_err(crate::eval::io_err(out, "cannot create"))?;
    let mut detector = Detector::from_bytes(init).map_err(|e| EvalError::Invalid(format!("init file: {e}")))?;
    let mut unfound = 0;
    for t in &set.images {
        let image = set.dir.join(&t.image);
        let photo = crate::photo::load_rgb(&image).map_err(|e| EvalError::Invalid(e.to_string()))?;
        let path = out.join(&t.landmarks_file);
        match start_points(&mut detector, &photo) {
            Ok((p, _)) => std::fs::write(&path, crate::photo::pts::pts_string(&p)).map_err(crate::eval::io_err(&path, "cannot write"))?,
            Err(_) => {
                // A stale file of an earlier init must not stand in for "no face".
                let _ = std::fs::remove_file(&path);
                unfound += 1;
            }
        }
    }
    Ok(unfound)
}
