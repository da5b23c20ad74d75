//! `gpmm.learn`'s native half: the learning loop of `gpmm learn` (`learn_run`), its wake phase on
//! this process's threads or handed back to Python (a Dask cluster), and one view's fit for a
//! worker (`learn_wake`).

use crate::args::{fit_settings_error, opt, FitKeywords, Int};
use crate::arrays::{json_to_py, vec3_to_numpy};
use crate::errors::{io_error, read_error, value_error};
use crate::model::Model;
use gpmm_host::fit::FitFlags;
use gpmm_host::learn::dev::{DevPoints, DevSet};
use gpmm_host::learn::run::{image_files, local_wake, run_with, Hooks, RunError, RunEvent, RunPlan, WakeJob};
use gpmm_host::learn::shading::{ShadingBases, ShadingModel, ShadingSettings};
use gpmm_host::learn::{albedo_change_limit, views, wake_image, ImageRecord, LearnSettings, Wake, DEFAULT_KEEP_VARIANCE, MIN_IOU};
use gpmm_host::mesh::Mesh;
use numpy::PyReadonlyArray2;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList, PyTuple};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

/// How many times this process prepared shape from shading's bases.
static SHADING_PREPARED: AtomicUsize = AtomicUsize::new(0);

/// How many times this process prepared shape from shading's bases for `learn_wake` (once per
/// model object and settings: a worker's count).
#[pyfunction]
pub fn learn_shading_preparations() -> usize {
    SHADING_PREPARED.load(Ordering::Relaxed)
}

/// Fits one view of a learning iteration (the image, or its mirror image with `mirrored`) as
/// `gpmm learn` does: `(record, positions, colors)`, the record as JSON text and the accepted
/// reconstruction's vertex positions and colours (`N x 3` float64), `None` when it was not
/// accepted. `settings_json`: the iteration's settings as the loop gives them to its wake phase.
/// Shape from shading's bases are prepared once per model object and settings.
#[pyfunction]
#[pyo3(signature = (model, init, image, mirrored, settings_json))]
#[allow(clippy::type_complexity)]
pub fn learn_wake<'py>(
    py: Python<'py>,
    model: &Model,
    init: Option<&[u8]>,
    image: PathBuf,
    mirrored: bool,
    settings_json: &str,
) -> PyResult<(String, Option<Bound<'py, PyAny>>, Option<Bound<'py, PyAny>>)> {
    let settings: LearnSettings =
        serde_json::from_str(settings_json).map_err(|e| value_error(format!("settings_json: not the settings of a learning run: {e}")))?;
    let m = model.host().clone();
    let init = init.map(<[u8]>::to_vec);
    let wake = py.detach(|| -> Result<Wake, String> {
        let ranks = settings.fit.core().ranks;
        let Some(sfs) = &settings.shading else { return Ok(wake_image(&m, None, init.as_deref(), &image, mirrored, &settings)) };
        let key = serde_json::to_string(&(ranks.shape, ranks.color, sfs)).map_err(|e| e.to_string())?;
        // A model whose bases cannot be prepared fails every image alike, as on the local threads.
        let prepare = |m: &_| {
            SHADING_PREPARED.fetch_add(1, Ordering::Relaxed);
            ShadingBases::new(m, ranks.shape, ranks.color, sfs)
        };
        let bases = match model.shading_bases(&key, prepare) {
            Ok(bases) => bases,
            Err(e) => return Err(format!("shape from shading: {e}")),
        };
        let sm = ShadingModel::with_bases(&m, &bases).ok_or("shape from shading: bases of another model")?;
        Ok(wake_image(&m, Some(&sm), init.as_deref(), &image, mirrored, &settings))
    });
    let wake = wake.unwrap_or_else(|reason| Wake::failed(&image, mirrored, reason));
    let record = serde_json::to_string(&wake.record).map_err(|e| value_error(e.to_string()))?;
    match &wake.reconstruction {
        Some(mesh) => Ok((record, Some(vec3_to_numpy(py, &mesh.positions)?), Some(vec3_to_numpy(py, &mesh.colors)?))),
        None => Ok((record, None, None)),
    }
}

