//! Low-rank (Mercer) approximation of a factored kernel by the Nyström method.
//!
//! For each [`DirectionClass`](crate::gp::kernel::DirectionClass) of a [`DiagonalKernel`], the
//! scalar kernel matrix `K` over the `N` mesh vertices is approximated from `m` sampled
//! vertices `Z` (farthest-point sampling): `K_ZZ = U Λ Uᵀ` and the Nyström extensions
//! `K_NZ u_i` of its leading eigenvectors span a subspace that holds `K`'s leading
//! eigenvectors. By default ([`NystromOptions::refine`]) that subspace is orthonormalized and a
//! Rayleigh–Ritz step against the exact `K` (streamed in row blocks, never stored) gives
//! the eigenpairs: plain Nyström underestimates every eigenvalue (`K̃ = K_NZ K_ZZ⁺ K_ZN ⪯ K`),
//! by several percent for short-range terms; Ritz values are far closer. With `refine`
//! off, the eigenpairs of `K̃` itself are returned (`K̃ = B Bᵀ`, `B = K_NZ U Λ^{-1/2}`,
//! diagonalizing `Bᵀ B`).
//!
//! Components of all classes (each scalar eigenpair once per direction of its class) are
//! merged and sorted by eigenvalue. The captured fraction is `Σ kept eigenvalues / trace(K)`
//! with the exact trace of the full `3N x 3N` kernel matrix.

use crate::gp::kernel::{DiagonalKernel, KernelBank, KernelPoint, ScalarKernel};
use crate::mesh::geometry::dist2;
use faer::{Mat, MatRef, Side};
use rand::seq::index::sample;
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;
use rayon::prelude::*;

/// How many components to keep.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RankSpec {
    /// Exactly this many (or fewer if the kernel has fewer non-zero eigenvalues).
    Count(usize),
    /// The fewest components whose eigenvalues sum to at least this fraction of the trace.
    Captured(f64),
}

impl RankSpec {
    /// The rank of one part from a count or a captured fraction (200 components if neither is
    /// given), as `gpmm build --rank-WHAT / --captured-WHAT` and the Python package take them.
    pub fn from_flags(count: Option<usize>, captured: Option<f64>, what: &str) -> Result<Self, String> {
        match (count, captured) {
            (Some(0), _) => Err(format!("--rank-{what} 0: a model needs at least one {what} component")),
            (Some(k), _) => Ok(Self::Count(k)),
            (None, Some(f)) if f > 0.0 && f <= 1.0 => Ok(Self::Captured(f)),
            (None, Some(f)) => Err(format!("--captured-{what} {f} must be in (0, 1]")),
            (None, None) => Ok(Self::Count(200)),
        }
    }
}

/// Nyström settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NystromOptions {
    /// Number of sampled vertices (all vertices if the mesh has fewer).
    pub points: usize,
    /// Seed of the vertex sample.
    pub seed: u64,
    /// Eigenvalues of `K_ZZ` below `tolerance · λ_max` are dropped (conditioning).
    pub tolerance: f64,
    /// Refine the Nyström eigenpairs by Rayleigh–Ritz against the exact kernel matrix.
    pub refine: bool,
}

impl Default for NystromOptions {
    fn default() -> Self {
        Self { points: 2000, seed: 0x6770_6d6d, tolerance: 1e-11, refine: true }
    }
}

/// Eigenpairs of one scalar kernel matrix, largest first.
#[derive(Debug, Clone)]
pub struct ScalarEigen {
    /// Eigenvalues, descending, all positive.
    pub values: Vec<f64>,
    /// Orthonormal eigenvectors, one column per eigenvalue (`N x values.len()`).
    pub vectors: Mat<f64>,
    /// Exact trace of the scalar kernel matrix.
    pub trace: f64,
}

