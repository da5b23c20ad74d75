//! Low-rank linear models: `instance = mean + Σ_k c_k · b_k`.
//!
//! Two basis layouts exist (see DESIGN.md, "Low rank"):
//! - [`FactoredBasis`]: component `k` is a scalar per-vertex field `f_k`
//!   (already scaled by `sqrt(eigenvalue)`) times one fixed unit 3-vector `e_k`.
//!   Every Gaussian-process kernel of the paper factors this way, which costs
//!   `N` values per component instead of `3N`.
//! - [`DenseBasis`]: component `k` holds a full 3-vector per vertex (PCA of
//!   learned or registered data).

/// A 3-vector (position in mm, or linear RGB colour).
pub type Vec3 = [f32; 3];

/// Why a model operation was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ModelError {
    /// Slice lengths do not agree with the basis dimensions.
    LengthMismatch,
    /// More coefficients were given than the basis has components.
    TooManyCoefficients,
}

/// A factored basis: `fields` is `rank × vertices` row-major, `directions` has `rank` entries.
#[derive(Debug, Clone, Copy)]
pub struct FactoredBasis<'a> {
    fields: &'a [f32],
    directions: &'a [Vec3],
    vertices: usize,
}

impl<'a> FactoredBasis<'a> {
    /// Wraps borrowed data, checking that `fields.len() == directions.len() * vertices`.
    pub fn new(fields: &'a [f32], directions: &'a [Vec3], vertices: usize) -> Result<Self, ModelError> {
        if directions.len().checked_mul(vertices) != Some(fields.len()) {
            return Err(ModelError::LengthMismatch);
        }
        Ok(Self { fields, directions, vertices })
    }

    /// Number of components.
    pub fn rank(&self) -> usize {
        self.directions.len()
    }

    /// Number of vertices each component covers.
    pub fn vertices(&self) -> usize {
        self.vertices
    }

    /// Adds `Σ_k coeffs[k] · f_k ⊗ e_k` to `out` (one entry per vertex).
    ///
    /// Fewer coefficients than components means the rest are zero.
    pub fn add_instance(&self, coeffs: &[f32], out: &mut [Vec3]) -> Result<(), ModelError> {
        if out.len() != self.vertices {
            return Err(ModelError::LengthMismatch);
        }
        if coeffs.len() > self.rank() {
            return Err(ModelError::TooManyCoefficients);
        }
        if self.vertices == 0 {
            return Ok(());
        }
        for ((c, dir), field) in coeffs.iter().zip(self.directions).zip(self.fields.chunks_exact(self.vertices)) {
            if *c == 0.0 {
                continue;
            }
            let d = [c * dir[0], c * dir[1], c * dir[2]];
            for (o, f) in out.iter_mut().zip(field) {
                o[0] += d[0] * f;
                o[1] += d[1] * f;
                o[2] += d[2] * f;
            }
        }
        Ok(())
    }

    /// Adds `Σ_k coeffs[k] · f_k[vertex] · e_k` to `out`: one vertex of the instance (e.g. a landmark) alone.
    pub fn add_vertex(&self, coeffs: &[f32], vertex: usize, out: &mut Vec3) -> Result<(), ModelError> {
        if vertex >= self.vertices {
            return Err(ModelError::LengthMismatch);
        }
        if coeffs.len() > self.rank() {
            return Err(ModelError::TooManyCoefficients);
        }
        for (k, (c, dir)) in coeffs.iter().zip(self.directions).enumerate() {
            let f = self.fields.get(k * self.vertices + vertex).copied().unwrap_or(0.0) * c;
            out[0] += f * dir[0];
            out[1] += f * dir[1];
            out[2] += f * dir[2];
        }
        Ok(())
    }
}

/// A dense basis: `values` is `rank × vertices × 3` row-major.
#[derive(Debug, Clone, Copy)]
pub struct DenseBasis<'a> {
    values: &'a [f32],
    rank: usize,
    vertices: usize,
}

impl<'a> DenseBasis<'a> {
    /// Wraps borrowed data, checking that `values.len() == rank * vertices * 3`.
    pub fn new(values: &'a [f32], rank: usize, vertices: usize) -> Result<Self, ModelError> {
        let expected = rank.checked_mul(vertices).and_then(|n| n.checked_mul(3));
        if expected != Some(values.len()) {
            return Err(ModelError::LengthMismatch);
        }
        Ok(Self { values, rank, vertices })
    }

    /// Number of components.
    pub fn rank(&self) -> usize {
        self.rank
    }

    /// Number of vertices each component covers.
    pub fn vertices(&self) -> usize {
        self.vertices
    }

