//! The training loop: fresh chunks of rendered samples, AdamW with a cosine learning rate, then
//! calibration, quantization and a check of the quantized networks through the core's detector.
//! The scenes' faces come from one model or a mixture of models; the networks start from random
//! weights or, fine-tuning, from an init file's ([`crate::start`]).

use crate::data::{face_free_frames, photo_face_samples, samples, Geometry, Sample};
use crate::encode::init_file_bytes;
pub use crate::error::{MixtureMismatch, TrainError};
use crate::mistakes::{scan_mistakes, MistakeScan, Mistakes};
use crate::nets::{batch_tensor, finder_specs, initializer_specs, Net};
use crate::scene::backgrounds::Backgrounds;
use crate::scene::head::HeadContext;
use crate::scene::{render_scene, FaceModel, Openings, SceneRanges, SceneSource, LIGHT_LABELS};
use crate::start::networks_of_init;
use candle_core::{Device, Tensor, D};
use candle_nn::{AdamW, Optimizer, ParamsAdamW};
use gpmm_core::net::Shape;
use gpmm_host::detect::eval::{quantile, score_detection};
use gpmm_host::detect::Detector;
use gpmm_host::gp::model::GpModel;
use gpmm_host::render::Renderer;
use serde::Serialize;

/// How long and on what to train.
#[derive(Debug, Clone, PartialEq)]
pub struct TrainOptions {
    /// Seed of the scenes, the initial weights and the sample order.
    pub seed: u64,
    /// Chunks of fresh scenes.
    pub chunks: usize,
    /// Scenes rendered per chunk.
    pub chunk_scenes: usize,
    /// Passes over each chunk.
    pub passes: usize,
    /// Passes of the initializer over each chunk (its steps cost a third of the finder's).
    pub init_passes: usize,
    /// The initializer's odd passes see every crop in a mirror ([`Sample::mirrored`]).
    pub mirror: bool,
    /// Samples per optimizer step.
    pub batch: usize,
    /// Peak learning rate.
    pub lr: f64,
    /// Held-out scenes the report measures the quantized networks on.
    pub validation: usize,
    /// What the scenes are drawn from.
    pub ranges: SceneRanges,
    /// With background photos: face-free frames cut from them per scene, shown to the finder
    /// with every cell "no face" (the hardest of [`MINED_FROM`] candidates each chunk).
    pub face_free: f64,
    /// With photos of people among the background photos: real faces per scene in both networks'
    /// batches ([`crate::data::photo_face_samples`]; the initializer learns their points, not
    /// their unknown pose and light).
    pub photo_faces: f64,
    /// The initializer learns the reference points of those real faces too (else renders only).
    pub photo_points: bool,
    /// Fine-tuning with background photos: the start file's finder scans them first, and every
    /// box it keeps away from their known faces is shown with every cell "no face"
    /// ([`crate::mistakes`]).
    pub scan_mistakes: Option<MistakeScan>,
}

/// Face-free frames are the hardest one of this many candidates: those the finder, as trained so
/// far, scores highest.
pub const MINED_FROM: usize = 4;

/// Chunks of the default fine-tuning ([`TrainOptions::fine_tuning`]): a tenth of a full training.
pub const FINE_TUNE_CHUNKS: usize = 4;

/// A fine-tuning's peak learning rate over a training's from random weights.
pub const FINE_TUNE_LR_SHARE: f64 = 0.25;

/// Scenes the activation scales are calibrated on (the first of the last chunk's).
const CALIBRATION_SCENES: usize = 256;

/// Weight of one cell of a face-free frame in the finder's loss (a positive frame's one face
/// cell weighs 1, all its other cells together 1).
const FACE_FREE_CELL_WEIGHT: f64 = 0.25;

impl TrainOptions {
    /// The default training (3,840 steps on 81,920 scenes, each seen three times, the second
    /// time mirrored by the initializer; about 25 minutes on two idle cores; 65 at load 4-8).
    pub fn full(seed: u64) -> Self {
        Self {
            seed,
            chunks: 40,
            chunk_scenes: 2048,
            passes: 3,
            init_passes: 3,
            mirror: true,
            batch: 64,
            lr: 2e-3,
            validation: 300,
            ranges: SceneRanges::default(),
            face_free: 0.125,
            photo_faces: 0.25,
            photo_points: true,
            scan_mistakes: None,
        }
    }

