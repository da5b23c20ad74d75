//! Statistical models from examples in correspondence: principal component analysis with dense
//! bases ([`covariance_basis`], [`pca_model`]), as the 10-scan PCA baseline of the paper.
//!
//! For `m` deviation vectors `d_j` (3N values each) and a factor `f`, the covariance is
//! `C = f Σ_j d_j d_jᵀ`. Its non-zero eigenpairs come from the small `m × m` Gram matrix
//! `G = f DᵀD = V Λ Vᵀ`: `C (D v_k) = λ_k (D v_k)` and `|D v_k|² = λ_k / f`, so the basis scaled by
//! `sqrt(λ_k)` (what a model file stores) is `sqrt(f) D v_k`.

use crate::gp::model::{GpModel, ModelMetadata, ModelPart, PartBasis};
use crate::mesh::template::Provenance;
use crate::mesh::Mesh;

use crate::eval::EvalError;

/// Eigenvalues (descending) and the scaled dense basis (`rank × values`, row-major) of `f Σ d_j d_jᵀ`.
///
/// Keeps at most `max_rank` components and drops those below `1e-10` of the largest eigenvalue.
pub fn covariance_basis(deviations: &[Vec<f64>], factor: f64, max_rank: usize) -> Result<(Vec<f64>, Vec<Vec<f64>>), EvalError> {
    let m = deviations.len();
    let Some(len) = deviations.first().map(Vec::len) else {
        return Ok((Vec::new(), Vec::new()));
    };
    if deviations.iter().any(|d| d.len() != len) {
        return Err(EvalError::Invalid("the examples do not have the same number of values".into()));
    }
    if !(factor.is_finite() && factor > 0.0) {
        return Err(EvalError::Invalid(format!("covariance factor {factor} must be positive")));
    }
    let gram = faer::Mat::from_fn(m, m, |i, j| factor * deviations[i].iter().zip(&deviations[j]).map(|(a, b)| a * b).sum::<f64>());
    let eig = gram.self_adjoint_eigen(faer::Side::Lower).map_err(|e| EvalError::Invalid(format!("eigendecomposition failed: {e:?}")))?;
    let values = eig.S().column_vector();
    let mut order: Vec<usize> = (0..m).collect();
    order.sort_by(|&a, &b| values[b].total_cmp(&values[a]));
    let top = order.first().map_or(0.0, |&k| values[k]).max(0.0);
    let mut eigenvalues = Vec::new();
    let mut basis = Vec::new();
    let u = eig.U();
    for &k in order.iter().take(max_rank) {
        let lambda = values[k];
        if !(lambda > 1e-10 * top && lambda > 0.0) {
            break;
        }
        let mut b = vec![0.0f64; len];
        for (j, d) in deviations.iter().enumerate() {
            let w = factor.sqrt() * u[(j, k)];
            for (bi, di) in b.iter_mut().zip(d) {
                *bi += w * di;
            }
        }
        eigenvalues.push(lambda);
        basis.push(b);
    }
    Ok((eigenvalues, basis))
}

/// A model part from a mean and a scaled dense basis.
pub fn dense_part(mean: &[[f64; 3]], eigenvalues: Vec<f64>, basis: &[Vec<f64>]) -> ModelPart {
    ModelPart {
        mean: mean.iter().map(|p| p.map(|v| v as f32)).collect(),
        eigenvalues,
        basis: PartBasis::Dense { values: basis.iter().flatten().map(|&v| v as f32).collect() },
    }
}

/// Metadata of a model that was not built from a kernel (`kernel` names what it is).
pub fn learned_metadata(kernel: &str, shape_trace: f64, color_trace: f64, source: &str, attribution: &str) -> ModelMetadata {
    let template = Provenance {
        source: source.into(),
        attribution: Some(attribution.into()),
        scale_mm_per_unit: 1.0,
        cropped: true,
        ..Provenance::default()
    };
    let created_by = concat!("gpmm ", env!("CARGO_PKG_VERSION")).into();
    ModelMetadata::without_kernel(kernel, [shape_trace, color_trace], "ibug68".into(), template, created_by)
}

/// Every scaled component of `part` as a dense `3N` vector, times `w`.
fn scaled_components(part: &crate::gp::model::ModelPart, w: f64) -> Vec<Vec<f64>> {
    let basis = crate::fit::register::basis_matrix(part, part.rank());
    (0..basis.ncols()).map(|j| (0..basis.nrows()).map(|r| w * basis[(r, j)]).collect()).collect()
}

