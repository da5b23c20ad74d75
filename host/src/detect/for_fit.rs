//! The faces a fit takes from a photo when it has no landmark file: those the init file finds at
//! its advised score and its face check keeps, or, for a fit of one face, the best weaker one.

use super::{DetectError, Detector, DEFAULT_MIN_SCORE, DEFAULT_SMALLEST_FACE};
use gpmm_core::net::face::{Detection, Reading};
use image::RgbImage;

/// What [`faces_for_fit`] found.
#[derive(Debug, Clone)]
pub struct FitFaces {
    /// The faces, best first (empty when there is none).
    pub faces: Vec<Detection>,
    /// The finder score they were asked to reach.
    pub min_score: f32,
    /// No face reached it, and these are the weaker faces of [`DEFAULT_MIN_SCORE`] instead.
    pub weaker: bool,
}

/// The faces of `image` a fit takes: those `detector` finds at `min_score` (`None`: its
/// [`Detector::advised_min_score`]) down to [`DEFAULT_SMALLEST_FACE`] px, read with
/// [`Reading::DEFAULT`]. With `all`, every face its face check keeps; otherwise the check's faces,
/// or every face when the check keeps none, or — with the advised score and no face reaching it —
/// those of [`DEFAULT_MIN_SCORE`] (the photo was given as a face's: its best box is better fitted
/// than none), marked `weaker`.
pub fn faces_for_fit(detector: &mut Detector, image: &RgbImage, min_score: Option<f32>, all: bool) -> Result<FitFaces, DetectError> {
    let min = min_score.unwrap_or(detector.advised_min_score());
    let (smallest, reading) = (DEFAULT_SMALLEST_FACE, Reading::DEFAULT);
    let faces =
        if all { detector.scan_all(image, min, smallest, reading)? } else { detector.scan_for_fit(image, min, smallest, reading)? };
    if faces.is_empty() && !all && min_score.is_none() && min > DEFAULT_MIN_SCORE {
        let weaker = detector.scan_for_fit(image, DEFAULT_MIN_SCORE, smallest, reading)?;
        let found = !weaker.is_empty();
        return Ok(FitFaces { faces: weaker, min_score: min, weaker: found });
    }
    Ok(FitFaces { faces, min_score: min, weaker: false })
}
