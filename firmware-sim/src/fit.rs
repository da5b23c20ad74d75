//! The fit on the device: the model blob and the fit input from the data partition, the core's
//! standard fit (`gpmm_core::fit::standard_fit`, the same function `gpmm fit` runs), the
//! result and the instruction counts of every stage logged with defmt.
//!
//! RAM: the per-vertex buffers of the fit (positions, albedos and normals: three `Vec3` per
//! vertex) are carved out of one static `Vec3` pool, the projected vertices out of the
//! renderer's static array; the rest (parameters, chain states, background model) is stack.

use crate::{clock, fail, fit_input, Rasterizer};
use gpmm_core::blob::ModelBlob;
use gpmm_core::fit::{
    project_landmarks, standard_fit, FitError, FitSettings, Instance, InstanceBuffers, Stage, TargetImage, MAX_LANDMARKS,
};
use gpmm_core::{ProjectedVertex, Vec3};
use rand_core::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;

/// Shape coefficient capacity (`m4f` blobs have 50 components by default, `m7` 80). Every
/// parameter copy on the stack holds `KS + KC` floats, so the small profile keeps it small.
pub const KS: usize = if cfg!(feature = "m7") { 100 } else { 64 };
/// Colour coefficient capacity.
pub const KC: usize = KS;
/// Largest image side the firmware accepts (the profile's image size).
pub const MAX_SIDE: u32 = if cfg!(feature = "m7") { 256 } else { 128 };

/// Instruction counter readings at the stage boundaries.
#[derive(Default)]
struct Marks {
    landmark_start: u64,
    landmark_end: u64,
    image_start: u64,
    image_end: u64,
}

fn instructions_now() -> u64 {
    clock::ticks() * u64::from(clock::INSTRUCTIONS_PER_TICK)
}

