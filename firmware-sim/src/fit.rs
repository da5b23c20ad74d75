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

use crate::board::{fail, Rasterizer, MASK_WORDS, PROFILE};
use crate::clock::instructions_now;
use crate::{hexlog, stack};
use gpmm_core::error::FitError;
use gpmm_core::fit::{
    pose_spread, project_landmarks, standard_fit, FitSettings, LandmarkTarget, OcclusionMask, PoseSpread, Stage, StandardFit, TargetImage,
};
use gpmm_core::format::blob::ModelBlob;
use gpmm_core::format::fit_input::{self, FitInput};
use gpmm_core::format::fit_record::{self, DeviceCounts};
use gpmm_core::geometry::Vec3;
use gpmm_core::model::{Instance, InstanceBuffers, MorphableModel, MAX_LANDMARKS};
use gpmm_core::render::frame_cache::{CompactBuffers, FrameCache};
use gpmm_core::render::ProjectedVertex;
use rand_core::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;

/// Shape coefficient capacity of this profile's fit. Every parameter copy on the stack holds
/// `KS + KC` floats, so the small profile keeps it small.
pub const KS: usize = PROFILE.shape_capacity;
/// Colour coefficient capacity.
pub const KC: usize = PROFILE.color_capacity;

/// Instruction counter readings at the stage boundaries.
#[derive(Default)]
pub(crate) struct Marks {
    landmark_start: u64,
    landmark_end: u64,
    image_start: u64,
    image_end: u64,
    /// Just before the fit.
    pub fit_start: u64,
    /// Just after it.
    pub fit_end: u64,
}

/// The fit's static buffers: the `Vec3` pool, the projected vertices, the renderer, the frame cache.
pub(crate) struct Buffers<'b> {
    /// Three `Vec3` per model vertex.
    pub pool: &'b mut [Vec3],
    /// One projected vertex per model vertex.
    pub projected: &'b mut [ProjectedVertex],
    /// The renderer.
    pub raster: &'b mut Rasterizer,
    /// The compact frame cache.
    pub cache: CompactBuffers<'b>,
    /// The occlusion-aware fit's labels.
    pub mask: &'b mut OcclusionMask<MASK_WORDS>,
}

/// The fit to a fit input's image and landmarks (its own frame: the landmark-free path's locals
/// are not on its stack, nor its on theirs).
#[inline(never)]
pub(crate) fn landmark_fit(
    part: &[u8],
    blob: &ModelBlob<'_>,
    model: &MorphableModel<'_, u16>,
    rest: &[u8],
    bufs: Buffers<'_>,
    t_start: u64,
) {
    let input: FitInput<'_, FitSettings> = match fit_input::parse::<FitSettings>(rest, PROFILE.image_side, MAX_LANDMARKS) {
        Ok(i) => i,
        Err(e) => {
            defmt::error!("data partition: no valid fit input after the blob: {}", defmt::Display2Format(&e));
            fail();
        }
    };
    let t_parsed = instructions_now();
    let image = match TargetImage::new(input.pixels, input.width, input.height).and_then(|t| t.with_covered(input.covered)) {
        Ok(i) => i,
        Err(e) => fit_failed("target image", e),
    };
    let sizes = Sizes { blob_bytes: blob.len() as u32, partition_bytes: part.len() as u32, bits: u32::from(blob.bits()) };
    fit_and_log(model, image, input.landmarks, &input.settings, input.seed, bufs, sizes, (t_parsed - t_start, t_start));
}

/// What the fit record says about the inputs.
pub(crate) struct Sizes {
    /// The blob's bytes.
    pub blob_bytes: u32,
    /// The data partition's bytes.
    pub partition_bytes: u32,
    /// Bits per basis value.
    pub bits: u32,
}

