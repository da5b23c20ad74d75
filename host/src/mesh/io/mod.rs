//! Mesh and landmark file input/output.
//!
//! * [`read_mesh`] reads a coloured triangle mesh from
//!   - **PLY** (ASCII, binary little- or big-endian): vertex `x y z` (float or
//!     double); colours from `red green blue` (also `r g b` or
//!     `diffuse_red diffuse_green diffuse_blue`; integer values are 0-255,
//!     `ushort` 0-65535, float values already in \[0, 1\]); faces from a
//!     `vertex_indices` (or `vertex_index`) integer list; polygons with more
//!     than three corners are fan-triangulated.
//!   - **glTF** (`.glb`, or `.gltf` with its buffers next to it): every
//!     triangle primitive of the default scene (node transforms applied), or of
//!     all meshes when the file has no scene. Colours are the bilinear sample
//!     of the texture (the `--texture` image if given, else the material's base
//!     colour image) at `TEXCOORD_0`, with texture row `= (1 - v) * height`
//!     (pixel centres at half-integers; `u`/`v` wrap around), which is the
//!     convention that reproduces the reference PLY of the template scan; or
//!     `COLOR_0` when there is no texture. Vertices that the file splits at UV
//!     seams are **welded**: vertices at the same position (within 1e-6 of the
//!     bounding-box diagonal) become one vertex whose colour is the mean of
//!     theirs. The welded vertices are ordered lexicographically by position
//!     `(x, y, z)`, so landmark ids refer to the welded mesh ordered by
//!     position; for the Lee Perry-Smith template this reproduces
//!     `lee-perry-smith.ply` vertex for vertex.
//!
//!   The result is validated: at least one triangle, finite coordinates and
//!   colours, triangle indices in range, every undirected edge used by at
//!   most two triangles (manifold). Degenerate triangles (a repeated vertex
//!   index) are dropped with a warning.
//! * [`read_landmarks_json`] reads `{"scheme": "ibug68", "vertex_ids": [...]}`.
//! * [`write_ply`] / [`write_ply_with`] write a coloured mesh as binary
//!   little-endian or ASCII PLY (`float x y z`, `uchar red green blue`,
//!   `list uchar int vertex_indices`).
//!
//! Every error names the offending file; bad data never panics.

use std::collections::HashMap;
use std::fs::File;
use std::io::{BufReader, BufWriter, Write};
use std::path::Path;

use ply_rs_bw::parser::Parser;
use ply_rs_bw::ply::{Property, PropertyAccess, PropertyAccessResult, PropertyType, ScalarType};

use crate::mesh::Mesh;

mod common;
mod gltf_file;
pub use common::{ColorSource, MeshIoError};
use gltf_file::read_gltf;

/// Reads a coloured triangle mesh, dispatching on the extension (`.ply`, `.glb`/`.gltf`).
///
/// `texture` overrides the texture image of a glTF file; `default_color` is
/// used when the file has no colours (otherwise that is an error).
pub fn read_mesh(path: &Path, texture: Option<&Path>, default_color: Option<[f64; 3]>) -> Result<Mesh, MeshIoError> {
    read_mesh_with_info(path, texture, default_color).map(|(mesh, _)| mesh)
}

/// Like [`read_mesh`], also telling where the colours came from.
pub fn read_mesh_with_info(
    path: &Path,
    texture: Option<&Path>,
    default_color: Option<[f64; 3]>,
) -> Result<(Mesh, ColorSource), MeshIoError> {
    if let Some(c) = default_color {
        if c.iter().any(|v| !v.is_finite() || *v < 0.0 || *v > 1.0) {
            return Err(MeshIoError::invalid(path, format!("default colour {c:?} is not in [0,1]")));
        }
    }
    let ext = path.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase()).unwrap_or_default();
    let (mut mesh, source) = match ext.as_str() {
        "ply" => read_ply(path, default_color)?,
        "glb" | "gltf" => read_gltf(path, texture, default_color)?,
        _ => return Err(MeshIoError::UnsupportedFormat { path: path.to_path_buf() }),
    };
    validate_mesh(path, &mut mesh)?;
    Ok((mesh, source))
}

