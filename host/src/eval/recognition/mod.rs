//! Face recognition across yaw (`gpmm eval recognition`), the paper's protocol on `gpmm synth` images.
//!
//! Every image of the selected identities is fitted exactly as `gpmm fit` does (its `.pts`, the
//! crop, the landmark chain, the image chain; each image has its own random light and pose). The
//! gallery is the yaw-0 image of every identity, the probes are all other images. A fit's feature
//! is the joint coefficient vector (shape coefficients, then colour coefficients); a probe is
//! identified as the gallery identity of maximum cosine similarity
//! ([`crate::eval::models::kde::score`] for several components; [`identify`]). Rank-1 accuracy per
//! probe yaw is reported with its Wilson 95 % interval ([`report`]); a probe whose fit failed
//! counts as wrong. Chance is 1 / gallery size.
//!
//! Fits are cached per row component in `OUT/fits/LABEL.json` ([`fits`]), keyed by the model
//! file's SHA-256, the fit settings, the synth directory's `truth.json` SHA-256 and the selected
//! images: a re-run with the same inputs reuses them.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::eval::EvalError;
use crate::fit::FitOptions;

pub mod fits;
pub mod identify;
pub mod report;
pub mod seeds;
mod set;

use fits::{fit_set, Coefficients, Feature};
use identify::{Identification, ProbeOutcome, YawAccuracy};
pub use set::SynthSet;

/// How [`evaluate`] fits: the settings, those of KDE components, and the coefficients compared.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitPlan {
    /// Fit settings.
    pub settings: FitOptions,
    /// Settings of the KDE components' fits.
    pub kde_settings: FitOptions,
    /// The coefficients compared.
    pub coefficients: Coefficients,
}

/// One row of the table: a model, or a KDE mixture of several component models.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    /// Row label (e.g. `symmetric-full`, `kde-10`).
    pub label: String,
    /// What the row is, in words.
    pub description: String,
    /// The component model files with their cache labels (one for a plain model).
    pub components: Vec<(String, PathBuf)>,
}

/// The result of one row.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RowResult {
    /// Row label.
    pub label: String,
    /// What the row is.
    pub description: String,
    /// Component model files.
    pub models: Vec<String>,
    /// Vertices of the (first) model.
    pub vertices: usize,
    /// Accuracy per probe yaw.
    pub yaws: Vec<YawAccuracy>,
    /// Accuracy over all probes (every probe yaw pooled; `yaw_deg` is NaN).
    pub pooled: YawAccuracy,
    /// Diagnostic: accuracy per probe yaw from the shape coefficients alone (same fits).
    pub shape_only: Vec<YawAccuracy>,
    /// Diagnostic: accuracy per probe yaw from the colour coefficients alone (same fits).
    pub color_only: Vec<YawAccuracy>,
    /// Median pixel RMSE of the fits (per channel, covered pixels).
    pub median_pixel_rmse: f64,
    /// Fits done (all components).
    pub fits: usize,
    /// Failed fits.
    pub failures: usize,
    /// Wall-clock seconds of this row's fits when they were made.
    pub fit_wall_seconds: f64,
    /// Median seconds per fit (one thread).
    pub seconds_per_fit: f64,
    /// Whether every component's fits came from the cache.
    pub cached: bool,
    /// Per probe: image, identity, predicted identity.
    pub probes: Vec<ProbeOutcome>,
}

/// How a run reports progress.
pub enum Progress<'a> {
    /// Fitting a component (label, done, total).
    Fitting(&'a str, usize, usize),
    /// A row is done.
    RowDone(&'a RowResult),
}

/// Evaluates every row on `set` as `plan` says (rows of several components, the KDEs, with its
/// `kde_settings`).
pub fn evaluate(
    rows: &[Row],
    set: &SynthSet,
    plan: &FitPlan,
    jobs: usize,
    out: &Path,
    progress: &(dyn Fn(Progress<'_>) + Sync),
) -> Result<Vec<RowResult>, EvalError> {
    let yaws = set.probe_yaws();
    let mut results = Vec::new();
    for row in rows {
        let s = if row.components.len() > 1 { &plan.kde_settings } else { &plan.settings };
        let mut sets = Vec::new();
        let mut cached = true;
        for (label, path) in &row.components {
            let cache = out.join("fits").join(format!("{label}.json"));
            let (fs, hit) = fit_set(path, set, s, plan.coefficients, jobs, &cache, &|d, t| progress(Progress::Fitting(label, d, t)))?;
            cached &= hit;
            sets.push(fs);
        }
        let images = set.labeled_images();
        let joint = Identification::new(&images, &sets, Feature::Joint, &yaws);
        let shape_only = Identification::new(&images, &sets, Feature::Shape, &yaws).per_yaw;
        let color_only = Identification::new(&images, &sets, Feature::Color, &yaws).per_yaw;
        let mut rmse: Vec<f64> = sets.iter().flat_map(|s| s.fits.iter().map(|f| f64::from(f.pixel_rmse))).collect();
        rmse.sort_by(f64::total_cmp);
        let mut per_fit: Vec<f64> = sets.iter().flat_map(|s| s.fits.iter().map(|f| f.seconds)).collect();
        per_fit.sort_by(f64::total_cmp);
        let vertices = match row.components.first() {
            Some((_, p)) => crate::gp::model_io::load(p)?.vertices(),
            None => 0,
        };
        let r = RowResult {
            label: row.label.clone(),
            description: row.description.clone(),
            models: row.components.iter().map(|(_, p)| p.display().to_string()).collect(),
            vertices,
            yaws: joint.per_yaw,
            pooled: joint.pooled,
            shape_only,
            color_only,
            median_pixel_rmse: rmse.get(rmse.len() / 2).copied().unwrap_or(f64::NAN),
            fits: sets.iter().map(|s| s.fits.len() + s.failures.len()).sum(),
            failures: sets.iter().map(|s| s.failures.len()).sum(),
            fit_wall_seconds: sets.iter().map(|s| s.wall_seconds).sum(),
            seconds_per_fit: per_fit.get(per_fit.len() / 2).copied().unwrap_or(0.0),
            cached,
            probes: joint.probes.into_iter().map(ProbeOutcome::from).collect(),
        };
        progress(Progress::RowDone(&r));
        results.push(r);
    }
    Ok(results)
}
