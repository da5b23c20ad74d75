//! The shape's Laplace spread from the landmarks: its coefficients' standard deviations against a
//! dense posterior computed independently, and the vertices' spread along their normals.

use faer::linalg::solvers::DenseSolveCore;
use gpmm_core::render::{Pose, ShLight};
use gpmm_host::fit::{morphable, project_landmarks_of, Params, ShapeSpread, SHAPE_SPREAD_FACTOR};
use gpmm_host::gp::kernel::ModelKernel;
use gpmm_host::gp::lowrank::{NystromOptions, RankSpec};
use gpmm_host::gp::model::{build_model, BuildOptions, GpModel};
use gpmm_host::mesh::template::{Mesh, Provenance, Template};

/// An ellipsoid of 12 × 24 vertices (mm, facing +z) with 16 landmarks on its front half.
fn ellipsoid_model() -> GpModel {
    let (rings, segments) = (12usize, 24usize);
    let mut positions = Vec::new();
    for i in 0..rings {
        let theta = std::f64::consts::PI * (i as f64 + 0.5) / rings as f64;
        for j in 0..segments {
            let phi = std::f64::consts::TAU * j as f64 / segments as f64;
            positions.push([70.0 * theta.sin() * phi.sin(), 90.0 * theta.cos(), 60.0 * theta.sin() * phi.cos()]);
        }
    }
    let mut triangles = Vec::new();
    for i in 0..rings - 1 {
        for j in 0..segments {
            let (a, b) = ((i * segments + j) as u32, (i * segments + (j + 1) % segments) as u32);
            let (c, d) = (a + segments as u32, b + segments as u32);
            triangles.extend([[a, c, b], [b, c, d]]);
        }
    }
    let colors = positions.iter().map(|_| [0.6, 0.45, 0.4]).collect();
    // The front half: rings 2..10, segments around phi = 0 (z > 0).
    let landmarks = (0..16u32).map(|k| (2 + k / 2) * segments as u32 + [22, 2][k as usize % 2] + (k % 4) / 2).collect();
    let template = Template {
        mesh: Mesh { positions, colors, triangles },
        landmarks,
        scheme: "points".into(),
        provenance: Provenance { source: "ellipsoid".into(), scale_mm_per_unit: 1.0, ..Default::default() },
    };
    let opts = BuildOptions {
        kernel: ModelKernel::SymmetricFull,
        hyperparameters: Default::default(),
        rank_shape: RankSpec::Count(8),
        rank_color: RankSpec::Count(2),
        nystrom: NystromOptions { points: 150, ..Default::default() },
    };
    build_model(&template, &opts, |_, _, _| {})
}

fn params(model: &GpModel) -> Params {
    let mut p =
        Params::new(Pose { yaw: 0.3, ..Pose::frontal(500.0) }, 300.0, ShLight::ambient_white(), model.shape.rank(), model.color.rank());
    p.shape_coeffs_mut()[0] = 0.5;
    p
}

/// `(I + JᵀJ / s²)⁻¹`'s diagonal with `J` from central differences of the projected landmarks.
fn dense_sd(model: &GpModel, p: &Params, size: u32, s: f64) -> Vec<f64> {
    let k = p.shape_len();
    let base = project_landmarks_of(model, p, size).unwrap();
    let m = 2 * base.len();
    let mut jac = faer::Mat::<f64>::zeros(m, k);
    for j in 0..k {
        let (mut a, mut b) = (p.clone(), p.clone());
        a.shape_coeffs_mut()[j] += 0.25;
        b.shape_coeffs_mut()[j] -= 0.25;
        let (pa, pb) = (project_landmarks_of(model, &a, size).unwrap(), project_landmarks_of(model, &b, size).unwrap());
        for i in 0..base.len() {
            for c in 0..2 {
                jac[(2 * i + c, j)] = f64::from(pa[i][c] - pb[i][c]) / 0.5;
            }
        }
    }
    let mut precision: faer::Mat<f64> = jac.transpose() * &jac / faer::Scale(s * s);
    for j in 0..k {
        precision[(j, j)] += 1.0;
    }
    let inverse = precision.llt(faer::Side::Lower).unwrap().inverse();
    (0..k).map(|j| inverse[(j, j)].sqrt()).collect()
}

#[test]
fn the_coefficients_spread_is_the_dense_posteriors() {
    let model = ellipsoid_model();
    let mm = morphable(&model).unwrap();
    let p = params(&model);
    let size = 128;
    let targets = project_landmarks_of(&model, &p, size).unwrap();
    for residual in [0.05f32, 0.5, 5.0] {
        let spread = ShapeSpread::of(&model, &mm, &p, &targets, size, size, residual).unwrap();
        let dense = dense_sd(&model, &p, size, f64::from(residual * SHAPE_SPREAD_FACTOR));
        assert_eq!(spread.coeff_sd.len(), model.shape.rank());
        for (j, (a, b)) in spread.coeff_sd.iter().zip(&dense).enumerate() {
            assert!((f64::from(*a) - b).abs() < 2e-3, "residual {residual}, coefficient {j}: {a} against {b}");
            assert!(*a > 0.0 && *a <= 1.0, "{a}");
        }
    }
}

#[test]
fn the_vertices_spread_narrows_where_the_landmarks_pin_it_and_widens_with_their_noise() {
    let model = ellipsoid_model();
    let mm = morphable(&model).unwrap();
    let p = params(&model);
    let targets = project_landmarks_of(&model, &p, 128).unwrap();
    let sd = |residual: f32| ShapeSpread::of(&model, &mm, &p, &targets, 128, 128, residual).unwrap().vertex_sd_mm(&model, &p).unwrap();
    let (sure, unsure, prior) = (sd(0.02), sd(2.0), sd(1e6));
    assert_eq!(sure.len(), model.vertices());
    for v in 0..model.vertices() {
        assert!(sure[v].is_finite() && sure[v] >= 0.0, "{v}: {}", sure[v]);
        // More noise never narrows a vertex, and nothing is wider than the prior.
        assert!(sure[v] <= unsure[v] + 1e-3 && unsure[v] <= prior[v] + 1e-3, "{v}: {} {} {}", sure[v], unsure[v], prior[v]);
    }
    // At the landmarks the spread falls well below the prior's; the prior spreads every vertex.
    let at_landmarks: f32 =
        model.landmarks.iter().map(|&v| sure[v as usize] / prior[v as usize]).sum::<f32>() / model.landmarks.len() as f32;
    assert!(at_landmarks < 0.6, "{at_landmarks}");
    assert!(prior.iter().all(|s| *s > 0.0));
    // A residual that is not a number is refused, not reported.
    assert!(ShapeSpread::of(&model, &mm, &p, &targets, 128, 128, f32::NAN).is_err());
}
