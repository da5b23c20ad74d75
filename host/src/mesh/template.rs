//! The template scan: a coloured triangle mesh with landmarks, normalized to
//! millimetres, centred and oriented, cropped to the face region and
//! optionally simplified ([`load_template`]).
//!
//! Steps:
//!
//! 1. **Read** the mesh ([`crate::mesh::io::read_mesh`]: PLY, or glTF +
//!    texture with seams welded; landmark ids of a glTF refer to the welded
//!    mesh ordered by position) and the landmarks
//!    ([`crate::mesh::io::read_landmarks_json`]); every landmark id must be a
//!    vertex of the mesh; the `ibug68` scheme needs exactly 68 ids.
//! 2. **Normalize**. For `ibug68`: the scale makes the outer eye corners
//!    (36, 45) [`OUTER_CANTHAL_MM`] = 90 mm apart, unless `scale` is given
//!    (then coordinates are multiplied by it). The x axis is the sum of the
//!    (image-right − image-left) vectors of the [`IBUG68_MIRROR_PAIRS`]
//!    (p16 − p0, p45 − p36, ...), normalized; y is the chin (8) → nose bridge
//!    (27) direction orthogonalized against x; z = x × y points toward the
//!    camera. The origin is the landmark centroid projected onto the mirror
//!    plane (the plane with normal x through the mean of the pairs'
//!    midpoints), so the face is bilaterally symmetric about x = 0. For any
//!    other scheme nothing face-specific happens: scale `scale` (default 1),
//!    origin at the vertex centroid, no rotation.
//! 3. **Crop** (`ibug68` only, unless `no_crop`), in the normalized mm frame,
//!    with d = eye–chin distance (mean height of the eye corners 36, 39, 42,
//!    45 minus the height of the chin 8) and the [`CropParams`] defaults. A
//!    vertex is inside the face region when both hold:
//!    * its (x, y) lies inside the face outline: the jaw contour 0..=16, each
//!      point pushed outward by 0.05 d (away from the point between the jaw
//!      ends at the nose tip's height), closed over the top by a half-ellipse
//!      from 16 to 0 whose top is 0.5 d above the higher brow (19/24), with
//!      the semi-axis half the distance between the pushed-out jaw ends;
//!    * its z is in front of the jaw contour's depth at that height on that
//!      side of x = 0 (interpolated along 0..=8 for x ≤ 0, 8..=16 for x > 0,
//!      held constant beyond the contour's ends), minus a margin growing from
//!      0.04 d at the jaw ends (0/16, which lie near the ears) to 0.15 d at
//!      the chin. This drops the ears, the back of the head and the neck
//!      (under the chin and behind the jaw line).
//!
//!    Triangles with all three vertices inside are kept, then only the
//!    connected components containing landmark vertices; vertices are
//!    compacted (keeping their order) and the landmark ids remapped. A
//!    landmark vertex left on no triangle is an error. On the Lee Perry-Smith
//!    scan this keeps 4,249 of 8,844 vertices: forehead to just below the
//!    chin, cheek to cheek up to the front of the ears. Without the crop,
//!    vertices used by no triangle are dropped (landmarks are kept).
//! 4. **Simplify** (`vertices = Some(n)`, when there are more than n
//!    vertices) with meshoptimizer's attribute-aware simplifier: landmark
//!    vertices locked, colours as attributes, the target index count
//!    3·triangles·n/vertices lowered until at most n vertices remain; then
//!    compacted and the landmarks remapped. Vertices are never moved, so the
//!    landmarks keep their positions.
//! 5. **Provenance**: source path, SHA-256 of the mesh file, texture,
//!    attribution (from a `LICENSE.txt` next to the mesh, see
//!    [`attribution_from_license`]), scale, whether cropped, source vertex count.

use crate::mesh::geometry::{add, centroid, cross, dot, mul, norm, point_in_polygon, sub};
use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

use crate::mesh::io::{read_landmarks_json, read_mesh_with_info, ColorSource, MeshIoError};

pub use crate::mesh::Mesh;

