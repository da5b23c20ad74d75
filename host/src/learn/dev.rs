//! Each learned model against its predecessor on a development set whose true faces are known: a
//! `gpmm synth` set, or a set made from one, with its `truth.json`.
//!
//! The development images are fitted as the loop fits its own images: the same start points (the
//! init file's finder and initializer, or landmark files when the loop reads those) and the same fit
//! settings. Each fit is measured against its true face as `gpmm eval reconstruction` measures it
//! (similarity alignment, scan-to-mesh distance); the median over all measured vertices decides,
//! provided the same fits still tell the identities apart: a model whose rank-1 identification
//! (gallery at yaw 0, as `gpmm eval recognition`) falls more than the allowed drop below the
//! model it is compared with does not count as better, however close its fits come.
//! Each model is compared with its predecessor and with the best so far; the run keeps the best.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::start_points;
use crate::detect::Detector;
use crate::eval::models::scans::EvalWorld;
use crate::eval::recognition::fits::{fit_set, Coefficients, Feature};
use crate::eval::recognition::identify::Identification;
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
    /// The largest rank-1 drop (0–1) a model closer in 3D may show and still count as better.
    pub max_rank1_drop: f64,
}

/// Where the development images' start points come from: as the loop's own.
#[derive(Debug, Clone, Copy)]
pub enum DevPoints<'a> {
    /// The init file's finder and initializer (its bytes).
    Init(&'a [u8]),
    /// Landmark files `DIR/STEM.pts`.
    Files(&'a Path),
}

impl<'a> DevPoints<'a> {
    /// The development images' points for a loop that reads landmark files from `landmarks_dir`
    /// (then `dev_files` must give the development set's) or starts from the init file `init`.
    pub fn like_the_loop(landmarks_dir: Option<&Path>, dev_files: Option<&'a Path>, init: Option<&'a [u8]>) -> Result<Self, &'static str> {
        match (landmarks_dir, dev_files, init) {
            (Some(_), Some(points), _) => Ok(Self::Files(points)),
            (Some(_), None, _) => {
                Err("a loop that reads landmark files needs the development images' landmark files too: they start as the loop's do")
            }
            (None, _, Some(init)) => Ok(Self::Init(init)),
            (None, _, None) => Err("an init file or landmark files are needed: the fits start from one of them"),
        }
    }
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
    /// Rank-1 identification of the development probes from the same fits (0–1; `None` in the
    /// records of runs made before it was measured).
    #[serde(default)]
    pub rank1: Option<f64>,
    /// Probes it counted.
    #[serde(default)]
    pub probes: Option<usize>,
}

/// The largest drop of rank-1 identification (0–1) the development check allows a model that
/// comes closer in 3D: five points, about one standard error of a rank-1 over the 60 probes of ten
/// development identities.
pub const DEFAULT_MAX_RANK1_DROP: f64 = 0.05;

impl DevFigure {
    /// Whether this model counts as better than `other`: its fits come closer to the true faces
    /// (a lower median) and its rank-1 is at most `max_rank1_drop` below `other`'s (not judged
    /// when either was not measured).
    pub fn better_than(&self, other: &DevFigure, max_rank1_drop: f64) -> bool {
        self.median_mm < other.median_mm && !self.lost_identity(other, max_rank1_drop)
    }

    /// Whether its rank-1 lies more than `max_rank1_drop` below `other`'s.
    pub fn lost_identity(&self, other: &DevFigure, max_rank1_drop: f64) -> bool {
        matches!((self.rank1, other.rank1), (Some(a), Some(b)) if a < b - max_rank1_drop)
    }
}

