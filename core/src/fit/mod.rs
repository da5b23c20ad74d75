//! Model fitting by Markov-chain Monte Carlo (docs/design.md, "Fitting"; Schönborn et al., IJCV 2017).
//!
//! The pieces, one module each:
//! - [`params`]: the parameter vector ([`FitParams`]: pose, focal length, SH light, coefficients).
//! - [`crate::model::morphable`] (re-exported as `morph`): the borrowed [`MorphableModel`] view and the cached per-vertex [`Instance`].
//! - [`prior`], [`landmarks`]: log prior and landmark log likelihood; [`contour`]: the jaw contour as a silhouette.
//! - [`image`], [`likelihood`]: the target image and background model; the image likelihood
//!   composed from a [`PixelLikelihood`] and a [`BackgroundLikelihood`].
//! - [`proposal`]: the [`Proposal`] trait, weighted mixtures, and the built-in coarse-to-fine
//!   Gaussian drift proposals.
//! - [`observer`]: [`ChainObserver`]s that see every proposal's outcome ([`Acceptance`] counts).
//! - [`light_fit`]: the closed-form least-squares SH light on sampled visible vertices.
//! - [`color_fit`]: the colour coefficients by regularized least squares (conjugate gradients).
//! - [`shape_fit`]: the leading shape coefficients by damped Gauss–Newton on the image.
//! - [`chain`]: Metropolis-Hastings with delayed acceptance (prior and landmarks, then the image).
//! - [`recipe`]: the standard fit end to end ([`standard_fit`]), shared by the host and the firmware.
//! - [`settings`]: its one [`FitSettings`] (steps, ranks, σ's, proposal mixtures, light).
//! - [`normal`]: uniform and standard-normal samples over any `rand_core` generator.
//!
//! All log densities are `f32` and "up to an additive constant" unless stated otherwise; the
//! chain only ever uses differences. Nothing allocates; every buffer is borrowed or fixed-size.

/// The parameter vector, under its old path (`gpmm_core::fit::params`); it lives in [`crate::model`].
pub use crate::model::params;
pub mod chain;
mod cholesky;
pub mod color_fit;
pub mod contour;
pub mod image;
pub mod init;
pub mod landmarks;
pub mod light_fit;
pub mod likelihood;
pub mod normal;
pub mod observer;
pub mod posterior;
pub mod prior;
pub mod proposal;
pub mod recipe;
pub mod settings;
pub mod shape_fit;

pub use crate::model::instance::{Instance, InstanceBuffers, SolveScratch, SolverView, SpareBuffers};
/// The morphable-model view under its old path (`gpmm_core::fit::morph`); it lives in [`crate::model`].
pub use crate::model::morphable as morph;
pub use crate::model::morphable::MorphableModel;
pub use chain::{
    filter_stage, image_chain, image_chain_observed, image_chain_with, image_log_likelihood, landmark_chain, landmark_chain_observed,
    landmark_chain_with, run_chain, ChainState, FitResult, ImageProblem, LandmarksOnly, Problem, RenderedImage, SecondStage,
};
pub use color_fit::{solve_color, ColorScene, ColorSolveConfig};
pub use contour::{Silhouette, CONTOUR_POOL, MAX_CONTOUR, NO_VERTEX};
pub use image::{BackgroundModel, ImageEval, TargetImage, DEFAULT_PIXEL_SIGMA};
pub use init::{initial_guess, landmark_pivot};
pub use landmarks::{evaluate_landmarks, LandmarkEval, LandmarkTarget, MAX_LANDMARKS};
pub use light_fit::{solve_light, LightSolveConfig};
pub use likelihood::{BackgroundLikelihood, GaussianPixel, ImageLikelihood, PixelLikelihood};
pub use observer::{Acceptance, ChainObserver, ChainSample, NoObserver, Progress, ProposalStep, StepOutcome};
pub use params::FitParams;
pub use posterior::PosteriorMoments;
pub use prior::Prior;
pub use proposal::{Mixture, MixtureEntry, OneOf, Proposal, ProposalContext, ProposalKind, Scale, StandardProposal, MAX_PROPOSALS};
pub use recipe::{project_landmarks, standard_fit, FitObserver, Stage, StandardFit};
pub use settings::{
    Drift, DriftSettings, FitSettings, ImageSettings, LandmarkSettings, LightSettings, MixtureShares, ProposalSettings, RankSettings,
    StartSettings, INIT_LANDMARK_SIGMA,
};
pub use shape_fit::{solve_shape, ShapeSolveConfig, ShapeSolveReport, MAX_SHAPE_SOLVE};

pub use crate::error::FitError;