    /// Adds `Σ_k coeffs[k] · b_k[vertex]` to `out`: one vertex of the instance alone.
    pub fn add_vertex(&self, coeffs: &[f32], vertex: usize, out: &mut Vec3) -> Result<(), ModelError> {
        if vertex >= self.vertices {
            return Err(ModelError::LengthMismatch);
        }
        if coeffs.len() > self.rank {
            return Err(ModelError::TooManyCoefficients);
        }
        for (k, c) in coeffs.iter().enumerate() {
            let at = (k * self.vertices + vertex) * 3;
            if let Some([x, y, z]) = self.values.get(at..at + 3) {
                out[0] += c * x;
                out[1] += c * y;
                out[2] += c * z;
            }
        }
        Ok(())
    }

    /// Adds `Σ_k coeffs[k] · b_k` to `out` (one entry per vertex).
    pub fn add_instance(&self, coeffs: &[f32], out: &mut [Vec3]) -> Result<(), ModelError> {
        if out.len() != self.vertices {
            return Err(ModelError::LengthMismatch);
        }
        if coeffs.len() > self.rank {
            return Err(ModelError::TooManyCoefficients);
        }
        if self.vertices == 0 {
            return Ok(());
        }
        for (c, comp) in coeffs.iter().zip(self.values.chunks_exact(self.vertices * 3)) {
            if *c == 0.0 {
                continue;
            }
            for (o, b) in out.iter_mut().zip(comp.chunks_exact(3)) {
                if let [x, y, z] = b {
                    o[0] += c * x;
                    o[1] += c * y;
                    o[2] += c * z;
                }
            }
        }
        Ok(())
    }
}

/// Either basis layout.
#[derive(Debug, Clone, Copy)]
pub enum Basis<'a> {
    /// Scalar field times a fixed direction per component.
    Factored(FactoredBasis<'a>),
    /// Full 3-vector per vertex per component.
    Dense(DenseBasis<'a>),
}

impl Basis<'_> {
    /// Number of components.
    pub fn rank(&self) -> usize {
        match self {
            Basis::Factored(b) => b.rank(),
            Basis::Dense(b) => b.rank(),
        }
    }

    /// Number of vertices each component covers.
    pub fn vertices(&self) -> usize {
        match self {
            Basis::Factored(b) => b.vertices(),
            Basis::Dense(b) => b.vertices(),
        }
    }

    /// Adds the linear combination of components at one vertex to `out`.
    pub fn add_vertex(&self, coeffs: &[f32], vertex: usize, out: &mut Vec3) -> Result<(), ModelError> {
        match self {
            Basis::Factored(b) => b.add_vertex(coeffs, vertex, out),
            Basis::Dense(b) => b.add_vertex(coeffs, vertex, out),
        }
    }

    /// Adds the linear combination of components to `out`.
    pub fn add_instance(&self, coeffs: &[f32], out: &mut [Vec3]) -> Result<(), ModelError> {
        match self {
            Basis::Factored(b) => b.add_instance(coeffs, out),
            Basis::Dense(b) => b.add_instance(coeffs, out),
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    #[test]
    fn factored_matches_dense_expansion() {
        let fields = [1.0, 2.0, 3.0, 0.5, -1.0, 0.0];
        let dirs = [[1.0, 0.0, 0.0], [0.0, 0.6, 0.8]];
        let f = FactoredBasis::new(&fields, &dirs, 3).unwrap();
        let mut dense = [0.0f32; 18];
        for k in 0..2 {
            for i in 0..3 {
                for a in 0..3 {
                    dense[k * 9 + i * 3 + a] = fields[k * 3 + i] * dirs[k][a];
                }
            }
        }
        let d = DenseBasis::new(&dense, 2, 3).unwrap();
        let c = [0.7, -2.0];
        let mut a = [[1.0f32; 3]; 3];
        let mut b = [[1.0f32; 3]; 3];
        f.add_instance(&c, &mut a).unwrap();
        d.add_instance(&c, &mut b).unwrap();
        assert_eq!(a, b);
        assert_eq!(a[1], [1.0 + 1.4, 1.0 + 0.6 * 2.0, 1.0 + 0.8 * 2.0]);
    }

    #[test]
    fn mismatched_lengths_are_errors_not_panics() {
        assert_eq!(FactoredBasis::new(&[1.0; 5], &[[1.0, 0.0, 0.0]; 2], 3).err(), Some(ModelError::LengthMismatch));
        assert_eq!(DenseBasis::new(&[1.0; 5], usize::MAX, 3).err(), Some(ModelError::LengthMismatch));
        let f = FactoredBasis::new(&[1.0; 6], &[[1.0, 0.0, 0.0]; 2], 3).unwrap();
        let mut out = [[0.0f32; 3]; 2];
        assert_eq!(f.add_instance(&[1.0], &mut out), Err(ModelError::LengthMismatch));
        let mut out = [[0.0f32; 3]; 3];
        assert_eq!(f.add_instance(&[1.0; 3], &mut out), Err(ModelError::TooManyCoefficients));
    }
}
