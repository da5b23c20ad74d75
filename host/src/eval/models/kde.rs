//! The multi-scan kernel density estimate (KDE) of the paper: several single-scan models, one per
//! coloured scan (each the symmetric-full kernel around its scan: mean = that scan), used together.
//!
//! Every image is fitted with every component. A probe is compared with a gallery identity by the
//! best cosine similarity over the components, each within its own coefficient space (coefficients
//! of different components are not comparable): `score(p, g) = max_c cos(f_c(p), f_c(g))`, and the
//! probe is identified as the gallery identity of the highest score. A plain model is the special
//! case of one component, so [`score`] serves every row of the recognition table.

use crate::eval::cosine;

/// `max_c cos(probe[c], gallery[c])` over the components where both fits exist (`None` if none does).
pub fn score(probe: &[Option<&[f32]>], gallery: &[Option<&[f32]>]) -> Option<f64> {
    probe
        .iter()
        .zip(gallery)
        .filter_map(|(p, g)| match (p, g) {
            (Some(p), Some(g)) => Some(cosine(p, g)),
            _ => None,
        })
        .reduce(f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kde_score_takes_the_best_component() {
        let (a, b, c) = ([1.0f32, 0.0], [0.0f32, 1.0], [1.0f32, 1.0]);
        // Component 0 says "orthogonal", component 1 says "identical": the KDE score is 1.
        let s = score(&[Some(&a), Some(&c)], &[Some(&b), Some(&c)]).unwrap();
        assert!((s - 1.0).abs() < 1e-12);
        // A failed fit leaves its component out.
        let s = score(&[Some(&a), None], &[Some(&c), Some(&c)]).unwrap();
        assert!((s - std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-12);
        assert_eq!(score(&[None], &[Some(&a)]), None);
    }
}
