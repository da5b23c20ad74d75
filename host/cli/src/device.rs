//! The device commands: `gpmm quantize`, `gpmm inspect`, `gpmm device-fit` and `gpmm device-detect`.

use crate::progress::spinner;
use anyhow::{Context, Result};
use clap::Args;
use gpmm_core::profile::DeviceProfile;
use gpmm_host::device::fit::{device_settings, fit_input_bytes, host_fit, parse_report, partition_bytes, run_firmware};
use gpmm_host::device::quantize::BlobBuf;
use gpmm_host::fit::{FitFlags, FitOptions, FitSettings};
use gpmm_host::gp::model_io;
use std::path::PathBuf;

/// Arguments of `gpmm device-fit`.
#[derive(Debug, Args)]
pub struct DeviceFitArgs {
    /// Device profile: m4f (Cortex-M4F, 1 MiB flash, 192 KiB RAM, 128x128 image) or m7 (Cortex-M7, 2 MiB, 512 KiB, 256x256).
    #[arg(long, default_value = "m4f", value_parser = ["m4f", "m7"])]
    pub profile: String,
    /// The model blob (`gpmm quantize`).
    pub blob: PathBuf,
    /// Photo: PNG, JPEG or PPM. With --landmarks: cropped around them and resampled to the
    /// profile's image size on the host. Without: scaled to cover the device's camera frame
    /// (--width x --height) and cut to it, as a camera would give; the device does the rest.
    pub image: PathBuf,
    /// Landmarks: iBUG .pts (68 points), 0-based continuous pixel coordinates. Without them
    /// everything runs on the device, from the camera frame (--init).
    #[arg(long, value_name = "PTS", conflicts_with = "init")]
    pub landmarks: Option<PathBuf>,
    /// Without --landmarks, the init file (`gpmm train-init`; default: the start gpmm ships). The
    /// partition holds the blob, the fit job, the init file and the whole camera frame; the
    /// firmware finds the face, reads its landmarks, cuts the working image (--side) around them
    /// and fits it with the initializer's landmarks as the landmark term (σ:
    /// --init-landmark-sigma, as `gpmm fit` without landmarks).
    #[arg(long, value_name = "INIT")]
    pub init: Option<PathBuf>,
    /// Without --landmarks: the landmark σ (fraction of the working side) of the initializer's landmarks.
    #[arg(long, value_name = "FRACTION", default_value_t = gpmm_host::detect::INIT_LANDMARK_SIGMA, conflicts_with = "landmarks")]
    pub init_landmark_sigma: f32,
    /// Without --landmarks: the camera frame's width (px).
    #[arg(long, default_value_t = gpmm_host::device::detect::DEFAULT_FRAME_WIDTH, conflicts_with = "landmarks")]
    pub width: u32,
    /// Without --landmarks: the camera frame's height (px).
    #[arg(long, default_value_t = gpmm_host::device::detect::DEFAULT_FRAME_HEIGHT, conflicts_with = "landmarks")]
    pub height: u32,
    /// Without --landmarks: re-centre the initializer's crop on its landmarks this many times (0..=8), less
    /// one when the finder looked twice at a small face (on the device a second look takes a
    /// pass's place: the instruction bound).
    #[arg(long, default_value_t = gpmm_core::net::face::DEVICE_REFINE as u32, conflicts_with = "landmarks")]
    pub refine: u32,
    /// Without --landmarks: smallest finder score (0..1) counted as a face (below it: "no face found").
    #[arg(long, default_value_t = crate::detect::DEFAULT_MIN_SCORE, conflicts_with = "landmarks")]
    pub min_score: f32,
    /// Without --landmarks: side (px) of the working image the device cuts around the face (default and
    /// largest: the profile's, 72 on m4f, 128 on m7; its RAM sits next to the fit's stack).
    #[arg(long, value_name = "PX", conflicts_with = "landmarks")]
    pub side: Option<u32>,
    /// The .pts file is 1-based (300-W / menpo convention).
    #[arg(long)]
    pub pts_one_based: bool,
    /// Seed of the chains.
    #[arg(long, default_value_t = FitOptions::DEFAULT.seed)]
    pub seed: u64,
    #[arg(long, value_name = "N", help = device_landmark_steps_help())]
    pub landmark_steps: Option<u32>,
    #[arg(long, value_name = "N", help = format!(
        "Image-chain steps (default: {}; without --landmarks {}), by default all at half the working \
         resolution (`image.coarse_steps`): the device's default fit is about a third of `gpmm fit`'s work",
        FitSettings::DEVICE.image.steps, FitSettings::DEVICE_FRAME.image.steps))]
    pub image_steps: Option<u32>,
    /// Also run the same fit on the host (the core on the same blob) and report the differences.
    #[arg(long)]
    pub compare_host: bool,
    /// Only run the fit on the host (the core on the same blob, as the firmware would): no QEMU.
    #[arg(long, conflicts_with = "compare_host")]
    pub host_only: bool,
    /// Keep the data partition image (blob + fit input) at this path.
    #[arg(long, value_name = "FILE")]
    pub keep_partition: Option<PathBuf>,
    /// QEMU time limit in seconds.
    #[arg(long, default_value_t = 1800)]
    pub timeout: u32,
    /// Any other setting of the fit, by its path in fit.json's `settings` (repeatable), as `gpmm
    /// fit --set` takes them, e.g. `--set occlusion.rounds=3`: the fit input carries every setting.
    #[arg(long = "set", value_name = "PATH=VALUE")]
    pub overrides: Vec<String>,
}

