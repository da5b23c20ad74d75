//! The template scan: a coloured triangle mesh with landmarks, normalized to
//! millimetres, centred and oriented, cropped to the face region and
//! optionally simplified. (Implementation in progress.)

use std::path::PathBuf;

/// A coloured triangle mesh in f64 (positions in the mesh's units, colours linear RGB in [0,1]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Mesh {
    /// Vertex positions.
    pub positions: Vec<[f64; 3]>,
    /// Per-vertex colours, same length as `positions`.
    pub colors: Vec<[f64; 3]>,
    /// Triangles as vertex indices (counter-clockwise seen from outside).
    pub triangles: Vec<[u32; 3]>,
}

/// Where a template came from and what was done to it (stored in model metadata).
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Provenance {
    /// The mesh file as given on the command line.
    pub source: String,
    /// SHA-256 of the mesh file's bytes, hex.
    pub source_sha256: String,
    /// Texture image, if colours were sampled from one.
    pub texture: Option<String>,
    /// Attribution line that must accompany anything built from the scan (from a LICENSE next to it, if any).
    pub attribution: Option<String>,
    /// Millimetres per source unit that was applied.
    pub scale_mm_per_unit: f64,
    /// Whether the face crop was applied.
    pub cropped: bool,
    /// Vertex count before cropping and simplification.
    pub source_vertices: usize,
}

/// A normalized template ready for model building.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Template {
    /// The mesh in millimetres, x right, y up, z toward the camera.
    pub mesh: Mesh,
    /// Landmark vertex ids (iBUG-68 order when `scheme == "ibug68"`).
    pub landmarks: Vec<u32>,
    /// Landmark scheme name from the landmark file.
    pub scheme: String,
    /// Provenance for the model metadata.
    pub provenance: Provenance,
}

/// How to import a template.
#[derive(Debug, Clone, Default)]
pub struct TemplateOptions {
    /// Texture image for glTF input (colours are sampled at the UVs).
    pub texture: Option<PathBuf>,
    /// Millimetres per source unit; default: outer eye corners (iBUG 36, 45) 90 mm apart.
    pub scale: Option<f64>,
    /// Skip the face crop.
    pub no_crop: bool,
    /// Simplify to at most this many vertices (landmark vertices are kept).
    pub vertices: Option<usize>,
    /// Colour to use when the mesh has none (otherwise a mesh without colours is an error).
    pub default_color: Option<[f64; 3]>,
}
