//! Low-rank (Mercer) approximation of a factored kernel by the Nyström method.
//!
//! For each [`DirectionClass`](crate::gp::kernel::DirectionClass) of a [`DiagonalKernel`], the
//! scalar kernel matrix `K` over the `N` mesh vertices is approximated from `m` sampled
//! vertices `Z` (farthest-point sampling): the Nyström extensions `K_NZ U` of a basis `U` of
//! `K_ZZ`'s leading subspace (a randomized range finder, see [`bank_nystrom`]) span a subspace that holds `K`'s leading
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
use crate::gp::kernel_columns::PointColumns;
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

/// A rank flag out of its range; `part` names the model part (`shape`, `color`).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RankFlagError {
    /// A count of zero components.
    #[error("--rank-{part} 0: a model needs at least one {part} component")]
    NoComponents {
        /// The model part.
        part: String,
    },
    /// A captured fraction outside `(0, 1]`.
    #[error("--captured-{part} {fraction} must be in (0, 1]")]
    Captured {
        /// The model part.
        part: String,
        /// The fraction given.
        fraction: f64,
    },
}

impl RankSpec {
    /// The rank of one part from a count or a captured fraction (200 components if neither is
    /// given), as `gpmm build --rank-WHAT / --captured-WHAT` and the Python package take them.
    pub fn from_flags(count: Option<usize>, captured: Option<f64>, what: &str) -> Result<Self, RankFlagError> {
        match (count, captured) {
            (Some(0), _) => Err(RankFlagError::NoComponents { part: what.to_string() }),
            (Some(k), _) => Ok(Self::Count(k)),
            (None, Some(f)) if f > 0.0 && f <= 1.0 => Ok(Self::Captured(f)),
            (None, Some(fraction)) => Err(RankFlagError::Captured { part: what.to_string(), fraction }),
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
    /// Without `refine`: eigenvalues of `K_ZZ` below `tolerance · λ_max` are dropped (conditioning).
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
    let mut all = bank_nystrom(std::slice::from_ref(kernel), points, opts, &[max_rank], None);
    all.pop().unwrap_or_else(|| ScalarEigen { values: Vec::new(), vectors: Mat::zeros(points.len(), 0), trace: 0.0 })
}

/// Nyström eigendecompositions of several scalar kernels over the same points and sample,
/// sharing every kernel evaluation (see [`KernelBank`]); kernel `k` keeps at most `max_ranks[k]` pairs.
///
/// With `split = Some((count, directions))` only the `count` largest components of the merged
/// kernel are wanted, kernel `k`'s pairs counting `directions[k]` times: the exact eigenvalues of
/// each kernel over the first `ESTIMATE_POINTS` sampled points estimate how many pairs each
/// kernel contributes to them, and a kernel's range finder, extension and Rayleigh–Ritz step are
/// sized for that estimate with a margin (see `split_bounds`) instead of `max_ranks[k]`.
///
/// With [`NystromOptions::refine`] (the default): `K_NZ` in single precision, a basis of the
/// leading subspace of `K_ZZ` from a randomized range finder (single precision too), its Nyström
/// extensions `Y = K_NZ U`, and a Rayleigh–Ritz step in double precision against the exact
/// kernel matrix (`rayleigh_ritz_bank`). The single-precision steps only choose the subspace:
/// the eigenpairs are exact Ritz pairs of `K` within it.
pub fn bank_nystrom(
    kernels: &[ScalarKernel],
    points: &[KernelPoint],
    opts: &NystromOptions,
    max_ranks: &[usize],
    split: Option<(usize, &[usize])>,
) -> Vec<ScalarEigen> {
    faer::set_global_parallelism(faer::Par::rayon(FAER_TASKS));
    let n = points.len();
    let c = kernels.len();
    assert_eq!(max_ranks.len(), c, "bank_nystrom: one rank per kernel");
    let bank = KernelBank::new(kernels);
    let traces: Vec<f64> = kernels.iter().map(|k| points.iter().map(|p| k.eval(p, p)).sum()).collect();
    let empty = |trace| ScalarEigen { values: Vec::new(), vectors: Mat::zeros(n, 0), trace };
    let max_rank = max_ranks.iter().copied().max().unwrap_or(0);
    if n == 0 || max_rank == 0 {
        return traces.into_iter().map(empty).collect();
    }
    let t0 = std::time::Instant::now();
    let m = opts.points.clamp(1, n);
    let mut z = sample_points(points, m, opts.seed);
    let bounds = match split {
        Some((count, directions)) if opts.refine => {
            let ids = &z[..z.len().min(ESTIMATE_POINTS)];
            let values: Vec<Vec<f64>> = kernels
                .iter()
                .map(|k| {
                    // The lower triangle only (all the eigensolver reads).
                    let a = Mat::from_fn(ids.len(), ids.len(), |i, j| if j <= i { k.eval(&points[ids[i]], &points[ids[j]]) } else { 0.0 });
                    a.self_adjoint_eigenvalues(Side::Lower).map(|v| v.into_iter().rev().collect()).unwrap_or_default()
                })
                .collect();
            split_bounds(count, directions, &values, max_ranks)
        }
        _ => max_ranks.to_vec(),
    };
    log::debug!("nystrom: pairs sized for {bounds:?} of at most {max_ranks:?} ({:.2?})", t0.elapsed());
    z.sort_unstable();
    let columns = PointColumns::new(points);
    // Kernel k's K_NZ in column-major order with column stride c · n (column j of every kernel together).
    if !opts.refine {
        let knz = kernel_columns(&bank, &columns, points, &z, |v| v);
        return (0..c)
            .zip(traces)
            .map(|(k, trace)| {
                let view = MatRef::from_column_major_slice_with_stride(&knz[k * n..], n, m, c * n);
                plain_nystrom(view, &z, opts.tolerance, max_ranks[k], trace)
            })
            .collect();
    }
    let knz = kernel_columns(&bank, &columns, points, &z, |v| v as f32);
    log::debug!("nystrom: N={n} m={m} classes={c}: K_NZ ({:.2?})", t0.elapsed());
    let knz_of = |k: usize| MatRef::from_column_major_slice_with_stride(&knz[k * n..], n, m, c * n);
    // Twice the rank (Rayleigh–Ritz needs room to converge) and 20 more, at most the sample.
    let dim_for = |rank: usize| m.min(rank.saturating_mul(2).saturating_add(20));
    let bases: Vec<Mat<f64>> = bounds
        .iter()
        .enumerate()
        .map(|(k, &bound)| {
            let dim = dim_for(bound);
            let kzz = Mat::from_fn(m, m, |a, b| knz_of(k)[(z[a], b)]);
            let u = range_basis(kzz.as_ref(), dim, opts.seed ^ (k as u64));
            let y = knz_of(k) * &u;
            let mut y = Mat::from_fn(n, dim, |i, j| f64::from(y[(i, j)]));
            for j in 0..dim {
                let norm = y.col(j).norm_l2();
                if norm > 0.0 {
                    y.col_mut(j).iter_mut().for_each(|v| *v /= norm);
                }
            }
            y
        })
        .collect();
    drop(knz);
    log::debug!("nystrom: subspaces ({:.2?})", t0.elapsed());
    let refined = rayleigh_ritz_bank(&bank, &columns, points, &bases, &bounds);
    log::debug!("nystrom: rayleigh-ritz ({:.2?})", t0.elapsed());
    refined
        .into_iter()
        .zip(traces)
        .map(|(e, trace)| e.map_or_else(|| empty(trace), |(values, vectors)| ScalarEigen { values, vectors, trace }))
        .collect()
}

/// Every kernel of `bank` between all points and the points `z`, converted by `cast`: column `j`
/// holds one column of length `N` per kernel, one after the other (so kernel `k`'s `N × |z|`
/// matrix starts at `k · N` with column stride `kernels · N`).
fn kernel_columns<T: Copy + Default + Send>(
    bank: &KernelBank,
    columns: &PointColumns,
    points: &[KernelPoint],
    z: &[usize],
    cast: impl Fn(f64) -> T + Sync,
) -> Vec<T> {
    let n = points.len();
    let stride = bank.len() * n;
    let mut data = vec![T::default(); stride * z.len()];
    data.par_chunks_mut(stride.max(1)).zip(z.par_iter()).for_each_init(
        || vec![0.0; stride],
        |values, (out, &j)| {
            bank.eval_column(columns, 0..n, &points[j], values);
            for (o, v) in out.iter_mut().zip(values.iter()) {
                *o = cast(*v);
            }
        },
    );
    data
}

/// Power iterations of [`range_basis`].
const POWER_ITERATIONS: usize = 3;

/// An orthonormal basis (`m × dim`) of the leading subspace of the symmetric positive
/// semi-definite `a`, by a randomized range finder with [`POWER_ITERATIONS`] power iterations
/// (Halko, Martinsson & Tropp 2011): `a` times a Gaussian block, re-orthonormalized after each
/// product. `O(m² · dim)` instead of the full decomposition's `O(m³)`.
fn range_basis(a: MatRef<'_, f32>, dim: usize, seed: u64) -> Mat<f32> {
    use rand_distr::{Distribution, StandardNormal};
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let omega = Mat::from_fn(a.nrows(), dim, |_, _| {
        let v: f64 = StandardNormal.sample(&mut rng);
        v as f32
    });
    let mut q = (a * &omega).qr().compute_thin_Q();
    for _ in 0..POWER_ITERATIONS {
        q = (a * &q).qr().compute_thin_Q();
    }
    q
}

/// Points of the estimate of [`bank_nystrom`]'s split (the first of the farthest-point sample).
const ESTIMATE_POINTS: usize = 300;

/// How many pairs each kernel needs for the `count` largest components (kernel `k`'s value `i`
/// counted `directions[k]` times), judged from estimated values (descending per kernel), with a
/// quarter and 10 pairs more as a margin; at most `max_ranks[k]`. A kernel keeps its
/// `max_ranks[k]` if the estimate cannot tell: too few values in all, or more than half of its
/// own needed.
fn split_bounds(count: usize, directions: &[usize], values: &[Vec<f64>], max_ranks: &[usize]) -> Vec<usize> {
    if values.iter().zip(directions).map(|(v, d)| v.len() * d).sum::<usize>() <= count {
        return max_ranks.to_vec();
    }
    let mut merged: Vec<(f64, usize)> =
        values.iter().enumerate().flat_map(|(k, v)| v.iter().flat_map(move |&x| std::iter::repeat_n((x, k), directions[k]))).collect();
    merged.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    let mut components = vec![0usize; values.len()];
    for &(_, k) in merged.iter().take(count) {
        components[k] += 1;
    }
    (0..values.len())
        .map(|k| {
            let pairs = components[k].div_ceil(directions[k].max(1));
            if 2 * pairs > values[k].len() {
                return max_ranks[k];
            }
            max_ranks[k].min(pairs + pairs / 4 + 10)
        })
        .collect()
}

/// Plain Nyström: `K̃ = B Bᵀ` with `B = K_NZ U Λ^{-1/2}` (`K_ZZ = U Λ Uᵀ`, eigenvalues below
/// `tolerance · λ_max` dropped); eigenpairs of `K̃` from `Bᵀ B = V S Vᵀ`.
fn plain_nystrom(knz: MatRef<'_, f64>, z: &[usize], tolerance: f64, max_rank: usize, trace: f64) -> ScalarEigen {
    let empty = || ScalarEigen { values: Vec::new(), vectors: Mat::zeros(knz.nrows(), 0), trace };
    let m = z.len();
    let kzz = Mat::from_fn(m, m, |a, b| knz[(z[a], b)]);
    let Ok(eig) = kzz.self_adjoint_eigen(Side::Lower) else {
        return empty();
    };
    let lambda = eig.S().column_vector();
    let u = eig.U();
    let lmax = (0..m).map(|i| lambda[i]).fold(0.0f64, f64::max);
    let keep: Vec<usize> = (0..m).rev().filter(|&i| lambda[i] > tolerance * lmax && lambda[i] > 0.0).collect();
    if keep.is_empty() {
        return empty();
    }
    let w = Mat::from_fn(m, keep.len(), |r, c| u[(r, keep[c])] / lambda[keep[c]].sqrt());
    let b = knz * &w;
    let c = b.transpose() * &b;
    let Ok(eig_c) = c.self_adjoint_eigen(Side::Lower) else {
        return empty();
    };
    let s = eig_c.S().column_vector();
    let v = eig_c.U();
    let r = keep.len();
    let smax = (0..r).map(|i| s[i]).fold(0.0f64, f64::max);
    let top: Vec<usize> = (0..r).rev().filter(|&i| s[i] > 1e-14 * smax && s[i] > 0.0).take(max_rank).collect();
    let vt = Mat::from_fn(r, top.len(), |row, col| v[(row, top[col])] / s[top[col]].sqrt());
    ScalarEigen { values: top.iter().map(|&i| s[i]).collect(), vectors: &b * &vt, trace }
}

/// Rows of the kernel matrix per Rayleigh–Ritz block.
const BLOCK: usize = 128;

/// Groups the block rows of [`rayleigh_ritz_bank`] are summed in (at most as many workers).
const SUM_GROUPS: usize = 8;

/// Tasks faer splits a product or a decomposition into, whatever the cores: its default follows
/// the thread count, and its sums then fall in another order, so a model built on 8 cores had
/// other bits than one built on 2.
const FAER_TASKS: usize = 4;

/// Gram eigenvalues below this fraction of the largest are dropped from a Rayleigh–Ritz basis
/// (directions the basis does not resolve to better than about 1e-7).
const GRAM_TOLERANCE: f64 = 1e-9;

/// Rayleigh–Ritz refinement of subspaces `span(Y_c)` (`N x k_c`, unit columns) against the exact
/// kernel matrices `K_c` of a bank: eigenvalues (descending, at most `max_ranks[c]`) and orthonormal
/// Ritz vectors, or `None` when the subspace is empty.
///
/// Nyström's `K̃ = K_NZ K_ZZ⁺ K_ZN` is below `K` (it underestimates every eigenvalue, most for
/// short-range terms the sample cannot resolve). Projecting the exact `K` onto the Nyström
/// subspace and diagonalizing gives the best eigenpairs within it (Ritz values are lower bounds
/// that converge fast). `H = Yᵀ K Y` is accumulated with `K` streamed in row blocks, only its
/// upper block triangle evaluated: `H = S + Sᵀ` with `S = Σ_i Y_iᵀ (½ K_ii Y_i + Σ_{j>i} K_ij Y_j)`
/// (one product per block row), every kernel evaluation shared by all classes of the bank. `Y` is
/// made orthonormal through its Gram matrix (`G = YᵀY = V S Vᵀ`, basis `Y V S^{-1/2}`), which the
/// unit columns keep well conditioned; then `(V S^{-1/2})ᵀ H (V S^{-1/2})` is diagonalized.
fn rayleigh_ritz_bank(
    bank: &KernelBank,
    columns: &PointColumns,
    points: &[KernelPoint],
    ys: &[Mat<f64>],
    max_ranks: &[usize],
) -> Vec<Option<(Vec<f64>, Mat<f64>)>> {
    let n = points.len();
    let c = bank.len();
    let starts: Vec<usize> = (0..n).step_by(BLOCK).collect();
    let zeros = || ys.iter().map(|y| Mat::<f64>::zeros(y.ncols(), y.ncols())).collect::<Vec<_>>();
    // The block rows in a fixed number of contiguous groups, each summed in order by one worker
    // and the groups' sums added in order: the same bits whatever the threads (a work-stealing
    // fold would add the partial sums in an order that depends on the scheduling).
    let group_len = starts.len().div_ceil(SUM_GROUPS).max(1);
    let partial: Vec<Vec<Mat<f64>>> = starts
        .par_chunks(group_len)
        .map(|group| {
            let (mut acc, mut t) = (zeros(), Vec::new());
            for &start in group {
                let rows = BLOCK.min(n - start);
                let len = n - start;
                // Row r of the block against points start..n, every kernel: the block's transpose
                // (in a buffer each worker reuses).
                t.resize(rows * c * len, 0.0);
                for (r, out) in t.chunks_mut(c * len).enumerate() {
                    bank.eval_column(columns, start..n, &points[start + r], out);
                }
                // Halve the diagonal block: then S = Σ_i Y_iᵀ [½K_ii K_i,>i] Y_≥i gives H = S + Sᵀ.
                for out in t.chunks_mut(c * len) {
                    for k in 0..c {
                        out[k * len..][..rows].iter_mut().for_each(|v| *v *= 0.5);
                    }
                }
                for (k, (sk, y)) in acc.iter_mut().zip(ys).enumerate() {
                    let tk = MatRef::from_column_major_slice_with_stride(&t[k * len..], len, rows, c * len);
                    let p = tk.transpose() * y.subrows(start, len);
                    *sk += y.subrows(start, rows).transpose() * &p;
                }
            }
            acc
        })
        .collect();
    let h = partial.into_iter().fold(zeros(), |mut a, b| {
        for (x, y) in a.iter_mut().zip(b) {
            *x += y;
        }
        a
    });
    ys.iter()
        .zip(h)
        .zip(max_ranks)
        .map(|((y, half), &max_rank)| {
            let h = &half + half.transpose();
            let k = y.ncols();
            let gram = y.transpose() * y;
            let ge = gram.self_adjoint_eigen(Side::Lower).ok()?;
            let s = ge.S().column_vector();
            let v = ge.U();
            let smax = (0..k).map(|i| s[i]).fold(0.0f64, f64::max);
            let keep: Vec<usize> = (0..k).filter(|&i| s[i] > GRAM_TOLERANCE * smax && s[i] > 0.0).collect();
            if keep.is_empty() {
                return None;
            }
            let b = Mat::from_fn(k, keep.len(), |r, c| v[(r, keep[c])] / s[keep[c]].sqrt());
            let projected = b.transpose() * (h * &b);
            let r = keep.len();
            let hs = Mat::from_fn(r, r, |i, j| 0.5 * (projected[(i, j)] + projected[(j, i)]));
            let eig = hs.self_adjoint_eigen(Side::Lower).ok()?;
            let theta = eig.S().column_vector();
            let w = eig.U();
            let order: Vec<usize> = (0..r).rev().filter(|&i| theta[i] > 0.0).take(max_rank).collect();
            let wt = Mat::from_fn(r, order.len(), |row, col| w[(row, order[col])]);
            Some((order.iter().map(|&i| theta[i]).collect(), y * (&b * &wt)))
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
    // A pair of a class with d directions gives d components: with a count of k, pairs beyond
    // the first ceil(k / d) can never be kept (the candidates sort by value, then pair index).
    let max_ranks: Vec<usize> = classes
        .iter()
        .map(|class| match rank {
            RankSpec::Count(k) => k.div_ceil(class.directions.len().max(1)),
            RankSpec::Captured(_) => usize::MAX,
        })
        .collect();
    let mut candidates: Vec<(f64, usize, usize, usize)> = Vec::new(); // (value, class, pair, direction)
    let kernels: Vec<ScalarKernel> = classes.iter().map(|c| c.kernel.clone()).collect();
    progress(0, 1);
    let directions: Vec<usize> = classes.iter().map(|c| c.directions.len()).collect();
    let split = match rank {
        RankSpec::Count(k) => Some((k, directions.as_slice())),
        RankSpec::Captured(_) => None,
    };
    let eigens = bank_nystrom(&kernels, points, opts, &max_ranks, split);
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
    let per_class: Vec<usize> = (0..classes.len()).map(|ci| candidates[..keep].iter().filter(|c| c.1 == ci).count()).collect();
    log::debug!("low rank: components kept per class {per_class:?}");
    let lr = LowRank { components, trace };
    log::debug!("low rank: {keep} components, captured {:.6}", lr.captured());
    lr
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

    #[test]
    fn a_low_rank_model_has_the_same_bits_whatever_the_threads() {
        // Enough points for several block rows in several groups of the refinement's sum.
        let pts = grid(1200);
        let hp = Hyperparameters::default();
        let k = ModelKernel::SymmetricFull.shape_kernel(&hp);
        let opts = NystromOptions { points: 300, ..Default::default() };
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("thread pool");
            pool.install(|| low_rank(&k, &pts, RankSpec::Count(20), &opts, |_, _| {}))
        };
        let bits = |lr: &LowRank| -> Vec<u64> {
            lr.components.iter().flat_map(|c| std::iter::once(c.eigenvalue.to_bits()).chain(c.field.iter().map(|v| v.to_bits()))).collect()
        };
        let one = bits(&run(1));
        assert!(one.len() > 20 * 1200, "{} values", one.len());
        for threads in [2, 3, 8] {
            assert!(bits(&run(threads)) == one, "{threads} threads give other bits than one");
        }
    }
}
