//! The jaw contour as a silhouette: contour landmarks (iBUG-68 points 0–16) that a detector puts
//! on the face's outline correspond to the model's current outline, not to fixed vertices.
//!
//! A [`Silhouette`] holds a pool of candidate vertices around the jaw and cheeks (chosen once on
//! the model's mean shape, up to [`CONTOUR_POOL`] of them) and, per target contour point, the
//! image direction pointing out of the face (from the neighbouring target points). Under a pose,
//! contour landmark `i` is the pool vertex that projects farthest out along its direction among
//! those within a band across it: the outline point on the line through the target point. The
//! choice depends on the pose and camera only (the mean shape's positions), so the landmark term
//! stays a function of the state; the selected vertex's position is then the current shape's.
//! The residual of a contour landmark is its distance along the outward direction only: where
//! on the outline a detector puts a jaw point varies between detectors and views.
//!
//! This follows the idea of eos's contour fitting (nearest model-contour vertex to each detected
//! contour point), with the outline found per pose instead of from a fixed vertex list.

use crate::error::FitError;
use crate::fit::likelihood::landmarks::LandmarkTarget;
use crate::fit::solve::light::facing;
use crate::geometry::mat_vec;
use crate::geometry::{TriIndex, Vec3};
use crate::model::morphable::MorphableModel;
use crate::render::{Camera, Pose};

/// Largest number of candidate vertices of the silhouette pool.
pub const CONTOUR_POOL: usize = 1024;
/// Largest number of contour landmarks (iBUG-68: 17).
pub const MAX_CONTOUR: usize = 17;
/// "No vertex selected": the contour landmark keeps its fixed vertex.
pub const NO_VERTEX: u32 = u32::MAX;

/// iBUG-68 indices used to build the face frame.
const CHIN: usize = 8;
const EYES: core::ops::Range<usize> = 36..48;
const NOSE_TIP: usize = 30;
const OUTER_EYES: (usize, usize) = (36, 45);

/// The candidate pool and the target's outward directions (see the module docs).
#[derive(Debug, Clone)]
pub struct Silhouette<'a> {
    mean: &'a [Vec3],
    ids: heapless::Vec<u32, CONTOUR_POOL>,
    normals: [[i8; 3]; CONTOUR_POOL],
    ends: [Vec3; 2],
    near_frontal: f32,
    outward: [[f32; 2]; MAX_CONTOUR],
    count: usize,
    band: f32,
}

impl<'a> Silhouette<'a> {
    /// The pool of `model` (iBUG-68 landmarks, the first `count` ≤ [`MAX_CONTOUR`] of them the
    /// contour) for `target`'s contour points. `Err(BadConfig)` if the model has no 68 landmarks or
    /// its landmarks give no face frame.
    pub fn new<I: TriIndex>(model: &MorphableModel<'a, I>, target: &LandmarkTarget<'_>, count: usize) -> Result<Self, FitError> {
        let lms = model.landmarks();
        if lms.len() != 68 || count == 0 || count > MAX_CONTOUR || target.len() != 68 {
            return Err(FitError::BadConfig);
        }
        let mean = model.shape_mean();
        let at = |i: usize| -> Result<Vec3, FitError> {
            let v = *lms.get(i).ok_or(FitError::IndexOutOfRange)? as usize;
            mean.get(v).copied().ok_or(FitError::IndexOutOfRange)
        };
        let frame = FaceFrame::new(&at)?;
        let local = |p: Vec3| frame.local(p);
        let chin = local(at(CHIN)?);
        let ends = [local(at(0)?), local(at(count - 1)?)];
        let d = frame.eye_distance;
        // The frontal jaw outline as a function of x (the contour points are ordered in x).
        let mut outline = [[0.0f32; 2]; MAX_CONTOUR];
        for (o, i) in outline.iter_mut().zip(0..count) {
            let p = local(at(i)?);
            *o = [p[0], p[1]];
        }
        let outline = outline.get(..count).ok_or(FitError::BadConfig)?;
        let top = ends[0][1].max(ends[1][1]);
        // The cheeks and jaw sides from the jaw angle forward: where the outline of the side
        // turned away runs up to about 50° of yaw (the chin's points keep fixed vertices).
        let back = ends[0][2].min(ends[1][2]) - 0.35 * d;
        let lateral = 0.25 * d;
        let keep = |p: Vec3| -> bool {
            let q = local(p);
            let below_outline = q[1] < outline_height(outline, q[0]) - 0.05 * d;
            q[1] >= chin[1] && q[1] <= top && q[2] >= back && q[0].abs() >= lateral && !below_outline
        };
        let total = mean.iter().filter(|p| keep(**p)).count();
        let stride = total.div_ceil(CONTOUR_POOL).max(1);
        let mut s = Self {
            mean,
            ids: heapless::Vec::new(),
            normals: [[0; 3]; CONTOUR_POOL],
            ends: [at(0)?, at(count - 1)?],
            near_frontal: 0.13 * d,
            outward: [[0.0; 2]; MAX_CONTOUR],
            count,
            band: 0.0,
        };
        for (v, _) in mean.iter().enumerate().filter(|(_, p)| keep(**p)).step_by(stride) {
            // The stride keeps the pool within its capacity, so the push cannot fail.
            if s.ids.push(v as u32).is_err() {
                break;
            }
        }
        if s.ids.is_empty() {
            return Err(FitError::BadConfig);
        }
        s.pool_normals(model.triangles(), mean)?;
        s.set_target(target);
        Ok(s)
    }

