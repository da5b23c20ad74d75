//! Fitting a recognition set's images with one model, and the fits' cache.

use std::path::Path;
use std::time::Instant;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::eval::{create_dir, file_sha256, write_text, EvalError, ImageFitError};
use crate::fit::{fit_prepared, load_photo, FitOptions};
use crate::synth::ImageTruth;

use super::set::SynthSet;

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
    /// Per vertex of the fitted shape, its reported standard deviation along the normal (mm;
    /// [`crate::fit::ShapeSpread::vertex_sd_mm`]), rounded to 0.01 mm to keep the cache small;
    /// empty when the fit reported none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub vertex_sd_mm: Vec<f32>,
}

/// A `--coefficients` value that names no choice.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("'{0}': the coefficients are posterior-mean or best")]
pub struct UnknownCoefficients(pub String);

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
    pub fn parse(s: &str) -> Result<Self, UnknownCoefficients> {
        Self::ALL.into_iter().find(|c| c.name() == s.trim()).ok_or_else(|| UnknownCoefficients(s.to_string()))
    }

    /// How reports name it.
    pub fn describe(self) -> &'static str {
        match self {
            Coefficients::PosteriorMean => "the image chain's posterior mean",
            Coefficients::Best => "the image chain's best sample",
        }
    }
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

fn fit_one(
    model: &crate::gp::model::GpModel,
    set: &SynthSet,
    t: &ImageTruth,
    settings: &FitOptions,
    coefficients: Coefficients,
) -> Result<ImageFit, ImageFitError> {
    let t0 = Instant::now();
    let pts = set.landmarks.file(&set.dir, &t.landmarks_file);
    let prepared = load_photo(model, &set.dir.join(&t.image), &pts, false, settings.size, set.landmarks.calibration())
        .map_err(ImageFitError::naming(&t.image))?;
    let o = fit_prepared(model, &prepared, settings, &mut |_, _, _| {}).map_err(ImageFitError::naming(&t.image))?;
    let p = match coefficients {
        Coefficients::PosteriorMean => o.posterior.mean_params(&o.params),
        Coefficients::Best => o.params.clone(),
    };
    Ok(ImageFit {
        image: t.image.clone(),
        identity: t.identity,
        yaw_deg: t.yaw_deg,
        shape: p.shape_coeffs().to_vec(),
        color: p.color_coeffs().to_vec(),
        pixel_rmse: o.pixel_rmse,
        seconds: t0.elapsed().as_secs_f64(),
        vertex_sd_mm: o.vertex_sd_mm(model).map_err(ImageFitError::naming(&t.image))?.iter().map(|s| (s * 100.0).round() / 100.0).collect(),
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
    settings.validate()?;
    // The settings as text: JSON numbers read back from the cache need not be bit-equal to the
    // f32 → f64 values written (serde_json's float parser is not exact), a string is.
    let settings_text = serde_json::to_string(settings).map_err(|error| EvalError::Json { what: "fit settings", error })?;
    let key = serde_json::json!({
        "model_sha256": file_sha256(model_path)?,
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
        key["landmark_calibration"] = serde_json::to_value(c).map_err(|error| EvalError::Json { what: "landmark calibration", error })?;
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
        return Err(EvalError::ModelLandmarks { path: model_path.to_path_buf(), count: model.landmarks.len() });
    }
    let jobs = jobs.max(1);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(jobs).build().map_err(|error| EvalError::Threads { jobs, error })?;
    let done = std::sync::atomic::AtomicUsize::new(0);
    let total = set.images.len();
    let t0 = Instant::now();
    let results: Vec<Result<ImageFit, ImageFitError>> = pool.install(|| {
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
            Err(e) => failures.push(e.to_string()),
        }
    }
    let out = FitSet { key, fits, failures, wall_seconds, jobs };
    if let Some(parent) = cache.parent() {
        create_dir(parent)?;
    }
    let text = serde_json::to_string(&out).map_err(|error| EvalError::Json { what: "fit cache", error })?;
    write_text(cache, &text)?;
    Ok((out, false))
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
        assert!(Coefficients::parse("mean").unwrap_err().to_string().contains("posterior-mean or best"));
    }
}
