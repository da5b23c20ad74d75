//! Closed-form and least-squares solves the chains use as proposals: the SH [`light`], the
//! [`color`] coefficients and the leading [`shape`] coefficients, each on sampled visible
//! vertices for a fixed rest of the state.

pub(crate) mod cholesky;
pub mod color;
pub mod light;
mod ring;
pub mod shape;
