//! One vertex's row of a basis: every component's (scaled) vector there, whatever the layout
//! (the colour solve's linear map, `crate::fit::solve::color`).

use super::{Basis, Vec3};

impl Basis<'_> {
    /// Component `k`'s (scaled) vector at `vertex`; zero outside the basis.
    pub fn component_at(&self, k: usize, vertex: usize) -> Vec3 {
        let n = self.vertices();
        if k >= self.rank() || vertex >= n {
            return [0.0; 3];
        }
        let at = k * n + vertex;
        let scale = |m: f32, e: &Vec3| [m * e[0], m * e[1], m * e[2]];
        match self {
            Basis::Factored(b) => match (b.fields.get(at), b.directions.get(k)) {
                (Some(f), Some(e)) => scale(*f, e),
                _ => [0.0; 3],
            },
            Basis::Dense(b) => match b.values.get(3 * at..3 * at + 3) {
                Some([x, y, z]) => [*x, *y, *z],
                _ => [0.0; 3],
            },
            Basis::Quantized(b) => {
                let s = b.scales.get(k).copied().unwrap_or(0.0);
                match b.directions.and_then(|d| d.get(k)) {
                    Some(e) => scale(s * b.values.get(at), e),
                    None => [s * b.values.get(3 * at), s * b.values.get(3 * at + 1), s * b.values.get(3 * at + 2)],
                }
            }
        }
    }

    /// The (scaled) vectors of the first `out.len()` components at `vertex` into `out` (zero
    /// outside the basis): one row of the basis, read with the layout matched once.
    pub fn components_at(&self, vertex: usize, out: &mut [Vec3]) {
        let n = self.vertices();
        let rank = self.rank();
        if vertex >= n {
            out.fill([0.0; 3]);
            return;
        }
        let keep = out.len().min(rank);
        let (out, rest) = out.split_at_mut(keep);
        rest.fill([0.0; 3]);
        match self {
            Basis::Factored(b) => {
                for ((o, e), f) in out.iter_mut().zip(b.directions).zip(b.fields.iter().skip(vertex).step_by(n)) {
                    *o = [f * e[0], f * e[1], f * e[2]];
                }
            }
            Basis::Dense(b) => {
                for (o, v) in out.iter_mut().zip(b.values.chunks_exact(3).skip(vertex).step_by(n)) {
                    if let [x, y, z] = v {
                        *o = [*x, *y, *z];
                    }
                }
            }
            Basis::Quantized(_) => {
                for (k, o) in out.iter_mut().enumerate() {
                    *o = self.component_at(k, vertex);
                }
            }
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::super::tests::for_every_layout;

    #[test]
    fn basis_rows_are_the_unit_coefficient_sums_for_every_layout() {
        for_every_layout(|b| {
            for v in 0..3 {
                // Three slots for a rank-2 basis: the extra one is zero.
                let mut row = [[9.0f32; 3]; 3];
                b.components_at(v, &mut row);
                for (k, r) in row.iter().enumerate() {
                    let mut unit = [0.0f32; 2];
                    let mut expected = [0.0f32; 3];
                    if k < 2 {
                        unit[k] = 1.0;
                        b.add_vertex(&unit, v, &mut expected).unwrap();
                    }
                    for a in 0..3 {
                        assert!((r[a] - expected[a]).abs() <= 1e-6 * (1.0 + expected[a].abs()), "{b:?} v{v} k{k}: {r:?} vs {expected:?}");
                    }
                    assert_eq!(*r, b.component_at(k, v));
                }
            }
            // Outside the basis: zeros, no panic.
            let mut row = [[9.0f32; 3]; 2];
            b.components_at(3, &mut row);
            assert_eq!(row, [[0.0; 3]; 2]);
            assert_eq!(b.component_at(0, 3), [0.0; 3]);
            assert_eq!(b.component_at(2, 0), [0.0; 3]);
        });
    }
}
