//! Why training stopped: the one error of the training loop, the mistake scan and their checks.

use crate::encode::EncodeError;
use crate::start::StartError;
use gpmm_core::net::NetError;
use gpmm_host::detect::DetectError;

/// Why training or its validation stopped.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    /// No model to draw faces from.
    #[error("no model to train on")]
    NoModels,
    /// A model of a mixture is not in the first one's topology.
    #[error("{error}")]
    Mixture {
        /// Index of the model in the mixture.
        index: usize,
        /// How it differs from the first.
        error: MixtureMismatch,
    },
    /// The init file to start from does not fit the training.
    #[error("{error}")]
    Start {
        /// Why.
        error: StartError,
    },
    /// The initializer cannot read this many landmarks.
    #[error("the model has {0} landmarks; the initializer reads 1 to 68")]
    Landmarks(usize),
    /// Mirroring crops needs the symmetric iBUG-68 scheme.
    #[error("mirrored crops need the 68 iBUG landmarks; the model has {0}")]
    MirrorNeedsIbug68(usize),
    /// Scanning for the finder's mistakes needs the file it starts from and background photos.
    #[error("scanning for the finder's mistakes needs an init file to start from and background photos")]
    MistakesNeedStart,
    /// A chunk of scenes rendered empty.
    #[error("no training scene could be rendered (is the model's landmark list valid?)")]
    NoScenes,
    /// A loss became NaN or infinite.
    #[error("training diverged at step {step} (loss {finder} / {initializer}); try a smaller learning rate")]
    Diverged {
        /// Steps done before.
        step: usize,
        /// The finder's loss.
        finder: f32,
        /// The initializer's loss.
        initializer: f32,
    },
    /// A tensor operation failed.
    #[error("{0}")]
    Tensor(candle_core::Error),
    /// The trained networks could not be encoded as an init file.
    #[error("{0}")]
    Encode(EncodeError),
    /// The encoded init file does not read back.
    #[error("{0}")]
    InitFile(NetError),
    /// The quantized detector failed on a validation scene.
    #[error("{0}")]
    Detect(DetectError),
}

/// How a model of a mixture differs from the first one (whose topology scenes and labels share).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MixtureMismatch {
    /// Another vertex count.
    #[error("it has {found} vertices, the first model {expected}; a mixture's models share the template's topology")]
    Vertices {
        /// This model's.
        found: usize,
        /// The first model's.
        expected: usize,
    },
    /// Another landmark count.
    #[error("it has {found} landmarks, the first model {expected}")]
    Landmarks {
        /// This model's.
        found: usize,
        /// The first model's.
        expected: usize,
    },
}
