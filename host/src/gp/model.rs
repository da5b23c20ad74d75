//! A Gaussian-process morphable model: mean shape and albedo, low-rank bases,
//! topology, landmarks and metadata; and how to build one from a template.

use crate::gp::kernel::{Hyperparameters, KernelPoint, ModelKernel};
use crate::gp::lowrank::{low_rank, LowRank, NystromOptions, RankSpec};
use crate::mesh::template::{Provenance, Template};
use crate::mesh::Mesh;
use gpmm_core::model::{Basis, DenseBasis, FactoredBasis, ModelError};
use rand::{Rng, RngExt};
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

/// The basis of one model part (shape or colour), scaled by `sqrt(eigenvalue)`.
#[derive(Debug, Clone, PartialEq)]
pub enum PartBasis {
    /// Component `k` = `fields[k] ⊗ directions[k]`; `fields` is `rank x vertices` row-major.
    Factored {
        /// Unit 3-vector per component.
        directions: Vec<[f32; 3]>,
        /// Scaled scalar fields, `rank x vertices`.
        fields: Vec<f32>,
    },
    /// Component `k` has a 3-vector per vertex; `values` is `rank x vertices x 3`.
    Dense {
        /// Scaled basis values.
        values: Vec<f32>,
    },
}

/// One part of a model (shape in mm, or colour in linear RGB).
#[derive(Debug, Clone, PartialEq)]
pub struct ModelPart {
    /// Mean per vertex.
    pub mean: Vec<[f32; 3]>,
    /// Eigenvalue of each component, descending.
    pub eigenvalues: Vec<f64>,
    /// The scaled basis.
    pub basis: PartBasis,
}

impl ModelPart {
    /// Builds a factored part from a low-rank decomposition.
    pub fn from_low_rank(mean: Vec<[f32; 3]>, lr: &LowRank) -> Self {
        let mut directions = Vec::with_capacity(lr.components.len());
        let mut fields = Vec::with_capacity(lr.components.len() * mean.len());
        for c in &lr.components {
            let s = c.eigenvalue.sqrt();
            directions.push(c.direction.map(|v| v as f32));
            fields.extend(c.field.iter().map(|f| (f * s) as f32));
        }
        Self { mean, eigenvalues: lr.components.iter().map(|c| c.eigenvalue).collect(), basis: PartBasis::Factored { directions, fields } }
    }

    /// Number of components.
    pub fn rank(&self) -> usize {
        self.eigenvalues.len()
    }

    /// The core's view of the basis (the same code the device runs).
    pub fn core_basis(&self) -> Result<Basis<'_>, ModelError> {
        let n = self.mean.len();
        Ok(match &self.basis {
            PartBasis::Factored { directions, fields } => Basis::Factored(FactoredBasis::new(fields, directions, n)?),
            PartBasis::Dense { values } => Basis::Dense(DenseBasis::new(values, self.rank(), n)?),
        })
    }

    /// `mean + Σ coeffs[k] · basis_k`.
    pub fn instance(&self, coeffs: &[f32]) -> Result<Vec<[f32; 3]>, ModelError> {
        let mut out = self.mean.clone();
        self.core_basis()?.add_instance(coeffs, &mut out)?;
        Ok(out)
    }
}

/// Everything the model file records besides the arrays.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelMetadata {
    /// Always `gpmm-model`.
    pub format: String,
    /// File format version.
    pub version: u32,
    /// Kernel name (one of the nine, or e.g. `pca` for learned models).
    pub kernel: String,
    /// Kernel hyperparameters used.
    pub hyperparameters: Hyperparameters,
    /// Nyström sample size.
    pub nystrom_points: usize,
    /// Nyström sample seed.
    pub nystrom_seed: u64,
    /// Exact trace of the shape kernel matrix (mm²).
    pub shape_trace: f64,
    /// Exact trace of the colour kernel matrix.
    pub color_trace: f64,
    /// Landmark scheme (e.g. `ibug68`).
    pub landmark_scheme: String,
    /// Where the template came from.
    pub template: Provenance,
    /// Units of positions.
    pub units: String,
    /// The program that wrote the file.
    pub created_by: String,
    /// How `gpmm learn` made the model from images (absent for every other model).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub learning: Option<LearningRecord>,
}

