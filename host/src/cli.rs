//! The `gpmm` command line.

use crate::kernel::{Hyperparameters, ModelKernel};
use crate::lowrank::{NystromOptions, RankSpec};
use crate::model::{build_model, BuildOptions, BuildStage, GpModel};
use crate::template::{load_template, TemplateOptions};
use crate::{mesh_io, model_io};
use anyhow::{bail, Context, Result};
use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// gpmm: Gaussian-process morphable models from one scan, fitted on microcontrollers.
#[derive(Debug, Parser)]
#[command(name = "gpmm", version, about, long_about = None, propagate_version = true)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Build a Gaussian-process morphable model (shape + albedo) from one coloured scan.
    ///
    /// The scan is normalized to millimetres (outer eye corners 90 mm apart unless --scale
    /// is given), centred on the landmarks' mirror plane, oriented (x right, y up, z toward
    /// the camera), cropped to the face and optionally simplified. The kernel is approximated
    /// by the Nyström method and kept as a low-rank model.
    Build(Box<BuildArgs>),
    /// Print a model file's key figures as JSON.
    Info(InfoArgs),
    /// Draw random instances (all coefficients ~ N(0,1)) and write them as coloured PLY meshes.
    Sample(SampleArgs),
}

/// Arguments of `gpmm build`.
#[derive(Debug, Args)]
pub struct BuildArgs {
    /// The template scan: PLY with per-vertex colours, or glTF (.glb) with --texture.
    #[arg(long, value_name = "PATH")]
    pub template: PathBuf,
    /// Albedo texture for a glTF template (sampled at the vertices' UVs).
    #[arg(long, value_name = "IMG")]
    pub texture: Option<PathBuf>,
    /// Landmark file: {"scheme": "ibug68", "vertex_ids": [...]}.
    #[arg(long, value_name = "JSON")]
    pub landmarks: PathBuf,
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
    /// Model file.
    pub model: PathBuf,
}

/// Arguments of `gpmm sample`.
#[derive(Debug, Args)]
pub struct SampleArgs {
    /// Model file.
    pub model: PathBuf,
    /// Number of samples.
    #[arg(short = 'n', long, default_value_t = 5)]
    pub count: usize,
    /// Random seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Directory for `mean.ply` and `sample_NNN.ply`.
    #[arg(long, value_name = "DIR")]
    pub out_dir: PathBuf,
}

fn parse_rgb(s: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> = s.split(',').map(|p| p.trim().parse::<f64>().map_err(|e| format!("'{p}': {e}"))).collect::<Result<_, _>>()?;
    match v.as_slice() {
        [r, g, b] if v.iter().all(|x| (0.0..=1.0).contains(x)) => Ok([*r, *g, *b]),
        _ => Err("expected three numbers in [0,1], e.g. 0.8,0.6,0.5".into()),
    }
}

/// Runs the program and maps errors to a message and exit code 1.
pub fn main() -> ExitCode {
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("warn")).init();
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// Runs one parsed command.
pub fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Build(a) => build(*a),
        Command::Info(a) => {
            let json = info_json(&a.model)?;
            println!("{}", serde_json::to_string_pretty(&json)?);
            Ok(())
        }
        Command::Sample(a) => sample(a),
    }
}

fn spinner(msg: &str) -> ProgressBar {
    let pb = ProgressBar::new_spinner();
    pb.set_style(ProgressStyle::with_template("{spinner} {msg} [{elapsed}]").unwrap_or_else(|_| ProgressStyle::default_spinner()));
    pb.set_message(msg.to_string());
    pb.enable_steady_tick(Duration::from_millis(120));
    pb
}

fn rank_spec(count: Option<usize>, captured: Option<f64>, what: &str) -> Result<RankSpec> {
    match (count, captured) {
        (Some(k), _) => Ok(RankSpec::Count(k)),
        (None, Some(f)) if f > 0.0 && f <= 1.0 => Ok(RankSpec::Captured(f)),
        (None, Some(f)) => bail!("--captured-{what} {f} must be in (0, 1]"),
        (None, None) => Ok(RankSpec::Count(200)),
    }
}

/// Peak resident memory of this process in bytes (Linux), if known.
pub fn peak_memory_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

