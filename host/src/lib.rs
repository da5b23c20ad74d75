//! gpmm-host: everything that runs on the workstation.
//!
//! Template import ([`mesh_io`], [`template`]), the paper's Gaussian-process
//! kernels ([`kernel`]), their low-rank Nyström/Mercer approximation
//! ([`lowrank`]), the model file ([`model_io`]), rendering through the core's tile
//! rasterizer ([`render`], [`figure`]) and the `gpmm` program ([`cli`]).
#![deny(missing_docs)]

pub mod cli;
pub mod data;
pub mod demo;
pub mod device_fit;
pub mod device_mesh;
pub mod eval;
pub mod figure;
pub mod fit;
pub mod fit_bench;
pub mod geom;
pub mod kernel;
pub mod lowrank;
pub mod mesh_io;
pub mod model;
pub mod model_io;
pub mod npy;
pub mod photo;
pub mod pts;
pub mod quantize;
pub mod register;
pub mod render;
pub mod synth;
pub mod template;