/// Checks a mesh read from `path` (errors name `path`) and drops degenerate triangles.
///
/// Errors: no vertices or triangles, colour count differing from vertex count,
/// a non-finite coordinate or colour, a colour outside \[0, 1\], a triangle index
/// out of range, an undirected edge shared by more than two triangles.
pub fn validate_mesh(path: &Path, mesh: &mut Mesh) -> Result<(), MeshIoError> {
    let n = mesh.positions.len();
    if n == 0 {
        return Err(MeshIoError::invalid(path, "the mesh has no vertices"));
    }
    if mesh.colors.len() != n {
        return Err(MeshIoError::invalid(path, format!("the mesh has {} colours for {} vertices", mesh.colors.len(), n)));
    }
    for (i, p) in mesh.positions.iter().enumerate() {
        if p.iter().any(|v| !v.is_finite()) {
            return Err(MeshIoError::invalid(path, format!("vertex {i} has a non-finite coordinate")));
        }
    }
    for (i, c) in mesh.colors.iter().enumerate() {
        if c.iter().any(|v| !v.is_finite() || *v < -1e-6 || *v > 1.0 + 1e-6) {
            return Err(MeshIoError::invalid(path, format!("vertex {i} has colour {c:?} outside [0,1]")));
        }
    }
    for c in mesh.colors.iter_mut() {
        for v in c.iter_mut() {
            *v = v.clamp(0.0, 1.0);
        }
    }
    for (t, tri) in mesh.triangles.iter().enumerate() {
        if let Some(&bad) = tri.iter().find(|&&i| i as usize >= n) {
            return Err(MeshIoError::invalid(path, format!("triangle {t} refers to vertex {bad} but the mesh has {n} vertices")));
        }
    }
    let before = mesh.triangles.len();
    mesh.triangles.retain(|t| t[0] != t[1] && t[1] != t[2] && t[0] != t[2]);
    let dropped = before - mesh.triangles.len();
    if dropped > 0 {
        log::warn!("{}: dropped {dropped} degenerate triangle(s) with a repeated vertex", path.display());
    }
    if mesh.triangles.is_empty() {
        return Err(MeshIoError::invalid(path, "the mesh has no triangles"));
    }
    check_manifold(path, &mesh.triangles)
}

/// Errors if an undirected edge is used by more than two triangles.
fn check_manifold(path: &Path, triangles: &[[u32; 3]]) -> Result<(), MeshIoError> {
    let mut uses: HashMap<(u32, u32), u32> = HashMap::with_capacity(triangles.len() * 2);
    for t in triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let key = (a.min(b), a.max(b));
            let count = uses.entry(key).or_insert(0);
            *count += 1;
            if *count > 2 {
                return Err(MeshIoError::invalid(
                    path,
                    format!("non-manifold edge: the edge between vertices {} and {} is used by more than 2 triangles", key.0, key.1),
                ));
            }
        }
    }
    Ok(())
}

// ---------------------------------------------------------------- PLY input

/// One PLY element (vertex or face) as the parser fills it.
#[derive(Debug, Default)]
struct PlyElem {
    pos: [f64; 3],
    color: [f64; 3],
    indices: Vec<i64>,
}

fn scalar_f64(p: &Property) -> Option<f64> {
    Some(match *p {
        Property::Char(v) => f64::from(v),
        Property::UChar(v) => f64::from(v),
        Property::Short(v) => f64::from(v),
        Property::UShort(v) => f64::from(v),
        Property::Int(v) => f64::from(v),
        Property::UInt(v) => f64::from(v),
        Property::Float(v) => f64::from(v),
        Property::Double(v) => v,
        _ => return None,
    })
}

/// A colour component in \[0, 1\]: integers are 0-255 (`ushort`: 0-65535), floats already in \[0, 1\].
fn color_f64(p: &Property) -> Option<f64> {
    match *p {
        Property::UShort(v) => Some(f64::from(v) / 65535.0),
        Property::Float(v) => Some(f64::from(v)),
        Property::Double(v) => Some(v),
        _ => scalar_f64(p).map(|v| v / 255.0),
    }
}

fn list_i64(p: Property) -> Option<Vec<i64>> {
    Some(match p {
        Property::ListChar(v) => v.into_iter().map(i64::from).collect(),
        Property::ListUChar(v) => v.into_iter().map(i64::from).collect(),
        Property::ListShort(v) => v.into_iter().map(i64::from).collect(),
        Property::ListUShort(v) => v.into_iter().map(i64::from).collect(),
        Property::ListInt(v) => v.into_iter().map(i64::from).collect(),
        Property::ListUInt(v) => v.into_iter().map(i64::from).collect(),
        _ => return None,
    })
}

const COLOR_NAMES: [[&str; 3]; 3] = [["red", "green", "blue"], ["r", "g", "b"], ["diffuse_red", "diffuse_green", "diffuse_blue"]];

fn color_channel(name: &str) -> Option<usize> {
    COLOR_NAMES.iter().find_map(|set| set.iter().position(|&n| n == name))
}