    /// The default fine-tuning of an init file ([`fine_tune`]): the default training's chunks
    /// ([`FINE_TUNE_CHUNKS`] of them) at its learning rate times [`FINE_TUNE_LR_SHARE`].
    pub fn fine_tuning(seed: u64) -> Self {
        let full = Self::full(seed);
        Self { chunks: FINE_TUNE_CHUNKS, lr: full.lr * FINE_TUNE_LR_SHARE, ..full }
    }

    /// A few seconds: for tests (the networks learn little).
    pub fn quick(seed: u64) -> Self {
        Self {
            seed,
            chunks: 2,
            chunk_scenes: 48,
            passes: 1,
            init_passes: 1,
            mirror: false,
            batch: 16,
            lr: 2e-3,
            validation: 12,
            ranges: SceneRanges::default(),
            face_free: 0.125,
            photo_faces: 0.25,
            photo_points: true,
            scan_mistakes: None,
        }
    }

    /// Batches in all (a batch is a step of the finder, the initializer or both).
    pub fn steps(&self) -> usize {
        self.chunks * self.passes.max(self.init_passes) * self.chunk_scenes.div_ceil(self.batch)
    }

    /// The finder's and the initializer's optimizer steps.
    pub fn net_steps(&self) -> [usize; 2] {
        [self.passes, self.init_passes].map(|p| self.chunks * p * self.chunk_scenes.div_ceil(self.batch))
    }
}

/// What training measured: losses, and the quantized detector on held-out renders.
#[derive(Debug, Clone, Serialize)]
pub struct TrainReport {
    /// Optimizer steps taken.
    pub steps: usize,
    /// Mean finder loss over the last chunk.
    pub finder_loss: f32,
    /// Mean initializer loss over the last chunk.
    pub initializer_loss: f32,
    /// Held-out scenes measured.
    pub validation_scenes: usize,
    /// Fraction of them where the found box's centre is within half a face size of the truth.
    pub found: f64,
    /// Median landmark error over the inter-ocular distance (outer eye corners), quantized.
    pub median_landmark_error: f64,
    /// Median |yaw error| (degrees), quantized.
    pub median_yaw_error_deg: f64,
    /// Multiply-accumulates of the finder and the initializer.
    pub macs: [usize; 2],
    /// Bytes of the init file.
    pub bytes: usize,
    /// Seconds spent rendering scenes.
    pub render_seconds: f64,
    /// Seconds spent in optimizer steps.
    pub train_seconds: f64,
    /// Boxes the start file's finder kept on face-free parts of the background photos
    /// ([`TrainOptions::scan_mistakes`]; 0 without that scan).
    pub scan_mistakes: usize,
}

/// What training reports as it goes.
#[derive(Debug, Clone, Copy)]
pub enum Progress {
    /// A chunk of scenes is being rendered.
    Rendering {
        /// Chunk index.
        chunk: usize,
    },
    /// An optimizer step finished.
    Step {
        /// Steps done.
        done: usize,
        /// Steps in all.
        total: usize,
        /// Finder loss of the step.
        finder: f32,
        /// Initializer loss of the step.
        initializer: f32,
    },
    /// The start file's finder is scanning the background photos for its mistakes.
    Scanning,
    /// Quantizing and validating.
    Validating,
}

/// The finder's and initializer's sizes (the init file's geometry).
pub fn geometry(landmarks: usize) -> Geometry {
    Geometry { frame_side: 96, grid: 6, crop_side: 64, crop_margin: 1.4, landmarks, light: LIGHT_LABELS }
}

/// Checks that every model of `models` has the first one's vertex and landmark counts.
pub fn check_mixture(models: &[&GpModel]) -> Result<(), TrainError> {
    let first = models.first().ok_or(TrainError::NoModels)?;
    for (index, m) in models.iter().enumerate().skip(1) {
        let error = if m.vertices() != first.vertices() {
            MixtureMismatch::Vertices { found: m.vertices(), expected: first.vertices() }
        } else if m.landmarks.len() != first.landmarks.len() {
            MixtureMismatch::Landmarks { found: m.landmarks.len(), expected: first.landmarks.len() }
        } else {
            continue;
        };
        return Err(TrainError::Mixture { index, error });
    }
    Ok(())
}

