//! The Gaussian-process model: the paper's kernels ([`kernel`], evaluated a column at a time by
//! [`kernel_columns`]), their low-rank Nyström/Mercer
//! approximation ([`lowrank`]), the model and its builder ([`model`]) and the model file
//! ([`model_io`]), and statismo / scalismo `.h5` files ([`statismo`]).

pub mod kernel;
pub mod kernel_columns;
pub mod lowrank;
pub mod model;
pub mod model_io;
pub mod statismo;
