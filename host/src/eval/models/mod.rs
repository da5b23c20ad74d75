//! The models an evaluation compares, built on demand and cached in a model directory.
//!
//! A model is described by a [`ModelRecipe`]; its file `DIR/LABEL.gpmm` is reused when
//! `DIR/LABEL.recipe.json` holds the same recipe, and (re)built otherwise. Template models go
//! through exactly what `gpmm build` does ([`load_template`] + [`build_model`]); the KDE
//! components are built the same way from scans written as coloured PLY files (`DIR/scans/`),
//! imported at scale 1 (they already are in millimetres) and face-cropped like the template.
//!
//! Besides the template kernels: the multi-scan KDE ([`kde`]), the PCA baseline ([`pca`]) and the
//! generating world as an upper-bound model, both learned from the world's scans ([`scans`]).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::gp::kernel::{Hyperparameters, ModelKernel};
use crate::gp::lowrank::{NystromOptions, RankSpec};
use crate::gp::model::{build_model, BuildOptions, GpModel};
use crate::mesh::template::{load_template, TemplateOptions};
use crate::synth::SynthOptions;

pub mod kde;
pub mod pca;
pub mod scans;

use crate::eval::recognition::Row;
use crate::eval::{create_dir, file_sha256, io_err, write_text, EvalError};
use scans::{EvalWorld, Scan, ICT_ATTRIBUTION, TRAIN_ID_BASE};

/// How GP models are built from a scan (the `gpmm build` options that matter here).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct GpBuild {
    /// Simplify the cropped scan to at most this many vertices (None: keep all).
    pub vertices: Option<usize>,
    /// Shape and colour rank.
    pub rank: usize,
    /// Nyström points.
    pub nystrom_points: usize,
    /// Nyström sample seed.
    pub seed: u64,
}

impl Default for GpBuild {
    /// The defaults of `gpmm build`: all vertices, rank 200, 2000 Nyström points.
    fn default() -> Self {
        Self { vertices: None, rank: 200, nystrom_points: 2000, seed: NystromOptions::default().seed }
    }
}

/// What a model is made from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum ModelRecipe {
    /// One of the nine kernels, built from the template scan.
    Template {
        /// Kernel name.
        kernel: String,
        /// SHA-256 of the template file.
        template_sha256: String,
        /// Build settings.
        build: GpBuild,
    },
    /// One KDE component: symmetric-full around training identity `index` of the world.
    KdeScan {
        /// Index among the training identities.
        index: usize,
        /// Vertex budget of the cropped scan (the template models' vertex count unless set).
        vertices: usize,
        /// World seed.
        seed: u64,
        /// World identity scale.
        identity_scale: f32,
        /// Build settings.
        build: GpBuild,
    },
    /// One of the nine kernels built around the world's mean face (ICT neutral with the
    /// transferred template albedo), as the paper builds its models around the BFM mean.
    MeanFace {
        /// Kernel name.
        kernel: String,
        /// Vertex budget of the cropped scan (the template models' vertex count).
        vertices: usize,
        /// Build settings.
        build: GpBuild,
    },
    /// PCA of `count` training identities.
    Pca {
        /// Number of training identities.
        count: usize,
        /// World seed.
        seed: u64,
        /// World identity scale.
        identity_scale: f32,
    },
    /// The generating world as a model.
    UpperBound {
        /// World seed.
        seed: u64,
        /// World identity scale.
        identity_scale: f32,
        /// Albedo samples of the colour PCA.
        color_samples: usize,
        /// Colour rank.
        color_rank: usize,
    },
}

/// Where models come from and go.
pub struct ModelFactory {
    /// Cache directory.
    pub dir: PathBuf,
    /// Data directory (template and ICT model).
    pub data: PathBuf,
    /// Build settings of GP models.
    pub build: GpBuild,
    /// The world options (seed, identity scale) of the training identities.
    pub world_options: SynthOptions,
    /// Albedo samples of the upper bound's colour PCA.
    pub color_samples: usize,
    world: Option<EvalWorld>,
    template_vertices: Option<usize>,
}

impl ModelFactory {
    /// A factory caching into `dir`, reading the template and the ICT model from `data`.
    pub fn new(dir: &Path, data: &Path, build: GpBuild, world_options: SynthOptions) -> Self {
        Self {
            dir: dir.to_path_buf(),
            data: data.to_path_buf(),
            build,
            world_options,
            color_samples: 300,
            world: None,
            template_vertices: None,
        }
    }

