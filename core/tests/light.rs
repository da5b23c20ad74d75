//! Spherical-harmonics irradiance against hand-computed formulas.
#![allow(clippy::indexing_slicing, clippy::unwrap_used, clippy::expect_used)]

use gpmm_core::render::light::{lambert_basis, sh_basis, LAMBERT_KERNEL, SH_COEFFS};
use gpmm_core::render::{shade_vertices, Pose, ProjectedVertex, ShLight};
use std::f64::consts::PI;

fn normals() -> Vec<[f32; 3]> {
    let mut v = vec![[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]];
    for k in 0..40 {
        let t = k as f32 * 0.37;
        let n = [t.sin() * (1.3 * t).cos(), (0.7 * t).cos(), t.cos() * (2.1 * t).sin()];
        let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        v.push([n[0] / l, n[1] / l, n[2] / l]);
    }
    v
}

fn single(i: usize) -> ShLight {
    let mut l = ShLight::zero();
    l.coeffs[i] = [1.0, 2.0, 3.0];
    l
}

#[test]
fn ambient_preset_is_constant() {
    let amb = ShLight::ambient_white();
    let tinted = ShLight::ambient([0.2, 0.5, 0.9]);
    for n in normals() {
        let e = amb.irradiance(n);
        assert!(e.iter().all(|c| (c - 1.0).abs() < 1e-6), "{e:?}");
        let e = tinted.irradiance(n);
        assert!((e[0] - 0.2).abs() < 1e-6 && (e[1] - 0.5).abs() < 1e-6 && (e[2] - 0.9).abs() < 1e-6);
    }
    // Zero or non-finite normals fall back to band 0 (no panic, finite).
    assert!(ShLight::frontal().irradiance([0.0; 3]).iter().all(|c| (c - 0.8).abs() < 1e-6));
    assert!(ShLight::frontal().irradiance([f32::NAN, 0.0, 1.0]).iter().all(|c| c.is_finite()));
}

#[test]
fn frontal_preset_is_ambient_plus_cosine_term() {
    // scalismo-faces: ambient 0.8 + diffuse 0.2 along +z => E(n) = 0.8 + 0.2 n_z.
    let l = ShLight::frontal();
    for n in normals() {
        let e = l.irradiance(n);
        let want = 0.8 + 0.2 * n[2];
        assert!(e.iter().all(|c| (c - want).abs() < 1e-5), "{n:?}: {e:?} vs {want}");
    }
    // Non-unit normals are normalized.
    assert_eq!(l.irradiance([0.0, 0.0, 5.0]), l.irradiance([0.0, 0.0, 1.0]));
}

#[test]
fn band1_light_is_brighter_on_the_side_facing_it() {
    let d = [0.6f32, 0.0, 0.8];
    let l = ShLight::from_ambient_diffuse([0.3; 3], [0.5, 0.6, 0.7], d);
    let toward = l.irradiance(d);
    let away = l.irradiance([-d[0], -d[1], -d[2]]);
    let side = l.irradiance([0.0, 1.0, 0.0]);
    for c in 0..3 {
        assert!(toward[c] > side[c] && side[c] > away[c]);
    }
    assert!((toward[1] - 0.9).abs() < 1e-5 && (away[1] + 0.3).abs() < 1e-5 && (side[1] - 0.3).abs() < 1e-5);
}

#[test]
fn single_coefficients_match_hand_formulas() {
    // E_i(n) = K_i · Y_i(n) for a unit coefficient; constants computed here in f64.
    let n0 = 0.5 * (1.0 / PI).sqrt();
    let n1 = 0.5 * (3.0 / PI).sqrt();
    let n21 = 0.5 * (15.0 / PI).sqrt();
    let n20 = 0.25 * (5.0 / PI).sqrt();
    let n22 = 0.25 * (15.0 / PI).sqrt();
    let (k0, k1, k2) = (PI, 2.0 * PI / 3.0, PI / 4.0);
    for n in normals() {
        let (x, y, z) = (n[0] as f64, n[1] as f64, n[2] as f64);
        let want = [
            k0 * n0,
            k1 * n1 * y,
            k1 * n1 * z,
            k1 * n1 * x,
            k2 * n21 * x * y,
            k2 * n21 * y * z,
            k2 * n20 * (3.0 * z * z - 1.0),
            k2 * n21 * z * x,
            k2 * n22 * (x * x - y * y),
        ];
        for (i, w) in want.iter().enumerate() {
            let e = single(i).irradiance(n);
            for (c, scale) in [1.0, 2.0, 3.0].iter().enumerate() {
                assert!((e[c] as f64 - w * scale).abs() < 2e-6, "coefficient {i} normal {n:?}: {} vs {}", e[c], w * scale);
            }
        }
        let b = lambert_basis(n);
        let y = sh_basis(n);
        for i in 0..SH_COEFFS {
            assert!((b[i] - y[i] * LAMBERT_KERNEL[i]).abs() < 1e-7);
        }
    }
    // Hand values: Y10 alone at n = +z gives sqrt(3π)/3; Y20 at +z gives sqrt(5π)/8.
    assert!((single(2).irradiance([0.0, 0.0, 1.0])[0] as f64 - (3.0 * PI).sqrt() / 3.0).abs() < 1e-6);
    assert!((single(6).irradiance([0.0, 0.0, 1.0])[0] as f64 - (5.0 * PI).sqrt() / 8.0).abs() < 1e-6);
}

#[test]
fn projected_point_light_matches_the_addition_theorem() {
    // Light = SH projection of a unit delta from d: L_i = Y_i(d). By the addition theorem,
    // E(d) = π/(4π)·1 + (2π/3)·3/(4π) + (π/4)·5/(4π) = 1/4 + 1/2 + 5/16 and E(−d) = 1/4 − 1/2 + 5/16.
    for d in normals() {
        let y = sh_basis(d);
        let mut l = ShLight::zero();
        for (c, v) in l.coeffs.iter_mut().zip(y) {
            *c = [v; 3];
        }
        assert!((l.irradiance(d)[0] - 1.0625).abs() < 1e-5);
        assert!((l.irradiance([-d[0], -d[1], -d[2]])[0] - 0.0625).abs() < 1e-5);
    }
}

#[test]
fn shading_uses_the_normal_rotated_by_the_pose() {
    // Light from +x (image right). A normal along +z, yawed by +90°, points to +x: fully lit.
    let light = ShLight::from_ambient_diffuse([0.5; 3], [0.5; 3], [1.0, 0.0, 0.0]);
    let mut out = [ProjectedVertex::INVALID];
    let pose = Pose { yaw: std::f32::consts::FRAC_PI_2, ..Pose::frontal(500.0) };
    shade_vertices(&[[0.8, 0.6, 0.4]], &[[0.0, 0.0, 1.0]], &pose, &light, &mut out).unwrap();
    assert!(out[0].color.iter().zip([0.8, 0.6, 0.4]).all(|(c, a)| (c - a).abs() < 1e-5), "{:?}", out[0].color);
    shade_vertices(&[[0.8, 0.6, 0.4]], &[[0.0, 0.0, 1.0]], &Pose::frontal(500.0), &light, &mut out).unwrap();
    assert!(out[0].color.iter().zip([0.4, 0.3, 0.2]).all(|(c, a)| (c - a).abs() < 1e-5), "{:?}", out[0].color);
}
