//! `gpmm._gpmm`: the native half of the gpmm Python package, a thin layer over the gpmm-host
//! library (the code the `gpmm` program runs): models and their arrays, building from a template,
//! sampling, rendering, fitting, quantization, blobs, statismo `.h5` files and learning models from
//! images.
//!
//! Long work runs with the GIL released; every error is a `gpmm.GpmmError` carrying the message
//! the `gpmm` program prints for the same failure (see `errors`).

mod args;
mod arrays;
mod detect;
mod errors;
mod from_arrays;
mod learn;
mod model;

use args::{opt, Int};
use arrays::json_to_py;
use errors::{err, read_error, value_error};
use gpmm_host::device::quantize::BlobBuf;
use gpmm_host::gp::kernel::{Hyperparameters, ModelKernel};
use gpmm_host::gp::lowrank::{NystromOptions, RankSpec};
use gpmm_host::gp::model::{build_model, BuildOptions};
use gpmm_host::gp::statismo::{self, ImportOptions};
use gpmm_host::mesh::template::{load_template, TemplateOptions};
use model::Model;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::{Path, PathBuf};

/// Loads a model file (`.gpmm`, safetensors).
#[pyfunction]
fn load(py: Python<'_>, path: PathBuf) -> PyResult<Model> {
    Model::load(py, path)
}

/// A model from the bytes of a model file (what `Model.to_bytes()` and pickling give).
#[pyfunction]
fn model_from_bytes(py: Python<'_>, data: &[u8]) -> PyResult<Model> {
    Model::from_bytes(py, data)
}

/// The nine kernel names `build` takes.
#[pyfunction]
fn kernels() -> Vec<&'static str> {
    ModelKernel::ALL.iter().map(|k| k.name()).collect()
}

/// Builds a model from a template scan, as `gpmm build` does (same options, same defaults).
#[pyfunction]
#[pyo3(signature = (template, landmarks, kernel = "symmetric-full", rank_shape = None, rank_color = None,
    captured_shape = None, captured_color = None, vertices = None, scale = None, no_crop = false,
    texture = None, config = None, default_color = None, nystrom_points = Int::of(2000), seed = None),
    text_signature = "(template, landmarks, kernel='symmetric-full', rank_shape=None, rank_color=None, captured_shape=None, \
    captured_color=None, vertices=None, scale=None, no_crop=False, texture=None, config=None, default_color=None, \
    nystrom_points=2000, seed=None)")]
#[allow(clippy::too_many_arguments)]
fn build(
    py: Python<'_>,
    template: PathBuf,
    landmarks: PathBuf,
    kernel: &str,
    rank_shape: Option<Int>,
    rank_color: Option<Int>,
    captured_shape: Option<f64>,
    captured_color: Option<f64>,
    vertices: Option<Int>,
    scale: Option<f64>,
    no_crop: bool,
    texture: Option<PathBuf>,
    config: Option<PathBuf>,
    default_color: Option<[f64; 3]>,
    nystrom_points: Int,
    seed: Option<Int>,
) -> PyResult<Model> {
    let kernel: ModelKernel = kernel.parse().map_err(err)?;
    let hyperparameters = match &config {
        Some(p) => Hyperparameters::from_toml_file(p).map_err(|e| read_error(e, &[p]))?,
        None => Hyperparameters::default(),
    };
    let opts = BuildOptions {
        kernel,
        hyperparameters,
        rank_shape: RankSpec::from_flags(opt(&rank_shape, "rank_shape")?, captured_shape, "shape").map_err(err)?,
        rank_color: RankSpec::from_flags(opt(&rank_color, "rank_color")?, captured_color, "color").map_err(err)?,
        nystrom: NystromOptions {
            points: nystrom_points.get::<usize>("nystrom_points")?.max(1),
            seed: opt(&seed, "seed")?.unwrap_or(NystromOptions::default().seed),
            ..Default::default()
        },
    };
    let vertices = opt(&vertices, "vertices")?;
    let read: Vec<PathBuf> = [Some(&template), Some(&landmarks), texture.as_ref()].into_iter().flatten().cloned().collect();
    let topts = TemplateOptions { texture, scale, no_crop, vertices, default_color };
    let model = py
        .detach(|| -> Result<_, gpmm_host::mesh::template::TemplateError> {
            let t = load_template(&template, &landmarks, &topts)?;
            Ok(build_model(&t, &opts, |_, _, _| {}))
        })
        .map_err(|e| read_error(e, &read.iter().map(PathBuf::as_path).collect::<Vec<_>>()))?;
    Ok(Model::new(model, "<built>".into()))
}

