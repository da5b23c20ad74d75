//! Reading the ICT-FaceKit's NumPy `.npy` arrays with the `npyz` crate.
//!
//! Only what gpmm reads: arrays of floats (`f4`, `f8`), loaded as `f32` ([`read_f32`]), or of
//! integers (1 to 8 bytes, signed or unsigned), loaded as `u32` with a range check
//! ([`read_u32`]); either byte order; C order, or Fortran order reordered to C order on load.
//! Every error names the file and says what is wrong; nothing panics on malformed input.

use std::io::ErrorKind;
use std::path::{Path, PathBuf};

use npyz::{DType, NpyFile, Order, TypeChar};

/// Why a `.npy` file could not be read.
#[derive(Debug, thiserror::Error)]
pub enum NpyError {
    /// The file could not be opened or read.
    #[error("{}: cannot read: {error}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        error: std::io::Error,
    },
    /// The file is not a valid `.npy` array of a supported type.
    #[error("{}: {problem}", path.display())]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        problem: NpyProblem,
    },
}

/// What is wrong with the content of a `.npy` file.
#[derive(Debug, thiserror::Error)]
pub enum NpyProblem {
    /// The header is missing or malformed.
    #[error("not a valid .npy file: {0}")]
    Header(std::io::Error),
    /// The element type is not the one asked for.
    #[error("expected {expected} array, found {found}")]
    Type {
        /// What was asked for.
        expected: &'static str,
        /// The file's element type and shape.
        found: String,
    },
    /// The data ends before the shape's elements do (or cannot be decoded).
    #[error("truncated or unreadable data for shape {shape:?}: {error}")]
    Data {
        /// The array's shape.
        shape: Vec<usize>,
        /// The decoder's error.
        error: std::io::Error,
    },
    /// The shape does not fit in memory's address space.
    #[error("the shape {0:?} is too large")]
    Shape(Vec<u64>),
    /// An integer is not a valid `u32` index.
    #[error("value {value} at element {index} is not a valid index (0 to {})", u32::MAX)]
    Index {
        /// The value.
        value: i128,
        /// Its element number (file order).
        index: usize,
    },
}

/// Reads a float array (`f4` or `f8`) as `f32` in C order; returns `(shape, values)`.
pub fn read_f32(path: &Path) -> Result<(Vec<usize>, Vec<f32>), NpyError> {
    let bytes = std::fs::read(path).map_err(|error| NpyError::Io { path: path.to_path_buf(), error })?;
    parse_f32(&bytes).map_err(|problem| NpyError::Format { path: path.to_path_buf(), problem })
}

/// Reads an integer array (1 to 8 bytes, signed or unsigned) as `u32` in C order; returns `(shape, values)`.
///
/// A negative value or one above `u32::MAX` is an error.
pub fn read_u32(path: &Path) -> Result<(Vec<usize>, Vec<u32>), NpyError> {
    let bytes = std::fs::read(path).map_err(|error| NpyError::Io { path: path.to_path_buf(), error })?;
    parse_u32(&bytes).map_err(|problem| NpyError::Format { path: path.to_path_buf(), problem })
}

/// A plain array's element kind and size in bytes.
type Element = (TypeChar, u64);

/// The shape, element kind and element size of a plain (non-record) array whose data can fit in
/// `file_len` bytes (so that a header claiming more elements than the file holds is refused before
/// any memory is reserved for them).
fn layout(file: &NpyFile<&[u8]>, file_len: usize) -> Result<(Vec<usize>, Option<Element>), NpyProblem> {
    let too_large = || NpyProblem::Shape(file.shape().to_vec());
    let shape: Vec<usize> = file.shape().iter().map(|&d| usize::try_from(d).map_err(|_| too_large())).collect::<Result<_, _>>()?;
    let count = shape.iter().try_fold(1usize, |a, &d| a.checked_mul(d)).ok_or_else(too_large)?;
    let element = match file.dtype() {
        DType::Plain(t) => Some((t.type_char(), t.size_field())),
        _ => None,
    };
    if let Some((_, size)) = element {
        if usize::try_from(size).ok().and_then(|s| count.checked_mul(s)).is_none_or(|need| need > file_len) {
            let error = std::io::Error::new(
                ErrorKind::UnexpectedEof,
                format!("{count} elements of {size} bytes do not fit in a {file_len}-byte file"),
            );
            return Err(NpyProblem::Data { shape, error });
        }
    }
    Ok((shape, element))
}

