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
//! the rasterizer's coordinates, [`gpmm_core::camera`]). Jaw landmarks 0-16 are the projected
//! vertices (not the silhouette); `landmarks_visible` flags landmarks hidden by the face itself
//! (depth test against the rendered depth buffer).

use std::path::{Path, PathBuf};

use gpmm_core::{vertex_stage, Camera, Cull, Pose, ProjectedVertex, ShLight, Tile, TileRasterizer, TileSink, Vec3};
use image::{Rgb, RgbImage};
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;
use rand_xoshiro::Xoshiro256PlusPlus;
use serde::{Deserialize, Serialize};

use crate::eval::npy::{self, NpyError};
use crate::mesh::geometry::{add, centroid, cross, dot, mul, norm, sub};
use crate::mesh::io::read_landmarks_json;
use crate::mesh::template::{load_template, TemplateError, TemplateOptions, IBUG68_COUNT};

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
    #[error("{}: {action}: {source}", path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// What was being done.
        action: &'static str,
        /// The underlying error.
        source: std::io::Error,
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
    Template(#[from] TemplateError),
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
    move |source| SynthError::Io { path: path.to_path_buf(), action, source }
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

impl SynthWorld {
    /// Loads and checks the ICT model and the template, closes the holes and transfers the albedo.
    pub fn load(options: &SynthOptions) -> Result<Self, SynthError> {
        options.validate()?;
        let dir = &options.ict_dir;
        let neutral_path = dir.join("neutral.npy");
        let modes_path = dir.join("identity_modes.npy");
        let tri_path = dir.join("triangles.npy");
        let lm_path = dir.join("landmarks_ibug68.json");
        let data_err = |path: &Path, message: String| SynthError::Data { path: path.to_path_buf(), message };

        let (shape, neutral_cm) = npy::read_f32(&neutral_path)?;
        if shape.len() != 2 || shape[1] != 3 || shape[0] < IBUG68_COUNT {
            return Err(data_err(&neutral_path, format!("expected shape (N, 3) with N >= {IBUG68_COUNT}, found {shape:?}")));
        }
        let n = shape[0];
        if !neutral_cm.iter().all(|v| v.is_finite()) {
            return Err(data_err(&neutral_path, "contains NaN or infinite values".into()));
        }
        let neutral: Vec<[f64; 3]> =
            neutral_cm.chunks_exact(3).map(|c| [10.0 * f64::from(c[0]), 10.0 * f64::from(c[1]), 10.0 * f64::from(c[2])]).collect();

        let (shape, tri_raw) = npy::read_u32(&tri_path)?;
        if shape.len() != 2 || shape[1] != 3 || shape[0] == 0 {
            return Err(data_err(&tri_path, format!("expected shape (T, 3), found {shape:?}")));
        }
        if let Some(bad) = tri_raw.iter().find(|&&i| i as usize >= n) {
            return Err(data_err(&tri_path, format!("vertex index {bad} out of range: {} has {n} vertices", neutral_path.display())));
        }
        let mut triangles: Vec<[u32; 3]> = tri_raw.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();

        let (shape, mut modes) = npy::read_f32(&modes_path)?;
        if shape.len() != 3 || shape[1] != n || shape[2] != 3 || shape[0] == 0 {
            return Err(data_err(&modes_path, format!("expected shape (K, {n}, 3) to match {}, found {shape:?}", neutral_path.display())));
        }
        if !modes.iter().all(|v| v.is_finite()) {
            return Err(data_err(&modes_path, "contains NaN or infinite values".into()));
        }
        let n_modes = options.modes.map_or(shape[0], |m| m.min(shape[0]));
        modes.truncate(n_modes * n * 3);
        for v in modes.iter_mut() {
            *v *= 10.0;
        }

        let (scheme, landmarks) = read_landmarks_json(&lm_path)
            .map_err(|e| SynthError::Data { path: lm_path.clone(), message: strip_path(&e.to_string(), &lm_path) })?;
        if scheme != "ibug68" || landmarks.len() != IBUG68_COUNT {
            return Err(data_err(&lm_path, format!("expected scheme ibug68 with 68 ids, found {scheme:?} with {} ids", landmarks.len())));
        }
        if let Some((k, id)) = landmarks.iter().enumerate().find(|(_, &id)| id as usize >= n) {
            return Err(data_err(&lm_path, format!("landmark {k} refers to vertex {id} but the mesh has {n} vertices")));
        }

        // The neutral in its face frame (the albedo is transferred there; bump centres live there).
        let neutral_face = to_face_frame(&neutral, &landmarks).map_err(|m| data_err(&lm_path, m))?;
        // Winding: counter-clockwise seen from outside means the summed normal points toward +z (the camera).
        let mut nz = 0.0;
        for t in &triangles {
            let [a, b, c] = t.map(|i| neutral_face[i as usize]);
            nz += cross(sub(b, a), sub(c, a))[2];
        }
        let flipped = nz < 0.0;
        if flipped {
            for t in triangles.iter_mut() {
                t.swap(1, 2);
            }
        }

        // Close the inner boundary loops.
        let loops = boundary_loops(&triangles, n);
        let lm_pos = |ids: std::ops::Range<usize>| -> [f64; 3] {
            let s = ids.clone().fold([0.0; 3], |acc, k| add(acc, neutral_face[landmarks[k] as usize]));
            mul(s, 1.0 / ids.len() as f64)
        };
        let targets = [(lm_pos(36..42), HoleKind::Eye), (lm_pos(42..48), HoleKind::Eye), (lm_pos(60..68), HoleKind::Mouth)];
        let eye_width = norm(sub(neutral_face[landmarks[39] as usize], neutral_face[landmarks[36] as usize]));
        let outer =
            loops.iter().enumerate().map(|(k, l)| (k, loop_length(l, &neutral_face))).max_by(|a, b| a.1.total_cmp(&b.1)).map(|(k, _)| k);
        let mut fans = Vec::new();
        for (k, ring) in loops.into_iter().enumerate() {
            if Some(k) == outer || ring.len() < 3 {
                continue;
            }
            let c = centroid(ring.iter().map(|&i| neutral_face[i as usize]));
            let kind = targets
                .iter()
                .map(|(p, kind)| (norm(sub(*p, c)), *kind))
                .min_by(|a, b| a.0.total_cmp(&b.0))
                .filter(|(d, _)| *d < eye_width)
                .map_or(HoleKind::Other, |(_, kind)| kind);
            let center = (n + fans.len()) as u32;
            // `ring` follows the boundary half-edges a -> b of its triangles; the fan uses b -> a.
            for w in 0..ring.len() {
                let (a, b) = (ring[w], ring[(w + 1) % ring.len()]);
                triangles.push([b, a, center]);
            }
            fans.push(Fan { ring, center, kind });
        }

        let template_albedo = transfer_albedo(options, &neutral_face, &landmarks)?;
        let mut base_albedo = template_albedo;
        for fan in &fans {
            let mean = mean3(fan.ring.iter().map(|&i| base_albedo[i as usize]));
            base_albedo.push(match fan.kind {
                HoleKind::Eye => [0.035, 0.03, 0.028],
                HoleKind::Mouth => mean.map(|c| 0.4 * c),
                HoleKind::Other => mean,
            });
        }
        Ok(Self {
            options: options.clone(),
            n_ict: n,
            n_modes,
            neutral,
            modes,
            triangles,
            fans,
            landmarks,
            base_albedo,
            neutral_face,
            flipped,
        })
    }

    /// Sizes of the loaded model.
    pub fn summary(&self) -> IctSummary {
        IctSummary {
            vertices: self.n_ict,
            modes: self.n_modes,
            triangles: self.triangles.len(),
            holes: self.fans.iter().map(|f| f.kind).collect(),
            flipped: self.flipped,
        }
    }

    /// The render triangles (ICT triangles, then the hole fans), counter-clockwise seen from outside.
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// The 68 landmark vertex ids.
    pub fn landmarks(&self) -> &[u32] {
        &self.landmarks
    }

    /// The transferred template albedo before per-identity variation (fan centres included).
    pub fn base_albedo(&self) -> &[Vec3] {
        &self.base_albedo
    }

    /// Identity `id`: random coefficients, shape in its face frame, varied albedo (deterministic for (seed, id)).
    pub fn identity(&self, id: usize) -> Result<Identity, SynthError> {
        let mut rng = stream(self.options.seed, id as u64, 0);
        let s = self.options.identity_scale;
        let coefficients: Vec<f32> = (0..self.n_modes).map(|_| s * rng.sample::<f32, _>(StandardNormal)).collect();
        let n = self.n_ict;
        let mut acc: Vec<f32> = self.neutral.iter().flat_map(|p| p.map(|v| v as f32)).collect();
        for (k, &w) in coefficients.iter().enumerate() {
            if w == 0.0 {
                continue;
            }
            for (a, m) in acc.iter_mut().zip(&self.modes[k * n * 3..(k + 1) * n * 3]) {
                *a += w * m;
            }
        }
        let raw: Vec<[f64; 3]> = acc.chunks_exact(3).map(|c| [f64::from(c[0]), f64::from(c[1]), f64::from(c[2])]).collect();
        let face = to_face_frame(&raw, &self.landmarks).map_err(|m| SynthError::Render { message: format!("identity {id}: {m}") })?;
        let mut positions: Vec<Vec3> = face.iter().map(|p| p.map(|v| v as f32)).collect();
        for fan in &self.fans {
            let c = centroid(fan.ring.iter().map(|&i| face[i as usize]));
            positions.push(c.map(|v| v as f32));
        }

        // Albedo variation.
        let brightness = rng.random_range(0.8f32..1.15);
        let tint = [0; 3].map(|_| (0.05 * rng.sample::<f32, _>(StandardNormal)).exp());
        let bumps: Vec<AlbedoBump> = (0..ALBEDO_BUMPS)
            .map(|_| {
                let v = rng.random_range(0..n);
                let center = self.neutral_face[v].map(|c| c as f32);
                let radius = rng.random_range(20.0f32..60.0);
                let g = 0.12 * rng.sample::<f32, _>(StandardNormal);
                let amplitude = [0; 3].map(|_| g + 0.04 * rng.sample::<f32, _>(StandardNormal));
                AlbedoBump { center, radius, amplitude }
            })
            .collect();
        let variation = AlbedoVariation { brightness, tint, bumps };
        let mut albedo = self.base_albedo.clone();
        for (i, a) in albedo.iter_mut().enumerate() {
            // Fan centres take the variation at their ring's centroid on the neutral.
            let p = if i < n {
                self.neutral_face[i]
            } else {
                let fan = &self.fans[i - n];
                centroid(fan.ring.iter().map(|&r| self.neutral_face[r as usize]))
            };
            let mut log = [0.0f32; 3];
            for b in &variation.bumps {
                let d2: f32 = (0..3).map(|k| (p[k] as f32 - b.center[k]).powi(2)).sum();
                let g = (-d2 / (b.radius * b.radius)).exp();
                for (l, amp) in log.iter_mut().zip(b.amplitude) {
                    *l += amp * g;
                }
            }
            for ((a, t), l) in a.iter_mut().zip(tint).zip(log) {
                *a = (*a * brightness * t * l.exp()).clamp(0.0, 1.0);
            }
        }
        Ok(Identity { id, coefficients, positions, albedo, variation })
    }

    /// Renders `identity` at the yaw `yaw_index` of the options, with that view's random pose, camera and light.
    pub fn render_view(&self, identity: &Identity, yaw_index: usize) -> Result<SynthFace, SynthError> {
        let o = &self.options;
        let yaw_deg = *o
            .yaws_deg
            .get(yaw_index)
            .ok_or_else(|| SynthError::Options { message: format!("yaw index {yaw_index} is out of range ({} yaws)", o.yaws_deg.len()) })?;
        let expected = self.base_albedo.len();
        if identity.positions.len() != expected || identity.albedo.len() != expected {
            return Err(SynthError::Options {
                message: format!(
                    "identity {} has {} positions and {} colours, the world has {expected} vertices",
                    identity.id,
                    identity.positions.len(),
                    identity.albedo.len()
                ),
            });
        }
        let mut rng = stream(o.seed, identity.id as u64, 1 + yaw_index as u64);
        let size = o.size;
        let m = o.max_pitch_roll_deg;
        let pitch_deg = if m > 0.0 { rng.random_range(-m..=m) } else { 0.0 };
        let roll_deg = if m > 0.0 { rng.random_range(-m..=m) } else { 0.0 };
        let fov_deg = rng.random_range(o.fov_deg[0]..=o.fov_deg[1]);
        let fill = rng.random_range(o.face_fill[0]..=o.face_fill[1]);
        let shift = [rng.random_range(-0.05f32..=0.05), rng.random_range(-0.05f32..=0.05)];
        let focal = Camera::focal_from_fov(size, fov_deg.to_radians());
        let camera = Camera::centered(size, size, focal);

        // Framing: the face (chin to forehead) fills `fill` of the image height.
        let lm = |k: usize| identity.positions[self.landmarks[k] as usize];
        let chin = lm(8)[1];
        let eyes = (lm(36)[1] + lm(39)[1] + lm(42)[1] + lm(45)[1]) / 4.0;
        let top = lm(19)[1].max(lm(24)[1]) + 0.5 * (eyes - chin);
        let height = (top - chin).max(1.0);
        let distance = focal * height / (fill * size as f32);
        let center = [0.0, 0.5 * (top + chin), 0.0];
        let mut pose =
            Pose { yaw: yaw_deg.to_radians(), pitch: pitch_deg.to_radians(), roll: roll_deg.to_radians(), translation: [0.0; 3] };
        let rc = pose.transform_point(center);
        let px_to_mm = distance / focal;
        // Image x right = camera +x; image y down = camera −y.
        let off = [shift[0] * size as f32 * px_to_mm, -shift[1] * size as f32 * px_to_mm];
        pose.translation = [off[0] - rc[0], off[1] - rc[1], -distance - rc[2]];

        // Light: ambient plus one directional term no stronger than it.
        let a = rng.random_range(0.55f32..0.85);
        let light_ambient = [0; 3].map(|_| a * rng.random_range(0.95f32..1.05));
        let d = rng.random_range(0.15f32..0.45);
        let light_diffuse: [f32; 3] = std::array::from_fn(|c| (d * rng.random_range(0.95f32..1.05)).min(light_ambient[c]));
        let theta = rng.random_range(0.0f32..70.0).to_radians();
        let phi = rng.random_range(-std::f32::consts::PI..std::f32::consts::PI);
        let light_direction = [theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos()];
        let light = ShLight::from_ambient_diffuse(light_ambient, light_diffuse, light_direction);
        let background_rgb = [0; 3].map(|_| rng.random_range(0.1f32..0.9));

        // Render.
        let n = identity.positions.len();
        let mut normals = vec![[0.0f32; 3]; n];
        let mut projected = vec![ProjectedVertex::INVALID; n];
        vertex_stage(&identity.positions, &identity.albedo, &self.triangles, &pose, &camera, &light, &mut normals, &mut projected)
            .map_err(|e| SynthError::Render { message: format!("vertex stage: {e:?}") })?;
        let mut raster: Box<TileRasterizer<TILE, TILE, BIN>> = Box::new(TileRasterizer::new());
        let mut sink = FrameSink::new(size, size);
        raster
            .render(&projected, &self.triangles, size, size, Cull::Clockwise, &mut sink)
            .map_err(|e| SynthError::Render { message: format!("rasterizer: {e:?}") })?;

        let sigma = o.background_noise;
        let mut image = RgbImage::new(size, size);
        let mut covered = 0usize;
        for (i, px) in image.pixels_mut().enumerate() {
            let noise: [f32; 3] = [0; 3].map(|_| sigma * rng.sample::<f32, _>(StandardNormal));
            let c = match sink.color[i] {
                Some(c) => {
                    covered += 1;
                    c
                }
                None => std::array::from_fn(|k| background_rgb[k] + noise[k]),
            };
            *px = Rgb(c.map(to_u8));
        }

        // Landmarks and their visibility (depth test against the rendered surface around them).
        let mut landmarks = Vec::with_capacity(IBUG68_COUNT);
        let mut landmarks_visible = Vec::with_capacity(IBUG68_COUNT);
        let tol = (3.0 * px_to_mm).max(5.0);
        for &id in &self.landmarks {
            let q = pose.transform_point(identity.positions[id as usize]);
            let (pt, vis) = match camera.project(q) {
                Some(s) => ([s.x, s.y], sink.visible(s.x, s.y, -q[2], tol)),
                None => ([f32::NAN, f32::NAN], false),
            };
            landmarks.push(pt);
            landmarks_visible.push(vis);
        }
        if landmarks.iter().flatten().any(|v| !v.is_finite()) {
            return Err(SynthError::Render { message: format!("identity {}: a landmark is behind the camera", identity.id) });
        }
        let stem = format!("{:04}_yaw{}", identity.id, yaw_tag(yaw_deg));
        let truth = ImageTruth {
            image: format!("{stem}.png"),
            landmarks_file: format!("{stem}.pts"),
            identity: identity.id,
            yaw_index,
            yaw_deg,
            pitch_deg,
            roll_deg,
            translation_mm: pose.translation,
            focal_px: focal,
            fov_deg,
            principal_px: camera.principal,
            width: size,
            height: size,
            light: light.coeffs,
            light_ambient,
            light_diffuse,
            light_direction,
            background_rgb,
            background_noise: sigma,
            shape_coefficients: identity.coefficients.clone(),
            landmarks,
            landmarks_visible,
            face_fraction: covered as f32 / (size as f32 * size as f32),
        };
        Ok(SynthFace { image, truth })
    }
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

/// Landmarks in the iBUG `.pts` format (`version: 1`, `n_points:  N`, `{`, `x y` lines, `}`), 3 decimals.
pub fn pts_string(points: &[[f32; 2]]) -> String {
    let mut s = format!("version: 1\nn_points:  {}\n{{\n", points.len());
    for p in points {
        s.push_str(&format!("{:.3} {:.3}\n", p[0], p[1]));
    }
    s.push_str("}\n");
    s
}

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

/// Collects finished tiles into full-image colour (None = uncovered) and depth buffers.
struct FrameSink {
    width: u32,
    height: u32,
    color: Vec<Option<Vec3>>,
    inv_w: Vec<f32>,
}

impl FrameSink {
    fn new(width: u32, height: u32) -> Self {
        let n = width as usize * height as usize;
        Self { width, height, color: vec![None; n], inv_w: vec![0.0; n] }
    }

    /// Whether a point at pixel position (x, y) and depth `w` (mm) is not hidden: some covered pixel of the
    /// 3×3 neighbourhood shows a surface no more than `tol` mm in front of it.
    fn visible(&self, x: f32, y: f32, w: f32, tol: f32) -> bool {
        if !(x >= 0.0 && y >= 0.0 && x < self.width as f32 && y < self.height as f32) {
            return false;
        }
        let (xi, yi) = (x.floor() as i64, y.floor() as i64);
        for dy in -1..=1 {
            for dx in -1..=1 {
                let (px, py) = (xi + dx, yi + dy);
                if px < 0 || py < 0 || px >= i64::from(self.width) || py >= i64::from(self.height) {
                    continue;
                }
                let inv = self.inv_w[py as usize * self.width as usize + px as usize];
                if inv > 0.0 && 1.0 / inv >= w - tol {
                    return true;
                }
            }
        }
        false
    }
}

impl TileSink<TILE, TILE> for FrameSink {
    fn consume(&mut self, tile: &Tile<TILE, TILE>) {
        let (x0, y0) = tile.origin();
        let (w, h) = tile.size();
        for ly in 0..h as usize {
            for lx in 0..w as usize {
                let (x, y) = (x0 as usize + lx, y0 as usize + ly);
                if x >= self.width as usize || y >= self.height as usize {
                    continue;
                }
                if let Some(f) = tile.fragment(lx, ly) {
                    let i = y * self.width as usize + x;
                    self.color[i] = Some(f.color);
                    self.inv_w[i] = f.inv_w;
                }
            }
        }
    }
}

// ------------------------------------------------------------ geometry

fn mean3(colors: impl Iterator<Item = Vec3>) -> Vec3 {
    let (s, n) = colors.fold(([0.0f32; 3], 0usize), |(s, n), c| ([s[0] + c[0], s[1] + c[1], s[2] + c[2]], n + 1));
    s.map(|v| v / n.max(1) as f32)
}

/// The template's face frame from iBUG-68 landmarks (the same frame `template.rs` normalizes to).
fn face_frame(lm: &[[f64; 3]]) -> Result<([[f64; 3]; 3], [f64; 3]), String> {
    if lm.len() != IBUG68_COUNT {
        return Err(format!("need {IBUG68_COUNT} landmarks, got {}", lm.len()));
    }
    let frame = crate::mesh::template::ibug_frame(lm)?;
    Ok((frame.axes, frame.center))
}

/// Maps `points` into the face frame of their landmarks `ids` (no scaling).
fn to_face_frame(points: &[[f64; 3]], ids: &[u32]) -> Result<Vec<[f64; 3]>, String> {
    let lm: Vec<[f64; 3]> = ids.iter().map(|&i| points[i as usize]).collect();
    let (axes, center) = face_frame(&lm)?;
    Ok(points
        .iter()
        .map(|p| {
            let d = sub(*p, center);
            [dot(axes[0], d), dot(axes[1], d), dot(axes[2], d)]
        })
        .collect())
}

/// Boundary loops (edges of exactly one triangle), each as a vertex list following the
/// triangles' own direction of the boundary half-edges.
fn boundary_loops(triangles: &[[u32; 3]], n: usize) -> Vec<Vec<u32>> {
    use std::collections::HashMap;
    let mut count: HashMap<(u32, u32), u32> = HashMap::new();
    for t in triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *count.entry((a.min(b), a.max(b))).or_insert(0) += 1;
        }
    }
    // Boundary half-edges a -> b (as they occur in their triangle).
    let mut next: Vec<Vec<u32>> = vec![Vec::new(); n];
    let mut starts = Vec::new();
    for t in triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            if count.get(&(a.min(b), a.max(b))) == Some(&1) {
                next[a as usize].push(b);
                starts.push(a);
            }
        }
    }
    let mut loops = Vec::new();
    for &s in &starts {
        if next[s as usize].is_empty() {
            continue;
        }
        let mut ring = vec![s];
        let mut cur = s;
        while let Some(b) = next[cur as usize].pop() {
            if b == s {
                break;
            }
            ring.push(b);
            cur = b;
            if ring.len() > n {
                break;
            }
        }
        loops.push(ring);
    }
    loops
}

