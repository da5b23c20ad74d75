//! `gpmm device-fit BLOB IMAGE --init INIT`: the landmark-free fit, everything on the device.

use crate::device::{DeviceFitArgs, DeviceFitInputs};
use anyhow::{Context, Result};
use gpmm_host::device::detect::camera_frame;
use gpmm_host::device::fit::{frame_fit_settings, run_firmware};
use gpmm_host::device::frame_fit::{self as ff, check_landmarks, check_side, host_frame_fit, job_bytes, HostFrameFit};
use gpmm_host::fit::FitFlags;

/// Runs `gpmm device-fit` without landmarks: frame, job and partition, the firmware under QEMU (or the host
/// only), the JSON report; fails with "no face found" when the finder finds none.
pub fn device_fit_init(a: DeviceFitArgs) -> Result<()> {
    let DeviceFitInputs { blob, landmarks: model_landmarks, ranks, profile } = a.inputs()?;
    let (blob, profile) = (&blob, &profile);
    let init = gpmm_host::detect::shipped::open(a.init.as_deref())?;
    let init_name = gpmm_host::detect::shipped::init_name(a.init.as_deref());
    let needed = init.file().map(|f| f.scratch_bytes()).unwrap_or(0);
    if needed > profile.net_scratch {
        anyhow::bail!(
            "{}: its networks need {needed} bytes per activation buffer; the {} firmware gives them {}",
            init_name,
            profile.name,
            profile.net_scratch
        );
    }
    check_landmarks(&init, model_landmarks).with_context(|| format!("{init_name} and {}", a.blob.display()))?;
    let side = a.side.unwrap_or(profile.frame_fit_side);
    check_side(side, profile)?;
    if a.width == 0 || a.height == 0 || a.width > 1024 || a.height > 1024 {
        anyhow::bail!("--width and --height must be 1..=1024 (got {}x{})", a.width, a.height);
    }
    let photo = gpmm_host::photo::load_rgb(&a.image)?;
    let (frame, mapping) = camera_frame(&photo, a.width, a.height);
    let flags = FitFlags { initializer_sigma: Some(a.init_landmark_sigma), ..a.flags(ranks, side) };
    let options = crate::device::device_options(&flags, gpmm_host::fit::FitSettings::DEVICE_FRAME)?;
    options.validate()?;
    let settings = frame_fit_settings(&options.core(), profile);
    let host = |()| -> Result<HostFrameFit> { Ok(host_frame_fit(blob, &init, &frame, a.min_score, a.refine, side, &settings, a.seed)?) };
    let no_face = |score: f32| {
        anyhow::anyhow!(
            "no face found in {}: the finder's best score {score} is below --min-score {} (nothing was fitted)",
            a.image.display(),
            a.min_score
        )
    };
    if a.host_only {
        let h = host(())?;
        let json = serde_json::json!({
            "profile": profile.name,
            "found": h.detection.is_some(),
            "score": h.face.score,
            "detected_landmarks_frame_px": h.detection.as_ref().map(|d| d.landmarks.to_vec()),
            "fit": h.fitted.as_ref().map(|f| serde_json::json!({
                "side": side,
                "yaw_deg": f.fit.params().pose.yaw.to_degrees(),
                "pitch_deg": f.fit.params().pose.pitch.to_degrees(),
                "roll_deg": f.fit.params().pose.roll.to_degrees(),
                "log_likelihood": f.fit.record_figures(f.spread.as_ref()).log_likelihood,
                "landmarks_px": f.fitted_landmarks,
                "landmarks_frame_px": f.fitted_landmarks.iter().map(|p| <[f32; 2]>::from(f.window.to_source(p[0], p[1]))).collect::<Vec<_>>(),
            })),
        });
        println!("{}", serde_json::to_string_pretty(&json)?);
        return if h.detection.is_some() { Ok(()) } else { Err(no_face(h.face.score)) };
    }
    let partition = ff::partition_bytes(
        blob.bytes(),
        &job_bytes(side, a.seed, &settings)?,
        init.bytes(),
        &ff::frame_section(&frame, a.min_score, a.refine)?,
        profile,
    )?;
    let dir = tempfile::tempdir().context("creating a temporary directory")?;
    let path = a.keep_partition.clone().unwrap_or_else(|| dir.path().join("partition.bin"));
    std::fs::write(&path, &partition).with_context(|| format!("writing {}", path.display()))?;
    let pb = indicatif::ProgressBar::new_spinner();
    pb.set_message(format!("building the {} firmware; detecting, cropping and fitting under QEMU (a few minutes)", profile.name));
    pb.enable_steady_tick(std::time::Duration::from_millis(200));
    let log = run_firmware(profile.name, &path, a.timeout);
    pb.finish_and_clear();
    let report = ff::parse_report(profile.name, &log?)?;
    let mut json = serde_json::to_value(&report)?;
    json["frame_to_photo"] = serde_json::to_value(mapping)?;
    if let Some(lm) = &report.fitted_landmarks_frame_px {
        json["fitted_landmarks_photo_px"] = serde_json::to_value(lm.iter().map(|p| mapping.to_photo(*p)).collect::<Vec<_>>())?;
    }
    json["ram"] = serde_json::to_value(report.ram())?;
    if a.compare_host {
        json["parity"] = serde_json::to_value(ff::compare(&report, &host(())?)?)?;
    }
    println!("{}", serde_json::to_string_pretty(&json)?);
    if report.detection.detection.found {
        Ok(())
    } else {
        Err(no_face(report.detection.detection.score))
    }
}