/// One component of a low-rank model: `sqrt(eigenvalue) · field ⊗ direction`.
#[derive(Debug, Clone, PartialEq)]
pub struct Component {
    /// Eigenvalue of the `3N x 3N` kernel matrix.
    pub eigenvalue: f64,
    /// Unit 3-vector.
    pub direction: [f64; 3],
    /// Unit-norm scalar field over the vertices.
    pub field: Vec<f64>,
}

/// A low-rank approximation of a factored kernel.
#[derive(Debug, Clone, PartialEq)]
pub struct LowRank {
    /// Components, eigenvalue descending.
    pub components: Vec<Component>,
    /// Exact trace of the `3N x 3N` kernel matrix.
    pub trace: f64,
}

impl LowRank {
    /// Fraction of the kernel's trace the kept components capture.
    pub fn captured(&self) -> f64 {
        if self.trace > 0.0 {
            self.components.iter().map(|c| c.eigenvalue).sum::<f64>() / self.trace
        } else {
            0.0
        }
    }
}

/// Evaluates `k(points[i], points[cols[j]])` into a column-major `N x cols.len()` buffer, in parallel.
fn cross_matrix(kernel: &ScalarKernel, points: &[KernelPoint], cols: &[usize]) -> Vec<f64> {
    let n = points.len();
    let mut data = vec![0.0; n * cols.len()];
    data.par_chunks_mut(n.max(1)).zip(cols.par_iter()).for_each(|(col, &j)| {
        let pj = &points[j];
        for (v, pi) in col.iter_mut().zip(points) {
            *v = kernel.eval(pi, pj);
        }
    });
    data
}

/// Chooses `m` of the points for the Nyström sample: farthest-point sampling in position
/// space from a seeded random start, so the sample covers the surface evenly (stationary
/// kernels are then approximated about equally well everywhere).
pub fn sample_points(points: &[KernelPoint], m: usize, seed: u64) -> Vec<usize> {
    let n = points.len();
    if m >= n {
        return (0..n).collect();
    }
    if m == 0 {
        return Vec::new();
    }
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let start = sample(&mut rng, n, 1).index(0);
    let mut chosen = Vec::with_capacity(m);
    let mut nearest = vec![f64::INFINITY; n];
    let mut next = start;
    for _ in 0..m {
        chosen.push(next);
        let p = points[next].position;
        let mut best = (f64::NEG_INFINITY, 0);
        for (i, (d, q)) in nearest.iter_mut().zip(points).enumerate() {
            *d = d.min(dist2(p, q.position));
            if *d > best.0 {
                best = (*d, i);
            }
        }
        next = best.1;
    }
    chosen
}

/// Nyström eigendecomposition of one scalar kernel over `points`, keeping at most `max_rank` pairs.
pub fn scalar_nystrom(kernel: &ScalarKernel, points: &[KernelPoint], opts: &NystromOptions, max_rank: usize) -> ScalarEigen {
    let mut all = bank_nystrom(std::slice::from_ref(kernel), points, opts, max_rank);
    all.pop().unwrap_or_else(|| ScalarEigen { values: Vec::new(), vectors: Mat::zeros(points.len(), 0), trace: 0.0 })
}