/// Stable `ln(1 + e^x)`.
fn softplus(x: &Tensor) -> candle_core::Result<Tensor> {
    x.relu()? + (x.abs()?.neg()?.exp()? + 1.0)?.log()?
}

/// The finder's loss on a batch of scenes and face-free frames (`face_free`, every cell negative).
fn finder_loss(net: &Net, batch: &[&Sample], face_free: &[&[i8]], geo: &Geometry, device: &Device) -> candle_core::Result<Tensor> {
    let x = batch_tensor(batch.iter().map(|s| s.frame.as_slice()).chain(face_free.iter().copied()), geo.frame_side, device)?;
    let (out, _) = net.forward(&x)?;
    let (b, cells) = (batch.len(), geo.grid * geo.grid);
    // NHWC output: (b, cells, 4) → (b, 4, cells).
    let all = out.reshape((b + face_free.len(), cells, 4))?.transpose(1, 2)?.contiguous()?;
    let out = all.narrow(0, 0, b)?;
    let mut onehot = vec![0f32; b * cells];
    for (i, s) in batch.iter().enumerate() {
        onehot[i * cells + s.cell] = 1.0;
    }
    let y = Tensor::from_vec(onehot, (b, 1, cells), device)?;
    let logits = out.narrow(1, 0, 1)?;
    // Binary cross-entropy per cell; the one positive cell weighs as much as all negatives.
    let pos = (softplus(&logits.neg()?)? * &y)?.sum_all()?;
    let neg = (softplus(&logits)? * (1.0 - &y)?)?.sum_all()?;
    let cls = ((pos + (neg / (cells as f64 - 1.0))?)? / b as f64)?;
    let place = out.narrow(1, 1, 3)?.broadcast_mul(&y)?.sum(D::Minus1)?;
    let target = Tensor::from_vec(batch.iter().flat_map(|s| s.place).collect::<Vec<f32>>(), (b, 3), device)?;
    let reg = (place - target)?.abs()?.mean_all()?;
    let loss = (cls + (reg * 4.0)?)?;
    if face_free.is_empty() {
        return Ok(loss);
    }
    let free = softplus(&all.narrow(0, b, face_free.len())?.narrow(1, 0, 1)?)?.sum_all()?;
    loss + (free * (FACE_FREE_CELL_WEIGHT / b as f64))?
}

/// The finder's highest face logit on each of `frames` (letterboxed), without training.
fn finder_peaks(net: &Net, frames: &[Vec<i8>], geo: &Geometry, device: &Device) -> candle_core::Result<Vec<f32>> {
    let cells = geo.grid * geo.grid;
    let mut peaks = Vec::with_capacity(frames.len());
    for chunk in frames.chunks(128) {
        let x = batch_tensor(chunk.iter().map(Vec::as_slice), geo.frame_side, device)?;
        let (out, _) = net.forward(&x)?;
        let logits = out.reshape((chunk.len(), cells, 4))?.narrow(2, 0, 1)?.squeeze(2)?.max(1)?.detach();
        peaks.extend(logits.to_vec1::<f32>()?);
    }
    Ok(peaks)
}

/// Face-free frames for one chunk: the `keep` of `keep · MINED_FROM` fresh candidates that the
/// finder scores highest (hard negatives: textures, foliage, things it takes for faces).
fn mine_face_free(
    net: &Net,
    source: SceneSource<'_>,
    geo: &Geometry,
    seed: u64,
    start: u64,
    keep: usize,
    device: &Device,
) -> candle_core::Result<Vec<Vec<i8>>> {
    let candidates = face_free_frames(source, geo, seed, start * MINED_FROM as u64, (keep * MINED_FROM) as u64);
    let peaks = finder_peaks(net, &candidates, geo, device)?;
    let mut order: Vec<usize> = (0..candidates.len()).collect();
    order.sort_by(|&a, &b| peaks[b].total_cmp(&peaks[a]));
    let mut slots: Vec<Option<Vec<i8>>> = candidates.into_iter().map(Some).collect();
    Ok(order.into_iter().take(keep).filter_map(|i| slots.get_mut(i).and_then(Option::take)).collect())
}

