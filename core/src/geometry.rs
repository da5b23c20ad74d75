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
///
/// # Examples
///
/// An index type of one's own (one byte per index, for meshes of at most 256 vertices) works
/// wherever the crate takes triangles, e.g. with the rasterizer:
///
/// ```
/// use gpmm_core::geometry::TriIndex;
/// use gpmm_core::render::{Cull, ProjectedVertex, RasterError, Tile, TileRasterizer};
///
/// #[derive(Clone, Copy)]
/// struct Byte(u8);
///
/// impl TriIndex for Byte {
///     fn index(self) -> usize {
///         usize::from(self.0)
///     }
/// }
///
/// // A 4 × 4 square of two triangles.
/// let vertex = |x, y| ProjectedVertex { x, y, inv_w: 0.01, color: [1.0; 3] };
/// let vertices = [vertex(0.0, 0.0), vertex(4.0, 0.0), vertex(4.0, 4.0), vertex(0.0, 4.0)];
/// let square = [[Byte(0), Byte(1), Byte(2)], [Byte(0), Byte(2), Byte(3)]];
/// let mut raster = TileRasterizer::<4, 4, 8>::new();
/// let mut ignore = |_: &Tile<4, 4>| {};
/// let stats = raster.render(&vertices, &square, 4, 4, Cull::None, &mut ignore)?;
/// assert_eq!((stats.drawn, stats.covered_pixels), (2, 16));
///
/// // An index past the vertices is an error, not a panic.
/// let broken = [[Byte(0), Byte(1), Byte(9)]];
/// assert_eq!(raster.render(&vertices, &broken, 4, 4, Cull::None, &mut ignore), Err(RasterError::IndexOutOfRange));
/// # Ok::<(), RasterError>(())
/// ```
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

/// The working pixels whose centres lie in the photo: a rectangle, half-open (`x0 ≤ x < x1`,
/// `y0 ≤ y < y1`), in working pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct CoveredPixels {
    /// First covered column.
    pub x0: u32,
    /// First covered row.
    pub y0: u32,
    /// One past the last covered column.
    pub x1: u32,
    /// One past the last covered row.
    pub y1: u32,
}

impl CoveredPixels {
    /// Every pixel of a `width × height` image.
    pub const fn whole(width: u32, height: u32) -> Self {
        Self { x0: 0, y0: 0, x1: width, y1: height }
    }

    /// The pixels of a `side × side` working image whose pixel `(u, v)` spans the photo from
    /// `(left + u · step, top + v · step)` to `step` further (continuous photo pixels) that lie in
    /// a `width × height` photo: the centre of each lies inside it.
    pub fn of_crop(left: f32, top: f32, step: f32, side: u32, width: u32, height: u32) -> Self {
        // Pixel u's centre left + (u + 0.5) · step lies in [0, extent) for first ≤ u < end.
        let range = |start: f32, extent: u32| -> (u32, u32) {
            if !(step > 0.0 && step.is_finite() && start.is_finite()) {
                return (0, 0);
            }
            let bound = |edge: f32| -> u32 {
                let u = libm::ceilf((edge - start) / step - 0.5);
                if u <= 0.0 {
                    0
                } else if u >= side as f32 {
                    side
                } else {
                    u as u32
                }
            };
            let (a, b) = (bound(0.0), bound(extent as f32));
            (a, b.max(a))
        };
        let ((x0, x1), (y0, y1)) = (range(left, width), range(top, height));
        Self { x0, y0, x1, y1 }
    }

    /// Whether pixel `(x, y)` is covered.
    #[inline(always)]
    pub fn contains(&self, x: u32, y: u32) -> bool {
        x >= self.x0 && x < self.x1 && y >= self.y0 && y < self.y1
    }

    /// Covered pixels.
    pub fn count(&self) -> u32 {
        self.x1.saturating_sub(self.x0).saturating_mul(self.y1.saturating_sub(self.y0))
    }

    /// Whether the rectangle lies in a `width × height` image and covers at least one pixel.
    pub fn fits(&self, width: u32, height: u32) -> bool {
        self.x0 < self.x1 && self.y0 < self.y1 && self.x1 <= width && self.y1 <= height
    }
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