impl PropertyAccess for PlyElem {
    fn new() -> Self {
        Self::default()
    }
    fn set_property(&mut self, name: &str, property: Property) -> PropertyAccessResult {
        match name {
            "x" | "y" | "z" => {
                let k = match name {
                    "x" => 0,
                    "y" => 1,
                    _ => 2,
                };
                self.pos[k] = scalar_f64(&property).unwrap_or(f64::NAN);
                PropertyAccessResult::Set
            }
            "vertex_indices" | "vertex_index" => {
                // Non-integer lists are rejected from the header before parsing.
                self.indices = list_i64(property).unwrap_or_default();
                PropertyAccessResult::Set
            }
            _ => match color_channel(name) {
                Some(k) => {
                    self.color[k] = color_f64(&property).unwrap_or(f64::NAN);
                    PropertyAccessResult::Set
                }
                None => PropertyAccessResult::Ignored,
            },
        }
    }
}

fn is_int(t: &ScalarType) -> bool {
    !matches!(t, ScalarType::Float | ScalarType::Double)
}

fn read_ply(path: &Path, default_color: Option<[f64; 3]>) -> Result<(Mesh, ColorSource), MeshIoError> {
    let file = File::open(path).map_err(|e| MeshIoError::read(path, e))?;
    let mut reader = BufReader::new(file);
    let parser = Parser::<PlyElem>::new();
    let ply = parser.read_ply(&mut reader).map_err(|e| MeshIoError::ply(path, e.to_string()))?;
    let header = &ply.header;
    let vdef = header.elements.get("vertex").ok_or_else(|| MeshIoError::ply(path, "no `vertex` element"))?;
    for name in ["x", "y", "z"] {
        match vdef.properties.get(name).map(|p| &p.data_type) {
            Some(PropertyType::Scalar(_)) => {}
            Some(PropertyType::List(..)) => return Err(MeshIoError::ply(path, format!("vertex property `{name}` is a list"))),
            None => return Err(MeshIoError::ply(path, format!("vertex property `{name}` is missing"))),
        }
    }
    let has_colors = COLOR_NAMES
        .iter()
        .any(|set| set.iter().all(|n| matches!(vdef.properties.get(*n).map(|p| &p.data_type), Some(PropertyType::Scalar(_)))));
    let fdef = header.elements.get("face").ok_or_else(|| MeshIoError::ply(path, "no `face` element (point clouds are not supported)"))?;
    let index_prop = ["vertex_indices", "vertex_index"]
        .into_iter()
        .find(|n| fdef.properties.contains_key(*n))
        .ok_or_else(|| MeshIoError::ply(path, "face property `vertex_indices` is missing"))?;
    match fdef.properties.get(index_prop).map(|p| &p.data_type) {
        Some(PropertyType::List(_, item)) if is_int(item) => {}
        _ => return Err(MeshIoError::ply(path, format!("face property `{index_prop}` is not a list of integers"))),
    }

    let empty = Vec::new();
    let verts = ply.payload.get("vertex").unwrap_or(&empty);
    let faces = ply.payload.get("face").unwrap_or(&empty);
    let positions: Vec<[f64; 3]> = verts.iter().map(|v| v.pos).collect();
    let (colors, source) = if has_colors {
        (verts.iter().map(|v| v.color).collect(), ColorSource::Vertex)
    } else if let Some(c) = default_color {
        (vec![c; verts.len()], ColorSource::Default)
    } else {
        return Err(MeshIoError::NoColors { path: path.to_path_buf() });
    };
    let mut triangles = Vec::with_capacity(faces.len());
    for (f, face) in faces.iter().enumerate() {
        let idx = &face.indices;
        if idx.len() < 3 {
            return Err(MeshIoError::invalid(path, format!("face {f} has {} vertices (at least 3 needed)", idx.len())));
        }
        let mut conv = Vec::with_capacity(idx.len());
        for &i in idx {
            let u = u32::try_from(i).map_err(|_| MeshIoError::invalid(path, format!("face {f} has an invalid vertex index {i}")))?;
            conv.push(u);
        }
        for k in 1..conv.len() - 1 {
            triangles.push([conv[0], conv[k], conv[k + 1]]);
        }
    }
    Ok((Mesh { positions, colors, triangles }, source))
}

// ---------------------------------------------------------------- landmarks

#[derive(serde::Deserialize)]
struct LandmarkFile {
    scheme: String,
    vertex_ids: Vec<u32>,
}

/// Reads `{"scheme": "ibug68", "vertex_ids": [...]}` and returns (scheme, vertex ids).
pub fn read_landmarks_json(path: &Path) -> Result<(String, Vec<u32>), MeshIoError> {
    let text = std::fs::read_to_string(path).map_err(|e| MeshIoError::read(path, e))?;
    let file: LandmarkFile =
        serde_json::from_str(&text).map_err(|e| MeshIoError::Landmarks { path: path.to_path_buf(), message: e.to_string() })?;
    Ok((file.scheme, file.vertex_ids))
}

// --------------------------------------------------------------- PLY output