/// An iteration's model against its predecessor's and the best so far.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DevComparison {
    /// The development set's directory.
    pub set: String,
    /// The model the iteration started from.
    pub previous: DevFigure,
    /// The model it made.
    pub learned: DevFigure,
    /// Whether the learned model is better than its predecessor (a lower median, its rank-1 kept
    /// within the allowed drop).
    pub better: bool,
    /// Whether its fits come closer to the true faces than its predecessor's (a lower median),
    /// identity aside.
    #[serde(default)]
    pub closer: bool,
    /// Whether it is the best so far, the start model included (the run keeps the best).
    pub best: bool,
    /// The best model so far and its median (mm), after this iteration.
    pub best_model: String,
    /// Its median.
    pub best_median_mm: f64,
    /// Its rank-1.
    #[serde(default)]
    pub best_rank1: Option<f64>,
}

/// The development figures a run carries from one iteration to the next: its latest model's and
/// its best model's (`None` once the start points changed and it must be measured again).
#[derive(Debug, Clone, Default)]
pub struct DevTrack {
    /// The latest model's figure.
    last: Option<DevFigure>,
    /// The best model and its figure.
    best: Option<(PathBuf, Option<DevFigure>)>,
}

impl DevTrack {
    /// The start points changed (a retrained init file): every figure must be measured again.
    pub fn forget(&mut self) {
        self.last = None;
        if let Some(b) = &mut self.best {
            b.1 = None;
        }
    }

    /// Takes in a comparison read back from disk: `previous` the model it started from, `next`
    /// the model it made.
    pub fn reuse(&mut self, c: &DevComparison, previous: &Path, next: &Path) {
        if self.best.is_none() {
            self.best = Some((previous.to_path_buf(), Some(c.previous.clone())));
        }
        if c.best {
            self.best = Some((next.to_path_buf(), Some(c.learned.clone())));
        } else if Path::new(&c.best_model) == previous {
            // The predecessor, measured again from new points, took the lead.
            self.best = Some((previous.to_path_buf(), Some(c.previous.clone())));
        }
        self.last = Some(c.learned.clone());
    }

    /// Compares the model `next` with `previous` (its predecessor) and with the best so far,
    /// measuring what is not known yet with `measure`; a model counts as better as
    /// [`DevFigure::better_than`] says, with `max_rank1_drop`.
    pub fn compare<E>(
        &mut self,
        set: &Path,
        previous: &Path,
        next: &Path,
        max_rank1_drop: f64,
        measure: &dyn Fn(&Path) -> Result<DevFigure, E>,
    ) -> Result<DevComparison, E> {
        let before = match self.last.take() {
            Some(f) => f,
            None => measure(previous)?,
        };
        let (best_path, best_figure) = match self.best.take() {
            Some((path, Some(f))) => (path, f),
            Some((path, None)) if path != previous => {
                let f = measure(&path)?;
                (path, f)
            }
            _ => (previous.to_path_buf(), before.clone()),
        };
        // Measured again from new points, the predecessor may now lead the old best.
        let (best_path, best_figure) = if before.better_than(&best_figure, max_rank1_drop) {
            (previous.to_path_buf(), before.clone())
        } else {
            (best_path, best_figure)
        };
        let learned = measure(next)?;
        let better = learned.better_than(&before, max_rank1_drop);
        let best = learned.better_than(&best_figure, max_rank1_drop);
        let closer = learned.median_mm < before.median_mm;
        let (best_path, best_figure) = if best { (next.to_path_buf(), learned.clone()) } else { (best_path, best_figure) };
        let c = DevComparison {
            set: set.display().to_string(),
            previous: before,
            learned: learned.clone(),
            better,
            closer,
            best,
            best_model: best_path.display().to_string(),
            best_median_mm: best_figure.median_mm,
            best_rank1: best_figure.rank1,
        };
        self.best = Some((best_path, Some(best_figure)));
        self.last = Some(learned);
        Ok(c)
    }

    /// The best model so far, if any was measured.
    pub fn best(&self) -> Option<&Path> {
        self.best.as_ref().map(|(p, _)| p.as_path())
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
        Ok(Self { set, world, work: work.to_path_buf(), unfound, max_rank1_drop: DEFAULT_MAX_RANK1_DROP })
    }

