//! 3D-to-3D registration of a model to a mesh (`gpmm register`): the paper's registration task and
//! the fit behind the generalization measure of `gpmm eval specgen`.
//!
//! The model instance `x(α) = μ + B α` (first `shape_rank` components, prior α ~ N(0, I)) is brought
//! onto the target surface by iterated closest points with the model's prior as regularizer:
//!
//! 1. **Initial alignment**: when the model and the target both have 68 iBUG landmarks, the
//!    least-squares rigid transform (rotation and translation, no scale: size is part of identity)
//!    of the mean's non-jaw landmarks (17-67; the jaw points are silhouette-dependent) onto the
//!    target's; otherwise the centroids are aligned.
//! 2. **Iterate** ([`RegisterOptions::iterations`] times):
//!    - correspondences: for every model vertex, the closest point on the target surface (the
//!      nearest target vertex, then the closest point on the triangles around it). A
//!      correspondence is rejected when that nearest vertex lies on the target's border (the model
//!      reaches past the target there) or when it is further than max(5 mm, 3 × the median distance);
//!    - pose: the rigid transform that best maps the current instance onto the accepted points;
//!    - shape: the posterior mean (MAP) of α given the accepted points with isotropic noise σ, plus
//!      the landmark pairs weighted ×w: `(Bᵀ W B / σ² + I) α = Bᵀ W (y − μ) / σ²`. σ falls
//!      geometrically from [`RegisterOptions::sigma_start_mm`] to [`RegisterOptions::sigma_end_mm`]
//!      (coarse to fine) and w from [`RegisterOptions::landmark_weight`] to 1 (it stays 0 when that
//!      is 0: the landmarks then only give the initial alignment).
//! 3. **Colour**: the target's colours at the final closest points (interpolated barycentrically)
//!    give the colour coefficients the same way (noise [`RegisterOptions::color_sigma`]).
//!
//! The residual is the distance from each model vertex of the result to its closest target point,
//! over the vertices whose closest target vertex is not on the border (no distance cut); the colour
//! residual is the Euclidean RGB distance between the fitted albedo and the target's colour there.

use crate::gp::model::{GpModel, ModelPart, PartBasis};
use crate::mesh::closest::{closest_on_triangle, Grid};
use crate::mesh::geometry::{add, centroid, dist2, mul, sub};
use crate::mesh::Mesh;
use faer::linalg::solvers::Solve;
use faer::Mat;
use serde::{Deserialize, Serialize};

/// Why a registration failed.
#[derive(Debug, thiserror::Error)]
pub enum RegisterError {
    /// The inputs cannot be registered.
    #[error("{0}")]
    Invalid(String),
    /// A linear solve failed (should not happen: the systems are positive definite).
    #[error("numerical failure: {0}")]
    Numerical(String),
}

/// Settings of [`register`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RegisterOptions {
    /// Shape components used (the leading ones; capped by the model's rank).
    pub shape_rank: usize,
    /// Colour components used.
    pub color_rank: usize,
    /// Closest-point iterations.
    pub iterations: usize,
    /// Noise σ of the first iteration (mm).
    pub sigma_start_mm: f64,
    /// Noise σ of the last iteration (mm).
    pub sigma_end_mm: f64,
    /// Weight of each landmark pair at the start (falls to 1, or stays 0 when 0: the landmarks then
    /// only give the initial rigid alignment).
    pub landmark_weight: f64,
    /// Noise σ of the colour fit (colours in \[0, 1\]).
    pub color_sigma: f64,
}

impl Default for RegisterOptions {
    fn default() -> Self {
        Self {
            shape_rank: usize::MAX,
            color_rank: usize::MAX,
            iterations: 20,
            sigma_start_mm: 8.0,
            sigma_end_mm: 1.0,
            landmark_weight: 20.0,
            color_sigma: 0.02,
        }
    }
}