/// PLY payload encoding for [`write_ply_with`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlyEncoding {
    /// `binary_little_endian 1.0` (compact; the default of [`write_ply`]).
    BinaryLittleEndian,
    /// `ascii 1.0` (human-readable).
    Ascii,
}

/// Writes a coloured mesh as binary little-endian PLY (float xyz, uchar rgb, uchar-count int face lists).
pub fn write_ply(path: &Path, mesh: &Mesh) -> Result<(), MeshIoError> {
    write_ply_with(path, mesh, PlyEncoding::BinaryLittleEndian, &[])
}

/// Writes a coloured mesh as PLY in the given encoding, with header comment lines (e.g. attribution).
pub fn write_ply_with(path: &Path, mesh: &Mesh, encoding: PlyEncoding, comments: &[&str]) -> Result<(), MeshIoError> {
    write_ply_with_quality(path, mesh, None, encoding, comments)
}

/// [`write_ply_with`] with a per-vertex scalar `quality` (a float property of that name, which
/// MeshLab and Open3D read as the vertex quality and can colour by) when given.
pub fn write_ply_with_quality(
    path: &Path,
    mesh: &Mesh,
    quality: Option<&[f32]>,
    encoding: PlyEncoding,
    comments: &[&str],
) -> Result<(), MeshIoError> {
    if let Some(q) = quality.filter(|q| q.len() != mesh.positions.len()) {
        return Err(MeshIoError::invalid(path, format!("cannot write {} vertex qualities for {} vertices", q.len(), mesh.positions.len())));
    }
    if mesh.colors.len() != mesh.positions.len() {
        return Err(MeshIoError::invalid(
            path,
            format!("cannot write a mesh with {} colours for {} vertices", mesh.colors.len(), mesh.positions.len()),
        ));
    }
    let file = File::create(path).map_err(|e| MeshIoError::write(path, e))?;
    let mut w = BufWriter::new(file);
    write_ply_to(&mut w, mesh, quality, encoding, comments).and_then(|_| w.flush()).map_err(|e| MeshIoError::write(path, e))
}

fn to_u8(c: f64) -> u8 {
    (c.clamp(0.0, 1.0) * 255.0).round() as u8
}

fn write_ply_to<W: Write>(
    w: &mut W,
    mesh: &Mesh,
    quality: Option<&[f32]>,
    encoding: PlyEncoding,
    comments: &[&str],
) -> std::io::Result<()> {
    let format = match encoding {
        PlyEncoding::BinaryLittleEndian => "binary_little_endian",
        PlyEncoding::Ascii => "ascii",
    };
    writeln!(w, "ply\nformat {format} 1.0")?;
    for c in comments {
        // Comments are single header lines.
        writeln!(w, "comment {}", c.replace(['\n', '\r'], " "))?;
    }
    writeln!(w, "element vertex {}", mesh.positions.len())?;
    writeln!(w, "property float x\nproperty float y\nproperty float z")?;
    writeln!(w, "property uchar red\nproperty uchar green\nproperty uchar blue")?;
    if quality.is_some() {
        writeln!(w, "property float quality")?;
    }
    writeln!(w, "element face {}", mesh.triangles.len())?;
    writeln!(w, "property list uchar int vertex_indices\nend_header")?;
    match encoding {
        PlyEncoding::BinaryLittleEndian => {
            for (i, (p, c)) in mesh.positions.iter().zip(&mesh.colors).enumerate() {
                for v in p {
                    w.write_all(&(*v as f32).to_le_bytes())?;
                }
                w.write_all(&c.map(to_u8))?;
                if let Some(q) = quality.and_then(|q| q.get(i)) {
                    w.write_all(&q.to_le_bytes())?;
                }
            }
            for t in &mesh.triangles {
                w.write_all(&[3u8])?;
                for i in t {
                    // PLY `int`: indices beyond i32::MAX cannot be represented.
                    let i =
                        i32::try_from(*i).map_err(|_| std::io::Error::new(std::io::ErrorKind::InvalidInput, "vertex index too large"))?;
                    w.write_all(&i.to_le_bytes())?;
                }
            }
        }
        PlyEncoding::Ascii => {
            for (i, (p, c)) in mesh.positions.iter().zip(&mesh.colors).enumerate() {
                let c = c.map(to_u8);
                write!(w, "{} {} {} {} {} {}", p[0] as f32, p[1] as f32, p[2] as f32, c[0], c[1], c[2])?;
                match quality.and_then(|q| q.get(i)) {
                    Some(q) => writeln!(w, " {q}")?,
                    None => writeln!(w)?,
                }
            }
            for t in &mesh.triangles {
                writeln!(w, "3 {} {} {}", t[0], t[1], t[2])?;
            }
        }
    }
    Ok(())
}
