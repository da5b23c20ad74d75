//! Reconstruction error (`gpmm eval reconstruction`): the 3D face a fit recovers from one image
//! against the true face of a set with known truth, measured as the NoW benchmark measures it.
//!
//! For each image of a `gpmm synth` set (or an independent renderer's set made from one), the fit's
//! shape coefficients give a mesh in the model's topology. The true face is the image's identity
//! cut to the face region ([`crate::eval::models::scans::EvalWorld::cropped_scan`]: the template's face
//! crop carried over to the ICT topology, the same part of the face the models cover). Then:
//! 1. **Landmark alignment**: the similarity transform (rotation, translation, scale) taking the
//!    fitted mesh's inner iBUG landmarks (17–67; the jaw contour is not the same anatomy on two
//!    faces) onto the true face's.
//! 2. **Refinement**: [`ALIGNMENT_ITERATIONS`] rounds of closest points from every true vertex to
//!    the fitted surface (pairs whose nearest fitted vertex lies on the border, or farther than
//!    three times the median and 5 mm, left out), each followed by the least-squares similarity.
//!    NoW aligns the same way (landmarks, then the scan-to-mesh distance; scale included, since
//!    a single image does not fix a face's size).
//! 3. **Distance**: for every true vertex, the distance to the closest point of the fitted surface
//!    (mm). Every vertex counts, as in NoW; the share whose closest point lies on the fitted mesh's
//!    border is reported beside it.
//!
//! Per image, the median, mean and standard deviation of the distances; per |yaw| and over the set,
//! the same over all distances of those images pooled. The model's mean shape, aligned the same way
//! to each true face, is the reference a fit must beat.

pub mod report;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::eval::model_frame::ALIGNED_LANDMARKS;
use crate::eval::models::scans::{EvalWorld, Scan};
use crate::eval::recognition::fits::ImageFit;
use crate::eval::EvalError;
use crate::fit::register::{basis_instance, basis_matrix, PreparedTarget};
use crate::fit::{Z50, Z90};
use crate::gp::model::GpModel;
use crate::mesh::align::Similarity;
use crate::mesh::geometry::dist2;
use crate::mesh::Mesh;

/// Closest-point refinement rounds after the landmark alignment.
pub const ALIGNMENT_ITERATIONS: usize = 10;

/// Distance statistics (mm).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Distances {
    /// Median.
    pub median_mm: f64,
    /// Mean.
    pub mean_mm: f64,
    /// Standard deviation.
    pub std_mm: f64,
    /// Distances measured.
    pub count: usize,
}

impl Distances {
    /// The statistics of `d` (NaN for no distances).
    pub fn of(d: &[f64]) -> Self {
        let n = d.len();
        if n == 0 {
            return Self { median_mm: f64::NAN, mean_mm: f64::NAN, std_mm: f64::NAN, count: 0 };
        }
        let mut s = d.to_vec();
        s.sort_by(f64::total_cmp);
        let median_mm = if n % 2 == 1 { s[n / 2] } else { 0.5 * (s[n / 2 - 1] + s[n / 2]) };
        let mean_mm = s.iter().sum::<f64>() / n as f64;
        let std_mm = (s.iter().map(|x| (x - mean_mm).powi(2)).sum::<f64>() / n as f64).sqrt();
        Self { median_mm, mean_mm, std_mm, count: n }
    }
}

/// The true face against one fitted mesh: its distances and how it was aligned.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanToMesh {
    /// Per true vertex, the distance to the fitted surface after alignment (mm).
    pub distances: Vec<f64>,
    /// Share of true vertices whose closest fitted point lies on the fitted mesh's border.
    pub border_fraction: f64,
    /// Scale of the final alignment (fitted mesh to true face).
    pub scale: f64,
    /// Per true vertex, the fitted mesh's spread along the normal at its closest point (mm, in the
    /// true face's scale), interpolated from the vertices' spreads given as the fitted mesh's
    /// colour (its first channel); meaningless for a mesh without them.
    pub spread_mm: Vec<f64>,
    /// Per true vertex, whether its closest fitted point's nearest vertex lies on the border.
    pub on_border: Vec<bool>,
}