    /// Starts the development images from `init`'s points from now on, written to `work/NAME`
    /// (a directory per init file: the fit cache knows points by their directory).
    pub fn repoint(&mut self, init: &[u8], name: &str) -> Result<(), EvalError> {
        let out = self.work.join(name);
        self.unfound = write_start_points(&self.set, init, &out)?;
        self.set.landmarks = LandmarkSource::new(Some(out), None)?;
        Ok(())
    }

    /// The same check allowing a rank-1 drop of `drop` (0–1) for a model that comes closer in 3D.
    pub fn with_max_rank1_drop(self, drop: f64) -> Self {
        Self { max_rank1_drop: drop, ..self }
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
        // The same fits, read back from the cache the measurement just wrote.
        let cache = self.work.join("fits").join(format!("{label}.json"));
        let (fits, _) = fit_set(model, &self.set, settings, Coefficients::PosteriorMean, jobs, &cache, &|_, _| {})?;
        let identified = Identification::new(&self.set.labeled_images(), &[fits], Feature::Joint, &self.set.probe_yaws()).pooled;
        Ok(DevFigure {
            model: model.display().to_string(),
            median_mm: overall.fit.median_mm,
            mean_mm: overall.fit.mean_mm,
            fits: r.fits,
            failed: r.failures.len(),
            rank1: Some(identified.accuracy),
            probes: Some(identified.total),
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

#[cfg(test)]
mod tests {
    use super::*;
    use std::cell::RefCell;

    fn fig(path: &Path, median: f64) -> DevFigure {
        DevFigure { model: path.display().to_string(), median_mm: median, mean_mm: median, fits: 1, failed: 0, rank1: None, probes: None }
    }

    #[test]
    fn the_track_keeps_the_best_and_measures_each_model_once_until_the_points_change() {
        let medians = [("start", 1.5), ("m1", 1.4), ("m2", 1.45), ("m3", 1.3)];
        let measured = RefCell::new(Vec::new());
        let measure = |p: &Path| -> Result<DevFigure, ()> {
            let name = p.display().to_string();
            measured.borrow_mut().push(name.clone());
            Ok(fig(p, medians.iter().find(|(n, _)| *n == name).map(|m| m.1).unwrap_or(f64::NAN)))
        };
        let set = Path::new("dev");
        let mut t = DevTrack::default();
        let c1 = t.compare(set, Path::new("start"), Path::new("m1"), 0.05, &measure).unwrap();
        assert!(c1.better && c1.best && c1.best_model == "m1");
        let c2 = t.compare(set, Path::new("m1"), Path::new("m2"), 0.05, &measure).unwrap();
        assert!(!c2.better && !c2.best && c2.best_model == "m1" && c2.best_median_mm == 1.4);
        assert_eq!(*measured.borrow(), ["start", "m1", "m2"]);
        // New start points: the latest and the best are measured again before the comparison.
        t.forget();
        let c3 = t.compare(set, Path::new("m2"), Path::new("m3"), 0.05, &measure).unwrap();
        assert!(c3.better && c3.best && c3.previous.median_mm == 1.45);
        assert_eq!(*measured.borrow(), ["start", "m1", "m2", "m2", "m1", "m3"]);
        assert_eq!(t.best(), Some(Path::new("m3")));
        // A run read back from disk ends with the same best.
        let mut again = DevTrack::default();
        for (c, (p, n)) in [&c1, &c2, &c3].into_iter().zip([("start", "m1"), ("m1", "m2"), ("m2", "m3")]) {
            again.reuse(c, Path::new(p), Path::new(n));
        }
        assert_eq!(again.best(), Some(Path::new("m3")));
    }

    #[test]
    fn measured_from_new_points_the_predecessor_can_become_the_best() {
        // With the first points the start leads; with the second, m1 reads better than the start,
        // and m2, worse than m1, must not be called the best.
        let second = std::cell::Cell::new(false);
        let measure = |p: &Path| -> Result<DevFigure, ()> {
            let table =
                if second.get() { [("start", 1.50), ("m1", 1.44), ("m2", 1.47)] } else { [("start", 1.45), ("m1", 1.46), ("m2", 9.0)] };
            Ok(fig(p, table.iter().find(|(n, _)| Path::new(n) == p).map_or(f64::NAN, |m| m.1)))
        };
        let set = Path::new("dev");
        let mut t = DevTrack::default();
        let c1 = t.compare(set, Path::new("start"), Path::new("m1"), 0.05, &measure).unwrap();
        assert!(!c1.better && !c1.best && c1.best_model == "start");
        t.forget();
        second.set(true);
        let c2 = t.compare(set, Path::new("m1"), Path::new("m2"), 0.05, &measure).unwrap();
        assert!(!c2.better && !c2.best, "{c2:?}");
        assert_eq!((c2.best_model.as_str(), c2.best_median_mm), ("m1", 1.44));
        assert_eq!(t.best(), Some(Path::new("m1")));
        // Read back from disk, the run ends with the same best.
        let mut again = DevTrack::default();
        again.reuse(&c1, Path::new("start"), Path::new("m1"));
        again.reuse(&c2, Path::new("m1"), Path::new("m2"));
        assert_eq!(again.best(), Some(Path::new("m1")));
    }

    #[test]
    fn a_model_closer_in_3d_that_loses_identity_is_not_kept() {
        // m1 comes closer but identifies far fewer probes; m2 comes closer still, within the drop.
        let table = [("start", 1.50, 0.70), ("m1", 1.40, 0.55), ("m2", 1.38, 0.67)];
        let measure = |p: &Path| -> Result<DevFigure, ()> {
            let (_, median, rank1) = table.iter().find(|(n, _, _)| Path::new(n) == p).copied().unwrap_or(("", f64::NAN, f64::NAN));
            Ok(DevFigure { rank1: Some(rank1), probes: Some(60), ..fig(p, median) })
        };
        let set = Path::new("dev");
        let mut t = DevTrack::default();
        let c1 = t.compare(set, Path::new("start"), Path::new("m1"), 0.05, &measure).unwrap();
        assert!(c1.closer && !c1.better && !c1.best && c1.best_model == "start", "{c1:?}");
        assert_eq!(c1.best_rank1, Some(0.70));
        // m2 against its predecessor m1 and against the best, the start: closer than both, and
        // within five points of the start's identity.
        let c2 = t.compare(set, Path::new("m1"), Path::new("m2"), 0.05, &measure).unwrap();
        assert!(c2.closer && c2.better && c2.best && c2.best_model == "m2", "{c2:?}");
        assert_eq!(t.best(), Some(Path::new("m2")));
        // With no drop allowed, m2 (0.67 against 0.70) is not the best either.
        let mut strict = DevTrack::default();
        strict.compare(set, Path::new("start"), Path::new("m1"), 0.0, &measure).unwrap();
        let c = strict.compare(set, Path::new("m1"), Path::new("m2"), 0.0, &measure).unwrap();
        assert!(c.better && !c.best && c.best_model == "start", "{c:?}");
    }

    #[test]
    fn figures_without_identity_are_judged_by_the_median_alone() {
        let a = fig(Path::new("a"), 1.4);
        let b = DevFigure { rank1: Some(0.9), ..fig(Path::new("b"), 1.5) };
        assert!(a.better_than(&b, 0.0) && !b.better_than(&a, 0.0));
        let old: DevFigure = serde_json::from_str(r#"{"model":"m","median_mm":1.2,"mean_mm":1.5,"fits":70,"failed":0}"#).unwrap();
        assert_eq!((old.rank1, old.probes), (None, None));
    }
}
