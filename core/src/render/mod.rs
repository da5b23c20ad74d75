//! Rendering: the pinhole [`camera`], the rigid [`pose`], spherical-harmonics [`light`], the
//! per-vertex [`shading`] stage, the tiled [`raster`]izer and the [`tile`] buffers it hands to a
//! [`tile::TileSink`] (an image, or a likelihood that never stores the frame), and the
//! [`frame_cache`] that re-shades a frame whose geometry did not change.

pub mod camera;
mod fragment;
pub mod frame_cache;
pub mod light;
pub mod pose;
pub mod raster;
pub mod shading;
pub mod tile;

pub use camera::{Camera, ScreenPoint};
pub use light::ShLight;
pub use pose::Pose;
pub use raster::{Cull, FrameStats, RasterError, TileRasterizer};
pub use shading::{project_vertices, shade_vertices, vertex_normals, vertex_stage, ProjectedVertex, VertexError};
pub use tile::{Fragment, Tile, TileSink, NO_TRIANGLE};
