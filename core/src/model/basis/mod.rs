//! Low-rank linear models: `instance = mean + Σ_k c_k · b_k`.
//!
//! Two basis layouts exist (see docs/design.md, "Low rank"):
//! - [`FactoredBasis`]: component `k` is a scalar per-vertex field `f_k`
//!   (already scaled by `sqrt(eigenvalue)`) times one fixed unit 3-vector `e_k`.
//!   Every Gaussian-process kernel of the paper factors this way, which costs
//!   `N` values per component instead of `3N`.
//! - [`DenseBasis`]: component `k` holds a full 3-vector per vertex (PCA of
//!   learned or registered data).

use crate::geometry::Vec3;

/// Why a model operation was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
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

    /// The per-vertex fields, `rank × vertices` row-major.
    pub fn fields(&self) -> &'a [f32] {
        self.fields
    }

    /// The unit direction of each component.
    pub fn directions(&self) -> &'a [Vec3] {
        self.directions
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
        let comps = coeffs
            .iter()
            .zip(self.directions)
            .zip(self.fields.chunks_exact(self.vertices))
            .filter(|((c, _), _)| **c != 0.0)
            .map(|((c, dir), field)| ([c * dir[0], c * dir[1], c * dir[2]], field));
        // Directions along the axes (every kernel of the paper's shape models): each component
        // moves one coordinate, so a pass per axis skips the two zero products of each term (a
        // pass per axis for other directions costs more than one pass over all three).
        if comps.clone().all(|(d, _)| d.iter().filter(|x| **x != 0.0).count() <= 1) {
            fold_axis_all::<0, _>(comps.clone().map(|(d, f)| (d[0], f)), out);
            fold_axis_all::<1, _>(comps.clone().map(|(d, f)| (d[1], f)), out);
            fold_axis_all::<2, _>(comps.map(|(d, f)| (d[2], f)), out);
        } else {
            fold_factored_all(comps, out);
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
        let comps = coeffs.iter().zip(self.values.chunks_exact(self.vertices * 3)).filter(|(c, _)| **c != 0.0);
        fold_dense_all(comps.map(|(c, comp)| (*c, comp)), out);
        Ok(())
    }
}

/// Quantized basis values, borrowed (e.g. in place from a model blob in flash).
#[derive(Debug, Clone, Copy)]
pub enum QuantValues<'a> {
    /// 8-bit signed values.
    I8(&'a [i8]),
    /// 16-bit signed values.
    I16(&'a [i16]),
}

impl QuantValues<'_> {
    /// Number of values.
    pub fn len(&self) -> usize {
        match self {
            QuantValues::I8(v) => v.len(),
            QuantValues::I16(v) => v.len(),
        }
    }

    /// Whether there are no values.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Bits per value (8 or 16).
    pub fn bits(&self) -> u8 {
        match self {
            QuantValues::I8(_) => 8,
            QuantValues::I16(_) => 16,
        }
    }

    /// Value `i` as `f32` (0 past the end).
    pub fn get(&self, i: usize) -> f32 {
        match self {
            QuantValues::I8(v) => v.get(i).map_or(0.0, |&q| f32::from(q)),
            QuantValues::I16(v) => v.get(i).map_or(0.0, |&q| f32::from(q)),
        }
    }
}

