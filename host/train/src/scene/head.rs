//! The head around the face in training scenes. A model covers the face only; photos show a
//! face on a head, with ears, scalp, hair and neck. The template scan has them: its whole head,
//! in the model's frame, is deformed and recoloured to continue each random face instance, laid
//! a little beneath the face (the face wins the depth test, the head fills any seam), and
//! sometimes given hair. The finder then learns heads, not floating masks.

use gpmm_core::geometry::Vec3;
use gpmm_core::render::{vertex_normals, VertexError};
use gpmm_host::gp::model::GpModel;
use gpmm_host::mesh::closest::{closest_on_triangle, Grid};
use gpmm_host::mesh::geometry::dist2;
use gpmm_host::mesh::template::{face_crop_indices, load_template, Template, TemplateError, TemplateOptions};
use gpmm_host::render::Instance;
use rand::{Rng, RngExt};
use std::path::{Path, PathBuf};

/// Nearest face vertices each head vertex follows.
const ANCHORS: usize = 6;
/// How far beneath the face the head lies (mm, along its normals).
const INSET_MM: f32 = 1.5;
/// Distance from the face (mm) over which the head's deformation fades out.
const FADE_MM: f32 = 45.0;
/// Largest median distance (mm) from the model's mean vertices to the head for the two to be
/// taken as one frame.
const ALIGNED_MM: f32 = 2.0;

/// One head vertex's link to the face: the nearest mean-face vertices, their weights, and how
/// much of their shape change it takes (1 on the face, fading away from it).
#[derive(Debug, Clone, Copy)]
struct Anchor {
    ids: [u32; ANCHORS],
    weights: [f32; ANCHORS],
    fade: f32,
}

/// The template's whole head, ready to be put around face instances of one model.
#[derive(Debug, Clone)]
pub struct HeadContext {
    /// Rest positions (mm, model frame), already inset beneath the surface.
    pub(super) positions: Vec<Vec3>,
    /// Rest vertex normals (unit, outward).
    pub(super) normals: Vec<Vec3>,
    /// Rest albedos (linear RGB).
    albedos: Vec<Vec3>,
    /// Triangles over the head's vertices.
    triangles: Vec<[u32; 3]>,
    /// Per vertex: which face vertices it follows.
    anchors: Vec<Anchor>,
    /// Per vertex: whether hair may cover it (scalp and back of the head, never the face).
    pub(super) scalp: Vec<bool>,
    /// Height (mm, model frame) of the eyes, for the hairline.
    pub(super) eye_y: f32,
    /// Height (mm, model frame) of the chin (landmark 8), for necklines.
    pub(super) chin_y: f32,
}

/// Short hair painted on the scalp: its albedo, the hairline's height, and how far forward (z,
/// mm) the back of the head is covered down to the ears.
#[derive(Debug, Clone, Copy)]
pub(super) struct Hair {
    /// Linear albedo.
    pub(super) tone: Vec3,
    /// Height (mm, model frame) above which the scalp is covered.
    pub(super) hairline: f32,
    /// Depth (mm, model frame) behind which the head is covered down to the ears.
    pub(super) back: f32,
}

/// A head instance around a face: the combined vertices and triangles, face first (so the
/// model's vertex ids, landmarks included, still index the face).
#[derive(Debug, Clone)]
pub struct HeadedInstance {
    /// Face vertices, then head vertices.
    pub instance: Instance,
    /// The model's triangles, then the head's.
    pub triangles: Vec<[u32; 3]>,
}

/// Why a template cannot be the head around a model.
#[derive(Debug, thiserror::Error)]
pub enum HeadError {
    /// The template's files could not be read or prepared.
    #[error("{0}")]
    Template(TemplateError),
    /// The template and the model do not fit together.
    #[error("{}: as the head around the model: {error}", path.display())]
    Mismatch {
        /// The template's mesh file.
        path: PathBuf,
        /// Why they do not fit.
        error: HeadMismatch,
    },
}

/// Why a template does not fit a model as its head.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum HeadMismatch {
    /// The model or the head has no vertices.
    #[error("empty model or head")]
    Empty,
    /// The model's mean face is not on the head's surface.
    #[error(
        "the model's mean face lies {median_mm:.1} mm (median) from this head, more than {ALIGNED_MM} mm: \
         the model was not built from this template (or at another scale)"
    )]
    NotOnHead {
        /// Median distance of the mean face's vertices from the head (mm).
        median_mm: f32,
    },
    /// The head's normals cannot be computed.
    #[error("the head mesh: {0}")]
    Normals(VertexError),
}

