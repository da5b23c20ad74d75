//! `gpmm eval recognition` and `gpmm eval specgen`: the paper's evaluation.

use crate::eval_setup::{
    command_line, eval_factory, eval_selection, eval_world, start_on_synth, EvalFitArgs, EvalLandmarkArgs, EvalModelArgs,
};
use crate::progress::{bar_style, note, spinner};
use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use gpmm_host::eval::recognition::fits::Coefficients;
use gpmm_host::gp::kernel::ModelKernel;
use indicatif::ProgressBar;
use std::path::{Path, PathBuf};
use std::time::Instant;

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
    /// --mean-face-kernels (the same kernels built around the world's mean face: the paper's setting),
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
    /// The face finder and initializer of an init file against reference landmarks.
    ///
    /// DIR is a `gpmm synth` set (its truth.json lists the images and their yaw) or any folder of
    /// images with a .pts of the same name (photos). Prints JSON: the fraction of faces found (box
    /// centre within half a face size of the reference's), the median and 90th percentile of the
    /// mean landmark error over the outer-eye-corner distance, the median |yaw error| per |yaw|,
    /// and the finder's box size over the reference's (10th, 50th, 90th percentile). Writes
    /// DIR/detect.json with every image unless --no-write.
    ///
    /// DIR may instead be a real-photo set (images with a STEM.faces.json of reference boxes and
    /// points; docs/formats.md): every face found at --min-score is matched to the reference faces
    /// at IoU ≥ 0.5 and it prints recall and precision by face size (≥ 64, 32–64, < 32 px), false
    /// positives per face-free photo and the landmark error of the faces found; --draw-dir writes
    /// each photo with its faces found (green), missed (red) and false positives (orange).
    Detect(DetectEvalArgs),
    /// The 3D error of fits against the true faces of a set with known truth, as NoW measures it.
    ///
    /// Every image of a `gpmm synth` directory (or an independent renderer's set made from one: its
    /// truth.json names the identities) is fitted like `gpmm fit`; the fit's shape is aligned to the
    /// image's true face (a similarity on the inner landmarks, refined on closest points) and every
    /// vertex of the true face, cut to the face region, is measured to the fitted surface (mm). Writes
    /// OUT/reconstruction.{md,csv,json,png}: median / mean / std per |yaw| and over the set, per model,
    /// beside each model's own mean shape; fits go to OUT/fits (shared with `gpmm eval recognition`
    /// when model, settings and images agree). Models as for recognition (default: symmetric-full built
    /// from the template).
    Reconstruction(Box<crate::eval_reconstruction::ReconstructionArgs>),
}

/// Arguments of `gpmm eval detect`.
#[derive(Debug, Args)]
pub struct DetectEvalArgs {
    /// Directory of images (see above).
    pub dir: PathBuf,
    /// Init file from `gpmm train-init` (default: the start gpmm ships).
    #[arg(long, value_name = "INIT")]
    pub init: Option<PathBuf>,
    /// Read the reference .pts from this directory instead of DIR.
    #[arg(long, value_name = "DIR")]
    pub reference_dir: Option<PathBuf>,
    /// The reference .pts files are 1-based (300-W / menpo convention).
    #[arg(long)]
    pub pts_one_based: bool,
    /// Do not write DIR/detect.json.
    #[arg(long)]
    pub no_write: bool,
    /// Write each detection's 68 landmarks to PTS_DIR/NAME.pts (0-based; a point beyond the
    /// margin a fit accepts outside the image moved onto its edge, as `gpmm fit --init` does), e.g. for `gpmm bench-fit --landmarks-dir
    /// PTS_DIR` or `gpmm eval recognition --landmarks-dir PTS_DIR`.
    #[arg(long, value_name = "PTS_DIR")]
    pub pts_dir: Option<PathBuf>,
    /// Re-centre the initializer's crop on its landmarks this many times.
    #[arg(long, default_value_t = gpmm_core::net::face::DEFAULT_REFINE)]
    pub refine: usize,
    /// Read the face once, without the mirrored second reading that is averaged in by default
    /// (one initializer run fewer; for comparisons and the device's budget).
    #[arg(long)]
    pub single_read: bool,
    /// Real-photo sets: the smallest finder score counted as a face (default: 0.9 with an init
    /// file trained on real photos, one with a face check as the shipped start, else 0.05).
    #[arg(long, value_name = "S")]
    pub min_score: Option<f32>,
    /// Real-photo sets: the smallest face (px) looked for. Beside the finder's view of the whole
    /// photo, windows half its shorter side wide, a quarter, … are scanned until a face this small
    /// fills enough of one, each window's face confirmed by a closer look; `inf`: no scan.
    #[arg(long, value_name = "PX", default_value_t = gpmm_host::detect::DEFAULT_SMALLEST_FACE)]
    pub smallest_face: f32,
    /// Keep photos' faces that fail the init file's face check (`gpmm check-init`), for
    /// comparisons; files without a check are not checked anyway.
    #[arg(long)]
    pub no_face_check: bool,
    /// Real-photo sets: write each photo with its boxes drawn to DRAW_DIR/STEM.png.
    #[arg(long, value_name = "DRAW_DIR")]
    pub draw_dir: Option<PathBuf>,
    /// Real-photo sets: score each photo's mirror image too (its reference boxes and points
    /// mirrored), as STEM.mirrored.EXT: twice the faces and face-free photos, figures that depend
    /// less on which way the set's faces turn (one init file's figures on a set and on its mirror
    /// image differ by as much as two trainings' do). Twice the time.
    #[arg(long)]
    pub mirror: bool,
}