/// Where a template came from and what was done to it (stored in model metadata).
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Provenance {
    /// The mesh file's name, without its folder: a build gives the same bytes wherever the data
    /// lies (`source_sha256` names the file's contents).
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

/// Errors from template import; each names the file concerned.
#[derive(Debug, thiserror::Error)]
pub enum TemplateError {
    /// Reading the mesh, texture or landmark file failed (the message names the file).
    #[error(transparent)]
    MeshIo(#[from] MeshIoError),
    /// The landmarks do not fit the mesh or the scheme.
    #[error("{}: {message}", path.display())]
    Landmarks {
        /// The landmark file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// Normalization, cropping or simplification cannot be done as asked.
    #[error("{}: {message}", path.display())]
    Processing {
        /// The mesh file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The face crop or the simplification cannot be done as asked.
    #[error("{}: {error}", path.display())]
    Crop {
        /// The mesh file.
        path: PathBuf,
        /// What is wrong.
        error: CropError,
    },
    /// An option is invalid.
    #[error("{message}")]
    Options {
        /// What is wrong.
        message: String,
    },
}

/// Number of landmarks of the iBUG-68 scheme (the core's one definition).
pub use gpmm_core::model::ibug::IBUG68_POINTS as IBUG68_COUNT;

/// Outer canthal distance (iBUG 36 to 45) that the default scale maps to, in millimetres.
pub const OUTER_CANTHAL_MM: f64 = 90.0;

/// The iBUG-68 bilateral pairs (the core's one definition, shared with the initializer's mirror read).
pub use gpmm_core::model::ibug::IBUG68_MIRROR_PAIRS;

/// The documented default face crop, in normalized millimetre coordinates (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CropParams {
    /// Outward offset of the jaw contour, as a fraction of the eye–chin distance.
    pub jaw_margin: f64,
    /// Height of the forehead arc's top above the higher brow (iBUG 19/24), as a fraction of the eye–chin distance.
    pub forehead: f64,
    /// Depth margin behind the jaw contour at its upper ends (iBUG 0/16, near the ears), as a fraction of the eye–chin distance.
    pub back_ear: f64,
    /// Depth margin behind the jaw contour at the chin (iBUG 8), as a fraction of the eye–chin distance.
    pub back_chin: f64,
}

impl Default for CropParams {
    fn default() -> Self {
        CropParams { jaw_margin: 0.05, forehead: 0.5, back_ear: 0.04, back_chin: 0.15 }
    }
}

/// Loads, validates, normalizes, crops and simplifies a template (see the module docs).
pub fn load_template(mesh_path: &Path, landmarks_path: &Path, opts: &TemplateOptions) -> Result<Template, TemplateError> {
    if let Some(s) = opts.scale {
        if !(s.is_finite() && s > 0.0) {
            return Err(TemplateError::Options { message: format!("the scale must be a positive number, got {s}") });
        }
    }
    if opts.vertices == Some(0) {
        return Err(TemplateError::Options { message: "the vertex budget must be positive".into() });
    }
    let (scheme, landmarks) = read_landmarks_json(landmarks_path)?;
    let (mesh, color_source) = read_mesh_with_info(mesh_path, opts.texture.as_deref(), opts.default_color)?;
    let bytes = std::fs::read(mesh_path).map_err(|e| MeshIoError::Io { path: mesh_path.to_path_buf(), action: "cannot read", error: e })?;
    let sha = Sha256::digest(&bytes);
    let source_sha256 = sha.iter().map(|b| format!("{b:02x}")).collect::<String>();
    let n = mesh.positions.len();
    let lm_err = |message: String| TemplateError::Landmarks { path: landmarks_path.to_path_buf(), message };
    for (k, &id) in landmarks.iter().enumerate() {
        if id as usize >= n {
            return Err(lm_err(format!("landmark {k} refers to vertex {id} but the mesh has {n} vertices")));
        }
    }
    let is_ibug = scheme == "ibug68";
    if is_ibug && landmarks.len() != IBUG68_COUNT {
        return Err(lm_err(format!("scheme ibug68 needs {IBUG68_COUNT} landmarks, the file has {}", landmarks.len())));
    }

    let proc_err = |error: CropError| TemplateError::Crop { path: mesh_path.to_path_buf(), error };
    let mut mesh = mesh;
    let mut landmarks = landmarks;
    let scale = if is_ibug {
        let lm: Vec<[f64; 3]> = landmarks.iter().map(|&i| mesh.positions[i as usize]).collect();
        let frame = ibug_frame(&lm).map_err(|m| lm_err(m.to_string()))?;
        let scale = match opts.scale {
            Some(s) => s,
            None => OUTER_CANTHAL_MM / frame.canthal,
        };
        apply_frame(&mut mesh, frame.center, &frame.axes, scale);
        scale
    } else {
        let scale = opts.scale.unwrap_or(1.0);
        let c = centroid(mesh.positions.iter().copied());
        apply_frame(&mut mesh, c, &[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], scale);
        scale
    };
    let source_vertices = n;

    let cropped = is_ibug && !opts.no_crop;
    if cropped {
        let lm: Vec<[f64; 3]> = landmarks.iter().map(|&i| mesh.positions[i as usize]).collect();
        let region = FaceRegion::new(&lm, &CropParams::default());
        let inside: Vec<bool> = mesh.positions.iter().map(|p| region.contains(p)).collect();
        let (m, l) = crop(&mesh, &landmarks, &inside).map_err(proc_err)?;
        mesh = m;
        landmarks = l;
    } else {
        // Drop vertices that no triangle uses (landmark vertices are kept).
        let (m, l) = compact(&mesh, &landmarks);
        mesh = m;
        landmarks = l;
    }
    if let Some(target) = opts.vertices {
        if mesh.positions.len() > target {
            let (m, l) = simplify(&mesh, &landmarks, target).map_err(proc_err)?;
            mesh = m;
            landmarks = l;
        }
    }
    let texture = match color_source {
        ColorSource::Texture(t) => Some(t),
        _ => None,
    };
    let provenance = Provenance {
        source: mesh_path.file_name().map_or_else(|| mesh_path.display().to_string(), |n| n.to_string_lossy().into_owned()),
        source_sha256,
        texture,
        attribution: read_attribution(mesh_path),
        scale_mm_per_unit: scale,
        cropped,
        source_vertices,
    };
    Ok(Template { mesh, landmarks, scheme, provenance })
}

// ------------------------------------------------------------ normalization

/// A face frame from iBUG-68 landmarks (in source units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaceFrame {
    /// Rows: the x (image right), y (up), z (toward the camera) unit axes.
    pub axes: [[f64; 3]; 3],
    /// The origin: landmark centroid projected onto the mirror plane.
    pub center: [f64; 3],
    /// Outer canthal distance |p45 - p36|.
    pub canthal: f64,
}

/// Computes the face frame (x from the mirror pairs, y from chin to nose bridge, origin on
/// the mirror plane); `lm` are the 68 iBUG landmark positions.
pub fn ibug_frame(lm: &[[f64; 3]]) -> Result<FaceFrame, &'static str> {
    let p = |i: usize| lm.get(i).copied().unwrap_or([0.0; 3]);
    let canthal = norm(sub(p(45), p(36)));
    if !canthal.is_finite() || canthal <= 0.0 {
        return Err("landmarks 36 and 45 (outer eye corners) coincide");
    }
    let mut xsum = [0.0; 3];
    let mut mids = [0.0; 3];
    for &(l, r) in &IBUG68_MIRROR_PAIRS {
        xsum = add(xsum, sub(p(r), p(l)));
        mids = add(mids, mul(add(p(l), p(r)), 0.5));
    }
    let xn = norm(xsum);
    if !xn.is_finite() || xn <= 0.0 {
        return Err("the mirror landmark pairs give no left-right direction");
    }
    let x = mul(xsum, 1.0 / xn);
    let mid = mul(mids, 1.0 / IBUG68_MIRROR_PAIRS.len() as f64);
    let up = sub(p(27), p(8));
    let up = sub(up, mul(x, dot(up, x)));
    let yn = norm(up);
    if !yn.is_finite() || yn <= 0.0 {
        return Err("landmarks 8 (chin) and 27 (nose bridge) give no up direction");
    }
    let y = mul(up, 1.0 / yn);
    let z = cross(x, y);
    let c = centroid(lm.iter().copied());
    let center = sub(c, mul(x, dot(sub(c, mid), x)));
    Ok(FaceFrame { axes: [x, y, z], center, canthal })
}

/// Maps every vertex `p` to `scale * axes * (p - center)`.
fn apply_frame(mesh: &mut Mesh, center: [f64; 3], axes: &[[f64; 3]; 3], scale: f64) {
    for p in mesh.positions.iter_mut() {
        let d = sub(*p, center);
        *p = [scale * dot(axes[0], d), scale * dot(axes[1], d), scale * dot(axes[2], d)];
    }
}

// --------------------------------------------------------------------- crop

/// The face region in normalized coordinates (see the module docs).
struct FaceRegion {
    /// Closed outline polygon in the (x, y) plane.
    outline: Vec<[f64; 2]>,
    /// Depth bound profiles (y, z_min) along the image-left (0..=8) and image-right (8..=16) jaw contour, sorted by y.
    profiles: [Vec<[f64; 2]>; 2],
}

impl FaceRegion {
    fn new(lm: &[[f64; 3]], params: &CropParams) -> Self {
        let p = |i: usize| lm.get(i).copied().unwrap_or([0.0; 3]);
        let eye_y = (p(36)[1] + p(39)[1] + p(42)[1] + p(45)[1]) / 4.0;
        let d = (eye_y - p(8)[1]).abs().max(1e-9);
        let margin = params.jaw_margin * d;
        // Centre of the jaw contour's expansion: between the jaw ends, at the nose tip's height.
        let c = [(p(0)[0] + p(16)[0]) / 2.0, p(30)[1]];
        let mut outline: Vec<[f64; 2]> = (0..=16)
            .map(|i| {
                let q = [p(i)[0], p(i)[1]];
                let v = [q[0] - c[0], q[1] - c[1]];
                let len = (v[0] * v[0] + v[1] * v[1]).sqrt().max(1e-12);
                [q[0] + v[0] / len * margin, q[1] + v[1] / len * margin]
            })
            .collect();
        // Forehead: half an ellipse from the right jaw end (16) over the top back to the left one (0).
        let (l, r) = (outline[0], outline[16]);
        let base_y = (l[1] + r[1]) / 2.0;
        let xc = (l[0] + r[0]) / 2.0;
        let a = (r[0] - l[0]).abs() / 2.0;
        let top = p(19)[1].max(p(24)[1]) + params.forehead * d;
        let b = (top - base_y).max(0.0);
        const ARC: usize = 24;
        for k in 1..ARC {
            let t = std::f64::consts::PI * k as f64 / ARC as f64;
            outline.push([xc + a * t.cos(), base_y + b * t.sin()]);
        }
        let profile = |ids: std::ops::RangeInclusive<usize>| {
            let mut v: Vec<[f64; 2]> = ids
                .map(|i| {
                    // The margin grows linearly from the jaw ends (0, 16) to the chin (8).
                    let t = 1.0 - (i as f64 - 8.0).abs() / 8.0;
                    let back = params.back_ear + t * (params.back_chin - params.back_ear);
                    [p(i)[1], p(i)[2] - back * d]
                })
                .collect();
            v.sort_by(|a, b| a[0].total_cmp(&b[0]));
            v
        };
        FaceRegion { outline, profiles: [profile(0..=8), profile(8..=16)] }
    }

    /// The depth bound at height `y` on one side (clamped beyond the contour's ends).
    fn z_min(&self, side: usize, y: f64) -> f64 {
        let prof = &self.profiles[side.min(1)];
        let (Some(first), Some(last)) = (prof.first(), prof.last()) else {
            return f64::NEG_INFINITY;
        };
        if y <= first[0] {
            return first[1];
        }
        if y >= last[0] {
            return last[1];
        }
        for w in prof.windows(2) {
            let (a, b) = (w[0], w[1]);
            if y <= b[0] {
                let t = if b[0] > a[0] { (y - a[0]) / (b[0] - a[0]) } else { 0.0 };
                return a[1] + t * (b[1] - a[1]);
            }
        }
        last[1]
    }

    fn contains(&self, q: &[f64; 3]) -> bool {
        let side = usize::from(q[0] > 0.0);
        q[2] >= self.z_min(side, q[1]) && point_in_polygon(&self.outline, [q[0], q[1]])
    }
}

/// Why the face crop or the simplification of a template cannot be done.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CropError {
    /// The crop needs the iBUG-68 landmarks, inside the mesh.
    #[error("the face crop needs {IBUG68_COUNT} landmark ids inside the mesh")]
    Landmarks,
    /// A landmark vertex would be cut away.
    #[error("the face crop would drop landmark {index} (vertex {vertex}); check the landmarks or pass --no-crop")]
    DropsLandmark {
        /// The landmark's index.
        index: usize,
        /// Its vertex id.
        vertex: u32,
    },
    /// The simplification failed.
    #[error("{0}")]
    Simplify(crate::mesh::simplify::SimplifyError),
    /// The simplification left a landmark vertex on no triangle.
    #[error("simplification left landmark {0} on no triangle; use a larger vertex budget")]
    LandmarkOffMesh(usize),
}

