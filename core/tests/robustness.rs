//! Overflow, near plane, borders, degenerate and non-finite inputs: no panic, a sensible result or an error.
#![allow(clippy::indexing_slicing, clippy::unwrap_used, clippy::expect_used)]

mod common;

use common::{head_mesh, reference_render, screen_grid, sv, FrameSink, Rng};
use gpmm_core::render::{
    project_vertices, shade_vertices, vertex_normals, vertex_stage, Camera, Cull, Pose, ProjectedVertex, RasterError, ShLight,
    TileRasterizer, VertexError, NO_TRIANGLE,
};

fn stage(pos: &[[f32; 3]], albedo: &[[f32; 3]], tris: &[[u32; 3]], pose: &Pose, cam: &Camera) -> Vec<ProjectedVertex> {
    let mut normals = vec![[0.0; 3]; pos.len()];
    let mut out = vec![ProjectedVertex::INVALID; pos.len()];
    vertex_stage(pos, albedo, tris, pose, cam, &ShLight::frontal(), &mut normals, &mut out).unwrap();
    out
}

fn render<const BIN: usize>(v: &[ProjectedVertex], tris: &[[u32; 3]], w: u32, h: u32) -> (FrameSink, gpmm_core::render::FrameStats) {
    let mut sink = FrameSink::new(w, h);
    let stats = TileRasterizer::<16, 16, BIN>::new().render(v, tris, w, h, Cull::Clockwise, &mut sink).unwrap();
    assert!(sink.writes.iter().all(|&n| n == 1));
    (sink, stats)
}

#[test]
fn bin_overflow_gives_identical_frames() {
    let (pos, albedo, tris) = head_mesh(40, 60, 0.12, None);
    let cam = Camera::centered(128, 128, 330.0);
    let pose = Pose { yaw: 0.4, pitch: -0.2, roll: 0.1, translation: [0.0, 0.0, -600.0] };
    let v = stage(&pos, &albedo, &tris, &pose, &cam);
    let (big, s_big) = render::<8192>(&v, &tris, 128, 128);
    let (small, s_small) = render::<7>(&v, &tris, 128, 128);
    let (none, s_none) = render::<0>(&v, &tris, 128, 128);
    println!("no overflow {s_big:?}\nBIN=7 {s_small:?}\nBIN=0 {s_none:?}");
    assert_eq!(s_big.overflow_rows, 0);
    assert!(s_small.overflow_rows > 0 && s_none.overflow_rows > 0);
    assert!(big.covered() > 5000);
    for other in [&small, &none] {
        assert_eq!(big.tri, other.tri);
        assert_eq!(big.color, other.color);
        assert_eq!(big.inv_w, other.inv_w);
    }
    assert_eq!(s_big.covered_pixels, s_small.covered_pixels);
}

#[test]
fn many_tiny_triangles_in_one_tile() {
    // 400 triangles inside one 16x16 tile with a bin of 8: drawn completely (multi-pass fallback).
    let mut rng = Rng::new(5);
    let (v, tris) = screen_grid(&mut rng, 20, 10, [1.0, 2.0, 15.0, 14.0], 0.2, 0.0);
    let (sink, stats) = render::<8>(&v, &tris, 16, 16);
    let reference = reference_render(&v, &tris, 16, 16);
    assert_eq!(stats.drawn + stats.off_screen, 400);
    assert!(stats.overflow_rows == 1);
    let covered_ref = reference.tri.iter().filter(|&&t| t != NO_TRIANGLE).count();
    assert_eq!(sink.covered(), covered_ref);
    assert_eq!(sink.covered(), 14 * 12);
}