fn loop_length(ring: &[u32], pos: &[[f64; 3]]) -> f64 {
    (0..ring.len()).map(|k| norm(sub(pos[ring[k] as usize], pos[ring[(k + 1) % ring.len()] as usize]))).sum()
}

// ------------------------------------------------------------ albedo transfer

/// The template's colours on the ICT neutral (face frame) by landmark-aligned closest vertex.
fn transfer_albedo(options: &SynthOptions, neutral_face: &[[f64; 3]], landmarks: &[u32]) -> Result<Vec<Vec3>, SynthError> {
    let dir = &options.template_dir;
    let topts = TemplateOptions { no_crop: true, ..Default::default() };
    let template = load_template(&dir.join("lee-perry-smith.ply"), &dir.join("landmarks_ibug68.json"), &topts)?;
    if template.landmarks.len() != IBUG68_COUNT {
        return Err(SynthError::Data {
            path: dir.join("landmarks_ibug68.json"),
            message: format!("the template needs {IBUG68_COUNT} iBUG landmarks, it has {}", template.landmarks.len()),
        });
    }
    let src: Vec<[f64; 3]> = (17..IBUG68_COUNT).map(|k| template.mesh.positions[template.landmarks[k] as usize]).collect();
    let dst: Vec<[f64; 3]> = (17..IBUG68_COUNT).map(|k| neutral_face[landmarks[k] as usize]).collect();
    let sim = Similarity::fit(&src, &dst)
        .ok_or_else(|| SynthError::Render { message: "cannot align the template to the ICT landmarks".into() })?;
    let aligned: Vec<[f64; 3]> = template.mesh.positions.iter().map(|&p| sim.apply(p)).collect();
    let grid = Grid::new(&aligned, 6.0);
    let mut incident: Vec<Vec<u32>> = vec![Vec::new(); aligned.len()];
    for (k, t) in template.mesh.triangles.iter().enumerate() {
        for &i in t {
            if let Some(list) = incident.get_mut(i as usize) {
                list.push(k as u32);
            }
        }
    }
    let colors = &template.mesh.colors;
    let color = |i: u32| colors.get(i as usize).map_or([0.5; 3], |c| c.map(|v| v as f32));
    Ok(neutral_face
        .iter()
        .map(|&p| {
            let Some(v) = grid.nearest(&aligned, p) else {
                return [0.5; 3];
            };
            // The closest point on the triangles around the closest vertex, colour interpolated there.
            let mut best = (norm(sub(aligned[v], p)), [v as u32; 3], [1.0, 0.0, 0.0]);
            for &k in &incident[v] {
                let t = template.mesh.triangles[k as usize];
                let (q, bary) = closest_on_triangle(p, t.map(|i| aligned[i as usize]));
                let d = norm(sub(q, p));
                if d < best.0 {
                    best = (d, t, bary);
                }
            }
            let (_, t, b) = best;
            let c = t.map(color);
            std::array::from_fn(|ch| (b[0] as f32) * c[0][ch] + (b[1] as f32) * c[1][ch] + (b[2] as f32) * c[2][ch])
        })
        .collect())
}