/// Batch `step`'s `per_batch` of `items`, taken in turn and from the start again when used up
/// (none of an empty list).
fn cycled<T>(items: &[T], per_batch: usize, step: usize) -> impl Iterator<Item = &T> {
    let n = if items.is_empty() { 0 } else { per_batch };
    (0..n).filter_map(move |k| items.get((step * per_batch + k) % items.len()))
}

/// The learning rate after `done` of `total` steps: a cosine from `peak` down to 5 % of it.
pub fn cosine_lr(peak: f64, done: usize, total: usize) -> f64 {
    peak * (0.05 + 0.95 * 0.5 * (1.0 + (std::f64::consts::PI * done as f64 / total.max(1) as f64).cos()))
}

/// The order in which pass `pass` over chunk `chunk` shows its `n` samples: fixed for a seed.
pub fn pass_order(seed: u64, chunk: usize, pass: usize, n: usize) -> Vec<usize> {
    let mut order: Vec<usize> = (0..n).collect();
    let mut state = seed ^ ((chunk * 31 + pass) as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    for i in (1..order.len()).rev() {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        order.swap(i, (state % (i as u64 + 1)) as usize);
    }
    order
}

/// The initializer's loss on a batch: L1 over landmarks (weight 1), angles (2) and light (0.3).
pub fn initializer_loss(net: &Net, batch: &[&Sample], geo: &Geometry, device: &Device) -> candle_core::Result<Tensor> {
    let x = batch_tensor(batch.iter().map(|s| s.crop.as_slice()), geo.crop_side, device)?;
    let (out, _) = net.forward(&x)?;
    output_loss(out, batch, geo, device)
}

/// The initializer's loss of outputs `out` (`[batch, outputs]`): weighted L1 against the targets;
/// a NaN target (a real face's unknown pose and light) adds nothing.
pub fn output_loss(out: Tensor, batch: &[&Sample], geo: &Geometry, device: &Device) -> candle_core::Result<Tensor> {
    let d = geo.initializer_outputs();
    let weight = |i: usize| -> f32 {
        if i < 2 * geo.landmarks {
            1.0
        } else if i < 2 * geo.landmarks + 3 {
            2.0
        } else {
            0.3
        }
    };
    let (mut target, mut weights) = (Vec::with_capacity(batch.len() * d), Vec::with_capacity(batch.len() * d));
    for s in batch {
        for i in 0..d {
            let t = s.target.get(i).copied().unwrap_or(f32::NAN);
            target.push(if t.is_nan() { 0.0 } else { t });
            weights.push(if t.is_nan() { 0.0 } else { weight(i) });
        }
    }
    let target = Tensor::from_vec(target, (batch.len(), d), device)?;
    let w = Tensor::from_vec(weights, (batch.len(), d), device)?;
    ((out - target)?.abs()? * w)?.mean_all()? * (d as f64 / (2 * geo.landmarks) as f64)
}

/// Trains both networks on renders of `model` (faces on `head` when given) over procedural
/// backgrounds; returns the init file's bytes and the report.
pub fn train(
    model: &GpModel,
    head: Option<&HeadContext>,
    opts: &TrainOptions,
    progress: impl FnMut(Progress),
) -> Result<(Vec<u8>, TrainReport), TrainError> {
    train_with(model, head, None, opts, progress)
}

/// [`train`], some scenes over real face-free photos and, as many as `opts.face_free` says,
/// face-free frames mined from them.
pub fn train_with(
    model: &GpModel,
    head: Option<&HeadContext>,
    backgrounds: Option<&Backgrounds>,
    opts: &TrainOptions,
    progress: impl FnMut(Progress),
) -> Result<(Vec<u8>, TrainReport), TrainError> {
    train_on(&[model], head, backgrounds, None, opts, progress)
}

/// Both networks of the init file `from` trained further on scenes of a mixture of `models` (the
/// learning loop's retraining; [`TrainOptions::fine_tuning`] is the default length and rate).
pub fn fine_tune(
    models: &[&GpModel],
    head: Option<&HeadContext>,
    backgrounds: Option<&Backgrounds>,
    from: &[u8],
    opts: &TrainOptions,
    progress: impl FnMut(Progress),
) -> Result<(Vec<u8>, TrainReport), TrainError> {
    train_on(models, head, backgrounds, Some(from), opts, progress)
}

/// Trains both networks on scenes whose faces come from `models` (each scene's from one of them,
/// [`crate::scene::face_model_index`]; all in the first one's topology, `head` linked to the
/// first), starting from random weights or from the init file `from`. With `opts.chunks` zero,
/// `from`'s networks are only re-calibrated and re-quantized.
pub fn train_on(
    models: &[&GpModel],
    head: Option<&HeadContext>,
    backgrounds: Option<&Backgrounds>,
    from: Option<&[u8]>,
    opts: &TrainOptions,
    mut progress: impl FnMut(Progress),
) -> Result<(Vec<u8>, TrainReport), TrainError> {
    check_mixture(models)?;
    let openings: Vec<Openings> = models.iter().map(|m| Openings::of_model(m, &opts.ranges)).collect();
    let faces: Vec<FaceModel<'_>> = models.iter().zip(&openings).map(|(&model, openings)| FaceModel { model, openings }).collect();
    let source = SceneSource { faces: &faces, head, ranges: &opts.ranges, backgrounds };
    let model = faces[0].model;
    let landmarks = model.landmarks.len();
    if landmarks == 0 || landmarks > gpmm_core::format::init_file::MAX_INIT_LANDMARKS {
        return Err(TrainError::Landmarks(landmarks));
    }
    if opts.mirror && landmarks != gpmm_core::model::ibug::IBUG68_POINTS {
        return Err(TrainError::MirrorNeedsIbug68(landmarks));
    }
    let device = Device::Cpu;
    let geo = geometry(landmarks);
    let (finder, initializer, from_metadata) = match from {
        Some(bytes) => {
            let (f, i, metadata) = networks_of_init(bytes, &geo, &device).map_err(|error| TrainError::Start { error })?;
            (f, i, Some(metadata))
        }
        None => (
            Net::new(Shape { h: geo.frame_side, w: geo.frame_side, c: 3 }, finder_specs(), opts.seed, &device)
                .map_err(TrainError::Tensor)?,
            Net::new(
                Shape { h: geo.crop_side, w: geo.crop_side, c: 3 },
                initializer_specs(geo.initializer_outputs()),
                opts.seed ^ 1,
                &device,
            )
            .map_err(TrainError::Tensor)?,
            None,
        ),
    };
    let params = |lr| ParamsAdamW { lr, weight_decay: 1e-4, ..Default::default() };
    let mut opt_f = AdamW::new(finder.vars(), params(opts.lr)).map_err(TrainError::Tensor)?;
    let mut opt_i = AdamW::new(initializer.vars(), params(opts.lr)).map_err(TrainError::Tensor)?;
    let total = opts.steps();
    let net_total = opts.net_steps();
    let (mut done, mut net_done) = (0, [0usize; 2]);
    let (mut last_f, mut last_i) = (0.0f32, 0.0f32);
    let mut calib: Vec<Sample> = Vec::new();
    let (mut render_seconds, mut train_seconds) = (0.0, 0.0);
    // Each network's learning rate follows the cosine over its own steps.
    let lr_at = |done: usize, total: usize| cosine_lr(opts.lr, done, total);
    let mistakes = match (opts.scan_mistakes, from, backgrounds) {
        (None, _, _) => Mistakes::default(),
        (Some(scan), Some(bytes), Some(b)) => {
            progress(Progress::Scanning);
            scan_mistakes(bytes, b, geo.frame_side, scan)?
        }
        (Some(_), _, _) => return Err(TrainError::MistakesNeedStart),
    };
    let mistakes_per_batch = opts.scan_mistakes.map_or(0, |m| (opts.batch as f64 * m.per_scene).ceil() as usize);
    for chunk in 0..opts.chunks {
        progress(Progress::Rendering { chunk });
        let start = (chunk * opts.chunk_scenes) as u64;
        let t0 = std::time::Instant::now();
        let data = samples(source, &geo, opts.seed, start, opts.chunk_scenes as u64);
        render_seconds += t0.elapsed().as_secs_f64();
        let t0 = std::time::Instant::now();
        if data.is_empty() {
            return Err(TrainError::NoScenes);
        }
        let keep = if backgrounds.is_some() { (opts.chunk_scenes as f64 * opts.face_free).round() as usize } else { 0 };
        let face_free = mine_face_free(&finder, source, &geo, opts.seed ^ 0xFACE_F4EE, start, keep, &device).map_err(TrainError::Tensor)?;
        let per_batch = (opts.batch as f64 * opts.face_free).ceil() as usize;
        // Empty without photos of people.
        let n_real = (opts.chunk_scenes as f64 * opts.photo_faces).round() as u64;
        let real = photo_face_samples(source, &geo, opts.seed ^ 0x9E0_F1E5, start, n_real);
        let real_per_batch = (opts.batch as f64 * opts.photo_faces).ceil() as usize;
        // The real faces whose points the reference read teach the initializer those points.
        let real_crops: Vec<&Sample> = real.iter().filter(|s| opts.photo_points && !s.crop.is_empty()).collect();
        let (mut sum, mut n) = ([0.0f32; 2], [0usize; 2]);
        let (mut f, mut i) = (last_f, last_i);
        for pass in 0..opts.passes.max(opts.init_passes) {
            let order = pass_order(opts.seed, chunk, pass, data.len());
            let (train_f, train_i) = (pass < opts.passes, pass < opts.init_passes);
            for (step, idx) in order.chunks(opts.batch).enumerate() {
                let batch: Vec<&Sample> = idx.iter().map(|&i| &data[i]).collect();
                // The two networks learn from the same batch independently: their steps run side
                // by side (each alone leaves a core mostly idle between its matrix products).
                let finder_step = || -> Result<Option<f32>, TrainError> {
                    if !train_f {
                        return Ok(None);
                    }
                    opt_f.set_learning_rate(lr_at(net_done[0], net_total[0]));
                    // The mistakes in turn over the whole training, not from the start each pass.
                    let free: Vec<&[i8]> = cycled(&face_free, per_batch, step)
                        .chain(cycled(&mistakes.frames, mistakes_per_batch, net_done[0]))
                        .map(Vec::as_slice)
                        .collect();
                    let seen: Vec<&Sample> = batch.iter().copied().chain(cycled(&real, real_per_batch, step)).collect();
                    let lf = finder_loss(&finder, &seen, &free, &geo, &device).map_err(TrainError::Tensor)?;
                    opt_f.backward_step(&lf).map_err(TrainError::Tensor)?;
                    Ok(Some(lf.to_scalar::<f32>().map_err(TrainError::Tensor)?))
                };
                let initializer_step = || -> Result<Option<f32>, TrainError> {
                    if !train_i {
                        return Ok(None);
                    }
                    opt_i.set_learning_rate(lr_at(net_done[1], net_total[1]));
                    let with_real: Vec<&Sample> = batch.iter().copied().chain(cycled(&real_crops, real_per_batch, step).copied()).collect();
                    let li = if opts.mirror && pass % 2 == 1 {
                        let seen: Vec<Sample> = with_real.iter().filter_map(|s| s.mirrored(&geo)).collect();
                        initializer_loss(&initializer, &seen.iter().collect::<Vec<_>>(), &geo, &device).map_err(TrainError::Tensor)?
                    } else {
                        initializer_loss(&initializer, &with_real, &geo, &device).map_err(TrainError::Tensor)?
                    };
                    opt_i.backward_step(&li).map_err(TrainError::Tensor)?;
                    Ok(Some(li.to_scalar::<f32>().map_err(TrainError::Tensor)?))
                };
                let (lf, li) = rayon::join(finder_step, initializer_step);
                if let Some(v) = lf? {
                    f = v;
                    net_done[0] += 1;
                }
                if let Some(v) = li? {
                    i = v;
                    net_done[1] += 1;
                }
                if !(f.is_finite() && i.is_finite()) {
                    return Err(TrainError::Diverged { step: done, finder: f, initializer: i });
                }
                for (k, (last_pass, value)) in [(opts.passes, f), (opts.init_passes, i)].into_iter().enumerate() {
                    if pass + 1 == last_pass {
                        sum[k] += value;
                        n[k] += 1;
                    }
                }
                done += 1;
                progress(Progress::Step { done, total, finder: f, initializer: i });
            }
        }
        train_seconds += t0.elapsed().as_secs_f64();
        (last_f, last_i) = (sum[0] / n[0].max(1) as f32, sum[1] / n[1].max(1) as f32);
        if chunk + 1 == opts.chunks {
            calib = data.into_iter().take(CALIBRATION_SCENES).collect();
        }
    }
    progress(Progress::Validating);
    if calib.is_empty() {
        // No training chunk: calibrate on scenes of their own.
        calib = samples(source, &geo, opts.seed, 0, opts.chunk_scenes.min(CALIBRATION_SCENES) as u64);
        if calib.is_empty() {
            return Err(TrainError::NoScenes);
        }
    }
    let fx = batch_tensor(calib.iter().map(|s| s.frame.as_slice()), geo.frame_side, &device).map_err(TrainError::Tensor)?;
    let ix = batch_tensor(calib.iter().map(|s| s.crop.as_slice()), geo.crop_side, &device).map_err(TrainError::Tensor)?;
    let f_float = finder.to_float(&finder.calibrate(&fx).map_err(TrainError::Tensor)?).map_err(TrainError::Tensor)?;
    let i_float = initializer.to_float(&initializer.calibrate(&ix).map_err(TrainError::Tensor)?).map_err(TrainError::Tensor)?;
    let mut metadata = serde_json::json!({
        "format": "gpmm-init",
        "trained_on": model.metadata.kernel,
        "seed": opts.seed,
        "steps": total,
        "finder_steps": net_total[0],
        "initializer_steps": net_total[1],
        "mirror": opts.mirror,
        "scenes": opts.chunks * opts.chunk_scenes,
        "yaw_range_deg": opts.ranges.yaw,
        "head_vertices": head.map_or(0, HeadContext::vertices),
        "open_eyes": opts.ranges.open_eyes,
        "aspects": opts.ranges.aspects,
        "dressed": opts.ranges.dressed,
        "look_share": opts.ranges.look_share,
        "occluders": opts.ranges.occluders,
        // What every scene is, recorded as files have always recorded it: no open mouths, no
        // plainer skin, the prior's spread of shapes and colours, crops jittered as the finder
        // misses, no cast shadows.
        "open_mouth": false,
        "plain_skin": 0.0f32,
        "shape_sigma": [1.0f32, 1.0],
        "colour_spread": [1.0f32, 1.0],
        "wide_crops": 0.0f32,
        "shadows": false,
        "background_photos": backgrounds.map_or(0, Backgrounds::len),
        "background_share": backgrounds.map_or(0.0, |b| b.share),
        "face_free_frames": if backgrounds.is_some() { opts.face_free } else { 0.0 },
        "people_photos": backgrounds.map_or(0, Backgrounds::people_photos),
        "photo_faces": backgrounds.map_or(0, Backgrounds::faces),
        "photo_face_share": if backgrounds.is_some_and(|b| b.faces() > 0) { opts.photo_faces } else { 0.0 },
        "photo_points": opts.photo_points && backgrounds.is_some_and(|b| b.faces() > 0) && opts.photo_faces > 0.0,
        "created_by": concat!("gpmm-train ", env!("CARGO_PKG_VERSION")),
    });
    // A single model trained from random weights records what it always recorded.
    if models.len() > 1 {
        metadata["models"] = models
            .iter()
            .map(|m| serde_json::json!({ "kernel": m.metadata.kernel, "learning_iteration": m.metadata.learning.as_ref().map(|l| l.iteration) }))
            .collect();
    }
    if let Some(scan) = opts.scan_mistakes {
        metadata["scan_mistakes"] = serde_json::json!({
            "min_score": scan.min_score,
            "smallest_face": scan.smallest_face,
            "per_scene": scan.per_scene,
            "photos": mistakes.photos,
            "boxes": mistakes.boxes,
            "frames": mistakes.frames.len(),
        });
    }
    if let Some(from) = from_metadata {
        metadata["fine_tuned_from"] = serde_json::from_str(&from).unwrap_or(serde_json::Value::String(from));
    }
    let metadata = metadata.to_string();
    let bytes =
        init_file_bytes(&f_float, &i_float, geo.crop_margin, landmarks as u16, geo.light as u16, &metadata).map_err(TrainError::Encode)?;
    let mut detector = Detector::from_bytes(&bytes).map_err(TrainError::InitFile)?;
    let v = validate(source, opts.seed.wrapping_add(0x0DD5_EED5), opts.validation, &mut detector)?;
    let file = detector.file().map_err(TrainError::InitFile)?;
    let report = TrainReport {
        steps: total,
        finder_loss: last_f,
        initializer_loss: last_i,
        validation_scenes: v.scenes,
        found: v.found,
        median_landmark_error: v.landmark_error,
        median_yaw_error_deg: v.yaw_error,
        macs: [file.finder.macs(), file.initializer.macs()],
        bytes: bytes.len(),
        render_seconds,
        train_seconds,
        scan_mistakes: mistakes.boxes,
    };
    Ok((bytes, report))
}

/// The quantized detector measured on rendered scenes it was not trained on.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Validation {
    /// Scenes measured.
    pub scenes: usize,
    /// Fraction found (box centre within half a face size of the truth).
    pub found: f64,
    /// Median landmark error / inter-ocular distance.
    pub landmark_error: f64,
    /// Median |yaw error| (degrees).
    pub yaw_error: f64,
}