impl RegisterOptions {
    /// Checks the ranges.
    pub fn validate(&self) -> Result<(), RegisterError> {
        let pos = |v: f64| v.is_finite() && v > 0.0;
        if !(pos(self.sigma_start_mm)
            && pos(self.sigma_end_mm)
            && pos(self.color_sigma)
            && self.landmark_weight.is_finite()
            && self.landmark_weight >= 0.0)
        {
            return Err(RegisterError::Invalid("the noise levels must be positive and the landmark weight finite and not negative".into()));
        }
        if self.iterations == 0 || self.iterations > 1000 {
            return Err(RegisterError::Invalid(format!("{} iterations: need 1 to 1000", self.iterations)));
        }
        Ok(())
    }
}

/// A target mesh indexed for closest-point queries.
pub struct PreparedTarget {
    mesh: Mesh,
    landmarks: Option<Vec<u32>>,
    grid: Grid,
    incident: Vec<Vec<u32>>,
    border: Vec<bool>,
}

impl PreparedTarget {
    /// Indexes `mesh` (mm); `landmarks` are its iBUG-68 vertex ids, if known.
    pub fn new(mesh: Mesh, landmarks: Option<Vec<u32>>) -> Result<Self, RegisterError> {
        let n = mesh.positions.len();
        if n < 3 || mesh.triangles.is_empty() || mesh.colors.len() != n {
            return Err(RegisterError::Invalid("the target needs vertices, colours and triangles".into()));
        }
        if mesh.triangles.iter().flatten().any(|&i| i as usize >= n) {
            return Err(RegisterError::Invalid("a target triangle refers to a missing vertex".into()));
        }
        if let Some(lm) = &landmarks {
            if let Some(bad) = lm.iter().find(|&&i| i as usize >= n) {
                return Err(RegisterError::Invalid(format!("target landmark vertex {bad} does not exist ({n} vertices)")));
            }
        }
        let mut incident: Vec<Vec<u32>> = vec![Vec::new(); n];
        let mut edges: std::collections::HashMap<(u32, u32), u32> = std::collections::HashMap::new();
        for (k, t) in mesh.triangles.iter().enumerate() {
            for j in 0..3 {
                incident[t[j] as usize].push(k as u32);
                let (a, b) = (t[j], t[(j + 1) % 3]);
                *edges.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
        let mut border = vec![false; n];
        for (&(a, b), &c) in &edges {
            if c == 1 {
                border[a as usize] = true;
                border[b as usize] = true;
            }
        }
        let grid = Grid::new(&mesh.positions, 4.0);
        Ok(Self { mesh, landmarks, grid, incident, border })
    }

    /// The mesh.
    pub fn mesh(&self) -> &Mesh {
        &self.mesh
    }

    /// The closest surface point to `q`: (point, colour, whether its nearest vertex is on the border).
    pub fn closest(&self, q: [f64; 3]) -> ([f64; 3], [f64; 3], bool) {
        let Some(v) = self.grid.nearest(&self.mesh.positions, q) else {
            return (q, [0.0; 3], true);
        };
        let mut best = (dist2(self.mesh.positions[v], q), self.mesh.positions[v], [v as u32; 3], [1.0, 0.0, 0.0]);
        for &k in &self.incident[v] {
            let t = self.mesh.triangles[k as usize];
            let (p, bary) = closest_on_triangle(q, t.map(|i| self.mesh.positions[i as usize]));
            let d = dist2(p, q);
            if d < best.0 {
                best = (d, p, t, bary);
            }
        }
        let (_, p, t, b) = best;
        let c = t.map(|i| self.mesh.colors[i as usize]);
        let color = std::array::from_fn(|ch| b[0] * c[0][ch] + b[1] * c[1][ch] + b[2] * c[2][ch]);
        (p, color, self.border[v])
    }
}

/// A rigid transform `p ↦ R p + t`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Rigid {
    /// Rotation (rows).
    pub rotation: [[f64; 3]; 3],
    /// Translation.
    pub translation: [f64; 3],
}

impl Rigid {
    /// The identity.
    pub const IDENTITY: Rigid = Rigid { rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], translation: [0.0; 3] };

