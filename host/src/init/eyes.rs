//! Open eyes painted over the template's closed ones in training scenes. The template scan was
//! captured with its eyes shut, so every face a model built from it renders has them shut, while
//! faces in photos mostly have them open: a dark iris in a light sclera, framed by lash lines. A
//! network that has only seen shut lids reads an open eye's dark opening as a crease and puts the
//! eye (and the brows above it) too low. Here each scene may open the eyes: the albedo of the face
//! vertices inside an almond between the eye corners is repainted (sclera, iris, pupil, lash line),
//! and the lid landmarks follow the painted lids, so the labels still say where the lids are.
//!
//! Everything is measured on the model's mean shape in an eye frame: `s` runs from the first
//! corner (−1) to the second (+1), `t` upwards, both in half eye widths.

use crate::gp::model::GpModel;
use gpmm_core::Vec3;
use rand::{Rng, RngExt};

/// The iBUG-68 index of each eye's first corner (its ring of six follows).
const EYE_FIRST: [usize; 2] = [36, 42];
/// Chance that a scene's eyes stay shut as in the scan (blinks, squints, smiles).
const SHUT: f64 = 0.2;
/// Vertices farther than this from the eye's plane (mm) are not the eye.
const PLANE_MM: f32 = 10.0;

/// One eye's vertices and triangles in its frame, and where its lid landmarks sit along it.
#[derive(Debug, Clone)]
struct EyeRegion {
    /// iBUG index of the eye's first corner.
    first: usize,
    /// Face vertex ids near the eye and their `(s, t)`.
    vertices: Vec<(u32, [f32; 2])>,
    /// Model triangles whose three vertices are all near the eye (indices into `vertices`).
    triangles: Vec<[usize; 3]>,
    /// `s` of the lid landmarks `first + 1, + 2` (upper) and `+ 4, + 5` (lower).
    lid_s: [f32; 4],
    /// `t` of the shut lid's line at `s = 0` (the line curves like `1 − s²`).
    shut_t: f32,
}

/// The eyes of one model, ready to be opened in its instances.
#[derive(Debug, Clone)]
pub struct OpenEyes {
    eyes: Vec<EyeRegion>,
}

/// How one scene opens its eyes (shared by both eyes, as people open them).
#[derive(Debug, Clone, Copy)]
pub struct Opening {
    /// Opening at the eye's middle (half eye widths).
    height: f32,
    /// Share of the opening above the shut lid's line.
    upper: f32,
}

fn sub(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: Vec3, b: Vec3) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn scaled(a: Vec3, k: f32) -> Vec3 {
    a.map(|v| v * k)
}

/// The lid curve's shape: 1 in the middle, 0 at the corners.
fn lid(s: f32) -> f32 {
    (1.0 - s * s).max(0.0)
}