/// Multiply-adds the components `(d, values)` in turn, four per pass over `out`: each entry
/// still sums the components in their order (the same bits as one pass per component), with a
/// quarter of the loads and stores of `out`.
fn fold_factored_all<'v, Q: Copy + Into<f32> + 'v>(comps: impl Iterator<Item = (Vec3, &'v [Q])>, out: &mut [Vec3]) {
    in_blocks_of_four(comps, out, |block, out| fold_factored4(block, out), |d, values, out| fold_factored(d, values, out));
}

/// Four components of [`fold_factored`] in one pass (one at a time if a field is short).
fn fold_factored4<Q: Copy + Into<f32>>(block: &[(Vec3, &[Q]); 4], out: &mut [Vec3]) {
    let [(d0, f0), (d1, f1), (d2, f2), (d3, f3)] = *block;
    let n = out.len();
    let (Some(f0), Some(f1), Some(f2), Some(f3)) = (f0.get(..n), f1.get(..n), f2.get(..n), f3.get(..n)) else {
        for (d, values) in block {
            fold_factored(*d, values, out);
        }
        return;
    };
    for ((((o, &q0), &q1), &q2), &q3) in out.iter_mut().zip(f0).zip(f1).zip(f2).zip(f3) {
        let (q0, q1, q2, q3): (f32, f32, f32, f32) = (q0.into(), q1.into(), q2.into(), q3.into());
        o[0] = o[0] + d0[0] * q0 + d1[0] * q1 + d2[0] * q2 + d3[0] * q3;
        o[1] = o[1] + d0[1] * q0 + d1[1] * q1 + d2[1] * q2 + d3[1] * q3;
        o[2] = o[2] + d0[2] * q0 + d1[2] * q1 + d2[2] * q2 + d3[2] * q3;
    }
}

/// Multiply-adds `out[v] += d · q[v]` (factored) over one component's values.
fn fold_factored<Q: Copy + Into<f32>>(d: Vec3, values: &[Q], out: &mut [Vec3]) {
    for (o, &q) in out.iter_mut().zip(values) {
        let q: f32 = q.into();
        o[0] += d[0] * q;
        o[1] += d[1] * q;
        o[2] += d[2] * q;
    }
}

/// A quantized basis: component `k` is `scales[k] · q_k`, with integer values `q_k`.
///
/// With `directions` (factored layout) `values` is `rank × vertices` and component `k` is
/// `scales[k] · q_k ⊗ directions[k]`; without (dense layout) `values` is `rank × vertices × 3`.
/// The dequantized value of `q` is `scales[k] · q`; sums fold `c_k · scales[k] (· e_k)` into
/// at most three floats per component, then do one multiply-add per stored value.
#[derive(Debug, Clone, Copy)]
pub struct QuantizedBasis<'a> {
    values: QuantValues<'a>,
    scales: &'a [f32],
    directions: Option<&'a [Vec3]>,
    vertices: usize,
}

impl<'a> QuantizedBasis<'a> {
    /// Wraps borrowed data; the rank is `scales.len()`, and `directions` (if any) and `values` must agree.
    pub fn new(values: QuantValues<'a>, scales: &'a [f32], directions: Option<&'a [Vec3]>, vertices: usize) -> Result<Self, ModelError> {
        let rank = scales.len();
        let per_component = match directions {
            Some(d) if d.len() != rank => return Err(ModelError::LengthMismatch),
            Some(_) => Some(vertices),
            None => vertices.checked_mul(3),
        };
        if per_component.and_then(|p| p.checked_mul(rank)) != Some(values.len()) {
            return Err(ModelError::LengthMismatch);
        }
        Ok(Self { values, scales, directions, vertices })
    }

    /// Number of components.
    pub fn rank(&self) -> usize {
        self.scales.len()
    }

    /// Number of vertices each component covers.
    pub fn vertices(&self) -> usize {
        self.vertices
    }

