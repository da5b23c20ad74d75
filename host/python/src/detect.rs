//! `gpmm.detect`: every face an init file's finder and initializer find in an image, as
//! `gpmm detect` lists them.

use crate::arrays::{json_to_py, numpy_to_rgb, points_to_numpy};
use crate::errors::{err, read_error};
use gpmm_core::net::face::{Detection, Reading};
use gpmm_host::detect::record::FaceRecord;
use gpmm_host::detect::{shipped, CheckedFaces, Detector, DEFAULT_SMALLEST_FACE};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::path::{Path, PathBuf};

/// Every face in an image (`H x W x 3` uint8) that the init file (default: the start gpmm ships,
/// trained on real photos) finds and its face check keeps, best first, as `gpmm detect` lists them:
/// dicts with 'box' (cx, cy, size, score), 'yaw_deg', 'pitch_deg', 'roll_deg' and 'landmarks' (an
/// `L x 2` float32 array, image pixels). An empty list when there is none. `min_score`: default
/// 0.9 for a file trained on real photos (with a face check, as the shipped start), else 0.05.
#[pyfunction]
#[pyo3(signature = (image, init = None, min_score = None, smallest_face = DEFAULT_SMALLEST_FACE, refine = gpmm_core::net::face::DEFAULT_REFINE, face_check = true),
    text_signature = "(image, init=None, min_score=None, smallest_face=32.0, refine=3, face_check=True)")]
pub(crate) fn detect<'py>(
    py: Python<'py>,
    image: &Bound<'py, PyAny>,
    init: Option<PathBuf>,
    min_score: Option<f32>,
    smallest_face: f32,
    refine: usize,
    face_check: bool,
) -> PyResult<Bound<'py, PyList>> {
    let photo = numpy_to_rgb(image)?;
    let mut detector = open_init(init.as_deref())?;
    let min_score = min_score.unwrap_or(detector.advised_min_score());
    if !face_check {
        detector.set_check(None);
    }
    let reading = Reading { refine, mirror: true };
    let CheckedFaces { kept, .. } = py.detach(move || detector.scan_split(&photo, min_score, smallest_face, reading)).map_err(err)?;
    let faces = PyList::empty(py);
    for det in &kept {
        faces.append(face_dict(py, det)?)?;
    }
    Ok(faces)
}

/// The init file at `init`, or the shipped start; a Python error naming the file otherwise.
pub(crate) fn open_init(init: Option<&Path>) -> PyResult<Detector> {
    shipped::open(init).map_err(|e| match init {
        Some(path) => read_error(e, &[path]),
        None => err(e),
    })
}

/// A face record as a dict (`gpmm detect`'s fields) with its landmarks as an `L x 2` array.
pub(crate) fn face_dict<'py>(py: Python<'py>, det: &gpmm_core::net::face::Detection) -> PyResult<Bound<'py, PyAny>> {
    let face = json_to_py(py, &FaceRecord::from(det))?;
    let dict = face.cast::<PyDict>().map_err(|_| crate::errors::value_error("a face record is not a dict"))?;
    dict.set_item("landmarks", points_to_numpy(py, &det.landmarks)?)?;
    Ok(face)
}

/// The face a fit without landmarks takes from `photo` (`Model.fit(image)`): the init file's
/// (the shipped start's) faces as `gpmm fit` takes them, the largest or the `face`-th; an error
/// when there is none.
pub(crate) fn face_for_fit(py: Python<'_>, photo: &image::RgbImage, init: Option<&Path>, face: Option<usize>) -> PyResult<Detection> {
    let mut detector = open_init(init)?;
    let photo = photo.clone();
    let mut found = py.detach(move || gpmm_host::detect::for_fit::faces_for_fit(&mut detector, &photo, None, false)).map_err(err)?;
    let name = shipped::init_name(init);
    if found.faces.is_empty() {
        return Err(crate::errors::value_error(format!("no face found by {name} (finder score below {})", found.min_score)));
    }
    let chosen = gpmm_host::detect::choose_face(&found.faces, face).ok_or_else(|| {
        crate::errors::value_error(format!("face={} asked for, but {} faces were found", face.unwrap_or(0), found.faces.len()))
    })?;
    Ok(found.faces.swap_remove(chosen))
}