fn describe(file: &NpyFile<&[u8]>) -> String {
    format!("{} with shape {:?}", file.dtype().descr(), file.shape())
}

/// The values of `file` as `T` (in file order), naming a short or undecodable data part.
fn values<T: npyz::Deserialize>(file: NpyFile<&[u8]>, shape: &[usize]) -> Result<Vec<T>, NpyProblem> {
    file.into_vec::<T>().map_err(|error| NpyProblem::Data { shape: shape.to_vec(), error })
}

/// Parses the bytes of a float `.npy` file (see [`read_f32`]).
fn parse_f32(bytes: &[u8]) -> Result<(Vec<usize>, Vec<f32>), NpyProblem> {
    let file = NpyFile::new(bytes).map_err(NpyProblem::Header)?;
    let (shape, element) = layout(&file, bytes.len())?;
    let fortran = file.order() == Order::Fortran;
    let vals: Vec<f32> = match element {
        Some((TypeChar::Float, 4)) => values::<f32>(file, &shape)?,
        Some((TypeChar::Float, 8)) => values::<f64>(file, &shape)?.into_iter().map(|v| v as f32).collect(),
        _ => return Err(NpyProblem::Type { expected: "a float32 or float64", found: describe(&file) }),
    };
    Ok((shape.clone(), to_c_order(vals, &shape, fortran)))
}

/// Parses the bytes of an integer `.npy` file (see [`read_u32`]).
fn parse_u32(bytes: &[u8]) -> Result<(Vec<usize>, Vec<u32>), NpyProblem> {
    let file = NpyFile::new(bytes).map_err(NpyProblem::Header)?;
    let (shape, element) = layout(&file, bytes.len())?;
    let fortran = file.order() == Order::Fortran;
    let wide: Vec<i128> = match element {
        Some((TypeChar::Int, 1)) => values::<i8>(file, &shape)?.into_iter().map(i128::from).collect(),
        Some((TypeChar::Int, 2)) => values::<i16>(file, &shape)?.into_iter().map(i128::from).collect(),
        Some((TypeChar::Int, 4)) => values::<i32>(file, &shape)?.into_iter().map(i128::from).collect(),
        Some((TypeChar::Int, 8)) => values::<i64>(file, &shape)?.into_iter().map(i128::from).collect(),
        Some((TypeChar::Uint, 1)) => values::<u8>(file, &shape)?.into_iter().map(i128::from).collect(),
        Some((TypeChar::Uint, 2)) => values::<u16>(file, &shape)?.into_iter().map(i128::from).collect(),
        Some((TypeChar::Uint, 4)) => values::<u32>(file, &shape)?.into_iter().map(i128::from).collect(),
        Some((TypeChar::Uint, 8)) => values::<u64>(file, &shape)?.into_iter().map(i128::from).collect(),
        _ => return Err(NpyProblem::Type { expected: "an integer", found: describe(&file) }),
    };
    let vals: Vec<u32> = wide
        .into_iter()
        .enumerate()
        .map(|(index, value)| u32::try_from(value).map_err(|_| NpyProblem::Index { value, index }))
        .collect::<Result<_, _>>()?;
    Ok((shape.clone(), to_c_order(vals, &shape, fortran)))
}

