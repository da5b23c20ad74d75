//! A host fit's options and the one place where what the user gave (flags, keywords) becomes them.

use super::error::FitRunError;
use super::overrides::override_settings;
use super::params::{KC, KS};
use gpmm_core::fit::FitSettings;
use gpmm_core::fit::RankSettings;
use serde::{Deserialize, Serialize};

/// The largest working image side.
pub const MAX_SIZE: u32 = 1024;

/// The occlusion labels of a fit of any working size.
pub type HostMask = gpmm_core::fit::OcclusionMask<{ (MAX_SIZE * MAX_SIZE / 32) as usize }>;

/// A host fit: the working image side and the seed around the core's one [`FitSettings`]
/// (serialized flat: `size`, `seed` and the settings' fields side by side).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FitOptions {
    /// Working image side (pixels, 16 to 1024): the crop is resampled to `size × size`.
    pub size: u32,
    /// Seed of the chains' generator.
    pub seed: u64,
    /// The standard fit's settings (ranks beyond [`KS`] / [`KC`] are capped).
    #[serde(flatten)]
    pub fit: FitSettings,
}

impl FitOptions {
    /// A 128 × 128 working image, seed 0, the core's default settings.
    pub const DEFAULT: Self = Self { size: 128, seed: 0, fit: FitSettings::DEFAULT };

    /// The core's settings for this fit (ranks capped at [`KS`] / [`KC`]).
    pub fn core(&self) -> FitSettings {
        FitSettings { ranks: RankSettings { shape: self.fit.ranks.shape.min(KS), color: self.fit.ranks.color.min(KC) }, ..self.fit }
    }

    /// Checks the ranges (the host's limits, then the core's own check).
    pub fn validate(&self) -> Result<(), FitRunError> {
        let f = &self.fit;
        if !(f.landmarks.contour_sigma_factor > 0.0 && f.landmarks.contour_sigma_factor <= 100.0) {
            return Err(FitRunError::Settings(format!(
                "contour sigma factor {} is invalid: it must be in (0, 100]",
                f.landmarks.contour_sigma_factor
            )));
        }
        if !(f.landmarks.sigma > 0.0 && f.landmarks.sigma <= 0.5) {
            return Err(FitRunError::Settings(format!("landmark sigma {} is invalid: it must be in (0, 0.5]", f.landmarks.sigma)));
        }
        if !(16..=MAX_SIZE).contains(&self.size) {
            return Err(FitRunError::Settings(format!("working size {} is invalid: it must be 16 to {MAX_SIZE} pixels", self.size)));
        }
        f.validate().map_err(|_| {
            FitRunError::Settings("the fit settings are out of range (a σ, share, stride or step size is not positive and finite)".into())
        })
    }
}

impl Default for FitOptions {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// What the user gave for a fit (`gpmm fit`'s and `gpmm device-fit`'s flags, the Python
/// package's keywords): each `None` keeps [`FitOptions::DEFAULT`]'s value. [`Self::resolve`]
/// turns them into the options once.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FitFlags {
    /// Working image side (pixels).
    pub size: Option<u32>,
    /// Seed of the chains.
    pub seed: Option<u64>,
    /// Landmark-chain steps.
    pub landmark_steps: Option<u32>,
    /// Image-chain steps.
    pub image_steps: Option<u32>,
    /// Shape components fitted.
    pub shape_rank: Option<usize>,
    /// Colour components fitted.
    pub color_rank: Option<usize>,
    /// Landmark σ (fraction of the working image side).
    pub landmark_sigma: Option<f32>,
    /// Factor on the jaw contour's landmark σ while the landmark chain fits the pose.
    pub contour_sigma: Option<f32>,
    /// The landmarks come from the initializer (a fit's landmark-free start): their σ, in place
    /// of `landmark_sigma` ([`gpmm_core::fit::LandmarkSettings::for_initializer`]).
    pub initializer_sigma: Option<f32>,
    /// `PATH=VALUE` settings (`--set`, [`override_settings`]), applied last: they win over every
    /// other field.
    pub overrides: Vec<String>,
}

impl FitFlags {
    /// The options: the defaults, the flags given, the initializer's landmark σ, then the
    /// overrides (each applied once).
    pub fn resolve(&self) -> Result<FitOptions, FitRunError> {
        self.resolve_from(FitOptions::DEFAULT)
    }

    /// [`Self::resolve`] from other defaults than [`FitOptions::DEFAULT`] (a command whose fits
    /// differ, e.g. `gpmm learn`'s): a flag not given keeps `d`'s value.
    pub fn resolve_from(&self, d: FitOptions) -> Result<FitOptions, FitRunError> {
        let mut fit = d.fit.with_steps(self.landmark_steps.unwrap_or(d.fit.landmarks.steps), self.image_steps.unwrap_or(d.fit.image.steps));
        fit = fit.with_ranks(self.shape_rank.unwrap_or(d.fit.ranks.shape), self.color_rank.unwrap_or(d.fit.ranks.color));
        fit.landmarks.sigma = self.landmark_sigma.unwrap_or(fit.landmarks.sigma);
        fit.landmarks.contour_sigma_factor = self.contour_sigma.unwrap_or(fit.landmarks.contour_sigma_factor);
        if let Some(sigma) = self.initializer_sigma {
            fit.landmarks = fit.landmarks.for_initializer(sigma);
        }
        Ok(FitOptions {
            size: self.size.unwrap_or(d.size),
            seed: self.seed.unwrap_or(d.seed),
            fit: override_settings(&fit, &self.overrides)?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_flags_are_the_defaults() {
        assert_eq!(FitFlags::default().resolve().unwrap(), FitOptions::DEFAULT);
    }

    #[test]
    fn overrides_win_over_the_initializer_and_the_flags() {
        let flags = FitFlags {
            landmark_sigma: Some(0.02),
            initializer_sigma: Some(0.05),
            image_steps: Some(10),
            overrides: vec!["image.steps=20".into()],
            ..FitFlags::default()
        };
        let o = flags.resolve().unwrap();
        assert_eq!((o.fit.landmarks.sigma, o.fit.image.steps), (0.05, 20));
        assert_eq!(o.fit.landmarks, FitSettings::DEFAULT.landmarks.for_initializer(0.05));
        let set = FitFlags { overrides: vec!["landmarks.sigma=0.03".into()], ..flags }.resolve().unwrap();
        assert_eq!(set.fit.landmarks.sigma, 0.03);
    }

    #[test]
    fn other_defaults_hold_where_no_flag_is_given() {
        let base = FitOptions { fit: FitSettings::DEFAULT.with_image_shape(900), ..FitOptions::DEFAULT };
        assert_eq!(FitFlags::default().resolve_from(base).unwrap(), base);
        let o = FitFlags { image_steps: Some(30), ..FitFlags::default() }.resolve_from(base).unwrap();
        assert_eq!((o.fit.image.steps, o.fit.proposals.image.shape), (30, base.fit.proposals.image.shape));
        let off = FitFlags { overrides: vec!["proposals.image.shape=0".into()], ..FitFlags::default() }.resolve_from(base).unwrap();
        assert_eq!((off.fit.image.steps, off.fit.proposals.image.shape), (900, 0.0));
    }
}