    /// The world (loaded once).
    pub fn world(&mut self) -> Result<&EvalWorld, EvalError> {
        if self.world.is_none() {
            self.world = Some(EvalWorld::load(&self.world_options)?);
        }
        self.world.as_ref().ok_or_else(|| EvalError::Invalid("the world could not be loaded".into()))
    }

    fn template_paths(&self) -> (PathBuf, PathBuf) {
        let t = crate::data::template_dir(&self.data);
        (t.join("lee-perry-smith.ply"), t.join("landmarks_ibug68.json"))
    }

    /// The recipe of a template kernel model.
    pub fn template_recipe(&self, kernel: ModelKernel) -> Result<ModelRecipe, EvalError> {
        let (ply, _) = self.template_paths();
        if !ply.is_file() {
            return Err(EvalError::Invalid(format!("template {} not found: pass --data DIR (the shared data directory)", ply.display())));
        }
        Ok(ModelRecipe::Template { kernel: kernel.name().into(), template_sha256: file_sha256(&ply)?, build: self.build })
    }

    /// The recipe of KDE component `index`: simplified to the vertex count of the template models (same budget).
    pub fn kde_recipe(&mut self, index: usize) -> Result<ModelRecipe, EvalError> {
        let vertices = self.template_vertex_count()?;
        let o = &self.world_options;
        Ok(ModelRecipe::KdeScan { index, vertices, seed: o.seed, identity_scale: o.identity_scale, build: self.build })
    }

    /// The recipe of a kernel model around the world's mean face, simplified to the template
    /// models' vertex count.
    pub fn mean_face_recipe(&mut self, kernel: ModelKernel) -> Result<ModelRecipe, EvalError> {
        let vertices = self.template_vertex_count()?;
        Ok(ModelRecipe::MeanFace { kernel: kernel.name().into(), vertices, build: self.build })
    }

    /// The recipe of the PCA baseline of `count` scans.
    pub fn pca_recipe(&self, count: usize) -> ModelRecipe {
        ModelRecipe::Pca { count, seed: self.world_options.seed, identity_scale: self.world_options.identity_scale }
    }

    /// Vertices of the cropped (and simplified) template: the budget of models built from world scans.
    fn template_vertex_count(&mut self) -> Result<usize, EvalError> {
        if let Some(v) = self.template_vertices {
            return Ok(v);
        }
        let (ply, lm) = self.template_paths();
        let v = load_template(&ply, &lm, &TemplateOptions { vertices: self.build.vertices, ..Default::default() })?.mesh.positions.len();
        self.template_vertices = Some(v);
        Ok(v)
    }

    /// The recipe of the upper bound.
    pub fn upper_bound_recipe(&self) -> ModelRecipe {
        let o = &self.world_options;
        ModelRecipe::UpperBound { seed: o.seed, identity_scale: o.identity_scale, color_samples: self.color_samples, color_rank: 100 }
    }

    /// The model file of `label` made by `recipe` (`DIR/LABEL.gpmm`, or `DIR/LABEL-seedS.gpmm` for models made
    /// from the world): reused if cached with the same recipe, built otherwise. Returns the path and whether it was built now.
    pub fn get(&mut self, label: &str, recipe: &ModelRecipe) -> Result<(PathBuf, bool), EvalError> {
        create_dir(&self.dir)?;
        let stem = match recipe {
            ModelRecipe::Template { .. } => label.to_string(),
            _ => format!("{label}-seed{}", self.world_options.seed),
        };
        let path = self.dir.join(format!("{stem}.gpmm"));
        let key_path = self.dir.join(format!("{stem}.recipe.json"));
        let key = serde_json::to_string_pretty(recipe).map_err(|error| EvalError::Json { what: "recipe", error })?;
        if path.is_file() && std::fs::read_to_string(&key_path).is_ok_and(|k| k == key) {
            return Ok((path, false));
        }
        let model = self.build(recipe)?;
        crate::gp::model_io::save(&model, &path)?;
        write_text(&key_path, &key)?;
        Ok((path, true))
    }

