//! Synthetic face images with known truth: ICT-FaceKit identities, template albedo, random
//! light, known pose and camera ([`synthesize`], [`write_synth_dir`]).
//!
//! The "world" the faces come from is the ICT-FaceKit identity model (a real statistical face
//! model made by others, never the model we fit). Everything is deterministic for a seed: the
//! identity `i` uses its own random stream (seed, i), and each of its views its own stream
//! (seed, i, yaw index), so changing `count` does not change the faces that are kept.
//!
//! # Shape
//! `neutral.npy` (N×3, cm) + Σ_k w_k · `identity_modes.npy`\[k\] (K×N×3), w_k = s · z_k with
//! z_k ~ N(0, 1) and s = [`SynthOptions::identity_scale`] (the modes carry their own scale),
//! converted to millimetres (×10). Each identity is then put into the same frame as the template
//! (see [`crate::mesh::template`]): x is the sum of the (image-right − image-left) vectors of the
//! iBUG mirror pairs, y the chin (8) → nose bridge (27) direction orthogonalized against x,
//! z = x × y toward the camera, origin the landmark centroid projected onto the mirror plane;
//! no rescaling (identities keep their real size). A pose of yaw = pitch = roll = 0 is frontal.
//!
//! The ICT face area is an open surface. Its boundary loops (edges used by one triangle) are
//! found once; the longest (by length) is the outer border and stays open, every other loop
//! (the two eye holes and the mouth slit) is closed by a fan of triangles around a new vertex at
//! the loop's centroid, wound consistently with the loop's triangles. The ICT triangles are
//! counter-clockwise seen from outside (the renderer's front-face convention, checked on load
//! from the summed face normal in the face frame, and flipped if needed), so back faces are
//! culled ([`Cull::Clockwise`]).
//!
//! # Albedo
//! 1. **Transfer** (once, on the ICT neutral in the face frame): the template
//!    (`lee-perry-smith.ply` + `landmarks_ibug68.json`, imported by
//!    [`crate::mesh::template::load_template`] without cropping, in mm) is aligned to the ICT neutral
//!    by the least-squares similarity transform (Horn's quaternion method, with scale) from the
//!    51 non-jaw landmark pairs (iBUG 17-67; the jaw points are silhouette-dependent). Each ICT
//!    vertex takes the colour of its closest point on the aligned template surface: the closest
//!    template vertex (uniform-grid search), then the closest point on the triangles around it,
//!    with the colour interpolated barycentrically there.
//! 2. **Hole fans**: the centre vertex of an eye fan is near-black (a dark eye opening, shading
//!    to the eyelid colour at the rim); of the mouth fan, 40 % of the rim's mean colour; of any
//!    other loop, the rim's mean colour.
//! 3. **Per-identity variation** ([`AlbedoVariation`], smooth and low-frequency): colour =
//!    base × brightness × tint_c × exp(Σ_b a_b,c · exp(−|x − c_b|² / r_b²)), clamped to
//!    \[0, 1\], with brightness ~ U(0.8, 1.15), tint_c = exp(N(0, 0.05²)) per channel, and
//!    [`ALBEDO_BUMPS`] Gaussian bumps: centre c_b a random ICT vertex of the neutral, radius r_b
//!    ~ U(20, 60) mm, amplitude a_b,c = g + N(0, 0.04²) with a common g ~ N(0, 0.12²).
//!
//! # Views
//! For every identity and every yaw of [`SynthOptions::yaws_deg`]: pitch and roll ~
//! U(−m, m) with m = [`SynthOptions::max_pitch_roll_deg`]; horizontal field of view ~
//! U([`SynthOptions::fov_deg`]) → focal length f = size / 2 / tan(fov / 2) (pixels, square
//! image, principal point at the image centre); the face height H (chin 8 to 0.5·d above the
//! higher brow 19/24, d = eye-corner height − chin height) fills a fraction ~
//! U([`SynthOptions::face_fill`]) of the image height at distance f·H / (fill·size); the face
//! centre is moved off the optical axis by U(−5 %, 5 %) of the image side in x and y. The light
//! is ambient a ~ U(0.55, 0.85) (per-channel tint ×U(0.95, 1.05)) plus one directional term of
//! strength d ~ U(0.15, 0.45)·(per-channel ×U(0.95, 1.05)), capped at the ambient, from a
//! direction within 70° of the camera axis: irradiance a + d (n · l) ≥ a − d ≥ 0 for every
//! normal ([`ShLight::from_ambient_diffuse`]). The light lives in camera space.
//!
//! **Background**: a plain colour ~ U(0.1, 0.9)³ plus independent per-pixel Gaussian noise of
//! σ = [`SynthOptions::background_noise`] (default 0.02) on every channel, clamped. The face
//! pixels carry no noise. Colours are linear and written as-is (no gamma), 8 bits.
//!
//! # Files ([`write_synth_dir`])
//! Per image `NNNN_yawYY.png` (RGB8) and `NNNN_yawYY.pts` (the 68 projected landmark vertices
//! in the iBUG format of the photos' `.pts` files: `version: 1`, `n_points:  68`, `{`, one
//! `x y` per line, `}`), and one `truth.json` ([`TruthFile`]). **Coordinate convention**:
//! landmark coordinates are the camera's continuous, 0-based pixel coordinates: pixel (i, j)
//! covers \[i, i+1) × \[j, j+1), its centre is (i + 0.5, j + 0.5), x right, y down (exactly
//! the rasterizer's coordinates, [`gpmm_core::render::camera`]). Jaw landmarks 0-16 are the projected
//! vertices (not the silhouette); `landmarks_visible` flags landmarks hidden by the face itself
//! (depth test against the rendered depth buffer).

