//! Which vertices the image says something about, decided as the fit's shape solve decides it:
//! facing the camera, not hidden behind a nearer part of the face (a coarse depth grid of vertex
//! splats), and projecting into the pixels the photo covers.
//!
//! The tests are the core's own ([`facing`], [`DepthGrid`]).

use gpmm_core::fit::solve::light::facing;
use gpmm_core::fit::solve::shape::{DepthGrid, DEPTH_CELLS};
use gpmm_core::fit::TargetImage;
use gpmm_core::render::{Camera, Pose};

type Vec3 = [f32; 3];

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
    let mut depth = vec![0u16; DEPTH_CELLS];
    let Some(grid) = DepthGrid::new(&mut depth, pose, *camera, positions, image.width(), image.height()) else { return Vec::new() };
    let mut out = Vec::new();
    for (v, (p, n)) in positions.iter().zip(normals).enumerate() {
        let f = facing(&r, pose.translation, *p, *n);
        if f.cos.is_nan() || f.cos < min_cos || !grid.seen(*p) {
            continue;
        }
        let Some(s) = camera.project(f.position) else { continue };
        if let Some(target) = image.sample_bilinear(s.x, s.y) {
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
