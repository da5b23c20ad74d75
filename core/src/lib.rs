//! gpmm-core: the `no_std`, allocation-free heart of gpmm.
//!
//! Everything here runs unchanged on the host (tests, batch fitting) and on
//! Cortex-M firmware. Nothing allocates, nothing panics on data: every
//! operation on caller-provided slices checks lengths and returns a small
//! `Copy` error instead.
//!
//! The modules, from the ground floor up (each imports only those before it):
//! - [`geometry`]: 3-vectors, 3×3 matrices and triangle indices;
//! - [`render`]: camera, pose, SH light, the per-vertex stage and the tiled rasterizer;
//! - [`model`]: low-rank bases and the morphable-model view with its cached instance;
//! - [`format`]: the wire formats (the model blob and the device's inputs and records);
//! - [`fit`]: the MCMC fit and its standard recipe;
//! - beside them [`checksum`], [`error`], [`net`] and [`profile`].
//!
//! Items are reached through their module; the crate root re-exports nothing. The entry points:
//! - a model: [`format::blob::ModelBlob`] reads one, [`model::MorphableModel`] views it;
//! - rendering: [`render::vertex_stage`] and [`render::TileRasterizer`] into a [`render::TileSink`];
//! - fitting: [`fit::standard_fit`] with its [`fit::FitSettings`].
#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
#![deny(missing_docs)]
#![deny(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]

pub mod checksum;
pub mod error;
pub mod fit;
pub mod format;
pub mod geometry;
pub mod model;
pub mod net;
pub mod profile;
pub mod render;
