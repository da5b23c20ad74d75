//! The penalty of per-vertex offsets against a model part's subspace: their distance from it and
//! the prior on their projection into it.
//!
//! For a part with scaled basis `B` (`3N × K`, columns scaled by √eigenvalue, so that coefficients
//! are standard normal) and offsets `D`, the projection's coefficients are `α = G⁻¹ Bᵀ D` with the
//! Gram matrix `G = Bᵀ B` (the columns need not be orthogonal: a Nyström basis is only nearly so),
//! and the penalty is
//!
//! `P(D) = λ |D − B α|² + |α|²  =  λ |D|² + yᵀ Q y`,  `y = Bᵀ D`, `Q = G⁻² − λ G⁻¹`,
//!
//! (`|D − Bα|² = |D|² − yᵀ G⁻¹ y`, `|α|² = yᵀ G⁻² y`), so `∇P = 2 λ D + 2 B (Q y)`: a step costs two
//! products with `B` and one with the `K × K` matrix `Q`, prepared once per model.

use crate::gp::model::{ModelPart, PartBasis};

/// One model part's leading components, dense, with the matrix `Q` of the penalty.
#[derive(Debug, Clone)]
pub struct Subspace {
    /// Vertices.
    vertices: usize,
    /// Components used.
    rank: usize,
    /// `rank × vertices × 3`, component-major.
    basis: Vec<f32>,
    /// `rank × rank`, row-major: `G⁻² − λ G⁻¹`.
    q: Vec<f64>,
    /// `λ = 1 / σ²` of the distance from the subspace.
    lambda: f64,
}

/// Why a subspace could not be prepared.
#[derive(Debug, thiserror::Error)]
pub enum SubspaceError {
    /// The Gram matrix of the basis is singular (components linearly dependent).
    #[error("the model's {part} basis has linearly dependent components (its Gram matrix is singular)")]
    Singular {
        /// Shape or colour.
        part: &'static str,
    },
    /// The basis arrays do not match the part's size.
    #[error("the model's {part} basis does not match its {vertices} vertices")]
    Size {
        /// Shape or colour.
        part: &'static str,
        /// Vertices of the part.
        vertices: usize,
    },
}

impl Subspace {
    /// The first `rank` components of `part` (fewer if it has fewer) and the distance penalty
    /// `1 / sigma²` (`sigma` in the part's units).
    pub fn new(part: &ModelPart, rank: usize, sigma: f32, name: &'static str) -> Result<Self, SubspaceError> {
        let n = part.mean.len();
        let rank = rank.min(part.rank());
        let mut basis = vec![0.0f32; rank * n * 3];
        match &part.basis {
            PartBasis::Factored { directions, fields } => {
                if fields.len() < rank * n || directions.len() < rank {
                    return Err(SubspaceError::Size { part: name, vertices: n });
                }
                for k in 0..rank {
                    let d = directions[k];
                    for v in 0..n {
                        let f = fields[k * n + v];
                        basis[(k * n + v) * 3..(k * n + v) * 3 + 3].copy_from_slice(&[f * d[0], f * d[1], f * d[2]]);
                    }
                }
            }
            PartBasis::Dense { values } => {
                let len = rank * n * 3;
                basis.copy_from_slice(values.get(..len).ok_or(SubspaceError::Size { part: name, vertices: n })?);
            }
        }
        let len = n * 3;
        let mut gram = vec![0.0f64; rank * rank];
        for i in 0..rank {
            let bi = &basis[i * len..(i + 1) * len];
            for j in 0..=i {
                let bj = &basis[j * len..(j + 1) * len];
                let s: f64 = bi.iter().zip(bj).map(|(a, b)| f64::from(*a) * f64::from(*b)).sum();
                gram[i * rank + j] = s;
                gram[j * rank + i] = s;
            }
        }
        let inverse = invert_spd(&gram, rank).ok_or(SubspaceError::Singular { part: name })?;
        let lambda = 1.0 / f64::from(sigma * sigma);
        let mut q = vec![0.0f64; rank * rank];
        for i in 0..rank {
            for j in 0..rank {
                let square: f64 = (0..rank).map(|l| inverse[i * rank + l] * inverse[l * rank + j]).sum();
                q[i * rank + j] = square - lambda * inverse[i * rank + j];
            }
        }
        Ok(Self { vertices: n, rank, basis, q, lambda })
    }

    /// Components used.
    pub fn rank(&self) -> usize {
        self.rank
    }

    /// Vertices.
    pub fn vertices(&self) -> usize {
        self.vertices
    }