/// Runs the detector on `count` scenes of the stream `seed`.
pub fn validate(source: SceneSource<'_>, seed: u64, count: usize, detector: &mut Detector) -> Result<Validation, TrainError> {
    let mut renderer = Renderer::new();
    let (mut found, mut errors, mut yaws, mut scenes) = (0usize, Vec::new(), Vec::new(), 0usize);
    for i in 0..count as u64 {
        let Some(scene) = render_scene(source, seed, i, &mut renderer) else { continue };
        scenes += 1;
        let Some(det) = detector.detect(&scene.frame, 0.0, gpmm_core::net::face::Reading::DEFAULT).map_err(TrainError::Detect)? else {
            continue;
        };
        let (hit, error) = score_detection(&det, &scene.landmarks);
        found += usize::from(hit);
        errors.extend(error);
        yaws.push(f64::from((det.angles[0] - scene.angles[0]).abs().to_degrees()));
    }
    Ok(Validation {
        scenes,
        found: found as f64 / scenes.max(1) as f64,
        landmark_error: quantile(errors, 0.5),
        yaw_error: quantile(yaws, 0.5),
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn unknown_targets_add_nothing_to_the_initializers_loss() {
        let geo = geometry(68);
        let d = geo.initializer_outputs();
        let device = Device::Cpu;
        let known: Vec<f32> = (0..d).map(|i| (i as f32 * 0.61).sin()).collect();
        let out = Tensor::from_vec((0..2 * d).map(|i| (i as f32 * 0.23).cos()).collect::<Vec<f32>>(), (2, d), &device).unwrap();
        let sample = |target: Vec<f32>| Sample { frame: Vec::new(), cell: 0, place: [0.0; 3], crop: Vec::new(), target };
        let loss = |a: &Sample, b: &Sample| output_loss(out.clone(), &[a, b], &geo, &device).unwrap().to_scalar::<f32>().unwrap();
        let full = sample(known.clone());
        // The second sample's pose and light unknown: its points alone count.
        let mut points_only = known.clone();
        points_only.iter_mut().skip(2 * geo.landmarks).for_each(|v| *v = f32::NAN);
        let partial = sample(points_only);
        let with_nan = loss(&full, &partial);
        assert!(with_nan.is_finite());
        // Against the outputs themselves, the unknown entries' error would be zero: the same loss.
        let outs = out.to_vec2::<f32>().unwrap();
        let mut filled = known.clone();
        filled.iter_mut().enumerate().skip(2 * geo.landmarks).for_each(|(i, v)| *v = outs[1][i]);
        assert!((with_nan - loss(&full, &sample(filled))).abs() < 1e-6);
        // And less than with the known targets there.
        assert!(with_nan < loss(&full, &full));
    }
}
