//! gpmm-train: the face finder and the initializer of a landmark-free fit, trained on the CPU with
//! candle on scenes rendered from the morphable model itself ([`scene`]), then quantized into an
//! init file ([`encode`], `docs/init-format.md`). Deterministic for a seed.

pub mod data;
pub mod encode;
pub mod error;
pub mod mistakes;
pub mod nets;
pub mod patches;
pub mod preview;
pub mod scene;
pub mod start;
pub mod train;

pub use train::{fine_tune, train, train_on, train_with, TrainError, TrainOptions, TrainReport};
