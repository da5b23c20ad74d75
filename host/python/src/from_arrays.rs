//! `gpmm.Model.from_arrays`: a model from numpy arrays (a PCA of one's own, a model from another
//! tool), every array checked with an error that names it.

use crate::arrays::shape_text;
use crate::errors::value_error;
use gpmm_host::gp::model::{GpModel, ModelMetadata, ModelPart, PartBasis};
use gpmm_host::gp::model_io;
use gpmm_host::mesh::template::Provenance;
use pyo3::prelude::*;

/// How far a basis component's squared norm may be from its eigenvalue (relative).
const EIGENVALUE_TOLERANCE: f64 = 1e-3;
/// How far a factored direction's length may be from 1.
const DIRECTION_TOLERANCE: f32 = 1e-3;
/// The albedo of a model given without colours (linear RGB).
const DEFAULT_ALBEDO: f32 = 0.5;

/// One part's arrays as given (`None` = not given).
pub(crate) struct PartArrays<'py> {
    /// `mean`: `N x 3`.
    pub mean: Option<Bound<'py, PyAny>>,
    /// `basis`: `K x N x 3`, scaled by sqrt(eigenvalue).
    pub basis: Option<Bound<'py, PyAny>>,
    /// `eigenvalues`: `K`.
    pub eigenvalues: Option<Bound<'py, PyAny>>,
    /// `directions`: `K x 3` unit vectors of a factored basis.
    pub directions: Option<Bound<'py, PyAny>>,
    /// `fields`: `K x N` scaled scalar fields of a factored basis.
    pub fields: Option<Bound<'py, PyAny>>,
}

/// An array's values with its shape checked against `want` (`None` = any size; the first such
/// size is returned), every value finite. `what` says what the dimensions are, for the message.
fn floats<T: numpy::Element + Copy + Into<f64>>(
    obj: &Bound<'_, PyAny>,
    name: &str,
    dtype: &str,
    want: &[Option<usize>],
    what: &str,
) -> PyResult<(Vec<usize>, Vec<T>)> {
    let np = obj.py().import("numpy")?;
    let arr = np
        .call_method1("ascontiguousarray", (obj, dtype))
        .map_err(|e| value_error(format!("{name} must be an array of numbers ({what}): {e}")))?;
    let shape: Vec<usize> = arr.getattr("shape")?.extract()?;
    check_shape(name, &shape, want, what)?;
    let values: Vec<T> = arr.call_method0("ravel")?.extract::<numpy::PyReadonlyArray1<'_, T>>()?.as_slice()?.to_vec();
    if let Some(i) = values.iter().position(|v| !(*v).into().is_finite()) {
        return Err(value_error(format!("{name} has a non-finite value at flat index {i}")));
    }
    Ok((shape, values))
}

fn check_shape(name: &str, shape: &[usize], want: &[Option<usize>], what: &str) -> PyResult<()> {
    let ok = shape.len() == want.len() && shape.iter().zip(want).all(|(g, w)| w.is_none_or(|w| w == *g));
    if ok {
        Ok(())
    } else {
        Err(value_error(format!("{name} has shape {}; expected {what}", shape_text(shape))))
    }
}

/// Vertex ids (`triangles`, `landmarks`): integers in `0..n`.
fn vertex_ids(obj: &Bound<'_, PyAny>, name: &str, want: &[Option<usize>], what: &str, n: usize) -> PyResult<Vec<u32>> {
    let np = obj.py().import("numpy")?;
    let arr = np.call_method1("asarray", (obj,))?;
    let kind: String = arr.getattr("dtype")?.getattr("kind")?.extract()?;
    let shape: Vec<usize> = arr.getattr("shape")?.extract()?;
    // An empty list has dtype float64: nothing to check but the shape.
    if !(kind == "i" || kind == "u" || shape.contains(&0)) {
        return Err(value_error(format!("{name} must hold integer vertex ids, got dtype {}", arr.getattr("dtype")?.str()?)));
    }
    check_shape(name, &shape, want, what)?;
    let ids: Vec<i64> = arr.call_method1("astype", ("int64",))?.call_method0("ravel")?.call_method0("tolist")?.extract()?;
    if let Some(i) = ids.iter().position(|&v| v < 0 || v as u64 >= n as u64) {
        return Err(value_error(format!(
            "{name} refers to vertex {} (flat index {i}); shape_mean has {n} vertices (ids 0 to {})",
            ids[i],
            n.saturating_sub(1)
        )));
    }
    Ok(ids.into_iter().map(|v| v as u32).collect())
}

