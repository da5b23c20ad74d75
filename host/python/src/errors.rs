//! Raising the package's exceptions (defined in `gpmm/_errors.py`): `GpmmValueError` for bad
//! arguments and bad data, `GpmmFileNotFoundError` / `GpmmOSError` (with `filename`) for files
//! that are missing or cannot be read or written. Every message is the one the `gpmm` program
//! prints, so each cause is said once.

use pyo3::prelude::*;
use pyo3::types::PyType;
use pyo3::PyErrArguments;
use std::io::Read;
use std::path::Path;

/// `errno` of a missing file (ENOENT) in a message's `(os error N)`.
const ENOENT: i32 = 2;

fn raise(class: &str, args: impl PyErrArguments + 'static) -> PyErr {
    Python::attach(|py| {
        let class = py.import("gpmm._errors").and_then(|m| m.getattr(class)).and_then(|c| c.cast_into::<PyType>().map_err(PyErr::from));
        match class {
            Ok(c) => PyErr::from_type(c, args),
            Err(e) => e,
        }
    })
}

/// A `GpmmValueError` with a message.
pub(crate) fn value_error(message: impl Into<String>) -> PyErr {
    raise("GpmmValueError", (message.into(),))
}

/// A `GpmmValueError` from any error: its message, which names its cause itself.
pub(crate) fn err(e: impl std::error::Error) -> PyErr {
    value_error(e.to_string())
}

/// A `GpmmFileNotFoundError` (`not_found`) or `GpmmOSError` for `path` with the program's message.
fn os_error(message: String, not_found: bool, errno: Option<i32>, path: &Path) -> PyErr {
    let class = if not_found { "GpmmFileNotFoundError" } else { "GpmmOSError" };
    raise(class, (message, errno, path.display().to_string()))
}

/// The OS error of `path` for an I/O failure `io`, with the program's message.
pub(crate) fn io_error(message: impl Into<String>, io: &std::io::Error, path: &Path) -> PyErr {
    let not_found = io.kind() == std::io::ErrorKind::NotFound;
    os_error(message.into(), not_found, io.raw_os_error().or(not_found.then_some(ENOENT)), path)
}

/// The error of a failed read of `paths` (the files a call reads): an OS error naming the one of
/// them that cannot be opened and read (the one the message names, if several), else (the files
/// are fine, their content is not) a `GpmmValueError`. `message` is the program's.
pub(crate) fn read_error(message: impl std::fmt::Display, paths: &[&Path]) -> PyErr {
    let message = message.to_string();
    let failing = paths.iter().filter_map(|p| std::fs::File::open(p).and_then(|mut f| f.read(&mut [0u8; 1])).err().map(|io| (p, io)));
    // The file the message names, if several cannot be read.
    let (named, others): (Vec<_>, Vec<_>) = failing.partition(|(p, _)| message.contains(&p.display().to_string()));
    match named.into_iter().chain(others).next() {
        Some((p, io)) => os_error(message, io.kind() == std::io::ErrorKind::NotFound, io.raw_os_error(), p),
        None => value_error(message),
    }
}

/// The error of a failed write of `path`: an OS error when the message carries one (Rust's
/// `(os error N)`), else a `GpmmValueError`.
pub(crate) fn write_error(message: impl std::fmt::Display, path: &Path) -> PyErr {
    let message = message.to_string();
    match os_errno(&message) {
        Some(errno) => os_error(message, errno == ENOENT, Some(errno), path),
        None => value_error(message),
    }
}

/// The `N` of the last `(os error N)` in a message.
fn os_errno(message: &str) -> Option<i32> {
    let start = message.rfind("(os error ")? + "(os error ".len();
    message[start..].split(')').next()?.parse().ok()
}
