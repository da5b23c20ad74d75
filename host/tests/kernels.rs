//! Kernel tests: positive semi-definiteness, the factored form against the paper's formulas,
//! mirror anti-correlation of the symmetric shape kernel, channel correlation of the albedo kernels.
#![allow(clippy::needless_range_loop)] // index loops mirror the matrix formulas

use faer::{Mat, Side};
use gpmm_host::gp::kernel::*;
use gpmm_host::gp::lowrank::{low_rank, NystromOptions, RankSpec};
use rand::{RngExt, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

fn random_points(n: usize, seed: u64) -> Vec<KernelPoint> {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    (0..n)
        .map(|_| KernelPoint {
            position: [rng.random_range(-80.0..80.0), rng.random_range(-100.0..100.0), rng.random_range(-10.0..60.0)],
            color: [rng.random_range(0.2..0.9), rng.random_range(0.1..0.7), rng.random_range(0.1..0.6)],
        })
        .collect()
}

fn full_matrix(eval: impl Fn(&KernelPoint, &KernelPoint) -> [[f64; 3]; 3], pts: &[KernelPoint]) -> Mat<f64> {
    let n = pts.len();
    let mut m = Mat::zeros(3 * n, 3 * n);
    for i in 0..n {
        for j in 0..n {
            let k = eval(&pts[i], &pts[j]);
            for a in 0..3 {
                for b in 0..3 {
                    m[(3 * i + a, 3 * j + b)] = k[a][b];
                }
            }
        }
    }
    m
}

fn se(terms: &[SeTerm], d2: f64) -> f64 {
    terms.iter().map(|t| t.weight * (-d2 / (t.scale * t.scale)).exp()).sum()
}
fn d2(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|i| (a[i] - b[i]).powi(2)).sum()
}
fn mirror(p: [f64; 3]) -> [f64; 3] {
    [-p[0], p[1], p[2]]
}
fn scaled(m: [[f64; 3]; 3], s: f64) -> [[f64; 3]; 3] {
    m.map(|r| r.map(|v| v * s))
}
fn add(a: [[f64; 3]; 3], b: [[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let mut o = a;
    for r in 0..3 {
        for c in 0..3 {
            o[r][c] += b[r][c];
        }
    }
    o
}
const I3: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
const PHI: [[f64; 3]; 3] = [[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
fn mx(x: f64) -> [[f64; 3]; 3] {
    [[1.0, x, x], [x, 1.0, x], [x, x, 1.0]]
}

/// The paper's formulas, written out directly (independently of the factored code).
fn direct(model: ModelKernel, shape: bool, hp: &Hyperparameters, a: &KernelPoint, b: &KernelPoint) -> [[f64; 3]; 3] {
    let s0 = se(&hp.shape_terms, d2(a.position, b.position));
    let s0m = se(&hp.shape_terms, d2(a.position, mirror(b.position)));
    let sx = se(&hp.albedo_xyz_terms, d2(a.position, b.position));
    let sxm = se(&hp.albedo_xyz_terms, d2(a.position, mirror(b.position)));
    let sr = se(&hp.albedo_rgb_terms, d2(a.color, b.color));
    let name = model.name();
    if shape {
        let ks = scaled(I3, s0);
        return if name.starts_with("symmetric") { add(ks, scaled(PHI, hp.shape_alpha * s0m)) } else { ks };
    }
    let ka_xyz = scaled(I3, sx);
    let ka_rgb = scaled(I3, sr);
    let ka_xyz_cor = scaled(mx(hp.beta), sx);
    let ka_rgb_sym = scaled(mx(hp.gamma), sr);
    let ka_xyz_sym = add(ka_xyz_cor, scaled(mx(hp.beta), hp.albedo_alpha * sxm));
    match name {
        "standard-full" => scaled(add(ka_xyz, ka_rgb), 0.5),
        "standard-rgb" => ka_rgb,
        "standard-xyz" => ka_xyz,
        "symmetric-full" => scaled(add(ka_rgb_sym, ka_xyz_sym), 0.5),
        "symmetric-rgb" | "correlated-rgb" => ka_rgb_sym,
        "symmetric-xyz" => ka_xyz_sym,
        "correlated-full" => scaled(add(ka_rgb_sym, ka_xyz_cor), 0.5),
        "correlated-xyz" => ka_xyz_cor,
        other => panic!("unknown {other}"),
    }
}

#[test]
fn factored_kernels_equal_the_papers_formulas() {
    let hp = Hyperparameters::default();
    let pts = random_points(30, 1);
    for model in ModelKernel::ALL {
        for shape in [true, false] {
            let k = if shape { model.shape_kernel(&hp) } else { model.albedo_kernel(&hp) };
            for a in &pts {
                for b in pts.iter().take(10) {
                    let got = k.eval_matrix(a, b);
                    let want = direct(model, shape, &hp, a, b);
                    for r in 0..3 {
                        for c in 0..3 {
                            assert!(
                                (got[r][c] - want[r][c]).abs() < 1e-12 * (1.0 + want[r][c].abs()),
                                "{model} shape={shape} [{r}][{c}]: {} vs {}",
                                got[r][c],
                                want[r][c]
                            );
                        }
                    }
                }
            }
        }
    }
}

#[test]
fn every_kernel_matrix_is_symmetric_positive_semidefinite() {
    let hp = Hyperparameters::default();
    for seed in [2, 3] {
        let pts = random_points(60, seed);
        for model in ModelKernel::ALL {
            for (what, k) in [("shape", model.shape_kernel(&hp)), ("albedo", model.albedo_kernel(&hp))] {
                let m = full_matrix(|a, b| k.eval_matrix(a, b), &pts);
                let n = m.nrows();
                let mut max = 0.0f64;
                for i in 0..n {
                    for j in 0..n {
                        assert!((m[(i, j)] - m[(j, i)]).abs() < 1e-12, "{model} {what} not symmetric");
                        max = max.max(m[(i, j)].abs());
                    }
                }
                let ev = m.self_adjoint_eigenvalues(Side::Lower).unwrap();
                assert!(ev[0] > -1e-10 * max, "{model} {what}: smallest eigenvalue {} (largest entry {max})", ev[0]);
            }
        }
    }
}

#[test]
fn symmetric_shape_kernel_anticorrelates_x_and_correlates_yz_of_mirror_pairs() {
    let hp = Hyperparameters::default();
    let k = shape_symmetric(&hp);
    let s00 = se(&hp.shape_terms, 0.0);
    for x in [5.0, 20.0, 40.0, 70.0] {
        let p = KernelPoint { position: [x, 10.0, 30.0], color: [0.5; 3] };
        let q = KernelPoint { position: mirror(p.position), color: [0.5; 3] };
        let cross = k.eval_matrix(&p, &q);
        let var = k.eval_matrix(&p, &p);
        let spq = se(&hp.shape_terms, d2(p.position, q.position));
        // x: Σ0(p,q) - α Σ0(p,Φq) = Σ0(p,q) - α Σ0(0); variance Σ0(0) - α Σ0(p,Φp).
        let corr_x = cross[0][0] / var[0][0];
        let want_x = (spq - hp.shape_alpha * s00) / (s00 - hp.shape_alpha * spq);
        assert!((corr_x - want_x).abs() < 1e-12);
        let corr_y = cross[1][1] / var[1][1];
        let want_y = (spq + hp.shape_alpha * s00) / (s00 + hp.shape_alpha * spq);
        assert!((corr_y - want_y).abs() < 1e-12 && (cross[2][2] / var[2][2] - want_y).abs() < 1e-12);
        if x >= 40.0 {
            assert!(corr_x < -0.3, "mirror pair at ±{x} mm: x correlation {corr_x} should be clearly negative");
        }
        assert!(corr_y > 0.7, "mirror pair at ±{x} mm: y correlation {corr_y}");
    }
}

#[test]
fn low_rank_symmetric_model_reproduces_mirror_correlation() {
    // A mirror-symmetric point set; covariances from the low-rank components.
    let hp = Hyperparameters::default();
    let half = random_points(80, 9);
    let mut pts: Vec<KernelPoint> =
        half.iter().map(|p| KernelPoint { position: [p.position[0].abs() + 5.0, p.position[1], p.position[2]], ..*p }).collect();
    let mirrored: Vec<KernelPoint> = pts.iter().map(|p| KernelPoint { position: mirror(p.position), ..*p }).collect();
    pts.extend(mirrored);
    let lr = low_rank(&shape_symmetric(&hp), &pts, RankSpec::Captured(0.999), &NystromOptions::default(), |_, _| {});
    let cov = |i: usize, a: usize, j: usize, b: usize| -> f64 {
        lr.components.iter().map(|c| c.eigenvalue * c.field[i] * c.direction[a] * c.field[j] * c.direction[b]).sum()
    };
    let k = shape_symmetric(&hp);
    for i in 0..80 {
        let exact = k.eval_matrix(&pts[i], &pts[i + 80]);
        for a in 0..3 {
            assert!(
                (cov(i, a, i + 80, a) - exact[a][a]).abs() < 0.05 * 15.0,
                "pair {i} axis {a}: {} vs {}",
                cov(i, a, i + 80, a),
                exact[a][a]
            );
        }
    }
}

#[test]
fn colour_correlated_kernels_give_channel_correlation_beta_and_gamma() {
    let hp = Hyperparameters::default();
    let p = KernelPoint { position: [10.0, 0.0, 40.0], color: [0.6, 0.4, 0.3] };
    let corr = |k: &DiagonalKernel| {
        let m = k.eval_matrix(&p, &p);
        [m[0][1] / m[0][0], m[0][2] / m[0][0], m[1][2] / m[1][1]]
    };
    for c in corr(&albedo(AlbedoKernel::CorrelatedXyz, &hp)) {
        assert!((c - hp.beta).abs() < 1e-12);
    }
    for c in corr(&albedo(AlbedoKernel::CorrelatedRgb, &hp)) {
        assert!((c - hp.gamma).abs() < 1e-12);
    }
    for c in corr(&albedo(AlbedoKernel::StandardXyz, &hp)) {
        assert!(c.abs() < 1e-12, "standard kernels have independent channels");
    }
    // Mixed: variance-weighted average of β and γ.
    let (vx, vr) = (se(&hp.albedo_xyz_terms, 0.0), se(&hp.albedo_rgb_terms, 0.0));
    let want = (hp.beta * vx + hp.gamma * vr) / (vx + vr);
    for c in corr(&albedo(AlbedoKernel::Correlated, &hp)) {
        assert!((c - want).abs() < 1e-12);
    }
}

#[test]
fn hyperparameters_toml_overrides_only_what_it_names() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("hp.toml");
    std::fs::write(&path, "shape_alpha = 0.5\nshape_terms = [{ weight = 1.0, scale = 30.0 }]\n").unwrap();
    let hp = Hyperparameters::from_toml_file(&path).unwrap();
    assert_eq!(hp.shape_alpha, 0.5);
    assert_eq!(hp.shape_terms, vec![SeTerm { weight: 1.0, scale: 30.0 }]);
    assert_eq!(hp.beta, Hyperparameters::default().beta);
    std::fs::write(&path, "shape_alfa = 0.5\n").unwrap();
    let err = Hyperparameters::from_toml_file(&path).unwrap_err().to_string();
    assert!(err.contains("hp.toml") && err.contains("shape_alfa"), "{err}");
    std::fs::write(&path, "gamma = 3.0\n").unwrap();
    assert!(Hyperparameters::from_toml_file(&path).unwrap_err().to_string().contains("gamma"));
}

#[test]
fn documented_hyperparameter_file_equals_the_defaults() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/hyperparameters.toml");
    assert_eq!(Hyperparameters::from_toml_file(&path).unwrap(), Hyperparameters::default());
}