/// Aligns `fitted` (with its iBUG-68 landmark vertices `landmarks`) to the true face `truth` and
/// measures the distance from every true vertex to the fitted surface (see the module docs).
pub fn scan_to_mesh(fitted: &Mesh, landmarks: &[u32], truth: &Scan) -> Result<ScanToMesh, EvalError> {
    let bad = |what: &str| EvalError::Invalid(format!("reconstruction of identity {}: {what}", truth.id));
    if landmarks.len() != 68 || truth.landmarks.len() != 68 {
        return Err(bad("the fitted and the true face need the 68 iBUG landmarks"));
    }
    let point = |m: &Mesh, v: u32| m.positions.get(v as usize).copied().ok_or_else(|| bad("a landmark vertex is past its mesh"));
    let src = ALIGNED_LANDMARKS.map(|k| point(fitted, landmarks[k])).collect::<Result<Vec<_>, _>>()?;
    let dst = ALIGNED_LANDMARKS.map(|k| point(&truth.mesh, truth.landmarks[k])).collect::<Result<Vec<_>, _>>()?;
    let mut align = Similarity::fit(&src, &dst).ok_or_else(|| bad("the landmarks cannot be aligned"))?;
    let mut moved = fitted.clone();
    for _ in 0..ALIGNMENT_ITERATIONS {
        moved.positions = fitted.positions.iter().map(|p| align.apply(*p)).collect();
        let target = PreparedTarget::new(moved.clone(), None)?;
        let hits: Vec<([f64; 3], bool)> = truth
            .mesh
            .positions
            .iter()
            .map(|q| {
                let (p, _, border) = target.closest(*q);
                (p, border)
            })
            .collect();
        let d: Vec<f64> = truth.mesh.positions.iter().zip(&hits).map(|(q, (p, _))| dist2(*p, *q).sqrt()).collect();
        let mut inner: Vec<f64> = d.iter().zip(&hits).filter(|(_, h)| !h.1).map(|(x, _)| *x).collect();
        inner.sort_by(f64::total_cmp);
        let cut = (3.0 * inner.get(inner.len() / 2).copied().unwrap_or(0.0)).max(5.0);
        // Pairs: each kept true vertex with its closest fitted point, mapped back to the fitted
        // mesh's own frame so that the refined similarity replaces the current one.
        let keep: Vec<usize> = (0..d.len()).filter(|&i| !hits[i].1 && d[i] <= cut).collect();
        let refined = (keep.len() >= 3)
            .then(|| {
                let src: Vec<[f64; 3]> = keep.iter().map(|&i| inverse(&align, hits[i].0)).collect();
                let dst: Vec<[f64; 3]> = keep.iter().map(|&i| truth.mesh.positions[i]).collect();
                Similarity::fit(&src, &dst)
            })
            .flatten();
        match refined {
            Some(r) => align = r,
            None => return Err(bad("too few true vertices reach the fitted surface")),
        }
    }
    moved.positions = fitted.positions.iter().map(|p| align.apply(*p)).collect();
    let target = PreparedTarget::new(moved, None)?;
    let hits: Vec<(f64, f64, bool)> = truth
        .mesh
        .positions
        .iter()
        .map(|q| {
            let (p, spread, on_border) = target.closest(*q);
            (dist2(p, *q).sqrt(), spread[0] * align.scale, on_border)
        })
        .collect();
    let border = hits.iter().filter(|h| h.2).count();
    let border_fraction = border as f64 / hits.len().max(1) as f64;
    Ok(ScanToMesh {
        distances: hits.iter().map(|h| h.0).collect(),
        border_fraction,
        scale: align.scale,
        spread_mm: hits.iter().map(|h| h.1).collect(),
        on_border: hits.iter().map(|h| h.2).collect(),
    })
}

/// `p` mapped back through the similarity `s` (its inverse: `Rᵀ (p − t) / s`).
fn inverse(s: &Similarity, p: [f64; 3]) -> [f64; 3] {
    let d = [p[0] - s.trans[0], p[1] - s.trans[1], p[2] - s.trans[2]];
    [0, 1, 2].map(|j| (s.rot[0][j] * d[0] + s.rot[1][j] * d[1] + s.rot[2][j] * d[2]) / s.scale)
}

/// One image's reconstruction error.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ImageReconstruction {
    /// Image file name.
    pub image: String,
    /// Identity number.
    pub identity: usize,
    /// True yaw (degrees).
    pub yaw_deg: f32,
    /// The fit's distances.
    pub fit: Distances,
    /// The model's mean shape's distances (the same alignment), for reference.
    pub mean_shape: Distances,
    /// Share of true vertices whose closest fitted point lies on the fitted border.
    pub border_fraction: f64,
    /// Scale of the fit's alignment.
    pub scale: f64,
    /// How often the fit's reported vertex spread holds the true surface (`None` when the fit
    /// reported none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coverage: Option<SurfaceCoverage>,
}