/// The vertices (ascending original indices) that the default face crop of step 3 keeps of a mesh
/// already in the normalized frame (mm, x right, y up, z toward the camera) with iBUG-68 `landmarks`.
pub fn face_crop_indices(mesh: &Mesh, landmarks: &[u32]) -> Result<Vec<u32>, CropError> {
    if landmarks.len() != IBUG68_COUNT || landmarks.iter().any(|&i| i as usize >= mesh.positions.len()) {
        return Err(CropError::Landmarks);
    }
    let lm: Vec<[f64; 3]> = landmarks.iter().map(|&i| mesh.positions[i as usize]).collect();
    let region = FaceRegion::new(&lm, &CropParams::default());
    let inside: Vec<bool> = mesh.positions.iter().map(|p| region.contains(p)).collect();
    // Crop a copy whose colours carry the vertex indices (exact in f64), then read them back.
    let tagged = Mesh {
        positions: mesh.positions.clone(),
        colors: (0..mesh.positions.len()).map(|i| [i as f64, 0.0, 0.0]).collect(),
        triangles: mesh.triangles.clone(),
    };
    let (kept, _) = crop(&tagged, landmarks, &inside)?;
    Ok(kept.colors.iter().map(|c| c[0] as u32).collect())
}

/// Keeps triangles with all vertices inside, then the connected components
/// containing landmark vertices; compacts and remaps the landmarks.
fn crop(mesh: &Mesh, landmarks: &[u32], inside: &[bool]) -> Result<(Mesh, Vec<u32>), CropError> {
    let kept: Vec<[u32; 3]> =
        mesh.triangles.iter().filter(|t| t.iter().all(|&i| inside.get(i as usize).copied().unwrap_or(false))).copied().collect();
    let n = mesh.positions.len();
    let mut uf = UnionFind::new(n);
    let mut used = vec![false; n];
    for t in &kept {
        uf.union(t[0] as usize, t[1] as usize);
        uf.union(t[1] as usize, t[2] as usize);
        for &i in t {
            used[i as usize] = true;
        }
    }
    for (k, &id) in landmarks.iter().enumerate() {
        if !used.get(id as usize).copied().unwrap_or(false) {
            return Err(CropError::DropsLandmark { index: k, vertex: id });
        }
    }
    let mut keep_root = vec![false; n];
    for &id in landmarks {
        let r = uf.find(id as usize);
        keep_root[r] = true;
    }
    let tris: Vec<[u32; 3]> = kept.into_iter().filter(|t| keep_root[uf.find(t[0] as usize)]).collect();
    let cropped = Mesh { positions: mesh.positions.clone(), colors: mesh.colors.clone(), triangles: tris };
    Ok(compact(&cropped, landmarks))
}