/// Arguments of `gpmm eval recognition`.
#[derive(Debug, Args)]
pub struct RecognitionArgs {
    /// A `gpmm synth` directory rendered with yaw 0 among its yaws (e.g. --yaws 0,15,30,45).
    #[arg(long, value_name = "DIR")]
    pub synth: PathBuf,
    /// Landmarks.
    #[command(flatten)]
    pub landmarks: EvalLandmarkArgs,
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
    /// Fit settings.
    #[command(flatten)]
    pub fit: EvalFitArgs,
    /// Image-chain steps per fit of a KDE component (default: as --image-steps).
    #[arg(long, value_name = "N")]
    pub kde_image_steps: Option<u32>,
    /// Seed of the fitting chains; several (`--fit-seed 0,1,2,3`) run the evaluation once per
    /// seed into OUT/seed-N and write the pooled accuracies per seed, their mean and spread to
    /// OUT/seeds.{md,json} (one seed's figure moves by several points with the chains' path).
    #[arg(long, value_delimiter = ',', num_args = 1.., default_values_t = [gpmm_host::fit::FitOptions::DEFAULT.seed], value_name = "SEED")]
    pub fit_seed: Vec<u64>,
    /// Which coefficients are compared: the image chain's posterior mean over its second half
    /// (the posterior's estimate; where the image says little, as for a colour the light explains
    /// as well, it stays near the prior instead of where the chain's walk left it), or its best
    /// sample (the fit `gpmm fit` draws).
    #[arg(long, value_name = "posterior-mean|best", default_value = "posterior-mean", value_parser = Coefficients::parse)]
    pub coefficients: Coefficients,
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

/// Runs `gpmm eval recognition`.
pub fn eval_recognition(a: RecognitionArgs) -> Result<()> {
    use gpmm_host::eval::recognition::report::{markdown, write_report, RecognitionReport};
    use gpmm_host::eval::recognition::{evaluate, FitPlan, Progress};
    let t0 = Instant::now();
    let q = a.models.quick;
    let start = start_on_synth(&a.synth, 50, a.identities.or(q.then_some(4)), &a.landmarks, &a.models, &a.output)?;
    let (set, mut sel, mut factory) = (start.set, start.selection, start.factory);
    sel.kde = a.kde.map(|n| n as usize);
    if a.all {
        sel.kernels = ModelKernel::ALL.to_vec();
        sel.upper_bound = true;
        sel.pca = sel.pca.or(Some(10));
        sel.kde = sel.kde.or(Some(10));
    }
    eprintln!("{}: {} identities, {} images; probe yaws {:?}", a.synth.display(), set.identities.len(), set.images.len(), set.probe_yaws());
    let pb = spinner("preparing models");
    let rows = factory.rows(&sel, &mut |label, built| {
        note(&pb, format!("model {label}: {}", if built { "built" } else { "reused" }));
    })?;
    pb.finish_and_clear();
    // The one resolution of a fit's settings; --quick only shortens the chains it is not told about.
    let base = a.fit.flags(q).resolve()?;
    let jobs = a.fit.jobs();
    let mut seeds: Vec<u64> = Vec::new();
    for s in &a.fit_seed {
        if !seeds.contains(s) {
            seeds.push(*s);
        }
    }
    if seeds.is_empty() {
        bail!("--fit-seed needs at least one seed");
    }
    let mut reports = Vec::new();
    for &seed in &seeds {
        // The first seed's time includes preparing the models; a later one's is its own.
        let t_seed = if reports.is_empty() { t0 } else { Instant::now() };
        let out = if seeds.len() == 1 { a.output.clone() } else { a.output.join(format!("seed-{seed}")) };
        if seeds.len() > 1 {
            eprintln!("fit seed {seed} -> {}", out.display());
        }
        let settings = gpmm_host::fit::FitOptions { seed, ..base };
        settings.validate()?;
        let kde_settings = gpmm_host::fit::FitOptions {
            fit: settings.fit.with_steps(settings.fit.landmarks.steps, a.kde_image_steps.unwrap_or(settings.fit.image.steps)),
            ..settings
        };
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
                note(
                    &bar,
                    format!("{}: {} ({:.0} s{})", r.label, acc.join(", "), r.fit_wall_seconds, if r.cached { ", cached" } else { "" }),
                );
            }
        };
        let plan = FitPlan { settings, kde_settings, coefficients: a.coefficients };
        let results = evaluate(&rows, &set, &plan, jobs, &out, &progress)?;
        bar.finish_and_clear();
        let report = RecognitionReport {
            synth_dir: a.synth.display().to_string(),
            synth_seed: set.seed,
            identities: set.identities.len(),
            gallery: set.identities.len(),
            chance: 1.0 / set.identities.len().max(1) as f64,
            settings,
            kde_settings: (kde_settings != settings && sel.kde.is_some_and(|n| n > 1)).then_some(kde_settings),
            coefficients: a.coefficients,
            jobs,
            command: command_line(),
            rows: results,
            total_seconds: t_seed.elapsed().as_secs_f64(),
        };
        write_report(&report, &out)?;
        if seeds.len() == 1 {
            println!("{}", markdown(&report));
        }
        eprintln!("wrote recognition.md, .csv, .json and .png to {}", out.display());
        reports.push(report);
    }
    if seeds.len() > 1 {
        use gpmm_host::eval::recognition::seeds::{markdown, summarize, write_summary};
        let summary = summarize(&seeds, &reports, command_line())?;
        write_summary(&summary, &a.output)?;
        println!("{}", markdown(&summary));
        eprintln!("wrote seeds.md and seeds.json to {}", a.output.display());
    }
    Ok(())
}

