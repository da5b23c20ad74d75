//! The fit on the device: the model blob and the fit input from the data partition, the core's
//! standard fit (`gpmm_core::fit::standard_fit`, the same function `gpmm fit` runs) with the
//! settings the fit input carries, and the result as a binary fit record
//! (`gpmm_core::format::fit_record`, logged as `GPFR <hex>` lines) plus one human line.
//!
//! RAM: the per-vertex buffers of the fit (positions, albedos and normals: three `Vec3` per
//! vertex) are carved out of one static `Vec3` pool, the projected vertices out of the
//! renderer's static array, the compact frame cache (a coverage bit per pixel, a triangle id per
//! covered pixel) out of two static arrays; the rest (parameters, chain states, background
//! model) is stack.

use crate::{clock, fail, hexlog, stack, Rasterizer, PROFILE};
use gpmm_core::blob::ModelBlob;
use gpmm_core::fit::{
    project_landmarks, standard_fit, FitError, FitSettings, Instance, InstanceBuffers, Stage, StandardFit, TargetImage, MAX_LANDMARKS,
};
use gpmm_core::format::fit_input::{self, FitInput};
use gpmm_core::format::fit_record::{self, DeviceCounts, FitFigures};
use gpmm_core::frame_cache::{CompactBuffers, FrameCache};
use gpmm_core::{ProjectedVertex, Vec3};
use rand_core::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;

/// Shape coefficient capacity of this profile's fit. Every parameter copy on the stack holds
/// `KS + KC` floats, so the small profile keeps it small.
pub const KS: usize = PROFILE.shape_capacity;
/// Colour coefficient capacity.
pub const KC: usize = PROFILE.color_capacity;

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
pub fn run(part: &'static [u8], pool: &mut [Vec3], projected: &mut [ProjectedVertex], raster: &mut Rasterizer, cache: CompactBuffers<'_>) {
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
        Err(e) => fit_failed("model blob", e),
    };
    let input_at = (blob.len() + 15) & !15;
    let parsed = part.get(input_at..).map(|rest| fit_input::parse::<FitSettings>(rest, PROFILE.image_side, MAX_LANDMARKS));
    let input: FitInput<'_, FitSettings> = match parsed {
        Some(Ok(i)) => i,
        Some(Err(e)) => {
            defmt::error!("data partition: no valid fit input after the blob: {}", defmt::Display2Format(&e));
            fail();
        }
        None => {
            defmt::error!("data partition: the blob fills it, no room for a fit input");
            fail();
        }
    };
    let t_parsed = instructions_now();
    let n = model.vertices();

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
    // A colour or light proposal re-shades the last frame from the compact cache instead of
    // rendering it (the same sums: host and device still agree).
    let mut instance = match Instance::<KS, KC>::new(InstanceBuffers { positions, albedos, normals, projected }, n) {
        Ok(i) => i.with_frame_cache(FrameCache::compact(cache)),
        Err(e) => fit_failed("instance", e),
    };
    let image = match TargetImage::new(input.pixels, input.width, input.height) {
        Ok(i) => i,
        Err(e) => fit_failed("target image", e),
    };
    let valid = [true; MAX_LANDMARKS];
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
        &input.settings,
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

    let steps = |n: u32| u64::from(n.max(1));
    let (landmark, image_chain) =
        (marks.landmark_end.saturating_sub(marks.landmark_start), marks.image_end.saturating_sub(marks.image_start));
    let counts = DeviceCounts {
        instructions_parse: t_parsed - t_start,
        instructions_landmark_chain: landmark,
        instructions_light_and_start: marks.image_start.saturating_sub(marks.landmark_end),
        instructions_image_chain: image_chain,
        instructions_per_landmark_step: if input.settings.landmarks.steps > 0 {
            landmark / steps(input.settings.landmarks.steps)
        } else {
            0
        },
        instructions_per_image_step: if input.settings.image.steps > 0 { image_chain / steps(input.settings.image.steps) } else { 0 },
        instructions_fit: t_end - t_fit,
        instructions_total: t_end - t_start,
        shape_updates: instance.shape_updates,
        color_updates: instance.color_updates,
        stack_peak_bytes: 0,
        blob_bytes: blob.len() as u32,
        partition_bytes: part.len() as u32,
        model_vertices: n as u32,
        model_triangles: model.triangles().len() as u32,
        bits: u32::from(blob.bits()),
        image_width: input.width,
        image_height: input.height,
    };
    log_record(&model, &fit, &input, counts);
}

/// Encodes the fit record and logs it as hex lines, then a human summary (a frame of its own, so
/// the record's buffers are not on the stack during the fit).
#[inline(never)]
fn log_record(
    model: &gpmm_core::fit::MorphableModel<'_, u16>,
    fit: &StandardFit<KS, KC>,
    input: &FitInput<'_, FitSettings>,
    mut counts: DeviceCounts,
) {
    let p = fit.params();
    let mut lm = [[0.0f32; 2]; MAX_LANDMARKS];
    let k = match project_landmarks(model, p, input.width, input.height, &mut lm) {
        Ok(k) => k,
        Err(e) => fit_failed("landmark projection", e),
    };
    let img = fit.image.best_image.unwrap_or(fit.start_image);
    let figures = FitFigures {
        yaw: p.pose.yaw,
        pitch: p.pose.pitch,
        roll: p.pose.roll,
        focal: p.focal,
        translation: p.pose.translation,
        log_posterior: fit.image.best_log_posterior,
        log_likelihood: img.log_likelihood,
        landmark_log_likelihood: fit.image.best_landmarks.log_likelihood,
        landmark_rmse_px: fit.image.best_landmarks.rmse(),
        pixel_rmse: img.rmse(),
        acceptance_landmark_chain: fit.landmark.acceptance.overall(),
        acceptance_image_chain: fit.image.acceptance.overall(),
        covered_pixels: img.covered,
    };
    // Everything the fit used is behind us: the high-water mark is the fit's.
    counts.stack_peak_bytes = stack::peak_bytes();
    let mut record = [0u8; fit_record::encoded_len(KS, KC, MAX_LANDMARKS)];
    let len =
        match fit_record::write(&mut record, &figures, &counts, &p.light, p.shape_coeffs(), p.color_coeffs(), lm.get(..k).unwrap_or(&[])) {
            Ok(len) => len,
            Err(e) => {
                defmt::error!("fit record: {}", e);
                fail();
            }
        };
    hexlog::lines("GPFR", record.get(..len).unwrap_or(&[]));
    let deg = 180.0 / core::f32::consts::PI;
    defmt::info!(
        "fit: yaw {=f32} deg, pitch {=f32} deg, landmark RMSE {=f32} px, log-likelihood {=f32}; {=u64} instructions ({=u64} per image step), stack {=u32} B",
        p.pose.yaw * deg,
        p.pose.pitch * deg,
        figures.landmark_rmse_px,
        figures.log_likelihood,
        counts.instructions_total,
        counts.instructions_per_image_step,
        counts.stack_peak_bytes
    );
}

fn fit_failed(stage: &str, e: FitError) -> ! {
    defmt::error!("{=str}: the core refused the input: {}", stage, e);
    fail()
}
