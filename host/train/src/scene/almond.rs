//! The geometry of the painted eyes of training scenes (`crate::scene::eyes`): an almond-shaped
//! opening between two corner landmarks of the model's mean face, the face vertices and triangles
//! around it, and the landmarks on its two rims.
//!
//! Coordinates are an opening's own frame on the mean shape: `s` runs from the first corner (−1)
//! to the second (+1) along the model's +x, `t` upwards, both in half widths. The shut line (where
//! the scan's rims meet) curves like `1 − s²`, and so do the rims of an opening.

use gpmm_core::geometry::Vec3;
use gpmm_host::gp::model::GpModel;

/// Vertices farther than this from the opening's plane (mm) are not part of it.
const PLANE_MM: f32 = 10.0;

/// How far one scene opens an opening.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Opening {
    /// Height at the middle (half widths).
    pub height: f32,
    /// Share of the height above the shut line.
    pub upper: f32,
}

/// An opening between two corner landmarks.
#[derive(Debug, Clone)]
pub struct Almond {
    /// Face vertex ids around the opening and their `(s, t)`.
    pub vertices: Vec<(u32, [f32; 2])>,
    /// Model triangles whose three vertices are all around it (indices into `vertices`).
    triangles: Vec<[usize; 3]>,
    /// Each vertex's height in front of the opening's plane (mm).
    depth: Vec<f32>,
    /// iBUG indices of the upper rim's landmarks and their `s`.
    upper: Vec<(usize, f32)>,
    /// iBUG indices of the lower rim's landmarks and their `s`.
    lower: Vec<(usize, f32)>,
    /// `t` of the shut line at `s = 0`.
    shut_t: f32,
}

/// An opening's frame: origin (mm), the `s`, `t` and out-of-plane directions, half width (mm).
/// In `f32`, as the measured trainings were made (`gpmm_host::mesh::geometry`'s `f64` helpers would
/// move borderline vertices and change the trained networks).
#[derive(Debug, Clone, Copy)]
struct Frame {
    origin: Vec3,
    u: Vec3,
    w: Vec3,
    n: Vec3,
    half: f32,
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

impl Frame {
    /// The frame between corners `a` and `b` (`t` along the model's +y); `None` if degenerate.
    fn between(a: Vec3, b: Vec3) -> Option<Self> {
        let origin = scaled([a[0] + b[0], a[1] + b[1], a[2] + b[2]], 0.5);
        let across = sub(b, a);
        let half = dot(across, across).sqrt() * 0.5;
        if half.is_nan() || half <= 1.0 {
            return None;
        }
        let u = scaled(across, 0.5 / half);
        // Up: the model's +y without its part along the opening.
        let y = [0.0, 1.0, 0.0];
        let w0 = sub(y, scaled(u, dot(y, u)));
        let wn = dot(w0, w0).sqrt();
        if wn.is_nan() || wn <= 0.1 {
            return None;
        }
        let w = scaled(w0, 1.0 / wn);
        let n = [u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]];
        Some(Self { origin, u, w, n, half })
    }

    /// `(s, t)` of a point (mm), and its height in front of the plane (mm).
    fn of(&self, p: Vec3) -> ([f32; 2], f32) {
        let d = sub(p, self.origin);
        ([dot(d, self.u) / self.half, dot(d, self.w) / self.half], dot(d, self.n))
    }
}

/// Landmark `k` (iBUG index) of `model`'s mean shape (mm), if it has it.
pub fn mean_landmark(model: &GpModel, k: usize) -> Option<Vec3> {
    model.landmarks.get(k).and_then(|&i| model.shape.mean.get(i as usize)).copied()
}

/// A rim's shape: 1 in the middle, 0 at the corners.
pub fn rim(s: f32) -> f32 {
    (1.0 - s * s).max(0.0)
}