    /// Area-weighted vertex normals of the pool vertices on the mean shape (the pool's ids are
    /// increasing, so a triangle's corners are found by binary search).
    fn pool_normals<I: TriIndex>(&mut self, triangles: &[[I; 3]], mean: &[Vec3]) -> Result<(), FitError> {
        // Accumulated in f32 in chunks of the pool (the i8 store keeps the pool small on a device).
        const CHUNK: usize = 128;
        let mut start = 0;
        while start < self.ids.len() {
            let ids = self.ids.get(start..(start + CHUNK).min(self.ids.len())).unwrap_or(&[]);
            let mut acc = [[0.0f32; 3]; CHUNK];
            for t in triangles {
                let [a, b, c] = [t[0].index(), t[1].index(), t[2].index()];
                let hit = |v: usize| ids.binary_search(&(v as u32)).ok();
                if hit(a).is_none() && hit(b).is_none() && hit(c).is_none() {
                    continue;
                }
                let (pa, pb, pc) = (
                    mean.get(a).copied().ok_or(FitError::IndexOutOfRange)?,
                    mean.get(b).copied().ok_or(FitError::IndexOutOfRange)?,
                    mean.get(c).copied().ok_or(FitError::IndexOutOfRange)?,
                );
                let n = cross(sub(pb, pa), sub(pc, pa));
                for k in [a, b, c].into_iter().filter_map(hit) {
                    if let Some(slot) = acc.get_mut(k) {
                        *slot = [slot[0] + n[0], slot[1] + n[1], slot[2] + n[2]];
                    }
                }
            }
            for (k, n) in acc.iter().enumerate().take(ids.len()) {
                let u = normalize(*n).unwrap_or([0.0; 3]);
                if let Some(slot) = self.normals.get_mut(start + k) {
                    *slot = u.map(|c| libm::roundf(c * 127.0) as i8);
                }
            }
            start += CHUNK;
        }
        Ok(())
    }

    /// Outward image directions of the target's contour points (perpendicular to the line through
    /// the neighbouring valid points, pointing away from the centroid of the inner points) and the
    /// band half-width (half the mean spacing of consecutive contour points).
    fn set_target(&mut self, target: &LandmarkTarget<'_>) {
        let (pts, valid) = (target.points(), target.valid());
        let n = self.count;
        let ok = |i: usize| valid.get(i).copied().unwrap_or(false);
        let pt = |i: usize| pts.get(i).copied().unwrap_or([0.0; 2]);
        let (mut c, mut k) = ([0.0f32; 2], 0.0f32);
        for i in (n..pts.len()).filter(|&i| ok(i)) {
            c = [c[0] + pt(i)[0], c[1] + pt(i)[1]];
            k += 1.0;
        }
        let c = [c[0] / k.max(1.0), c[1] / k.max(1.0)];
        let (mut spacing, mut pairs) = (0.0f32, 0.0f32);
        for i in 0..n {
            let prev = (0..i).rev().find(|&j| ok(j)).unwrap_or(i);
            let next = (i + 1..n).find(|&j| ok(j)).unwrap_or(i);
            let (a, b) = (pt(prev), pt(next));
            let t = [b[0] - a[0], b[1] - a[1]];
            let len = libm::sqrtf(t[0] * t[0] + t[1] * t[1]);
            let mut o = if len > 0.0 { [t[1] / len, -t[0] / len] } else { [0.0, 0.0] };
            let p = pt(i);
            if o[0] * (p[0] - c[0]) + o[1] * (p[1] - c[1]) < 0.0 {
                o = [-o[0], -o[1]];
            }
            if let Some(slot) = self.outward.get_mut(i) {
                *slot = o;
            }
            if ok(i) && i + 1 < n && ok(i + 1) {
                let q = pt(i + 1);
                spacing += libm::sqrtf((q[0] - p[0]) * (q[0] - p[0]) + (q[1] - p[1]) * (q[1] - p[1]));
                pairs += 1.0;
            }
        }
        self.band = (0.5 * spacing / pairs.max(1.0)).max(1.0);
    }

    /// Number of contour landmarks.
    pub fn count(&self) -> usize {
        self.count
    }