/// Runs `gpmm learn`'s loop (same settings, same outputs in `output`): `model_N.gpmm` and
/// `iteration_N/` per iteration, resumable. `wake_all`: `None` fits each iteration's views on this
/// process's threads (`jobs`, default all cores); else a callable
/// `wake_all(iteration, model_path, init, settings_json, views)` that returns, for each
/// `(image, mirrored)` of `views` in order, what `learn_wake` returns for it or a string saying
/// why it could not be fitted. `progress`: called with a dict per event. Returns `kept` (the
/// model to use), `best` (with `dev`: `output/model.gpmm`, its copy), `model` (the last one
/// written, `None` if no iteration ran) and `iterations` (each iteration's records.json as a dict).
#[pyfunction]
#[pyo3(signature = (model, images, output, *, init = None, landmarks_dir = None, learn_landmarks = false, iterations = Int::of(5), mirror = false,
    min_iou = None, init_landmark_sigma = None, shape_from_shading = false, keep_variance = None, dev = None,
    dev_landmarks_dir = None, dev_identities = None, dev_max_identity_drop = None, data = None, jobs = None, wake_all = None, progress = None,
    seed = None, size = None, landmark_steps = None, image_steps = None, shape_rank = None, color_rank = None,
    landmark_sigma = None, contour_sigma = None, set = None),
    text_signature = "(model, images, output, *, init=None, landmarks_dir=None, learn_landmarks=False, iterations=5, mirror=False, \
    min_iou=None, init_landmark_sigma=None, shape_from_shading=False, keep_variance=None, dev=None, dev_landmarks_dir=None, \
    dev_identities=None, dev_max_identity_drop=None, data=None, jobs=None, wake_all=None, progress=None, seed=None, size=None, \
    landmark_steps=None, image_steps=None, shape_rank=None, color_rank=None, landmark_sigma=None, contour_sigma=None, set=None)")]
