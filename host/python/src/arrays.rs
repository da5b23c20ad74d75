//! Conversions between Python objects and the host library's values: numpy arrays of images,
//! points and vectors, and serializable values as dicts and lists.

use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{IntoPyArray, PyReadonlyArray2, PyReadonlyArray3};
use pyo3::prelude::*;

use crate::errors::{err, value_error};
use numpy::ndarray::s;

/// An `H x W x 3` uint8 array of an RGB image.
pub fn rgb_to_numpy<'py>(py: Python<'py>, img: &image::RgbImage) -> PyResult<Bound<'py, PyAny>> {
    let (w, h) = img.dimensions();
    let a = Array3::from_shape_vec((h as usize, w as usize, 3), img.as_raw().clone()).map_err(|e| value_error(e.to_string()))?;
    Ok(a.into_pyarray(py).into_any())
}

/// An `H x W x 4` uint8 array of an RGBA image.
pub fn rgba_to_numpy<'py>(py: Python<'py>, img: &image::RgbaImage) -> PyResult<Bound<'py, PyAny>> {
    let (w, h) = img.dimensions();
    let a = Array3::from_shape_vec((h as usize, w as usize, 4), img.as_raw().clone()).map_err(|e| value_error(e.to_string()))?;
    Ok(a.into_pyarray(py).into_any())
}

/// An `H x W` boolean array of a mask image (true where the pixel is set).
pub fn mask_to_numpy<'py>(py: Python<'py>, img: &image::GrayImage) -> PyResult<Bound<'py, PyAny>> {
    let (w, h) = img.dimensions();
    let bits = img.as_raw().iter().map(|v| *v > 127).collect();
    let a = Array2::from_shape_vec((h as usize, w as usize), bits).map_err(|e| value_error(e.to_string()))?;
    Ok(a.into_pyarray(py).into_any())
}

/// An `L x 2` float32 array of points.
pub fn points_to_numpy<'py>(py: Python<'py>, points: &[[f32; 2]]) -> PyResult<Bound<'py, PyAny>> {
    let a =
        Array2::from_shape_vec((points.len(), 2), points.iter().flatten().copied().collect()).map_err(|e| value_error(e.to_string()))?;
    Ok(a.into_pyarray(py).into_any())
}

/// An `N x 3` array of 3-vectors.
pub fn vec3_to_numpy<'py, T: numpy::Element + Copy>(py: Python<'py>, v: &[[T; 3]]) -> PyResult<Bound<'py, PyAny>> {
    let a = Array2::from_shape_vec((v.len(), 3), v.iter().flatten().copied().collect()).map_err(|e| value_error(e.to_string()))?;
    Ok(a.into_pyarray(py).into_any())
}

/// A 1-D array.
pub fn vec_to_numpy<'py, T: numpy::Element>(py: Python<'py>, v: Vec<T>) -> Bound<'py, PyAny> {
    Array1::from_vec(v).into_pyarray(py).into_any()
}

/// A `K x N x 3` array from row-major values.
pub fn basis_to_numpy<'py>(py: Python<'py>, values: Vec<f32>, k: usize, n: usize) -> PyResult<Bound<'py, PyAny>> {
    let a = Array3::from_shape_vec((k, n, 3), values).map_err(|e| value_error(e.to_string()))?;
    Ok(a.into_pyarray(py).into_any())
}

/// An RGB image from an `H x W x 3` (RGB) or `H x W x 4` (RGBA: alpha dropped) uint8 array, or
/// anything `numpy.asarray` makes one of (a PIL image); the pixel values are used as they are.
pub fn numpy_to_rgb(obj: &Bound<'_, PyAny>) -> PyResult<image::RgbImage> {
    let np = obj.py().import("numpy")?;
    let arr = np.call_method1("asarray", (obj,))?;
    let dtype = arr.getattr("dtype")?.str()?.to_string();
    let shape: Vec<usize> = arr.getattr("shape")?.extract()?;
    let expect = "expected an H x W x 3 (RGB) or H x W x 4 (RGBA) array of uint8, as gpmm.load_image gives";
    if dtype != "uint8" {
        return Err(value_error(format!("image has dtype {dtype}; {expect} (scale floats in [0, 1] by 255 and round)")));
    }
    let (h, w, c) = match shape[..] {
        [h, w, c] if (c == 3 || c == 4) && h > 0 && w > 0 => (h, w, c),
        _ => return Err(value_error(format!("image has shape {}; {expect}", shape_text(&shape)))),
    };
    let arr: PyReadonlyArray3<'_, u8> = arr.extract()?;
    let a = arr.as_array();
    let raw: Vec<u8> = if c == 3 { a.iter().copied().collect() } else { a.slice(s![.., .., ..3]).iter().copied().collect() };
    let too_large = || value_error(format!("image has shape {}: too large", shape_text(&shape)));
    let (w, h) = (u32::try_from(w).map_err(|_| too_large())?, u32::try_from(h).map_err(|_| too_large())?);
    image::RgbImage::from_raw(w, h, raw).ok_or_else(too_large)
}

/// Points from an `L x 2` array of numbers of any dtype (converted to float32).
pub fn numpy_to_points(py: Python<'_>, obj: &Bound<'_, PyAny>) -> PyResult<Vec<[f32; 2]>> {
    let np = py.import("numpy")?;
    let conv = np
        .call_method1("ascontiguousarray", (obj, "float32"))
        .map_err(|_| value_error("landmarks must be an L x 2 array of pixel coordinates"))?;
    let shape: Vec<usize> = conv.getattr("shape")?.extract()?;
    if shape.len() != 2 || shape[1] != 2 {
        return Err(value_error(format!("landmarks have shape {}; expected (L, 2) pixel coordinates", shape_text(&shape))));
    }
    let arr: PyReadonlyArray2<'_, f32> = conv.extract()?;
    Ok(arr.as_array().rows().into_iter().map(|r| [r[0], r[1]]).collect())
}

/// A shape as numpy prints it: `(20, 10, 3)`, `(5,)`.
pub(crate) fn shape_text(shape: &[usize]) -> String {
    match shape {
        [one] => format!("({one},)"),
        _ => format!("({})", shape.iter().map(usize::to_string).collect::<Vec<_>>().join(", ")),
    }
}

/// A serializable value as Python objects (dicts, lists, numbers) through its JSON text, so that
/// floats are the ones the `gpmm` program writes (an f32 reads back as the program's decimal).
pub(crate) fn json_to_py<'py, T: serde::Serialize + ?Sized>(py: Python<'py>, value: &T) -> PyResult<Bound<'py, PyAny>> {
    let text = serde_json::to_string(value).map_err(err)?;
    py.import("json")?.call_method1("loads", (text,))
}
