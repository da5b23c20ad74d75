//! gpmm-host: everything that runs on the workstation, as a library (the `gpmm` program is the
//! separate crate in `host/cli/`).
//!
//! Modules by concern: meshes, templates and their geometry ([`mesh`]); the paper's
//! Gaussian-process kernels, their low-rank Nyström/Mercer approximation and the model file
//! ([`gp`]); rendering through the core's tile rasterizer and figures ([`render`]); photos and
//! landmark files ([`photo`]); the face finder and initializer of an init file run on an image
//! ([`detect`]); fitting a model to a photo or a mesh ([`fit`]); the device side: quantization,
//! the model blob and the firmware run ([`device`]); synthetic faces with known truth
//! ([`synth`]); the paper's evaluation on them ([`eval`]); where the data lives ([`data`]); this
//! process's memory use ([`process`]).
#![deny(missing_docs)]

pub mod data;
pub mod detect;
pub mod device;
pub mod eval;
pub mod fit;
pub mod gp;
pub mod learn;
pub mod mesh;
pub mod photo;
pub mod process;
pub mod render;
pub mod synth;
