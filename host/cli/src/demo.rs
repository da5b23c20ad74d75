//! `gpmm demo` (the main job end to end) and `gpmm synth` (synthetic faces with known truth).

use crate::cli::{run, Cli};
use anyhow::{bail, Context, Result};
use clap::{Args, Parser};
use gpmm_host::eval::synth::{contact_sheet, synthesize, write_synth_dir, SynthOptions};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::{Path, PathBuf};
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

/// Arguments of `gpmm synth`.
#[derive(Debug, Args)]
pub struct SynthArgs {
    /// ICT-FaceKit directory (neutral.npy, identity_modes.npy, triangles.npy, landmarks_ibug68.json).
    #[arg(long, value_name = "DIR")]
    pub ict: Option<PathBuf>,
    /// Template directory whose albedo is transferred to the ICT faces.
    #[arg(long, value_name = "DIR")]
    pub template_dir: Option<PathBuf>,
    /// Number of identities (each is rendered at every yaw).
    #[arg(long, default_value_t = 10)]
    pub count: usize,
    /// Seed of everything random.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Yaw angles in degrees (positive turns the face toward the image right).
    #[arg(long, value_delimiter = ',', default_value = "0,15,30,45", allow_hyphen_values = true)]
    pub yaws: Vec<f32>,
    /// Image width and height in pixels.
    #[arg(long, default_value_t = 128)]
    pub size: u32,
    /// Also write a contact sheet of the images to this PNG.
    #[arg(long, value_name = "PNG")]
    pub sheet: Option<PathBuf>,
    /// Output directory: NNNN_yawYY.png, NNNN_yawYY.pts, truth.json.
    #[arg(short, long, value_name = "DIR")]
    pub output: PathBuf,
}

fn bar(len: usize, what: &str) -> ProgressBar {
    let pb = ProgressBar::new(len as u64);
    let template = format!("{{bar:30}} {{pos}}/{{len}} {what} [{{elapsed}}]");
    pb.set_style(ProgressStyle::with_template(&template).unwrap_or_else(|_| ProgressStyle::default_bar()));
    pb
}

/// Runs `gpmm synth`.
pub fn synth(a: SynthArgs) -> Result<()> {
    let mut opts = SynthOptions::default();
    if let Some(d) = a.ict {
        opts.ict_dir = d;
    }
    if let Some(d) = a.template_dir {
        opts.template_dir = d;
    }
    opts.count = a.count;
    opts.seed = a.seed;
    opts.yaws_deg = a.yaws;
    opts.size = a.size;
    opts.validate()?;
    let t0 = Instant::now();
    let pb = bar(opts.count * opts.yaws_deg.len(), "images");
    let summary = write_synth_dir(&opts, &a.output, |done, _| pb.set_position(done as u64))?;
    pb.finish_and_clear();
    eprintln!(
        "wrote {} images of {} identities and {} in {:.1} s",
        summary.images,
        summary.identities,
        summary.truth.display(),
        t0.elapsed().as_secs_f64()
    );
    if let Some(sheet) = a.sheet {
        let faces = synthesize(&SynthOptions { count: opts.count.min(8), ..opts.clone() }, |_, _| {})?;
        contact_sheet(&faces, opts.yaws_deg.len().max(1) * 2).save(&sheet).with_context(|| format!("cannot write {}", sheet.display()))?;
        eprintln!("wrote {}", sheet.display());
    }
    Ok(())
}

fn step(args: &[&str]) -> Result<()> {
    let cli = Cli::try_parse_from(std::iter::once("gpmm").chain(args.iter().copied())).map_err(|e| anyhow::anyhow!("{e}"))?;
    run(cli)
}

fn p(path: &Path) -> String {
    path.display().to_string()
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
    let (rank, vertices, nystrom, count) = if a.quick { ("40", Some("1500"), "600", 2) } else { ("200", None, "2000", 6) };

    eprintln!("[1/6] building the symmetric-full model from the template");
    let mut build = vec!["build", "--template", ply.to_str().unwrap_or_default(), "--landmarks", lm.to_str().unwrap_or_default()];
    build.extend(["--kernel", "symmetric-full", "--rank-shape", rank, "--rank-color", rank, "--nystrom-points", nystrom, "--timings"]);
    if let Some(v) = vertices {
        build.extend(["--vertices", v]);
    }
    let model_s = p(&model);
    build.extend(["-o", &model_s]);
    step(&build)?;
    let info = crate::cli::info_json(&model)?;
    std::fs::write(out.join("info.json"), serde_json::to_string_pretty(&info)?)?;

    eprintln!("[2/6] rendering the mean face");
    for (name, yaw) in [("mean.png", "0"), ("mean_yaw30.png", "30")] {
        step(&["render", &model_s, "--yaw", yaw, "--light", "frontal", "--size", "256", "-o", &p(&out.join(name))])?;
    }
    eprintln!("[3/6] random samples (PLY meshes and a picture)");
    step(&["sample", &model_s, "-n", "5", "--seed", "1", "--out-dir", &p(&out.join("samples")), "-o", &p(&out.join("samples.png"))])?;

    eprintln!("[4/6] the kernel figure: samples of all nine kernels");
    let mut fig = vec!["figure", "kernels", "--template", ply.to_str().unwrap_or_default(), "--landmarks", lm.to_str().unwrap_or_default()];
    if a.quick {
        fig.extend(["--vertices", "800", "--ranks", "20,20", "--nystrom-points", "300"]);
    }
    let fig_out = p(&out.join("kernels.png"));
    fig.extend(["-o", &fig_out]);
    step(&fig)?;

    eprintln!("[5/6] synthetic faces with known truth (ICT identities)");
    let count_s = count.to_string();
    let ict = p(&data.join("ict"));
    let tdir_s = p(&tdir);
    step(&[
        "synth",
        "--ict",
        &ict,
        "--template-dir",
        &tdir_s,
        "--count",
        &count_s,
        "--seed",
        "1",
        "--sheet",
        &p(&out.join("synth.png")),
        "-o",
        &p(&out.join("synth")),
    ])?;

    eprintln!("[6/6] fitting a photo (astronaut.png, public domain, with its 68 landmarks) by MCMC");
    let (photo, pts) = (data.join("images/astronaut.png"), data.join("images/astronaut.pts"));
    if photo.is_file() && pts.is_file() {
        let (lm_steps, img_steps) = if a.quick { ("2000", "150") } else { ("5000", "600") };
        step(&[
            "fit",
            &model_s,
            &p(&photo),
            "--landmarks",
            &p(&pts),
            "--landmark-steps",
            lm_steps,
            "--image-steps",
            img_steps,
            "-o",
            &p(&out.join("fit")),
        ])?;
    } else {
        eprintln!("  skipped: {} or {} is absent", photo.display(), pts.display());
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
    ] {
        eprintln!("  {f}");
    }
    eprintln!("Pictures of models built from the template must carry: \"Infinite, 3D Head Scan\" by Lee Perry-Smith, CC BY 3.0");
    Ok(())
}
