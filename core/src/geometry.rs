//! Plain geometry shared by the renderer, the model and the fit: 3-vectors, row-major 3×3
//! matrices and their products, and the vertex index type of triangle lists.
//!
//! This module is the crate's ground floor: it imports nothing of the crate.

use nalgebra::{Matrix3, Vector3};

/// A 3-vector (position in mm, or linear RGB colour).
pub type Vec3 = [f32; 3];

/// A row-major 3×3 matrix.
pub type Mat3 = [[f32; 3]; 3];

/// A vertex index type for triangle lists (`u16` on the device, `u32` on the host).
pub trait TriIndex: Copy {
    /// The index as `usize`.
    fn index(self) -> usize;
}

impl TriIndex for u16 {
    fn index(self) -> usize {
        usize::from(self)
    }
}

impl TriIndex for u32 {
    fn index(self) -> usize {
        self as usize
    }
}

/// The nalgebra matrix of a row-major [`Mat3`].
pub fn to_matrix3(m: &Mat3) -> Matrix3<f32> {
    let [[a, b, c], [d, e, f], [g, h, i]] = *m;
    Matrix3::new(a, b, c, d, e, f, g, h, i)
}

/// The row-major [`Mat3`] of an nalgebra matrix.
pub fn from_matrix3(m: &Matrix3<f32>) -> Mat3 {
    [[m.m11, m.m12, m.m13], [m.m21, m.m22, m.m23], [m.m31, m.m32, m.m33]]
}

/// `a · b` for 3×3 matrices (nalgebra's product: the same operations, in the same order, as the
/// row-by-column sums written out; `tests::nalgebra_products_match_the_written_out_sums`).
pub fn mat_mul(a: &Mat3, b: &Mat3) -> Mat3 {
    from_matrix3(&(to_matrix3(a) * to_matrix3(b)))
}

/// `m · v`.
pub fn mat_vec(m: &Mat3, v: Vec3) -> Vec3 {
    let r = to_matrix3(m) * Vector3::new(v[0], v[1], v[2]);
    [r.x, r.y, r.z]
}

#[cfg(test)]
#[allow(clippy::indexing_slicing)]
mod tests {
    use super::*;

    /// The written-out sums nalgebra's products replaced (left to right, row by column).
    fn mat_mul_written_out(a: &Mat3, b: &Mat3) -> Mat3 {
        let [b0, b1, b2] = *b;
        a.map(|[x, y, z]| [x * b0[0] + y * b1[0] + z * b2[0], x * b0[1] + y * b1[1] + z * b2[1], x * b0[2] + y * b1[2] + z * b2[2]])
    }

    #[test]
    fn nalgebra_products_match_the_written_out_sums() {
        // A simple LCG: many matrices with mixed signs and magnitudes, compared bit for bit.
        let mut state = 0x1234_5678_u32;
        let mut next = || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) as f32 / (1u32 << 24) as f32 * 4.0 - 2.0
        };
        for _ in 0..20_000 {
            let a: Mat3 = [[next(), next(), next()], [next(), next(), next()], [next(), next(), next()]];
            let b: Mat3 = [[next(), next(), next()], [next(), next(), next()], [next(), next(), next()]];
            let v = [next() * 300.0, next() * 300.0, next() * 300.0];
            let (p, q) = (mat_mul(&a, &b), mat_mul_written_out(&a, &b));
            assert_eq!(p.map(|r| r.map(f32::to_bits)), q.map(|r| r.map(f32::to_bits)));
            let w = [
                a[0][0] * v[0] + a[0][1] * v[1] + a[0][2] * v[2],
                a[1][0] * v[0] + a[1][1] * v[1] + a[1][2] * v[2],
                a[2][0] * v[0] + a[2][1] * v[1] + a[2][2] * v[2],
            ];
            assert_eq!(mat_vec(&a, v).map(f32::to_bits), w.map(f32::to_bits));
        }
    }
}