impl Almond {
    /// The opening between landmarks `corners` of `model` (iBUG indices) with the given rim
    /// landmarks; `None` if the model lacks them or they are degenerate.
    pub fn of_model(model: &GpModel, corners: [usize; 2], upper: &[usize], lower: &[usize]) -> Option<Self> {
        let mean = &model.shape.mean;
        let at = |k: usize| mean_landmark(model, k);
        let frame = Frame::between(at(corners[0])?, at(corners[1])?)?;
        let mut index = vec![usize::MAX; mean.len()];
        let mut vertices = Vec::new();
        let mut depths = Vec::new();
        for (i, p) in mean.iter().enumerate() {
            let (st, depth) = frame.of(*p);
            if st[0].abs() <= 1.4 && st[1].abs() <= 1.2 && depth.abs() <= PLANE_MM {
                index[i] = vertices.len();
                vertices.push((i as u32, st));
                depths.push(depth);
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
        let on_rim = |ks: &[usize]| -> Option<Vec<(usize, [f32; 2])>> { ks.iter().map(|&k| Some((k, frame.of(at(k)?).0))).collect() };
        let (up, low) = (on_rim(upper)?, on_rim(lower)?);
        let rims: Vec<[f32; 2]> = up.iter().chain(&low).map(|r| r.1).collect();
        if rims.is_empty() {
            return None;
        }
        let shut_t = rims.iter().map(|st| st[1] / rim(st[0]).max(0.2)).sum::<f32>() / rims.len() as f32;
        let s_of = |v: Vec<(usize, [f32; 2])>| v.into_iter().map(|(k, st)| (k, st[0])).collect();
        Some(Self { vertices, triangles, depth: depths, upper: s_of(up), lower: s_of(low), shut_t })
    }

    /// The shut line's `t` at `s`.
    pub fn shut(&self, s: f32) -> f32 {
        self.shut_t * rim(s)
    }

    /// The upper and lower rim's `t` at `s` for an opening.
    pub fn rims(&self, o: Opening, s: f32) -> (f32, f32) {
        let f = rim(s);
        (self.shut_t * f + o.height * o.upper * f, self.shut_t * f - o.height * (1.0 - o.upper) * f)
    }

    /// Moves the rim landmarks of `landmarks` (frame pixels, iBUG order) onto the rims of an
    /// opening: `projected(v)` is face vertex `v` in frame pixels.
    pub fn relabel(&self, o: Opening, projected: &impl Fn(u32) -> Option<[f32; 2]>, landmarks: &mut [[f32; 2]]) {
        for (rim_points, top) in [(&self.upper, true), (&self.lower, false)] {
            for &(k, s) in rim_points {
                let (up, down) = self.rims(o, s);
                let target = [s, if top { up } else { down }];
                if let (Some(p), Some(slot)) = (self.project(target, projected), landmarks.get_mut(k)) {
                    *slot = p;
                }
            }
        }
    }

    /// The point `(s, t)` of the surface in frame pixels: barycentric within the front-most
    /// triangle holding it (lips and lids fold, so several may), else the nearest vertex.
    pub fn project(&self, st: [f32; 2], projected: &impl Fn(u32) -> Option<[f32; 2]>) -> Option<[f32; 2]> {
        let mut best: Option<([usize; 3], [f32; 3], f32)> = None;
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
                let front = l0 * self.depth[tri[0]] + l1 * self.depth[tri[1]] + l2 * self.depth[tri[2]];
                if best.is_none_or(|b| front > b.2) {
                    best = Some((*tri, [l0, l1, l2], front));
                }
            }
        }
        if let Some((tri, l, _)) = best {
            let [pa, pb, pc] =
                [projected(self.vertices[tri[0]].0)?, projected(self.vertices[tri[1]].0)?, projected(self.vertices[tri[2]].0)?];
            return Some([l[0] * pa[0] + l[1] * pb[0] + l[2] * pc[0], l[0] * pa[1] + l[1] * pb[1] + l[2] * pc[1]]);
        }
        let nearest = self.vertices.iter().min_by(|x, y| {
            let dx = (x.1[0] - st[0]).powi(2) + (x.1[1] - st[1]).powi(2);
            let dy = (y.1[0] - st[0]).powi(2) + (y.1[1] - st[1]).powi(2);
            dx.total_cmp(&dy)
        })?;
        projected(nearest.0)
    }
}