    /// `R p + t`.
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let r = &self.rotation;
        add(r.map(|row| row[0] * p[0] + row[1] * p[1] + row[2] * p[2]), self.translation)
    }

    /// `Rᵀ (p − t)`.
    pub fn apply_inverse(&self, p: [f64; 3]) -> [f64; 3] {
        let d = sub(p, self.translation);
        let r = &self.rotation;
        [0, 1, 2].map(|j| r[0][j] * d[0] + r[1][j] * d[1] + r[2][j] * d[2])
    }

    /// The weighted least-squares rigid transform mapping `src` onto `dst` (Kabsch; `None` if degenerate).
    pub fn fit(src: &[[f64; 3]], dst: &[[f64; 3]], weights: &[f64]) -> Option<Rigid> {
        let wsum: f64 = weights.iter().sum();
        if src.len() != dst.len() || src.len() != weights.len() || src.len() < 3 || wsum.is_nan() || wsum <= 0.0 {
            return None;
        }
        let mean = |v: &[[f64; 3]]| v.iter().zip(weights).fold([0.0; 3], |acc, (p, w)| add(acc, mul(*p, w / wsum)));
        let (cs, cd) = (mean(src), mean(dst));
        let mut h = Mat::<f64>::zeros(3, 3);
        for ((a, b), w) in src.iter().zip(dst).zip(weights) {
            let (a, b) = (sub(*a, cs), sub(*b, cd));
            for i in 0..3 {
                for j in 0..3 {
                    h[(i, j)] += w * a[i] * b[j];
                }
            }
        }
        let svd = h.svd().ok()?;
        let (u, v) = (svd.U(), svd.V());
        // R = V diag(1, 1, d) Uᵀ with d = sign(det(V Uᵀ)).
        let vut = v * u.transpose();
        let det = vut[(0, 0)] * (vut[(1, 1)] * vut[(2, 2)] - vut[(1, 2)] * vut[(2, 1)])
            - vut[(0, 1)] * (vut[(1, 0)] * vut[(2, 2)] - vut[(1, 2)] * vut[(2, 0)])
            + vut[(0, 2)] * (vut[(1, 0)] * vut[(2, 1)] - vut[(1, 1)] * vut[(2, 0)]);
        let d = if det < 0.0 { -1.0 } else { 1.0 };
        let mut rotation = [[0.0; 3]; 3];
        for (i, row) in rotation.iter_mut().enumerate() {
            for (j, r) in row.iter_mut().enumerate() {
                *r = (0..3).map(|k| v[(i, k)] * if k == 2 { d } else { 1.0 } * u[(j, k)]).sum();
            }
        }
        if rotation.iter().flatten().any(|x| !x.is_finite()) {
            return None;
        }
        let rc = Rigid { rotation, translation: [0.0; 3] }.apply(cs);
        Some(Rigid { rotation, translation: sub(cd, rc) })
    }
}

/// Distance statistics of a registration (mm, or RGB units for colour).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Residual {
    /// Mean distance.
    pub mean: f64,
    /// Median distance.
    pub median: f64,
    /// 90th percentile.
    pub p90: f64,
    /// Fraction of model vertices whose closest target point is not on the border (they count).
    pub covered_fraction: f64,
}

/// The result of [`register`].
#[derive(Debug, Clone)]
pub struct Registration {
    /// Shape coefficients (the leading components used).
    pub shape: Vec<f64>,
    /// Colour coefficients.
    pub color: Vec<f64>,
    /// The target's frame to the model's: `p_model = pose.apply(p_target)`.
    pub pose: Rigid,
    /// The registered instance (model topology, model frame).
    pub positions: Vec<[f64; 3]>,
    /// Its fitted albedo.
    pub colors: Vec<[f64; 3]>,
    /// Per model vertex, the closest target point (model frame): the target resampled on the model's topology.
    pub closest: Vec<[f64; 3]>,
    /// The target's colour at `closest`.
    pub closest_colors: Vec<[f64; 3]>,
    /// Whether each model vertex's closest target vertex is off the border (the vertex counts in the residuals).
    pub covered: Vec<bool>,
    /// Shape residual (mm).
    pub residual: Residual,
    /// Colour residual (Euclidean RGB distance).
    pub color_residual: Residual,
    /// Mean residual (mm) after each iteration.
    pub history: Vec<f64>,
}

