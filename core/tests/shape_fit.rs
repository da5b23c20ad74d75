//! The start's shape solve (Gauss–Newton on the image) on a synthetic model with known truth.
#![allow(clippy::indexing_slicing, clippy::unwrap_used, clippy::expect_used)]

mod common;
mod fit_support;

use fit_support::*;
use gpmm_core::error::FitError;
use gpmm_core::fit::{solve_shape, ShapeSolveConfig, DEFAULT_PIXEL_SIGMA};
use gpmm_core::geometry::Vec3;
use gpmm_core::model::{FitParams, Instance, InstanceBuffers, SpareBuffers};

/// Per-vertex buffers with a spare instance (the chains' room; the solve needs none).
struct Room {
    main: Buffers,
    spare: [Vec<Vec3>; 3],
}

impl Room {
    fn new(n: usize) -> Self {
        Self { main: Buffers::new(n), spare: [vec![[0.0; 3]; n], vec![[0.0; 3]; n], vec![[0.0; 3]; n]] }
    }

    fn instance(&mut self, spare: bool) -> Instance<'_, KS, KC> {
        let n = self.main.positions.len();
        let m = &mut self.main;
        let bufs =
            InstanceBuffers { positions: &mut m.positions, albedos: &mut m.albedos, normals: &mut m.normals, projected: &mut m.projected };
        let inst = Instance::new(bufs, n).unwrap();
        if spare {
            let [p, nn, a] = &mut self.spare;
            inst.with_spare(SpareBuffers { positions: p, normals: nn, albedos: a }).unwrap()
        } else {
            inst
        }
    }
}

fn config() -> ShapeSolveConfig {
    ShapeSolveConfig { stride: 1, min_cos: 0.2, pixel_sigma: DEFAULT_PIXEL_SIGMA, weight: 1.0, components: KS, iterations: 6, pose: false }
}

fn distance(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f32>().sqrt()
}

/// The truth with its shape coefficients zeroed: where the solve starts.
fn start() -> FitParams<KS, KC> {
    let mut p = truth();
    p.shape_coeffs_mut().fill(0.0);
    p
}

#[test]
fn shape_solve_moves_the_shape_toward_the_rendered_one() {
    let r = Scene::new();
    let (synth, truth, image) = (&r.synth, &r.truth, r.image());
    let model = synth.model();
    let mut room = Room::new(synth.vertices());
    let mut inst = room.instance(true);
    let mut p = start();
    let before = distance(p.shape_coeffs(), truth.shape_coeffs());
    let report = solve_shape(&model, &mut inst, &mut p, &image, None, &config()).unwrap();
    let after = distance(p.shape_coeffs(), truth.shape_coeffs());
    eprintln!("{report:?}: distance to the truth {before:.3} -> {after:.3}; solved {:?}", p.shape_coeffs());
    assert!(report.samples > 100, "{report:?}");
    assert!(report.steps >= 1, "{report:?}");
    assert!(report.objective_after < 0.5 * report.objective_before, "{report:?}");
    // From the image alone (shading and where each vertex looks) the coefficients come most of
    // the way to the rendered ones.
    assert!(after < 0.4 * before, "{before} -> {after}");
    // Nothing else moved, and the instance holds the result.
    assert_eq!(p.pose, truth.pose);
    assert_eq!(p.color_coeffs(), truth.color_coeffs());
    let mut expected = vec![[0.0f32; 3]; synth.vertices()];
    model.shape_instance(p.shape_coeffs(), &mut expected).unwrap();
    assert_eq!(inst.positions(), &expected[..]);
}

#[test]
fn shape_solve_with_landmarks_agrees_with_both() {
    let r = Scene::new();
    let (synth, truth, image, lm) = (&r.synth, &r.truth, r.image(), r.landmarks());
    let model = synth.model();
    let mut room = Room::new(synth.vertices());
    let mut inst = room.instance(true);
    let mut p = start();
    let before = distance(p.shape_coeffs(), truth.shape_coeffs());
    let report = solve_shape(&model, &mut inst, &mut p, &image, Some(&lm), &config()).unwrap();
    let after = distance(p.shape_coeffs(), truth.shape_coeffs());
    eprintln!("{report:?}: {before:.3} -> {after:.3}");
    assert!(after < 0.4 * before, "{before} -> {after}");
    // Landmarks pulled elsewhere (shifted 3 px) move the solution away from the image's.
    let shifted: Vec<[f32; 2]> = r.points.iter().map(|q| [q[0] + 3.0, q[1]]).collect();
    let lm_shifted = target(&shifted, &r.valid);
    let mut q = start();
    solve_shape(&model, &mut inst, &mut q, &image, Some(&lm_shifted), &config()).unwrap();
    assert!(distance(q.shape_coeffs(), p.shape_coeffs()) > 0.05, "{:?} vs {:?}", q.shape_coeffs(), p.shape_coeffs());
}