struct UnionFind {
    parent: Vec<usize>,
}

impl UnionFind {
    fn new(n: usize) -> Self {
        UnionFind { parent: (0..n).collect() }
    }
    fn find(&mut self, mut i: usize) -> usize {
        while self.parent[i] != i {
            self.parent[i] = self.parent[self.parent[i]];
            i = self.parent[i];
        }
        i
    }
    fn union(&mut self, a: usize, b: usize) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            self.parent[ra.max(rb)] = ra.min(rb);
        }
    }
}

/// Drops vertices used by no triangle (landmark vertices are always kept),
/// keeping the vertex order, and remaps triangles and landmarks.
fn compact(mesh: &Mesh, landmarks: &[u32]) -> (Mesh, Vec<u32>) {
    let n = mesh.positions.len();
    let mut keep = vec![false; n];
    for t in &mesh.triangles {
        for &i in t {
            keep[i as usize] = true;
        }
    }
    for &id in landmarks {
        keep[id as usize] = true;
    }
    let mut map = vec![u32::MAX; n];
    let mut out = Mesh::default();
    for i in 0..n {
        if keep[i] {
            map[i] = out.positions.len() as u32;
            out.positions.push(mesh.positions[i]);
            out.colors.push(mesh.colors[i]);
        }
    }
    out.triangles = mesh.triangles.iter().map(|t| t.map(|i| map[i as usize])).collect();
    let lms = landmarks.iter().map(|&i| map[i as usize]).collect();
    (out, lms)
}

