//! The iBUG-68 landmark convention's left-right symmetry: which point is whose mirror image.

/// The iBUG-68 bilateral pairs `(image-left, image-right)` in a frontal view
/// (point 0 is the subject's right jaw end, seen on the image's left).
pub const IBUG68_MIRROR_PAIRS: [(usize, usize); 29] = [
    (0, 16),
    (1, 15),
    (2, 14),
    (3, 13),
    (4, 12),
    (5, 11),
    (6, 10),
    (7, 9),
    (17, 26),
    (18, 25),
    (19, 24),
    (20, 23),
    (21, 22),
    (31, 35),
    (32, 34),
    (36, 45),
    (37, 44),
    (38, 43),
    (39, 42),
    (40, 47),
    (41, 46),
    (48, 54),
    (49, 53),
    (50, 52),
    (59, 55),
    (58, 56),
    (60, 64),
    (61, 63),
    (67, 65),
];

/// Number of iBUG-68 landmarks.
pub const IBUG68_POINTS: usize = 68;

/// The point that `k` becomes in a mirror image (itself on the midline; `k` past 67 too).
pub fn ibug68_partner(k: usize) -> usize {
    IBUG68_MIRROR_PAIRS
        .iter()
        .find_map(|&(a, b)| {
            if a == k {
                Some(b)
            } else if b == k {
                Some(a)
            } else {
                None
            }
        })
        .unwrap_or(k)
}

/// iBUG-68 points of an image `width` px wide as its mirror image shows them: x becomes
/// `width − x` and each point takes its mirror partner's place, so point 36 stays the image-left
/// outer eye corner. A point whose partner is missing from `points` is left out.
pub fn mirrored_ibug68(points: &[[f32; 2]], width: f32) -> impl Iterator<Item = [f32; 2]> + '_ {
    (0..points.len()).filter_map(move |k| points.get(ibug68_partner(k))).map(move |&[x, y]| [width - x, y])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn partners_are_an_involution_over_the_68_points() {
        let mut midline = 0;
        for k in 0..IBUG68_POINTS {
            let p = ibug68_partner(k);
            assert!(p < IBUG68_POINTS);
            assert_eq!(ibug68_partner(p), k);
            midline += usize::from(p == k);
        }
        // Jaw tip, nose bridge and tip, centre of the nostrils, lips' centres: 10 points.
        assert_eq!(midline, 68 - 2 * IBUG68_MIRROR_PAIRS.len());
        assert_eq!(ibug68_partner(36), 45);
        assert_eq!(ibug68_partner(30), 30);
    }

    #[test]
    fn mirrored_points_swap_partners_and_mirror_back() {
        let points: [[f32; 2]; IBUG68_POINTS] = core::array::from_fn(|k| [k as f32, 100.0 + k as f32]);
        let mut once = [[0.0f32; 2]; IBUG68_POINTS];
        for (slot, p) in once.iter_mut().zip(mirrored_ibug68(&points, 200.0)) {
            *slot = p;
        }
        assert_eq!(once[36], [200.0 - 45.0, 145.0]);
        assert_eq!(once[30], [170.0, 130.0]);
        assert!(mirrored_ibug68(&once, 200.0).eq(points.iter().copied()));
        // A partner past the points given is left out, not read: of jaw points 0-9 only 7, 8
        // and 9 have theirs (9, 8, 7) among them.
        assert!(mirrored_ibug68(&points[..10], 200.0).eq([[191.0, 109.0], [192.0, 108.0], [193.0, 107.0]]));
    }
}
