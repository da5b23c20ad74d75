//! `gpmm build` (a model from one scan) and `gpmm info` (a model file's key figures).

use crate::progress::spinner;
use anyhow::Result;
use clap::Args;
use gpmm_host::gp::kernel::{Hyperparameters, ModelKernel};
use gpmm_host::gp::lowrank::{NystromOptions, RankSpec};
use gpmm_host::gp::model::{build_model, BuildOptions, BuildStage, GpModel};
use gpmm_host::gp::model_io;
use gpmm_host::mesh::template::{load_template, Template, TemplateOptions};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// The template scan and its landmarks, as `gpmm build` and `gpmm figure kernels` take them.
#[derive(Debug, Args)]
pub struct TemplateArgs {
    /// The template scan: PLY with per-vertex colours, or glTF (.glb) with --texture.
    #[arg(long, value_name = "PATH")]
    pub template: PathBuf,
    /// Albedo texture for a glTF template (sampled at the vertices' UVs).
    #[arg(long, value_name = "IMG")]
    pub texture: Option<PathBuf>,
    /// Landmark file: {"scheme": "ibug68", "vertex_ids": [...]}.
    #[arg(long, value_name = "JSON")]
    pub landmarks: PathBuf,
}

impl TemplateArgs {
    /// The template loaded and normalized with `options` (its texture the one given here).
    pub fn load(&self, options: TemplateOptions) -> Result<Template> {
        Ok(load_template(&self.template, &self.landmarks, &TemplateOptions { texture: self.texture.clone(), ..options })?)
    }
}

/// Arguments of `gpmm build`.
#[derive(Debug, Args)]
pub struct BuildArgs {
    /// The template scan, its texture and landmarks.
    #[command(flatten)]
    pub template: TemplateArgs,
    /// Kernel: standard-{full,rgb,xyz}, symmetric-{full,rgb,xyz} or correlated-{full,rgb,xyz}.
    #[arg(long, default_value = "symmetric-full", value_name = "NAME")]
    pub kernel: ModelKernel,
    /// Number of shape components to keep.
    #[arg(long, value_name = "K", conflicts_with = "captured_shape")]
    pub rank_shape: Option<usize>,
    /// Number of colour components to keep.
    #[arg(long, value_name = "K", conflicts_with = "captured_color")]
    pub rank_color: Option<usize>,
    /// Instead of --rank-shape: keep the fewest components that capture this fraction of the shape kernel's trace.
    #[arg(long, value_name = "FRACTION")]
    pub captured_shape: Option<f64>,
    /// Instead of --rank-color: keep the fewest components that capture this fraction of the colour kernel's trace.
    #[arg(long, value_name = "FRACTION")]
    pub captured_color: Option<f64>,
    /// TOML file overriding any of the paper's hyperparameters (see `docs/hyperparameters.toml`).
    #[arg(long, value_name = "TOML")]
    pub config: Option<PathBuf>,
    /// Simplify the cropped template to at most N vertices (landmark vertices are kept).
    #[arg(long, value_name = "N")]
    pub vertices: Option<usize>,
    /// Millimetres per template unit (default: outer eye corners 90 mm apart).
    #[arg(long, value_name = "MM_PER_UNIT")]
    pub scale: Option<f64>,
    /// Keep the whole scan instead of cropping the face region.
    #[arg(long)]
    pub no_crop: bool,
    /// Colour for a mesh without per-vertex colours, as R,G,B in [0,1] (otherwise such a mesh is an error).
    #[arg(long, value_name = "R,G,B", value_parser = parse_rgb)]
    pub default_color: Option<[f64; 3]>,
    /// Number of vertices sampled for the Nyström approximation.
    #[arg(long, default_value_t = 2000, value_name = "M")]
    pub nystrom_points: usize,
    /// Seed of the Nyström vertex sample.
    #[arg(long, default_value_t = NystromOptions::default().seed)]
    pub seed: u64,
    /// Print the time of each stage and the peak memory.
    #[arg(long)]
    pub timings: bool,
    /// Output model file (safetensors).
    #[arg(short, long, value_name = "MODEL")]
    pub output: PathBuf,
}

/// Arguments of `gpmm info`.
#[derive(Debug, Args)]
pub struct InfoArgs {
    /// Model file, or an init file (`gpmm train-init`): its sizes and metadata (what it was
    /// trained for and on). Without a file: the start gpmm ships.
    pub model: Option<PathBuf>,
}

pub use gpmm_host::render::light::parse_rgb;

/// The rank of one part from `--rank-*` or `--captured-*` (200 components if neither is given).
pub fn rank_spec(count: Option<usize>, captured: Option<f64>, what: &str) -> Result<RankSpec> {
    Ok(RankSpec::from_flags(count, captured, what)?)
}