/// What a learned model was learned from: the iteration, its inputs and its quality control.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LearningRecord {
    /// Iteration of the loop that made the model (1 for the first learned model).
    pub iteration: u32,
    /// The model the iteration started from.
    pub previous_model: String,
    /// The init file whose finder and initializer started every fit.
    pub init: String,
    /// Images given (mirror images counted when fitted).
    pub images: usize,
    /// Images whose fit was accepted into the model.
    pub accepted: usize,
    /// Images rejected because the fit's silhouette left its start's (overlap below `min_iou`).
    pub rejected_overlap: usize,
    /// Images rejected because shape from shading changed their albedo too much.
    #[serde(default)]
    pub rejected_albedo: usize,
    /// Images that could not be fitted (unreadable, no face found, fit error).
    pub failed: usize,
    /// The silhouette overlap a fit needed.
    pub min_iou: f64,
    /// The largest mean per-vertex albedo change of shape from shading (linear 0–1 colour);
    /// absent when the iteration ran without shape from shading.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_albedo_change: Option<f32>,
    /// Seed of the fits.
    pub seed: u64,
    /// Image-chain steps of each fit (absent in files written before it was recorded).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub image_steps: Option<u32>,
    /// The image chain's share of shape moves (0: the shape came from the landmarks and the
    /// start's solve alone; absent in files written before it was recorded).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub image_shape_share: Option<f32>,
    /// Landmark vertices the iteration moved to where its landmark files' points lie (absent when
    /// it kept its predecessor's landmarks).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub landmarks_moved: Option<usize>,
}

/// The current model file format version.
pub const MODEL_VERSION: u32 = 1;

impl ModelMetadata {
    /// Metadata of a model that was not built from a kernel (a PCA, an import, a learned model):
    /// `kernel` names what it is; no hyperparameters or Nyström sample; traces as given.
    pub fn without_kernel(
        kernel: &str,
        [shape_trace, color_trace]: [f64; 2],
        landmark_scheme: String,
        template: Provenance,
        created_by: String,
    ) -> Self {
        Self {
            format: "gpmm-model".into(),
            version: MODEL_VERSION,
            kernel: kernel.into(),
            hyperparameters: Hyperparameters::default(),
            nystrom_points: 0,
            nystrom_seed: 0,
            shape_trace,
            color_trace,
            landmark_scheme,
            template,
            units: "mm".into(),
            created_by,
            learning: None,
        }
    }

    /// Metadata of a PCA model given by its parts (arrays, a statismo file): kernel `pca`, each
    /// trace the sum of its part's eigenvalues (`0.0` for a part without components, not `-0.0`).
    pub fn pca(shape: &ModelPart, color: &ModelPart, landmark_scheme: String, template: Provenance, created_by: String) -> Self {
        // `+ 0.0`: the sum of no eigenvalues is -0.0, which the metadata would keep as written.
        let trace = |part: &ModelPart| part.eigenvalues.iter().sum::<f64>() + 0.0;
        Self::without_kernel("pca", [trace(shape), trace(color)], landmark_scheme, template, created_by)
    }
}

/// A Gaussian-process morphable model.
#[derive(Debug, Clone, PartialEq)]
pub struct GpModel {
    /// Shape part (mm).
    pub shape: ModelPart,
    /// Albedo part (linear RGB).
    pub color: ModelPart,
    /// Triangles (vertex indices).
    pub triangles: Vec<[u32; 3]>,
    /// Landmark vertex ids.
    pub landmarks: Vec<u32>,
    /// Metadata.
    pub metadata: ModelMetadata,
}

impl GpModel {
    /// Number of vertices.
    pub fn vertices(&self) -> usize {
        self.shape.mean.len()
    }

    /// Fraction of the shape kernel's trace the model keeps.
    pub fn captured_shape(&self) -> f64 {
        fraction(&self.shape.eigenvalues, self.metadata.shape_trace)
    }

    /// Fraction of the colour kernel's trace the model keeps.
    pub fn captured_color(&self) -> f64 {
        fraction(&self.color.eigenvalues, self.metadata.color_trace)
    }

