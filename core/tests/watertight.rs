//! Watertightness: shared edges leave no gap and no double hit.
#![allow(clippy::indexing_slicing, clippy::unwrap_used, clippy::expect_used)]

mod common;

use common::{head_mesh, screen_grid, FrameSink, Rng};
use gpmm_core::render::{vertex_stage, Camera, Cull, Pose, ProjectedVertex, ShLight, TileRasterizer, NO_TRIANGLE};

/// Renders each triangle alone and counts, per pixel, how many triangles cover it.
fn hits_per_pixel<const TW: usize, const TH: usize>(
    v: &[ProjectedVertex],
    tris: &[[u32; 3]],
    width: u32,
    height: u32,
    cull: Cull,
) -> Vec<u32> {
    let mut r = TileRasterizer::<TW, TH, 64>::new();
    let mut hits = vec![0u32; (width * height) as usize];
    for t in tris {
        let mut sink = FrameSink::new(width, height);
        r.render(v, std::slice::from_ref(t), width, height, cull, &mut sink).unwrap();
        assert!(sink.writes.iter().all(|&w| w == 1), "every pixel is in exactly one tile");
        for (h, &id) in hits.iter_mut().zip(&sink.tri) {
            if id != NO_TRIANGLE {
                *h += 1;
            }
        }
    }
    hits
}

fn check_grid<const TW: usize, const TH: usize>(seed: u64, width: u32, height: u32, snap: f32) {
    let mut rng = Rng::new(seed);
    // A screen-covering quad (overhanging every border) split into jittered triangles.
    let rect = [-3.3, -2.1, width as f32 + 2.7, height as f32 + 1.9];
    let (v, tris) = screen_grid(&mut rng, 7, 5, rect, 0.2, snap);
    let hits = hits_per_pixel::<TW, TH>(&v, &tris, width, height, Cull::Clockwise);
    let bad: Vec<_> = hits.iter().enumerate().filter(|(_, &h)| h != 1).map(|(i, h)| (i % width as usize, i / width as usize, *h)).collect();
    assert!(bad.is_empty(), "TW={TW} TH={TH} {width}x{height} seed {seed}: pixels not hit exactly once: {:?}", &bad[..bad.len().min(10)]);
    // The whole mesh at once covers everything, with the same owner as the single-triangle renders.
    let mut sink = FrameSink::new(width, height);
    let mut r = TileRasterizer::<TW, TH, 16>::new();
    let stats = r.render(&v, &tris, width, height, Cull::Clockwise, &mut sink).unwrap();
    assert_eq!(sink.covered(), (width * height) as usize);
    assert_eq!(stats.covered_pixels, width * height);
    assert_eq!(stats.culled, 0, "{stats:?}");
}

#[test]
fn jittered_grid_hits_every_pixel_exactly_once() {
    for seed in 1..=4 {
        for snap in [0.0, 0.5] {
            check_grid::<16, 16>(seed, 64, 48, snap);
            check_grid::<8, 8>(seed, 37, 29, snap);
            check_grid::<7, 5>(seed, 33, 17, snap);
            check_grid::<32, 4>(seed, 50, 23, snap);
            check_grid::<1, 1>(seed, 13, 11, snap);
        }
    }
}

#[test]
fn clockwise_grid_is_culled_and_drawn_without_culling() {
    let mut rng = Rng::new(9);
    let (v, mut tris) = screen_grid(&mut rng, 4, 4, [0.0, 0.0, 40.0, 30.0], 0.3, 0.5);
    for t in tris.iter_mut() {
        t.swap(1, 2);
    }
    let hits = hits_per_pixel::<16, 16>(&v, &tris, 40, 30, Cull::Clockwise);
    assert!(hits.iter().all(|&h| h == 0));
    let hits = hits_per_pixel::<16, 16>(&v, &tris, 40, 30, Cull::None);
    assert!(hits.iter().all(|&h| h == 1));
    let hits = hits_per_pixel::<16, 16>(&v, &tris, 40, 30, Cull::CounterClockwise);
    assert!(hits.iter().all(|&h| h == 1));
}

fn project(pos: &[[f32; 3]], albedo: &[[f32; 3]], tris: &[[u32; 3]], pose: &Pose, cam: &Camera) -> Vec<ProjectedVertex> {
    let mut normals = vec![[0.0; 3]; pos.len()];
    let mut out = vec![ProjectedVertex::INVALID; pos.len()];
    vertex_stage(pos, albedo, tris, pose, cam, &ShLight::frontal(), &mut normals, &mut out).unwrap();
    out
}

/// For a closed mesh every pixel-centre ray enters as often as it leaves: the number of front
/// faces covering a pixel equals the number of back faces (exactly, with a watertight rule).
#[test]
fn closed_mesh_front_hits_equal_back_hits() {
    let (w, h) = (61u32, 53u32);
    let cam = Camera::centered(w, h, 140.0);
    for seed in 0..3u64 {
        let mut rng = Rng::new(seed + 100);
        let (pos, albedo, tris) = head_mesh(12, 17, 0.15, Some(&mut rng));
        let pose =
            Pose { yaw: rng.range(-0.8, 0.8), pitch: rng.range(-0.5, 0.5), roll: rng.range(-0.4, 0.4), translation: [3.0, -2.0, -450.0] };
        let v = project(&pos, &albedo, &tris, &pose, &cam);
        let front = hits_per_pixel::<16, 16>(&v, &tris, w, h, Cull::Clockwise);
        let back = hits_per_pixel::<16, 16>(&v, &tris, w, h, Cull::CounterClockwise);
        let covered = front.iter().filter(|&&f| f > 0).count();
        assert!(covered > (w * h / 4) as usize, "the mesh covers a good part of the image ({covered})");
        for (i, (f, b)) in front.iter().zip(&back).enumerate() {
            assert_eq!(f, b, "seed {seed}: pixel ({}, {}) front {f} back {b}", i % w as usize, i / w as usize);
        }
    }
}

/// A convex closed mesh: its front faces tile the silhouette, every pixel is hit at most once,
/// and the front-face coverage equals the back-face coverage exactly.
#[test]
fn convex_mesh_front_faces_hit_each_pixel_at_most_once() {
    let (w, h) = (70u32, 45u32);
    let cam = Camera::centered(w, h, 120.0);
    let (pos, albedo, tris) = head_mesh(14, 19, 0.0, None);
    for yaw in [-0.6f32, 0.0, 0.45] {
        let pose = Pose { yaw, pitch: 0.2, roll: 0.1, translation: [0.0, 0.0, -400.0] };
        let v = project(&pos, &albedo, &tris, &pose, &cam);
        let front = hits_per_pixel::<8, 16>(&v, &tris, w, h, Cull::Clockwise);
        let back = hits_per_pixel::<8, 16>(&v, &tris, w, h, Cull::CounterClockwise);
        assert!(front.iter().all(|&f| f <= 1));
        assert_eq!(front, back);
        let mut sink = FrameSink::new(w, h);
        TileRasterizer::<8, 16, 256>::new().render(&v, &tris, w, h, Cull::Clockwise, &mut sink).unwrap();
        let covered: Vec<u32> = sink.tri.iter().map(|&t| u32::from(t != NO_TRIANGLE)).collect();
        assert_eq!(covered, front);
    }
}