/// Runs `gpmm build`.
pub fn build(a: BuildArgs) -> Result<()> {
    let t0 = Instant::now();
    let hyperparameters = match &a.config {
        Some(p) => Hyperparameters::from_toml_file(p)?,
        None => Hyperparameters::default(),
    };
    let opts = BuildOptions {
        kernel: a.kernel,
        hyperparameters,
        rank_shape: rank_spec(a.rank_shape, a.captured_shape, "shape")?,
        rank_color: rank_spec(a.rank_color, a.captured_color, "color")?,
        nystrom: NystromOptions { points: a.nystrom_points.max(1), seed: a.seed, ..Default::default() },
    };
    let topts = TemplateOptions { texture: None, scale: a.scale, no_crop: a.no_crop, vertices: a.vertices, default_color: a.default_color };
    let pb = spinner("loading and normalizing the template");
    let template = a.template.load(topts)?;
    pb.finish_and_clear();
    let t_template = t0.elapsed();
    eprintln!(
        "template: {} vertices, {} triangles, {} landmarks ({:.3} mm per unit)",
        template.mesh.positions.len(),
        template.mesh.triangles.len(),
        template.landmarks.len(),
        template.provenance.scale_mm_per_unit
    );

    let bar = ProgressBar::new(2);
    bar.set_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} kernels decomposed (shape and colour run together) [{elapsed}]")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.enable_steady_tick(Duration::from_millis(200));
    let mut stage_times = Vec::new();
    let started = Instant::now();
    let model = build_model(&template, &opts, |stage: BuildStage, done, total| {
        if done == total {
            bar.inc(1);
            stage_times.push((stage, started.elapsed()));
        }
    });
    bar.finish_and_clear();
    let t_build = t0.elapsed() - t_template;
    for (what, spec, got) in [("shape", opts.rank_shape, model.shape.rank()), ("color", opts.rank_color, model.color.rank())] {
        if let RankSpec::Count(asked) = spec {
            if got < asked {
                eprintln!(
                    "warning: --rank-{what} {asked} is more than the {} Nyström points support: the model keeps all {got} components \
                     (more --nystrom-points allow more)",
                    opts.nystrom.points
                );
            }
        }
    }
    model_io::save(&model, &a.output)?;
    eprintln!(
        "{}: kernel {}, rank {} shape / {} colour, captured {:.4} of the shape and {:.4} of the colour kernel trace",
        a.output.display(),
        model.metadata.kernel,
        model.shape.rank(),
        model.color.rank(),
        model.captured_shape(),
        model.captured_color()
    );
    if let Some(attr) = &model.metadata.template.attribution {
        eprintln!("attribution (must accompany anything built from this model): {attr}");
    }
    if a.timings {
        let peak =
            gpmm_host::process::peak_memory_bytes().map(|b| format!("{:.1} MiB", b as f64 / 1048576.0)).unwrap_or_else(|| "unknown".into());
        eprintln!(
            "timings: template {:.2} s, kernels + low rank {:.2} s, total {:.2} s; peak memory {peak}",
            t_template.as_secs_f64(),
            t_build.as_secs_f64(),
            t0.elapsed().as_secs_f64()
        );
        for (stage, d) in stage_times {
            eprintln!("  {stage:?} kernel finished after {:.2} s", d.as_secs_f64());
        }
    }
    Ok(())
}

/// The JSON `gpmm info` prints.
pub fn info_json(path: &Path) -> Result<serde_json::Value> {
    let model = model_io::load(path)?;
    let bytes = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
    Ok(model_summary(&model, bytes))
}

/// The key figures of a model as JSON.
pub fn model_summary(model: &GpModel, bytes: u64) -> serde_json::Value {
    model.summary(bytes)
}

/// Runs `gpmm info`: the model file's key figures, or an init file's sizes and metadata, as JSON
/// on stdout.
pub fn info(a: InfoArgs) -> Result<()> {
    let json = match &a.model {
        Some(path) if !is_init_file(path) => info_json(path)?,
        path => init_info(path.as_deref())?,
    };
    println!("{}", serde_json::to_string_pretty(&json)?);
    Ok(())
}

/// Whether the file at `path` starts as an init file does (its magic).
fn is_init_file(path: &Path) -> bool {
    use std::io::Read;
    let mut magic = [0u8; 4];
    std::fs::File::open(path).and_then(|mut f| f.read_exact(&mut magic)).is_ok() && magic == gpmm_core::format::init_file::INIT_MAGIC
}

/// An init file's (the shipped start's, for `None`) sizes and metadata as JSON.
fn init_info(path: Option<&Path>) -> Result<serde_json::Value> {
    let detector = gpmm_host::detect::shipped::open(path)?;
    let file = detector.file().map_err(|e| anyhow::anyhow!("{}: {e}", gpmm_host::detect::shipped::init_name(path)))?;
    let metadata: serde_json::Value = serde_json::from_str(file.metadata).unwrap_or(serde_json::Value::String(file.metadata.to_string()));
    Ok(serde_json::json!({
        "init_file": gpmm_host::detect::shipped::init_name(path),
        "bytes": detector.bytes().len(),
        "landmarks": file.landmarks,
        "light_values": file.light,
        "scratch_bytes": file.scratch_bytes(),
        "sha256": gpmm_host::detect::provenance::sha256_hex(detector.bytes()),
        "metadata": metadata,
    }))
}