/// Nyström eigendecompositions of several scalar kernels over the same points and sample,
/// sharing every kernel evaluation (see [`KernelBank`]).
pub fn bank_nystrom(kernels: &[ScalarKernel], points: &[KernelPoint], opts: &NystromOptions, max_rank: usize) -> Vec<ScalarEigen> {
    let n = points.len();
    let c = kernels.len();
    let bank = KernelBank::new(kernels);
    let traces: Vec<f64> = kernels.iter().map(|k| points.iter().map(|p| k.eval(p, p)).sum()).collect();
    let empty = |trace| ScalarEigen { values: Vec::new(), vectors: Mat::zeros(n, 0), trace };
    if n == 0 || max_rank == 0 || c == 0 {
        return traces.into_iter().map(empty).collect();
    }
    let t0 = std::time::Instant::now();
    let m = opts.points.clamp(1, n);
    let mut z = sample_points(points, m, opts.seed);
    z.sort_unstable();

    // K_NZ of every kernel at once: column j holds c stacked columns of length n.
    let mut knz_data = vec![0.0; c * n * m];
    knz_data.par_chunks_mut(c * n).zip(z.par_iter()).for_each(|(col, &j)| {
        let pj = &points[j];
        let mut scratch = vec![0.0; bank.term_count()];
        let mut vals = vec![0.0; c];
        for (i, pi) in points.iter().enumerate() {
            bank.eval_into(pi, pj, &mut scratch, &mut vals);
            for (k, v) in vals.iter().enumerate() {
                col[k * n + i] = *v;
            }
        }
    });
    log::debug!("nystrom: N={n} m={m} classes={c}: K_NZ ({:.2?})", t0.elapsed());

    let mut out = Vec::with_capacity(c);
    let mut subspaces = Vec::with_capacity(c);
    for (k, &trace) in traces.iter().enumerate() {
        let knz = MatRef::from_column_major_slice_with_stride(&knz_data[k * n..], n, m, c * n);
        let kzz = Mat::from_fn(m, m, |a, b| knz[(z[a], b)]);
        if opts.refine {
            // Only the leading subspace is needed (Rayleigh–Ritz against the exact kernel
            // follows): a randomized range finder instead of the full m × m decomposition.
            let dim = m.min(max_rank.saturating_mul(2).saturating_add(10));
            match leading_subspace(kzz.as_ref(), dim, opts.tolerance, opts.seed ^ (k as u64)) {
                Some(uk) => {
                    let ext = knz * &uk;
                    subspaces.push(Some(ext.qr().compute_thin_Q()));
                    out.push(None);
                }
                None => {
                    out.push(Some(empty(trace)));
                    subspaces.push(None);
                }
            }
            continue;
        }
        let Ok(eig) = kzz.self_adjoint_eigen(Side::Lower) else {
            out.push(Some(empty(trace)));
            subspaces.push(None);
            continue;
        };
        let lambda = eig.S().column_vector();
        let u = eig.U();
        let lmax = (0..m).map(|i| lambda[i]).fold(0.0f64, f64::max);
        let keep: Vec<usize> = (0..m).rev().filter(|&i| lambda[i] > opts.tolerance * lmax && lambda[i] > 0.0).collect();
        if keep.is_empty() {
            out.push(Some(empty(trace)));
            subspaces.push(None);
            continue;
        }
        if opts.refine {
            // The Nyström extensions K_NZ u_i of K_ZZ's leading eigenvectors span the subspace
            // (twice the rank: Rayleigh–Ritz needs room to converge); see `rayleigh_ritz_bank`.
            let dim = keep.len().min(max_rank.saturating_mul(2).saturating_add(10));
            let uk = Mat::from_fn(m, dim, |r, col| u[(r, keep[col])]);
            let ext = knz * &uk;
            subspaces.push(Some(ext.qr().compute_thin_Q()));
            out.push(None);
        } else {
            out.push(Some(plain_nystrom(knz, u, lambda.iter().copied().collect(), &keep, max_rank, trace)));
            subspaces.push(None);
        }
    }
    log::debug!("nystrom: eigendecompositions of K_ZZ ({:.2?})", t0.elapsed());
    drop(knz_data);
    if opts.refine {
        let refined = rayleigh_ritz_bank(&bank, points, &subspaces, max_rank, &traces);
        for (slot, r) in out.iter_mut().zip(refined) {
            if slot.is_none() {
                *slot = r;
            }
        }
        log::debug!("nystrom: rayleigh-ritz ({:.2?})", t0.elapsed());
    }
    out.into_iter().zip(traces).map(|(e, t)| e.unwrap_or_else(|| empty(t))).collect()
}

/// Power iterations of [`leading_subspace`].
const POWER_ITERATIONS: usize = 4;

