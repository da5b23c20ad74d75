//! `gpmm.detect`: every face an init file's finder and initializer find in an image, as
//! `gpmm detect` lists them.

use crate::arrays::{json_to_py, numpy_to_rgb, points_to_numpy};
use crate::errors::{err, read_error};
use gpmm_core::net::face::Reading;
use gpmm_host::detect::record::FaceRecord;
use gpmm_host::detect::{CheckedFaces, Detector, DEFAULT_MIN_SCORE, DEFAULT_SMALLEST_FACE};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::path::PathBuf;

/// Every face in an image (`H x W x 3` uint8) that the init file finds and its face check keeps,
/// best first, as `gpmm detect` lists them: dicts with 'box' (cx, cy, size, score), 'yaw_deg',
/// 'pitch_deg', 'roll_deg' and 'landmarks' (an `L x 2` float32 array, image pixels). An empty
/// list when there is none.
#[pyfunction]
#[pyo3(signature = (image, init, min_score = DEFAULT_MIN_SCORE, smallest_face = DEFAULT_SMALLEST_FACE, refine = gpmm_core::net::face::DEFAULT_REFINE, face_check = true),
    text_signature = "(image, init, min_score=0.05, smallest_face=32.0, refine=3, face_check=True)")]
pub(crate) fn detect<'py>(
    py: Python<'py>,
    image: &Bound<'py, PyAny>,
    init: PathBuf,
    min_score: f32,
    smallest_face: f32,
    refine: usize,
    face_check: bool,
) -> PyResult<Bound<'py, PyList>> {
    let photo = numpy_to_rgb(image)?;
    let mut detector = Detector::load(&init).map_err(|e| read_error(e, &[&init]))?;
    if !face_check {
        detector.set_check(None);
    }
    let reading = Reading { refine, mirror: true };
    let CheckedFaces { kept, .. } = py.detach(move || detector.scan_split(&photo, min_score, smallest_face, reading)).map_err(err)?;
    let faces = PyList::empty(py);
    for det in &kept {
        let record = FaceRecord::from(det);
        let face = json_to_py(py, &record)?;
        let dict = face.cast::<PyDict>().map_err(|_| crate::errors::value_error("a face record is not a dict"))?;
        dict.set_item("landmarks", points_to_numpy(py, &det.landmarks)?)?;
        faces.append(face)?;
    }
    Ok(faces)
}
