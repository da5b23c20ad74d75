//! Which vertices the image says something about, decided as the fit's shape solve decides it:
//! facing the camera, not hidden behind a nearer part of the face (a coarse depth grid of vertex
//! splats), and projecting into the pixels the photo covers.
//!
//! The core keeps its depth grid private; this is the same test with the same constants (64 cells
//! per side, 5 mm tolerance), written for the host.

use gpmm_core::fit::TargetImage;
use gpmm_core::geometry::mat_vec;
use gpmm_core::render::{Camera, Pose};

type Vec3 = [f32; 3];

/// Cells per side of the depth grid.
const DEPTH_GRID: usize = 64;
/// How far (mm) behind its cell's nearest vertex a vertex may lie and still count as seen.
const OCCLUSION_TOLERANCE_MM: f32 = 5.0;

/// A vertex the image speaks about: its index and the image's colour where it projects.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Seen {
    /// The vertex.
    pub vertex: usize,
    /// The image's linear colour at its projection (bilinear).
    pub target: Vec3,
}

/// The vertices of `positions` (normals `normals`, model space) seen through `pose` and `camera`
/// in `image` with a facing cosine of at least `min_cos`, in vertex order.
pub fn seen_vertices(
    positions: &[Vec3],
    normals: &[Vec3],
    pose: &Pose,
    camera: &Camera,
    image: &TargetImage<'_>,
    min_cos: f32,
) -> Vec<Seen> {
    let r = pose.rotation();
    let t = pose.translation;
    let to_camera = |p: Vec3| {
        let q = mat_vec(&r, p);
        [q[0] + t[0], q[1] + t[1], q[2] + t[2]]
    };
    let cell = (image.width().max(image.height()) as f32 / DEPTH_GRID as f32).max(1.0);
    let locate = |p: Vec3| -> Option<(usize, f32, f32, f32)> {
        let pc = to_camera(p);
        let s = camera.project(pc)?;
        if !(s.x >= 0.0 && s.y >= 0.0) {
            return None;
        }
        let (i, j) = ((s.x / cell) as usize, (s.y / cell) as usize);
        (i < DEPTH_GRID && j < DEPTH_GRID).then_some((j * DEPTH_GRID + i, -pc[2], s.x, s.y))
    };
    let mut depth = vec![f32::INFINITY; DEPTH_GRID * DEPTH_GRID];
    for p in positions {
        if let Some((c, d, _, _)) = locate(*p) {
            depth[c] = depth[c].min(d);
        }
    }
    let mut out = Vec::new();
    for (v, (p, n)) in positions.iter().zip(normals).enumerate() {
        let pc = to_camera(*p);
        let nc = mat_vec(&r, *n);
        let dist = (pc[0] * pc[0] + pc[1] * pc[1] + pc[2] * pc[2]).sqrt();
        let cos = -(nc[0] * pc[0] + nc[1] * pc[1] + nc[2] * pc[2]) / dist;
        if cos.is_nan() || cos < min_cos {
            continue;
        }
        let Some((c, d, x, y)) = locate(*p) else { continue };
        if d > depth[c] + OCCLUSION_TOLERANCE_MM {
            continue;
        }
        if let Some(target) = image.sample_bilinear(x, y) {
            out.push(Seen { vertex: v, target });
        }
    }
    out
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use gpmm_core::fit::CoveredPixels;

    #[test]
    fn hidden_back_facing_and_uncovered_vertices_are_not_seen() {
        let pixels = [[128u8; 3]; 64 * 64];
        // Only the right half of the image is covered by the photo.
        let image = TargetImage::new(&pixels, 64, 64).unwrap().with_covered(CoveredPixels { x0: 32, y0: 0, x1: 64, y1: 64 }).unwrap();
        let pose = Pose { yaw: 0.0, pitch: 0.0, roll: 0.0, translation: [0.0, 0.0, -500.0] };
        let camera = Camera::centered(64, 64, 500.0);
        let toward = [0.0, 0.0, 1.0];
        // A nose tip and the cheek 20 mm behind it on the same ray, a back-facing point, a point
        // on the uncovered left, and a lone visible point on the right.
        let positions = [[5.0, 0.0, 20.0], [5.0, 0.0, 0.0], [20.0, 5.0, 0.0], [-20.0, 0.0, 0.0], [20.0, -10.0, 0.0]];
        let normals = [toward, toward, [0.0, 0.0, -1.0], toward, toward];
        let seen: Vec<usize> = seen_vertices(&positions, &normals, &pose, &camera, &image, 0.3).iter().map(|s| s.vertex).collect();
        assert_eq!(seen, vec![0, 4]);
    }
}
