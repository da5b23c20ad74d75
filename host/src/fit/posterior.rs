//! The image chain's posterior summary as fit.json and the evaluation read it.

use super::params::{Params, KC, KS};
use gpmm_core::fit::PosteriorMoments;
use serde::{Deserialize, Serialize};

/// The image chain's posterior summary: mean and standard deviation of the coefficients and
/// the rotation over its samples from half-way on (one sample per step, the state the chain is
/// in). The mean is the posterior's estimate; the best sample (the fit) is one draw.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PosteriorSummary {
    /// Image-chain steps left out before the samples start.
    pub burn_in: u32,
    /// Samples summed.
    pub samples: u32,
    /// Mean shape coefficients.
    pub shape_mean: Vec<f32>,
    /// Their standard deviations.
    pub shape_sd: Vec<f32>,
    /// Mean colour coefficients.
    pub color_mean: Vec<f32>,
    /// Their standard deviations.
    pub color_sd: Vec<f32>,
    /// Mean yaw, pitch and roll (degrees).
    pub angles_mean_deg: [f32; 3],
    /// Their standard deviations (degrees).
    pub angles_sd_deg: [f32; 3],
}

impl PosteriorSummary {
    /// The summary of the core's moments.
    pub fn of(m: &PosteriorMoments<KS, KC>) -> Self {
        Self {
            burn_in: m.burn_in(),
            samples: m.samples(),
            shape_mean: m.shape_mean().collect(),
            shape_sd: m.shape_sd().collect(),
            color_mean: m.color_mean().collect(),
            color_sd: m.color_sd().collect(),
            angles_mean_deg: m.angles_mean().map(f32::to_degrees),
            angles_sd_deg: m.angles_sd().map(f32::to_degrees),
        }
    }

    /// The mean coefficients in place of `params`' (its pose, focal and light kept); `params`
    /// unchanged if nothing was summed or the lengths differ.
    pub fn mean_params(&self, params: &Params) -> Params {
        let mut p = params.clone();
        if self.samples > 0 && self.shape_mean.len() == p.shape_len() && self.color_mean.len() == p.color_len() {
            p.shape_coeffs_mut().copy_from_slice(&self.shape_mean);
            p.color_coeffs_mut().copy_from_slice(&self.color_mean);
        }
        p
    }
}