fn mean_of(items: &[&[[f64; 3]]]) -> Vec<[f64; 3]> {
    let n = items.first().map_or(0, |v| v.len());
    let mut mean = vec![[0.0; 3]; n];
    for v in items {
        for (m, p) in mean.iter_mut().zip(v.iter()) {
            for k in 0..3 {
                m[k] += p[k] / items.len() as f64;
            }
        }
    }
    mean
}

fn deviations(items: &[&[[f64; 3]]], mean: &[[f64; 3]]) -> Vec<Vec<f64>> {
    items.iter().map(|v| v.iter().zip(mean).flat_map(|(p, m)| [p[0] - m[0], p[1] - m[1], p[2] - m[2]]).collect()).collect()
}

/// PCA model (shape and colour, sample covariance `1/(m-1)`) of meshes in correspondence
/// (same vertex count and order); the topology and `landmarks` are taken as given.
pub fn pca_model(
    meshes: &[Mesh],
    triangles: &[[u32; 3]],
    landmarks: &[u32],
    kernel: &str,
    source: &str,
    attribution: &str,
) -> Result<GpModel, EvalError> {
    pca_beside(meshes, None, triangles, landmarks, kernel, source, attribution)
}

/// The covariance a learned model keeps of its predecessor beside its examples' (see
/// [`pca_beside`]).
#[derive(Debug, Clone, Copy)]
pub struct KeptCovariance<'a> {
    /// The predecessor.
    pub model: &'a GpModel,
    /// The share of its covariance kept (> 0).
    pub share: f64,
    /// Components of the result at most.
    pub max_rank: usize,
}

