//! Why a fit failed: the one error of the photo's preparation, the settings and the core's fit.

use crate::photo::calibration::CalibrationError;
use crate::photo::pts::PtsError;
use crate::photo::PhotoError;
use gpmm_core::error::FitError;

/// Why a fit failed.
#[derive(Debug, thiserror::Error)]
pub enum FitRunError {
    /// The landmark file was refused.
    #[error(transparent)]
    Pts(#[from] PtsError),
    /// The photo was refused.
    #[error(transparent)]
    Photo(#[from] PhotoError),
    /// The landmarks could not be corrected with the detector calibration.
    #[error("{}: {error}", path.display())]
    Calibration {
        /// The landmark file.
        path: std::path::PathBuf,
        /// What went wrong.
        error: CalibrationError,
    },
    /// The detector calibration file could not be read (the error names the file).
    #[error(transparent)]
    CalibrationFile(CalibrationError),
    /// The settings are out of range.
    #[error("{0}")]
    Settings(String),
    /// The model cannot be fitted (no landmarks, inconsistent arrays).
    #[error("the model cannot be fitted: {0}")]
    Model(String),
    /// The core fitter refused its input.
    #[error("{stage}: the core fitter refused the input: {error}")]
    Core {
        /// Which stage.
        stage: &'static str,
        /// The core's error.
        error: FitError,
    },
}
