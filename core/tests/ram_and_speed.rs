//! Renderer RAM (state + tile buffers) and a rough host timing of the binning strategies.
#![allow(clippy::indexing_slicing, clippy::unwrap_used, clippy::expect_used)]

mod common;

use common::head_mesh;
use gpmm_core::render::{vertex_stage, Camera, Cull, Pose, ProjectedVertex, ShLight, Tile, TileRasterizer};
use std::mem::size_of;

#[test]
fn renderer_ram_is_small_and_independent_of_the_image() {
    let report = |name: &str, bytes: usize, tw: usize, th: usize, bin: usize| {
        // 28 bytes per tile pixel (colour 12, 1/w 4, triangle id 4, barycentrics 8) + 12 per bin
        // entry (triangle and box) + a header.
        let bound = 28 * tw * th + 12 * bin + 64;
        println!("renderer RAM {name}: {bytes} bytes ({:.1} KiB), bound {bound}", bytes as f64 / 1024.0);
        assert!(bytes <= bound, "{name}: {bytes} > {bound}");
    };
    report("TileRasterizer<16, 16, 512>", size_of::<TileRasterizer<16, 16, 512>>(), 16, 16, 512);
    report("TileRasterizer<16, 16, 1024>", size_of::<TileRasterizer<16, 16, 1024>>(), 16, 16, 1024);
    report("TileRasterizer<32, 32, 2048>", size_of::<TileRasterizer<32, 32, 2048>>(), 32, 32, 2048);
    report("TileRasterizer<8, 8, 0>", size_of::<TileRasterizer<8, 8, 0>>(), 8, 8, 0);
    report("Tile<16, 16>", size_of::<Tile<16, 16>>(), 16, 16, 0);
    println!("per-vertex output: {} bytes per vertex (ProjectedVertex)", size_of::<ProjectedVertex>());
    assert!(size_of::<TileRasterizer<16, 16, 1024>>() <= 20 * 1024, "a small renderer fits 20 KiB");
    assert_eq!(size_of::<ProjectedVertex>(), 24);
}

fn time_frame<const BIN: usize>(v: &[ProjectedVertex], tris: &[[u32; 3]], size: u32, reps: u32) -> (f64, u32) {
    let mut r = TileRasterizer::<16, 16, BIN>::new();
    let mut sum = 0.0f32;
    let mut sink = |t: &Tile<16, 16>| {
        for row in t.colors() {
            for c in row {
                sum += c[0];
            }
        }
    };
    let start = std::time::Instant::now();
    let mut overflow = 0;
    for _ in 0..reps {
        overflow = r.render(v, tris, size, size, Cull::Clockwise, &mut sink).unwrap().overflow_rows;
    }
    assert!(sum.is_finite());
    (start.elapsed().as_secs_f64() / reps as f64 * 1e3, overflow)
}

/// `cargo test --release -p gpmm-core --test ram_and_speed -- --ignored --nocapture`
#[test]
#[ignore = "timing; run in release with --nocapture"]
fn binning_strategies_timing() {
    for (stacks, slices) in [(40, 60), (70, 100)] {
        let (pos, albedo, tris) = head_mesh(stacks, slices, 0.12, None);
        for size in [128u32, 256] {
            let cam = Camera::centered(size, size, size as f32 * 2.6);
            let pose = Pose { yaw: 0.3, pitch: 0.1, roll: 0.0, translation: [0.0, 0.0, -600.0] };
            let mut normals = vec![[0.0; 3]; pos.len()];
            let mut v = vec![ProjectedVertex::INVALID; pos.len()];
            let start = std::time::Instant::now();
            for _ in 0..20 {
                vertex_stage(&pos, &albedo, &tris, &pose, &cam, &ShLight::frontal(), &mut normals, &mut v).unwrap();
            }
            let vs = start.elapsed().as_secs_f64() / 20.0 * 1e3;
            let (t0, o0) = time_frame::<0>(&v, &tris, size, 20);
            let (t1, o1) = time_frame::<512>(&v, &tris, size, 20);
            let (t2, o2) = time_frame::<4096>(&v, &tris, size, 20);
            println!(
                "{} tris, {size}x{size}: vertex stage {vs:.3} ms; raster BIN=0 (scan all per tile) {t0:.3} ms ({o0} overflow rows), BIN=512 {t1:.3} ms ({o1}), BIN=4096 {t2:.3} ms ({o2})",
                tris.len()
            );
        }
    }
}
