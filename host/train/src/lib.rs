//! gpmm-train: the face finder and the initializer of a landmark-free fit, trained on the CPU with
//! candle on scenes rendered from the morphable model itself (`gpmm_host::init::scene`), then
//! quantized into an init file (`docs/init-format.md`). Deterministic for a seed.

pub mod data;
pub mod nets;
pub mod patches;
pub mod preview;
pub mod train;

pub use train::{train, TrainOptions, TrainReport};