    /// The mesh for given coefficients (missing coefficients are zero; colours clamped to \[0, 1\]).
    pub fn instance(&self, shape: &[f32], color: &[f32]) -> Result<Mesh, ModelError> {
        let p = self.shape.instance(shape)?;
        let c = self.color.instance(color)?;
        Ok(Mesh {
            positions: p.iter().map(|v| v.map(f64::from)).collect(),
            colors: c.iter().map(|v| v.map(|x| f64::from(x).clamp(0.0, 1.0))).collect(),
            triangles: self.triangles.clone(),
        })
    }

    /// The key figures `gpmm info` prints (and the Python package's `info()`), as JSON;
    /// `bytes` is the file size (0 when unknown).
    pub fn summary(&self, bytes: u64) -> serde_json::Value {
        let head = |v: &[f64]| v.iter().take(10).copied().collect::<Vec<_>>();
        let layout = |b: &PartBasis| match b {
            PartBasis::Factored { .. } => "factored",
            PartBasis::Dense { .. } => "dense",
        };
        serde_json::json!({
            "vertices": self.vertices(),
            "triangles": self.triangles.len(),
            "landmarks": self.landmarks.len(),
            "landmark_scheme": self.metadata.landmark_scheme,
            "kernel": self.metadata.kernel,
            "rank_shape": self.shape.rank(),
            "rank_color": self.color.rank(),
            "captured_shape": self.captured_shape(),
            "captured_color": self.captured_color(),
            "basis_layout": { "shape": layout(&self.shape.basis), "color": layout(&self.color.basis) },
            "eigenvalues_shape_head": head(&self.shape.eigenvalues),
            "eigenvalues_color_head": head(&self.color.eigenvalues),
            "nystrom_points": self.metadata.nystrom_points,
            "hyperparameters": self.metadata.hyperparameters,
            "template": self.metadata.template,
            "attribution": self.metadata.template.attribution,
            "units": self.metadata.units,
            "format_version": self.metadata.version,
            "file_bytes": bytes,
        })
    }

    /// A random instance: all coefficients drawn from N(0, 1).
    pub fn sample<R: Rng + ?Sized>(&self, rng: &mut R) -> Result<Mesh, ModelError> {
        let a: Vec<f32> = (0..self.shape.rank()).map(|_| rng.sample(StandardNormal)).collect();
        let b: Vec<f32> = (0..self.color.rank()).map(|_| rng.sample(StandardNormal)).collect();
        self.instance(&a, &b)
    }
}

fn fraction(eigenvalues: &[f64], trace: f64) -> f64 {
    if trace > 0.0 {
        (eigenvalues.iter().sum::<f64>() / trace).clamp(0.0, 1.0)
    } else {
        0.0
    }
}

/// Settings of a model build.
#[derive(Debug, Clone)]
pub struct BuildOptions {
    /// Which of the nine kernels.
    pub kernel: ModelKernel,
    /// Kernel hyperparameters.
    pub hyperparameters: Hyperparameters,
    /// Shape rank.
    pub rank_shape: RankSpec,
    /// Colour rank.
    pub rank_color: RankSpec,
    /// Nyström settings.
    pub nystrom: NystromOptions,
}

/// Which stage a build is in (for progress reporting).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BuildStage {
    /// Shape kernel: scalar problem `done` of `total` finished.
    Shape,
    /// Colour kernel: scalar problem `done` of `total` finished.
    Color,
}