    /// Number of candidate vertices in the pool.
    pub fn pool_len(&self) -> usize {
        self.ids.len()
    }

    /// The outward directions of the contour landmarks (for the landmark term).
    pub fn outward(&self) -> &[[f32; 2]] {
        self.outward.get(..self.count).unwrap_or(&[])
    }

    /// For each contour landmark on the side turned away from the camera (both sides within about
    /// 7.5° of frontal) the pool vertex on the outline under `pose` and `camera`: among the
    /// candidates that do not face away from the camera and project within the band, the one
    /// farthest along the outward direction. [`NO_VERTEX`] (the fixed vertex is used) on the side
    /// turned toward the camera, where the detected contour is the jaw's edge on the cheek rather
    /// than an occluding outline (eos uses only that side's contour too), and where no candidate
    /// projects into the band. `out` gets one id per contour landmark.
    pub fn select(&self, pose: &Pose, camera: &Camera, target: &LandmarkTarget<'_>, out: &mut [u32; MAX_CONTOUR]) {
        let r = pose.rotation();
        let t = pose.translation;
        let mut best = [f32::NEG_INFINITY; MAX_CONTOUR];
        *out = [NO_VERTEX; MAX_CONTOUR];
        // Depth (distance in front of the camera, −z) of the two ends of the contour.
        let depth = |p: Vec3| -(mat_vec(&r, p)[2] + t[2]);
        let (d0, d1) = (depth(self.ends[0]), depth(self.ends[1]));
        let half = self.count / 2;
        // The chin's outline is the jaw over the neck: an occlusion the pool cannot see, so the
        // points around it keep their fixed vertices.
        let chin = half.saturating_sub(2)..=half + 2;
        let active = |i: usize| {
            if chin.contains(&i) {
                false
            } else if d0 - d1 > self.near_frontal {
                i <= half
            } else if d1 - d0 > self.near_frontal {
                i >= half
            } else {
                true
            }
        };
        let pts = target.points();
        for (&id, nm) in self.ids.iter().zip(&self.normals) {
            let Some(p) = self.mean.get(id as usize) else { continue };
            let q = mat_vec(&r, *p);
            let q = [q[0] + t[0], q[1] + t[1], q[2] + t[2]];
            // Skip vertices that face away from the camera (slightly past grazing is allowed).
            let n = mat_vec(&r, nm.map(f32::from));
            if dot(n, q) > 0.1 * 127.0 * libm::sqrtf(dot(q, q)) {
                continue;
            }
            let Some(s) = camera.project(q) else {
                continue;
            };
            for (i, ((o, b), (n, tp))) in out.iter_mut().zip(best.iter_mut()).zip(self.outward.iter().zip(pts)).enumerate().take(self.count)
            {
                if !active(i) {
                    continue;
                }
                let (dx, dy) = (s.x - tp[0], s.y - tp[1]);
                let across = dx * n[1] - dy * n[0];
                let along = dx * n[0] + dy * n[1];
                if across.abs() <= self.band && along > *b {
                    *b = along;
                    *o = id;
                }
            }
        }
    }
}

/// Clears `mask[i]` for each of the first `contour` landmarks whose model vertex faces away from
/// the camera under `pose` (cosine between its normal and the direction to the camera below
/// `min_cos`): a detector puts such a point on the visible outline, where the fixed vertex is
/// not, and the point then pulls the shape and the yaw toward frontal. `positions` and `normals`
/// are the instance's (model space); landmarks past the mesh are left as they are.
pub fn hide_turned_away_contour<I: TriIndex>(
    model: &MorphableModel<'_, I>,
    positions: &[Vec3],
    normals: &[Vec3],
    pose: &Pose,
    contour: usize,
    min_cos: f32,
    mask: &mut [bool],
) {
    let r = pose.rotation();
    for (seen, &v) in mask.iter_mut().zip(model.landmarks()).take(contour.min(MAX_CONTOUR)) {
        let (Some(p), Some(n)) = (positions.get(v as usize), normals.get(v as usize)) else { continue };
        // NaN (a degenerate vertex) keeps the point.
        if facing(&r, pose.translation, *p, *n).cos < min_cos {
            *seen = false;
        }
    }
}

/// The frontal outline's height at `x`: piecewise linear through the contour points, clamped at
/// the ends (they are ordered in x, in either direction).
fn outline_height(outline: &[[f32; 2]], x: f32) -> f32 {
    let (Some(first), Some(last)) = (outline.first(), outline.last()) else {
        return f32::NEG_INFINITY;
    };
    let (lo, hi) = if first[0] <= last[0] { (first, last) } else { (last, first) };
    if x <= lo[0] {
        return lo[1];
    }
    if x >= hi[0] {
        return hi[1];
    }
    for w in outline.windows(2) {
        let (Some(a), Some(b)) = (w.first(), w.get(1)) else { continue };
        let (x0, x1) = (a[0].min(b[0]), a[0].max(b[0]));
        if x >= x0 && x <= x1 && x1 > x0 {
            let f = (x - a[0]) / (b[0] - a[0]);
            return a[1] + f * (b[1] - a[1]);
        }
    }
    lo[1].min(hi[1])
}