use std::path::{Path, PathBuf};

use gpmm_core::geometry::Vec3;
use gpmm_core::render::{vertex_stage, Camera, Cull, Pose, ProjectedVertex, ShLight, Tile, TileRasterizer, TileSink};
use image::{Rgb, RgbImage};
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;
use rand_xoshiro::Xoshiro256PlusPlus;
use serde::{Deserialize, Serialize};

mod albedo;
pub mod detector;
pub mod npy;
mod render;
mod shape;
mod world;

#[cfg(test)]
use crate::mesh::{
    align::Similarity,
    closest::{closest_on_triangle, Grid},
};
use albedo::*;
use render::*;
use shape::*;

use crate::mesh::geometry::{add, centroid, cross, dot, mul, norm, sub};
use crate::mesh::io::read_landmarks_json;
use crate::mesh::template::{load_template, TemplateError, TemplateOptions, IBUG68_COUNT};
use npy::NpyError;

/// Number of random Gaussian bumps of the per-identity albedo variation.
pub const ALBEDO_BUMPS: usize = 5;
/// Tile side of the rasterizer used here (pixels).
const TILE: usize = 32;
/// Per-tile-row triangle bin of the rasterizer used here.
const BIN: usize = 8192;
/// Largest accepted image side (pixels).
pub const MAX_SIZE: u32 = 4096;
/// Smallest accepted image side (pixels).
pub const MIN_SIZE: u32 = 16;

/// Options of a synthetic data set (see the module docs for what each random quantity is).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SynthOptions {
    /// ICT-FaceKit directory: `neutral.npy`, `identity_modes.npy`, `triangles.npy`, `landmarks_ibug68.json`.
    pub ict_dir: PathBuf,
    /// Template directory whose albedo is transferred: `lee-perry-smith.ply`, `landmarks_ibug68.json`.
    pub template_dir: PathBuf,
    /// Number of identities.
    pub count: usize,
    /// Seed of everything random.
    pub seed: u64,
    /// Yaw angles in degrees; every identity is rendered at each (positive turns the face toward the image right).
    pub yaws_deg: Vec<f32>,
    /// Image width and height (pixels).
    pub size: u32,
    /// Identity coefficients are `identity_scale · N(0, 1)`.
    pub identity_scale: f32,
    /// Use only the first this many identity modes (default: all).
    pub modes: Option<usize>,
    /// Pitch and roll are uniform in ±this (degrees).
    pub max_pitch_roll_deg: f32,
    /// Range of the horizontal field of view (degrees).
    pub fov_deg: [f32; 2],
    /// Range of the fraction of the image height the face (chin to forehead) fills.
    pub face_fill: [f32; 2],
    /// Standard deviation of the per-pixel background noise (colours in \[0, 1\]).
    pub background_noise: f32,
    /// Also write detector-like landmarks to `DIR/detector/` ([`detector::detector_landmarks`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub detector_noise: Option<detector::DetectorNoise>,
}