/// Fits the blob at the start of `part` to the fit input after it; logs everything, fails on bad data.
pub fn run(part: &'static [u8], pool: &mut [Vec3], projected: &mut [ProjectedVertex], raster: &mut Rasterizer) {
    let t_start = instructions_now();
    // The blob may be followed by more data: its header says how long it is.
    let blob = match ModelBlob::parse(part) {
        Ok(b) => b,
        Err(e) => {
            defmt::error!("data partition: not a valid model blob: {}", defmt::Display2Format(&e));
            fail();
        }
    };
    let model = match blob.morphable() {
        Ok(m) => m,
        Err(e) => {
            defmt::error!("model blob: the core refused the model: {}", defmt::Debug2Format(&e));
            fail();
        }
    };
    let t_parsed = instructions_now();
    let input_at = (blob.len() + 15) & !15;
    let input = match part.get(input_at..).map(|rest| fit_input::parse(rest, MAX_SIDE, MAX_LANDMARKS)) {
        Some(Ok(i)) => i,
        Some(Err(e)) => {
            defmt::error!("data partition: no valid fit input after the blob: {}", e);
            fail();
        }
        None => {
            defmt::error!("data partition: the blob fills it, no room for a fit input");
            fail();
        }
    };
    let n = model.vertices();
    defmt::info!(
        "blob_bytes={=u32} model_vertices={=u32} model_triangles={=u32} rank_shape={=u32} rank_color={=u32} bits={=u32} parse_instructions={=u64}",
        blob.len() as u32,
        n as u32,
        model.triangles().len() as u32,
        model.shape_rank() as u32,
        model.color_rank() as u32,
        u32::from(blob.bits()),
        t_parsed - t_start
    );
    defmt::info!(
        "image_width={=u32} image_height={=u32} landmarks={=u32} seed={=u64} landmark_steps={=u32} image_steps={=u32}",
        input.width,
        input.height,
        input.landmarks.len() as u32,
        input.seed,
        input.landmark_steps,
        input.image_steps
    );

    // Per-vertex buffers: three Vec3 slices from the pool, the projected vertices from the renderer's array.
    let (Some(vec3s), Some(projected)) = (pool.get_mut(..3 * n), projected.get_mut(..n)) else {
        defmt::error!(
            "model has {=u32} vertices; this firmware's buffers hold {=u32}",
            n as u32,
            (pool.len() / 3).min(projected.len()) as u32
        );
        fail();
    };
    let (positions, rest) = vec3s.split_at_mut(n);
    let (albedos, normals) = rest.split_at_mut(n);
    let mut instance = match Instance::<KS, KC>::new(InstanceBuffers { positions, albedos, normals, projected }, n) {
        Ok(i) => i,
        Err(e) => fit_failed("instance", e),
    };
    let image = match TargetImage::new(input.pixels, input.width, input.height) {
        Ok(i) => i,
        Err(e) => fit_failed("target image", e),
    };
    let valid = [true; MAX_LANDMARKS];
    let settings = FitSettings {
        landmark_steps: input.landmark_steps,
        image_steps: input.image_steps,
        shape_rank: input.shape_rank as usize,
        color_rank: input.color_rank as usize,
        landmark_sigma: input.landmark_sigma,
        ..FitSettings::DEFAULT
    };
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(input.seed);
    let mut marks = Marks::default();
    let mut observer = |stage: Stage, done: u32, total: u32| {
        let mark = match (stage, done == 0, done == total) {
            (Stage::LandmarkChain, true, _) => &mut marks.landmark_start,
            (Stage::LandmarkChain, _, true) => &mut marks.landmark_end,
            (Stage::ImageChain, true, _) => &mut marks.image_start,
            (Stage::ImageChain, _, true) => &mut marks.image_end,
            _ => return,
        };
        *mark = instructions_now();
    };
    let t_fit = instructions_now();
    let result = standard_fit(
        &model,
        image,
        input.landmarks,
        valid.get(..input.landmarks.len()).unwrap_or(&[]),
        &settings,
        &mut instance,
        raster,
        &mut rng,
        &mut observer,
    );
    let t_end = instructions_now();
    let fit = match result {
        Ok(f) => f,
        Err(e) => fit_failed("fit", e),
    };

    // The result.
    let p = fit.params();
    let deg = 180.0 / core::f32::consts::PI;
    defmt::info!(
        "yaw_deg={=f32} pitch_deg={=f32} roll_deg={=f32} focal_px={=f32}",
        p.pose.yaw * deg,
        p.pose.pitch * deg,
        p.pose.roll * deg,
        p.focal
    );
    defmt::info!("fit_translation_mm={=[?]}", p.pose.translation);
    let img = fit.image.best_image.unwrap_or(fit.start_image);
    defmt::info!(
        "log_posterior={=f32} log_likelihood={=f32} landmark_log_likelihood={=f32} landmark_rmse_px={=f32} pixel_rmse={=f32} covered_pixels={=u32}",
        fit.image.best_log_posterior,
        img.log_likelihood,
        fit.image.best_landmarks.log_likelihood,
        fit.image.best_landmarks.rmse(),
        img.rmse(),
        img.covered
    );
    defmt::info!(
        "acceptance_landmark_chain={=f32} acceptance_image_chain={=f32}",
        fit.landmark.acceptance.overall(),
        fit.image.acceptance.overall()
    );
    defmt::info!("fit_shape={=[?]}", p.shape_coeffs());
    defmt::info!("fit_color={=[?]}", p.color_coeffs());
    defmt::info!("fit_light={=[?]}", p.light.coeffs);
    let mut lm = [[0.0f32; 2]; MAX_LANDMARKS];
    match project_landmarks(&model, p, input.width, input.height, &mut lm) {
        Ok(k) => defmt::info!("fit_landmarks_px={=[?]}", lm.get(..k).unwrap_or(&[])),
        Err(e) => fit_failed("landmark projection", e),
    }

    // Where the instructions went.
    let landmark = marks.landmark_end.saturating_sub(marks.landmark_start);
    let image_chain = marks.image_end.saturating_sub(marks.image_start);
    let start_and_light = marks.image_start.saturating_sub(marks.landmark_end);
    let per_step = if input.image_steps > 0 { image_chain / u64::from(input.image_steps) } else { 0 };
    let per_lm_step = if input.landmark_steps > 0 { landmark / u64::from(input.landmark_steps) } else { 0 };
    defmt::info!(
        "instructions_landmark_chain={=u64} instructions_per_landmark_step={=u64} instructions_light_and_start={=u64} instructions_image_chain={=u64} instructions_per_image_step={=u64}",
        landmark,
        per_lm_step,
        start_and_light,
        image_chain,
        per_step
    );
    defmt::info!(
        "instructions_fit={=u64} instructions_total={=u64} shape_updates={=u32} color_updates={=u32}",
        t_end - t_fit,
        t_end - t_start,
        instance.shape_updates,
        instance.color_updates
    );
}

fn fit_failed(stage: &str, e: FitError) -> ! {
    defmt::error!("{=str}: the core refused the input: {}", stage, defmt::Debug2Format(&e));
    fail()
}