/// [`pca_model`] whose covariance also keeps `share` times `kept.model`'s (shape and colour):
/// `C = S + share · C_prev`, with `S` the examples' sample covariance around their mean. Without
/// it a model learned from its own fits can only lose variance (each fit is shrunk toward the
/// model it was fitted with); with it, directions the examples do not vary in keep some of the
/// predecessor's. The eigenbasis of the sum comes from the same Gram matrix, the predecessor's
/// scaled components standing as further deviation vectors.
pub fn pca_beside(
    meshes: &[Mesh],
    kept: Option<KeptCovariance<'_>>,
    triangles: &[[u32; 3]],
    landmarks: &[u32],
    kernel: &str,
    source: &str,
    attribution: &str,
) -> Result<GpModel, EvalError> {
    if meshes.len() < 2 {
        return Err(EvalError::Invalid(format!("a PCA model needs at least 2 examples, got {}", meshes.len())));
    }
    let n = meshes[0].positions.len();
    if meshes.iter().any(|m| m.positions.len() != n || m.colors.len() != n) {
        return Err(EvalError::Invalid("the PCA examples are not in correspondence (vertex counts differ)".into()));
    }
    if let Some(k) = &kept {
        if k.model.vertices() != n {
            return Err(EvalError::Invalid(format!("the kept model has {} vertices, the examples {n}", k.model.vertices())));
        }
        if !(k.share.is_finite() && k.share > 0.0) {
            return Err(EvalError::Invalid(format!("the kept covariance share {} must be positive", k.share)));
        }
    }
    let factor = 1.0 / (meshes.len() - 1) as f64;
    let shapes: Vec<&[[f64; 3]]> = meshes.iter().map(|m| m.positions.as_slice()).collect();
    let colors: Vec<&[[f64; 3]]> = meshes.iter().map(|m| m.colors.as_slice()).collect();
    let (ms, mc) = (mean_of(&shapes), mean_of(&colors));
    let (mut ds, mut dc) = (deviations(&shapes, &ms), deviations(&colors, &mc));
    let mut max_rank = meshes.len();
    if let Some(k) = kept {
        // f · e eᵀ = share · b bᵀ for e = sqrt(share / f) · b.
        let w = (k.share / factor).sqrt();
        ds.extend(scaled_components(&k.model.shape, w));
        dc.extend(scaled_components(&k.model.color, w));
        max_rank = k.max_rank;
    }
    let (es, bs) = covariance_basis(&ds, factor, max_rank)?;
    let (ec, bc) = covariance_basis(&dc, factor, max_rank)?;
    let (ts, tc) = (es.iter().sum(), ec.iter().sum());
    Ok(GpModel {
        shape: dense_part(&ms, es, &bs),
        color: dense_part(&mc, ec, &bc),
        triangles: triangles.to_vec(),
        landmarks: landmarks.to_vec(),
        metadata: learned_metadata(kernel, ts, tc, source, attribution),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn covariance_basis_reproduces_the_covariance() {
        let d: Vec<Vec<f64>> = (0..4).map(|j| (0..9).map(|i| ((i * 7 + j * 3) as f64 * 0.37).sin()).collect()).collect();
        let f = 0.25;
        let (ev, b) = covariance_basis(&d, f, 10).unwrap();
        assert!(ev.windows(2).all(|w| w[0] >= w[1]));
        for i in 0..9 {
            for j in 0..9 {
                let c: f64 = f * d.iter().map(|v| v[i] * v[j]).sum::<f64>();
                let r: f64 = b.iter().map(|v| v[i] * v[j]).sum();
                assert!((c - r).abs() < 1e-10, "{c} {r}");
            }
        }
        for (e, v) in ev.iter().zip(&b) {
            assert!((v.iter().map(|x| x * x).sum::<f64>() - e).abs() < 1e-10);
        }
    }

    /// A triangle whose first two vertices lie `s` out along x and y.
    fn triangle(s: f64) -> Mesh {
        Mesh { positions: vec![[s, 0.0, 0.0], [0.0, s, 0.0], [0.0, 0.0, 1.0]], colors: vec![[0.5; 3]; 3], triangles: vec![[0, 1, 2]] }
    }

    #[test]
    fn pca_of_two_meshes_has_one_component_through_both() {
        let m = triangle;
        let model = pca_model(&[m(1.0), m(3.0)], &[[0, 1, 2]], &[0, 1, 2], "pca", "test", "test").unwrap();
        assert_eq!(model.shape.rank(), 1);
        assert_eq!(model.color.rank(), 0);
        let a = model.instance(&[1.0], &[]).unwrap();
        let b = model.instance(&[-1.0], &[]).unwrap();
        let (hi, lo) = if a.positions[0][0] > b.positions[0][0] { (a, b) } else { (b, a) };
        // Sample variance of {1, 3} is 2 per coordinate: the mean ± one standard deviation per coordinate.
        assert!((hi.positions[0][0] - (2.0 + 2f64.sqrt())).abs() < 1e-5 && (lo.positions[1][1] - (2.0 - 2f64.sqrt())).abs() < 1e-5);
    }

    #[test]
    fn a_kept_share_adds_the_predecessors_covariance() {
        let m = triangle;
        let examples = [m(1.0), m(3.0)];
        // The predecessor: one component moving vertex 2 along z by 2 (variance 4), which the
        // examples never move.
        let mut prev = pca_model(&examples, &[[0, 1, 2]], &[0, 1, 2], "pca", "test", "test").unwrap();
        prev.shape = dense_part(&[[0.0; 3]; 3], vec![4.0], &[vec![0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.0]]);
        let kept = KeptCovariance { model: &prev, share: 0.25, max_rank: 10 };
        let model = pca_beside(&examples, Some(kept), &[[0, 1, 2]], &[0, 1, 2], "pca", "test", "test").unwrap();
        // Two components: the examples' (variance 2 on each of two coordinates: eigenvalue 4) and
        // a quarter of the predecessor's (eigenvalue 1).
        assert_eq!(model.shape.rank(), 2);
        assert!(
            (model.shape.eigenvalues[0] - 4.0).abs() < 1e-9 && (model.shape.eigenvalues[1] - 1.0).abs() < 1e-9,
            "{:?}",
            model.shape.eigenvalues
        );
        let z = model.instance(&[0.0, 1.0], &[]).unwrap();
        // One standard deviation of it moves vertex 2 by 1 along z (the kept variance 0.25 · 4 = 1).
        assert!(((z.positions[2][2] - 1.0).abs() - 1.0).abs() < 1e-5, "{:?}", z.positions);
        assert_eq!(model.instance(&[], &[]).unwrap().positions[0][0], 2.0);
        let refused = KeptCovariance { model: &prev, share: -1.0, max_rank: 10 };
        assert!(pca_beside(&examples, Some(refused), &[[0, 1, 2]], &[0, 1, 2], "pca", "test", "test").is_err());
    }
}