/// The closest point to `p` on triangle `t` and its barycentric coordinates (Ericson, Real-Time Collision Detection 5.1.5).
pub fn closest_on_triangle(p: [f64; 3], t: [[f64; 3]; 3]) -> ([f64; 3], [f64; 3]) {
    let [a, b, c] = t;
    let (ab, ac, ap) = (sub(b, a), sub(c, a), sub(p, a));
    let (d1, d2) = (dot(ab, ap), dot(ac, ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return (a, [1.0, 0.0, 0.0]);
    }
    let bp = sub(p, b);
    let (d3, d4) = (dot(ab, bp), dot(ac, bp));
    if d3 >= 0.0 && d4 <= d3 {
        return (b, [0.0, 1.0, 0.0]);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (add(a, mul(ab, v)), [1.0 - v, v, 0.0]);
    }
    let cp = sub(p, c);
    let (d5, d6) = (dot(ab, cp), dot(ac, cp));
    if d6 >= 0.0 && d5 <= d6 {
        return (c, [0.0, 0.0, 1.0]);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (add(a, mul(ac, w)), [1.0 - w, 0.0, w]);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (add(b, mul(sub(c, b), w)), [0.0, 1.0 - w, w]);
    }
    let denom = va + vb + vc;
    if !(denom.abs() > 0.0 && denom.is_finite()) {
        return (a, [1.0, 0.0, 0.0]);
    }
    let (v, w) = (vb / denom, vc / denom);
    (add(a, add(mul(ab, v), mul(ac, w))), [1.0 - v - w, v, w])
}

/// `p ↦ s R p + t`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Similarity {
    scale: f64,
    rot: [[f64; 3]; 3],
    trans: [f64; 3],
}

