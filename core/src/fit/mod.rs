//! Model fitting by Markov-chain Monte Carlo (docs/design.md, "Fitting"; Schönborn et al., IJCV 2017).
//!
//! The pieces, one module each:
//! - [`params`]: the parameter vector ([`FitParams`]: pose, focal length, SH light, coefficients).
//! - [`crate::model::morphable`] (re-exported as `morph`): the borrowed [`MorphableModel`] view and the cached per-vertex [`Instance`].
//! - [`prior`], [`landmarks`]: log prior and landmark log likelihood.
//! - [`image`], [`likelihood`]: the target image and background model; the image likelihood
//!   composed from a [`PixelLikelihood`] and a [`BackgroundLikelihood`].
//! - [`proposal`]: the [`Proposal`] trait, weighted mixtures, and the built-in coarse-to-fine
//!   Gaussian drift proposals.
//! - [`observer`]: [`ChainObserver`]s that see every proposal's outcome ([`Acceptance`] counts).
//! - [`light_fit`]: the closed-form least-squares SH light on sampled visible vertices.
//! - [`chain`]: Metropolis-Hastings with delayed acceptance (prior and landmarks, then the image).
//! - [`recipe`]: the standard fit end to end ([`standard_fit`]), shared by the host and the firmware.
//! - [`settings`]: its one [`FitSettings`] (steps, ranks, σ's, proposal mixtures, light).
//! - [`normal`]: uniform and standard-normal samples over any `rand_core` generator.
//!
//! All log densities are `f32` and "up to an additive constant" unless stated otherwise; the
//! chain only ever uses differences. Nothing allocates; every buffer is borrowed or fixed-size.

pub mod chain;
pub mod image;
pub mod init;
pub mod landmarks;
pub mod light_fit;
pub mod likelihood;
pub mod normal;
pub mod observer;
pub mod params;
pub mod prior;
pub mod proposal;
pub mod recipe;
pub mod settings;

/// The morphable-model view under its old path (`gpmm_core::fit::morph`); it lives in [`crate::model`].
pub use crate::model::morphable as morph;
pub use crate::model::morphable::{Instance, InstanceBuffers, MorphableModel};
pub use chain::{
    filter_stage, image_chain, image_chain_observed, image_chain_with, image_log_likelihood, landmark_chain, landmark_chain_observed,
    landmark_chain_with, run_chain, ChainState, FitResult, ImageProblem, LandmarksOnly, Problem, RenderedImage, SecondStage,
};
pub use image::{BackgroundModel, ImageEval, TargetImage, DEFAULT_PIXEL_SIGMA};
pub use init::{initial_guess, landmark_pivot};
pub use landmarks::{evaluate_landmarks, LandmarkEval, LandmarkTarget, MAX_LANDMARKS};
pub use light_fit::{solve_light, LightSolveConfig};
pub use likelihood::{BackgroundLikelihood, GaussianPixel, ImageLikelihood, PixelLikelihood};
pub use observer::{Acceptance, ChainObserver, NoObserver, Progress, ProposalStep, StepOutcome};
pub use params::FitParams;
pub use prior::Prior;
pub use proposal::{Mixture, MixtureEntry, OneOf, Proposal, ProposalContext, ProposalKind, Scale, StandardProposal, MAX_PROPOSALS};
pub use recipe::{project_landmarks, standard_fit, FitObserver, Stage, StandardFit};
pub use settings::{Drift, DriftSettings, FitSettings, LightSettings, MixtureShares, ProposalSettings};

use crate::{ModelError, RasterError, VertexError};

/// Why a fit (or one of its parts) was refused. Small and `Copy`; never a panic.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FitError {
    /// Slices that must agree in length do not (per-vertex buffers, landmark lists, image pixels).
    LengthMismatch,
    /// A triangle or landmark refers to a vertex that does not exist.
    IndexOutOfRange,
    /// A parameter, target landmark or model value is NaN or infinite.
    NonFinite,
    /// More landmarks than [`MAX_LANDMARKS`].
    TooManyLandmarks,
    /// No target landmark is marked valid.
    NoValidLandmarks,
    /// The target image has zero width or height.
    EmptyImage,
    /// A standard deviation, focal length or step count is out of range (zero, negative or NaN).
    BadConfig,
    /// The initial parameters have zero posterior density (e.g. landmarks behind the camera).
    ImpossibleStart,
    /// The least-squares light system is singular.
    Singular,
    /// The model's bases refused the coefficients.
    Model(ModelError),
    /// The per-vertex stage refused its input.
    Vertex(VertexError),
    /// The rasterizer refused the frame.
    Raster(RasterError),
}

impl From<ModelError> for FitError {
    fn from(e: ModelError) -> Self {
        FitError::Model(e)
    }
}

impl From<VertexError> for FitError {
    fn from(e: VertexError) -> Self {
        FitError::Vertex(e)
    }
}

impl From<RasterError> for FitError {
    fn from(e: RasterError) -> Self {
        FitError::Raster(e)
    }
}