/// A 600 mm square in the model's xy plane (counter-clockwise seen from +z), `n × n` quads.
fn plane(n: usize) -> common::Mesh {
    let mut pos = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            pos.push([-300.0 + 600.0 * i as f32 / n as f32, -300.0 + 600.0 * j as f32 / n as f32, 0.0]);
        }
    }
    let id = |i: usize, j: usize| (j * (n + 1) + i) as u32;
    let mut tris = Vec::new();
    for j in 0..n {
        for i in 0..n {
            tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    let albedo = vec![[0.6, 0.5, 0.4]; pos.len()];
    (pos, albedo, tris)
}

#[test]
fn near_plane_crossing_triangles_are_rejected_not_panicking() {
    // A floor-like plane tilted away from the camera: its near part passes through the near
    // plane (10 mm) and behind the camera; those triangles are rejected whole, the rest is drawn.
    let (pos, albedo, tris) = plane(24);
    let cam = Camera::centered(64, 64, 60.0);
    let pose = Pose { yaw: 0.2, pitch: -1.2, roll: 0.0, translation: [0.0, 0.0, -100.0] };
    let v = stage(&pos, &albedo, &tris, &pose, &cam);
    assert!(v.iter().any(|p| p.inv_w == 0.0) && v.iter().any(|p| p.inv_w > 0.0));
    let (sink, stats) = render::<256>(&v, &tris, 64, 64);
    println!("{stats:?}");
    assert!(stats.near_or_invalid > 0);
    assert!(stats.drawn > 0 && sink.covered() > 500);
    assert_eq!(
        stats.drawn + stats.culled + stats.degenerate + stats.near_or_invalid + stats.guard_band + stats.off_screen,
        stats.triangles
    );
    // Every visible fragment belongs to a triangle whose vertices are all in front of the near plane.
    for &t in sink.tri.iter().filter(|&&t| t != NO_TRIANGLE) {
        assert!(tris[t as usize].iter().all(|&i| v[i as usize].inv_w > 0.0));
    }
    // Same frame from the reference (which also skips such triangles).
    let reference = reference_render(&v, &tris, 64, 64);
    let agree = sink.tri.iter().zip(&reference.tri).filter(|(a, b)| (**a == NO_TRIANGLE) == (**b == NO_TRIANGLE)).count();
    assert!(agree as f64 >= 0.99 * 64.0 * 64.0);
}

#[test]
fn border_crossing_triangle_is_clipped_to_the_image() {
    // One huge triangle covering the whole 40x30 image from far outside.
    let v = [sv(-500.0, -400.0, 0.01, [1.0, 0.0, 0.0]), sv(-500.0, 900.0, 0.01, [0.0, 1.0, 0.0]), sv(900.0, -400.0, 0.01, [0.0, 0.0, 1.0])];
    let (sink, stats) = render::<4>(&v, &[[0, 1, 2]], 40, 30);
    assert_eq!(sink.covered(), 1200);
    assert_eq!(stats.drawn, 1);
    let reference = reference_render(&v, &[[0, 1, 2]], 40, 30);
    for (a, b) in sink.color.iter().zip(&reference.color) {
        assert!((0..3).all(|c| (a[c] - b[c]).abs() < 1e-4));
    }
    // Entirely off screen: nothing drawn, counted.
    let off = [sv(-50.0, -5.0, 0.01, [1.0; 3]), sv(-50.0, 5.0, 0.01, [1.0; 3]), sv(-40.0, -5.0, 0.01, [1.0; 3])];
    let (sink, stats) = render::<4>(&off, &[[0, 1, 2]], 40, 30);
    assert_eq!((sink.covered(), stats.off_screen), (0, 1));
}

#[test]
fn degenerate_nan_and_huge_inputs_do_not_panic() {
    let c = [0.5; 3];
    let v = vec![
        sv(10.0, 10.0, 0.01, c),
        sv(20.0, 20.0, 0.01, c),
        sv(30.0, 30.0, 0.01, c),             // collinear with 0, 1
        sv(f32::NAN, 5.0, 0.01, c),          // 3: NaN position
        sv(5.0, 25.0, f32::INFINITY, c),     // 4: infinite depth
        sv(1e30, 1e30, 0.01, c),             // 5: outside the guard band
        sv(5.0, 5.0, -0.01, c),              // 6: behind the camera
        sv(25.0, 5.0, 0.01, [f32::NAN; 3]),  // 7: NaN colour
        sv(3.0, 28.0, 0.01, c),              // 8
        sv(f32::MAX, -f32::MAX, 0.01, c),    // 9
        sv(5.0, 25.0, f32::MIN_POSITIVE, c), // 10: tiny depth
    ];
    let tris: Vec<[u32; 3]> = vec![
        [0, 1, 2],  // collinear
        [0, 0, 0],  // single point
        [0, 3, 8],  // NaN
        [0, 4, 8],  // inf
        [0, 5, 8],  // huge
        [0, 6, 8],  // behind
        [0, 8, 7],  // NaN colour
        [0, 9, 8],  // f32::MAX
        [0, 10, 8], // tiny depth: valid
    ];
    for cull in [Cull::None, Cull::Clockwise, Cull::CounterClockwise] {
        let mut sink = FrameSink::new(32, 32);
        let stats = TileRasterizer::<8, 8, 4>::new().render(&v, &tris, 32, 32, cull, &mut sink).unwrap();
        assert_eq!(stats.degenerate, 2);
        assert_eq!(stats.near_or_invalid, 4);
        assert_eq!(stats.guard_band, 2);
        assert!(sink.color.iter().all(|p| p.iter().all(|c| c.is_finite())));
        assert!(sink.tri.iter().all(|&t| t == NO_TRIANGLE || t == 8));
    }
}

#[test]
fn frame_errors_are_reported_before_any_tile() {
    let v = [sv(0.0, 0.0, 0.01, [0.0; 3]), sv(10.0, 0.0, 0.01, [0.0; 3]), sv(0.0, 10.0, 0.01, [0.0; 3])];
    let mut r = TileRasterizer::<8, 8, 4>::new();
    let tiles = std::cell::Cell::new(0);
    let mut count = |_: &gpmm_core::render::Tile<8, 8>| tiles.set(tiles.get() + 1);
    assert_eq!(r.render(&v, &[[0u32, 1, 3]], 16, 16, Cull::None, &mut count), Err(RasterError::IndexOutOfRange));
    assert_eq!(r.render(&v, &[[0u32, 1, 2]], 40000, 16, Cull::None, &mut count), Err(RasterError::ImageTooLarge));
    assert_eq!(tiles.get(), 0);
    // An empty image gives no tile; u16 indices work too.
    let stats = r.render(&v, &[[0u16, 2, 1]], 0, 0, Cull::None, &mut count).unwrap();
    assert_eq!(stats.tiles, 0);
    let stats = r.render(&v, &[[0u16, 2, 1]], 1, 1, Cull::None, &mut count).unwrap();
    assert_eq!((stats.tiles, stats.covered_pixels), (1, 1));
    assert_eq!(tiles.get(), 1);
    let mut z = TileRasterizer::<0, 8, 4>::new();
    assert_eq!(
        z.render(&v, &[[0u32, 1, 2]], 4, 4, Cull::None, &mut |_: &gpmm_core::render::Tile<0, 8>| {}),
        Err(RasterError::ZeroTileSize)
    );
}

#[test]
fn vertex_stage_errors() {
    let pos = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let alb = [[0.5; 3]; 3];
    let cam = Camera::centered(8, 8, 10.0);
    let pose = Pose::frontal(100.0);
    let light = ShLight::frontal();
    let mut n = [[0.0; 3]; 3];
    let mut out = [ProjectedVertex::INVALID; 3];
    assert_eq!(vertex_normals(&pos, &[[0u16, 1, 3]], &mut n), Err(VertexError::IndexOutOfRange));
    assert_eq!(vertex_normals(&pos, &[[0u16, 1, 2]], &mut n[..2]), Err(VertexError::LengthMismatch));
    assert_eq!(vertex_stage(&pos, &alb[..2], &[[0u32, 1, 2]], &pose, &cam, &light, &mut n, &mut out), Err(VertexError::LengthMismatch));
    let bad = [[0.0, f32::NAN, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    assert_eq!(vertex_normals(&bad, &[[0u32, 1, 2]], &mut n), Err(VertexError::NonFinite));
    assert_eq!(project_vertices(&bad, &pose, &cam, &mut out), Err(VertexError::NonFinite));
    let bad_pose = Pose { yaw: f32::NAN, ..pose };
    assert_eq!(project_vertices(&pos, &bad_pose, &cam, &mut out), Err(VertexError::NonFinite));
    assert_eq!(shade_vertices(&[[f32::INFINITY; 3]; 3], &n, &pose, &light, &mut out), Err(VertexError::NonFinite));
    // Valid: normals of a CCW triangle in the xy plane point to +z; the frontal light gives 0.8 + 0.2.
    vertex_stage(&pos, &alb, &[[0u32, 1, 2]], &pose, &cam, &light, &mut n, &mut out).unwrap();
    for (nv, o) in n.iter().zip(&out) {
        assert!((nv[2] - 1.0).abs() < 1e-6);
        assert!(o.color.iter().all(|c| (c - 0.5).abs() < 1e-5), "{:?}", o.color);
        assert!((o.inv_w - 0.01).abs() < 1e-8);
    }
    // A vertex in no triangle gets a zero normal and the ambient (band-0) light only.
    let mut n4 = [[9.0; 3]; 4];
    let pos4 = [pos[0], pos[1], pos[2], [5.0, 5.0, 5.0]];
    vertex_normals(&pos4, &[[0u32, 1, 2]], &mut n4).unwrap();
    assert_eq!(n4[3], [0.0; 3]);
}