/// An orthonormal basis (`m × ≤ dim`) of the leading eigenvectors of the symmetric positive
/// semi-definite `a` (those with eigenvalue above `tolerance` × the largest), by a randomized range
/// finder with [`POWER_ITERATIONS`] power iterations (Halko, Martinsson & Tropp 2011): `a` times a Gaussian block
/// with 10 extra columns, re-orthonormalized after each product, then the Ritz vectors of the
/// small projected matrix. `O(m² · dim)` instead of the full decomposition's `O(m³)`; `None` when
/// `a` has no positive eigenvalue.
fn leading_subspace(a: MatRef<'_, f64>, dim: usize, tolerance: f64, seed: u64) -> Option<Mat<f64>> {
    use rand_distr::{Distribution, StandardNormal};
    let m = a.nrows();
    let l = (dim + 10).min(m);
    if l == 0 {
        return None;
    }
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let omega = Mat::from_fn(m, l, |_, _| -> f64 { StandardNormal.sample(&mut rng) });
    let mut q = (a * &omega).qr().compute_thin_Q();
    for _ in 0..POWER_ITERATIONS {
        q = (a * &q).qr().compute_thin_Q();
    }
    let b = q.transpose() * a * &q;
    let eig = b.self_adjoint_eigen(Side::Lower).ok()?;
    let theta = eig.S().column_vector();
    let w = eig.U();
    let tmax = (0..l).map(|i| theta[i]).fold(0.0f64, f64::max);
    let keep: Vec<usize> = (0..l).rev().filter(|&i| theta[i] > tolerance * tmax && theta[i] > 0.0).take(dim).collect();
    if keep.is_empty() {
        return None;
    }
    let wk = Mat::from_fn(l, keep.len(), |r, c| w[(r, keep[c])]);
    Some(&q * &wk)
}

/// Plain Nyström: `K̃ = B Bᵀ` with `B = K_NZ U Λ^{-1/2}`; eigenpairs of `K̃` from `Bᵀ B = V S Vᵀ`.
fn plain_nystrom(knz: MatRef<'_, f64>, u: MatRef<'_, f64>, lambda: Vec<f64>, keep: &[usize], max_rank: usize, trace: f64) -> ScalarEigen {
    let m = u.nrows();
    let w = Mat::from_fn(m, keep.len(), |r, c| u[(r, keep[c])] / lambda[keep[c]].sqrt());
    let b = knz * &w;
    let c = b.transpose() * &b;
    let Ok(eig_c) = c.self_adjoint_eigen(Side::Lower) else {
        return ScalarEigen { values: Vec::new(), vectors: Mat::zeros(knz.nrows(), 0), trace };
    };
    let s = eig_c.S().column_vector();
    let v = eig_c.U();
    let r = keep.len();
    let smax = (0..r).map(|i| s[i]).fold(0.0f64, f64::max);
    let top: Vec<usize> = (0..r).rev().filter(|&i| s[i] > 1e-14 * smax && s[i] > 0.0).take(max_rank).collect();
    let vt = Mat::from_fn(r, top.len(), |row, col| v[(row, top[col])] / s[top[col]].sqrt());
    ScalarEigen { values: top.iter().map(|&i| s[i]).collect(), vectors: &b * &vt, trace }
}