impl Default for SynthOptions {
    /// The defaults with the data directory of [`crate::data::default_data_dir`] (`$GPMM_DATA` or `../shared/data`).
    fn default() -> Self {
        Self::with_data_dir(&crate::data::default_data_dir())
    }
}

impl SynthOptions {
    /// The defaults with the ICT model and template inside the data directory `data`.
    pub fn with_data_dir(data: &Path) -> Self {
        Self {
            ict_dir: data.join("ict"),
            template_dir: data.join("template/lee-perry-smith"),
            count: 10,
            seed: 0,
            yaws_deg: vec![0.0, 15.0, 30.0, 45.0],
            size: 128,
            identity_scale: 1.0,
            modes: None,
            max_pitch_roll_deg: 5.0,
            fov_deg: [30.0, 40.0],
            face_fill: [0.6, 0.7],
            background_noise: 0.02,
            detector_noise: None,
        }
    }

    /// Checks every option (not the files).
    pub fn validate(&self) -> Result<(), SynthError> {
        let bad = |message: String| Err(SynthError::Options { message });
        if !(MIN_SIZE..=MAX_SIZE).contains(&self.size) {
            return bad(format!("image size {} is invalid: it must be {MIN_SIZE} to {MAX_SIZE} pixels", self.size));
        }
        if self.yaws_deg.is_empty() {
            return bad("at least one yaw angle is needed".into());
        }
        for &y in &self.yaws_deg {
            if !(y.is_finite() && y.abs() <= 90.0) {
                return bad(format!("yaw {y}° is invalid: it must be between -90 and 90 degrees"));
            }
        }
        let mut tags: Vec<String> = self.yaws_deg.iter().map(|&y| yaw_tag(y)).collect();
        tags.sort();
        if tags.windows(2).any(|w| w[0] == w[1]) {
            return bad(format!("the yaw angles {:?} repeat (file names would clash)", self.yaws_deg));
        }
        if !(self.identity_scale.is_finite() && self.identity_scale >= 0.0) {
            return bad(format!("identity scale {} is invalid: it must be a non-negative number", self.identity_scale));
        }
        if self.modes == Some(0) {
            return bad("the number of identity modes must be positive".into());
        }
        if !(self.max_pitch_roll_deg.is_finite() && (0.0..=45.0).contains(&self.max_pitch_roll_deg)) {
            return bad(format!("max pitch/roll {}° is invalid: it must be 0 to 45 degrees", self.max_pitch_roll_deg));
        }
        let [f0, f1] = self.fov_deg;
        if !(f0.is_finite() && f1.is_finite() && f0 > 1.0 && f1 < 150.0 && f0 <= f1) {
            return bad(format!("field of view range {f0}..{f1}° is invalid: need 1 < low <= high < 150"));
        }
        let [a, b] = self.face_fill;
        if !(a.is_finite() && b.is_finite() && a > 0.05 && b <= 1.5 && a <= b) {
            return bad(format!("face fill range {a}..{b} is invalid: need 0.05 < low <= high <= 1.5"));
        }
        if !(self.background_noise.is_finite() && (0.0..=0.5).contains(&self.background_noise)) {
            return bad(format!("background noise {} is invalid: it must be 0 to 0.5", self.background_noise));
        }
        Ok(())
    }
}

/// Why synthesis failed; every data error names its file.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    /// A file could not be read, written or created.
    #[error("{}: {action}: {error}", path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// What was being done.
        action: &'static str,
        /// The underlying error.
        error: std::io::Error,
    },
    /// A `.npy` file is missing or malformed.
    #[error(transparent)]
    Npy(#[from] NpyError),
    /// A data file is readable but its content does not fit (shapes, indices, landmarks).
    #[error("{}: {message}", path.display())]
    Data {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The template (albedo source) could not be imported.
    #[error("albedo template: {0}")]
    Template(TemplateError),
    /// An option is invalid.
    #[error("invalid synth option: {message}")]
    Options {
        /// What is wrong.
        message: String,
    },
    /// Rendering failed (should not happen with valid data).
    #[error("rendering failed: {message}")]
    Render {
        /// What went wrong.
        message: String,
    },
}

fn io_err<'a>(path: &'a Path, action: &'static str) -> impl FnOnce(std::io::Error) -> SynthError + 'a {
    move |error| SynthError::Io { path: path.to_path_buf(), action, error }
}

/// Which hole of the ICT face area a closed boundary loop is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum HoleKind {
    /// An eye opening (closed dark).
    Eye,
    /// The mouth slit.
    Mouth,
    /// Any other inner loop.
    Other,
}