impl OpenEyes {
    /// The eye regions of `model` (`None` unless it has the 68 iBUG landmarks).
    pub fn of_model(model: &GpModel) -> Option<Self> {
        if model.landmarks.len() != 68 {
            return None;
        }
        let mean = &model.shape.mean;
        let at = |k: usize| model.landmarks.get(k).and_then(|&i| mean.get(i as usize)).copied();
        let mut eyes = Vec::new();
        for first in EYE_FIRST {
            let (a, b) = (at(first)?, at(first + 3)?);
            let origin = scaled([a[0] + b[0], a[1] + b[1], a[2] + b[2]], 0.5);
            let across = sub(b, a);
            let half = dot(across, across).sqrt() * 0.5;
            if half.is_nan() || half <= 1.0 {
                return None;
            }
            let u = scaled(across, 0.5 / half);
            // Up: the model's +y without its part along the eye.
            let y = [0.0, 1.0, 0.0];
            let w0 = sub(y, scaled(u, dot(y, u)));
            let wn = dot(w0, w0).sqrt();
            if wn.is_nan() || wn <= 0.1 {
                return None;
            }
            let w = scaled(w0, 1.0 / wn);
            let n = [u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]];
            let frame = |p: Vec3| {
                let d = sub(p, origin);
                ([dot(d, u) / half, dot(d, w) / half], dot(d, n))
            };
            let mut index = vec![usize::MAX; mean.len()];
            let mut vertices = Vec::new();
            for (i, p) in mean.iter().enumerate() {
                let (st, depth) = frame(*p);
                if st[0].abs() <= 1.4 && st[1].abs() <= 1.2 && depth.abs() <= PLANE_MM {
                    index[i] = vertices.len();
                    vertices.push((i as u32, st));
                }
            }
            let triangles = model
                .triangles
                .iter()
                .filter_map(|t| {
                    let v = t.map(|i| index.get(i as usize).copied().unwrap_or(usize::MAX));
                    v.iter().all(|&i| i != usize::MAX).then_some(v)
                })
                .collect();
            let lid_st: Vec<[f32; 2]> = [1, 2, 4, 5].iter().filter_map(|&k| at(first + k)).map(|p| frame(p).0).collect();
            let [l0, l1, l2, l3] = lid_st.as_slice() else { return None };
            let lid_s = [l0[0], l1[0], l2[0], l3[0]];
            let shut_t = lid_st.iter().map(|st| st[1] / lid(st[0]).max(0.2)).sum::<f32>() / 4.0;
            eyes.push(EyeRegion { first, vertices, triangles, lid_s, shut_t });
        }
        Some(Self { eyes })
    }

    /// Face vertices near each eye (for tests and reports).
    pub fn region_sizes(&self) -> Vec<usize> {
        self.eyes.iter().map(|e| e.vertices.len()).collect()
    }

    /// Draws whether and how this scene's eyes are open and repaints the face's `albedos` (the
    /// model's vertex order) accordingly; `None`: they stay shut.
    pub fn paint(&self, albedos: &mut [Vec3], rng: &mut impl Rng) -> Option<Opening> {
        if rng.random_bool(SHUT) {
            return None;
        }
        let opening = Opening { height: rng.random_range(0.45f32..0.9), upper: rng.random_range(0.5f32..0.7) };
        // Iris colours (linear albedo): dark brown, brown, hazel, blue-grey, green.
        let irises = [[0.03f32, 0.016, 0.008], [0.08, 0.04, 0.018], [0.12, 0.085, 0.04], [0.09, 0.12, 0.15], [0.07, 0.09, 0.05]];
        let iris = irises[rng.random_range(0..irises.len())].map(|c| c * rng.random_range(0.6f32..1.5));
        let sclera_level = rng.random_range(0.35f32..0.75);
        let sclera = [sclera_level, sclera_level * rng.random_range(0.9f32..1.0), sclera_level * rng.random_range(0.85f32..1.0)];
        let iris_r = rng.random_range(0.35f32..0.55);
        let pupil_r = iris_r * rng.random_range(0.25f32..0.5);
        let gaze = [rng.random_range(-0.3f32..0.3), rng.random_range(-0.1f32..0.1)];
        let lash = rng.random_range(0.25f32..0.8);
        for eye in &self.eyes {
            // Both eyes' `s` run along the model's +x, so one gaze moves both irises alike.
            let gaze_s = gaze[0];
            for &(v, [s, t]) in &eye.vertices {
                let Some(a) = albedos.get_mut(v as usize) else { continue };
                let (top, bottom) = eye.lids(opening, s);
                if s.abs() >= 1.0 {
                    continue;
                }
                if t <= top && t >= bottom {
                    let centre_t =
                        eye.shut_t * lid(gaze_s) + opening.height * (opening.upper - 0.5) * lid(gaze_s) + gaze[1] * opening.height;
                    let d = ((s - gaze_s).powi(2) + (t - centre_t).powi(2)).sqrt();
                    *a = if d < pupil_r {
                        [0.01; 3]
                    } else if d < iris_r {
                        iris
                    } else {
                        // The sclera darkens toward the corners and under the upper lid.
                        let shade = (0.55 + 0.45 * lid(s)) * (0.7 + 0.3 * ((top - t) / (0.3 * opening.height)).clamp(0.0, 1.0));
                        sclera.map(|c| c * shade)
                    };
                } else if t > top && t < top + 0.12 {
                    *a = a.map(|c| c * lash);
                }
            }
        }
        Some(opening)
    }

    /// Moves the lid landmarks of `landmarks` (frame pixels, iBUG order) onto the painted lids:
    /// `projected(v)` is face vertex `v` in frame pixels.
    pub fn relabel_lids(&self, opening: Opening, projected: impl Fn(u32) -> Option<[f32; 2]>, landmarks: &mut [[f32; 2]]) {
        for eye in &self.eyes {
            for (j, &k) in [1usize, 2, 4, 5].iter().enumerate() {
                let s = eye.lid_s[j];
                let (top, bottom) = eye.lids(opening, s);
                let target = [s, if j < 2 { top } else { bottom }];
                if let (Some(p), Some(slot)) = (eye.project(target, &projected), landmarks.get_mut(eye.first + k)) {
                    *slot = p;
                }
            }
        }
    }
}

impl EyeRegion {
    /// The upper and lower lid's `t` at `s` for an opening.
    fn lids(&self, o: Opening, s: f32) -> (f32, f32) {
        let f = lid(s);
        (self.shut_t * f + o.height * o.upper * f, self.shut_t * f - o.height * (1.0 - o.upper) * f)
    }

    /// The point `(s, t)` of the eye's surface in frame pixels: barycentric within the triangle
    /// holding it, else the nearest vertex.
    fn project(&self, st: [f32; 2], projected: &impl Fn(u32) -> Option<[f32; 2]>) -> Option<[f32; 2]> {
        for tri in &self.triangles {
            let [a, b, c] = tri.map(|i| self.vertices[i].1);
            let det = (b[1] - c[1]) * (a[0] - c[0]) + (c[0] - b[0]) * (a[1] - c[1]);
            if det.abs() < 1e-9 {
                continue;
            }
            let l0 = ((b[1] - c[1]) * (st[0] - c[0]) + (c[0] - b[0]) * (st[1] - c[1])) / det;
            let l1 = ((c[1] - a[1]) * (st[0] - c[0]) + (a[0] - c[0]) * (st[1] - c[1])) / det;
            let l2 = 1.0 - l0 - l1;
            if l0 >= -1e-4 && l1 >= -1e-4 && l2 >= -1e-4 {
                let [pa, pb, pc] =
                    [projected(self.vertices[tri[0]].0)?, projected(self.vertices[tri[1]].0)?, projected(self.vertices[tri[2]].0)?];
                return Some([l0 * pa[0] + l1 * pb[0] + l2 * pc[0], l0 * pa[1] + l1 * pb[1] + l2 * pc[1]]);
            }
        }
        let nearest = self.vertices.iter().min_by(|x, y| {
            let dx = (x.1[0] - st[0]).powi(2) + (x.1[1] - st[1]).powi(2);
            let dy = (y.1[0] - st[0]).powi(2) + (y.1[1] - st[1]).powi(2);
            dx.total_cmp(&dy)
        })?;
        projected(nearest.0)
    }
}
