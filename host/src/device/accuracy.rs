//! How far a quantized model is from the float model it came from: the quantization error over
//! random coefficient draws, and the simplification error of the mean surface.

use crate::device::quantize::{QuantizeError, QuantizedModel};
use crate::gp::model::GpModel;
use crate::mesh::closest::closest_on_triangle;
use crate::mesh::geometry::dist2;
use gpmm_core::format::blob::ModelBlob;
use gpmm_core::geometry::Vec3;
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;
use rand_xoshiro::Xoshiro256PlusPlus;

/// How far a blob is from the float model it was quantized from, over random coefficients.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct QuantizationStats {
    /// Coefficient draws (all coefficients N(0, 1)).
    pub draws: usize,
    /// Seed of the draws.
    pub seed: u64,
    /// RMS over draws and vertices of the position distance (mm).
    pub shape_rms_mm: f64,
    /// Largest position distance (mm).
    pub shape_max_mm: f64,
    /// RMS over draws and vertices of the RGB distance (colours on [0, 1], not clamped).
    pub color_rms: f64,
    /// Largest RGB distance.
    pub color_max: f64,
}

fn distance(a: Vec3, b: Vec3) -> f64 {
    a.iter().zip(&b).map(|(x, y)| (f64::from(*x) - f64::from(*y)).powi(2)).sum::<f64>().sqrt()
}

/// Compares `reference` (the float model of the same vertices and ranks, e.g.
/// [`QuantizedModel::reduced`]) with `blob` over `draws` random coefficient vectors.
pub fn quantization_error(reference: &GpModel, blob: &ModelBlob<'_>, draws: usize, seed: u64) -> Result<QuantizationStats, QuantizeError> {
    if reference.vertices() != blob.vertices() || reference.shape.rank() != blob.rank_shape() || reference.color.rank() != blob.rank_color()
    {
        return Err(QuantizeError::Model(format!(
            "the reference model ({} vertices, ranks {}/{}) does not match the blob ({} vertices, ranks {}/{})",
            reference.vertices(),
            reference.shape.rank(),
            reference.color.rank(),
            blob.vertices(),
            blob.rank_shape(),
            blob.rank_color()
        )));
    }
    let model_err = |e: gpmm_core::model::ModelError| QuantizeError::Model(e.to_string());
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let (mut s2, mut smax, mut c2, mut cmax, mut count) = (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0usize);
    for _ in 0..draws {
        let a: Vec<f32> = (0..blob.rank_shape()).map(|_| rng.sample(StandardNormal)).collect();
        let b: Vec<f32> = (0..blob.rank_color()).map(|_| rng.sample(StandardNormal)).collect();
        let want_s = reference.shape.instance(&a).map_err(model_err)?;
        let want_c = reference.color.instance(&b).map_err(model_err)?;
        let mut got_s = blob.shape_mean().to_vec();
        blob.shape_basis().add_instance(&a, &mut got_s).map_err(model_err)?;
        let mut got_c = blob.color_mean().to_vec();
        blob.color_basis().add_instance(&b, &mut got_c).map_err(model_err)?;
        for i in 0..want_s.len() {
            let ds = distance(want_s[i], got_s[i]);
            let dc = distance(want_c[i], got_c[i]);
            s2 += ds * ds;
            c2 += dc * dc;
            smax = smax.max(ds);
            cmax = cmax.max(dc);
        }
        count += want_s.len();
    }
    let rms = |sum: f64| if count > 0 { (sum / count as f64).sqrt() } else { 0.0 };
    Ok(QuantizationStats { draws, seed, shape_rms_mm: rms(s2), shape_max_mm: smax, color_rms: rms(c2), color_max: cmax })
}

/// What simplification costs: distances of the source mean shape's vertices to the simplified mean surface.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct SimplificationStats {
    /// Source vertices.
    pub source_vertices: usize,
    /// Kept vertices.
    pub kept_vertices: usize,
    /// RMS over all source vertices of the distance to the simplified surface (mm; kept vertices count as 0).
    pub mean_shape_rms_mm: f64,
    /// Largest distance (mm).
    pub mean_shape_max_mm: f64,
}

type P3 = [f64; 3];

/// Squared distance from `p` to triangle `t` (the closest point of [`closest_on_triangle`]).
fn point_triangle_dist2(p: P3, t: [P3; 3]) -> f64 {
    dist2(closest_on_triangle(p, t).0, p)
}

/// Distances of every vertex of `source`'s mean shape to the mean surface of `q` (its simplification).
pub fn simplification_error(source: &GpModel, q: &QuantizedModel) -> SimplificationStats {
    let p64 = |v: Vec3| v.map(f64::from);
    let tris: Vec<[P3; 3]> = q.reduced.triangles.iter().map(|t| t.map(|i| p64(q.reduced.shape.mean[i as usize]))).collect();
    let boxes: Vec<(P3, P3)> = tris
        .iter()
        .map(|t| {
            let lo = [0, 1, 2].map(|a| t[0][a].min(t[1][a]).min(t[2][a]));
            let hi = [0, 1, 2].map(|a| t[0][a].max(t[1][a]).max(t[2][a]));
            (lo, hi)
        })
        .collect();
    let mut kept = vec![false; source.vertices()];
    for &k in &q.kept {
        kept[k as usize] = true;
    }
    let (mut sum, mut max) = (0.0f64, 0.0f64);
    for (v, &p) in source.shape.mean.iter().enumerate() {
        if kept[v] {
            continue;
        }
        let p = p64(p);
        let mut best = f64::INFINITY;
        for (t, (lo, hi)) in tris.iter().zip(&boxes) {
            let outside: f64 = (0..3).map(|a| (lo[a] - p[a]).max(0.0).max(p[a] - hi[a]).powi(2)).sum();
            if outside < best {
                best = best.min(point_triangle_dist2(p, *t));
            }
        }
        if best.is_finite() {
            sum += best;
            max = max.max(best.sqrt());
        }
    }
    let n = source.vertices().max(1);
    SimplificationStats {
        source_vertices: source.vertices(),
        kept_vertices: q.kept.len(),
        mean_shape_rms_mm: (sum / n as f64).sqrt(),
        mean_shape_max_mm: max,
    }
}
