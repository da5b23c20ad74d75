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

pub mod checksum;
pub mod error;
pub mod fit;
pub mod format;
pub mod model;
pub mod net;
pub mod profile;
pub mod render;

// The render modules under their old crate-root paths (`gpmm_core::camera::Camera`, ...).
pub use render::{camera, frame_cache, light, pose, raster, shading, tile};

pub use camera::{Camera, ScreenPoint};
pub use checksum::{crc32, FrameChecksum};
pub use format::blob;
pub use format::blob::{BlobError, ModelBlob};
pub use light::ShLight;
pub use model::{Basis, DenseBasis, FactoredBasis, ModelError, QuantValues, QuantizedBasis, Vec3};
pub use pose::{Mat3, Pose};
pub use raster::{Cull, FrameStats, RasterError, TileRasterizer};
pub use shading::{project_vertices, shade_vertices, vertex_normals, vertex_stage, ProjectedVertex, TriIndex, VertexError};
pub use tile::{Fragment, Tile, TileSink, NO_TRIANGLE};
