//! The landmark-free fit on the device: the data partition holds the model blob, a fit job
//! (`GPFF`: working side, seed, settings), an init file (`GPMI`) and a camera frame (`GPDF`)
//! (`gpmm_core::format::frame_fit`). The firmware finds the face in the whole frame and reads its
//! landmarks (`detect.rs`: the core's finder and initializer, logged as a `GPDR` record), cuts the
//! working image around them (`gpmm_core::net::crop::crop_for_fit`, the routine the host's run
//! uses too) and runs the core's standard fit on it with the initializer's landmarks as the
//! landmark term (`fit.rs`, logged as a `GPFR` record). No face: the `GPDR` record says so, one
//! line says `no face found`, and the run ends with status ok.
//!
//! RAM: the detection's scratch is on the detection's stack frame, gone before the fit starts;
//! the working image (`PROFILE.frame_fit_side`² × 3 bytes) is on the stack frame that calls the
//! fit, so it sits next to the fit's own stack (README, "The landmark-free fit").

use crate::board::{fail, PROFILE};
use crate::clock::{self, instructions_now};
use crate::detect;
use crate::fit::{self, fit_failed, Buffers, Sizes};

use gpmm_core::error::FitError;
use gpmm_core::fit::{CoveredPixels, FitSettings, TargetImage};
use gpmm_core::format::blob::ModelBlob;
use gpmm_core::format::detection::{DetectCounts, Frame};
use gpmm_core::format::frame_fit::{self, FrameFitJob};
use gpmm_core::format::init_file::MAX_INIT_LANDMARKS;
use gpmm_core::model::MorphableModel;
use gpmm_core::net::crop::crop_for_fit;
use gpmm_core::net::face::Detection;

/// Largest working side of this firmware's landmark-free fit.
const SIDE: usize = PROFILE.frame_fit_side as usize;

/// Runs the landmark-free fit on the sections after the blob (the job starts at `job_at`).
#[inline(never)]
pub fn run(part: &'static [u8], blob: &ModelBlob<'_>, model: &MorphableModel<'_, u16>, job_at: usize, bufs: Buffers<'_>, t_start: u64) {
    let rest = part.get(job_at..).unwrap_or(&[]);
    let job: FrameFitJob<FitSettings> = match frame_fit::parse(rest, PROFILE.frame_fit_side) {
        Ok(j) => j,
        Err(e) => {
            defmt::error!(
                "data partition: no valid landmark-free fit job after the blob: {} (this firmware fits working sides of 16..={=u32} px)",
                defmt::Display2Format(&e),
                PROFILE.frame_fit_side
            );
            fail();
        }
    };
    let init_at = frame_fit::next_section(job_at + job.len);
    let init_bytes = part.get(init_at..).unwrap_or(&[]);
    let (init, init_len) = detect::init_file_at(init_bytes, " after the fit job");
    let frame = detect::frame_at(part, frame_fit::next_section(init_at + init_len));
    if init.landmarks != model.landmarks().len() {
        defmt::error!(
            "data partition: the init file reads {=u32} landmarks but the model has {=u32}: they do not belong together",
            init.landmarks as u32,
            model.landmarks().len() as u32
        );
        fail();
    }
    let needed = init.scratch_bytes();
    detect::check_scratch(needed);
    let t_parsed = instructions_now();

    // 1. Detection: finder and initializer (their scratch is gone when `networks` returns).
    let mut dc = DetectCounts {
        instructions_parse: t_parsed - t_start,
        scratch_bytes: detect::SCRATCH as u32,
        scratch_needed_bytes: needed as u32,
        init_bytes: init_len as u32,
        partition_bytes: part.len() as u32,
        finder_macs: init.finder.macs() as u32,
        initializer_macs: init.initializer.macs() as u32,
        frame_width: frame.width,
        frame_height: frame.height,
        ..DetectCounts::default()
    };
    let t_detect = instructions_now();
    let (face, det) = detect::networks(&init, &frame, &mut dc);
    dc.instructions_total = instructions_now() - t_start;
    let t_detected = instructions_now();
    detect::log_record(&face, det.as_ref(), &mut dc);
    let Some(det) = det else {
        defmt::info!(
            "no face found: the finder's score {=f32} is below the frame's minimum {=f32}; nothing to fit",
            face.score,
            frame.min_score
        );
        return;
    };
    // The fit record's stack peak is the crop's and the fit's (the detection's is in its record).
    crate::stack::repaint();
    let t_resume = instructions_now();
    // 2. + 3. The crop and the fit (the time spent logging the detection is left out of the total).
    let sizes = Sizes { blob_bytes: blob.len() as u32, partition_bytes: part.len() as u32, bits: u32::from(blob.bits()) };
    let detection = t_detected - t_detect;
    crop_and_fit(model, &frame, &det, &job, bufs, sizes, (t_parsed - t_start, detection, t_resume - (t_detected - t_start)));
}

/// Cuts the working image around the detected landmarks and fits it; logs the crop's figures and
/// the fit record. `times`: parse, detection and the instruction count the run's total starts from.
#[inline(never)]
fn crop_and_fit(
    model: &MorphableModel<'_, u16>,
    frame: &Frame<'_>,
    det: &Detection,
    job: &FrameFitJob<FitSettings>,
    bufs: Buffers<'_>,
    sizes: Sizes,
    (parse, detection, t_origin): (u64, u64, u64),
) {
    // The crop on this stack leaves no room for the start's shape solve beside the fit: refused
    // as a bad setting rather than run into a stack overflow.
    if job.settings.start.shape_rounds > 0 {
        fit_failed("settings (start.shape_rounds > 0: the landmark-free fit has no stack for the shape solve)", FitError::BadConfig);
    }
    let mut pixels = [[0u8; 3]; SIDE * SIDE];
    let mut working = [[0.0f32; 2]; MAX_INIT_LANDMARKS];
    let side = job.side as usize;
    let n = det.landmarks.len();
    let (Some(pixels), Some(working)) = (pixels.get_mut(..side * side), working.get_mut(..n)) else {
        defmt::error!("working side {=u32} exceeds this firmware's {=u32}", job.side, SIDE as u32);
        fail();
    };
    let (w, h) = (frame.width as usize, frame.height as usize);
    let (window, crop) = clock::measure(|| crop_for_fit(frame.rgb, w, h, &det.landmarks, side, pixels, working));
    let window = match window {
        Ok(win) => win,
        Err(e) => {
            defmt::error!("crop: the core refused the detection: {}", defmt::Display2Format(&e));
            fail();
        }
    };
    defmt::info!(
        "crop_instructions={=u64} crop_side={=u32} crop_bytes={=u32} detection_instructions={=u64}",
        crop,
        job.side,
        (side * side * 3) as u32,
        detection
    );
    defmt::info!("crop: x0 {=f32} y0 {=f32} px, {=f32} frame px per working px", window.x0, window.y0, window.step);
    // The working pixels whose centres lie in the frame: the rest is padding, left out of the fit.
    let covered = CoveredPixels::of_crop(window.x0, window.y0, window.step, job.side, frame.width, frame.height);
    let image = match TargetImage::new(pixels, job.side, job.side).and_then(|t| t.with_covered(covered)) {
        Ok(i) => i,
        Err(e) => fit_failed("target image", e),
    };
    fit::fit_and_log(model, image, working, &job.settings, job.seed, bufs, sizes, (parse, t_origin));
}
