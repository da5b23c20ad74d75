//! The start gpmm ships: an init file trained with the real-photo recipe (docs/real-photos.md)
//! for the default model, compiled into the program, used wherever a command is given no
//! landmarks and no init file. Its provenance: `host/assets/README.md` and its metadata.

use super::{DetectError, Detector};
use std::path::{Path, PathBuf};

/// The shipped init file's bytes (`host/assets/face.init`; rebuilt by
/// `tests/realphotos/shipped_init.sh`).
pub const SHIPPED_INIT: &[u8] = include_bytes!("../../assets/face.init");

/// How messages name the shipped init file.
pub const SHIPPED_INIT_NAME: &str = "the shipped start (face.init)";

/// The landmarks the shipped start reads: the 68 iBUG points. A model with other landmarks
/// cannot be fitted from it.
pub const SHIPPED_LANDMARKS: usize = 68;

/// The shipped start, loaded ([`SHIPPED_INIT`]).
pub fn shipped() -> Result<Detector, DetectError> {
    Detector::from_bytes(SHIPPED_INIT).map_err(|error| DetectError::Invalid { path: PathBuf::from(SHIPPED_INIT_NAME), error })
}

/// The init file at `init`, or the shipped start when none is given.
pub fn open(init: Option<&Path>) -> Result<Detector, DetectError> {
    match init {
        Some(path) => Detector::load(path),
        None => shipped(),
    }
}

/// How messages name `init` (its path), or the shipped start when none is given.
pub fn init_name(init: Option<&Path>) -> String {
    init.map_or_else(|| SHIPPED_INIT_NAME.to_string(), |p| p.display().to_string())
}

/// Whether the shipped start serves a model with `landmarks` landmarks: it reads the 68 iBUG
/// points, so any model with those is fitted from it (its pose and light are the model's own;
/// docs/real-photos.md, "The shipped start"); `Err` says why not.
pub fn serves(landmarks: usize) -> Result<(), String> {
    if landmarks == SHIPPED_LANDMARKS {
        Ok(())
    } else {
        Err(format!(
            "{SHIPPED_INIT_NAME} reads the {SHIPPED_LANDMARKS} iBUG landmarks and the model has {landmarks}: give --landmarks PTS, \
             or --init INIT trained for this model (`gpmm train-init`)"
        ))
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_start_parses_and_reads_68_points() {
        let detector = shipped().unwrap();
        let file = detector.file().unwrap();
        assert_eq!(file.landmarks, SHIPPED_LANDMARKS);
        assert!(!super::super::provenance::trained_for(file.metadata).is_empty(), "the shipped start names its model");
        assert!(detector.check().is_some(), "the shipped start carries its face check");
        assert!(serves(68).is_ok());
        assert!(serves(5).unwrap_err().contains("68"));
    }
}