/// An inner boundary loop closed by a fan around its centroid (vertex `center`).
#[derive(Debug, Clone, PartialEq)]
struct Fan {
    ring: Vec<u32>,
    center: u32,
    kind: HoleKind,
}

/// The per-identity albedo variation (see the module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AlbedoVariation {
    /// Global brightness factor.
    pub brightness: f32,
    /// Per-channel tint factor.
    pub tint: [f32; 3],
    /// Gaussian bumps: centre (mm, face frame of the ICT neutral), radius (mm), per-channel log-amplitude.
    pub bumps: Vec<AlbedoBump>,
}

/// One smooth bump of the albedo variation: colour ×= exp(amplitude · exp(−|x − centre|² / radius²)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AlbedoBump {
    /// Centre (mm).
    pub center: [f32; 3],
    /// Radius (mm).
    pub radius: f32,
    /// Per-channel log-amplitude.
    pub amplitude: [f32; 3],
}

/// One synthetic identity: coefficients, posable mesh (face frame, mm) and albedo.
#[derive(Debug, Clone, PartialEq)]
pub struct Identity {
    /// Identity number (0-based).
    pub id: usize,
    /// The ICT identity coefficients w.
    pub coefficients: Vec<f32>,
    /// Vertex positions in the identity's face frame (mm), fan centres included.
    pub positions: Vec<Vec3>,
    /// Vertex albedo (linear RGB in \[0, 1\]).
    pub albedo: Vec<Vec3>,
    /// How the albedo was varied.
    pub variation: AlbedoVariation,
}

/// The truth of one rendered image (one entry of `truth.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ImageTruth {
    /// Image file name (`NNNN_yawYY.png`).
    pub image: String,
    /// Landmark file name (`NNNN_yawYY.pts`).
    pub landmarks_file: String,
    /// Identity number.
    pub identity: usize,
    /// Index into the yaw list.
    pub yaw_index: usize,
    /// Yaw (degrees; positive turns the face toward the image right).
    pub yaw_deg: f32,
    /// Pitch (degrees; positive tilts the nose down).
    pub pitch_deg: f32,
    /// Roll (degrees; positive is counter-clockwise in the image).
    pub roll_deg: f32,
    /// Translation (mm, camera space) of the pose `p_cam = R p_face + t` (the face frame is described in the module docs).
    pub translation_mm: [f32; 3],
    /// Focal length (pixels).
    pub focal_px: f32,
    /// Horizontal field of view (degrees).
    pub fov_deg: f32,
    /// Principal point (pixels).
    pub principal_px: [f32; 2],
    /// Image width (pixels).
    pub width: u32,
    /// Image height (pixels).
    pub height: u32,
    /// SH light coefficients `[9][3]` (camera space, scalismo-faces order).
    pub light: [[f32; 3]; 9],
    /// Ambient irradiance of the light (RGB).
    pub light_ambient: [f32; 3],
    /// Strength of the directional term (RGB).
    pub light_diffuse: [f32; 3],
    /// Unit direction toward the light (camera space).
    pub light_direction: [f32; 3],
    /// Background base colour (linear RGB).
    pub background_rgb: [f32; 3],
    /// Background per-pixel noise σ.
    pub background_noise: f32,
    /// The ICT identity coefficients w of this identity.
    pub shape_coefficients: Vec<f32>,
    /// The 68 projected landmarks (continuous pixel coordinates, centres at +0.5).
    pub landmarks: Vec<[f32; 2]>,
    /// Whether each landmark is inside the image and not hidden by the face itself.
    pub landmarks_visible: Vec<bool>,
    /// Fraction of the image's pixels covered by the face.
    pub face_fraction: f32,
}