#[test]
fn shape_solve_needs_no_room_beyond_the_instance() {
    let r = Scene::new();
    let (synth, image, lm) = (&r.synth, r.image(), r.landmarks());
    let model = synth.model();
    let mut room = Room::new(synth.vertices());
    let mut solved = |spare: bool| {
        let mut p = start();
        let report = solve_shape(&model, &mut room.instance(spare), &mut p, &image, Some(&lm), &config()).unwrap();
        (p, report)
    };
    let (with, without) = (solved(true), solved(false));
    assert!(with.1.steps >= 1, "{:?}", with.1);
    assert_eq!(with, without, "the spare buffers change nothing");
}

#[test]
fn shape_solve_refuses_bad_settings() {
    let r = Scene::new();
    let (synth, image) = (&r.synth, r.image());
    let model = synth.model();
    let mut room = Room::new(synth.vertices());
    let mut p = start();
    let mut inst = room.instance(false);
    for bad in [
        ShapeSolveConfig { stride: 0, ..config() },
        ShapeSolveConfig { pixel_sigma: f32::NAN, ..config() },
        ShapeSolveConfig { weight: 0.0, ..config() },
        ShapeSolveConfig { min_cos: f32::INFINITY, ..config() },
    ] {
        assert_eq!(solve_shape(&model, &mut inst, &mut p, &image, None, &bad), Err(FitError::BadConfig), "{bad:?}");
    }
    assert_eq!(p.shape_coeffs(), start().shape_coeffs());
    // An image with nothing of the face in view: too few samples, nothing moves.
    let mut away = start();
    away.pose.translation = [5000.0, 0.0, -600.0];
    assert_eq!(solve_shape(&model, &mut inst, &mut away, &image, None, &config()), Err(FitError::Singular));
    assert_eq!(away.shape_coeffs(), start().shape_coeffs());
    // A NaN coefficient is refused by the model, not solved around.
    let mut nan = start();
    nan.shape_coeffs_mut()[0] = f32::NAN;
    assert!(solve_shape(&model, &mut inst, &mut nan, &image, None, &config()).is_err());
}

#[test]
fn shape_solve_with_the_pose_recovers_a_turned_start() {
    let r = Scene::new();
    let (synth, truth, image, lm) = (&r.synth, &r.truth, r.image(), r.landmarks());
    let model = synth.model();
    let mut room = Room::new(synth.vertices());
    let mut inst = room.instance(true);
    let turned = || {
        let mut p = start();
        p.pose.yaw += 3f32.to_radians();
        p.pose.translation[0] += 4.0;
        p
    };
    let yaw_error = |p: &FitParams<KS, KC>| (p.pose.yaw - truth.pose.yaw).to_degrees().abs();
    // The pose held: it stays where it was.
    let mut held = turned();
    solve_shape(&model, &mut inst, &mut held, &image, Some(&lm), &config()).unwrap();
    assert_eq!(held.pose, turned().pose);
    // The pose moving with the shape: the yaw comes back to within a degree of the truth.
    let mut moved = turned();
    let report = solve_shape(&model, &mut inst, &mut moved, &image, Some(&lm), &ShapeSolveConfig { pose: true, ..config() }).unwrap();
    eprintln!("{report:?}: yaw error 3.0 -> {:.2} deg, translation {:?}", yaw_error(&moved), moved.pose.translation);
    assert!(yaw_error(&moved) < 1.0, "{}", yaw_error(&moved));
    assert!((moved.pose.translation[0] - truth.pose.translation[0]).abs() < 2.0, "{:?}", moved.pose.translation);
}