#[allow(clippy::too_many_arguments)]
pub fn learn_run<'py>(
    py: Python<'py>,
    model: PathBuf,
    images: Vec<PathBuf>,
    output: PathBuf,
    init: Option<PathBuf>,
    landmarks_dir: Option<PathBuf>,
    learn_landmarks: bool,
    iterations: Int,
    mirror: bool,
    min_iou: Option<f64>,
    init_landmark_sigma: Option<f32>,
    shape_from_shading: bool,
    keep_variance: Option<f64>,
    dev: Option<PathBuf>,
    dev_landmarks_dir: Option<PathBuf>,
    dev_identities: Option<Int>,
    dev_max_identity_drop: Option<f64>,
    data: Option<PathBuf>,
    jobs: Option<Int>,
    wake_all: Option<Py<PyAny>>,
    progress: Option<Py<PyAny>>,
    seed: Option<Int>,
    size: Option<Int>,
    landmark_steps: Option<Int>,
    image_steps: Option<Int>,
    shape_rank: Option<Int>,
    color_rank: Option<Int>,
    landmark_sigma: Option<f32>,
    contour_sigma: Option<f32>,
    set: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    let min_iou = min_iou.unwrap_or(MIN_IOU);
    if !(min_iou.is_finite() && (0.0..=1.0).contains(&min_iou)) {
        return Err(value_error(format!("min_iou = {min_iou}: an overlap is between 0 and 1")));
    }
    let keep_variance = keep_variance.unwrap_or(DEFAULT_KEEP_VARIANCE);
    if !(keep_variance.is_finite() && keep_variance >= 0.0) {
        return Err(value_error(format!("keep_variance = {keep_variance}: a share of a covariance is 0 or more")));
    }
    let iterations: u32 = iterations.get("iterations")?;
    if !(1..=100).contains(&iterations) {
        return Err(value_error(format!("iterations = {iterations}: between 1 and 100")));
    }
    if init.is_none() && landmarks_dir.is_none() {
        return Err(value_error("init (an init file) or landmarks_dir is needed: the fits start from one of them"));
    }
    if learn_landmarks && landmarks_dir.is_none() {
        return Err(value_error("learn_landmarks needs landmarks_dir: the landmarks are learned from its points"));
    }
    // The initializer's points are fitted as `gpmm fit --init` fits them; landmark files as
    // `gpmm fit --landmarks` does.
    let keywords = FitKeywords { seed, size, landmark_steps, image_steps, shape_rank, color_rank, landmark_sigma, contour_sigma, set };
    let flags = FitFlags {
        initializer_sigma: landmarks_dir.is_none().then_some(init_landmark_sigma.unwrap_or(gpmm_host::detect::INIT_LANDMARK_SIGMA)),
        ..keywords.flags(None)?
    };
    let (fit, dev_fit) = gpmm_host::learn::loop_and_check_options(&flags).map_err(fit_settings_error)?;
    let images = image_files(&images).map_err(|e| run_error(e, &model))?;
    let jobs = match opt::<usize>(&jobs, "jobs")? {
        Some(j) => j.max(1),
        None => std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
    };
    let plan = RunPlan {
        model: model.clone(),
        init: if landmarks_dir.is_some() { None } else { init.clone() },
        images,
        out: output.clone(),
        iterations,
        settings: LearnSettings {
            fit,
            min_iou,
            mirror,
            shading: shape_from_shading.then_some(ShadingSettings::DEFAULT),
            max_albedo_change: albedo_change_limit(0),
            landmarks_dir: landmarks_dir.clone(),
            keep_variance,
            learn_landmarks,
        },
        dev_fit,
        jobs,
    };
    let dev_identities = opt::<usize>(&dev_identities, "dev_identities")?;
    let max_rank1_drop = match dev_max_identity_drop {
        Some(d) if (0.0..=100.0).contains(&d) => d / 100.0,
        Some(d) => return Err(value_error(format!("dev_max_identity_drop = {d}: percentage points from 0 to 100"))),
        None => gpmm_host::learn::dev::DEFAULT_MAX_RANK1_DROP,
    };
    // Python errors of the callbacks, raised again as they were once the loop has stopped.
    let raised: Mutex<Option<PyErr>> = Mutex::new(None);
    let keep = |e: PyErr| {
        let mut r = raised.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        let text = e.to_string();
        r.get_or_insert(e);
        text
    };
    let outcome = py.detach(|| -> PyResult<_> {
        let mut dev_set = match &dev {
            Some(dir) => {
                let data = data.clone().unwrap_or_else(gpmm_host::data::default_data_dir);
                let work = output.join("development");
                let bytes = match (&landmarks_dir, &init) {
                    (None, Some(init)) => Some(std::fs::read(init).map_err(|e| io_error(format!("{}: {e}", init.display()), &e, init))?),
                    _ => None,
                };
                let points = DevPoints::like_the_loop(landmarks_dir.as_deref(), dev_landmarks_dir.as_deref(), bytes.as_deref())
                    .map_err(|e| value_error(format!("dev: {e} (dev_landmarks_dir)")))?;
                let prepared = DevSet::prepare(dir, dev_identities, &data, points, &work);
                let prepared = prepared.map_err(|e| read_error(format!("development set: {e}"), &[dir.as_path(), data.as_path()]))?;
                Some(prepared.with_max_rank1_drop(max_rank1_drop))
            }
            None => None,
        };
        let events = |e: RunEvent<'_>| {
            let Some(callback) = &progress else { return };
            Python::attach(|py| {
                if let Err(e) = event_dict(py, &e).and_then(|d| callback.call1(py, (d,))) {
                    keep(e);
                }
            });
        };
        let local = local_wake(&plan, &events);
        let remote = |job: WakeJob<'_>| -> Result<Vec<Wake>, RunError> {
            let Some(callback) = &wake_all else { return local(job) };
            let views = views(&plan.images, job.settings.mirror);
            Python::attach(|py| remote_wake(py, callback, &job, &views))
                .map_err(|e| RunError::Hook { iteration: job.iteration, error: keep(e) })
        };
        let outcome = run_with(&plan, dev_set.as_mut(), &Hooks { wake_all: &remote, retrain: None, events: &events })
            .map_err(|e| run_error(e, &model))?;
        // With a development set, `output/model.gpmm` is the best model, as the program leaves it.
        let best = match &dev_set {
            Some(_) => Some(outcome.copy_kept(&output).map_err(|e| run_error(e, &model))?),
            None => None,
        };
        Ok((outcome, best))
    });
    if let Some(e) = raised.lock().unwrap_or_else(std::sync::PoisonError::into_inner).take() {
        return Err(e);
    }
    let (outcome, best) = outcome?;
    let out = PyDict::new(py);
    out.set_item("kept", outcome.kept.display().to_string())?;
    out.set_item("best", best.map(|p| p.display().to_string()))?;
    out.set_item("model", outcome.iterations.last().map(|f| f.model.clone()))?;
    out.set_item("iterations", json_to_py(py, &outcome.iterations)?)?;
    Ok(out.into_any())
}