/// Arguments of `gpmm device-detect`.
#[derive(Debug, Args)]
pub struct DeviceDetectArgs {
    /// Photo: PNG, JPEG or PPM (scaled to cover the device's frame and cut to it, as a camera would give).
    pub image: PathBuf,
    /// Init file from `gpmm train-init` (default: the start gpmm ships).
    #[arg(long, value_name = "INIT")]
    pub init: Option<PathBuf>,
    /// Device profile: m4f (Cortex-M4F, 192 KiB RAM) or m7 (Cortex-M7, 512 KiB RAM).
    #[arg(long, default_value = "m4f", value_parser = ["m4f", "m7"])]
    pub profile: String,
    /// Frame width (px) of the device's camera.
    #[arg(long, default_value_t = gpmm_host::device::detect::DEFAULT_FRAME_WIDTH)]
    pub width: u32,
    /// Frame height (px).
    #[arg(long, default_value_t = gpmm_host::device::detect::DEFAULT_FRAME_HEIGHT)]
    pub height: u32,
    /// Re-centre the crop on the read landmarks this many times (0..=8), less one when the finder
    /// looked twice at a small face (on the device a second look takes a pass's place: the
    /// instruction bound).
    #[arg(long, default_value_t = gpmm_core::net::face::DEVICE_REFINE as u32)]
    pub refine: u32,
    /// Smallest finder score (0..1) counted as a face.
    #[arg(long, default_value_t = crate::detect::DEFAULT_MIN_SCORE)]
    pub min_score: f32,
    /// Also run the core on the host on the same frame and report whether the outputs are bit-identical.
    #[arg(long)]
    pub compare_host: bool,
    /// Keep the data partition image (init file + frame) at this path.
    #[arg(long, value_name = "FILE")]
    pub keep_partition: Option<PathBuf>,
    /// QEMU time limit in seconds.
    #[arg(long, default_value_t = 600)]
    pub timeout: u32,
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

/// Runs `gpmm quantize`.
pub fn quantize(a: QuantizeArgs) -> Result<()> {
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
    let stats = gpmm_host::device::accuracy::quantization_error(&quantized.reduced, &view, a.draws, a.seed)?;
    let simp = gpmm_host::device::accuracy::simplification_error(&model, &quantized);
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

/// Runs `gpmm inspect`.
pub fn inspect(a: InspectArgs) -> Result<()> {
    let blob = BlobBuf::read(&a.blob)?;
    let (json, result) = gpmm_host::device::quantize::inspect(&blob);
    println!("{}", serde_json::to_string_pretty(&json)?);
    result.with_context(|| format!("{} is not a valid model blob", a.blob.display()))
}

/// A device fit's model blob, read and checked, and its device profile.
pub struct DeviceFitInputs {
    /// The model blob.
    pub blob: BlobBuf,
    /// Its landmarks.
    pub landmarks: usize,
    /// Its shape and colour ranks.
    pub ranks: [usize; 2],
    /// The device profile.
    pub profile: DeviceProfile,
}

impl DeviceFitArgs {
    /// Reads the blob and looks up the profile.
    pub fn inputs(&self) -> Result<DeviceFitInputs> {
        let blob = BlobBuf::read(&self.blob).with_context(|| format!("reading the model blob {}", self.blob.display()))?;
        let view = blob.view().map_err(|e| anyhow::anyhow!("{}: not a valid model blob: {e}", self.blob.display()))?;
        let (landmarks, ranks) = (view.landmarks().len(), [view.rank_shape(), view.rank_color()]);
        let profile = DeviceProfile::by_name(&self.profile).with_context(|| format!("unknown device profile {}", self.profile))?;
        Ok(DeviceFitInputs { blob, landmarks, ranks, profile })
    }

    /// The fit's flags: seed, steps, the blob's ranks, and a working side of `size` pixels.
    pub fn flags(&self, ranks: [usize; 2], size: u32) -> FitFlags {
        FitFlags {
            size: Some(size),
            seed: Some(self.seed),
            landmark_steps: self.landmark_steps,
            image_steps: self.image_steps,
            shape_rank: Some(ranks[0]),
            color_rank: Some(ranks[1]),
            overrides: self.overrides.clone(),
            ..FitFlags::default()
        }
    }
}

/// `flags` resolved from a device's default fit `base` ([`FitSettings::DEVICE`] with landmarks,
/// [`FitSettings::DEVICE_FRAME`] without).
pub fn device_options(flags: &FitFlags, base: FitSettings) -> Result<FitOptions> {
    Ok(flags.resolve_from(FitOptions { fit: base, ..FitOptions::DEFAULT })?)
}

/// Runs `gpmm device-fit --landmarks`: prepares the partition, runs the firmware, prints the
/// JSON report (`crate::device_frame` runs it with `--init`).
pub fn device_fit(a: DeviceFitArgs) -> Result<()> {
    let DeviceFitInputs { blob, landmarks: model_landmarks, ranks, profile } = a.inputs()?;
    let landmarks = a.landmarks.clone().context("a fit from landmarks needs --landmarks")?;
    let size = profile.image_side;
    let pts = gpmm_host::photo::pts::read_pts(&landmarks, a.pts_one_based)?;
    let photo = gpmm_host::photo::load_rgb(&a.image)?;
    pts.check(&landmarks, model_landmarks, "ibug68", photo.width(), photo.height(), a.pts_one_based)?;
    let prepared = gpmm_host::fit::prepare(&photo, &pts.points, size)?;
    let settings = device_options(&a.flags(ranks, size), FitSettings::DEVICE)?;
    settings.validate()?;
    let device = device_settings(&settings.core(), &profile);
    if a.host_only {
        let (fit, lm) = host_fit(&blob, &prepared, &device, settings.seed)?;
        let p = fit.params();
        // The pose's spread as the firmware records it, calibrated as its report is.
        let spread = gpmm_host::device::fit::device_pose_spread(&blob, &fit, &prepared.landmarks, size, size)?;
        let angles_sd = spread.as_ref().map_or([0.0; 3], gpmm_host::fit::calibrated_angles_sd_deg);
        let angles = [p.pose.yaw, p.pose.pitch, p.pose.roll].map(f32::to_degrees);
        let json = serde_json::json!({
            "profile": a.profile,
            "yaw_deg": angles[0],
            "pitch_deg": angles[1],
            "roll_deg": angles[2],
            "angles_sd_deg": angles_sd,
            "angles_interval_90_deg": gpmm_host::fit::central_intervals(angles, angles_sd, gpmm_host::fit::Z90),
            "log_posterior": fit.image.best_log_posterior,
            "log_likelihood": fit.image.best_image.map_or(f32::NAN, |e| e.log_likelihood),
            "landmarks_px": lm,
            "landmarks_original_px": lm.iter().map(|q| prepared.crop.to_original(*q, size)).collect::<Vec<_>>(),
            "shape": p.shape_coeffs(),
            "color": p.color_coeffs(),
        });
        println!("{}", serde_json::to_string_pretty(&json)?);
        return Ok(());
    }
    let partition = partition_bytes(blob.bytes(), &fit_input_bytes(&prepared, &device, settings.seed)?);
    let dir = tempfile::tempdir().context("creating a temporary directory")?;
    let path = a.keep_partition.clone().unwrap_or_else(|| dir.path().join("partition.bin"));
    std::fs::write(&path, &partition).with_context(|| format!("writing {}", path.display()))?;
    let pb = indicatif::ProgressBar::new_spinner();
    pb.set_message(format!("building the {} firmware and fitting under QEMU (a few minutes)", a.profile));
    pb.enable_steady_tick(std::time::Duration::from_millis(200));
    let log = run_firmware(&a.profile, &path, a.timeout);
    pb.finish_and_clear();
    let log = log?;
    let mut report = parse_report(&a.profile, &log)?;
    report.landmarks_original_px = Some(report.landmarks_px.iter().map(|p| prepared.crop.to_original(*p, size)).collect());
    let mut json = serde_json::to_value(&report)?;
    if a.compare_host {
        let (fit, lm) = host_fit(&blob, &prepared, &device, settings.seed)?;
        let max_diff = lm.iter().zip(&report.landmarks_px).map(|(p, q)| (p[0] - q[0]).hypot(p[1] - q[1])).fold(0.0f32, f32::max);
        let host_ll = fit.image.best_image.map_or(f32::NAN, |e| e.log_likelihood);
        json["host"] = serde_json::json!({
            "yaw_deg": fit.params().pose.yaw.to_degrees(),
            "pitch_deg": fit.params().pose.pitch.to_degrees(),
            "roll_deg": fit.params().pose.roll.to_degrees(),
            "log_likelihood": host_ll,
            "landmarks_px": lm,
        });
        json["parity"] = serde_json::json!({
            "max_landmark_difference_px": max_diff,
            "log_likelihood_relative_difference": ((host_ll - report.log_likelihood) / host_ll.abs().max(1e-9)).abs(),
        });
    }
    println!("{}", serde_json::to_string_pretty(&json)?);
    Ok(())
}

/// Runs `gpmm device-detect`: the frame and the partition, the firmware under QEMU, the JSON report.
pub fn device_detect(a: DeviceDetectArgs) -> Result<()> {
    use gpmm_host::device::detect::{camera_frame, compare, frame_bytes, host_detect, partition_bytes, run_detection};
    let profile =
        gpmm_core::profile::DeviceProfile::by_name(&a.profile).with_context(|| format!("unknown device profile {}", a.profile))?;
    let mut init = gpmm_host::detect::shipped::open(a.init.as_deref())?;
    let needed = init.file().map(|f| f.scratch_bytes()).unwrap_or(0);
    if needed > profile.net_scratch {
        anyhow::bail!(
            "{}: its networks need {needed} bytes per activation buffer; the {} firmware gives them {}",
            gpmm_host::detect::shipped::init_name(a.init.as_deref()),
            profile.name,
            profile.net_scratch
        );
    }
    let photo = gpmm_host::photo::load_rgb(&a.image)?;
    if a.width == 0 || a.height == 0 || a.width > 1024 || a.height > 1024 {
        anyhow::bail!("--width and --height must be 1..=1024 (got {}x{})", a.width, a.height);
    }
    let (frame, mapping) = camera_frame(&photo, a.width, a.height);
    let section = frame_bytes(&frame, a.min_score, a.refine)?;
    let partition = partition_bytes(init.bytes(), &section, &profile)?;
    let dir = tempfile::tempdir().context("creating a temporary directory")?;
    let path = a.keep_partition.clone().unwrap_or_else(|| dir.path().join("partition.bin"));
    let pb = indicatif::ProgressBar::new_spinner();
    pb.set_message(format!("building the {} firmware and detecting under QEMU", a.profile));
    pb.enable_steady_tick(std::time::Duration::from_millis(200));
    let report = run_detection(&a.profile, &partition, &path, a.timeout);
    pb.finish_and_clear();
    let report = report?;
    let mut json = serde_json::to_value(&report)?;
    json["frame_to_photo"] = serde_json::to_value(mapping)?;
    json["landmarks_photo_px"] = serde_json::to_value(report.landmarks_px.iter().map(|p| mapping.to_photo(*p)).collect::<Vec<_>>())?;
    if a.compare_host {
        let (face, det) = host_detect(&mut init, &frame, a.min_score, a.refine)?;
        json["parity"] = serde_json::to_value(compare(&report, &face, det.as_ref())?)?;
    }
    println!("{}", serde_json::to_string_pretty(&json)?);
    Ok(())
}

/// The help of `device-fit --landmark-steps`: the device's default fit's chain with landmarks;
/// without, the start has no shape solve ([`FitSettings::DEVICE_FRAME`]) and the chain fits the
/// shape too.
fn device_landmark_steps_help() -> String {
    let (with, frame) = (FitSettings::DEVICE, FitSettings::DEVICE_FRAME);
    format!(
        "{} (default: {}). Without --landmarks (no room for the shape solve beside the crop): {} % on the pose, then the shape (default: {})",
        crate::fit::landmark_steps_help(&with),
        with.landmarks.steps,
        (frame.landmarks.pose_share * 100.0).round(),
        frame.landmarks.steps
    )
}