    /// The integer values.
    pub fn values(&self) -> QuantValues<'a> {
        self.values
    }

    /// Per-component scales.
    pub fn scales(&self) -> &'a [f32] {
        self.scales
    }

    /// Per-component unit directions (factored layout), or `None` (dense layout).
    pub fn directions(&self) -> Option<&'a [Vec3]> {
        self.directions
    }

    fn check(&self, coeffs: &[f32]) -> Result<(), ModelError> {
        if coeffs.len() > self.rank() {
            return Err(ModelError::TooManyCoefficients);
        }
        Ok(())
    }

    /// Adds `Σ_k coeffs[k] · scales[k] · q_k` to `out` (one entry per vertex).
    pub fn add_instance(&self, coeffs: &[f32], out: &mut [Vec3]) -> Result<(), ModelError> {
        if out.len() != self.vertices {
            return Err(ModelError::LengthMismatch);
        }
        self.check(coeffs)?;
        if self.vertices == 0 {
            return Ok(());
        }
        let n = self.vertices;
        match self.directions {
            Some(dirs) => {
                let comps =
                    coeffs.iter().zip(self.scales).zip(dirs).map(|((c, s), e)| (c * s, e)).enumerate().filter(|(_, (m, _))| *m != 0.0);
                let d = |m: f32, e: &Vec3| [m * e[0], m * e[1], m * e[2]];
                match self.values {
                    QuantValues::I8(v) => {
                        fold_factored_all(comps.map(|(k, (m, e))| (d(m, e), v.get(k * n..(k + 1) * n).unwrap_or(&[]))), out)
                    }
                    QuantValues::I16(v) => {
                        fold_factored_all(comps.map(|(k, (m, e))| (d(m, e), v.get(k * n..(k + 1) * n).unwrap_or(&[]))), out)
                    }
                }
            }
            None => {
                let comps = coeffs.iter().zip(self.scales).map(|(c, s)| c * s).enumerate().filter(|(_, m)| *m != 0.0);
                match self.values {
                    QuantValues::I8(v) => fold_dense_all(comps.map(|(k, m)| (m, v.get(3 * k * n..3 * (k + 1) * n).unwrap_or(&[]))), out),
                    QuantValues::I16(v) => fold_dense_all(comps.map(|(k, m)| (m, v.get(3 * k * n..3 * (k + 1) * n).unwrap_or(&[]))), out),
                }
            }
        }
        Ok(())
    }

    /// Adds `Σ_k coeffs[k] · scales[k] · q_k[vertex]` to `out`: one vertex of the instance alone.
    pub fn add_vertex(&self, coeffs: &[f32], vertex: usize, out: &mut Vec3) -> Result<(), ModelError> {
        if vertex >= self.vertices {
            return Err(ModelError::LengthMismatch);
        }
        self.check(coeffs)?;
        let n = self.vertices;
        match self.directions {
            Some(dirs) => {
                for (k, ((c, s), e)) in coeffs.iter().zip(self.scales).zip(dirs).enumerate() {
                    let m = c * s;
                    let q = self.values.get(k * n + vertex);
                    out[0] += m * e[0] * q;
                    out[1] += m * e[1] * q;
                    out[2] += m * e[2] * q;
                }
            }
            None => {
                for (k, (c, s)) in coeffs.iter().zip(self.scales).enumerate() {
                    let m = c * s;
                    let at = (k * n + vertex) * 3;
                    out[0] += m * self.values.get(at);
                    out[1] += m * self.values.get(at + 1);
                    out[2] += m * self.values.get(at + 2);
                }
            }
        }
        Ok(())
    }
}