impl HeadContext {
    /// Loads the whole (uncropped) template from its mesh and landmark files, in the normalized
    /// frame a model built from it has, and links it to `model`.
    pub fn load(model: &GpModel, mesh: &Path, landmarks: &Path) -> Result<Self, HeadError> {
        let head = load_template(mesh, landmarks, &TemplateOptions { no_crop: true, ..Default::default() }).map_err(HeadError::Template)?;
        Self::new(model, &head).map_err(|error| HeadError::Mismatch { path: mesh.to_path_buf(), error })
    }

    /// Links a normalized, uncropped template to `model`; an error when the model's mean face
    /// does not lie on it (a model built from another scan or at another scale).
    pub fn new(model: &GpModel, head: &Template) -> Result<Self, HeadMismatch> {
        let face: Vec<Vec3> = model.shape.mean.clone();
        if face.is_empty() || head.mesh.positions.is_empty() {
            return Err(HeadMismatch::Empty);
        }
        let positions: Vec<Vec3> = head.mesh.positions.iter().map(|p| p.map(|v| v as f32)).collect();
        let albedos: Vec<Vec3> = head.mesh.colors.iter().map(|c| c.map(|v| v.clamp(0.0, 1.0) as f32)).collect();
        // Are they one frame? The mean face's vertices lie on the template's surface (measured to
        // the triangles around the nearest head vertex: a simplified face's vertices lie between
        // the head's).
        let mut around: Vec<Vec<u32>> = vec![Vec::new(); positions.len()];
        for (t, tri) in head.mesh.triangles.iter().enumerate() {
            for &v in tri {
                if let Some(a) = around.get_mut(v as usize) {
                    a.push(t as u32);
                }
            }
        }
        let grid = Grid::new(&head.mesh.positions, 5.0);
        let surface_gap = |p: Vec3| -> f32 {
            let q = p.map(f64::from);
            let Some(i) = grid.nearest(&head.mesh.positions, q) else { return f32::INFINITY };
            let d = head.mesh.positions.get(i).map_or(f32::INFINITY, |v| dist2(*v, q).sqrt() as f32);
            around[i]
                .iter()
                .filter_map(|&t| head.mesh.triangles.get(t as usize))
                .filter_map(|tri| {
                    let corners = [
                        head.mesh.positions.get(tri[0] as usize)?,
                        head.mesh.positions.get(tri[1] as usize)?,
                        head.mesh.positions.get(tri[2] as usize)?,
                    ];
                    let (c, _) = closest_on_triangle(q, corners.map(|c| *c));
                    Some(dist2(c, q).sqrt() as f32)
                })
                .fold(d, f32::min)
        };
        let mut gaps: Vec<f32> = face.iter().map(|p| surface_gap(*p)).collect();
        gaps.sort_by(f32::total_cmp);
        let median = gaps[gaps.len() / 2];
        if median.is_nan() || median > ALIGNED_MM {
            return Err(HeadMismatch::NotOnHead { median_mm: median });
        }
        let mut normals = vec![[0.0f32; 3]; positions.len()];
        vertex_normals(&positions, &head.mesh.triangles, &mut normals).map_err(HeadMismatch::Normals)?;
        let positions: Vec<Vec3> = positions.iter().zip(&normals).map(|(p, n)| std::array::from_fn(|k| p[k] - INSET_MM * n[k])).collect();
        let anchors = positions.iter().map(|p| anchor(&face, *p)).collect();
        let inside = face_crop_indices(&head.mesh, &head.landmarks).unwrap_or_default();
        let mut scalp = vec![true; positions.len()];
        for i in inside {
            if let Some(s) = scalp.get_mut(i as usize) {
                *s = false;
            }
        }
        let eyes: Vec<f32> = [36usize, 39, 42, 45]
            .iter()
            .filter_map(|&k| model.landmarks.get(k))
            .filter_map(|&i| face.get(i as usize))
            .map(|p| p[1])
            .collect();
        let eye_y = if eyes.is_empty() { 0.0 } else { eyes.iter().sum::<f32>() / eyes.len() as f32 };
        let chin_y = model.landmarks.get(8).and_then(|&i| face.get(i as usize)).map_or(eye_y - 120.0, |p| p[1]);
        Ok(Self { positions, normals, albedos, triangles: head.mesh.triangles.clone(), anchors, scalp, eye_y, chin_y })
    }

    /// Vertices of the head.
    pub fn vertices(&self) -> usize {
        self.positions.len()
    }