// ----------------------------------------------------------------- simplify

/// Simplifies to at most `target` vertices ([`crate::mesh::simplify`]), landmark vertices locked.
fn simplify(mesh: &Mesh, landmarks: &[u32], target: usize) -> Result<(Mesh, Vec<u32>), CropError> {
    let positions: Vec<[f32; 3]> = mesh.positions.iter().map(|p| p.map(|v| v as f32)).collect();
    let colors: Vec<[f32; 3]> = mesh.colors.iter().map(|c| c.map(|v| v as f32)).collect();
    let tris =
        crate::mesh::simplify::simplify_to(&positions, &colors, &mesh.triangles, landmarks, target).map_err(CropError::Simplify)?.triangles;
    let simplified = Mesh { positions: mesh.positions.clone(), colors: mesh.colors.clone(), triangles: tris };
    let (m, l) = compact(&simplified, landmarks);
    let mut lm_used = vec![false; m.positions.len()];
    for t in &m.triangles {
        for &i in t {
            lm_used[i as usize] = true;
        }
    }
    if let Some(k) = l.iter().position(|&i| !lm_used[i as usize]) {
        return Err(CropError::LandmarkOffMesh(k));
    }
    Ok((m, l))
}

// -------------------------------------------------------------- attribution

/// Builds a one-line attribution from a `LICENSE.txt` (or `LICENSE`) next to the mesh, if any.
fn read_attribution(mesh_path: &Path) -> Option<String> {
    let dir = mesh_path.parent()?;
    let text = ["LICENSE.txt", "LICENSE", "LICENSE.md"].iter().find_map(|n| std::fs::read_to_string(dir.join(n)).ok())?;
    Some(attribution_from_license(&text)).filter(|s| !s.is_empty())
}