    fn gp_options(&self, kernel: ModelKernel) -> BuildOptions {
        BuildOptions {
            kernel,
            hyperparameters: Hyperparameters::default(),
            rank_shape: RankSpec::Count(self.build.rank),
            rank_color: RankSpec::Count(self.build.rank),
            nystrom: NystromOptions { points: self.build.nystrom_points.max(1), seed: self.build.seed, ..Default::default() },
        }
    }

    fn build(&mut self, recipe: &ModelRecipe) -> Result<GpModel, EvalError> {
        match recipe {
            ModelRecipe::Template { kernel, .. } => {
                let kernel: ModelKernel = kernel.parse()?;
                let (ply, lm) = self.template_paths();
                let topts = TemplateOptions { vertices: self.build.vertices, ..Default::default() };
                let template = load_template(&ply, &lm, &topts)?;
                Ok(build_model(&template, &self.gp_options(kernel), |_, _, _| {}))
            }
            ModelRecipe::KdeScan { index, vertices, .. } => {
                let (ply, lm) = self.write_scan(*index)?;
                let topts = TemplateOptions { vertices: Some(*vertices), scale: Some(1.0), ..Default::default() };
                let template = load_template(&ply, &lm, &topts)?;
                let mut model = build_model(&template, &self.gp_options(ModelKernel::SymmetricFull), |_, _, _| {});
                model.metadata.template.attribution = Some(ICT_ATTRIBUTION.into());
                Ok(model)
            }
            ModelRecipe::MeanFace { kernel, vertices, .. } => {
                let kernel: ModelKernel = kernel.parse()?;
                let scan = self.world()?.mean_scan();
                let (ply, lm) = self.write_scan_files(&scan, "mean-face")?;
                let topts = TemplateOptions { vertices: Some(*vertices), scale: Some(1.0), ..Default::default() };
                let template = load_template(&ply, &lm, &topts)?;
                let mut model = build_model(&template, &self.gp_options(kernel), |_, _, _| {});
                model.metadata.template.attribution = Some(ICT_ATTRIBUTION.into());
                Ok(model)
            }
            ModelRecipe::Pca { count, .. } => self.world()?.pca_model(*count),
            ModelRecipe::UpperBound { color_samples, color_rank, .. } => self.world()?.upper_bound_model(*color_samples, *color_rank),
        }
    }

    /// Writes training identity `index` as a coloured PLY scan with its landmark file (`DIR/scans/seedS-scanNN.*`).
    pub fn write_scan(&mut self, index: usize) -> Result<(PathBuf, PathBuf), EvalError> {
        let scan = self.world()?.full_scan(TRAIN_ID_BASE + index)?;
        let seed = self.world_options.seed;
        self.write_scan_files(&scan, &format!("seed{seed}-scan{index:02}"))
    }

    /// Writes `scan` as `DIR/scans/STEM.ply` with its landmark file `STEM.landmarks.json`.
    fn write_scan_files(&self, scan: &Scan, stem: &str) -> Result<(PathBuf, PathBuf), EvalError> {
        let scans = self.dir.join("scans");
        create_dir(&scans)?;
        let ply = scans.join(format!("{stem}.ply"));
        let lm = scans.join(format!("{stem}.landmarks.json"));
        crate::mesh::io::write_ply_with(&ply, &scan.mesh, crate::mesh::io::PlyEncoding::BinaryLittleEndian, &[ICT_ATTRIBUTION])?;
        let json = serde_json::json!({ "scheme": "ibug68", "vertex_ids": scan.landmarks });
        std::fs::write(&lm, json.to_string()).map_err(io_err(&lm, "cannot write"))?;
        Ok((ply, lm))
    }
}

/// Which models an evaluation compares.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ModelSelection {
    /// Model files given by the user (label = file stem).
    pub files: Vec<PathBuf>,
    /// Kernels to build from the template.
    pub kernels: Vec<ModelKernel>,
    /// Kernels to build around the world's mean face (the paper's setting).
    pub mean_face_kernels: Vec<ModelKernel>,
    /// The generating world as a model.
    pub upper_bound: bool,
    /// PCA of this many training scans.
    pub pca: Option<usize>,
    /// KDE of this many single-scan models.
    pub kde: Option<usize>,
}

impl ModelSelection {
    /// Whether nothing is selected.
    pub fn is_empty(&self) -> bool {
        self.files.is_empty()
            && self.kernels.is_empty()
            && self.mean_face_kernels.is_empty()
            && !self.upper_bound
            && self.pca.is_none()
            && self.kde.is_none()
    }
}