/// One iteration's views fitted by the Python callable `callback` (a cluster's): each result
/// becomes the view's [`Wake`], a string the record of a view that could not be fitted.
fn remote_wake(py: Python<'_>, callback: &Py<PyAny>, job: &WakeJob<'_>, views: &[(&PathBuf, bool)]) -> PyResult<Vec<Wake>> {
    let settings = serde_json::to_string(job.settings).map_err(|e| value_error(e.to_string()))?;
    let list = PyList::empty(py);
    for (image, mirrored) in views {
        list.append((image.display().to_string(), *mirrored))?;
    }
    let init = job.init.map(|b| PyBytes::new(py, b));
    let results = callback.call1(py, (job.iteration, job.model_path.display().to_string(), init, settings, list))?;
    let results: Vec<Bound<'_, PyAny>> = results.bind(py).extract()?;
    if results.len() != views.len() {
        return Err(value_error(format!("wake_all returned {} results for {} views", results.len(), views.len())));
    }
    let vertices = job.model.shape.mean.len();
    views
        .iter()
        .zip(results)
        .map(|((image, mirrored), r)| {
            if let Ok(reason) = r.extract::<String>() {
                return Ok(Wake::failed(image, *mirrored, reason));
            }
            let t = r
                .cast::<PyTuple>()
                .map_err(|_| value_error(format!("{}: wake_all's result is neither learn_wake's nor a string", image.display())))?;
            let (text, positions, colors): (String, Option<Bound<'_, PyAny>>, Option<Bound<'_, PyAny>>) = t.extract()?;
            let record: ImageRecord =
                serde_json::from_str(&text).map_err(|e| value_error(format!("{}: not a learning record: {e}", image.display())))?;
            let reconstruction = match (positions, colors) {
                (Some(p), Some(c)) => Some(Mesh {
                    positions: rows(&p, vertices, image, "positions")?,
                    colors: rows(&c, vertices, image, "colors")?,
                    triangles: job.model.triangles.clone(),
                }),
                _ => None,
            };
            Ok(Wake { record, reconstruction })
        })
        .collect()
}

/// The `vertices x 3` rows of a returned array (one a cluster sent may be unaligned: copied then).
fn rows(a: &Bound<'_, PyAny>, vertices: usize, image: &Path, name: &str) -> PyResult<Vec<[f64; 3]>> {
    let np = a.py().import("numpy")?;
    let a = np.call_method1("require", (a, "float64", ["C", "A"]))?;
    let a: PyReadonlyArray2<'_, f64> =
        a.extract().map_err(|_| value_error(format!("{}: {name} is not an N x 3 array of numbers", image.display())))?;
    let a = a.as_array();
    if a.shape() != [vertices, 3] {
        return Err(value_error(format!("{}: {name} has shape {:?}; the model has {vertices} vertices", image.display(), a.shape())));
    }
    Ok(a.rows().into_iter().map(|r| [r[0], r[1], r[2]]).collect())
}

/// A progress event as a dict: `event` ("reused", "fitting", "checking", "finished") and its figures.
fn event_dict<'py>(py: Python<'py>, e: &RunEvent<'_>) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    match e {
        RunEvent::Reused(f) | RunEvent::Finished(f) => {
            d.set_item("event", if matches!(e, RunEvent::Reused(_)) { "reused" } else { "finished" })?;
            d.set_item("iteration", f.iteration)?;
            for (k, v) in [("images", f.images), ("accepted", f.accepted), ("rejected_overlap", f.rejected_overlap)] {
                d.set_item(k, v)?;
            }
            for (k, v) in [("rejected_albedo", f.rejected_albedo), ("failed", f.failed)] {
                d.set_item(k, v)?;
            }
            d.set_item("model", &f.model)?;
        }
        RunEvent::Fitting { iteration, done, total } => {
            d.set_item("event", "fitting")?;
            d.set_item("iteration", iteration)?;
            d.set_item("done", done)?;
            d.set_item("total", total)?;
        }
        RunEvent::Checking { iteration, model, done, total } => {
            d.set_item("event", "checking")?;
            d.set_item("iteration", iteration)?;
            d.set_item("model", model.display().to_string())?;
            d.set_item("done", done)?;
            d.set_item("total", total)?;
        }
    }
    Ok(d)
}

/// A run's error as the package raises it: a file that cannot be read or written as an OS error
/// naming it, anything else as a `GpmmValueError`; `model`: the start model.
fn run_error(e: RunError, model: &Path) -> PyErr {
    let message = e.to_string();
    match &e {
        RunError::Io { path, error } => io_error(message, error, path),
        RunError::Input { path, .. } if !path.exists() => io_error(message, &std::io::Error::from(std::io::ErrorKind::NotFound), path),
        RunError::Model(_) => read_error(message, &[model]),
        _ => value_error(message),
    }
}
