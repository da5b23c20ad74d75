//! A fit's input: the photo and its landmarks read and checked against the model, cropped and
//! resampled to the working image.

use super::error::FitRunError;
use crate::gp::model::GpModel;
use crate::photo::calibration::LandmarkCalibration;
use crate::photo::{crop_box, crop_resize, CropBox};
use gpmm_core::fit::CoveredPixels;
use image::RgbImage;

/// A photo cropped and resampled for fitting, with its landmarks in both images.
#[derive(Debug, Clone)]
pub struct Prepared {
    /// The working image (`size × size`).
    pub image: RgbImage,
    /// Landmarks in the working image (continuous pixel coordinates).
    pub landmarks: Vec<[f32; 2]>,
    /// The crop in the original image.
    pub crop: CropBox,
    /// The working pixels the photo covers (the rest of the crop lay past its edge).
    pub covered: CoveredPixels,
    /// Original image size.
    pub original_size: [u32; 2],
    /// Landmarks in the original image.
    pub original_landmarks: Vec<[f32; 2]>,
}

/// Crops `image` around `points` (original-image landmarks) and resamples it to `size × size`.
pub fn prepare(image: &RgbImage, points: &[[f32; 2]], size: u32) -> Result<Prepared, FitRunError> {
    let crop = crop_box(points, image.width(), image.height())?;
    Ok(Prepared {
        image: crop_resize(image, &crop, size),
        landmarks: points.iter().map(|p| crop.to_working(*p, size)).collect(),
        covered: crop.covered(size, image.width(), image.height()),
        crop,
        original_size: [image.width(), image.height()],
        original_landmarks: points.to_vec(),
    })
}

/// Loads a photo and its landmarks, checked against the model (count, inside the image), and
/// prepares it; with a detector `calibration` the landmarks are corrected first (and kept inside
/// the image).
pub fn load_photo(
    model: &GpModel,
    image: &std::path::Path,
    landmarks: &std::path::Path,
    one_based: bool,
    size: u32,
    calibration: Option<&LandmarkCalibration>,
) -> Result<Prepared, FitRunError> {
    check_landmarks(model)?;
    let pts = crate::photo::pts::read_pts(landmarks, one_based)?;
    let photo = crate::photo::load_rgb(image)?;
    pts.check(landmarks, model.landmarks.len(), &model.metadata.landmark_scheme, photo.width(), photo.height(), one_based)?;
    let points = match calibration {
        None => pts.points,
        Some(c) => c
            .correct_in_image(&pts.points, photo.width() as f32, photo.height() as f32)
            .map_err(|error| FitRunError::Calibration { path: landmarks.to_path_buf(), error })?,
    };
    prepare(&photo, &points, size)
}

/// Refuses a model without landmarks (e.g. a statismo import without usable ones) before any
/// photo is read, with a message that says what to do.
pub fn check_landmarks(model: &GpModel) -> Result<(), FitRunError> {
    if model.landmarks.is_empty() {
        return Err(FitRunError::Model(
            "it has 0 landmarks (a model imported from .h5 needs them: gpmm import-h5 --landmarks FILE.json)".into(),
        ));
    }
    Ok(())
}