/// [`gather_factored`] of the components `(d, values)` in turn, four per pass over `ids` (each
/// entry sums the components in their order: the same bits as one pass per component).
fn gather_factored_all<'v, Q: Copy + Into<f32> + 'v>(comps: impl Iterator<Item = (Vec3, &'v [Q])>, ids: &[u32], out: &mut [Vec3]) {
    in_blocks_of_four(comps, out, |block, out| gather_factored4(block, ids, out), |d, values, out| gather_factored(d, values, ids, out));
}

/// Four components of [`gather_factored`] in one pass.
fn gather_factored4<Q: Copy + Into<f32>>(block: &[(Vec3, &[Q]); 4], ids: &[u32], out: &mut [Vec3]) {
    let [(d0, f0), (d1, f1), (d2, f2), (d3, f3)] = *block;
    for (o, &v) in out.iter_mut().zip(ids) {
        let v = v as usize;
        let (Some(&q0), Some(&q1), Some(&q2), Some(&q3)) = (f0.get(v), f1.get(v), f2.get(v), f3.get(v)) else {
            // A short field: component by component, as one pass each would.
            for (d, values) in block {
                if let Some(&q) = values.get(v) {
                    let q: f32 = q.into();
                    o[0] += d[0] * q;
                    o[1] += d[1] * q;
                    o[2] += d[2] * q;
                }
            }
            continue;
        };
        let (q0, q1, q2, q3): (f32, f32, f32, f32) = (q0.into(), q1.into(), q2.into(), q3.into());
        o[0] = o[0] + d0[0] * q0 + d1[0] * q1 + d2[0] * q2 + d3[0] * q3;
        o[1] = o[1] + d0[1] * q0 + d1[1] * q1 + d2[1] * q2 + d3[1] * q3;
        o[2] = o[2] + d0[2] * q0 + d1[2] * q1 + d2[2] * q2 + d3[2] * q3;
    }
}

/// Multiply-adds `out[i] += d · values[ids[i]]` (factored) over one component's values.
fn gather_factored<Q: Copy + Into<f32>>(d: Vec3, values: &[Q], ids: &[u32], out: &mut [Vec3]) {
    for (o, &v) in out.iter_mut().zip(ids) {
        if let Some(&q) = values.get(v as usize) {
            let q: f32 = q.into();
            o[0] += d[0] * q;
            o[1] += d[1] * q;
            o[2] += d[2] * q;
        }
    }
}

/// Multiply-adds `out[i][a] += m · values[ids[i]][a]` (dense) over one component's values.
fn gather_dense<Q: Copy + Into<f32>>(m: f32, values: &[Q], ids: &[u32], out: &mut [Vec3]) {
    for (o, &v) in out.iter_mut().zip(ids) {
        let at = v as usize * 3;
        if let Some(&[x, y, z]) = values.get(at..at + 3) {
            o[0] += m * x.into();
            o[1] += m * y.into();
            o[2] += m * z.into();
        }
    }
}

/// Any basis layout.
#[derive(Debug, Clone, Copy)]
pub enum Basis<'a> {
    /// Scalar field times a fixed direction per component.
    Factored(FactoredBasis<'a>),
    /// Full 3-vector per vertex per component.
    Dense(DenseBasis<'a>),
    /// Integer values with per-component scales (factored or dense), e.g. from a model blob.
    Quantized(QuantizedBasis<'a>),
}

impl Basis<'_> {
    /// Number of components.
    pub fn rank(&self) -> usize {
        match self {
            Basis::Factored(b) => b.rank(),
            Basis::Dense(b) => b.rank(),
            Basis::Quantized(b) => b.rank(),
        }
    }

    /// Number of vertices each component covers.
    pub fn vertices(&self) -> usize {
        match self {
            Basis::Factored(b) => b.vertices(),
            Basis::Dense(b) => b.vertices(),
            Basis::Quantized(b) => b.vertices(),
        }
    }

    /// Adds the linear combination of components at one vertex to `out`.
    pub fn add_vertex(&self, coeffs: &[f32], vertex: usize, out: &mut Vec3) -> Result<(), ModelError> {
        match self {
            Basis::Factored(b) => b.add_vertex(coeffs, vertex, out),
            Basis::Dense(b) => b.add_vertex(coeffs, vertex, out),
            Basis::Quantized(b) => b.add_vertex(coeffs, vertex, out),
        }
    }

    /// Adds the linear combination of components at the vertices `ids` to `out` (one entry per
    /// id), with the component loop outside: the same sums as [`Basis::add_instance`] at those
    /// vertices, for `rank × ids` multiply-adds (the fitter's landmarks).
    pub fn add_vertices(&self, coeffs: &[f32], ids: &[u32], out: &mut [Vec3]) -> Result<(), ModelError> {
        let n = self.vertices();
        if out.len() != ids.len() || ids.iter().any(|&v| v as usize >= n) {
            return Err(ModelError::LengthMismatch);
        }
        if coeffs.len() > self.rank() {
            return Err(ModelError::TooManyCoefficients);
        }
        match self {
            Basis::Factored(b) => {
                let comps = coeffs.iter().zip(b.directions).zip(b.fields.chunks_exact(n.max(1)));
                gather_factored_all(comps.map(|((c, e), field)| ([c * e[0], c * e[1], c * e[2]], field)), ids, out);
            }
            Basis::Dense(b) => {
                for (c, comp) in coeffs.iter().zip(b.values.chunks_exact((3 * n).max(1))) {
                    gather_dense(*c, comp, ids, out);
                }
            }
            Basis::Quantized(b) if b.directions.is_some() => {
                let dirs = b.directions.unwrap_or(&[]);
                let comps = coeffs.iter().zip(b.scales).zip(dirs).map(|((c, s), e)| (c * s, e)).enumerate();
                let d = |m: f32, e: &Vec3| [m * e[0], m * e[1], m * e[2]];
                match b.values {
                    QuantValues::I8(v) => {
                        gather_factored_all(comps.map(|(k, (m, e))| (d(m, e), v.get(k * n..(k + 1) * n).unwrap_or(&[]))), ids, out)
                    }
                    QuantValues::I16(v) => {
                        gather_factored_all(comps.map(|(k, (m, e))| (d(m, e), v.get(k * n..(k + 1) * n).unwrap_or(&[]))), ids, out)
                    }
                }
            }
            Basis::Quantized(b) => {
                let per = if b.directions.is_some() { n } else { 3 * n };
                for (k, (c, s)) in coeffs.iter().zip(b.scales).enumerate() {
                    let m = c * s;
                    let range = k * per..(k + 1) * per;
                    match (b.directions.and_then(|d| d.get(k)), b.values) {
                        (Some(e), QuantValues::I8(v)) => {
                            gather_factored([m * e[0], m * e[1], m * e[2]], v.get(range).unwrap_or(&[]), ids, out)
                        }
                        (Some(e), QuantValues::I16(v)) => {
                            gather_factored([m * e[0], m * e[1], m * e[2]], v.get(range).unwrap_or(&[]), ids, out)
                        }
                        (None, QuantValues::I8(v)) => gather_dense(m, v.get(range).unwrap_or(&[]), ids, out),
                        (None, QuantValues::I16(v)) => gather_dense(m, v.get(range).unwrap_or(&[]), ids, out),
                    }
                }
            }
        }
        Ok(())
    }

    /// Adds the linear combination of components to `out`.
    pub fn add_instance(&self, coeffs: &[f32], out: &mut [Vec3]) -> Result<(), ModelError> {
        match self {
            Basis::Factored(b) => b.add_instance(coeffs, out),
            Basis::Dense(b) => b.add_instance(coeffs, out),
            Basis::Quantized(b) => b.add_instance(coeffs, out),
        }
    }
}

mod axis;
mod blocks;
mod dense;
mod rows;

use axis::fold_axis_all;
use blocks::in_blocks_of_four;
use dense::fold_dense_all;

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    /// Calls `f` with one rank-2, 3-vertex basis of every layout.
    pub(super) fn for_every_layout(mut f: impl FnMut(Basis<'_>)) {
        let fields = [1.0, 2.0, 3.0, 0.5, -1.0, 0.25];
        let dirs = [[1.0, 0.0, 0.0], [0.0, 0.6, 0.8]];
        let dense = [0.1, 0.2, 0.3, -0.4, 0.5, 0.6, 0.7, 0.8, -0.9, 1.0, 1.1, 1.2, 1.3, -1.4, 1.5, 1.6, 1.7, 1.8];
        let q8: [i8; 6] = [12, -7, 127, -128, 0, 55];
        let q16: [i16; 18] = [1, -2, 3, 400, -500, 600, 7, 8, 9, -10, 11, 12, 13, 14, 15, 16, 17, -32767];
        let scales = [0.01, 0.002];
        let bases = [
            Basis::Factored(FactoredBasis::new(&fields, &dirs, 3).unwrap()),
            Basis::Dense(DenseBasis::new(&dense, 2, 3).unwrap()),
            Basis::Quantized(QuantizedBasis::new(QuantValues::I8(&q8), &scales, Some(&dirs), 3).unwrap()),
            Basis::Quantized(QuantizedBasis::new(QuantValues::I16(&q16), &scales, None, 3).unwrap()),
        ];
        bases.into_iter().for_each(&mut f);
    }

    #[test]
    fn add_vertices_equals_add_vertex_for_every_layout() {
        let ids = [2u32, 0, 2, 1];
        for_every_layout(|b| {
            let c = [0.7, -2.0];
            let mut many = [[0.5f32; 3]; 4];
            b.add_vertices(&c, &ids, &mut many).unwrap();
            for (o, &v) in many.iter().zip(&ids) {
                let mut one = [0.5f32; 3];
                b.add_vertex(&c, v as usize, &mut one).unwrap();
                for a in 0..3 {
                    assert!((o[a] - one[a]).abs() <= 1e-6 * (1.0 + one[a].abs()), "{b:?}: {o:?} vs {one:?}");
                }
            }
            assert_eq!(b.add_vertices(&c, &[3], &mut [[0.0; 3]]), Err(ModelError::LengthMismatch));
            assert_eq!(b.add_vertices(&c, &[0, 1], &mut [[0.0; 3]]), Err(ModelError::LengthMismatch));
            assert_eq!(b.add_vertices(&[1.0; 3], &[0], &mut [[0.0; 3]]), Err(ModelError::TooManyCoefficients));
        });
    }

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

    /// Dequantized f32 bases and quantized ones give the same sums exactly (power-of-two scales
    /// make every dequantized value exact, so the two evaluation orders round identically).
    #[test]
    fn quantized_equals_dequantized_f32_basis() {
        let n = 4;
        let q8: [i8; 8] = [127, -128, 3, 0, -5, 64, -1, 100];
        let q16: [i16; 8] = [32767, -32768, 300, 0, -5000, 6400, -1, 10000];
        let scales = [0.25f32, 1.0 / 1024.0];
        let dirs = [[0.0, 0.6, 0.8], [1.0, 0.0, 0.0]];
        let coeffs = [0.37f32, -1.9];
        for values in [QuantValues::I8(&q8), QuantValues::I16(&q16)] {
            let fields: std::vec::Vec<f32> = (0..8).map(|i| scales[i / n] * values.get(i)).collect();
            let f = FactoredBasis::new(&fields, &dirs, n).unwrap();
            let q = Basis::Quantized(QuantizedBasis::new(values, &scales, Some(&dirs), n).unwrap());
            assert_eq!((q.rank(), q.vertices()), (2, n));
            let (mut a, mut b) = ([[0.5f32; 3]; 4], [[0.5f32; 3]; 4]);
            f.add_instance(&coeffs, &mut a).unwrap();
            q.add_instance(&coeffs, &mut b).unwrap();
            assert_eq!(a, b);
            assert_ne!(a, [[0.5f32; 3]; 4]);
            for (v, want) in b.iter().enumerate() {
                let mut p = [0.5f32; 3];
                q.add_vertex(&coeffs, v, &mut p).unwrap();
                assert_eq!(&p, want, "vertex {v}");
            }
        }
        // Dense layout: rank 2, 2 vertices, 3 values each.
        let qd: [i16; 12] = [1, -2, 3, 32767, 0, -32768, 7, 8, -9, 10, 11, 12];
        let dense: std::vec::Vec<f32> = (0..12).map(|i| scales[i / 6] * f32::from(qd[i])).collect();
        let d = DenseBasis::new(&dense, 2, 2).unwrap();
        let q = QuantizedBasis::new(QuantValues::I16(&qd), &scales, None, 2).unwrap();
        let (mut a, mut b) = ([[1.0f32; 3]; 2], [[1.0f32; 3]; 2]);
        d.add_instance(&coeffs, &mut a).unwrap();
        q.add_instance(&coeffs, &mut b).unwrap();
        assert_eq!(a, b);
        let mut p = [1.0f32; 3];
        q.add_vertex(&coeffs, 1, &mut p).unwrap();
        assert_eq!(p, b[1]);
        // Fewer coefficients: the rest are zero.
        let (mut a, mut b) = ([[0.0f32; 3]; 2], [[0.0f32; 3]; 2]);
        d.add_instance(&coeffs[..1], &mut a).unwrap();
        q.add_instance(&coeffs[..1], &mut b).unwrap();
        assert_eq!(a, b);
    }

    #[test]
    fn quantized_lengths_are_checked() {
        let v = [0i8; 6];
        let s = [1.0f32; 2];
        assert!(QuantizedBasis::new(QuantValues::I8(&v), &s, Some(&[[1.0, 0.0, 0.0]; 2]), 3).is_ok());
        assert!(QuantizedBasis::new(QuantValues::I8(&v), &s, None, 1).is_ok());
        assert_eq!(QuantizedBasis::new(QuantValues::I8(&v), &s, Some(&[[1.0, 0.0, 0.0]; 1]), 3).err(), Some(ModelError::LengthMismatch));
        assert_eq!(QuantizedBasis::new(QuantValues::I8(&v), &s, None, 3).err(), Some(ModelError::LengthMismatch));
        assert_eq!(QuantizedBasis::new(QuantValues::I8(&v), &s, None, usize::MAX).err(), Some(ModelError::LengthMismatch));
        let q = QuantizedBasis::new(QuantValues::I8(&v), &s, None, 1).unwrap();
        let mut out = [[0.0f32; 3]; 2];
        assert_eq!(q.add_instance(&[1.0], &mut out), Err(ModelError::LengthMismatch));
        let mut out = [[0.0f32; 3]; 1];
        assert_eq!(q.add_instance(&[1.0; 3], &mut out), Err(ModelError::TooManyCoefficients));
        assert_eq!(q.add_vertex(&[1.0], 1, &mut out[0]), Err(ModelError::LengthMismatch));
    }
}
