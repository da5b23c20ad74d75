//! Mesh and landmark file input/output.
//!
//! * [`read_mesh`] reads a coloured triangle mesh from
//!   - **PLY** (ASCII, binary little- or big-endian): vertex `x y z` (float or
//!     double); colours from `red green blue` (also `r g b` or
//!     `diffuse_red diffuse_green diffuse_blue`; integer values are 0-255,
//!     `ushort` 0-65535, float values already in [0,1]); faces from a
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
use std::path::{Path, PathBuf};

use ply_rs_bw::parser::Parser;
use ply_rs_bw::ply::{Property, PropertyAccess, PropertyAccessResult, PropertyType, ScalarType};

use crate::mesh::template::Mesh;

/// Errors from reading or writing mesh, texture and landmark files; each names the file.
#[derive(Debug, thiserror::Error)]
pub enum MeshIoError {
    /// The file could not be opened, read or written.
    #[error("{}: {action}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// What was being done ("cannot read", "cannot write").
        action: &'static str,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The file extension is not a supported mesh format.
    #[error("{}: unsupported mesh format (expected .ply, .glb or .gltf)", path.display())]
    UnsupportedFormat {
        /// The file.
        path: PathBuf,
    },
    /// The PLY file is malformed or lacks required elements or properties.
    #[error("{}: invalid PLY file: {message}", path.display())]
    Ply {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The glTF file is malformed or lacks required data.
    #[error("{}: invalid glTF file: {message}", path.display())]
    Gltf {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The texture image could not be read or decoded.
    #[error("{}: cannot read texture image: {message}", path.display())]
    Texture {
        /// The texture image file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The mesh has no per-vertex colours and no default colour was given.
    #[error(
        "{}: the mesh has no per-vertex colours (red/green/blue); pass --default-color R,G,B to use a constant colour",
        path.display()
    )]
    NoColors {
        /// The mesh file.
        path: PathBuf,
    },
    /// A glTF mesh has no texture image, no vertex colours and no default colour was given.
    #[error(
        "{}: the glTF file has no embedded texture image or vertex colours; pass --texture IMAGE (or --default-color R,G,B)",
        path.display()
    )]
    NoTexture {
        /// The mesh file.
        path: PathBuf,
    },
    /// The mesh data is invalid (non-finite coordinate, index out of range, non-manifold edge, empty mesh, ...).
    #[error("{}: {message}", path.display())]
    InvalidMesh {
        /// The mesh file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The landmark file is malformed.
    #[error("{}: invalid landmark file: {message}", path.display())]
    Landmarks {
        /// The landmark file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

impl MeshIoError {
    fn invalid(path: &Path, message: impl Into<String>) -> Self {
        MeshIoError::InvalidMesh { path: path.to_path_buf(), message: message.into() }
    }
    fn ply(path: &Path, message: impl Into<String>) -> Self {
        MeshIoError::Ply { path: path.to_path_buf(), message: message.into() }
    }
    fn gltf(path: &Path, message: impl Into<String>) -> Self {
        MeshIoError::Gltf { path: path.to_path_buf(), message: message.into() }
    }
    fn texture(path: &Path, message: impl Into<String>) -> Self {
        MeshIoError::Texture { path: path.to_path_buf(), message: message.into() }
    }
    fn read(path: &Path, source: std::io::Error) -> Self {
        MeshIoError::Io { path: path.to_path_buf(), action: "cannot read", source }
    }
    fn write(path: &Path, source: std::io::Error) -> Self {
        MeshIoError::Io { path: path.to_path_buf(), action: "cannot write", source }
    }
}

/// Where the colours of a mesh read by [`read_mesh_with_info`] came from.
#[derive(Debug, Clone, PartialEq)]
pub enum ColorSource {
    /// Per-vertex colours stored in the file.
    Vertex,
    /// Sampled from a texture image (its path, or `FILE#image` for an image embedded in a glTF file).
    Texture(String),
    /// The constant default colour.
    Default,
}

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
/// a non-finite coordinate or colour, a colour outside [0,1], a triangle index
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

/// A colour component in [0,1]: integers are 0-255 (`ushort`: 0-65535), floats already in [0,1].
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

// --------------------------------------------------------------- glTF input

/// An RGB texture in [0,1] with bilinear lookup.
struct Texture {
    width: usize,
    height: usize,
    rgb: Vec<[f32; 3]>,
}

impl Texture {
    fn from_image(img: image::DynamicImage) -> Self {
        let rgb = img.to_rgb32f();
        let (width, height) = (rgb.width() as usize, rgb.height() as usize);
        let rgb = rgb.pixels().map(|p| p.0).collect();
        Texture { width, height, rgb }
    }

    fn from_gltf(data: &gltf::image::Data) -> Option<Self> {
        use gltf::image::Format;
        let (w, h) = (data.width as usize, data.height as usize);
        let channels = match data.format {
            Format::R8 => 1,
            Format::R8G8 => 2,
            Format::R8G8B8 => 3,
            Format::R8G8B8A8 => 4,
            _ => return None,
        };
        if w == 0 || h == 0 || data.pixels.len() < w * h * channels {
            return None;
        }
        let rgb = data
            .pixels
            .chunks_exact(channels)
            .take(w * h)
            .map(|p| {
                let g = |k: usize| f32::from(p[k.min(channels - 1)]) / 255.0;
                if channels < 3 {
                    [g(0), g(0), g(0)]
                } else {
                    [g(0), g(1), g(2)]
                }
            })
            .collect();
        Some(Texture { width: w, height: h, rgb })
    }

    /// Bilinear sample at texture coordinates (u right, v up: row = (1 - v) * height), wrapping.
    fn sample(&self, u: f64, v: f64) -> [f64; 3] {
        let (w, h) = (self.width as f64, self.height as f64);
        let x = u * w - 0.5;
        let y = (1.0 - v) * h - 0.5;
        if !x.is_finite() || !y.is_finite() || self.rgb.is_empty() {
            return [0.0; 3];
        }
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let wrap = |i: f64, n: usize| -> usize { (i.rem_euclid(n as f64) as usize).min(n - 1) };
        let (xa, xb) = (wrap(x0, self.width), wrap(x0 + 1.0, self.width));
        let (ya, yb) = (wrap(y0, self.height), wrap(y0 + 1.0, self.height));
        let px = |xi: usize, yi: usize| self.rgb.get(yi * self.width + xi).copied().unwrap_or([0.0; 3]);
        let (p00, p10, p01, p11) = (px(xa, ya), px(xb, ya), px(xa, yb), px(xb, yb));
        let mut out = [0.0; 3];
        for k in 0..3 {
            let top = f64::from(p00[k]) * (1.0 - fx) + f64::from(p10[k]) * fx;
            let bottom = f64::from(p01[k]) * (1.0 - fx) + f64::from(p11[k]) * fx;
            out[k] = (top * (1.0 - fy) + bottom * fy).clamp(0.0, 1.0);
        }
        out
    }
}

/// Reads an image file as a texture; errors name the image.
fn read_texture(path: &Path) -> Result<Texture, MeshIoError> {
    let reader = image::ImageReader::open(path)
        .map_err(|e| MeshIoError::texture(path, e.to_string()))?
        .with_guessed_format()
        .map_err(|e| MeshIoError::texture(path, e.to_string()))?;
    let img = reader.decode().map_err(|e| MeshIoError::texture(path, e.to_string()))?;
    if img.width() == 0 || img.height() == 0 {
        return Err(MeshIoError::texture(path, "the image is empty"));
    }
    Ok(Texture::from_image(img))
}

/// A glTF primitive's vertices before welding.
#[derive(Default)]
struct RawVertices {
    positions: Vec<[f64; 3]>,
    colors: Vec<[f64; 3]>,
    triangles: Vec<[u32; 3]>,
}

type Mat4 = [[f64; 4]; 4];

fn mat_mul(a: &Mat4, b: &Mat4) -> Mat4 {
    // Column-major like glTF: m[col][row].
    let mut out = [[0.0; 4]; 4];
    for (c, col) in out.iter_mut().enumerate() {
        for (r, v) in col.iter_mut().enumerate() {
            *v = (0..4).map(|k| a[k][r] * b[c][k]).sum();
        }
    }
    out
}

fn transform_point(m: &Mat4, p: [f32; 3]) -> [f64; 3] {
    let p = [f64::from(p[0]), f64::from(p[1]), f64::from(p[2])];
    let mut out = [0.0; 3];
    for (r, o) in out.iter_mut().enumerate() {
        *o = m[0][r] * p[0] + m[1][r] * p[1] + m[2][r] * p[2] + m[3][r];
    }
    let w = m[0][3] * p[0] + m[1][3] * p[1] + m[2][3] * p[2] + m[3][3];
    if w != 0.0 && w != 1.0 {
        for o in out.iter_mut() {
            *o /= w;
        }
    }
    out
}

const IDENTITY: Mat4 = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];

fn read_gltf(path: &Path, texture: Option<&Path>, default_color: Option<[f64; 3]>) -> Result<(Mesh, ColorSource), MeshIoError> {
    let bytes = std::fs::read(path).map_err(|e| MeshIoError::read(path, e))?;
    // The texture override is read first so that an unreadable texture is reported as such.
    let override_tex = match texture {
        Some(t) => Some(read_texture(t)?),
        None => None,
    };
    // The gltf crate validates documents, but guard against a panic on malformed data anyway.
    let result =
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| read_gltf_inner(path, &bytes, override_tex, texture, default_color)));
    match result {
        Ok(r) => r,
        Err(_) => Err(MeshIoError::gltf(path, "malformed data")),
    }
}