/// One identity's entry of `truth.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IdentityTruth {
    /// Identity number.
    pub id: usize,
    /// The ICT identity coefficients w.
    pub shape_coefficients: Vec<f32>,
    /// The albedo variation.
    pub albedo: AlbedoVariation,
}

/// The content of `truth.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TruthFile {
    /// Always `"gpmm-synth"`.
    pub format: String,
    /// Format version (1).
    pub version: u32,
    /// The seed.
    pub seed: u64,
    /// All options used.
    pub options: SynthOptions,
    /// The conventions of the numbers in this file, in words.
    pub conventions: String,
    /// Number of ICT vertices, identity modes used and triangles (fans included).
    pub ict: IctSummary,
    /// One entry per identity.
    pub identities: Vec<IdentityTruth>,
    /// One entry per image.
    pub images: Vec<ImageTruth>,
}

/// Sizes of the loaded ICT model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IctSummary {
    /// Vertices of the face area.
    pub vertices: usize,
    /// Identity modes used.
    pub modes: usize,
    /// Triangles rendered (hole fans included).
    pub triangles: usize,
    /// The closed holes.
    pub holes: Vec<HoleKind>,
    /// Whether the triangles were flipped to be counter-clockwise seen from outside.
    pub flipped: bool,
}

/// What [`write_synth_dir`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct SynthSummary {
    /// The output directory.
    pub out_dir: PathBuf,
    /// Number of images.
    pub images: usize,
    /// Number of identities.
    pub identities: usize,
    /// The `truth.json` path.
    pub truth: PathBuf,
}

/// One rendered image and its truth.
#[derive(Debug, Clone, PartialEq)]
pub struct SynthFace {
    /// The RGB8 image.
    pub image: RgbImage,
    /// Its truth.
    pub truth: ImageTruth,
}

/// The conventions string stored in `truth.json`.
pub const CONVENTIONS: &str = "Lengths in mm, angles in degrees. Pose: p_cam = R p_face + t, R = Rz(roll) Ry(yaw) Rx(pitch); \
positive yaw turns the face toward the image right, positive pitch tilts the nose down, positive roll is counter-clockwise in the image. \
Face frame: x right, y up, z toward the camera, origin at the iBUG-68 landmark centroid projected onto the mirror plane. \
Camera at the origin looking down -z; pixel (i, j) covers [i, i+1) x [j, j+1), centre (i+0.5, j+0.5), x right, y down; \
landmarks (.pts and here) are 0-based continuous pixel coordinates in that system. \
Light: 9x3 SH coefficients in camera space (scalismo-faces order and Lambert convolution). Colours linear RGB in [0, 1], no gamma.";

/// The loaded world: ICT model with closed holes and transferred albedo.
#[derive(Debug, Clone)]
pub struct SynthWorld {
    options: SynthOptions,
    n_ict: usize,
    n_modes: usize,
    neutral: Vec<[f64; 3]>,
    modes: Vec<f32>,
    triangles: Vec<[u32; 3]>,
    fans: Vec<Fan>,
    landmarks: Vec<u32>,
    base_albedo: Vec<Vec3>,
    neutral_face: Vec<[f64; 3]>,
    flipped: bool,
}

/// Renders every identity at every yaw and returns the images with their truth (identity-major order).
///
/// `progress(done, total)` is called after each image.
pub fn synthesize(opts: &SynthOptions, mut progress: impl FnMut(usize, usize)) -> Result<Vec<SynthFace>, SynthError> {
    let world = SynthWorld::load(opts)?;
    let total = opts.count * opts.yaws_deg.len();
    let mut out = Vec::with_capacity(total);
    for id in 0..opts.count {
        let identity = world.identity(id)?;
        for k in 0..opts.yaws_deg.len() {
            out.push(world.render_view(&identity, k)?);
            progress(out.len(), total);
        }
    }
    Ok(out)
}

