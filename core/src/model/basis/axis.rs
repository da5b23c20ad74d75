//! Single-coordinate passes of the factored basis sums (see [`super::FactoredBasis::add_instance`]).

use super::Vec3;

/// Multiply-adds `out[v][A] += m · q[v]` for the components `(m, values)` with `m ≠ 0`, in
/// their order and four per pass: each entry sums the same non-zero terms in the same order as
/// [`fold_factored_all`] (a zero product `±0` leaves a sum unchanged, except the sign of a zero).
pub(super) fn fold_axis_all<'v, const A: usize, Q: Copy + Into<f32> + 'v>(comps: impl Iterator<Item = (f32, &'v [Q])>, out: &mut [Vec3]) {
    let mut block: [(f32, &[Q]); 4] = [(0.0, &[]); 4];
    let mut filled = 0;
    for comp in comps.filter(|(m, _)| *m != 0.0) {
        if let Some(slot) = block.get_mut(filled) {
            *slot = comp;
            filled += 1;
        }
        if filled == block.len() {
            fold_axis4::<A, Q>(&block, out);
            filled = 0;
        }
    }
    for (m, values) in block.iter().take(filled) {
        fold_axis::<A, Q>(*m, values, out);
    }
}

/// Four components of [`fold_axis`] in one pass (one at a time if a field is short).
fn fold_axis4<const A: usize, Q: Copy + Into<f32>>(block: &[(f32, &[Q]); 4], out: &mut [Vec3]) {
    let [(m0, f0), (m1, f1), (m2, f2), (m3, f3)] = *block;
    let n = out.len();
    let (Some(f0), Some(f1), Some(f2), Some(f3)) = (f0.get(..n), f1.get(..n), f2.get(..n), f3.get(..n)) else {
        for (m, values) in block {
            fold_axis::<A, Q>(*m, values, out);
        }
        return;
    };
    for ((((o, &q0), &q1), &q2), &q3) in out.iter_mut().zip(f0).zip(f1).zip(f2).zip(f3) {
        let (q0, q1, q2, q3): (f32, f32, f32, f32) = (q0.into(), q1.into(), q2.into(), q3.into());
        if let Some(x) = o.get_mut(A) {
            *x = *x + m0 * q0 + m1 * q1 + m2 * q2 + m3 * q3;
        }
    }
}

/// Multiply-adds `out[v][A] += m · q[v]` over one component's values.
fn fold_axis<const A: usize, Q: Copy + Into<f32>>(m: f32, values: &[Q], out: &mut [Vec3]) {
    for (o, &q) in out.iter_mut().zip(values) {
        if let Some(x) = o.get_mut(A) {
            *x += m * q.into();
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::super::{fold_factored_all, FactoredBasis};
    use super::*;

    #[test]
    fn axis_passes_give_the_bits_of_the_general_fold() {
        // 11 components (some coefficients zero), 37 vertices, pseudo-random values: along the
        // axes through `add_instance`, and along axes, a diagonal and a plane through the passes.
        let (rank, n) = (11, 37);
        let mut state = 0x2545_f491_u32;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            (state % 20_001) as f32 / 10_000.0 - 1.0
        };
        let fields: std::vec::Vec<f32> = (0..rank * n).map(|_| next()).collect();
        let coeffs: std::vec::Vec<f32> = (0..rank).map(|k| if k % 5 == 3 { 0.0 } else { 3.0 * next() }).collect();
        let mean: std::vec::Vec<Vec3> = (0..n).map(|_| [next() + 2.0, next(), next() - 2.0]).collect();
        let bits = |v: &[Vec3]| v.iter().flat_map(|p| p.map(f32::to_bits)).collect::<std::vec::Vec<_>>();
        let axes = [
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, -1.0],
            [0.577_350_3; 3],
            [core::f32::consts::FRAC_1_SQRT_2, -core::f32::consts::FRAC_1_SQRT_2, 0.0],
        ];
        for kinds in [3, axes.len()] {
            let dirs: std::vec::Vec<Vec3> = (0..rank).map(|k| axes[(k * 7) % kinds]).collect();
            let comps = || {
                coeffs
                    .iter()
                    .zip(&dirs)
                    .zip(fields.chunks_exact(n))
                    .filter(|((c, _), _)| **c != 0.0)
                    .map(|((c, d), f)| ([c * d[0], c * d[1], c * d[2]], f))
            };
            let mut general = mean.clone();
            fold_factored_all(comps(), &mut general);
            let mut passes = mean.clone();
            fold_axis_all::<0, _>(comps().map(|(d, f)| (d[0], f)), &mut passes);
            fold_axis_all::<1, _>(comps().map(|(d, f)| (d[1], f)), &mut passes);
            fold_axis_all::<2, _>(comps().map(|(d, f)| (d[2], f)), &mut passes);
            assert_eq!(bits(&passes), bits(&general));
            let mut instance = mean.clone();
            FactoredBasis::new(&fields, &dirs, n).unwrap().add_instance(&coeffs, &mut instance).unwrap();
            assert_eq!(bits(&instance), bits(&general));
        }
    }
}