/// An orthonormal face frame from the mean shape's landmarks: x from the first contour point to the
/// last, y up (chin to eyes), z forward (towards the nose tip); origin the eyes' centre.
struct FaceFrame {
    origin: Vec3,
    axes: [Vec3; 3],
    eye_distance: f32,
}

impl FaceFrame {
    fn new(at: &dyn Fn(usize) -> Result<Vec3, FitError>) -> Result<Self, FitError> {
        let mut eyes = [0.0f32; 3];
        for i in EYES {
            let p = at(i)?;
            eyes = [eyes[0] + p[0], eyes[1] + p[1], eyes[2] + p[2]];
        }
        let k = EYES.len() as f32;
        let origin = [eyes[0] / k, eyes[1] / k, eyes[2] / k];
        let x = normalize(sub(at(16)?, at(0)?)).ok_or(FitError::BadConfig)?;
        let up = sub(origin, at(CHIN)?);
        let y = normalize(sub(up, scale(x, dot(up, x)))).ok_or(FitError::BadConfig)?;
        let mut z = cross(x, y);
        if dot(sub(at(NOSE_TIP)?, origin), z) < 0.0 {
            z = scale(z, -1.0);
        }
        let eye_distance = libm::sqrtf(dot(sub(at(OUTER_EYES.1)?, at(OUTER_EYES.0)?), sub(at(OUTER_EYES.1)?, at(OUTER_EYES.0)?)));
        if !(eye_distance > 0.0 && eye_distance.is_finite()) {
            return Err(FitError::BadConfig);
        }
        Ok(Self { origin, axes: [x, y, z], eye_distance })
    }

    fn local(&self, p: Vec3) -> Vec3 {
        let d = sub(p, self.origin);
        [dot(d, self.axes[0]), dot(d, self.axes[1]), dot(d, self.axes[2])]
    }
}

fn sub(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn scale(a: Vec3, s: f32) -> Vec3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

fn dot(a: Vec3, b: Vec3) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: Vec3, b: Vec3) -> Vec3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

fn normalize(a: Vec3) -> Option<Vec3> {
    let n = libm::sqrtf(dot(a, a));
    (n > 0.0 && n.is_finite()).then(|| scale(a, 1.0 / n))
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;
    use crate::model::basis::{Basis, DenseBasis};

    #[test]
    fn contour_points_turned_away_from_the_camera_are_hidden() {
        // Three vertices, each a landmark: 0 faces the camera (+z, the camera 500 mm in front),
        // 1 faces away (−z), 2 faces sideways at 60° (cos 0.5); one degenerate triangle.
        let positions = [[0.0f32, 0.0, 0.0], [10.0, 0.0, 0.0], [0.0, 10.0, 0.0]];
        let normals = [[0.0f32, 0.0, 1.0], [0.0, 0.0, -1.0], [0.866, 0.0, 0.5]];
        let (empty, triangles, landmarks) = ([0.0f32; 0], [[0u32, 1, 2]], [0u32, 1, 2]);
        let basis = || Basis::Dense(DenseBasis::new(&empty, 0, 3).unwrap());
        let model = MorphableModel::new(&positions, &positions, basis(), basis(), &triangles, &landmarks).unwrap();
        let pose = Pose::frontal(500.0);
        let hide = |contour: usize, min_cos: f32| {
            let mut mask = [true; 3];
            hide_turned_away_contour(&model, &positions, &normals, &pose, contour, min_cos, &mut mask);
            mask
        };
        assert_eq!(hide(3, 0.0), [true, false, true]);
        assert_eq!(hide(3, 0.7), [true, false, false]);
        assert_eq!(hide(3, -1.5), [true, true, true], "-1 or less keeps every point");
        assert_eq!(hide(1, 0.7), [true, true, true], "only the contour's points are looked at");
    }

    #[test]
    fn outline_height_interpolates_and_clamps() {
        let o = [[-2.0, 0.0], [0.0, -1.0], [2.0, 0.0]];
        assert_eq!(outline_height(&o, -3.0), 0.0);
        assert!((outline_height(&o, -1.0) + 0.5).abs() < 1e-6);
        assert!((outline_height(&o, 1.0) + 0.5).abs() < 1e-6);
        let rev = [[2.0, 0.0], [0.0, -1.0], [-2.0, 0.0]];
        assert!((outline_height(&rev, 1.0) + 0.5).abs() < 1e-6);
    }
}