/// The core's standard fit of `model` to `image` and `landmarks` (working px) on the device's
/// buffers, then its record (`log_record`). `parse`: the instructions of parsing; the total counts
/// from `t_origin`. The one caller of `standard_fit`, so the compiler inlines that here and builds
/// the fit in place (with two callers it did not: 6 KB more stack), and the fit is never moved out
/// of its `Result` (a `StandardFit` is kilobytes; each move is a copy on the stack).
#[inline(never)]
#[allow(clippy::too_many_arguments)]
pub(crate) fn fit_and_log(
    model: &MorphableModel<'_, u16>,
    image: TargetImage<'_>,
    landmarks: &[[f32; 2]],
    settings: &FitSettings,
    seed: u64,
    bufs: Buffers<'_>,
    sizes: Sizes,
    (parse, t_origin): (u64, u64),
) {
    let n = model.vertices();
    let (width, height) = (image.width(), image.height());
    let Buffers { pool, projected, raster, cache, mask } = bufs;
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
    let valid = [true; MAX_LANDMARKS];
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
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
        model,
        image,
        landmarks,
        valid.get(..landmarks.len()).unwrap_or(&[]),
        settings,
        &mut instance,
        raster,
        mask,
        &mut rng,
        &mut observer,
    );
    let t_end = instructions_now();
    let fit = match result {
        Ok(f) => f,
        Err(e) => fit_failed("fit", e),
    };
    // How well the landmarks pin the fit's pose, after the fit (outside its stack frame).
    let target = LandmarkTarget::new(landmarks, valid.get(..landmarks.len()).unwrap_or(&[]), 1.0);
    let spread = target.ok().and_then(|t| pose_spread(model, fit.params(), &t, width, height).ok());
    marks.fit_start = t_fit;
    marks.fit_end = t_end;
    let mut counts = counts(settings, &marks, (instance.shape_updates, instance.color_updates), parse, t_end - t_origin);
    counts.blob_bytes = sizes.blob_bytes;
    counts.partition_bytes = sizes.partition_bytes;
    counts.bits = sizes.bits;
    log_record(model, &fit, spread.as_ref(), width, height, counts);
}

/// The record's counts of a fit: its stages from `marks`, `parse` and `total` instructions; the
/// sizes are the caller's to fill in.
pub(crate) fn counts(settings: &FitSettings, marks: &Marks, (shape, color): (u32, u32), parse: u64, total: u64) -> DeviceCounts {
    let steps = |n: u32| u64::from(n.max(1));
    let (landmark, image_chain) =
        (marks.landmark_end.saturating_sub(marks.landmark_start), marks.image_end.saturating_sub(marks.image_start));
    DeviceCounts {
        instructions_parse: parse,
        instructions_landmark_chain: landmark,
        instructions_light_and_start: marks.image_start.saturating_sub(marks.landmark_end),
        instructions_image_chain: image_chain,
        instructions_per_landmark_step: if settings.landmarks.steps > 0 { landmark / steps(settings.landmarks.steps) } else { 0 },
        instructions_per_image_step: if settings.image.steps > 0 { image_chain / steps(settings.image.steps) } else { 0 },
        instructions_fit: marks.fit_end - marks.fit_start,
        instructions_total: total,
        shape_updates: shape,
        color_updates: color,
        ..DeviceCounts::default()
    }
}

/// Encodes the fit record and logs it as hex lines, then a human summary (a frame of its own, so
/// the record's buffers are not on the stack during the fit). `counts` gets the model's sizes,
/// the image size and the stack peak here.
#[inline(never)]
pub(crate) fn log_record(
    model: &MorphableModel<'_, u16>,
    fit: &StandardFit<KS, KC>,
    spread: Option<&PoseSpread>,
    width: u32,
    height: u32,
    mut counts: DeviceCounts,
) {
    let p = fit.params();
    let mut lm = [[0.0f32; 2]; MAX_LANDMARKS];
    let k = match project_landmarks(model, p, width, height, &mut lm) {
        Ok(k) => k,
        Err(e) => fit_failed("landmark projection", e),
    };
    let figures = fit.record_figures(spread);
    counts.model_vertices = model.vertices() as u32;
    counts.model_triangles = model.triangles().len() as u32;
    counts.image_width = width;
    counts.image_height = height;
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

/// Logs that the core refused `stage`'s input and fails.
pub(crate) fn fit_failed(stage: &str, e: FitError) -> ! {
    defmt::error!("{=str}: the core refused the input: {}", stage, e);
    fail()
}
