//! Arguments as Python users give them, checked where the parameter's name is known, so that a
//! bad value is a `GpmmValueError` naming the parameter (not a bare `OverflowError` or a
//! conversion message of the binding library).

use crate::errors::value_error;
use gpmm_host::fit::FitFlags;
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::PyString;

/// A non-negative integer argument as given, checked by [`Int::get`] with the parameter's name.
pub(crate) enum Int {
    /// A value in `u64`.
    Value(u64),
    /// An int below 0 (its text).
    Negative(String),
    /// An int above `u64::MAX` (its text).
    TooLarge(String),
    /// Not an int at all (its type's name).
    Other(String),
}

impl Int {
    /// The given value (for defaults).
    pub(crate) const fn of(v: u64) -> Self {
        Self::Value(v)
    }

    /// The value as `T`: a `GpmmValueError` naming `name` when it is negative or too large for
    /// `T`, a `TypeError` naming it when it is not an int.
    pub(crate) fn get<T: TryFrom<u64>>(&self, name: &str) -> PyResult<T> {
        match self {
            Self::Value(v) => T::try_from(*v).map_err(|_| value_error(format!("{name} = {v} is too large"))),
            Self::TooLarge(text) => Err(value_error(format!("{name} = {text} is too large"))),
            Self::Negative(text) => Err(value_error(format!("{name} must be a non-negative integer, got {text}"))),
            Self::Other(type_name) => Err(PyTypeError::new_err(format!("{name} must be an int, got {type_name}"))),
        }
    }
}

impl<'a, 'py> FromPyObject<'a, 'py> for Int {
    type Error = PyErr;

    fn extract(obj: Borrowed<'a, 'py, PyAny>) -> PyResult<Self> {
        if let Ok(v) = obj.extract::<u64>() {
            return Ok(Self::Value(v));
        }
        // An int (or numpy integer) out of range, or no int: reported with the parameter's name by `get`.
        let Ok(int) = obj.py().import("operator")?.call_method1("index", (obj,)) else {
            return Ok(Self::Other(obj.get_type().name()?.to_string()));
        };
        let text = int.str()?.to_string();
        Ok(if int.lt(0)? { Self::Negative(text) } else { Self::TooLarge(text) })
    }
}

/// An optional [`Int`] as `T`.
pub(crate) fn opt<T: TryFrom<u64>>(v: &Option<Int>, name: &str) -> PyResult<Option<T>> {
    v.as_ref().map(|i| i.get(name)).transpose()
}

/// The `set` overrides: a list of `key=value` strings (a bare string is refused with a hint,
/// since iterating it would give one override per character).
pub(crate) fn overrides(obj: Option<&Bound<'_, PyAny>>) -> PyResult<Vec<String>> {
    let Some(obj) = obj.filter(|o| !o.is_none()) else { return Ok(Vec::new()) };
    if let Ok(s) = obj.cast::<PyString>() {
        return Err(value_error(format!("set must be a list of \"key=value\" strings, not a str: write set=[{:?}]", s.to_string())));
    }
    obj.extract::<Vec<String>>()
        .map_err(|_| value_error("set must be a list of \"key=value\" strings, e.g. set=[\"landmarks.student_t=4\"]"))
}

/// The fit keywords `Model.fit` and `learn` share, as given (`None`: the default).
pub(crate) struct FitKeywords<'a, 'py> {
    /// `seed`.
    pub seed: Option<Int>,
    /// `size`.
    pub size: Option<Int>,
    /// `landmark_steps`.
    pub landmark_steps: Option<Int>,
    /// `image_steps`.
    pub image_steps: Option<Int>,
    /// `shape_rank`.
    pub shape_rank: Option<Int>,
    /// `color_rank`.
    pub color_rank: Option<Int>,
    /// `landmark_sigma`.
    pub landmark_sigma: Option<f32>,
    /// `contour_sigma`.
    pub contour_sigma: Option<f32>,
    /// `set`.
    pub set: Option<&'a Bound<'py, PyAny>>,
}

impl FitKeywords<'_, '_> {
    /// The fit's flags (no initializer σ), each keyword checked under its name in the order of
    /// the signature; `ranks` (the model's shape and colour ranks), when given, bound the fitted ones.
    pub(crate) fn flags(&self, ranks: Option<[usize; 2]>) -> PyResult<FitFlags> {
        let rank = |given: &Option<Int>, name: &str, model_rank: Option<usize>| match model_rank {
            Some(m) => within_rank(opt(given, name)?, name, m),
            None => opt(given, name),
        };
        Ok(FitFlags {
            size: opt(&self.size, "size")?,
            seed: opt(&self.seed, "seed")?,
            landmark_steps: opt(&self.landmark_steps, "landmark_steps")?,
            image_steps: opt(&self.image_steps, "image_steps")?,
            shape_rank: rank(&self.shape_rank, "shape_rank", ranks.map(|r| r[0]))?,
            color_rank: rank(&self.color_rank, "color_rank", ranks.map(|r| r[1]))?,
            landmark_sigma: self.landmark_sigma,
            contour_sigma: self.contour_sigma,
            initializer_sigma: None,
            overrides: overrides(self.set)?,
        })
    }
}

/// A fit's settings refused, as a `GpmmValueError`: the program's messages name its flag
/// (`--set`), here the parameter is `set`.
pub(crate) fn fit_settings_error(e: impl std::fmt::Display) -> PyErr {
    value_error(e.to_string().replace("--set ", "set: "))
}

/// A rank the caller asked for, refused when the model has fewer components (`name` is the parameter).
pub(crate) fn within_rank(rank: Option<usize>, name: &str, model_rank: usize) -> PyResult<Option<usize>> {
    match rank {
        Some(r) if r > model_rank => Err(value_error(format!("{name} = {r} is more than the model's {model_rank} components"))),
        _ => Ok(rank),
    }
}

/// Coefficients (`shape` or `color` of `instance` / `render`): a sequence of finite numbers,
/// at most `rank` of them; a bad one is named with its array and index.
pub(crate) fn coefficients(obj: Option<&Bound<'_, PyAny>>, name: &str, rank: usize) -> PyResult<Vec<f32>> {
    let Some(obj) = obj.filter(|o| !o.is_none()) else { return Ok(Vec::new()) };
    let np = obj.py().import("numpy")?;
    let arr = np
        .call_method1("asarray", (obj, "float32"))
        .and_then(|a| a.call_method0("ravel"))
        .and_then(|a| a.call_method0("tolist"))
        .and_then(|l| l.extract::<Vec<f32>>())
        .map_err(|_| value_error(format!("{name} must be a sequence of numbers (coefficients)")))?;
    if arr.len() > rank {
        return Err(value_error(format!("{name} has {} coefficients; the model has {rank}", arr.len())));
    }
    if let Some(i) = arr.iter().position(|c| !c.is_finite()) {
        return Err(value_error(format!("{name}[{i}] is {}: coefficients must be finite", arr[i])));
    }
    Ok(arr)
}
