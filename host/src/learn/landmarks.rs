//! Landmark definitions learned from the points the loop is given (`--learn-landmarks`): in each
//! fit, the vertex each point lands on; over the accepted fits, the vertex they agree on. A model
//! whose landmark vertices sit where a detector puts its points is fitted from that detector's
//! points without bending its shape to another convention.

use crate::mesh::Mesh;
use gpmm_core::geometry::Vec3;
use gpmm_core::render::{vertex_normals, Camera, Pose};

/// How far (mm, on the model's mean shape) from its current vertex a landmark's vertex is looked
/// for in one iteration.
pub const LANDMARK_SEARCH_MM: f32 = 20.0;

/// For each of `points` (working-image pixels), the vertex of `fit` nearest to it in the image
/// among those within `radius` mm of the landmark's current vertex on `mean_shape` and facing the
/// camera; `None` where there is none, the point is not finite, the landmark is unknown or the
/// fit's positions are not finite.
pub fn landmark_hits(
    fit: &Mesh,
    pose: &Pose,
    camera: &Camera,
    mean_shape: &[Vec3],
    landmarks: &[u32],
    points: &[[f32; 2]],
    radius: f32,
) -> Vec<Option<u32>> {
    let positions: Vec<Vec3> = fit.positions.iter().map(|p| p.map(|v| v as f32)).collect();
    let mut normals = vec![[0.0f32; 3]; positions.len()];
    if vertex_normals(&positions, &fit.triangles, &mut normals).is_err() {
        return vec![None; points.len()];
    }
    // Image position of each vertex that faces the camera (camera space looks down −z).
    let seen: Vec<Option<[f32; 2]>> = positions
        .iter()
        .zip(&normals)
        .map(|(&p, n)| {
            let q = pose.transform_point(p);
            let tip = pose.transform_point([p[0] + n[0], p[1] + n[1], p[2] + n[2]]);
            let facing = (tip[0] - q[0]) * -q[0] + (tip[1] - q[1]) * -q[1] + (tip[2] - q[2]) * -q[2];
            if facing <= 0.0 {
                return None;
            }
            camera.project(q).map(|s| [s.x, s.y])
        })
        .collect();
    points
        .iter()
        .enumerate()
        .map(|(k, point)| {
            let centre = mean_shape.get(*landmarks.get(k)? as usize)?;
            if !(point[0].is_finite() && point[1].is_finite()) {
                return None;
            }
            let mut best: Option<(f32, u32)> = None;
            for (v, (m, s)) in mean_shape.iter().zip(&seen).enumerate() {
                let Some(s) = s else { continue };
                if dist2(m, centre) > radius * radius {
                    continue;
                }
                let d = (s[0] - point[0]).powi(2) + (s[1] - point[1]).powi(2);
                if best.is_none_or(|(b, _)| d < b) {
                    best = Some((d, v as u32));
                }
            }
            best.map(|b| b.1)
        })
        .collect()
}

/// The landmark vertices the fits agree on: for landmark `k`, of the vertices the fits' hits name,
/// the one nearest (on `mean_shape`) to the per-coordinate median of their positions; a landmark
/// no fit hit keeps its vertex in `current`.
pub fn agreed_landmarks(mean_shape: &[Vec3], current: &[u32], hits: &[&[Option<u32>]]) -> Vec<u32> {
    current
        .iter()
        .enumerate()
        .map(|(k, &now)| {
            let named: Vec<(u32, Vec3)> = hits
                .iter()
                .filter_map(|h| h.get(k).copied().flatten())
                .filter_map(|v| mean_shape.get(v as usize).map(|&p| (v, p)))
                .collect();
            let median = [0, 1, 2].map(|a| {
                let mut c: Vec<f32> = named.iter().map(|(_, p)| p[a]).collect();
                c.sort_by(f32::total_cmp);
                c.get(c.len() / 2).copied().unwrap_or(0.0)
            });
            named.iter().min_by(|a, b| dist2(&a.1, &median).total_cmp(&dist2(&b.1, &median))).map_or(now, |&(v, _)| v)
        })
        .collect()
}

fn dist2(a: &Vec3, b: &Vec3) -> f32 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fits_agree_on_the_median_hit() {
        let mean: Vec<Vec3> = (0..10).map(|i| [i as f32, 0.0, 0.0]).collect();
        let (a, b, c, d) = ([Some(4), None], [Some(5), Some(9)], [Some(6), None], [Some(9), None]);
        let hits: Vec<&[Option<u32>]> = vec![&a, &b, &c, &d];
        // Landmark 0: hits at x = 4, 5, 6, 9, median 6 (the upper middle) → vertex 6; landmark 1:
        // one hit; a third landmark no fit names keeps its vertex.
        assert_eq!(agreed_landmarks(&mean, &[0, 1, 2], &hits), vec![6, 9, 2]);
    }

    #[test]
    fn a_hit_is_the_vertex_projected_nearest_the_point_within_reach() {
        // A flat grid facing the camera (+z towards it), 10 mm apart, 500 mm in front.
        let mut positions = Vec::new();
        for y in 0..5 {
            for x in 0..5 {
                positions.push([f64::from(x) * 10.0, f64::from(y) * 10.0, 0.0]);
            }
        }
        let mut triangles = Vec::new();
        for y in 0..4u32 {
            for x in 0..4u32 {
                let i = y * 5 + x;
                triangles.push([i, i + 1, i + 6]);
                triangles.push([i, i + 6, i + 5]);
            }
        }
        let fit = Mesh { colors: vec![[0.5; 3]; positions.len()], positions, triangles };
        let mean: Vec<Vec3> = fit.positions.iter().map(|p| p.map(|v| v as f32)).collect();
        let pose = Pose { translation: [-20.0, -20.0, -500.0], ..Pose::frontal(500.0) };
        let camera = Camera { focal: 500.0, principal: [64.0, 64.0], near: 1.0 };
        let project = |v: usize| camera.project(pose.transform_point(mean[v])).map(|s| [s.x, s.y]).unwrap();
        // Landmark 0 sits at vertex 0; its point lies at vertex 7's image position (about 22 mm
        // away): within 30 mm it is found, within 15 mm the nearest reachable vertex is taken.
        let point = project(7);
        assert_eq!(landmark_hits(&fit, &pose, &camera, &mean, &[0], &[point], 30.0), vec![Some(7)]);
        let near = landmark_hits(&fit, &pose, &camera, &mean, &[0], &[point], 15.0);
        assert!(near[0].is_some_and(|v| v != 7 && [1, 5, 6].contains(&v)), "{near:?}");
        // Seen from behind, nothing faces the camera: no hit.
        let behind = Pose { yaw: std::f32::consts::PI, ..pose };
        assert_eq!(landmark_hits(&fit, &behind, &camera, &mean, &[0], &[point], 30.0), vec![None]);
        // A NaN point or an unknown landmark: no hit.
        assert_eq!(landmark_hits(&fit, &pose, &camera, &mean, &[0, 99], &[[f32::NAN, 1.0], point], 30.0), vec![None, None]);
    }
}
