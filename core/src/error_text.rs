//! The core's errors in words (`Display`), for messages on the host and the device.

use crate::fit::FitError;
use crate::model::ModelError;
use crate::render::raster::RasterError;
use crate::render::shading::VertexError;
use core::fmt;

impl fmt::Display for ModelError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            ModelError::LengthMismatch => "the model's arrays do not agree with its vertex count and rank",
            ModelError::TooManyCoefficients => "more coefficients than the basis has components",
        })
    }
}

impl fmt::Display for VertexError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            VertexError::LengthMismatch => "the per-vertex arrays differ in length",
            VertexError::IndexOutOfRange => "a triangle refers to a vertex that does not exist",
            VertexError::NonFinite => "a position, colour, pose, camera or light value is NaN or infinite",
        })
    }
}

impl fmt::Display for RasterError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            RasterError::IndexOutOfRange => "a triangle refers to a vertex that does not exist",
            RasterError::ImageTooLarge => "the image is larger than the rasterizer's 32,768 pixels a side",
            RasterError::TooManyTriangles => "more triangles than the rasterizer counts",
            RasterError::ZeroTileSize => "the tile size is zero",
        })
    }
}

impl fmt::Display for FitError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FitError::LengthMismatch => f.write_str("lengths that must agree do not (per-vertex buffers, landmarks or image pixels)"),
            FitError::IndexOutOfRange => f.write_str("a triangle or landmark refers to a vertex that does not exist"),
            FitError::NonFinite => f.write_str("a parameter, target landmark or model value is NaN or infinite"),
            FitError::TooManyLandmarks => write!(f, "more than {} landmarks", crate::fit::MAX_LANDMARKS),
            FitError::NoValidLandmarks => f.write_str("no target landmark is usable"),
            FitError::EmptyImage => f.write_str("the target image has no pixels"),
            FitError::BadConfig => f.write_str("a fit setting is out of range (a σ, factor, share or step size is zero, negative or NaN)"),
            FitError::ImpossibleStart => f.write_str("the start has zero posterior density (e.g. landmarks behind the camera)"),
            FitError::Singular => f.write_str("the least-squares light system is singular"),
            FitError::Model(e) => write!(f, "model: {e}"),
            FitError::Vertex(e) => write!(f, "vertex stage: {e}"),
            FitError::Raster(e) => write!(f, "rasterizer: {e}"),
        }
    }
}

impl core::error::Error for ModelError {}
impl core::error::Error for VertexError {}
impl core::error::Error for RasterError {}
impl core::error::Error for FitError {}
