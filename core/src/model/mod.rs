//! The model: low-rank linear bases ([`basis`]) and the borrowed morphable-model view with its
//! cached per-vertex instance ([`morphable`], [`instance`]).
//!
//! The rest of the crate reads a model only through these types: the blob format builds a
//! [`MorphableModel`] over its sections, the renderer draws an [`Instance`], the fitter moves
//! its coefficients.

pub mod basis;
pub mod ibug;
pub mod instance;
pub mod morphable;
pub mod params;

pub use basis::{Basis, DenseBasis, FactoredBasis, ModelError, QuantValues, QuantizedBasis};
pub use instance::{Instance, InstanceBuffers, SpareBuffers};
pub use morphable::MorphableModel;
pub use params::FitParams;

/// Most landmarks a model or a fit target has.
pub const MAX_LANDMARKS: usize = 128;