fn part(p: &PartArrays<'_>, prefix: &str, n: usize) -> PyResult<ModelPart> {
    let name = |s: &str| format!("{prefix}_{s}");
    let mean = match &p.mean {
        Some(m) => floats::<f32>(m, &name("mean"), "float32", &[Some(n), Some(3)], &format!("(N, 3) with N = {n}"))?.1,
        None => vec![DEFAULT_ALBEDO; n * 3],
    };
    let mean: Vec<[f32; 3]> = mean.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    let factored = p.directions.is_some() || p.fields.is_some();
    let (basis, norms) = match (&p.basis, factored) {
        (Some(_), true) => {
            return Err(value_error(format!("give either {} or {} + {}, not both", name("basis"), name("directions"), name("fields"))))
        }
        (Some(b), false) => {
            let (s, values) = floats::<f32>(b, &name("basis"), "float32", &[None, Some(n), Some(3)], &format!("(K, N, 3) with N = {n}"))?;
            let norms = values.chunks(n * 3).map(|c| c.iter().map(|&v| f64::from(v).powi(2)).sum()).collect::<Vec<f64>>();
            (PartBasis::Dense { values }, norms.into_iter().take(s[0]).collect())
        }
        (None, true) => {
            let (Some(d), Some(f)) = (&p.directions, &p.fields) else {
                return Err(value_error(format!("a factored basis needs both {} and {}", name("directions"), name("fields"))));
            };
            let (s, fields) = floats::<f32>(f, &name("fields"), "float32", &[None, Some(n)], &format!("(K, N) with N = {n}"))?;
            let k = s[0];
            let (_, dirs) = floats::<f32>(
                d,
                &name("directions"),
                "float32",
                &[Some(k), Some(3)],
                &format!("(K, 3) with K = {k} (the rows of {})", name("fields")),
            )?;
            let directions: Vec<[f32; 3]> = dirs.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
            if let Some(i) =
                directions.iter().position(|d| ((d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() - 1.0).abs() > DIRECTION_TOLERANCE)
            {
                return Err(value_error(format!("{}[{i}] = {:?} is not a unit vector", name("directions"), directions[i])));
            }
            let norms = fields.chunks(n.max(1)).take(k).map(|c| c.iter().map(|&v| f64::from(v).powi(2)).sum()).collect();
            (PartBasis::Factored { directions, fields }, norms)
        }
        (None, false) => (PartBasis::Dense { values: Vec::new() }, Vec::new()),
    };
    let k = norms.len();
    let basis_name = if factored { name("fields") } else { name("basis") };
    let eigenvalues = match &p.eigenvalues {
        None => norms,
        Some(e) => {
            let (_, ev) = floats::<f64>(
                e,
                &name("eigenvalues"),
                "float64",
                &[Some(k)],
                &format!("(K,) with K = {k} (the components of {basis_name})"),
            )?;
            for (i, (e, s)) in ev.iter().zip(&norms).enumerate() {
                if (e - s).abs() > EIGENVALUE_TOLERANCE * e.abs().max(*s) {
                    return Err(value_error(format!(
                        "{}[{i}] = {e} but component {i} of {basis_name} has squared norm {s}: the basis must be scaled by \
                         sqrt(eigenvalue), e.g. components * np.sqrt(eigenvalues)[:, None, None]",
                        name("eigenvalues")
                    )));
                }
            }
            ev
        }
    };
    if let Some(i) = eigenvalues.windows(2).position(|w| w[1] > w[0] * (1.0 + EIGENVALUE_TOLERANCE)) {
        return Err(value_error(format!(
            "the components of {basis_name} must be in descending order of eigenvalue; component {} ({}) is larger than {i} ({})",
            i + 1,
            eigenvalues[i + 1],
            eigenvalues[i]
        )));
    }
    Ok(ModelPart { mean, eigenvalues, basis })
}

/// The metadata of a model made from arrays, with the entries of `given` (a dict of
/// docs/model-format.md's fields) over the defaults.
fn metadata(given: Option<&Bound<'_, PyAny>>, shape: &ModelPart, color: &ModelPart, landmarks: usize) -> PyResult<ModelMetadata> {
    let n = shape.mean.len();
    let scheme = match landmarks {
        0 => "none",
        68 => "ibug68",
        _ => "custom",
    };
    let template = Provenance { source: "<arrays>".into(), scale_mm_per_unit: 1.0, source_vertices: n, ..Provenance::default() };
    let created_by = concat!("gpmm ", env!("CARGO_PKG_VERSION"), " python from_arrays").into();
    let defaults = ModelMetadata::pca(shape, color, scheme.into(), template, created_by);
    let Some(given) = given.filter(|g| !g.is_none()) else { return Ok(defaults) };
    let py = given.py();
    let text: String = py
        .import("json")?
        .call_method1("dumps", (given,))
        .and_then(|t| t.extract())
        .map_err(|e| value_error(format!("metadata must be a JSON-serializable dict: {e}")))?;
    let given: serde_json::Value = serde_json::from_str(&text).map_err(|e| value_error(format!("metadata: {e}")))?;
    let serde_json::Value::Object(given) = given else { return Err(value_error("metadata must be a dict")) };
    let mut merged = serde_json::to_value(&defaults).map_err(|e| value_error(format!("metadata: {e}")))?;
    for (key, value) in given {
        if key == "format" || key == "version" {
            continue;
        }
        match (merged.get_mut(&key), value) {
            (Some(serde_json::Value::Object(old)), serde_json::Value::Object(new)) => old.extend(new),
            (Some(old), new) => *old = new,
            (None, _) => return Err(value_error(format!("metadata has an unknown entry '{key}' (docs/model-format.md lists them)"))),
        }
    }
    serde_json::from_value(merged).map_err(|e| value_error(format!("metadata: {e}")))
}

/// The model of the given arrays, validated as a model file is.
pub(crate) fn model_from_arrays(
    shape: PartArrays<'_>,
    color: PartArrays<'_>,
    triangles: &Bound<'_, PyAny>,
    landmarks: Option<&Bound<'_, PyAny>>,
    metadata_given: Option<&Bound<'_, PyAny>>,
) -> PyResult<GpModel> {
    let Some(mean) = &shape.mean else { return Err(value_error("shape_mean is required")) };
    let (s, _) = floats::<f32>(mean, "shape_mean", "float32", &[None, Some(3)], "(N, 3) positions in mm")?;
    let n = s[0];
    if n == 0 {
        return Err(value_error("shape_mean has no vertices"));
    }
    let shape = part(&shape, "shape", n)?;
    let color = part(&color, "color", n)?;
    let tri = vertex_ids(triangles, "triangles", &[None, Some(3)], "(T, 3) vertex ids", n)?;
    let landmarks = match landmarks.filter(|l| !l.is_none()) {
        Some(l) => vertex_ids(l, "landmarks", &[None], "(L,) vertex ids", n)?,
        None => Vec::new(),
    };
    let metadata = metadata(metadata_given, &shape, &color, landmarks.len())?;
    let model = GpModel { shape, color, triangles: tri.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(), landmarks, metadata };
    // The checks a model file gets, so that what is made here saves and loads.
    let bytes = model_io::to_bytes(&model).map_err(|e| value_error(format!("the arrays do not make a model file: {e}")))?;
    model_io::from_bytes(&bytes, "<arrays>").map_err(|e| value_error(e.to_string()))
}
