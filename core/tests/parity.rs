//! Parity with an independent full-frame reference rasterizer (see `common::reference_render`).
#![allow(clippy::indexing_slicing, clippy::unwrap_used, clippy::expect_used)]

mod common;

use common::{head_mesh, reference_render, FrameSink};
use gpmm_core::render::{vertex_stage, Camera, Cull, Pose, ProjectedVertex, ShLight, TileRasterizer, NO_TRIANGLE};

fn compare<const TW: usize, const TH: usize, const BIN: usize>(pose: Pose, light: ShLight, width: u32, height: u32) {
    let (pos, albedo, tris) = head_mesh(40, 60, 0.12, None);
    let cam = Camera::centered(width, height, width as f32 * 2.6);
    let mut normals = vec![[0.0; 3]; pos.len()];
    let mut v = vec![ProjectedVertex::INVALID; pos.len()];
    vertex_stage(&pos, &albedo, &tris, &pose, &cam, &light, &mut normals, &mut v).unwrap();
    let mut sink = FrameSink::new(width, height);
    let stats = TileRasterizer::<TW, TH, BIN>::new().render(&v, &tris, width, height, Cull::Clockwise, &mut sink).unwrap();
    let reference = reference_render(&v, &tris, width as usize, height as usize);
    let (mut union, mut both, mut same_tri, mut colour_ok) = (0usize, 0usize, 0usize, 0usize);
    let mut max_same_tri_err = 0.0f32;
    for i in 0..(width * height) as usize {
        let (a, b) = (sink.tri[i], reference.tri[i]);
        if a == NO_TRIANGLE && b == NO_TRIANGLE {
            continue;
        }
        union += 1;
        if a == NO_TRIANGLE || b == NO_TRIANGLE {
            continue;
        }
        both += 1;
        let err = (0..3).map(|c| (sink.color[i][c] - reference.color[i][c]).abs()).fold(0.0, f32::max);
        if err <= 2.0 / 255.0 {
            colour_ok += 1;
        }
        if a == b {
            same_tri += 1;
            max_same_tri_err = max_same_tri_err.max(err);
        }
    }
    let coverage = both as f64 / union as f64;
    let colour = colour_ok as f64 / both as f64;
    println!(
        "{width}x{height} tiles {TW}x{TH} bin {BIN} pose {pose:?}: {union} px covered, coverage agreement {:.4}, colour within 2/255 {:.4}, same triangle {same_tri}, max colour error (same triangle) {max_same_tri_err:.2e}, {stats:?}",
        coverage, colour
    );
    assert!(union > (width * height / 6) as usize, "the head covers a good part of the image");
    assert!(coverage >= 0.99, "coverage agreement {coverage}");
    assert!(colour >= 0.99, "colour agreement {colour}");
    assert!(max_same_tri_err <= 2.0 / 255.0, "max colour error on the same triangle {max_same_tri_err}");
}

fn poses() -> Vec<Pose> {
    vec![
        Pose::frontal(600.0),
        Pose { yaw: 0.6, pitch: 0.1, roll: 0.0, translation: [10.0, 5.0, -600.0] },
        Pose { yaw: -1.1, pitch: -0.3, roll: 0.25, translation: [-20.0, 0.0, -700.0] },
        Pose { yaw: 0.2, pitch: 0.5, roll: -0.6, translation: [60.0, -40.0, -500.0] },
        Pose { yaw: 2.5, pitch: 0.0, roll: 0.0, translation: [0.0, 0.0, -650.0] },
    ]
}

#[test]
fn matches_reference_128_frontal_light() {
    for pose in poses() {
        compare::<16, 16, 512>(pose, ShLight::frontal(), 128, 128);
    }
}

#[test]
fn matches_reference_odd_sizes_and_lights() {
    let side = ShLight::from_ambient_diffuse([0.4, 0.45, 0.5], [0.7, 0.6, 0.5], [0.6, 0.3, 0.5]);
    for pose in poses() {
        compare::<8, 8, 128>(pose, side, 97, 75);
        compare::<32, 16, 2048>(pose, ShLight::ambient_white(), 256, 200);
    }
}
