//! The blocked passes' common loop: components handed on four at a time, the rest one by one.

use crate::geometry::Vec3;

/// Hands the components `(d, values)` to `four` in blocks of four and the rest to `one`, in
/// their order (the blocked passes of `fold_factored_all`, `gather_factored_all` and
/// `fold_dense_all`).
pub(super) fn in_blocks_of_four<'v, M: Copy + Default, Q: 'v>(
    comps: impl Iterator<Item = (M, &'v [Q])>,
    out: &mut [Vec3],
    four: impl Fn(&[(M, &'v [Q]); 4], &mut [Vec3]),
    one: impl Fn(M, &'v [Q], &mut [Vec3]),
) {
    let mut block: [(M, &[Q]); 4] = [(M::default(), &[]); 4];
    let mut filled = 0;
    for comp in comps {
        if let Some(slot) = block.get_mut(filled) {
            *slot = comp;
            filled += 1;
        }
        if filled == block.len() {
            four(&block, out);
            filled = 0;
        }
    }
    for (d, values) in block.iter().take(filled) {
        one(*d, values, out);
    }
}
