//! Nyström accuracy against the exact eigendecomposition on a small mesh.

use gpmm_host::gp::kernel::{DiagonalKernel, Hyperparameters, KernelPoint, ModelKernel};
use gpmm_host::gp::lowrank::{exact_scalar_eigenvalues, low_rank, NystromOptions, RankSpec};

/// A face-sized half ellipsoid (150 x 200 x 100 mm) with a smooth colour pattern, `n` vertices.
fn half_ellipsoid(n: usize) -> Vec<KernelPoint> {
    // Fibonacci points on the front half of the sphere, stretched.
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - (i as f64 + 0.5) / n as f64; // (0, 1]: front hemisphere
            let r = (1.0 - z * z).sqrt();
            let t = golden * i as f64;
            let (x, y) = (r * t.cos(), r * t.sin());
            let pos = [75.0 * x, 100.0 * y, 50.0 * z];
            let color = [0.6 + 0.2 * x, 0.45 + 0.1 * y * y, 0.35 + 0.15 * z];
            KernelPoint { position: pos, color }
        })
        .collect()
}

/// Exact eigenvalues of the 3N x 3N matrix kernel, from its scalar classes.
fn exact_matrix_eigenvalues(kernel: &DiagonalKernel, pts: &[KernelPoint]) -> (Vec<f64>, f64) {
    let mut all = Vec::new();
    let mut trace = 0.0;
    for class in kernel.classes() {
        let ev = exact_scalar_eigenvalues(&class.kernel, pts);
        trace += class.directions.len() as f64 * pts.iter().map(|p| class.kernel.eval(p, p)).sum::<f64>();
        for v in ev {
            for _ in &class.directions {
                all.push(v);
            }
        }
    }
    all.sort_by(|a, b| b.total_cmp(a));
    (all, trace)
}

#[test]
fn nystrom_top20_within_2_percent_and_captured_matches_exact() {
    let pts = half_ellipsoid(600);
    let hp = Hyperparameters::default();
    let opts = NystromOptions { points: 200, ..Default::default() };
    for model in ModelKernel::ALL {
        for (what, kernel) in [("shape", model.shape_kernel(&hp)), ("colour", model.albedo_kernel(&hp))] {
            let (exact, exact_trace) = exact_matrix_eigenvalues(&kernel, &pts);
            let lr = low_rank(&kernel, &pts, RankSpec::Count(20), &opts, |_, _| {});
            assert_eq!(lr.components.len(), 20);
            assert!((lr.trace - exact_trace).abs() < 1e-9 * exact_trace, "trace is computed exactly");
            for (i, (c, e)) in lr.components.iter().zip(&exact).enumerate() {
                let rel = (c.eigenvalue - e).abs() / e;
                assert!(rel < 0.02, "{model} {what}: eigenvalue {i}: nystrom {} vs exact {e} ({:.2}%)", c.eigenvalue, 100.0 * rel);
            }
            let exact_captured: f64 = exact[..20].iter().sum::<f64>() / exact_trace;
            assert!(
                (lr.captured() - exact_captured).abs() < 0.01 * exact_captured,
                "{model} {what}: captured {} vs exact {exact_captured}",
                lr.captured()
            );
        }
    }
}