/// Builds a model from a normalized template.
pub fn build_model(template: &Template, opts: &BuildOptions, mut progress: impl FnMut(BuildStage, usize, usize) + Send) -> GpModel {
    let mesh = &template.mesh;
    let points: Vec<KernelPoint> = mesh.positions.iter().zip(&mesh.colors).map(|(p, c)| KernelPoint { position: *p, color: *c }).collect();
    let hp = &opts.hyperparameters;
    // Shape and colour run concurrently: each alone leaves a core idle in the eigensolver.
    let progress = std::sync::Mutex::new(&mut progress);
    let report = |stage, d, t| {
        if let Ok(mut p) = progress.lock() {
            (*p)(stage, d, t)
        }
    };
    let (shape_lr, color_lr) = rayon::join(
        || low_rank(&opts.kernel.shape_kernel(hp), &points, opts.rank_shape, &opts.nystrom, |d, t| report(BuildStage::Shape, d, t)),
        || low_rank(&opts.kernel.albedo_kernel(hp), &points, opts.rank_color, &opts.nystrom, |d, t| report(BuildStage::Color, d, t)),
    );
    let to32 = |v: &[[f64; 3]]| v.iter().map(|p| p.map(|x| x as f32)).collect::<Vec<_>>();
    GpModel {
        shape: ModelPart::from_low_rank(to32(&mesh.positions), &shape_lr),
        color: ModelPart::from_low_rank(to32(&mesh.colors), &color_lr),
        triangles: mesh.triangles.clone(),
        landmarks: template.landmarks.clone(),
        metadata: ModelMetadata {
            format: "gpmm-model".into(),
            version: MODEL_VERSION,
            kernel: opts.kernel.name().into(),
            hyperparameters: hp.clone(),
            nystrom_points: opts.nystrom.points.min(points.len()),
            nystrom_seed: opts.nystrom.seed,
            shape_trace: shape_lr.trace,
            color_trace: color_lr.trace,
            landmark_scheme: template.scheme.clone(),
            template: template.provenance.clone(),
            units: "mm".into(),
            created_by: concat!("gpmm ", env!("CARGO_PKG_VERSION")).into(),
            learning: None,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn part(eigenvalues: &[f64]) -> ModelPart {
        ModelPart { mean: vec![[0.0; 3]], eigenvalues: eigenvalues.to_vec(), basis: PartBasis::Dense { values: Vec::new() } }
    }

    /// The metadata as `gpmm.Model.from_arrays` (`plus_zero`) and `gpmm import-h5` wrote it field
    /// by field before both called [`ModelMetadata::pca`].
    fn as_written_before(shape: &ModelPart, color: &ModelPart, template: Provenance, created_by: &str, plus_zero: bool) -> ModelMetadata {
        let zero = if plus_zero { 0.0 } else { -0.0 };
        ModelMetadata {
            format: "gpmm-model".into(),
            version: MODEL_VERSION,
            kernel: "pca".into(),
            hyperparameters: Hyperparameters::default(),
            nystrom_points: 0,
            nystrom_seed: 0,
            shape_trace: shape.eigenvalues.iter().sum::<f64>() + zero,
            color_trace: color.eigenvalues.iter().sum::<f64>() + zero,
            landmark_scheme: "ibug68".into(),
            template,
            units: "mm".into(),
            created_by: created_by.into(),
            learning: None,
        }
    }

    #[test]
    fn pca_metadata_is_written_as_from_arrays_and_import_wrote_it() {
        let arrays = Provenance { source: "<arrays>".into(), scale_mm_per_unit: 1.0, source_vertices: 1, ..Provenance::default() };
        let h5 = Provenance { source: "m.h5".into(), source_sha256: "ab".into(), scale_mm_per_unit: 1000.0, ..Provenance::default() };
        let json = |m: &ModelMetadata| serde_json::to_string(m).expect("metadata as JSON");
        let new = |s: &ModelPart, c: &ModelPart, t: &Provenance, by: &str| ModelMetadata::pca(s, c, "ibug68".into(), t.clone(), by.into());
        for (s, c) in [(&[4.0, 1.0e-3][..], &[0.5][..]), (&[], &[]), (&[2.0], &[]), (&[0.0], &[0.0])] {
            let (s, c) = (part(s), part(c));
            assert_eq!(json(&new(&s, &c, &arrays, "py")), json(&as_written_before(&s, &c, arrays.clone(), "py", true)));
        }
        // A statismo part has at least one component: the same bytes as before, unless every
        // variance of a part is -0.0 (then its trace is now written 0.0, as from arrays).
        for (s, c) in [(&[4.0, 1.0e-3][..], &[0.5][..]), (&[0.0], &[0.0]), (&[-0.0, 1.0], &[-0.0, 0.0])] {
            let (s, c) = (part(s), part(c));
            assert_eq!(json(&new(&s, &c, &h5, "h5")), json(&as_written_before(&s, &c, h5.clone(), "h5", false)));
        }
        let (s, c) = (part(&[-0.0]), part(&[]));
        let before = json(&as_written_before(&s, &c, h5.clone(), "h5", false));
        let now = json(&new(&s, &c, &h5, "h5"));
        assert!(before.contains(r#""shape_trace":-0.0,"color_trace":-0.0"#), "{before}");
        assert!(now.contains(r#""shape_trace":0.0,"color_trace":0.0"#), "{now}");
    }
}
