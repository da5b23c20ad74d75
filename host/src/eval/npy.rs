//! A small reader for NumPy `.npy` files (format versions 1.0, 2.0 and 3.0).
//!
//! Only what gpmm reads: C-order (or Fortran-order, transposed on load) arrays of floats
//! (`f4`, `f8`) or integers (`u1`/`i1` to `u8`/`i8`), in either byte order. Floats load as
//! `f32` ([`read_f32`]), integers as `u32` with a range check ([`read_u32`]). Every error names
//! the file and says what is wrong; nothing panics on malformed input.

use std::path::{Path, PathBuf};

/// Why a `.npy` file could not be read.
#[derive(Debug, thiserror::Error)]
pub enum NpyError {
    /// The file could not be opened or read.
    #[error("{}: cannot read: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The file is not a valid `.npy` array of a supported type.
    #[error("{}: {message}", path.display())]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

/// The element type of an array.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Float,
    Signed,
    Unsigned,
}

/// A parsed header: element type, size, byte order, layout and shape.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Header {
    kind: Kind,
    size: usize,
    big_endian: bool,
    fortran: bool,
    shape: Vec<usize>,
}

fn format_err(path: &Path, message: impl Into<String>) -> NpyError {
    NpyError::Format { path: path.to_path_buf(), message: message.into() }
}

/// Reads a float array (`f4` or `f8`) as `f32` in C order; returns `(shape, values)`.
pub fn read_f32(path: &Path) -> Result<(Vec<usize>, Vec<f32>), NpyError> {
    let bytes = std::fs::read(path).map_err(|source| NpyError::Io { path: path.to_path_buf(), source })?;
    parse_f32(&bytes).map_err(|m| format_err(path, m))
}

/// Reads an integer array (1 to 8 bytes, signed or unsigned) as `u32` in C order; returns `(shape, values)`.
///
/// A negative value or one above `u32::MAX` is an error.
pub fn read_u32(path: &Path) -> Result<(Vec<usize>, Vec<u32>), NpyError> {
    let bytes = std::fs::read(path).map_err(|source| NpyError::Io { path: path.to_path_buf(), source })?;
    parse_u32(&bytes).map_err(|m| format_err(path, m))
}

/// Parses the bytes of a float `.npy` file (see [`read_f32`]).
pub fn parse_f32(bytes: &[u8]) -> Result<(Vec<usize>, Vec<f32>), String> {
    let (h, data) = parse_header(bytes)?;
    if h.kind != Kind::Float || !(h.size == 4 || h.size == 8) {
        return Err(format!("expected a float32 or float64 array, found {}", describe(&h)));
    }
    let vals: Vec<f32> = data
        .chunks_exact(h.size)
        .map(|c| {
            if h.size == 4 {
                let a = [c[0], c[1], c[2], c[3]];
                if h.big_endian {
                    f32::from_be_bytes(a)
                } else {
                    f32::from_le_bytes(a)
                }
            } else {
                let a = [c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]];
                (if h.big_endian { f64::from_be_bytes(a) } else { f64::from_le_bytes(a) }) as f32
            }
        })
        .collect();
    Ok((h.shape.clone(), to_c_order(vals, &h)))
}

/// Parses the bytes of an integer `.npy` file (see [`read_u32`]).
pub fn parse_u32(bytes: &[u8]) -> Result<(Vec<usize>, Vec<u32>), String> {
    let (h, data) = parse_header(bytes)?;
    if h.kind == Kind::Float {
        return Err(format!("expected an integer array, found {}", describe(&h)));
    }
    let mut vals = Vec::with_capacity(data.len() / h.size);
    for c in data.chunks_exact(h.size) {
        let mut a = [0u8; 8];
        if h.big_endian {
            for (k, b) in c.iter().rev().enumerate() {
                a[k] = *b;
            }
        } else {
            a[..h.size].copy_from_slice(c);
        }
        let v: i128 = if h.kind == Kind::Signed {
            // Sign-extend from `size` bytes.
            let shift = 64 - 8 * h.size as u32;
            i128::from((i64::from_le_bytes(a) << shift) >> shift)
        } else {
            i128::from(u64::from_le_bytes(a))
        };
        let v = u32::try_from(v).map_err(|_| format!("value {v} at element {} is not a valid index (0 to {})", vals.len(), u32::MAX))?;
        vals.push(v);
    }
    Ok((h.shape.clone(), to_c_order(vals, &h)))
}

fn describe(h: &Header) -> String {
    let k = match h.kind {
        Kind::Float => "float",
        Kind::Signed => "int",
        Kind::Unsigned => "uint",
    };
    format!("{k}{} with shape {:?}", 8 * h.size, h.shape)
}

