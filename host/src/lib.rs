//! gpmm-host: everything that runs on the workstation.
//!
//! Template import ([`mesh_io`], [`template`]), the paper's Gaussian-process
//! kernels ([`kernel`]), their low-rank Nyström/Mercer approximation
//! ([`lowrank`]), the model file ([`model_io`]) and the `gpmm` program ([`cli`]).
#![deny(missing_docs)]

pub mod cli;
pub mod kernel;
pub mod lowrank;
pub mod mesh_io;
pub mod model;
pub mod model_io;
pub mod template;