/// Turns licence text into one attribution line.
///
/// A Creative Commons notice "TITLE by AUTHOR is licensed under a Creative
/// Commons Attribution 3.0 Unported License. Based on a work at SITE." becomes
/// `"TITLE" by AUTHOR, CC BY 3.0 (based on a work at SITE)`; otherwise the
/// first non-empty line that is not a bare heading is returned.
pub fn attribution_from_license(text: &str) -> String {
    let lines: Vec<&str> = text.lines().map(str::trim).filter(|l| !l.is_empty()).collect();
    let based_on = lines.iter().find_map(|l| {
        let lower = l.to_ascii_lowercase();
        lower.find("based on a work at ").map(|i| l[i + "based on a work at ".len()..].trim_end_matches('.').trim())
    });
    for line in &lines {
        if let Some(i) = line.find(" is licensed under ") {
            let work = line[..i].trim();
            let licence = line[i + " is licensed under ".len()..].trim_end_matches('.').trim_start_matches("a ").trim_start_matches("an ");
            let work = match work.rfind(" by ") {
                Some(j) => format!("\"{}\" by {}", &work[..j], &work[j + 4..]),
                None => work.to_string(),
            };
            let mut out = format!("{work}, {}", short_licence(licence));
            if let Some(site) = based_on {
                out.push_str(&format!(" (based on a work at {site})"));
            }
            return out;
        }
    }
    lines
        .iter()
        .find(|l| {
            let lower = l.to_ascii_lowercase();
            !(lower.ends_with("licence") || lower.ends_with("license")) || l.len() > 40
        })
        .or(lines.first())
        .map(|l| l.to_string())
        .unwrap_or_default()
}

