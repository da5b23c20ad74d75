//! Face recognition across yaw (`gpmm eval recognition`), the paper's protocol on `gpmm synth` images.
//!
//! Every image of the selected identities is fitted exactly as `gpmm fit` does (its `.pts`, the
//! crop, the landmark chain, the image chain; each image has its own random light and pose). The
//! gallery is the yaw-0 image of every identity, the probes are all other images. A fit's feature
//! is the joint coefficient vector (shape coefficients, then colour coefficients); a probe is
//! identified as the gallery identity of maximum cosine similarity ([`super::kde::score`] for
//! several components). Rank-1 accuracy per probe yaw is reported with its Wilson 95 % interval; a
//! probe whose fit failed counts as wrong. Chance is 1 / gallery size.
//!
//! Fits are cached per row component in `OUT/fits/LABEL.json`, keyed by the model file's SHA-256,
//! the fit settings, the synth directory's `truth.json` SHA-256 and the selected images: a re-run
//! with the same inputs reuses them.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::time::Instant;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::eval::synth::{read_truth, ImageTruth};
use crate::fit::{fit_prepared, load_photo, FitOptions};

use super::plot::{line_chart, Chart, Series};
use super::{create_dir, wilson_interval, write_text, EvalError, LandmarkSource};

/// One fitted image.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ImageFit {
    /// Image file name.
    pub image: String,
    /// Identity number.
    pub identity: usize,
    /// True yaw (degrees).
    pub yaw_deg: f32,
    /// Fitted shape coefficients.
    pub shape: Vec<f32>,
    /// Fitted colour coefficients.
    pub color: Vec<f32>,
    /// Pixel RMSE of the fit.
    pub pixel_rmse: f32,
    /// Seconds of this fit (one thread).
    pub seconds: f64,
}

/// Which of a fit's coefficients are compared.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Coefficients {
    /// The image chain's posterior mean (its second half): the posterior's estimate.
    #[default]
    PosteriorMean,
    /// The image chain's best sample (the fit `gpmm fit` draws).
    Best,
}

impl Coefficients {
    /// Both choices.
    pub const ALL: [Self; 2] = [Self::PosteriorMean, Self::Best];

    /// The name on the command line and in JSON.
    pub fn name(self) -> &'static str {
        match self {
            Coefficients::PosteriorMean => "posterior-mean",
            Coefficients::Best => "best",
        }
    }

    /// Parses `--coefficients`: `posterior-mean` or `best`.
    pub fn parse(s: &str) -> Result<Self, String> {
        Self::ALL.into_iter().find(|c| c.name() == s.trim()).ok_or_else(|| format!("'{s}': the coefficients are posterior-mean or best"))
    }

    /// How reports name it.
    pub fn describe(self) -> &'static str {
        match self {
            Coefficients::PosteriorMean => "the image chain's posterior mean",
            Coefficients::Best => "the image chain's best sample",
        }
    }
}

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

/// Which coefficients identify a face.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Feature {
    /// Shape coefficients, then colour coefficients (the paper's protocol).
    Joint,
    /// Shape coefficients only (a diagnostic).
    Shape,
    /// Colour coefficients only (a diagnostic).
    Color,
}

impl ImageFit {
    /// The feature vector: the joint vector is the shape coefficients, then the colour coefficients.
    pub fn features(&self, feature: Feature) -> Vec<f32> {
        match feature {
            Feature::Joint => self.shape.iter().chain(&self.color).copied().collect(),
            Feature::Shape => self.shape.clone(),
            Feature::Color => self.color.clone(),
        }
    }
}

/// The fits of one model (cached as `OUT/fits/LABEL.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FitSet {
    /// What the fits depend on (model SHA-256, settings, truth SHA-256, images).
    pub key: serde_json::Value,
    /// Successful fits.
    pub fits: Vec<ImageFit>,
    /// Failed fits (messages).
    pub failures: Vec<String>,
    /// Wall-clock seconds of fitting all images.
    pub wall_seconds: f64,
    /// Threads used.
    pub jobs: usize,
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

/// Accuracy at one probe yaw.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct YawAccuracy {
    /// Probe yaw (degrees).
    pub yaw_deg: f32,
    /// Probes identified correctly (rank 1).
    pub correct: usize,
    /// Probes.
    pub total: usize,
    /// correct / total.
    pub accuracy: f64,
    /// Wilson 95 % interval of the accuracy.
    pub wilson95: [f64; 2],
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
    pub probes: Vec<(String, usize, Option<usize>)>,
}

