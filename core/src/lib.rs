//! gpmm-core: the `no_std`, allocation-free heart of gpmm.
//!
//! Everything here runs unchanged on the host (tests, batch fitting) and on
//! Cortex-M firmware. Nothing allocates, nothing panics on data: every
//! operation on caller-provided slices checks lengths and returns a small
//! `Copy` error instead.
#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
#![deny(missing_docs)]
#![deny(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]

pub mod model;

pub use model::{Basis, DenseBasis, FactoredBasis, ModelError, Vec3};