/// "Creative Commons Attribution-ShareAlike 4.0 International License" -> "CC BY-SA 4.0".
fn short_licence(licence: &str) -> String {
    let lower = licence.to_ascii_lowercase();
    if !lower.starts_with("creative commons attribution") {
        return licence.to_string();
    }
    let mut s = String::from("CC BY");
    if lower.contains("noncommercial") {
        s.push_str("-NC");
    }
    if lower.contains("noderiv") {
        s.push_str("-ND");
    }
    if lower.contains("sharealike") {
        s.push_str("-SA");
    }
    if let Some(v) = licence.split_whitespace().find(|w| w.chars().next().is_some_and(|c| c.is_ascii_digit())) {
        s.push(' ');
        s.push_str(v);
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn template_attribution_from_cc_notice() {
        let text = "Creative Commons Licence\nInfinite, 3D Head Scan by Lee Perry-Smith is licensed under a Creative Commons Attribution 3.0 Unported License.\nBased on a work at www.triplegangers.com.\n";
        assert_eq!(
            attribution_from_license(text),
            "\"Infinite, 3D Head Scan\" by Lee Perry-Smith, CC BY 3.0 (based on a work at www.triplegangers.com)"
        );
        assert_eq!(short_licence("Creative Commons Attribution-NonCommercial-ShareAlike 4.0 International License"), "CC BY-NC-SA 4.0");
        assert_eq!(attribution_from_license("MIT License\n\nCopyright (c) 2024 Someone\n"), "Copyright (c) 2024 Someone");
    }

    #[test]
    fn template_point_in_polygon() {
        let square = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        assert!(point_in_polygon(&square, [0.5, 0.5]));
        assert!(!point_in_polygon(&square, [1.5, 0.5]));
        assert!(!point_in_polygon(&square, [0.5, -0.1]));
    }

    /// Symmetric synthetic landmarks, rotated and moved, are mapped back to the symmetric frame.
    #[test]
    fn template_frame_recovers_rotation() {
        let mut lm = vec![[0.0f64; 3]; IBUG68_COUNT];
        for (k, &(l, r)) in IBUG68_MIRROR_PAIRS.iter().enumerate() {
            let (a, y, z) = (10.0 + k as f64, 50.0 - 4.0 * k as f64, (k % 5) as f64 * 3.0);
            lm[l] = [-a, y, z];
            lm[r] = [a, y, z];
        }
        for (i, y) in [(8, -80.0), (27, 40.0), (28, 30.0), (29, 20.0), (30, 10.0), (33, 0.0)] {
            lm[i] = [0.0, y, 20.0];
        }
        // Rotate about an oblique axis and translate.
        let (c, s) = (0.8f64, 0.6f64);
        let rot = |p: [f64; 3]| -> [f64; 3] {
            let q = [c * p[0] - s * p[2], p[1], s * p[0] + c * p[2]];
            [q[0] + 5.0, c * q[1] - s * q[2] - 3.0, s * q[1] + c * q[2] + 7.0]
        };
        let moved: Vec<[f64; 3]> = lm.iter().map(|&p| rot(p)).collect();
        let frame = ibug_frame(&moved).unwrap();
        let mut mesh = Mesh { positions: moved, colors: vec![[0.0; 3]; IBUG68_COUNT], triangles: vec![] };
        apply_frame(&mut mesh, frame.center, &frame.axes, 1.0);
        let cy = lm.iter().map(|p| p[1]).sum::<f64>() / IBUG68_COUNT as f64;
        let cz = lm.iter().map(|p| p[2]).sum::<f64>() / IBUG68_COUNT as f64;
        for (a, b) in mesh.positions.iter().zip(&lm) {
            let want = [b[0], b[1] - cy, b[2] - cz];
            for k in 0..3 {
                assert!((a[k] - want[k]).abs() < 1e-9, "{a:?} vs {want:?}");
            }
        }
    }
}