/// How often a fit's per-vertex intervals along the normal (± z · sd) hold the true surface:
/// the share of the true vertices (their closest fitted point off the border) within
/// [`Z50`] and [`Z90`] standard deviations of the fitted surface.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SurfaceCoverage {
    /// Share within the 50 % interval (ideal 0.5).
    pub covered_50: f64,
    /// Share within the 90 % interval (ideal 0.9).
    pub covered_90: f64,
    /// Median reported standard deviation at the true vertices' closest points (mm).
    pub median_sd_mm: f64,
    /// True vertices counted.
    pub count: usize,
}

impl SurfaceCoverage {
    /// The coverage of `m`'s distances by its spreads (`None` without vertices off the border).
    pub fn of(m: &ScanToMesh) -> Option<Self> {
        let kept: Vec<(f64, f64)> =
            m.distances.iter().zip(&m.spread_mm).zip(&m.on_border).filter(|(_, b)| !**b).map(|((d, s), _)| (*d, *s)).collect();
        if kept.is_empty() {
            return None;
        }
        let share = |z: f32| kept.iter().filter(|(d, s)| *d <= f64::from(z) * s).count() as f64 / kept.len() as f64;
        let sds: Vec<f64> = kept.iter().map(|k| k.1).collect();
        Some(Self { covered_50: share(Z50), covered_90: share(Z90), median_sd_mm: Distances::of(&sds).median_mm, count: kept.len() })
    }

    /// The count-weighted mean of several images' coverage (`None` without any).
    pub fn pooled<'a>(parts: impl Iterator<Item = &'a SurfaceCoverage>) -> Option<Self> {
        let parts: Vec<&SurfaceCoverage> = parts.collect();
        let n: usize = parts.iter().map(|c| c.count).sum();
        if n == 0 {
            return None;
        }
        let mean = |f: &dyn Fn(&SurfaceCoverage) -> f64| parts.iter().map(|c| f(c) * c.count as f64).sum::<f64>() / n as f64;
        let mut sds: Vec<f64> = parts.iter().map(|c| c.median_sd_mm).collect();
        sds.sort_by(f64::total_cmp);
        Some(Self { covered_50: mean(&|c| c.covered_50), covered_90: mean(&|c| c.covered_90), median_sd_mm: sds[sds.len() / 2], count: n })
    }
}

/// Pooled figures of a group of images (a |yaw|, or the whole set).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PooledReconstruction {
    /// |yaw| (degrees, rounded), or `None` for the whole set.
    pub abs_yaw_deg: Option<i32>,
    /// Images.
    pub images: usize,
    /// The fits' distances, all images pooled.
    pub fit: Distances,
    /// The mean shape's distances, pooled.
    pub mean_shape: Distances,
    /// How often the fits' vertex intervals held the true surface, pooled (`None` without spreads).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coverage: Option<SurfaceCoverage>,
}