/// The first `k` components of a part as a dense `3N × k` matrix (scaled by √eigenvalue).
pub fn basis_matrix(part: &ModelPart, k: usize) -> Mat<f64> {
    let n = part.mean.len();
    Mat::from_fn(3 * n, k.min(part.rank()), |r, j| basis_entry(part, r, j))
}

/// Row `r` (vertex `r / 3`, coordinate `r % 3`) of component `j` of a part's basis (scaled by
/// √eigenvalue): the entry of [`basis_matrix`] without building it.
pub fn basis_entry(part: &ModelPart, r: usize, j: usize) -> f64 {
    let n = part.mean.len();
    match &part.basis {
        PartBasis::Factored { directions, fields } => f64::from(fields[j * n + r / 3]) * f64::from(directions[j][r % 3]),
        PartBasis::Dense { values } => f64::from(values[j * n * 3 + r]),
    }
}

/// A posterior-mean solve: `(Σ w_i B_iᵀB_i / σ² + I) α = Σ w_i B_iᵀ (y_i − μ_i) / σ²` over the given vertices.
fn map_coefficients(basis: &Mat<f64>, mean: &[[f32; 3]], obs: &[(usize, [f64; 3], f64)], sigma: f64) -> Result<Vec<f64>, RegisterError> {
    let k = basis.ncols();
    if k == 0 || obs.is_empty() {
        return Ok(vec![0.0; k]);
    }
    let a = Mat::from_fn(3 * obs.len(), k, |r, j| {
        let (v, _, w) = obs[r / 3];
        w.sqrt() / sigma * basis[(3 * v + r % 3, j)]
    });
    let b = Mat::from_fn(3 * obs.len(), 1, |r, _| {
        let (v, y, w) = obs[r / 3];
        w.sqrt() / sigma * (y[r % 3] - f64::from(mean[v][r % 3]))
    });
    let mut n = a.transpose() * &a;
    for j in 0..k {
        n[(j, j)] += 1.0;
    }
    let rhs = a.transpose() * &b;
    let llt = n.llt(faer::Side::Lower).map_err(|e| RegisterError::Numerical(format!("Cholesky: {e:?}")))?;
    let x = llt.solve(&rhs);
    Ok((0..k).map(|j| x[(j, 0)]).collect())
}

/// `mean + basis · coeffs` per vertex (the basis as from [`basis_matrix`]).
pub fn basis_instance(basis: &Mat<f64>, mean: &[[f32; 3]], coeffs: &[f64]) -> Vec<[f64; 3]> {
    mean.iter()
        .enumerate()
        .map(|(v, m)| {
            std::array::from_fn(|c| f64::from(m[c]) + coeffs.iter().enumerate().map(|(j, a)| a * basis[(3 * v + c, j)]).sum::<f64>())
        })
        .collect()
}

fn quantile(sorted: &[f64], f: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let pos = f * (sorted.len() - 1) as f64;
    let (i, t) = (pos.floor() as usize, pos - pos.floor());
    let a = sorted[i];
    a + t * (sorted.get(i + 1).copied().unwrap_or(a) - a)
}

fn residual(d: &[f64], total: usize) -> Residual {
    let mut s: Vec<f64> = d.to_vec();
    s.sort_by(f64::total_cmp);
    let mean = if s.is_empty() { f64::NAN } else { s.iter().sum::<f64>() / s.len() as f64 };
    Residual { mean, median: quantile(&s, 0.5), p90: quantile(&s, 0.9), covered_fraction: s.len() as f64 / total.max(1) as f64 }
}

/// The model's and the target's landmark pairs used for alignment (non-jaw iBUG points), if both have 68.
fn landmark_pairs(model: &GpModel, target: &PreparedTarget) -> Vec<(usize, [f64; 3])> {
    match &target.landmarks {
        Some(t) if t.len() == 68 && model.landmarks.len() == 68 => {
            (17..68).map(|k| (model.landmarks[k] as usize, target.mesh.positions[t[k] as usize])).collect()
        }
        _ => Vec::new(),
    }
}