/// Runs `gpmm eval specgen`.
pub fn eval_specgen(a: SpecgenArgs) -> Result<()> {
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

/// Runs `gpmm eval`.
pub fn eval(a: EvalArgs) -> Result<()> {
    match a.eval {
        EvalCommand::Recognition(r) => eval_recognition(*r),
        EvalCommand::Specgen(s) => eval_specgen(*s),
        EvalCommand::Detect(d) => eval_detect(d),
        EvalCommand::Reconstruction(r) => crate::eval_reconstruction::run(*r),
    }
}

/// Runs `gpmm eval detect`.
fn eval_detect(a: DetectEvalArgs) -> Result<()> {
    let mut init = gpmm_host::detect::shipped::open(a.init.as_deref())?;
    let init_name = gpmm_host::detect::shipped::init_name(a.init.as_deref());
    let min_score = a.min_score.unwrap_or(init.advised_min_score());
    if a.no_face_check {
        init.set_check(None);
    }
    if !gpmm_host::detect::photos::list_photo_set(&a.dir)?.is_empty() {
        let run = crate::detect::PhotoSetRun {
            dir: &a.dir,
            init: &init_name,
            min_score,
            smallest_face: a.smallest_face,
            reading: gpmm_core::net::face::Reading { refine: a.refine, mirror: !a.single_read },
            mirror: a.mirror,
            draw_dir: a.draw_dir.as_deref(),
            write: !a.no_write,
        };
        return crate::detect::eval_photo_set(&init, &run);
    }
    let images = gpmm_host::detect::eval::list_images(&a.dir, a.reference_dir.as_deref())?;
    if images.is_empty() {
        bail!("{}: no image with a reference .pts found", a.dir.display());
    }
    let (summary, rows) = gpmm_host::detect::eval::evaluate(
        &mut init,
        &images,
        a.pts_one_based,
        gpmm_core::net::face::Reading { refine: a.refine, mirror: !a.single_read },
    )?;
    if let Some(dir) = &a.pts_dir {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        for r in rows.iter().filter(|r| !r.landmarks.is_empty()) {
            let image = a.dir.join(&r.image);
            let (w, h) = image::image_dimensions(&image).with_context(|| format!("cannot read {}", image.display()))?;
            crate::detect::write_pts(&dir.join(Path::new(&r.image).with_extension("pts")), &r.landmarks, w, h)?;
        }
        eprintln!("wrote {} .pts files to {}", rows.iter().filter(|r| !r.landmarks.is_empty()).count(), dir.display());
    }
    if !a.no_write {
        let path = a.dir.join("detect.json");
        let body = serde_json::json!({ "init": init_name, "summary": summary, "images": rows });
        std::fs::write(&path, serde_json::to_string_pretty(&body)? + "\n").with_context(|| format!("cannot write {}", path.display()))?;
        eprintln!("wrote {}", path.display());
    }
    println!("{}", serde_json::to_string_pretty(&summary)?);
    Ok(())
}