    /// The head around `face` (an instance of `model`): shape and colour changes of the face
    /// carried over to the head (shape fading away from the face), with random hair from `rng`.
    pub fn around(&self, model: &GpModel, face: &Instance, rng: &mut impl Rng) -> HeadedInstance {
        let hair = self.draw_hair(rng);
        let mut headed = self.around_bare(model, face);
        if let Some(hair) = hair {
            self.paint_hair(&mut headed, face.positions.len(), hair, |_| hair.tone);
        }
        headed
    }

    /// Short hair in 60 % of draws.
    pub(super) fn draw_hair(&self, rng: &mut impl Rng) -> Option<Hair> {
        rng.random_bool(0.6).then(|| {
            let tones = [[0.02f32, 0.015, 0.01], [0.08, 0.04, 0.02], [0.25, 0.15, 0.07], [0.45, 0.35, 0.2], [0.35, 0.35, 0.35]];
            let t = tones[rng.random_range(0..tones.len())];
            let v = rng.random_range(0.7f32..1.3);
            Hair {
                tone: t.map(|c| (c * v).min(1.0)),
                hairline: self.eye_y + rng.random_range(20.0f32..55.0),
                back: rng.random_range(-40.0f32..10.0),
            }
        })
    }

    /// Whether `hair` covers head vertex `i` (rest position `p`): the scalp above the hairline,
    /// and the back of the head down to the ears.
    fn covers(&self, i: usize, hair: &Hair) -> bool {
        let p = self.positions[i];
        self.scalp[i] && (p[1] > hair.hairline || (p[2] < hair.back && p[1] > self.eye_y - 25.0))
    }

    /// Paints `hair` over the head part of `headed` (head vertex `i` at `n + i`), each covered
    /// vertex with `tone(i)`; returns the covered head vertices (`i`).
    pub(super) fn paint_hair(&self, headed: &mut HeadedInstance, n: usize, hair: Hair, tone: impl Fn(usize) -> Vec3) -> Vec<usize> {
        let covered: Vec<usize> = (0..self.positions.len()).filter(|&i| self.covers(i, &hair)).collect();
        for &i in &covered {
            if let Some(c) = headed.instance.albedos.get_mut(n + i) {
                *c = tone(i);
            }
        }
        covered
    }

    /// The bare head around `face`: its shape and colour changes carried over.
    pub(super) fn around_bare(&self, model: &GpModel, face: &Instance) -> HeadedInstance {
        let n = face.positions.len();
        let mean = &model.shape.mean;
        let colour_mean = &model.color.mean;
        let delta = |values: &[Vec3], base: &[Vec3], a: &Anchor| -> Vec3 {
            let mut d = [0.0f32; 3];
            for (&id, &w) in a.ids.iter().zip(&a.weights) {
                let (v, b) = (values.get(id as usize), base.get(id as usize));
                if let (Some(v), Some(b)) = (v, b) {
                    for k in 0..3 {
                        d[k] += w * (v[k] - b[k]);
                    }
                }
            }
            d
        };
        let mut positions = face.positions.clone();
        let mut albedos = face.albedos.clone();
        for (i, a) in self.anchors.iter().enumerate() {
            let ds = delta(&face.positions, mean, a);
            let dc = delta(&face.albedos, colour_mean, a);
            let p = self.positions[i];
            positions.push(std::array::from_fn(|k| p[k] + a.fade * ds[k]));
            albedos.push(std::array::from_fn(|k| (self.albedos[i][k] + dc[k]).clamp(0.0, 1.0)));
        }
        let mut triangles = model.triangles.clone();
        triangles.extend(self.triangles.iter().map(|t| t.map(|v| v + n as u32)));
        HeadedInstance { instance: Instance { positions, albedos }, triangles }
    }
}

/// The `ANCHORS` nearest face vertices of `p`, weighted by inverse squared distance.
fn anchor(face: &[Vec3], p: Vec3) -> Anchor {
    let mut near = [(0u32, f32::INFINITY); ANCHORS];
    for (i, q) in face.iter().enumerate() {
        let d = (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2);
        if d < near[ANCHORS - 1].1 {
            near[ANCHORS - 1] = (i as u32, d);
            near.sort_by(|a, b| a.1.total_cmp(&b.1));
        }
    }
    let raw: [f32; ANCHORS] = near.map(|(_, d)| 1.0 / (d + 1.0));
    let sum: f32 = raw.iter().sum();
    let closest = near[0].1.sqrt();
    Anchor { ids: near.map(|(i, _)| i), weights: raw.map(|w| w / sum), fade: (-(closest / FADE_MM).powi(2)).exp() }
}
