//! Multiply-add passes of dense basis sums (component `k` stores three values per vertex), used by
//! [`super::DenseBasis`] and the dense layout of [`super::QuantizedBasis`].

use super::blocks::in_blocks_of_four;
use super::Vec3;

/// Multiply-adds `out[v][a] += m · q[v][a]` for the components `(m, values)` in their order, four
/// per pass over `out`: each entry sums the same terms in the same order as one pass per
/// component (the same bits), with a quarter of the loads and stores of `out`.
pub(super) fn fold_dense_all<'v, Q: Copy + Into<f32> + 'v>(comps: impl Iterator<Item = (f32, &'v [Q])>, out: &mut [Vec3]) {
    in_blocks_of_four(comps, out, |block, out| fold_dense4(block, out), |m, values, out| fold_dense(m, values, out));
}

/// Four components of [`fold_dense`] in one pass (one at a time if a component is short).
fn fold_dense4<Q: Copy + Into<f32>>(block: &[(f32, &[Q]); 4], out: &mut [Vec3]) {
    let [(m0, f0), (m1, f1), (m2, f2), (m3, f3)] = *block;
    let flat = out.as_flattened_mut();
    let n = flat.len();
    let (Some(f0), Some(f1), Some(f2), Some(f3)) = (f0.get(..n), f1.get(..n), f2.get(..n), f3.get(..n)) else {
        for (m, values) in block {
            fold_dense(*m, values, out);
        }
        return;
    };
    for ((((o, &q0), &q1), &q2), &q3) in flat.iter_mut().zip(f0).zip(f1).zip(f2).zip(f3) {
        *o = *o + m0 * q0.into() + m1 * q1.into() + m2 * q2.into() + m3 * q3.into();
    }
}

/// Multiply-adds `out[v][a] += m · q[v][a]` over one component's values.
fn fold_dense<Q: Copy + Into<f32>>(m: f32, values: &[Q], out: &mut [Vec3]) {
    for (o, &q) in out.as_flattened_mut().iter_mut().zip(values) {
        *o += m * q.into();
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    /// One pass per component, in order: the sums the blocked passes must reproduce bit for bit.
    fn reference<Q: Copy + Into<f32>>(comps: &[(f32, Vec<Q>)], out: &mut [Vec3]) {
        for (m, values) in comps {
            for (o, q) in out.iter_mut().zip(values.chunks_exact(3)) {
                for a in 0..3 {
                    o[a] += m * q[a].into();
                }
            }
        }
    }

    #[test]
    fn blocked_passes_give_the_bits_of_one_pass_per_component() {
        let n = 37;
        // Awkward magnitudes, so that a different order of the sums would round differently.
        let value = |k: usize, i: usize| ((k * 7919 + i * 104_729) % 2003) as f32 * 1e-3 - 1.0 + 1e-7 * (i as f32);
        for rank in 0..11 {
            let comps: Vec<(f32, Vec<f32>)> = (0..rank)
                .map(|k| (0.3 + k as f32 * 1.7e-2, (0..3 * n).map(|i| value(k, i) * 10f32.powi(k as i32 % 4)).collect()))
                .collect();
            let start: Vec<Vec3> = (0..n).map(|v| [v as f32 * 0.1, 1.0 / (v as f32 + 1.0), -0.5]).collect();
            let (mut want, mut got) = (start.clone(), start.clone());
            reference(&comps, &mut want);
            fold_dense_all(comps.iter().map(|(m, v)| (*m, v.as_slice())), &mut got);
            assert!(want.iter().zip(&got).all(|(a, b)| a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())), "rank {rank}");
            // Integer values (the quantized layout) the same way.
            let ints: Vec<(f32, Vec<i16>)> =
                comps.iter().map(|(m, v)| (*m * 1e-3, v.iter().map(|x| (x * 1000.0) as i16).collect())).collect();
            let (mut want, mut got) = (start.clone(), start);
            reference(&ints, &mut want);
            fold_dense_all(ints.iter().map(|(m, v)| (*m, v.as_slice())), &mut got);
            assert!(want.iter().zip(&got).all(|(a, b)| a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())), "rank {rank}, i16");
        }
    }

    #[test]
    fn a_short_component_adds_what_it_has() {
        let mut out = vec![[0.0f32; 3]; 2];
        let full = [1.0f32; 6];
        let short = [1.0f32; 4];
        let comps = [(1.0, &full[..]), (2.0, &short[..]), (1.0, &full[..]), (1.0, &full[..])];
        fold_dense_all(comps.into_iter(), &mut out);
        assert_eq!(out, [[5.0, 5.0, 5.0], [5.0, 3.0, 3.0]]);
    }
}