fn read_gltf_inner(
    path: &Path,
    bytes: &[u8],
    override_tex: Option<Texture>,
    texture_path: Option<&Path>,
    default_color: Option<[f64; 3]>,
) -> Result<(Mesh, ColorSource), MeshIoError> {
    let gltf::Gltf { document, blob } = gltf::Gltf::from_slice(bytes).map_err(|e| MeshIoError::gltf(path, e.to_string()))?;
    let base = path.parent();
    let buffers = gltf::import_buffers(&document, base, blob).map_err(|e| MeshIoError::gltf(path, format!("cannot load buffers: {e}")))?;

    // Collect (mesh, world transform) pairs: the default scene, else every mesh untransformed.
    let mut instances: Vec<(gltf::Mesh, Mat4)> = Vec::new();
    let scene = document.default_scene().or_else(|| document.scenes().next());
    if let Some(scene) = scene {
        let mut visited = vec![false; document.nodes().len()];
        let mut stack: Vec<(gltf::Node, Mat4)> = scene.nodes().map(|n| (n, IDENTITY)).collect();
        while let Some((node, parent)) = stack.pop() {
            match visited.get_mut(node.index()) {
                Some(v) if !*v => *v = true,
                _ => continue,
            }
            let local = node.transform().matrix();
            let local: Mat4 = local.map(|c| c.map(f64::from));
            let world = mat_mul(&parent, &local);
            if let Some(mesh) = node.mesh() {
                instances.push((mesh, world));
            }
            for child in node.children() {
                stack.push((child, world));
            }
        }
        // Keep a deterministic order (by node traversal is fine, but sort by mesh index for clarity).
        instances.sort_by_key(|(m, _)| m.index());
    } else {
        instances = document.meshes().map(|m| (m, IDENTITY)).collect();
    }
    if instances.is_empty() {
        return Err(MeshIoError::gltf(path, "the file contains no meshes"));
    }

    // Embedded images are decoded only when needed.
    let mut images: Option<Vec<gltf::image::Data>> = None;
    let mut source = ColorSource::Vertex;
    let mut raw = RawVertices::default();
    for (mesh, world) in &instances {
        for prim in mesh.primitives() {
            if prim.mode() != gltf::mesh::Mode::Triangles {
                log::warn!(
                    "{}: skipping a primitive of mesh {} with mode {:?} (only triangles are read)",
                    path.display(),
                    mesh.index(),
                    prim.mode()
                );
                continue;
            }
            let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
            let positions: Vec<[f64; 3]> = reader
                .read_positions()
                .ok_or_else(|| MeshIoError::gltf(path, "a primitive has no POSITION"))?
                .map(|p| transform_point(world, p))
                .collect();
            let n = positions.len();
            let indices: Vec<u32> = match reader.read_indices() {
                Some(ix) => ix.into_u32().collect(),
                None => (0..n as u32).collect(),
            };
            if !indices.chunks_exact(3).remainder().is_empty() {
                return Err(MeshIoError::gltf(path, format!("a primitive has {} indices, not a multiple of 3", indices.len())));
            }
            // Colours of this primitive.
            let tex_info = prim.material().pbr_metallic_roughness().base_color_texture();
            let set = tex_info.as_ref().map_or(0, |t| t.tex_coord());
            let uvs: Option<Vec<[f32; 2]>> = reader.read_tex_coords(set).map(|t| t.into_f32().collect());
            let colors: Vec<[f64; 3]> = if let (Some(tex), Some(uvs)) = (&override_tex, &uvs) {
                source = ColorSource::Texture(texture_path.map(|p| p.display().to_string()).unwrap_or_default());
                sample_all(path, tex, uvs, n)?
            } else if let (Some(info), Some(uvs), None) = (&tex_info, &uvs, &override_tex) {
                if images.is_none() {
                    images = Some(
                        gltf::import_images(&document, base, &buffers)
                            .map_err(|e| MeshIoError::gltf(path, format!("cannot load images: {e}")))?,
                    );
                }
                let img_index = info.texture().source().index();
                let tex = images
                    .as_ref()
                    .and_then(|imgs| imgs.get(img_index))
                    .and_then(Texture::from_gltf)
                    .ok_or_else(|| MeshIoError::gltf(path, format!("image {img_index} has an unsupported format")))?;
                source = ColorSource::Texture(format!("{}#image{img_index}", path.display()));
                sample_all(path, &tex, uvs, n)?
            } else if let Some(cols) = reader.read_colors(0) {
                let cols: Vec<[f64; 3]> = cols.into_rgb_f32().map(|c| c.map(f64::from)).collect();
                if cols.len() != n {
                    return Err(MeshIoError::gltf(path, "COLOR_0 and POSITION counts differ"));
                }
                cols
            } else if let Some(c) = default_color {
                source = ColorSource::Default;
                vec![c; n]
            } else if override_tex.is_some() {
                return Err(MeshIoError::gltf(path, "a primitive has no TEXCOORD_0 to sample the texture at"));
            } else {
                return Err(MeshIoError::NoTexture { path: path.to_path_buf() });
            };
            let offset = raw.positions.len() as u64;
            for (t, tri) in indices.chunks_exact(3).enumerate() {
                let mut out = [0u32; 3];
                for k in 0..3 {
                    let i = tri[k];
                    if i as usize >= n {
                        return Err(MeshIoError::invalid(
                            path,
                            format!("triangle {t} of mesh {} refers to vertex {i} but the primitive has {n} vertices", mesh.index()),
                        ));
                    }
                    out[k] = u32::try_from(offset + u64::from(i)).map_err(|_| MeshIoError::gltf(path, "too many vertices"))?;
                }
                raw.triangles.push(out);
            }
            raw.positions.extend(positions);
            raw.colors.extend(colors);
        }
    }
    for (i, p) in raw.positions.iter().enumerate() {
        if p.iter().any(|v| !v.is_finite()) {
            return Err(MeshIoError::invalid(path, format!("vertex {i} has a non-finite coordinate")));
        }
    }
    Ok((weld(raw), source))
}