/// Imports a statismo / scalismo `.h5` model (as `gpmm import-h5`): the model and a dict of what was found.
#[pyfunction]
#[pyo3(signature = (path, scale = None, landmarks = None))]
fn import_h5<'py>(py: Python<'py>, path: PathBuf, scale: Option<f64>, landmarks: Option<PathBuf>) -> PyResult<(Model, Bound<'py, PyAny>)> {
    let name = path.display().to_string();
    let read: Vec<&Path> = [Some(path.as_path()), landmarks.as_deref()].into_iter().flatten().collect();
    let (model, report) = py
        .detach(|| -> Result<_, String> {
            let landmarks = landmarks.as_deref().map(gpmm_host::mesh::io::read_landmarks_json).transpose().map_err(|e| e.to_string())?;
            statismo::import(&path, &ImportOptions { scale, landmarks }).map_err(|e| e.to_string())
        })
        .map_err(|e| read_error(e, &read))?;
    let report = json_to_py(py, &report)?;
    Ok((Model::new(model, name), report))
}

/// Validates a model blob with the device's parser: its header and metadata as a dict; raises
/// (with the parser's message) if it is invalid, unless `strict=False` (then `error` says why).
#[pyfunction]
#[pyo3(signature = (blob, strict = true))]
fn inspect<'py>(py: Python<'py>, blob: &[u8], strict: bool) -> PyResult<Bound<'py, PyAny>> {
    let buf = BlobBuf::from_bytes(blob);
    let (json, result) = gpmm_host::device::quantize::inspect(&buf);
    if let (true, Err(e)) = (strict, &result) {
        return Err(value_error(format!("not a valid model blob: {e}")));
    }
    let d = json_to_py(py, &json)?;
    if let Ok(dict) = d.cast::<PyDict>() {
        dict.set_item("error", result.err().map(|e| e.to_string()))?;
    }
    Ok(d)
}

/// Loads a photo (PNG, JPEG or PPM) as an `H x W x 3` uint8 array, as `gpmm fit` reads it (an alpha
/// channel is dropped; the values are used as they are).
#[pyfunction]
fn load_image<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyAny>> {
    let img = py.detach(|| gpmm_host::photo::load_rgb(&path)).map_err(|e| read_error(e, &[&path]))?;
    arrays::rgb_to_numpy(py, &img)
}

/// Reads an iBUG `.pts` landmark file as an `L x 2` float32 array (0-based pixel coordinates).
#[pyfunction]
#[pyo3(signature = (path, one_based = false))]
fn read_pts<'py>(py: Python<'py>, path: PathBuf, one_based: bool) -> PyResult<Bound<'py, PyAny>> {
    let pts = gpmm_host::photo::pts::read_pts(&path, one_based).map_err(|e| read_error(e, &[&path]))?;
    arrays::points_to_numpy(py, &pts.points)
}

/// The data directory (template scan, photos): `$GPMM_DATA` if set, else `../shared/data` beside the
/// current directory or the source checkout; a `FileNotFoundError` if it does not exist.
#[pyfunction]
fn data_dir(py: Python<'_>) -> PyResult<Bound<'_, PyAny>> {
    let dir = gpmm_host::data::default_data_dir();
    if !dir.is_dir() {
        let message = format!("{}: the gpmm data directory does not exist (set GPMM_DATA to it)", dir.display());
        return Err(read_error(message, &[&dir]));
    }
    py.import("pathlib")?.getattr("Path")?.call1((dir,))
}

/// The native module.
#[pymodule]
fn _gpmm(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("LIGHT_PRESETS", gpmm_host::render::light::LIGHT_PRESETS.to_vec())?;
    m.add_class::<Model>()?;
    m.add_function(wrap_pyfunction!(load, m)?)?;
    m.add_function(wrap_pyfunction!(model_from_bytes, m)?)?;
    m.add_function(wrap_pyfunction!(kernels, m)?)?;
    m.add_function(wrap_pyfunction!(build, m)?)?;
    m.add_function(wrap_pyfunction!(import_h5, m)?)?;
    m.add_function(wrap_pyfunction!(inspect, m)?)?;
    m.add_function(wrap_pyfunction!(load_image, m)?)?;
    m.add_function(wrap_pyfunction!(read_pts, m)?)?;
    m.add_function(wrap_pyfunction!(detect::detect, m)?)?;
    m.add_function(wrap_pyfunction!(data_dir, m)?)?;
    m.add_function(wrap_pyfunction!(learn::learn_wake, m)?)?;
    m.add_function(wrap_pyfunction!(learn::learn_run, m)?)?;
    m.add_function(wrap_pyfunction!(learn::learn_shading_preparations, m)?)?;
    Ok(())
}