/// Renders the data set into `out_dir` (created if needed): per image a PNG and a `.pts`, then `truth.json`.
///
/// Images are written as they are rendered; `progress(done, total)` is called after each.
pub fn write_synth_dir(opts: &SynthOptions, out_dir: &Path, mut progress: impl FnMut(usize, usize)) -> Result<SynthSummary, SynthError> {
    let world = SynthWorld::load(opts)?;
    std::fs::create_dir_all(out_dir).map_err(io_err(out_dir, "cannot create the output directory"))?;
    let total = opts.count * opts.yaws_deg.len();
    let mut identities = Vec::with_capacity(opts.count);
    let mut images = Vec::with_capacity(total);
    for id in 0..opts.count {
        let identity = world.identity(id)?;
        for k in 0..opts.yaws_deg.len() {
            let face = world.render_view(&identity, k)?;
            let png = out_dir.join(&face.truth.image);
            let mut bytes = Vec::new();
            face.image
                .write_to(&mut std::io::Cursor::new(&mut bytes), image::ImageFormat::Png)
                .map_err(|e| SynthError::Render { message: format!("PNG encoding: {e}") })?;
            std::fs::write(&png, bytes).map_err(io_err(&png, "cannot write"))?;
            let pts = out_dir.join(&face.truth.landmarks_file);
            std::fs::write(&pts, pts_string(&face.truth.landmarks)).map_err(io_err(&pts, "cannot write"))?;
            if let Some(noise) = &opts.detector_noise {
                let dir = out_dir.join("detector");
                std::fs::create_dir_all(&dir).map_err(io_err(&dir, "cannot create"))?;
                let noisy = detector::detector_landmarks(&face.truth.landmarks, noise, opts.seed, id as u64, k as u64);
                let path = dir.join(&face.truth.landmarks_file);
                std::fs::write(&path, pts_string(&noisy)).map_err(io_err(&path, "cannot write"))?;
            }
            images.push(face.truth);
            progress(images.len(), total);
        }
        identities.push(IdentityTruth { id, shape_coefficients: identity.coefficients, albedo: identity.variation });
    }
    let truth = TruthFile {
        format: "gpmm-synth".into(),
        version: 1,
        seed: opts.seed,
        options: opts.clone(),
        conventions: CONVENTIONS.into(),
        ict: world.summary(),
        identities,
        images,
    };
    let path = out_dir.join("truth.json");
    let text = serde_json::to_string_pretty(&truth).map_err(|e| SynthError::Render { message: format!("truth.json: {e}") })?;
    std::fs::write(&path, text).map_err(io_err(&path, "cannot write"))?;
    Ok(SynthSummary { out_dir: out_dir.to_path_buf(), images: truth.images.len(), identities: opts.count, truth: path })
}

/// Reads a `truth.json` written by [`write_synth_dir`].
pub fn read_truth(path: &Path) -> Result<TruthFile, SynthError> {
    let text = std::fs::read_to_string(path).map_err(io_err(path, "cannot read"))?;
    serde_json::from_str(&text).map_err(|e| SynthError::Data { path: path.to_path_buf(), message: format!("not a synth truth file: {e}") })
}

pub use crate::photo::pts::pts_string;

/// Tiles images (all the size of the first) into a grid of `columns` columns, row-major.
pub fn contact_sheet(faces: &[SynthFace], columns: usize) -> RgbImage {
    let Some(first) = faces.first() else {
        return RgbImage::new(1, 1);
    };
    let (w, h) = first.image.dimensions();
    let cols = columns.clamp(1, faces.len());
    let rows = faces.len().div_ceil(cols);
    let mut sheet = RgbImage::new(w * cols as u32, h * rows as u32);
    for (k, f) in faces.iter().enumerate() {
        let (x0, y0) = ((k % cols) as u32 * w, (k / cols) as u32 * h);
        for (x, y, p) in f.image.enumerate_pixels() {
            if x < w && y < h {
                sheet.put_pixel(x0 + x, y0 + y, *p);
            }
        }
    }
    sheet
}

// ---------------------------------------------------------------- helpers

/// The file-name tag of a yaw: `00`, `15`, `-30`, or the decimal value when not whole.
fn yaw_tag(yaw: f32) -> String {
    if yaw.fract() == 0.0 {
        format!("{:02}", yaw as i32)
    } else {
        format!("{yaw}")
    }
}

/// A random stream for (seed, identity, view) (splitmix64 mixing of the three).
fn stream(seed: u64, identity: u64, view: u64) -> Xoshiro256PlusPlus {
    let mut x = seed;
    for v in [identity, view] {
        x = splitmix(x ^ splitmix(v.wrapping_add(0x9e37_79b9_7f4a_7c15)));
    }
    Xoshiro256PlusPlus::seed_from_u64(x)
}