/// Reorders a Fortran-order array to C order.
fn to_c_order<T: Copy + Default>(vals: Vec<T>, h: &Header) -> Vec<T> {
    if !h.fortran || h.shape.len() < 2 {
        return vals;
    }
    let shape = &h.shape;
    let n = vals.len();
    let mut out = vec![T::default(); n];
    // Fortran strides: stride[0] = 1, stride[k] = stride[k-1] * shape[k-1].
    let mut fstride = vec![1usize; shape.len()];
    for k in 1..shape.len() {
        fstride[k] = fstride[k - 1] * shape[k - 1];
    }
    let mut idx = vec![0usize; shape.len()];
    for o in out.iter_mut() {
        let src: usize = idx.iter().zip(&fstride).map(|(i, s)| i * s).sum();
        *o = vals[src];
        // Advance the C-order multi-index (last axis fastest).
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

/// Splits a `.npy` file into its parsed header and exactly the data bytes the shape needs.
fn parse_header(bytes: &[u8]) -> Result<(Header, &[u8]), String> {
    const MAGIC: &[u8] = b"\x93NUMPY";
    if bytes.len() < 10 || &bytes[..6] != MAGIC {
        return Err("not a .npy file (the magic bytes \\x93NUMPY are missing)".into());
    }
    let major = bytes[6];
    let (len, start) = match major {
        1 => (usize::from(u16::from_le_bytes([bytes[8], bytes[9]])), 10usize),
        2 | 3 => {
            if bytes.len() < 12 {
                return Err("truncated .npy header".into());
            }
            (u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize, 12)
        }
        v => return Err(format!("unsupported .npy format version {v}")),
    };
    let end = start.checked_add(len).filter(|&e| e <= bytes.len()).ok_or("truncated .npy header")?;
    let text = std::str::from_utf8(&bytes[start..end]).map_err(|_| "the .npy header is not text")?;
    let descr = dict_value(text, "descr").ok_or("the .npy header has no 'descr'")?;
    let descr = descr.trim().trim_matches(|c| c == '\'' || c == '"');
    let mut chars = descr.chars();
    let order = chars.next().ok_or("empty dtype in the .npy header")?;
    let big_endian = match order {
        '<' | '|' => false,
        '>' => true,
        '=' => cfg!(target_endian = "big"),
        _ => return Err(format!("unsupported dtype '{descr}'")),
    };
    let kind = match chars.next() {
        Some('f') => Kind::Float,
        Some('i') => Kind::Signed,
        Some('u') => Kind::Unsigned,
        _ => return Err(format!("unsupported dtype '{descr}' (need a float or integer type)")),
    };
    let size: usize = chars.as_str().parse().map_err(|_| format!("unsupported dtype '{descr}'"))?;
    if !matches!(size, 1 | 2 | 4 | 8) || (kind == Kind::Float && size < 4) {
        return Err(format!("unsupported dtype '{descr}'"));
    }
    let fortran = match dict_value(text, "fortran_order").map(str::trim) {
        Some("False") => false,
        Some("True") => true,
        _ => return Err("the .npy header has no valid 'fortran_order'".into()),
    };
    let shape_text = dict_value(text, "shape").ok_or("the .npy header has no 'shape'")?;
    let inner = shape_text.trim().strip_prefix('(').and_then(|s| s.strip_suffix(')')).ok_or("malformed 'shape' in the .npy header")?;
    let shape: Vec<usize> = inner
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.trim_end_matches('L').parse::<usize>().map_err(|_| format!("malformed 'shape' ({shape_text}) in the .npy header")))
        .collect::<Result<_, _>>()?;
    let count = shape.iter().try_fold(1usize, |a, &d| a.checked_mul(d)).ok_or("the .npy shape is too large")?;
    let need = count.checked_mul(size).ok_or("the .npy shape is too large")?;
    let data = &bytes[end..];
    if data.len() < need {
        return Err(format!("truncated data: shape {shape:?} needs {need} bytes, the file has {}", data.len()));
    }
    Ok((Header { kind, size, big_endian, fortran, shape }, &data[..need]))
}

/// The raw text of `'key': value` in a Python dict literal (value up to the next top-level comma or brace).
fn dict_value<'a>(text: &'a str, key: &str) -> Option<&'a str> {
    let pat1 = format!("'{key}'");
    let pat2 = format!("\"{key}\"");
    let pos = text.find(&pat1).map(|p| p + pat1.len()).or_else(|| text.find(&pat2).map(|p| p + pat2.len()))?;
    let rest = text[pos..].trim_start().strip_prefix(':')?;
    let mut depth = 0i32;
    for (i, c) in rest.char_indices() {
        match c {
            '(' | '[' => depth += 1,
            ')' | ']' => depth -= 1,
            ',' | '}' if depth == 0 => return Some(&rest[..i]),
            _ => {}
        }
    }
    Some(rest)
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
        let data: Vec<u8> = [-1i64].iter().flat_map(|v| v.to_le_bytes()).collect();
        assert!(parse_u32(&npy("<i8", false, "(1,)", &data)).unwrap_err().contains("not a valid index"));
    }

    #[test]
    fn npy_rejects_malformed() {
        assert!(parse_f32(b"hello").is_err());
        let data: Vec<u8> = [1.0f32].iter().flat_map(|v| v.to_le_bytes()).collect();
        assert!(parse_f32(&npy("<f4", false, "(2, 3)", &data)).unwrap_err().contains("truncated"));
        assert!(parse_u32(&npy("<f4", false, "(1,)", &data)).unwrap_err().contains("integer"));
        assert!(parse_f32(&npy("<c8", false, "(1,)", &data)).is_err());
        assert!(parse_f32(&npy("<f4", false, "(x,)", &data)).is_err());
        let mut bad = npy("<f4", false, "(1,)", &data);
        bad.truncate(12);
        assert!(parse_f32(&bad).is_err());
    }
}