/// Registers `model` to `target` (see the module docs).
pub fn register(model: &GpModel, target: &PreparedTarget, opts: &RegisterOptions) -> Result<Registration, RegisterError> {
    opts.validate()?;
    let n = model.vertices();
    if n == 0 {
        return Err(RegisterError::Invalid("the model has no vertices".into()));
    }
    let bs = basis_matrix(&model.shape, opts.shape_rank);
    let bc = basis_matrix(&model.color, opts.color_rank);
    let mean = &model.shape.mean;
    let lms = landmark_pairs(model, target);

    // Initial alignment (target frame -> model frame).
    let mean64: Vec<[f64; 3]> = mean.iter().map(|p| p.map(f64::from)).collect();
    let mut pose = if lms.len() >= 3 {
        let src: Vec<[f64; 3]> = lms.iter().map(|l| l.1).collect();
        let dst: Vec<[f64; 3]> = lms.iter().map(|l| mean64[l.0]).collect();
        Rigid::fit(&src, &dst, &vec![1.0; src.len()]).ok_or_else(|| RegisterError::Invalid("the landmarks are degenerate".into()))?
    } else {
        let t = sub(centroid(mean64.iter().copied()), centroid(target.mesh.positions.iter().copied()));
        Rigid { translation: t, ..Rigid::IDENTITY }
    };

    let mut alpha = vec![0.0; bs.ncols()];
    let mut history = Vec::with_capacity(opts.iterations);
    let iters = opts.iterations;
    for it in 0..iters {
        let f = if iters > 1 { it as f64 / (iters - 1) as f64 } else { 1.0 };
        let sigma = opts.sigma_start_mm * (opts.sigma_end_mm / opts.sigma_start_mm).powf(f);
        let w_lm = opts.landmark_weight * (1.0 - f) + opts.landmark_weight.min(1.0) * f;
        let x = basis_instance(&bs, mean, &alpha);
        // Closest points (target frame), accepted if off the border and not far out.
        let hits: Vec<([f64; 3], bool)> = x
            .iter()
            .map(|p| {
                let (q, _, border) = target.closest(pose.apply_inverse(*p));
                (q, !border)
            })
            .collect();
        let mut d: Vec<f64> = x.iter().zip(&hits).filter(|(_, h)| h.1).map(|(p, h)| dist2(pose.apply(h.0), *p).sqrt()).collect();
        d.sort_by(f64::total_cmp);
        let cut = (3.0 * quantile(&d, 0.5)).max(5.0);
        let accepted: Vec<usize> = (0..n).filter(|&i| hits[i].1 && dist2(pose.apply(hits[i].0), x[i]).sqrt() <= cut).collect();
        if accepted.len() < 3 {
            return Err(RegisterError::Invalid(format!(
                "iteration {it}: only {} model vertices found the target surface; is the target in millimetres and in front of the model?",
                accepted.len()
            )));
        }
        // Pose: instance -> target points (weighted landmarks too), inverted into target -> model.
        let mut src: Vec<[f64; 3]> = accepted.iter().map(|&i| hits[i].0).collect();
        let mut dst: Vec<[f64; 3]> = accepted.iter().map(|&i| x[i]).collect();
        let mut w = vec![1.0; src.len()];
        for &(v, p) in &lms {
            src.push(p);
            dst.push(x[v]);
            w.push(w_lm);
        }
        if let Some(p) = Rigid::fit(&src, &dst, &w) {
            pose = p;
        }
        // Shape given the correspondences in the model frame.
        let mut obs: Vec<(usize, [f64; 3], f64)> = accepted.iter().map(|&i| (i, pose.apply(hits[i].0), 1.0)).collect();
        obs.extend(lms.iter().map(|&(v, p)| (v, pose.apply(p), w_lm)));
        alpha = map_coefficients(&bs, mean, &obs, sigma)?;
        let x = basis_instance(&bs, mean, &alpha);
        let dm: Vec<f64> = accepted.iter().map(|&i| dist2(pose.apply(hits[i].0), x[i]).sqrt()).collect();
        history.push(dm.iter().sum::<f64>() / dm.len().max(1) as f64);
    }

    // Final correspondences, residual and colour.
    let positions = basis_instance(&bs, mean, &alpha);
    let mut closest = Vec::with_capacity(n);
    let mut closest_colors = Vec::with_capacity(n);
    let mut covered = Vec::with_capacity(n);
    for p in &positions {
        let (q, c, border) = target.closest(pose.apply_inverse(*p));
        closest.push(pose.apply(q));
        closest_colors.push(c);
        covered.push(!border);
    }
    let d: Vec<f64> = (0..n).filter(|&i| covered[i]).map(|i| dist2(positions[i], closest[i]).sqrt()).collect();
    let obs: Vec<(usize, [f64; 3], f64)> = (0..n).filter(|&i| covered[i]).map(|i| (i, closest_colors[i], 1.0)).collect();
    let beta = map_coefficients(&bc, &model.color.mean, &obs, opts.color_sigma)?;
    let colors: Vec<[f64; 3]> = basis_instance(&bc, &model.color.mean, &beta).into_iter().map(|c| c.map(|v| v.clamp(0.0, 1.0))).collect();
    let dc: Vec<f64> = (0..n).filter(|&i| covered[i]).map(|i| dist2(colors[i], closest_colors[i]).sqrt()).collect();
    Ok(Registration {
        shape: alpha,
        color: beta,
        pose,
        residual: residual(&d, n),
        color_residual: residual(&dc, n),
        positions,
        colors,
        closest,
        closest_colors,
        covered,
        history,
    })
}