fn splitmix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// A linear colour channel to 8 bits (clamped, rounded, no gamma).
fn to_u8(c: f32) -> u8 {
    if c.is_nan() {
        return 0;
    }
    (c.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// Removes a leading "PATH: " from a message (the error adds the path itself).
fn strip_path(msg: &str, path: &Path) -> String {
    let p = format!("{}: ", path.display());
    msg.strip_prefix(&p).unwrap_or(msg).to_string()
}
#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn synth_similarity_recovers_transform() {
        let src: Vec<[f64; 3]> = (0..20).map(|i| [(i as f64 * 1.3).sin() * 10.0, (i as f64 * 0.7).cos() * 8.0, i as f64 * 0.5]).collect();
        let (c, s) = (0.6f64, 0.8f64);
        let truth = Similarity { scale: 1.7, rot: [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]], trans: [3.0, -2.0, 5.0] };
        let dst: Vec<[f64; 3]> = src.iter().map(|&p| truth.apply(p)).collect();
        let fit = Similarity::fit(&src, &dst).unwrap();
        for (a, b) in src.iter().zip(&dst) {
            assert!(norm(sub(fit.apply(*a), *b)) < 1e-9);
        }
        assert!((fit.scale - 1.7).abs() < 1e-9);
    }

    #[test]
    fn synth_grid_nearest_matches_brute_force() {
        let pts: Vec<[f64; 3]> = (0..500)
            .map(|i| [(i as f64 * 12.9898).sin() * 50.0, (i as f64 * 78.233).sin() * 30.0, (i as f64 * 3.7).cos() * 20.0])
            .collect();
        let grid = Grid::new(&pts, 6.0);
        for k in 0..200 {
            let q = [(k as f64 * 1.1).sin() * 80.0, (k as f64 * 2.3).cos() * 50.0, (k as f64 * 0.37).sin() * 40.0];
            let brute = (0..pts.len()).min_by(|&a, &b| norm(sub(pts[a], q)).total_cmp(&norm(sub(pts[b], q)))).unwrap();
            let got = grid.nearest(&pts, q).unwrap();
            assert!((norm(sub(pts[got], q)) - norm(sub(pts[brute], q))).abs() < 1e-12);
        }
    }

    #[test]
    fn synth_boundary_loops_of_a_square_with_hole() {
        // A 4x4 vertex grid with the middle quad missing: one outer loop (12 vertices), one inner (4).
        let mut tris = Vec::new();
        for y in 0..3u32 {
            for x in 0..3u32 {
                if x == 1 && y == 1 {
                    continue;
                }
                let v = y * 4 + x;
                tris.push([v, v + 1, v + 5]);
                tris.push([v, v + 5, v + 4]);
            }
        }
        let mut loops = boundary_loops(&tris, 16);
        loops.sort_by_key(|l| l.len());
        assert_eq!(loops.iter().map(Vec::len).collect::<Vec<_>>(), vec![4, 12]);
    }

    #[test]
    fn synth_closest_point_on_triangle() {
        let t = [[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0]];
        let (q, b) = closest_on_triangle([0.5, 0.5, 3.0], t);
        assert!(norm(sub(q, [0.5, 0.5, 0.0])) < 1e-12 && (b[0] - 0.5).abs() < 1e-12 && (b[1] - 0.25).abs() < 1e-12);
        let (q, b) = closest_on_triangle([-1.0, -1.0, 0.0], t);
        assert_eq!((q, b), ([0.0; 3], [1.0, 0.0, 0.0]));
        let (q, _) = closest_on_triangle([2.0, 2.0, 1.0], t);
        assert!(norm(sub(q, [1.0, 1.0, 0.0])) < 1e-12);
    }

    #[test]
    fn synth_pts_format() {
        let s = pts_string(&[[1.0, 2.5], [3.25, 4.0]]);
        assert_eq!(s, "version: 1\nn_points:  2\n{\n1.000 2.500\n3.250 4.000\n}\n");
        assert_eq!(yaw_tag(0.0), "00");
        assert_eq!(yaw_tag(45.0), "45");
        assert_eq!(yaw_tag(-15.0), "-15");
        assert_eq!(yaw_tag(7.5), "7.5");
    }
}
