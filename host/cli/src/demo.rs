//! `gpmm demo`: the main job end to end, through the same functions as the single commands.

use crate::build::{build, info_json, BuildArgs, TemplateArgs};
use crate::fit::run_fit;
use crate::render::{figure_kernels, render, sample, KernelFigureArgs, RenderArgs, SampleArgs};
use crate::synth::{synth, SynthArgs};
use anyhow::{bail, Context, Result};
use clap::Args;
use gpmm_host::fit::{FitJob, FitOptions, FitSettings};
use gpmm_host::gp::kernel::ModelKernel;
use gpmm_host::gp::lowrank::NystromOptions;
use gpmm_host::render::Background;
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `gpmm demo`.
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Data directory holding `template/lee-perry-smith` and `ict` (default: $GPMM_DATA or ../shared/data).
    #[arg(long, value_name = "DIR")]
    pub data: Option<PathBuf>,
    /// Where the model, pictures and figures go.
    #[arg(long, value_name = "DIR", default_value = "out/demo")]
    pub out_dir: PathBuf,
    /// A fast smoke run: simplified template, low ranks, few synthetic faces.
    #[arg(long)]
    pub quick: bool,
}

/// Runs `gpmm demo`: builds a model from the template, renders it, samples it, draws the
/// kernel figure and synthetic test faces, and fits a photo.
pub fn demo(a: DemoArgs) -> Result<()> {
    let t0 = Instant::now();
    let data = a.data.unwrap_or_else(gpmm_host::data::default_data_dir);
    let tdir = gpmm_host::data::template_dir(&data);
    let (ply, lm) = (tdir.join("lee-perry-smith.ply"), tdir.join("landmarks_ibug68.json"));
    if !ply.is_file() {
        bail!("template {} not found: pass --data DIR or set GPMM_DATA to the shared data directory", ply.display());
    }
    let out = a.out_dir;
    std::fs::create_dir_all(&out).with_context(|| format!("cannot create {}", out.display()))?;
    let model = out.join("model.gpmm");
    let (rank, vertices, nystrom_points, count) = if a.quick { (40, Some(1500), 600, 2) } else { (200, None, 2000, 6) };

    eprintln!("[1/7] building the symmetric-full model from the template");
    let template = || TemplateArgs { template: ply.clone(), texture: None, landmarks: lm.clone() };
    build(BuildArgs {
        template: template(),
        kernel: ModelKernel::SymmetricFull,
        rank_shape: Some(rank),
        rank_color: Some(rank),
        captured_shape: None,
        captured_color: None,
        config: None,
        vertices,
        scale: None,
        no_crop: false,
        default_color: None,
        nystrom_points,
        seed: NystromOptions::default().seed,
        timings: true,
        output: model.clone(),
    })?;
    let info = info_json(&model)?;
    std::fs::write(out.join("info.json"), serde_json::to_string_pretty(&info)?)?;

    eprintln!("[2/7] rendering the mean face");
    for (name, yaw) in [("mean.png", 0.0), ("mean_yaw30.png", 30.0)] {
        render(RenderArgs {
            model: model.clone(),
            yaw,
            pitch: 0.0,
            roll: 0.0,
            light: "frontal".into(),
            size: (256, 256),
            shape: None,
            color: None,
            background: Background::Color([0.0; 3]),
            fov: 20.0,
            output: out.join(name),
        })?;
    }
    eprintln!("[3/7] random samples (PLY meshes and a picture)");
    sample(SampleArgs {
        model: model.clone(),
        count: 5,
        seed: 1,
        out_dir: Some(out.join("samples")),
        output: Some(out.join("samples.png")),
        size: (192, 192),
        light: "frontal".into(),
        side_yaw: 45.0,
    })?;

    eprintln!("[4/7] the kernel figure: samples of all nine kernels");
    let (fig_vertices, fig_ranks, fig_nystrom) = if a.quick { (800, (20, 20), 300) } else { (2000, (50, 50), 500) };
    figure_kernels(KernelFigureArgs {
        template: template(),
        vertices: fig_vertices,
        nystrom_points: fig_nystrom,
        ranks: fig_ranks,
        seed: 0,
        shape_scale: 2.0,
        shape_yaw: 0.0,
        cell: 96,
        output: out.join("kernels.png"),
    })?;

    eprintln!("[5/7] synthetic faces with known truth (ICT identities)");
    synth(SynthArgs {
        ict: Some(data.join("ict")),
        template_dir: Some(tdir),
        count,
        seed: 1,
        yaws: vec![0.0, 15.0, 30.0, 45.0],
        size: 128,
        detector_noise: false,
        sheet: Some(out.join("synth.png")),
        output: out.join("synth"),
    })?;

    eprintln!("[6/7] fitting a photo (astronaut.png, public domain, with its 68 landmarks) by MCMC");
    let (photo, pts) = (data.join("images/astronaut.png"), data.join("images/astronaut.pts"));
    if photo.is_file() && pts.is_file() {
        let (landmark_steps, image_steps) = if a.quick { (2000, 150) } else { (5000, 600) };
        run_fit(&FitJob {
            model,
            image: photo,
            landmarks: pts,
            pts_one_based: false,
            landmark_calibration: None,
            settings: FitOptions { fit: FitSettings::DEFAULT.with_steps(landmark_steps, image_steps), ..FitOptions::DEFAULT },
            out_dir: out.join("fit"),
            timing: true,
        })?;
    } else {
        eprintln!("  skipped: {} or {} is absent", photo.display(), pts.display());
    }

    let group = data.join("images/two_people.jpg");
    eprintln!("[7/7] fitting every face of a group photo (two_people.jpg) with no landmark file: the shipped start finds the faces");
    if group.is_file() {
        let (landmark_steps, image_steps) = if a.quick { (1000, 50) } else { (5000, 600) };
        let flags = gpmm_host::fit::FitFlags {
            landmark_steps: Some(landmark_steps),
            image_steps: Some(image_steps),
            initializer_sigma: Some(gpmm_host::detect::INIT_LANDMARK_SIGMA),
            ..Default::default()
        };
        let settings = flags.resolve()?;
        crate::fit_faces::fit_all_faces(&crate::fit_faces::AllFaces {
            model: &out.join("model.gpmm"),
            image: &group,
            init: None,
            min_score: None,
            settings: &settings,
            out_dir: &out.join("group"),
            timing: true,
        })?;
    } else {
        eprintln!("  skipped: {} is absent", group.display());
    }

    eprintln!("\ndemo finished in {:.1} s; in {}:", t0.elapsed().as_secs_f64(), out.display());
    for f in [
        "model.gpmm",
        "info.json",
        "mean.png",
        "mean_yaw30.png",
        "samples.png",
        "samples/",
        "kernels.png",
        "synth.png",
        "synth/",
        "fit/overlay.png",
        "fit/fit.json",
        "fit/fit.ply",
        "group/faces.png",
        "group/faces.json",
        "group/face-00/",
    ] {
        eprintln!("  {f}");
    }
    eprintln!("Pictures of models built from the template must carry: \"Infinite, 3D Head Scan\" by Lee Perry-Smith, CC BY 3.0");
    Ok(())
}