/// The content of `register.json` written by `gpmm register`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RegisterReport {
    /// Always `gpmm-register`.
    pub format: String,
    /// Model file as given.
    pub model: String,
    /// The model's kernel.
    pub model_kernel: String,
    /// Target mesh as given.
    pub target: String,
    /// Whether landmarks aligned the target first.
    pub landmarks_used: bool,
    /// Settings.
    pub options: RegisterOptions,
    /// Shape and colour components used.
    pub ranks: [usize; 2],
    /// Shape residual (mm): model vertex to the closest target point.
    pub residual_mm: Residual,
    /// Colour residual (Euclidean RGB distance in \[0, 1\] units).
    pub color_residual: Residual,
    /// The target-to-model rigid transform.
    pub pose: Rigid,
    /// Shape coefficients.
    pub shape: Vec<f64>,
    /// Colour coefficients.
    pub color: Vec<f64>,
    /// Mean residual (mm) after each iteration.
    pub history_mm: Vec<f64>,
    /// Seconds.
    pub seconds: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rigid_fit_recovers_a_rotation() {
        let (c, s) = (0.8f64, 0.6f64);
        let truth = Rigid { rotation: [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]], translation: [1.0, -2.0, 3.0] };
        let src: Vec<[f64; 3]> = (0..10).map(|i| [(i as f64).sin() * 5.0, (i as f64 * 0.7).cos() * 3.0, i as f64]).collect();
        let dst: Vec<[f64; 3]> = src.iter().map(|&p| truth.apply(p)).collect();
        let fit = Rigid::fit(&src, &dst, &[1.0; 10]).unwrap();
        for (a, b) in src.iter().zip(&dst) {
            assert!(dist2(fit.apply(*a), *b) < 1e-18);
            assert!(dist2(fit.apply_inverse(*b), *a) < 1e-18);
        }
    }

    #[test]
    fn map_coefficients_shrinks_toward_the_prior() {
        // One component moving vertex 0 along x by 2 mm per unit; the target is 4 mm away.
        let part = ModelPart { mean: vec![[0.0; 3]], eigenvalues: vec![4.0], basis: PartBasis::Dense { values: vec![2.0, 0.0, 0.0] } };
        let b = basis_matrix(&part, 1);
        let a = map_coefficients(&b, &part.mean, &[(0, [4.0, 0.0, 0.0], 1.0)], 1.0).unwrap();
        // (4/1 + 1) a = 2 * 4  ->  a = 1.6
        assert!((a[0] - 1.6).abs() < 1e-12);
        let a = map_coefficients(&b, &part.mean, &[(0, [4.0, 0.0, 0.0], 1.0)], 1e-3).unwrap();
        assert!((a[0] - 2.0).abs() < 1e-5);
    }
}