fn sample_all(path: &Path, tex: &Texture, uvs: &[[f32; 2]], n: usize) -> Result<Vec<[f64; 3]>, MeshIoError> {
    if uvs.len() != n {
        return Err(MeshIoError::gltf(path, "TEXCOORD and POSITION counts differ"));
    }
    Ok(uvs.iter().map(|uv| tex.sample(f64::from(uv[0]), f64::from(uv[1]))).collect())
}

/// Welds vertices at the same position (within 1e-6 of the bounding-box
/// diagonal); the result is ordered lexicographically by position and colours
/// of merged vertices are averaged.
fn weld(raw: RawVertices) -> Mesh {
    let n = raw.positions.len();
    if n == 0 {
        return Mesh { positions: raw.positions, colors: raw.colors, triangles: raw.triangles };
    }
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in &raw.positions {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let diag = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
    let tol = 1e-6 * diag;

    // Cluster vertices within `tol` (per axis) with union-find over a hash grid
    // of cell size `tol`: near vertices are in the same or a neighbouring cell.
    let cmp = |a: &[f64; 3], b: &[f64; 3]| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])).then(a[2].total_cmp(&b[2]));
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| cmp(&raw.positions[a], &raw.positions[b]).then(a.cmp(&b)));
    let mut parent: Vec<usize> = (0..n).collect();
    fn find(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    let cell = if tol > 0.0 { tol } else { 1.0 };
    let key = |p: &[f64; 3]| p.map(|v| (v / cell).floor() as i64);
    let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::with_capacity(n);
    for &a in &order {
        let pa = raw.positions[a];
        let ka = key(&pa);
        for dx in -1..=1i64 {
            for dy in -1..=1i64 {
                for dz in -1..=1i64 {
                    let kb = [ka[0].saturating_add(dx), ka[1].saturating_add(dy), ka[2].saturating_add(dz)];
                    let Some(list) = grid.get(&kb) else { continue };
                    for &b in list {
                        let pb = raw.positions[b];
                        if (0..3).all(|k| (pb[k] - pa[k]).abs() <= tol) {
                            let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
                            if ra != rb {
                                parent[ra.max(rb)] = ra.min(rb);
                            }
                        }
                    }
                }
            }
        }
        grid.entry(ka).or_default().push(a);
    }
    // Each cluster is represented by its smallest position; order clusters by that.
    let mut rep_pos: HashMap<usize, [f64; 3]> = HashMap::new();
    for &i in &order {
        let r = find(&mut parent, i);
        rep_pos.entry(r).or_insert(raw.positions[i]);
    }
    let mut roots: Vec<(usize, [f64; 3])> = rep_pos.into_iter().collect();
    roots.sort_by(|a, b| cmp(&a.1, &b.1).then(a.0.cmp(&b.0)));
    let mut new_index: HashMap<usize, u32> = HashMap::with_capacity(roots.len());
    for (k, (r, _)) in roots.iter().enumerate() {
        new_index.insert(*r, k as u32);
    }
    let m = roots.len();
    let positions: Vec<[f64; 3]> = roots.iter().map(|(_, p)| *p).collect();
    let mut sums = vec![[0.0; 3]; m];
    let mut counts = vec![0usize; m];
    let mut map = vec![0u32; n];
    for (i, (slot, color)) in map.iter_mut().zip(&raw.colors).enumerate() {
        let r = find(&mut parent, i);
        let k = new_index.get(&r).copied().unwrap_or(0);
        *slot = k;
        let ku = k as usize;
        counts[ku] += 1;
        for (sum, c) in sums[ku].iter_mut().zip(color) {
            *sum += c;
        }
    }
    let colors = sums.iter().zip(&counts).map(|(s, &c)| s.map(|v| v / c.max(1) as f64)).collect();
    let triangles = raw.triangles.iter().map(|t| t.map(|i| map[i as usize])).collect();
    Mesh { positions, colors, triangles }
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
    if mesh.colors.len() != mesh.positions.len() {
        return Err(MeshIoError::invalid(
            path,
            format!("cannot write a mesh with {} colours for {} vertices", mesh.colors.len(), mesh.positions.len()),
        ));
    }
    let file = File::create(path).map_err(|e| MeshIoError::write(path, e))?;
    let mut w = BufWriter::new(file);
    write_ply_to(&mut w, mesh, encoding, comments).and_then(|_| w.flush()).map_err(|e| MeshIoError::write(path, e))
}

fn to_u8(c: f64) -> u8 {
    (c.clamp(0.0, 1.0) * 255.0).round() as u8
}

fn write_ply_to<W: Write>(w: &mut W, mesh: &Mesh, encoding: PlyEncoding, comments: &[&str]) -> std::io::Result<()> {
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
    writeln!(w, "element face {}", mesh.triangles.len())?;
    writeln!(w, "property list uchar int vertex_indices\nend_header")?;
    match encoding {
        PlyEncoding::BinaryLittleEndian => {
            for (p, c) in mesh.positions.iter().zip(&mesh.colors) {
                for v in p {
                    w.write_all(&(*v as f32).to_le_bytes())?;
                }
                w.write_all(&c.map(to_u8))?;
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
            for (p, c) in mesh.positions.iter().zip(&mesh.colors) {
                let c = c.map(to_u8);
                writeln!(w, "{} {} {} {} {} {}", p[0] as f32, p[1] as f32, p[2] as f32, c[0], c[1], c[2])?;
            }
            for t in &mesh.triangles {
                writeln!(w, "3 {} {} {}", t[0], t[1], t[2])?;
            }
        }
    }
    Ok(())
}