/// Rayleigh–Ritz refinement of orthonormal subspaces `Q_c` (`N x k_c`) against the exact
/// kernel matrices `K_c` of a bank.
///
/// Nyström's `K̃ = K_NZ K_ZZ⁺ K_ZN` is below `K` (it underestimates every eigenvalue, most for
/// short-range terms the sample cannot resolve). Projecting the exact `K` onto the Nyström
/// subspace (`H = Qᵀ K Q`) and diagonalizing `H` gives the best eigenpairs within it (Ritz
/// values are lower bounds that converge fast). `K` is streamed in row blocks and only its
/// upper block triangle is evaluated (`H = Σ_i Q_iᵀ K_ii Q_i + Σ_{i<j} (X_ij + X_ijᵀ)` with
/// `X_ij = Q_iᵀ K_ij Q_j`), every kernel evaluation shared by all classes of the bank.
fn rayleigh_ritz_bank(
    bank: &KernelBank,
    points: &[KernelPoint],
    qs: &[Option<Mat<f64>>],
    max_rank: usize,
    traces: &[f64],
) -> Vec<Option<ScalarEigen>> {
    let n = points.len();
    const BLOCK: usize = 96;
    let starts: Vec<usize> = (0..n).step_by(BLOCK).collect();
    let dims: Vec<usize> = qs.iter().map(|q| q.as_ref().map_or(0, |q| q.ncols())).collect();
    let zeros = || dims.iter().map(|&k| Mat::<f64>::zeros(k, k)).collect::<Vec<_>>();
    let h = starts
        .par_iter()
        .fold(zeros, |mut acc, &start| {
            let rows = BLOCK.min(n - start);
            let cols = n - start;
            let mut kb: Vec<Mat<f64>> = qs.iter().map(|q| if q.is_some() { Mat::zeros(rows, cols) } else { Mat::zeros(0, 0) }).collect();
            let mut scratch = vec![0.0; bank.term_count()];
            let mut vals = vec![0.0; bank.len()];
            for c in 0..cols {
                let pc = &points[start + c];
                for r in 0..rows {
                    bank.eval_into(&points[start + r], pc, &mut scratch, &mut vals);
                    for ((m, v), q) in kb.iter_mut().zip(&vals).zip(qs) {
                        if q.is_some() {
                            m[(r, c)] = *v;
                        }
                    }
                }
            }
            for ((hk, m), q) in acc.iter_mut().zip(&kb).zip(qs) {
                let Some(q) = q else { continue };
                let qi = q.subrows(start, rows);
                let diag = m.subcols(0, rows) * qi;
                *hk += qi.transpose() * &diag;
                if cols > rows {
                    let upper = m.subcols(rows, cols - rows) * q.subrows(start + rows, cols - rows);
                    let x = qi.transpose() * &upper;
                    *hk += &x;
                    *hk += x.transpose();
                }
            }
            acc
        })
        .reduce(zeros, |mut a, b| {
            for (x, y) in a.iter_mut().zip(b) {
                *x += y;
            }
            a
        });
    qs.iter()
        .zip(h)
        .zip(traces)
        .map(|((q, h), &trace)| {
            let q = q.as_ref()?;
            let k = q.ncols();
            let hs = Mat::from_fn(k, k, |i, j| 0.5 * (h[(i, j)] + h[(j, i)]));
            let eig = hs.self_adjoint_eigen(Side::Lower).ok()?;
            let theta = eig.S().column_vector();
            let w = eig.U();
            let order: Vec<usize> = (0..k).rev().filter(|&i| theta[i] > 0.0).take(max_rank).collect();
            let wt = Mat::from_fn(k, order.len(), |r, c| w[(r, order[c])]);
            Some(ScalarEigen { values: order.iter().map(|&i| theta[i]).collect(), vectors: q * &wt, trace })
        })
        .collect()
}

