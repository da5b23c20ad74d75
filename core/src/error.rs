//! The fit's error type, shared by the model view, the formats and the fit (it lives here so
//! that neither imports the fit), and the core's errors in words (`Display`).

use crate::model::ModelError;
use crate::render::raster::RasterError;
use crate::render::shading::VertexError;
use core::fmt;

/// Why a fit (or one of its parts) was refused. Small and `Copy`; never a panic.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FitError {
    /// Slices that must agree in length do not (per-vertex buffers, landmark lists, image pixels).
    LengthMismatch,
    /// A triangle or landmark refers to a vertex that does not exist.
    IndexOutOfRange,
    /// A parameter, target landmark or model value is NaN or infinite.
    NonFinite,
    /// More landmarks than [`crate::model::MAX_LANDMARKS`].
    TooManyLandmarks,
    /// No target landmark is marked valid.
    NoValidLandmarks,
    /// The target image has zero width or height.
    EmptyImage,
    /// A standard deviation, focal length or step count is out of range (zero, negative or NaN).
    BadConfig,
    /// The initial parameters have zero posterior density (e.g. landmarks behind the camera).
    ImpossibleStart,
    /// The least-squares light system is singular.
    Singular,
    /// The model's bases refused the coefficients.
    Model(ModelError),
    /// The per-vertex stage refused its input.
    Vertex(VertexError),
    /// The rasterizer refused the frame.
    Raster(RasterError),
}

impl From<ModelError> for FitError {
    fn from(e: ModelError) -> Self {
        FitError::Model(e)
    }
}

impl From<VertexError> for FitError {
    fn from(e: VertexError) -> Self {
        FitError::Vertex(e)
    }
}

impl From<RasterError> for FitError {
    fn from(e: RasterError) -> Self {
        FitError::Raster(e)
    }
}

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
            FitError::TooManyLandmarks => write!(f, "more than {} landmarks", crate::model::MAX_LANDMARKS),
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
