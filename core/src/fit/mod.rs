//! Model fitting by Markov-chain Monte Carlo (docs/design.md, "Fitting"; Schönborn et al., IJCV 2017).
//!
//! The pieces, by role:
//! - [`likelihood`]: the posterior's terms: the prior, the landmark likelihood and the jaw contour
//!   as a silhouette, the target image and background model, and the image likelihood composed
//!   from a [`PixelLikelihood`] and a [`BackgroundLikelihood`].
//! - [`solve`]: the closed-form least-squares SH light, the colour coefficients (conjugate
//!   gradients) and the leading shape coefficients (damped Gauss–Newton on the image).
//! - [`chain`]: Metropolis-Hastings with delayed acceptance (prior and landmarks, then the image),
//!   its [`Proposal`]s and mixtures, the [`ChainObserver`]s that see every proposal's outcome,
//!   the posterior's moments and the random samples it draws.
//! - [`start`]: the chains' starting point from the target landmarks alone.
//! - [`spread`]: how well the landmarks pin the fitted pose down (a Laplace approximation).
//! - [`frame`]: the photo's edge: how far outside it landmarks may lie, and the working pixels it covers.
//! - [`coarse`]: the image chain's first steps at half resolution.
//! - [`recipe`]: the standard fit end to end ([`standard_fit`]), shared by the host and the firmware.
//! - [`settings`]: its one [`FitSettings`] (steps, ranks, σ's, proposal mixtures, light).
//!
//! The parameter vector ([`FitParams`](crate::model::FitParams)) and the model view the fit moves
//! ([`MorphableModel`](crate::model::MorphableModel), [`Instance`](crate::model::Instance)) live in
//! [`crate::model`].
//!
//! All log densities are `f32` and "up to an additive constant" unless stated otherwise; the
//! chain only ever uses differences. Nothing allocates; every buffer is borrowed or fixed-size.

pub mod chain;
pub mod coarse;
pub mod frame;
pub mod likelihood;
pub mod recipe;
pub mod settings;
pub mod solve;
pub mod spread;
pub mod start;

pub use chain::observer::{Acceptance, ChainObserver, ChainSample, NoObserver, Progress, ProposalStep, StepOutcome};
pub use chain::posterior::PosteriorMoments;
pub use chain::proposal::{Mixture, MixtureEntry, OneOf, Proposal, ProposalContext, ProposalKind, Scale, StandardProposal, MAX_PROPOSALS};
pub use chain::{
    image_chain, image_log_likelihood, landmark_chain, run_chain, ChainState, FitResult, ImageProblem, LandmarksOnly, Problem,
    RenderedImage, SecondStage,
};
pub use frame::{first_beyond_margin, landmark_margin, CoveredPixels, LANDMARK_MARGIN};
pub use likelihood::contour::{Silhouette, CONTOUR_POOL, MAX_CONTOUR, NO_VERTEX};
pub use likelihood::image::{BackgroundModel, ImageEval, TargetImage, DEFAULT_PIXEL_SIGMA};
pub use likelihood::labeller::Labeller;
pub use likelihood::landmarks::{evaluate_landmarks, LandmarkEval, LandmarkTarget};
pub use likelihood::occlusion::{MaskView, OcclusionMask, OcclusionSettings};
pub use likelihood::pixel::{BackgroundLikelihood, GaussianPixel, ImageLikelihood, PixelLikelihood};
pub use likelihood::prior::Prior;
pub use recipe::{project_landmarks, standard_fit, FitObserver, Stage, StandardFit};
pub use settings::{
    Drift, DriftSettings, FitSettings, ImageSettings, LandmarkSettings, LightSettings, MixtureShares, ProposalSettings, RankSettings,
    StartSettings, INIT_LANDMARK_SIGMA,
};
pub use solve::color::{solve_color, ColorScene, ColorSolveConfig};
pub use solve::light::{solve_light, LightSolveConfig};
pub use solve::shape::{solve_shape, ShapeSolveConfig, ShapeSolveReport, MAX_SHAPE_SOLVE};
pub use spread::{pose_spread, PoseSpread};
pub use start::{initial_guess, landmark_pivot};