/// Reorders a Fortran-order array to C order (last axis fastest).
fn to_c_order<T: Copy>(vals: Vec<T>, shape: &[usize], fortran: bool) -> Vec<T> {
    if !fortran || shape.len() < 2 {
        return vals;
    }
    // Fortran strides: stride[0] = 1, stride[k] = stride[k-1] * shape[k-1].
    let mut fstride = vec![1usize; shape.len()];
    for k in 1..shape.len() {
        fstride[k] = fstride[k - 1] * shape[k - 1];
    }
    let mut idx = vec![0usize; shape.len()];
    let mut out = Vec::with_capacity(vals.len());
    for _ in 0..vals.len() {
        out.push(vals[idx.iter().zip(&fstride).map(|(i, s)| i * s).sum::<usize>()]);
        for k in (0..shape.len()).rev() {
            idx[k] += 1;
            if idx[k] < shape[k] {
                break;
            }
            idx[k] = 0;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn npy(descr: &str, fortran: bool, shape: &str, data: &[u8]) -> Vec<u8> {
        let mut header = format!("{{'descr': '{descr}', 'fortran_order': {}, 'shape': {shape}, }}", if fortran { "True" } else { "False" });
        while (10 + header.len() + 1) % 64 != 0 {
            header.push(' ');
        }
        header.push('\n');
        let mut out = b"\x93NUMPY\x01\x00".to_vec();
        out.extend_from_slice(&(header.len() as u16).to_le_bytes());
        out.extend_from_slice(header.as_bytes());
        out.extend_from_slice(data);
        out
    }

    #[test]
    fn npy_reads_floats_and_ints() {
        let data: Vec<u8> = [1.0f32, 2.0, 3.0, 4.0, 5.0, 6.0].iter().flat_map(|v| v.to_le_bytes()).collect();
        let (s, v) = parse_f32(&npy("<f4", false, "(2, 3)", &data)).unwrap();
        assert_eq!(s, vec![2, 3]);
        assert_eq!(v, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        // Fortran order is transposed to C order.
        let (_, v) = parse_f32(&npy("<f4", true, "(2, 3)", &data)).unwrap();
        assert_eq!(v, vec![1.0, 3.0, 5.0, 2.0, 4.0, 6.0]);
        let data: Vec<u8> = [7.0f64, -1.5].iter().flat_map(|v| v.to_be_bytes()).collect();
        assert_eq!(parse_f32(&npy(">f8", false, "(2,)", &data)).unwrap().1, vec![7.0, -1.5]);
        let data: Vec<u8> = [3u32, 9].iter().flat_map(|v| v.to_le_bytes()).collect();
        assert_eq!(parse_u32(&npy("<u4", false, "(1, 2)", &data)).unwrap(), (vec![1, 2], vec![3, 9]));
        let data: Vec<u8> = [5i16, 300].iter().flat_map(|v| v.to_be_bytes()).collect();
        assert_eq!(parse_u32(&npy(">i2", false, "(2,)", &data)).unwrap().1, vec![5, 300]);
        let data: Vec<u8> = [-1i64].iter().flat_map(|v| v.to_le_bytes()).collect();
        assert!(parse_u32(&npy("<i8", false, "(1,)", &data)).unwrap_err().to_string().contains("not a valid index"));
    }

    #[test]
    fn npy_rejects_malformed() {
        assert!(parse_f32(b"hello").is_err());
        let data: Vec<u8> = [1.0f32].iter().flat_map(|v| v.to_le_bytes()).collect();
        assert!(parse_f32(&npy("<f4", false, "(2, 3)", &data)).unwrap_err().to_string().contains("truncated"));
        assert!(parse_u32(&npy("<f4", false, "(1,)", &data)).unwrap_err().to_string().contains("integer"));
        assert!(parse_f32(&npy("<c8", false, "(1,)", &data)).is_err());
        assert!(parse_f32(&npy("<f4", false, "(x,)", &data)).is_err());
        let mut bad = npy("<f4", false, "(1,)", &data);
        bad.truncate(12);
        assert!(parse_f32(&bad).is_err());
    }

    #[test]
    fn npy_errors_name_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("missing.npy");
        let e = read_f32(&missing).unwrap_err().to_string();
        assert!(e.starts_with(&format!("{}: cannot read", missing.display())), "{e}");
        let junk = dir.path().join("junk.npy");
        std::fs::write(&junk, b"not numpy").unwrap();
        let e = read_u32(&junk).unwrap_err().to_string();
        assert!(e.starts_with(&format!("{}: not a valid .npy file", junk.display())), "{e}");
    }
}