impl Similarity {
    /// Least-squares similarity from `src` to `dst` (Horn's quaternion method; scale as Umeyama).
    fn fit(src: &[[f64; 3]], dst: &[[f64; 3]]) -> Option<Self> {
        if src.len() != dst.len() || src.len() < 3 {
            return None;
        }
        let cs = centroid(src.iter().copied());
        let cd = centroid(dst.iter().copied());
        let mut s = [[0.0f64; 3]; 3];
        let mut var = 0.0;
        for (a, b) in src.iter().zip(dst) {
            let (a, b) = (sub(*a, cs), sub(*b, cd));
            var += dot(a, a);
            for i in 0..3 {
                for j in 0..3 {
                    s[i][j] += a[i] * b[j];
                }
            }
        }
        if !(var > 0.0 && var.is_finite()) {
            return None;
        }
        let [[sxx, sxy, sxz], [syx, syy, syz], [szx, szy, szz]] = s;
        let nmat = [
            [sxx + syy + szz, syz - szy, szx - sxz, sxy - syx],
            [syz - szy, sxx - syy - szz, sxy + syx, szx + sxz],
            [szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy],
            [sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz],
        ];
        let m = faer::Mat::from_fn(4, 4, |i, j| nmat[i][j]);
        let eig = m.self_adjoint_eigen(faer::Side::Lower).ok()?;
        let lambda = eig.S().column_vector();
        let top = (0..4).max_by(|&a, &b| lambda[a].total_cmp(&lambda[b]))?;
        let u = eig.U();
        let (w, x, y, z) = (u[(0, top)], u[(1, top)], u[(2, top)], u[(3, top)]);
        let rot = [
            [w * w + x * x - y * y - z * z, 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
            [2.0 * (x * y + w * z), w * w - x * x + y * y - z * z, 2.0 * (y * z - w * x)],
            [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), w * w - x * x - y * y + z * z],
        ];
        let mut num = 0.0;
        for (a, b) in src.iter().zip(dst) {
            let (a, b) = (sub(*a, cs), sub(*b, cd));
            num += dot(b, [dot(rot[0], a), dot(rot[1], a), dot(rot[2], a)]);
        }
        let scale = num / var;
        if !(scale.is_finite() && scale > 0.0) {
            return None;
        }
        let rc = [dot(rot[0], cs), dot(rot[1], cs), dot(rot[2], cs)];
        Some(Self { scale, rot, trans: sub(cd, mul(rc, scale)) })
    }

    fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let r = [dot(self.rot[0], p), dot(self.rot[1], p), dot(self.rot[2], p)];
        add(mul(r, self.scale), self.trans)
    }
}

/// A uniform grid over points for nearest-neighbour queries.
pub struct Grid {
    lo: [f64; 3],
    cell: f64,
    dims: [usize; 3],
    /// Point indices sorted by cell; `starts[c]..starts[c + 1]` are cell `c`'s.
    order: Vec<u32>,
    starts: Vec<u32>,
}

impl Grid {
    /// Bins `points` into cubic cells of side `cell` (enlarged so that no side has more than 256 cells).
    pub fn new(points: &[[f64; 3]], cell: f64) -> Self {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in points {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        if points.is_empty() {
            lo = [0.0; 3];
            hi = [0.0; 3];
        }
        // At most 256 cells along the longest side (a huge mesh gets larger cells).
        let extent = (0..3).map(|k| hi[k] - lo[k]).fold(0.0f64, f64::max);
        let cell = if cell > 0.0 { cell.max(extent / 256.0) } else { (extent / 256.0).max(1e-9) };
        let dims = [0, 1, 2].map(|k| (((hi[k] - lo[k]) / cell).floor() as usize + 1).min(257));
        let mut grid = Self { lo, cell, dims, order: Vec::new(), starts: Vec::new() };
        let ncell = dims[0] * dims[1] * dims[2];
        let cells: Vec<usize> = points.iter().map(|p| grid.cell_index(grid.coords(*p))).collect();
        let mut counts = vec![0u32; ncell + 1];
        for &c in &cells {
            counts[c + 1] += 1;
        }
        for c in 0..ncell {
            counts[c + 1] += counts[c];
        }
        let mut fill = counts.clone();
        let mut order = vec![0u32; points.len()];
        for (i, &c) in cells.iter().enumerate() {
            order[fill[c] as usize] = i as u32;
            fill[c] += 1;
        }
        grid.order = order;
        grid.starts = counts;
        grid
    }

    fn coords(&self, p: [f64; 3]) -> [i64; 3] {
        [0, 1, 2].map(|k| (((p[k] - self.lo[k]) / self.cell).floor() as i64).clamp(0, self.dims[k] as i64 - 1))
    }

    fn cell_index(&self, c: [i64; 3]) -> usize {
        (c[2] as usize * self.dims[1] + c[1] as usize) * self.dims[0] + c[0] as usize
    }

    /// Index of the point nearest to `q` (searching shells of cells outward).
    pub fn nearest(&self, points: &[[f64; 3]], q: [f64; 3]) -> Option<usize> {
        let c = self.coords(q);
        let maxr = self.dims.iter().copied().max().unwrap_or(1) as i64;
        let mut best: Option<(f64, usize)> = None;
        for r in 0..=maxr {
            for z in (c[2] - r).max(0)..=(c[2] + r).min(self.dims[2] as i64 - 1) {
                for y in (c[1] - r).max(0)..=(c[1] + r).min(self.dims[1] as i64 - 1) {
                    for x in (c[0] - r).max(0)..=(c[0] + r).min(self.dims[0] as i64 - 1) {
                        let on_shell = (x - c[0]).abs() == r || (y - c[1]).abs() == r || (z - c[2]).abs() == r;
                        if !on_shell {
                            continue;
                        }
                        let cell = self.cell_index([x, y, z]);
                        for &i in &self.order[self.starts[cell] as usize..self.starts[cell + 1] as usize] {
                            let d = norm(sub(points[i as usize], q));
                            if best.is_none_or(|(bd, _)| d < bd) {
                                best = Some((d, i as usize));
                            }
                        }
                    }
                }
            }
            // Every point in a shell beyond r lies at least r whole cells away from q.
            if let Some((bd, _)) = best {
                if bd <= r as f64 * self.cell {
                    break;
                }
            }
        }
        best.map(|(_, i)| i)
    }
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
