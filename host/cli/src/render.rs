//! `gpmm sample`, `gpmm render` and `gpmm figure`: pictures of a model.

use crate::build::TemplateArgs;
use crate::progress::spinner;
use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use gpmm_core::render::ShLight;
use gpmm_host::gp::model::GpModel;
use gpmm_host::gp::model_io;
use gpmm_host::mesh::io as mesh_io;
use gpmm_host::mesh::template::TemplateOptions;
use gpmm_host::render::figure::{self, KernelFigureOptions};
use gpmm_host::render::light::parse_background;
use gpmm_host::render::{check_size, render_model, Background, RenderSettings, View};
use indicatif::{ProgressBar, ProgressStyle};
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;
use std::path::PathBuf;
use std::time::{Duration, Instant};

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
    /// The template scan, its texture and landmarks.
    #[command(flatten)]
    pub template: TemplateArgs,
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

/// Parses `--light`: a preset name, an inline 9x3 JSON array, or a JSON file holding one.
pub fn parse_light(s: &str) -> Result<ShLight> {
    Ok(gpmm_host::render::light::parse_light(s)?)
}

/// Runs `gpmm sample`.
pub fn sample(a: SampleArgs) -> Result<()> {
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
    let mean = model.instance(&[], &[]).map_err(|e| anyhow::anyhow!("{e}"))?;
    if let Some(dir) = &a.out_dir {
        mesh_io::write_ply(&dir.join("mean.ply"), &mean)?;
    }
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(a.seed);
    let bar = ProgressBar::new(a.count as u64);
    let mut meshes = vec![mean];
    for i in 0..a.count {
        let mesh = model.sample(&mut rng).map_err(|e| anyhow::anyhow!("{e}"))?;
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

/// Prints the attribution the model's template requires, if any.
pub fn print_attribution(model: &GpModel) {
    if let Some(attr) = &model.metadata.template.attribution {
        eprintln!("attribution (must accompany this image): {attr}");
    }
}

/// Runs `gpmm render`.
pub fn render(a: RenderArgs) -> Result<()> {
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

/// Runs `gpmm figure kernels`.
pub fn figure_kernels(a: KernelFigureArgs) -> Result<()> {
    let t0 = Instant::now();
    if !(a.shape_scale.is_finite() && a.shape_scale > 0.0 && a.shape_scale <= 10.0 && a.shape_yaw.is_finite()) {
        bail!("--shape-scale must be in (0, 10] and --shape-yaw a finite angle");
    }
    let topts = TemplateOptions { vertices: Some(a.vertices.max(3)), ..Default::default() };
    let pb = spinner("loading and normalizing the template");
    let template = a.template.load(topts)?;
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

/// Runs `gpmm figure`.
pub fn figure(a: FigureArgs) -> Result<()> {
    match a.figure {
        FigureCommand::Kernels(k) => figure_kernels(k),
    }
}