/// Progress of [`ModelFactory::rows`]: (label, whether it was built now rather than reused).
pub type BuildProgress<'a> = dyn FnMut(&str, bool) + 'a;

impl ModelFactory {
    /// The selected models as table rows (building or reusing their files), in the order
    /// files, kernels, mean-face kernels, upper bound, PCA, KDE. `progress(label, built)` after each model file.
    pub fn rows(&mut self, sel: &ModelSelection, progress: &mut BuildProgress<'_>) -> Result<Vec<Row>, EvalError> {
        let mut rows: Vec<Row> = Vec::new();
        let mut taken = std::collections::BTreeSet::new();
        for f in &sel.files {
            if !f.is_file() {
                return Err(EvalError::Invalid(format!("model file {} not found", f.display())));
            }
            crate::gp::model_io::load(f)?;
            let stem = f.file_stem().and_then(|s| s.to_str()).unwrap_or("model").to_string();
            let mut label = stem.clone();
            let mut k = 2;
            while !taken.insert(label.clone()) {
                label = format!("{stem}-{k}");
                k += 1;
            }
            rows.push(Row {
                label: label.clone(),
                description: format!("model file {}", f.display()),
                components: vec![(label, f.clone())],
            });
        }
        let b = self.build;
        let built = |what: &str| {
            format!(
                "{what}; {} vertices, rank {}, {} Nystrom points",
                b.vertices.map_or("all cropped".to_string(), |v| format!("at most {v}")),
                b.rank,
                b.nystrom_points
            )
        };
        for &k in &sel.kernels {
            let recipe = self.template_recipe(k)?;
            let label = k.name().to_string();
            let (path, new) = self.get(&label, &recipe)?;
            progress(&label, new);
            let description = built(&format!("built from the template scan (Lee Perry-Smith) with the {label} kernel"));
            rows.push(Row { label: label.clone(), description, components: vec![(label, path)] });
        }
        for &k in &sel.mean_face_kernels {
            let recipe = self.mean_face_recipe(k)?;
            let label = format!("mean-face-{}", k.name());
            let (path, new) = self.get(&label, &recipe)?;
            progress(&label, new);
            let description = built(&format!(
                "built with the {} kernel around the world's mean face (ICT neutral, transferred template albedo; the paper builds around the BFM mean)",
                k.name()
            ));
            rows.push(Row { label: label.clone(), description, components: vec![(label, path)] });
        }
        if sel.upper_bound {
            let recipe = self.upper_bound_recipe();
            let (path, new) = self.get("upper-bound", &recipe)?;
            progress("upper-bound", new);
            let description = format!(
                "the generating world as a model: exact ICT identity-mode covariance, albedo PCA of {} world identities; face-cropped ICT topology",
                self.color_samples
            );
            rows.push(Row { label: "upper-bound".into(), description, components: vec![("upper-bound".into(), path)] });
        }
        if let Some(n) = sel.pca {
            let label = format!("pca-{n}");
            let recipe = self.pca_recipe(n);
            let (path, new) = self.get(&label, &recipe)?;
            progress(&label, new);
            let description =
                format!("PCA of {n} training identities of the world (face-cropped ICT topology, {} components)", n.saturating_sub(1));
            rows.push(Row { label: label.clone(), description, components: vec![(label, path)] });
        }
        if let Some(n) = sel.kde {
            let label = format!("kde-{n}");
            let mut components = Vec::new();
            for j in 0..n {
                let c = format!("{label}-c{j:02}");
                let recipe = self.kde_recipe(j)?;
                let (path, new) = self.get(&c, &recipe)?;
                progress(&c, new);
                components.push((c, path));
            }
            let v = self.template_vertices.unwrap_or(0);
            let description = format!(
                "KDE of {n} single-scan symmetric-full models, one around each of the first {n} training identities (the PCA's first {n}), \
exported as coloured PLY scans and imported like the template (face crop), simplified to {v} vertices (as the template models); \
rank {}, {} Nystrom points",
                b.rank, b.nystrom_points
            );
            rows.push(Row { label, description, components });
        }
        if rows.is_empty() {
            return Err(EvalError::Invalid(
                "no models selected: give --model FILE, --kernels, --mean-face-kernels, --upper-bound, --pca N or --kde N".into(),
            ));
        }
        Ok(rows)
    }
}