    /// Component `k` at vertex `v`.
    pub fn component(&self, k: usize, v: usize) -> [f32; 3] {
        let i = (k * self.vertices + v) * 3;
        [self.basis[i], self.basis[i + 1], self.basis[i + 2]]
    }

    /// The distance weight `λ`.
    pub fn lambda(&self) -> f64 {
        self.lambda
    }

    /// `y = Bᵀ D` for offsets `D = Σ_v` (`offset(v)` at vertex `v`).
    pub fn project(&self, offset: impl Fn(usize) -> [f32; 3]) -> Vec<f64> {
        let mut y = vec![0.0f64; self.rank];
        for v in 0..self.vertices {
            let d = offset(v);
            if d == [0.0; 3] {
                continue;
            }
            for (k, yk) in y.iter_mut().enumerate() {
                let b = self.component(k, v);
                *yk += f64::from(b[0] * d[0] + b[1] * d[1] + b[2] * d[2]);
            }
        }
        y
    }

    /// `(yᵀ Q y, Q y)` of the projection `y`: the subspace part of the penalty and what its
    /// gradient needs (`2 B (Q y)`, added by the caller with [`Subspace::component`]).
    pub fn quadratic(&self, y: &[f64]) -> (f64, Vec<f64>) {
        let qy: Vec<f64> = (0..self.rank).map(|i| (0..self.rank).map(|j| self.q[i * self.rank + j] * y[j]).sum()).collect();
        let value = y.iter().zip(&qy).map(|(a, b)| a * b).sum();
        (value, qy)
    }
}

/// The inverse of the symmetric positive definite `n × n` matrix `a` (row-major), by Cholesky;
/// `None` if it is not positive definite.
fn invert_spd(a: &[f64], n: usize) -> Option<Vec<f64>> {
    let mut l = vec![0.0f64; n * n];
    for i in 0..n {
        for j in 0..=i {
            let s: f64 = a[i * n + j] - (0..j).map(|k| l[i * n + k] * l[j * n + k]).sum::<f64>();
            if i == j {
                if s.is_nan() || s <= 1e-12 * a[i * n + i].abs().max(1e-300) {
                    return None;
                }
                l[i * n + i] = s.sqrt();
            } else {
                l[i * n + j] = s / l[j * n + j];
            }
        }
    }
    let mut inverse = vec![0.0f64; n * n];
    let mut column = vec![0.0f64; n];
    for c in 0..n {
        // L z = e_c, then Lᵀ x = z.
        for i in 0..n {
            let rhs = if i == c { 1.0 } else { 0.0 };
            column[i] = (rhs - (0..i).map(|k| l[i * n + k] * column[k]).sum::<f64>()) / l[i * n + i];
        }
        for i in (0..n).rev() {
            column[i] = (column[i] - (i + 1..n).map(|k| l[k * n + i] * column[k]).sum::<f64>()) / l[i * n + i];
        }
        for i in 0..n {
            inverse[i * n + c] = column[i];
        }
    }
    Some(inverse)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// Two vertices, two non-orthogonal components: an offset inside the span costs only its
    /// prior, one orthogonal to it only its distance.
    #[test]
    fn penalty_splits_into_distance_and_prior() {
        let part = ModelPart {
            mean: vec![[0.0; 3]; 2],
            eigenvalues: vec![1.0, 1.0],
            basis: PartBasis::Dense { values: vec![1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0] },
        };
        let s = Subspace::new(&part, 2, 0.5, "shape").unwrap();
        let penalty = |d: [[f32; 3]; 2]| {
            let y = s.project(|v| d[v]);
            let norm: f64 = d.iter().flatten().map(|x| f64::from(x * x)).sum();
            s.lambda() * norm + s.quadratic(&y).0
        };
        // 2 × (1, 1, 0) at vertex 0 is coefficients (0, 2): prior 4, no distance.
        assert!((penalty([[2.0, 2.0, 0.0], [0.0; 3]]) - 4.0).abs() < 1e-9);
        // (0, 0, 1) at vertex 1 is outside the span: distance 1 / 0.25.
        assert!((penalty([[0.0; 3], [0.0, 0.0, 1.0]]) - 4.0).abs() < 1e-9);
        let inv = invert_spd(&[4.0, 2.0, 2.0, 3.0], 2).unwrap();
        assert!((inv[0] - 0.375).abs() < 1e-12 && (inv[1] + 0.25).abs() < 1e-12 && (inv[3] - 0.5).abs() < 1e-12);
        assert!(invert_spd(&[1.0, 1.0, 1.0, 1.0], 2).is_none());
    }
}