/// Measures every fit of `fits` (shape coefficients of `model`) against its true face in `world`;
/// `progress(done, total)` after each.
pub fn measure_fits(
    model: &GpModel,
    world: &EvalWorld,
    fits: &[ImageFit],
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Vec<ImageReconstruction>, EvalError> {
    let ranks = fits.iter().map(|f| f.shape.len()).max().unwrap_or(0);
    let basis = basis_matrix(&model.shape, ranks);
    // The fitted spreads ride along as the mesh's colour, which the closest points interpolate.
    let mesh_of = |coeffs: &[f64], spread: &[f32]| Mesh {
        positions: basis_instance(&basis, &model.shape.mean, coeffs),
        colors: (0..model.vertices()).map(|v| [f64::from(spread.get(v).copied().unwrap_or(0.0)); 3]).collect(),
        triangles: model.triangles.clone(),
    };
    let mean = mesh_of(&vec![0.0; basis.ncols()], &[]);
    let done = std::sync::atomic::AtomicUsize::new(0);
    fits.par_iter()
        .map(|f| {
            let truth = world.cropped_scan(f.identity)?;
            let mut coeffs: Vec<f64> = f.shape.iter().map(|&c| f64::from(c)).collect();
            coeffs.resize(basis.ncols(), 0.0);
            let fitted = scan_to_mesh(&mesh_of(&coeffs, &f.vertex_sd_mm), &model.landmarks, &truth)?;
            let reference = scan_to_mesh(&mean, &model.landmarks, &truth)?;
            progress(done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1, fits.len());
            Ok(ImageReconstruction {
                image: f.image.clone(),
                identity: f.identity,
                yaw_deg: f.yaw_deg,
                fit: Distances::of(&fitted.distances),
                mean_shape: Distances::of(&reference.distances),
                border_fraction: fitted.border_fraction,
                scale: fitted.scale,
                coverage: if f.vertex_sd_mm.len() == model.vertices() { SurfaceCoverage::of(&fitted) } else { None },
            })
        })
        .collect()
}

/// Pools per-image distances: one row per |yaw| (ascending), then the whole set. The pooled
/// statistics come from each image's stored median, mean and spread weighted by its count (the
/// mean and standard deviation exactly; the median as the count-weighted median of the images'
/// medians, since single distances are not kept).
pub fn pool(images: &[ImageReconstruction]) -> Vec<PooledReconstruction> {
    let mut yaws: Vec<i32> = images.iter().map(|i| i.yaw_deg.abs().round() as i32).collect();
    yaws.sort_unstable();
    yaws.dedup();
    let group = |abs_yaw_deg: Option<i32>| {
        let sel: Vec<&ImageReconstruction> =
            images.iter().filter(|i| abs_yaw_deg.is_none_or(|y| i.yaw_deg.abs().round() as i32 == y)).collect();
        PooledReconstruction {
            abs_yaw_deg,
            images: sel.len(),
            fit: combine(sel.iter().map(|i| i.fit)),
            mean_shape: combine(sel.iter().map(|i| i.mean_shape)),
            coverage: SurfaceCoverage::pooled(sel.iter().filter_map(|i| i.coverage.as_ref())),
        }
    };
    yaws.into_iter().map(|y| group(Some(y))).chain(std::iter::once(group(None))).collect()
}

/// Count-weighted combination of several images' statistics.
fn combine(parts: impl Iterator<Item = Distances>) -> Distances {
    let parts: Vec<Distances> = parts.filter(|d| d.count > 0 && d.mean_mm.is_finite()).collect();
    let n: usize = parts.iter().map(|d| d.count).sum();
    if n == 0 {
        return Distances::of(&[]);
    }
    let mean_mm = parts.iter().map(|d| d.mean_mm * d.count as f64).sum::<f64>() / n as f64;
    let second = parts.iter().map(|d| (d.std_mm.powi(2) + d.mean_mm.powi(2)) * d.count as f64).sum::<f64>() / n as f64;
    let std_mm = (second - mean_mm * mean_mm).max(0.0).sqrt();
    let mut medians: Vec<(f64, usize)> = parts.iter().map(|d| (d.median_mm, d.count)).collect();
    medians.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut seen = 0usize;
    let median_mm = medians
        .iter()
        .find(|(_, c)| {
            seen += c;
            2 * seen >= n
        })
        .map_or(f64::NAN, |m| m.0);
    Distances { median_mm, mean_mm, std_mm, count: n }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A bumpy square patch of `n × n` vertices (mm) with 68 landmarks spread over it.
    fn patch(n: usize, bump: f64) -> (Mesh, Vec<u32>) {
        let mut positions = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let (x, y) = (i as f64 * 4.0, j as f64 * 4.0);
                positions.push([x, y, bump * ((x / 17.0).sin() + (y / 23.0).cos())]);
            }
        }
        let mut triangles = Vec::new();
        for j in 0..n - 1 {
            for i in 0..n - 1 {
                let v = (j * n + i) as u32;
                triangles.push([v, v + 1, v + n as u32]);
                triangles.push([v + 1, v + n as u32 + 1, v + n as u32]);
            }
        }
        let landmarks = (0..68).map(|k| ((k * 7 + 3) % (n * n)) as u32).collect();
        (Mesh { colors: vec![[0.5; 3]; positions.len()], positions, triangles }, landmarks)
    }

    #[test]
    fn a_moved_and_scaled_copy_of_the_truth_has_no_error() {
        let (mesh, landmarks) = patch(20, 6.0);
        let truth = Scan { id: 0, mesh: mesh.clone(), landmarks: landmarks.clone() };
        let (c, s) = (0.3f64.cos(), 0.3f64.sin());
        let moved = Mesh {
            positions: mesh
                .positions
                .iter()
                .map(|p| [1.2 * (c * p[0] - s * p[2]) + 10.0, 1.2 * p[1] - 4.0, 1.2 * (s * p[0] + c * p[2])])
                .collect(),
            ..mesh.clone()
        };
        let r = scan_to_mesh(&moved, &landmarks, &truth).unwrap();
        let d = Distances::of(&r.distances);
        assert!(d.mean_mm < 1e-6, "{d:?}");
        assert!((r.scale - 1.0 / 1.2).abs() < 1e-6, "{}", r.scale);
    }

    #[test]
    fn a_flattened_face_lies_as_far_as_its_lost_relief() {
        let (truth_mesh, landmarks) = patch(20, 6.0);
        let (flat, _) = patch(20, 0.0);
        let truth = Scan { id: 3, mesh: truth_mesh, landmarks: landmarks.clone() };
        let d = Distances::of(&scan_to_mesh(&flat, &landmarks, &truth).unwrap().distances);
        // The relief is ±12 mm around its mean; the best plane leaves several mm on average.
        assert!(d.mean_mm > 2.0 && d.mean_mm < 12.0, "{d:?}");
        let same = Distances::of(&scan_to_mesh(&truth.mesh, &landmarks, &truth).unwrap().distances);
        assert!(same.mean_mm < 1e-9, "{same:?}");
    }

    #[test]
    fn a_fits_vertex_intervals_hold_the_truth_as_wide_as_they_are() {
        let (truth_mesh, landmarks) = patch(20, 6.0);
        let truth = Scan { id: 1, mesh: truth_mesh, landmarks: landmarks.clone() };
        let measured = |sd: f64| {
            let (mut flat, _) = patch(20, 0.0);
            flat.colors = vec![[sd; 3]; flat.positions.len()];
            scan_to_mesh(&flat, &landmarks, &truth).unwrap()
        };
        let coverage = |sd: f64| SurfaceCoverage::of(&measured(sd)).unwrap();
        let (narrow, wide) = (coverage(0.01), coverage(100.0));
        assert!(narrow.covered_90 < 0.2 && narrow.covered_50 <= narrow.covered_90, "{narrow:?}");
        assert!(wide.covered_50 > 0.99 && wide.covered_90 > 0.99, "{wide:?}");
        // The spread is reported in the true face's scale.
        assert!((wide.median_sd_mm - 100.0 * measured(100.0).scale).abs() < 1e-6, "{wide:?}");
        let pooled = SurfaceCoverage::pooled([narrow, wide].iter()).unwrap();
        assert!((pooled.covered_90 - 0.5 * (narrow.covered_90 + wide.covered_90)).abs() < 1e-9 && pooled.count == 2 * narrow.count);
    }

    #[test]
    fn missing_landmarks_are_refused_with_the_identity() {
        let (mesh, landmarks) = patch(10, 1.0);
        let truth = Scan { id: 7, mesh: mesh.clone(), landmarks: landmarks[..60].to_vec() };
        let e = scan_to_mesh(&mesh, &landmarks, &truth).unwrap_err().to_string();
        assert!(e.contains("identity 7") && e.contains("68"), "{e}");
    }

    #[test]
    fn pooling_weights_images_by_their_counts() {
        let a = Distances::of(&[1.0, 1.0, 1.0]);
        let b = Distances::of(&[3.0]);
        let all = Distances::of(&[1.0, 1.0, 1.0, 3.0]);
        let pooled = combine([a, b].into_iter());
        assert!((pooled.mean_mm - all.mean_mm).abs() < 1e-12 && (pooled.std_mm - all.std_mm).abs() < 1e-12);
        assert_eq!(pooled.median_mm, 1.0);
        assert_eq!(pooled.count, 4);
        let img = |yaw: f32, d: Distances| ImageReconstruction {
            image: String::new(),
            identity: 0,
            yaw_deg: yaw,
            fit: d,
            mean_shape: d,
            border_fraction: 0.0,
            scale: 1.0,
            coverage: None,
        };
        let rows = pool(&[img(-30.0, a), img(30.0, b), img(0.0, a)]);
        assert_eq!(rows.iter().map(|r| r.abs_yaw_deg).collect::<Vec<_>>(), vec![Some(0), Some(30), None]);
        assert_eq!(rows[1].images, 2);
        assert_eq!(rows[2].fit.count, 7);
    }
}