fn build(a: BuildArgs) -> Result<()> {
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
    let topts = TemplateOptions {
        texture: a.texture.clone(),
        scale: a.scale,
        no_crop: a.no_crop,
        vertices: a.vertices,
        default_color: a.default_color,
    };
    let pb = spinner("loading and normalizing the template");
    let template = load_template(&a.template, &a.landmarks, &topts)?;
    pb.finish_and_clear();
    let t_template = t0.elapsed();
    eprintln!(
        "template: {} vertices, {} triangles, {} landmarks ({:.3} mm per unit)",
        template.mesh.positions.len(),
        template.mesh.triangles.len(),
        template.landmarks.len(),
        template.provenance.scale_mm_per_unit
    );

    let bar = ProgressBar::new(1);
    bar.set_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} scalar eigenproblems ({msg}) [{elapsed}]")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.enable_steady_tick(Duration::from_millis(200));
    let mut stage_times = Vec::new();
    let mut last = Instant::now();
    let mut offset = 0;
    let mut current = None;
    let model = build_model(&template, &opts, |stage, done, total| {
        if current != Some(stage) {
            offset = bar.position();
            current = Some(stage);
            bar.set_length(offset + total as u64 + if stage == BuildStage::Shape { 2 } else { 0 });
        }
        bar.set_message(if stage == BuildStage::Shape { "shape" } else { "colour" });
        bar.set_position(offset + done as u64);
        stage_times.push((stage, last.elapsed()));
        last = Instant::now();
    });
    bar.finish_and_clear();
    let t_build = t0.elapsed() - t_template;
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
        let peak = peak_memory_bytes().map(|b| format!("{:.1} MiB", b as f64 / 1048576.0)).unwrap_or_else(|| "unknown".into());
        eprintln!(
            "timings: template {:.2} s, kernels + low rank {:.2} s, total {:.2} s; peak memory {peak}",
            t_template.as_secs_f64(),
            t_build.as_secs_f64(),
            t0.elapsed().as_secs_f64()
        );
        for (stage, d) in stage_times {
            eprintln!("  {:?} scalar problem: {:.2} s", stage, d.as_secs_f64());
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

fn model_summary(model: &GpModel, bytes: u64) -> serde_json::Value {
    let head = |v: &[f64]| v.iter().take(10).copied().collect::<Vec<_>>();
    let layout = |b: &crate::model::PartBasis| match b {
        crate::model::PartBasis::Factored { .. } => "factored",
        crate::model::PartBasis::Dense { .. } => "dense",
    };
    serde_json::json!({
        "vertices": model.vertices(),
        "triangles": model.triangles.len(),
        "landmarks": model.landmarks.len(),
        "landmark_scheme": model.metadata.landmark_scheme,
        "kernel": model.metadata.kernel,
        "rank_shape": model.shape.rank(),
        "rank_color": model.color.rank(),
        "captured_shape": model.captured_shape(),
        "captured_color": model.captured_color(),
        "basis_layout": { "shape": layout(&model.shape.basis), "color": layout(&model.color.basis) },
        "eigenvalues_shape_head": head(&model.shape.eigenvalues),
        "eigenvalues_color_head": head(&model.color.eigenvalues),
        "nystrom_points": model.metadata.nystrom_points,
        "hyperparameters": model.metadata.hyperparameters,
        "template": model.metadata.template,
        "attribution": model.metadata.template.attribution,
        "units": model.metadata.units,
        "format_version": model.metadata.version,
        "file_bytes": bytes,
    })
}

fn sample(a: SampleArgs) -> Result<()> {
    let model = model_io::load(&a.model)?;
    std::fs::create_dir_all(&a.out_dir).with_context(|| format!("cannot create {}", a.out_dir.display()))?;
    let mean = model.instance(&[], &[]).map_err(|e| anyhow::anyhow!("{e:?}"))?;
    mesh_io::write_ply(&a.out_dir.join("mean.ply"), &mean)?;
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(a.seed);
    let bar = ProgressBar::new(a.count as u64);
    for i in 0..a.count {
        let mesh = model.sample(&mut rng).map_err(|e| anyhow::anyhow!("{e:?}"))?;
        mesh_io::write_ply(&a.out_dir.join(format!("sample_{i:03}.ply")), &mesh)?;
        bar.inc(1);
    }
    bar.finish_and_clear();
    eprintln!("wrote mean.ply and {} samples to {}", a.count, a.out_dir.display());
    Ok(())
}