/// Low-rank approximation of a factored kernel over `points`.
///
/// `progress` is called after each scalar problem with (done, total).
pub fn low_rank(
    kernel: &DiagonalKernel,
    points: &[KernelPoint],
    rank: RankSpec,
    opts: &NystromOptions,
    mut progress: impl FnMut(usize, usize),
) -> LowRank {
    let classes = kernel.classes();
    let max_rank = match rank {
        RankSpec::Count(k) => k,
        RankSpec::Captured(_) => usize::MAX,
    };
    let mut candidates: Vec<(f64, usize, usize, usize)> = Vec::new(); // (value, class, pair, direction)
    let kernels: Vec<ScalarKernel> = classes.iter().map(|c| c.kernel.clone()).collect();
    progress(0, 1);
    let eigens = bank_nystrom(&kernels, points, opts, max_rank);
    progress(1, 1);
    let mut trace = 0.0;
    for (ci, (class, e)) in classes.iter().zip(&eigens).enumerate() {
        trace += e.trace * class.directions.len() as f64;
        for (pi, &val) in e.values.iter().enumerate() {
            for di in 0..class.directions.len() {
                candidates.push((val, ci, pi, di));
            }
        }
    }
    // Stable, deterministic order: eigenvalue descending, then class, pair, direction.
    candidates.sort_by(|a, b| b.0.total_cmp(&a.0).then((a.1, a.2, a.3).cmp(&(b.1, b.2, b.3))));
    let keep = match rank {
        RankSpec::Count(k) => k.min(candidates.len()),
        RankSpec::Captured(f) => {
            let target = f.clamp(0.0, 1.0) * trace;
            let mut acc = 0.0;
            let mut count = candidates.len();
            for (i, c) in candidates.iter().enumerate() {
                acc += c.0;
                if acc >= target {
                    count = i + 1;
                    break;
                }
            }
            count
        }
    };
    let components = candidates[..keep]
        .iter()
        .map(|&(val, ci, pi, di)| Component {
            eigenvalue: val,
            direction: classes[ci].directions[di],
            field: eigens[ci].vectors.col(pi).iter().copied().collect(),
        })
        .collect();
    LowRank { components, trace }
}

/// Exact eigenvalues (descending) of the scalar kernel matrix over `points` (test and report helper).
pub fn exact_scalar_eigenvalues(kernel: &ScalarKernel, points: &[KernelPoint]) -> Vec<f64> {
    let n = points.len();
    let all: Vec<usize> = (0..n).collect();
    let data = cross_matrix(kernel, points, &all);
    let k = MatRef::from_column_major_slice(&data, n, n);
    match k.self_adjoint_eigenvalues(Side::Lower) {
        Ok(mut v) => {
            v.reverse();
            v
        }
        Err(_) => Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gp::kernel::{Hyperparameters, ModelKernel};

    fn grid(n: usize) -> Vec<KernelPoint> {
        (0..n)
            .map(|i| {
                let t = i as f64 / n as f64;
                let a = t * 40.0;
                KernelPoint { position: [60.0 * a.cos() * t, 80.0 * (t - 0.5), 40.0 * a.sin()], color: [t, 0.5 * t, 0.3] }
            })
            .collect()
    }

    #[test]
    fn with_all_points_nystrom_is_exact() {
        let pts = grid(150);
        let hp = Hyperparameters::default();
        let class = &ModelKernel::StandardFull.shape_kernel(&hp).classes()[0];
        let opts = NystromOptions { points: 1000, ..Default::default() };
        let e = scalar_nystrom(&class.kernel, &pts, &opts, 10);
        let exact = exact_scalar_eigenvalues(&class.kernel, &pts);
        for (a, b) in e.values.iter().zip(&exact) {
            assert!((a - b).abs() < 1e-8 * exact[0], "{a} vs {b}");
        }
        // Orthonormal eigenvectors.
        let g = e.vectors.transpose() * &e.vectors;
        for i in 0..e.values.len() {
            for j in 0..e.values.len() {
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((g[(i, j)] - want).abs() < 1e-8);
            }
        }
    }

    #[test]
    fn captured_rank_selects_the_fewest_components() {
        let pts = grid(120);
        let hp = Hyperparameters::default();
        let k = ModelKernel::SymmetricFull.shape_kernel(&hp);
        let lr = low_rank(&k, &pts, RankSpec::Captured(0.9), &NystromOptions::default(), |_, _| {});
        assert!(lr.captured() >= 0.9);
        let without_last: f64 = lr.components[..lr.components.len() - 1].iter().map(|c| c.eigenvalue).sum();
        assert!(without_last / lr.trace < 0.9);
        assert!(lr.components.windows(2).all(|w| w[0].eigenvalue >= w[1].eigenvalue));
    }
}