/// The whole report (`OUT/recognition.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RecognitionReport {
    /// The synth directory.
    pub synth_dir: String,
    /// Its seed.
    pub synth_seed: u64,
    /// Identities evaluated.
    pub identities: usize,
    /// Gallery size (identities with a yaw-0 image).
    pub gallery: usize,
    /// Chance rate of rank-1 identification.
    pub chance: f64,
    /// Fit settings.
    pub settings: FitOptions,
    /// Settings of the KDE components' fits, if different.
    pub kde_settings: Option<FitOptions>,
    /// The coefficients compared (absent in older reports: the best sample).
    #[serde(default = "best_sample")]
    pub coefficients: Coefficients,
    /// Threads.
    pub jobs: usize,
    /// The command line that produced the report.
    pub command: String,
    /// Rows.
    pub rows: Vec<RowResult>,
    /// Wall-clock seconds of the whole run (model building included).
    pub total_seconds: f64,
}

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
    pub options: crate::eval::synth::SynthOptions,
    /// Where the landmarks are read from (the set's exact `.pts` unless told otherwise).
    pub landmarks: LandmarkSource,
}

impl SynthSet {
    /// Reads `dir/truth.json` and keeps the first `limit` identities that have a yaw-0 image.
    pub fn load(dir: &Path, limit: Option<usize>) -> Result<Self, EvalError> {
        let truth_path = dir.join("truth.json");
        if !truth_path.is_file() {
            return Err(EvalError::Invalid(format!("{} not found: is {} a `gpmm synth` directory?", truth_path.display(), dir.display())));
        }
        let truth = read_truth(&truth_path)?;
        let with_gallery: BTreeSet<usize> = truth.images.iter().filter(|t| t.yaw_deg == 0.0).map(|t| t.identity).collect();
        if with_gallery.is_empty() {
            return Err(EvalError::Invalid(format!("{}: no yaw-0 images, so no gallery (render with --yaws 0,...)", dir.display())));
        }
        let identities: Vec<usize> = with_gallery.into_iter().take(limit.unwrap_or(usize::MAX)).collect();
        let keep: BTreeSet<usize> = identities.iter().copied().collect();
        let images: Vec<ImageTruth> = truth.images.into_iter().filter(|t| keep.contains(&t.identity)).collect();
        if images.iter().all(|t| t.yaw_deg == 0.0) {
            return Err(EvalError::Invalid(format!("{}: only yaw-0 images, so no probes", dir.display())));
        }
        Ok(Self {
            dir: dir.to_path_buf(),
            seed: truth.seed,
            truth_sha256: super::file_sha256(&truth_path)?,
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

    /// The probe yaws (all but 0, ascending).
    pub fn probe_yaws(&self) -> Vec<f32> {
        let mut y: Vec<f32> = self.images.iter().map(|t| t.yaw_deg).filter(|&y| y != 0.0).collect();
        y.sort_by(f32::total_cmp);
        y.dedup();
        y
    }
}

/// What reports written before the choice compared.
fn best_sample() -> Coefficients {
    Coefficients::Best
}

fn fit_one(
    model: &crate::gp::model::GpModel,
    set: &SynthSet,
    t: &ImageTruth,
    settings: &FitOptions,
    coefficients: Coefficients,
) -> Result<ImageFit, String> {
    let t0 = Instant::now();
    let pts = set.landmarks.file(&set.dir, &t.landmarks_file);
    let prepared = load_photo(model, &set.dir.join(&t.image), &pts, false, settings.size, set.landmarks.calibration())
        .map_err(|e| format!("{}: {e}", t.image))?;
    let o = fit_prepared(model, &prepared, settings, &mut |_, _, _| {}).map_err(|e| format!("{}: {e}", t.image))?;
    let p = match coefficients {
        Coefficients::PosteriorMean => o.posterior.mean_params(&o.params),
        Coefficients::Best => o.params,
    };
    Ok(ImageFit {
        image: t.image.clone(),
        identity: t.identity,
        yaw_deg: t.yaw_deg,
        shape: p.shape_coeffs().to_vec(),
        color: p.color_coeffs().to_vec(),
        pixel_rmse: o.pixel_rmse,
        seconds: t0.elapsed().as_secs_f64(),
    })
}

/// Fits every image of `set` with the model at `model_path` (cached in `cache`) and keeps
/// `coefficients`; `progress(done, total)` after each fit.
pub fn fit_set(
    model_path: &Path,
    set: &SynthSet,
    settings: &FitOptions,
    coefficients: Coefficients,
    jobs: usize,
    cache: &Path,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<(FitSet, bool), EvalError> {
    settings.validate().map_err(|e| EvalError::Invalid(e.to_string()))?;
    // The settings as text: JSON numbers read back from the cache need not be bit-equal to the
    // f32 → f64 values written (serde_json's float parser is not exact), a string is.
    let settings_text = serde_json::to_string(settings).map_err(|e| EvalError::Invalid(e.to_string()))?;
    let key = serde_json::json!({
        "model_sha256": super::file_sha256(model_path)?,
        "settings": settings_text,
        "truth_sha256": set.truth_sha256,
        "images": set.images.iter().map(|t| t.image.as_str()).collect::<Vec<_>>(),
        "coefficients": coefficients,
    });
    let mut key = key;
    if let Some(d) = &set.landmarks.dir {
        key["landmarks_dir"] = serde_json::Value::String(d.display().to_string());
    }
    if let Some((_, c)) = &set.landmarks.calibration {
        // The contents, not the path: a re-learned calibration must not reuse old fits.
        key["landmark_calibration"] = serde_json::to_value(c).map_err(|e| EvalError::Invalid(e.to_string()))?;
    }
    if let Ok(text) = std::fs::read_to_string(cache) {
        if let Ok(cached) = serde_json::from_str::<FitSet>(&text) {
            if cached.key == key {
                progress(set.images.len(), set.images.len());
                return Ok((cached, true));
            }
        }
    }
    let model = crate::gp::model_io::load(model_path)?;
    if model.landmarks.len() != 68 {
        return Err(EvalError::Invalid(format!(
            "{}: the model has {} landmarks; recognition needs the 68 iBUG landmarks",
            model_path.display(),
            model.landmarks.len()
        )));
    }
    let jobs = jobs.max(1);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(jobs)
        .build()
        .map_err(|e| EvalError::Invalid(format!("cannot start {jobs} threads: {e}")))?;
    let done = std::sync::atomic::AtomicUsize::new(0);
    let total = set.images.len();
    let t0 = Instant::now();
    let results: Vec<Result<ImageFit, String>> = pool.install(|| {
        set.images
            .par_iter()
            .map(|t| {
                let r = fit_one(&model, set, t, settings, coefficients);
                progress(done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1, total);
                r
            })
            .collect()
    });
    let wall_seconds = t0.elapsed().as_secs_f64();
    let (mut fits, mut failures) = (Vec::new(), Vec::new());
    for r in results {
        match r {
            Ok(f) => fits.push(f),
            Err(e) => failures.push(e),
        }
    }
    let out = FitSet { key, fits, failures, wall_seconds, jobs };
    if let Some(parent) = cache.parent() {
        create_dir(parent)?;
    }
    let text = serde_json::to_string(&out).map_err(|e| EvalError::Invalid(format!("fit cache: {e}")))?;
    write_text(cache, &text)?;
    Ok((out, false))
}

/// Rank-1 identification of every probe from the fits of each component; returns (image, identity, yaw, predicted).
pub fn identify(set: &SynthSet, components: &[FitSet], feature: Feature) -> Vec<(String, usize, f32, Option<usize>)> {
    let maps: Vec<BTreeMap<&str, Vec<f32>>> =
        components.iter().map(|c| c.fits.iter().map(|f| (f.image.as_str(), f.features(feature))).collect()).collect();
    let gallery: Vec<&ImageTruth> = set.images.iter().filter(|t| t.yaw_deg == 0.0).collect();
    set.images
        .iter()
        .filter(|t| t.yaw_deg != 0.0)
        .map(|p| {
            let probe: Vec<Option<&[f32]>> = maps.iter().map(|m| m.get(p.image.as_str()).map(Vec::as_slice)).collect();
            let mut best: Option<(f64, usize)> = None;
            for g in &gallery {
                let gal: Vec<Option<&[f32]>> = maps.iter().map(|m| m.get(g.image.as_str()).map(Vec::as_slice)).collect();
                if let Some(s) = super::kde::score(&probe, &gal) {
                    if best.is_none_or(|(bs, _)| s > bs) {
                        best = Some((s, g.identity));
                    }
                }
            }
            (p.image.clone(), p.identity, p.yaw_deg, best.map(|b| b.1))
        })
        .collect()
}

/// Accuracy per probe yaw of identification results.
pub fn accuracy_by_yaw(results: &[(String, usize, f32, Option<usize>)], yaws: &[f32]) -> Vec<YawAccuracy> {
    yaws.iter()
        .map(|&y| {
            let at: Vec<_> = results.iter().filter(|r| r.2 == y).collect();
            let correct = at.iter().filter(|r| r.3 == Some(r.1)).count();
            let total = at.len();
            let (lo, hi) = wilson_interval(correct, total, 1.96);
            YawAccuracy {
                yaw_deg: y,
                correct,
                total,
                accuracy: if total > 0 { correct as f64 / total as f64 } else { 0.0 },
                wilson95: [lo, hi],
            }
        })
        .collect()
}

/// Accuracy over all identification results (every probe yaw pooled).
pub fn pooled(results: &[(String, usize, f32, Option<usize>)]) -> YawAccuracy {
    let correct = results.iter().filter(|r| r.3 == Some(r.1)).count();
    let total = results.len();
    let (lo, hi) = wilson_interval(correct, total, 1.96);
    YawAccuracy {
        yaw_deg: f32::NAN,
        correct,
        total,
        accuracy: if total > 0 { correct as f64 / total as f64 } else { 0.0 },
        wilson95: [lo, hi],
    }
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
        let probes = identify(set, &sets, Feature::Joint);
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
            yaws: accuracy_by_yaw(&probes, &yaws),
            pooled: pooled(&probes),
            shape_only: accuracy_by_yaw(&identify(set, &sets, Feature::Shape), &yaws),
            color_only: accuracy_by_yaw(&identify(set, &sets, Feature::Color), &yaws),
            median_pixel_rmse: rmse.get(rmse.len() / 2).copied().unwrap_or(f64::NAN),
            fits: sets.iter().map(|s| s.fits.len() + s.failures.len()).sum(),
            failures: sets.iter().map(|s| s.failures.len()).sum(),
            fit_wall_seconds: sets.iter().map(|s| s.wall_seconds).sum(),
            seconds_per_fit: per_fit.get(per_fit.len() / 2).copied().unwrap_or(0.0),
            cached,
            probes: probes.into_iter().map(|(i, id, _, p)| (i, id, p)).collect(),
        };
        progress(Progress::RowDone(&r));
        results.push(r);
    }
    Ok(results)
}

fn pct(x: f64) -> String {
    format!("{:.1}", 100.0 * x)
}

/// The table as Markdown.
pub fn markdown(report: &RecognitionReport) -> String {
    let yaws: Vec<f32> = report.rows.first().map(|r| r.yaws.iter().map(|y| y.yaw_deg).collect()).unwrap_or_default();
    let mut s = String::new();
    s.push_str(&format!(
        "Rank-1 recognition (%), gallery yaw 0 ({} identities, chance {} %), `gpmm synth` seed {}; [Wilson 95 % interval]; \
fit: {} landmark + {} image steps at {}x{} px, {} shape + {} colour components; compared: {}",
        report.gallery,
        pct(report.chance),
        report.synth_seed,
        report.settings.fit.landmarks.steps,
        report.settings.fit.image.steps,
        report.settings.size,
        report.settings.size,
        report.settings.fit.ranks.shape,
        report.settings.fit.ranks.color,
        report.coefficients.describe()
    ));
    if let Some(k) = &report.kde_settings {
        s.push_str(&format!(" (KDE components: {} image steps)", k.fit.image.steps));
    }
    s.push_str(".\n\n| model |");
    for y in &yaws {
        s.push_str(&format!(" {y}° |"));
    }
    s.push_str(" all probes | fits | fit wall time |\n|---|");
    for _ in &yaws {
        s.push_str("---|");
    }
    s.push_str("---|---|---|\n");
    for r in &report.rows {
        s.push_str(&format!("| {} |", r.label));
        for y in r.yaws.iter().chain([&r.pooled]) {
            s.push_str(&format!(" {} [{}, {}] |", pct(y.accuracy), pct(y.wilson95[0]), pct(y.wilson95[1])));
        }
        let failed = if r.failures > 0 { format!(" ({} failed)", r.failures) } else { String::new() };
        s.push_str(&format!(
            " {}{failed} | {:.0} s ({:.2} s/fit, {} threads){} |\n",
            r.fits,
            r.fit_wall_seconds,
            r.seconds_per_fit,
            report.jobs,
            if r.cached { ", cached" } else { "" }
        ));
    }
    s.push_str("| chance |");
    for _ in 0..=yaws.len() {
        s.push_str(&format!(" {} |", pct(report.chance)));
    }
    s.push_str(" | |\n\n");
    s.push_str("Diagnostic, from the same fits: rank-1 accuracy (%) from the shape coefficients alone | from the colour coefficients alone; median pixel RMSE of the fits.\n\n| model |");
    for y in &yaws {
        s.push_str(&format!(" {y}° shape \\| colour |"));
    }
    s.push_str(" pixel RMSE |\n|---|");
    for _ in &yaws {
        s.push_str("---|");
    }
    s.push_str("---|\n");
    for r in &report.rows {
        s.push_str(&format!("| {} |", r.label));
        for (a, b) in r.shape_only.iter().zip(&r.color_only) {
            s.push_str(&format!(" {} \\| {} |", pct(a.accuracy), pct(b.accuracy)));
        }
        s.push_str(&format!(" {:.4} |\n", r.median_pixel_rmse));
    }
    s.push('\n');
    for r in &report.rows {
        s.push_str(&format!("- `{}`: {}\n", r.label, r.description));
    }
    let reused = if report.rows.iter().any(|r| r.cached) {
        "; rows marked cached reused the fits of an earlier run and show its fit times"
    } else {
        ""
    };
    s.push_str(&format!("\nCommand: `{}` (this run: {:.0} s{reused}).\n", report.command, report.total_seconds));
    s
}

/// The table as CSV (one line per row and probe yaw).
pub fn csv(report: &RecognitionReport) -> String {
    let mut s = String::from("model,yaw_deg,correct,total,accuracy,wilson95_low,wilson95_high,chance,fit_wall_seconds,seconds_per_fit\n");
    for r in &report.rows {
        for y in &r.yaws {
            s.push_str(&format!(
                "{},{},{},{},{:.4},{:.4},{:.4},{:.4},{:.1},{:.3}\n",
                r.label,
                y.yaw_deg,
                y.correct,
                y.total,
                y.accuracy,
                y.wilson95[0],
                y.wilson95[1],
                report.chance,
                r.fit_wall_seconds,
                r.seconds_per_fit
            ));
        }
    }
    s
}

/// Writes `recognition.md`, `recognition.csv`, `recognition.json` and `recognition.png` into `out`.
pub fn write_report(report: &RecognitionReport, out: &Path) -> Result<(), EvalError> {
    create_dir(out)?;
    write_text(&out.join("recognition.md"), &markdown(report))?;
    write_text(&out.join("recognition.csv"), &csv(report))?;
    let json = serde_json::to_string_pretty(report).map_err(|e| EvalError::Invalid(format!("report: {e}")))?;
    write_text(&out.join("recognition.json"), &(json + "\n"))?;
    let series: Vec<Series> = report
        .rows
        .iter()
        .map(|r| Series { label: r.label.clone(), points: r.yaws.iter().map(|y| (f64::from(y.yaw_deg), 100.0 * y.accuracy)).collect() })
        .collect();
    let chart = Chart {
        title: format!("Rank-1 recognition, gallery yaw 0, {} identities (chance {} %)", report.gallery, pct(report.chance)),
        x_label: "probe yaw (degrees)".into(),
        y_label: "rank-1 accuracy (%)".into(),
        log_x: false,
        y_range: Some((0.0, 100.0)),
        series,
    };
    let png = out.join("recognition.png");
    super::save_png(&line_chart(&chart, 760, 480), &png)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::Coefficients;

    #[test]
    fn coefficient_names_parse_back_and_match_the_json() {
        for c in Coefficients::ALL {
            assert_eq!(Coefficients::parse(c.name()), Ok(c));
            assert_eq!(serde_json::to_value(c).unwrap(), serde_json::Value::String(c.name().into()));
        }
        assert!(Coefficients::parse("mean").unwrap_err().contains("posterior-mean or best"));
    }
}
