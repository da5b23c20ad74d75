//! Conversions between numpy arrays and the host library's images, points and vectors.

use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{IntoPyArray, PyReadonlyArray2, PyReadonlyArray3};
use pyo3::prelude::*;

use crate::err_msg;

/// An `H x W x 3` uint8 array of an RGB image.
pub fn rgb_to_numpy<'py>(py: Python<'py>, img: &image::RgbImage) -> PyResult<Bound<'py, PyAny>> {
    let (w, h) = img.dimensions();
    let a = Array3::from_shape_vec((h as usize, w as usize, 3), img.as_raw().clone()).map_err(|e| err_msg(e.to_string()))?;
    Ok(a.into_pyarray(py).into_any())
}

/// An `H x W x 4` uint8 array of an RGBA image.
pub fn rgba_to_numpy<'py>(py: Python<'py>, img: &image::RgbaImage) -> PyResult<Bound<'py, PyAny>> {
    let (w, h) = img.dimensions();
    let a = Array3::from_shape_vec((h as usize, w as usize, 4), img.as_raw().clone()).map_err(|e| err_msg(e.to_string()))?;
    Ok(a.into_pyarray(py).into_any())
}

/// An `L x 2` float32 array of points.
pub fn points_to_numpy<'py>(py: Python<'py>, points: &[[f32; 2]]) -> PyResult<Bound<'py, PyAny>> {
    let a = Array2::from_shape_vec((points.len(), 2), points.iter().flatten().copied().collect()).map_err(|e| err_msg(e.to_string()))?;
    Ok(a.into_pyarray(py).into_any())
}

/// An `N x 3` array of 3-vectors.
pub fn vec3_to_numpy<'py, T: numpy::Element + Copy>(py: Python<'py>, v: &[[T; 3]]) -> PyResult<Bound<'py, PyAny>> {
    let a = Array2::from_shape_vec((v.len(), 3), v.iter().flatten().copied().collect()).map_err(|e| err_msg(e.to_string()))?;
    Ok(a.into_pyarray(py).into_any())
}

/// A 1-D array.
pub fn vec_to_numpy<'py, T: numpy::Element>(py: Python<'py>, v: Vec<T>) -> Bound<'py, PyAny> {
    Array1::from_vec(v).into_pyarray(py).into_any()
}

/// A `K x N x 3` array from row-major values.
pub fn basis_to_numpy<'py>(py: Python<'py>, values: Vec<f32>, k: usize, n: usize) -> PyResult<Bound<'py, PyAny>> {
    let a = Array3::from_shape_vec((k, n, 3), values).map_err(|e| err_msg(e.to_string()))?;
    Ok(a.into_pyarray(py).into_any())
}

/// An RGB image from an `H x W x 3` uint8 array (any strides).
pub fn numpy_to_rgb(obj: &Bound<'_, PyAny>) -> PyResult<image::RgbImage> {
    let arr: PyReadonlyArray3<'_, u8> =
        obj.extract().map_err(|_| err_msg("image must be an H x W x 3 numpy array of uint8 (RGB, as gpmm.load_image gives)"))?;
    let a = arr.as_array();
    let (h, w, c) = a.dim();
    if c != 3 || h == 0 || w == 0 {
        return Err(err_msg(format!("image has shape ({h}, {w}, {c}); expected (H, W, 3) with H, W > 0")));
    }
    let raw: Vec<u8> = a.iter().copied().collect();
    image::RgbImage::from_raw(w as u32, h as u32, raw).ok_or_else(|| err_msg("image buffer has the wrong size"))
}

/// Points from an `L x 2` array of any float dtype (converted to float32).
pub fn numpy_to_points(py: Python<'_>, obj: &Bound<'_, PyAny>) -> PyResult<Vec<[f32; 2]>> {
    let np = py.import("numpy")?;
    let conv = np.call_method1("ascontiguousarray", (obj, "float32"))?;
    let arr: PyReadonlyArray2<'_, f32> = conv.extract().map_err(|_| err_msg("landmarks must be an L x 2 array of pixel coordinates"))?;
    let a = arr.as_array();
    if a.dim().1 != 2 {
        return Err(err_msg(format!("landmarks have shape {:?}; expected (L, 2)", a.dim())));
    }
    Ok(a.rows().into_iter().map(|r| [r[0], r[1]]).collect())
}
