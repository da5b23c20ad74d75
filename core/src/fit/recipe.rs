//! The standard fit, end to end, as one function: the host's `gpmm fit` and the firmware run
//! exactly this, so a seed gives the same fit on both (the parity test compares them).
//!
//! 1. Start: a scaled-orthographic least-squares pose of the mean face's landmarks
//!    ([`initial_guess`]; run twice, the first probe measures the depth at which the focal length
//!    puts the face at [`StartSettings::nominal_distance_mm`](crate::fit::settings::StartSettings)), ambient light, zero coefficients;
//!    the prior is centred on it ([`Prior::around`]).
//! 2. The landmark chain (prior × landmarks, no rendering) in two phases (by default the first
//!    only: [`LandmarkSettings::pose_share`](crate::fit::settings::LandmarkSettings) 1, the shape coming
//!    from step 3's solve), as the paper's fit script fits the pose to the landmarks before
//!    anything else: first the pose alone
//!    ([`Mixture::landmark_pose`]: no shape, no distance changes; the jaw contour's σ scaled by
//!    [`LandmarkSettings::contour_sigma_factor`](crate::fit::settings::LandmarkSettings)), then the shape with yaw and distance held
//!    ([`Mixture::landmark_shape`]). Letting shape and yaw move together trades one for the
//!    other: on faces from another model (ICT) such a joint chain underestimated a 30° yaw by
//!    5–7°, because the template's landmark depths (the silhouette contour above all) differ from
//!    the face's.
//! 3. The landmark chain's best sample gets the closed-form least-squares SH light on every
//!    visible vertex, then (if [`FitSettings::start`] asks for rounds) the colour coefficients
//!    solved for that light and the light again for the new albedo ([`crate::fit::solve::color`]), then
//!    the shape solve's rounds (Gauss–Newton on landmarks and image, [`crate::fit::solve::shape`]; the
//!    host's default, not on a device).
//! 4. The image chain from there (prior × landmarks × image, delayed acceptance; the parameters
//!    its mixture moves: by default pose, colour and light, the shape staying the solve's);
//!    optionally its best sample's colour and light solved again ([`ImageSettings::color_polish_rounds`](crate::fit::settings::ImageSettings)),
//!    kept if that raises the log posterior.
//!
//! Nothing allocates: the per-vertex buffers and the rasterizer are the caller's.

use crate::error::FitError;
use crate::fit::chain::observer::{Acceptance, ChainObserver, ChainSample, NoObserver, ProposalStep};
use crate::fit::chain::proposal::{Mixture, StandardProposal};
use crate::fit::chain::{image_chain, image_log_likelihood, landmark_chain, ChainState, FitResult, ImageProblem, Problem};
use crate::fit::coarse::half_resolution_chain;
use crate::fit::likelihood::contour::{hide_turned_away_contour, Silhouette};
use crate::fit::likelihood::image::{BackgroundModel, ImageEval, TargetImage};
use crate::fit::likelihood::labeller::Labeller;
use crate::fit::likelihood::landmarks::{LandmarkEval, LandmarkTarget};
use crate::fit::likelihood::occlusion::{OcclusionMask, OcclusionSettings};
use crate::fit::likelihood::pixel::GaussianPixel;
use crate::fit::likelihood::prior::Prior;
use crate::fit::settings::FitSettings;
use crate::fit::solve::color::{solve_color, ColorScene, ColorSolveConfig};
use crate::fit::solve::light::{solve_light, LightSolveConfig};
use crate::fit::solve::shape::{solve_shape, ShapeSolveConfig};
use crate::fit::spread::PoseSpread;
use crate::fit::start::{initial_guess, landmark_pivot};
use crate::format::fit_record::FitFigures;
use crate::geometry::TriIndex;
use crate::model::instance::Instance;
use crate::model::morphable::MorphableModel;
use crate::model::params::FitParams;
use crate::render::{Cull, ShLight, TileRasterizer};
use rand_core::Rng;

/// Landmark count of the iBUG-68 scheme, whose first 17 points are the jaw contour.
const IBUG68: usize = 68;

/// The stage a progress report is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    /// The landmark chain.
    LandmarkChain,
    /// The least-squares light and the image chain.
    ImageChain,
}

/// Receives progress: `step(stage, done, total)` before each step of a chain and once with
/// `done == total` when it ends (the firmware reads its instruction counter here), and every
/// proposal's outcome (`proposal`, by default ignored).
///
/// # Examples
///
/// An observer of one's own that keeps each stage's last progress report and counts the
/// proposals of each stage of a short [`standard_fit`] (a device would read its cycle counter in
/// `step`):
///
/// ```
/// use gpmm_core::fit::{standard_fit, FitObserver, FitSettings, OcclusionMask, ProposalStep, Stage};
/// # use gpmm_core::fit::{project_landmarks, TargetImage};
/// # use gpmm_core::model::{Basis, FactoredBasis, FitParams, Instance, InstanceBuffers, MorphableModel};
/// # use gpmm_core::render::{Pose, ProjectedVertex, ShLight, TileRasterizer};
/// # use rand_core::SeedableRng;
///
/// #[derive(Default)]
/// struct Log {
///     last: Vec<(Stage, u32, u32)>,
///     proposals: [u32; 2],
/// }
///
/// impl FitObserver for Log {
///     fn step(&mut self, stage: Stage, done: u32, total: u32) {
///         self.last.retain(|(s, _, _)| *s != stage);
///         self.last.push((stage, done, total));
///     }
///
///     fn proposal(&mut self, stage: Stage, _step: &ProposalStep) {
///         self.proposals[usize::from(stage == Stage::ImageChain)] += 1;
///     }
/// }
///
/// # // A tetrahedron (mm) with one shape component, every vertex a landmark, on a grey image.
/// # let shape_mean = [[-10.0, -8.0, 0.0], [10.0, -8.0, 0.0], [0.0, 12.0, 0.0], [0.0, 0.0, 10.0]];
/// # let (fields, directions) = ([0.0, 0.0, 0.0, 5.0], [[0.0, 0.0, 1.0]]);
/// # let shape = Basis::Factored(FactoredBasis::new(&fields, &directions, 4)?);
/// # let color = Basis::Factored(FactoredBasis::new(&[], &[], 4)?);
/// # let triangles: [[u32; 3]; 4] = [[0, 2, 1], [0, 1, 3], [1, 2, 3], [2, 0, 3]];
/// # let model = MorphableModel::new(&shape_mean, &[[0.6, 0.5, 0.4]; 4], shape, color, &triangles, &[0, 1, 2, 3])?;
/// # let truth = FitParams::<1, 1>::new(Pose { yaw: 0.3, ..Pose::frontal(200.0) }, 200.0, ShLight::ambient_white(), 1, 0);
/// # let mut points = [[0.0f32; 2]; 4];
/// # project_landmarks(&model, &truth, 32, 32, &mut points)?;
/// # let pixels = [[150u8, 125, 100]; 32 * 32];
/// # let image = TargetImage::new(&pixels, 32, 32)?;
/// # let (mut positions, mut albedos, mut normals) = ([[0.0; 3]; 4], [[0.0; 3]; 4], [[0.0; 3]; 4]);
/// # let mut projected = [ProjectedVertex::INVALID; 4];
/// # let bufs = InstanceBuffers { positions: &mut positions, albedos: &mut albedos, normals: &mut normals, projected: &mut projected };
/// # let mut instance = Instance::<1, 1>::new(bufs, 4)?;
/// # let mut raster = TileRasterizer::<16, 16, 64>::new();
/// # let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(7);
/// // A short fit of a tetrahedron's landmarks and image (set up as in `standard_fit`'s example).
/// let settings = FitSettings::DEFAULT.with_steps(200, 40).without_shape_solve().with_ranks(1, 0);
/// let mut log = Log::default();
/// let mut mask = OcclusionMask::<32>::new();
/// standard_fit(&model, image, &points, &[true; 4], &settings, &mut instance, &mut raster, &mut mask, &mut rng, &mut log)?;
///
/// // Both landmark phases report as one chain of 200 steps; each chain ends with done == total.
/// assert_eq!(log.last, [(Stage::LandmarkChain, 200, 200), (Stage::ImageChain, 40, 40)]);
/// assert_eq!(log.proposals, [200, 40]);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub trait FitObserver {
    /// One progress report.
    fn step(&mut self, stage: Stage, done: u32, total: u32);

    /// One mixture component of a chain of `stage`, before its first step (see
    /// [`ChainObserver::component`]).
    fn component(&mut self, _stage: Stage, _id: usize, _name: &'static str) {}

    /// One proposal of a chain of `stage` (both landmark phases report [`Stage::LandmarkChain`]).
    fn proposal(&mut self, _stage: Stage, _step: &ProposalStep) {}

    /// The state of a chain of `stage` after a step (see [`ChainObserver::sample`]).
    fn sample(&mut self, _stage: Stage, _sample: &ChainSample<'_>) {}
}

/// A [`FitObserver`] seen by one chain (or one phase of the landmark chain): progress is shifted
/// by `offset` steps of `total`, reported only below `steps` (and at the end if `report_end`).
struct PhaseObserver<'o> {
    observer: &'o mut dyn FitObserver,
    stage: Stage,
    offset: u32,
    total: u32,
    steps: u32,
    report_end: bool,
}

impl ChainObserver for PhaseObserver<'_> {
    fn component(&mut self, id: usize, name: &'static str) {
        self.observer.component(self.stage, id, name)
    }

    fn progress(&mut self, done: u32) {
        if done < self.steps || self.report_end {
            self.observer.step(self.stage, self.offset + done, self.total)
        }
    }

    fn proposal(&mut self, step: &ProposalStep) {
        self.observer.proposal(self.stage, &ProposalStep { step: self.offset + step.step, ..*step })
    }

    fn sample(&mut self, sample: &ChainSample<'_>) {
        self.observer.sample(self.stage, &ChainSample { step: self.offset + sample.step, ..*sample })
    }
}

impl<F: FnMut(Stage, u32, u32)> FitObserver for F {
    fn step(&mut self, stage: Stage, done: u32, total: u32) {
        self(stage, done, total)
    }
}

/// Everything [`standard_fit`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct StandardFit<const KS: usize, const KC: usize> {
    /// The start of the landmark chain.
    pub init: FitParams<KS, KC>,
    /// Proposal counts of the landmark chain's pose phase (its mixture: [`Mixture::landmark_pose`]).
    pub pose_acceptance: Acceptance,
    /// The landmark chain's shape phase (started from the pose phase's best sample).
    pub landmark: FitResult<KS, KC>,
    /// The shape phase's best sample with the least-squares light: the image chain's start.
    pub start: FitParams<KS, KC>,
    /// The image term of `start`.
    pub start_image: ImageEval,
    /// The landmark term of `start`.
    pub start_landmarks: LandmarkEval,
    /// The image chain (its `best` is the fit; with occlusion rounds, its parts together).
    pub image: FitResult<KS, KC>,
    /// The last labelling of what the face does not explain (`None` without occlusion rounds).
    pub occlusion: Option<OcclusionFigures>,
}

/// The labels of an occlusion-aware fit's last labelling.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct OcclusionFigures {
    /// Working pixels labelled occluded.
    pub occluded: u32,
    /// Photo pixels the labelled sample's face covered.
    pub covered: u32,
}

impl OcclusionFigures {
    /// The occluded fraction of the face's pixels (0 if it covers none).
    pub fn fraction(&self) -> f32 {
        if self.covered == 0 {
            0.0
        } else {
            (self.occluded as f32 / self.covered as f32).min(1.0)
        }
    }
}

impl<const KS: usize, const KC: usize> StandardFit<KS, KC> {
    /// The fit: the image chain's best sample.
    pub fn params(&self) -> &FitParams<KS, KC> {
        &self.image.best
    }
}

/// Runs the standard fit of `model` to `image` with target `landmarks` (working-image pixels, one
/// per model landmark; `valid` marks the usable ones). `instance` must be built for `model`.
///
/// ```
/// use gpmm_core::fit::{project_landmarks, standard_fit, FitSettings, OcclusionMask, Stage, TargetImage};
/// use gpmm_core::model::{Basis, FactoredBasis, FitParams, Instance, InstanceBuffers, MorphableModel};
/// use gpmm_core::render::{Pose, ProjectedVertex, ShLight, TileRasterizer};
/// use rand_core::SeedableRng;
///
/// // A tetrahedron (mm), its apex toward the camera, with one shape component (the apex's
/// // height) and no colour component; every vertex is a landmark.
/// let shape_mean = [[-10.0, -8.0, 0.0], [10.0, -8.0, 0.0], [0.0, 12.0, 0.0], [0.0, 0.0, 10.0]];
/// let color_mean = [[0.6, 0.5, 0.4]; 4];
/// let (fields, directions) = ([0.0, 0.0, 0.0, 5.0], [[0.0, 0.0, 1.0]]);
/// let shape = Basis::Factored(FactoredBasis::new(&fields, &directions, 4)?);
/// let color = Basis::Factored(FactoredBasis::new(&[], &[], 4)?);
/// let triangles: [[u32; 3]; 4] = [[0, 2, 1], [0, 1, 3], [1, 2, 3], [2, 0, 3]];
/// let model = MorphableModel::new(&shape_mean, &color_mean, shape, color, &triangles, &[0, 1, 2, 3])?;
///
/// // The target: the landmarks of the model turned and close to a wide-angle camera (60 mm, a
/// // perspective the start's orthographic fit misses), on a grey image.
/// let (w, h) = (32, 32);
/// let turned = Pose { yaw: 0.5, pitch: -0.2, ..Pose::frontal(60.0) };
/// let truth = FitParams::<1, 1>::new(turned, 48.0, ShLight::ambient_white(), 1, 0);
/// let mut points = [[0.0f32; 2]; 4];
/// project_landmarks(&model, &truth, w, h, &mut points)?;
/// let pixels = [[150u8, 125, 100]; 32 * 32];
/// let image = TargetImage::new(&pixels, w, h)?;
///
/// // The per-vertex buffers, the rasterizer and a seeded generator: nothing is allocated.
/// let (mut positions, mut albedos, mut normals) = ([[0.0; 3]; 4], [[0.0; 3]; 4], [[0.0; 3]; 4]);
/// let mut projected = [ProjectedVertex::INVALID; 4];
/// let bufs = InstanceBuffers { positions: &mut positions, albedos: &mut albedos, normals: &mut normals, projected: &mut projected };
/// let mut instance = Instance::<1, 1>::new(bufs, 4)?;
/// let mut raster = TileRasterizer::<16, 16, 64>::new();
/// let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(7);
///
/// // A short fit: few steps, no start shape solve; the occlusion labels (one bit per pixel) are
/// // the caller's too, though these settings infer none.
/// let settings = FitSettings::DEFAULT.with_steps(400, 40).without_shape_solve().with_ranks(1, 0);
/// let mut mask = OcclusionMask::<{ 32 * 32 / 32 }>::new();
/// let mut progress = |_: Stage, _: u32, _: u32| {};
/// let fit = standard_fit(&model, image, &points, &[true; 4], &settings, &mut instance, &mut raster, &mut mask, &mut rng, &mut progress)?;
///
/// // The landmarks' pixel error of the start and of the fit.
/// let error = |p: &FitParams<1, 1>| -> f32 {
///     let mut at = [[0.0f32; 2]; 4];
///     project_landmarks(&model, p, w, h, &mut at).map_or(f32::INFINITY, |_| {
///         at.iter().zip(&points).map(|(a, b)| (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sum::<f32>().sqrt()
///     })
/// };
/// assert!(fit.image.best_log_posterior.is_finite());
/// assert!(error(fit.params()) <= error(&fit.init), "{} > {}", error(fit.params()), error(&fit.init));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[allow(clippy::too_many_arguments)]
pub fn standard_fit<
    R: Rng + ?Sized,
    I: TriIndex,
    const KS: usize,
    const KC: usize,
    const TW: usize,
    const TH: usize,
    const BIN: usize,
    const MW: usize,
>(
    model: &MorphableModel<'_, I>,
    image: TargetImage<'_>,
    landmarks: &[[f32; 2]],
    valid: &[bool],
    settings: &FitSettings,
    instance: &mut Instance<'_, KS, KC>,
    raster: &mut TileRasterizer<TW, TH, BIN>,
    mask: &mut OcclusionMask<MW>,
    rng: &mut R,
    observer: &mut dyn FitObserver,
) -> Result<StandardFit<KS, KC>, FitError> {
    settings.validate()?;
    let (w, h) = (image.width(), image.height());
    let side = w.max(h) as f32;
    let lm = LandmarkTarget::new(landmarks, valid, settings.landmarks.sigma * side)?.with_student_t(settings.landmarks.student_t)?;
    let contour = settings.landmarks.contour_landmarks.min(crate::fit::MAX_CONTOUR);
    let silhouette = if settings.landmarks.silhouette && lm.len() == IBUG68 { Some(Silhouette::new(model, &lm, contour)?) } else { None };
    let lm = match &silhouette {
        Some(s) => lm.with_outward(s.outward())?,
        None => lm,
    };
    let (shape_len, color_len) = (settings.ranks.shape, settings.ranks.color);

    // 1. The start and the prior.
    let ambient = settings.light.start_light();
    let probe: FitParams<KS, KC> = initial_guess(model, &lm, w as f32, w, h, ambient, shape_len, color_len)?;
    let pivot = landmark_pivot(model, Some(&lm))?;
    let depth = -(probe.pose.translation[2] + pivot[2]);
    let focal = if depth > 0.0 && depth.is_finite() { w as f32 * settings.start.nominal_distance_mm / depth } else { w as f32 };
    let init: FitParams<KS, KC> = initial_guess(model, &lm, focal, w, h, ambient, shape_len, color_len)?;
    let prior = Prior::around(&init);

    // 2. The landmark chain: the pose (contour σ scaled), then the shape with yaw and distance held.
    let (pose_acceptance, landmark) = landmark_phases(model, lm, silhouette.as_ref(), &prior, &init, settings, w, h, rng, observer)?;

    // 3. The least-squares light of its best sample (kept only if the solve succeeds); with
    // occlusion rounds, the pixels labelled and the light solved again on the face's.
    let background = BackgroundModel::from_image(&image, settings.image.background_floor)?;
    let pixel = GaussianPixel::new(settings.image.pixel_sigma)?;
    let occ = settings.occlusion;
    mask.reset(if occ.enabled() { w } else { 0 }, h)?;
    let mut labels = Labels { image, pixel, background: &background, settings: occ, figures: None };
    let mut start = landmark.best.clone();
    instance.update(model, &start, w, h)?;
    let every_vertex = settings.light.solve_config(settings.light.start_stride);
    if let Some(l) = light_of(instance, &start, w, h, &image, &every_vertex) {
        start.light = l;
    }
    if occ.enabled() {
        labels.label(model, &start, instance, raster, mask)?;
        if let Some(l) = light_of(instance, &start, w, h, &labels.target(mask)?, &every_vertex) {
            start.light = l;
        }
        labels.label(model, &start, instance, raster, mask)?;
    }
    // Contour points on the side turned away are left to the pose phase.
    let mut seen = [false; crate::model::MAX_LANDMARKS];
    let seen = seen.get_mut(..valid.len()).ok_or(FitError::TooManyLandmarks)?;
    seen.copy_from_slice(valid);
    if lm.len() == IBUG68 {
        let (positions, normals) = (instance.positions(), instance.normals());
        hide_turned_away_contour(model, positions, normals, &start.pose, contour, settings.landmarks.hidden_contour_min_cos, seen);
    }
    let lm = if seen.iter().any(|&v| v) { lm.with_valid(seen)? } else { lm };
    color_rounds::<I, KS, KC>(model, &labels.target(mask)?, settings, settings.start.color_rounds, &mut start, instance, w, h)?;
    if occ.enabled() && settings.start.shape_rounds > 0 {
        labels.label(model, &start, instance, raster, mask)?;
    }
    let shape_lm = settings.start.shape_landmarks.then_some(&lm);
    shape_rounds::<I, KS, KC>(model, &labels.target(mask)?, shape_lm, settings, &mut start, instance, w, h)?;

    // 4. The image chain, its landmark σ scaled.
    let img_mix = Mixture::from_shares(&settings.proposals.image, &settings.proposals.drift, side)?;
    let img_lm = lm.with_sigma(lm.sigma() * settings.image.landmark_sigma_factor)?;
    let problem = Problem {
        model: *model,
        landmarks: img_lm,
        prior: &prior,
        mixture: &img_mix,
        width: w,
        height: h,
        silhouette: silhouette.as_ref(),
    };
    if occ.enabled() {
        labels.label(model, &start, instance, raster, mask)?;
    }
    let light_solve = settings.light.solve_config(settings.light.solve_stride);
    let start_image = {
        let ip = ImageProblem { image: labels.target(mask)?, pixel, background: &background, light_solve };
        image_log_likelihood(&problem, &ip, &start, instance, raster)?
    };
    // Zero steps draw nothing from the generator: this only evaluates the landmark term.
    let start_landmarks = landmark_chain(&problem, &start, 0, rng, NoObserver)?.best_landmarks;
    // The image chain: its first `coarse_steps` at half resolution, then the rest in `rounds`
    // parts with occlusion rounds: each from the best sample so far, its pixels labelled again.
    let img_steps = settings.image.steps;
    let coarse = settings.image.coarse_steps.min(img_steps);
    let mut image: Option<FitResult<KS, KC>> = None;
    if coarse > 0 {
        let ip = ImageProblem { image: labels.target(mask)?, pixel, background: &background, light_solve };
        let phase = PhaseObserver {
            observer: &mut *observer,
            stage: Stage::ImageChain,
            offset: 0,
            total: img_steps,
            steps: coarse,
            report_end: false,
        };
        image = Some(half_resolution_chain(&problem, &ip, &settings.proposals, &mut start, coarse, instance, raster, rng, phase)?);
    }
    let fine = img_steps - coarse;
    let parts = occ.rounds.clamp(1, fine.max(1));
    let mut done = coarse;
    for part in 0..parts {
        let steps = coarse + fine * (part + 1) / parts - done;
        let from = match &image {
            Some(r) => {
                if occ.enabled() {
                    labels.label(model, &r.best, instance, raster, mask)?;
                }
                r.best.clone()
            }
            None => start.clone(),
        };
        let ip = ImageProblem { image: labels.target(mask)?, pixel, background: &background, light_solve };
        let last = part + 1 == parts;
        let phase =
            PhaseObserver { observer: &mut *observer, stage: Stage::ImageChain, offset: done, total: img_steps, steps, report_end: last };
        let mut next = image_chain(&problem, &ip, &from, steps, instance, raster, rng, phase)?;
        if last {
            polish(&problem, &ip, settings, &mut next, instance, raster)?;
        }
        done += steps;
        image = Some(match image {
            Some(before) => FitResult { acceptance: before.acceptance.combined(&next.acceptance), steps: done, ..next },
            None => next,
        });
    }
    let image = image.ok_or(FitError::BadConfig)?;
    Ok(StandardFit { init, pose_acceptance, landmark, start, start_image, start_landmarks, image, occlusion: labels.figures })
}

/// The occlusion labels' inputs and the last labelling's figures.
struct Labels<'a, 'b> {
    image: TargetImage<'a>,
    pixel: GaussianPixel,
    background: &'b BackgroundModel,
    settings: OcclusionSettings,
    figures: Option<OcclusionFigures>,
}

impl<'a> Labels<'a, '_> {
    /// Labels the pixels `params`' face covers ([`Labeller`]) and smooths the labels.
    #[inline(never)]
    fn label<I: TriIndex, const KS: usize, const KC: usize, const TW: usize, const TH: usize, const BIN: usize, const MW: usize>(
        &mut self,
        model: &MorphableModel<'_, I>,
        params: &FitParams<KS, KC>,
        instance: &mut Instance<'_, KS, KC>,
        raster: &mut TileRasterizer<TW, TH, BIN>,
        mask: &mut OcclusionMask<MW>,
    ) -> Result<(), FitError> {
        let (w, h) = (self.image.width(), self.image.height());
        instance.update(model, params, w, h)?;
        let mut sink = Labeller::new(mask, self.image, self.pixel, self.background, self.settings.threshold)?;
        raster.render(instance.projected(), model.triangles(), w, h, Cull::Clockwise, &mut sink)?;
        let covered = sink.covered();
        mask.smooth(self.settings.smoothing);
        self.figures = Some(OcclusionFigures { occluded: mask.count(), covered });
        Ok(())
    }

    /// The target image, its occluded pixels absent (all observed without occlusion rounds).
    fn target<'m, const MW: usize>(&self, mask: &'m OcclusionMask<MW>) -> Result<TargetImage<'m>, FitError>
    where
        'a: 'm,
    {
        if self.settings.enabled() {
            self.image.with_mask(mask.view())
        } else {
            Ok(self.image)
        }
    }
}

/// The image chain's best sample after [`ImageSettings::color_polish_rounds`](crate::fit::settings::ImageSettings)
/// colour-and-light rounds, kept if its log posterior (prior, landmarks, image) is higher.
#[inline(never)]
fn polish<I: TriIndex, const KS: usize, const KC: usize, const TW: usize, const TH: usize, const BIN: usize>(
    problem: &Problem<'_, I, StandardProposal>,
    ip: &ImageProblem<'_, GaussianPixel, BackgroundModel>,
    settings: &FitSettings,
    image: &mut FitResult<KS, KC>,
    instance: &mut Instance<'_, KS, KC>,
    raster: &mut TileRasterizer<TW, TH, BIN>,
) -> Result<(), FitError> {
    let rounds = settings.image.color_polish_rounds;
    if rounds == 0 {
        return Ok(());
    }
    let (w, h) = (problem.width, problem.height);
    let mut p = image.best.clone();
    instance.update(&problem.model, &p, w, h)?;
    color_rounds::<I, KS, KC>(&problem.model, &ip.image, settings, rounds, &mut p, instance, w, h)?;
    let state = ChainState::new(problem, &p)?;
    let Ok(eval) = image_log_likelihood(problem, ip, &p, instance, raster) else { return Ok(()) };
    let posterior = state.filter_term() + eval.log_likelihood;
    if posterior > image.best_log_posterior {
        image.best = p;
        image.best_log_posterior = posterior;
        image.best_landmarks = state.landmarks;
        image.best_image = Some(eval);
    }
    Ok(())
}

/// `rounds` colour-and-light rounds on `start` (step 3 of [`standard_fit`] with
/// [`StartSettings::color_rounds`](crate::fit::settings::StartSettings), and the polish): the colour
/// coefficients solved for the light, then the light for the new albedo; a failed solve ends
/// the rounds and keeps what was found before it. `instance` must hold `start`.
#[inline(never)]
#[allow(clippy::too_many_arguments)]
fn color_rounds<I: TriIndex, const KS: usize, const KC: usize>(
    model: &MorphableModel<'_, I>,
    image: &TargetImage<'_>,
    settings: &FitSettings,
    rounds: u32,
    start: &mut FitParams<KS, KC>,
    instance: &mut Instance<'_, KS, KC>,
    w: u32,
    h: u32,
) -> Result<(), FitError> {
    let s = &settings.start;
    let config = ColorSolveConfig {
        stride: s.color_stride,
        min_cos: settings.light.min_cos,
        pixel_sigma: settings.image.pixel_sigma,
        weight: s.color_weight,
        iterations: s.color_iterations,
    };
    let every_vertex = settings.light.solve_config(settings.light.start_stride);
    for _ in 0..rounds {
        let camera = start.camera(w, h);
        // A copy: the solve writes the coefficients while the scene borrows the pose and light.
        let mut coeffs = [0.0f32; KC];
        let Some(c) = coeffs.get_mut(..start.color_coeffs().len()) else { break };
        c.copy_from_slice(start.color_coeffs());
        let scene = ColorScene {
            positions: instance.positions(),
            normals: instance.normals(),
            pose: &start.pose,
            camera: &camera,
            light: &start.light,
            image,
        };
        if solve_color::<I, KC>(model, &scene, &config, c).is_err() {
            break;
        }
        start.color_coeffs_mut().copy_from_slice(c);
        instance.update(model, start, w, h)?;
        match light_of(instance, start, w, h, image, &every_vertex) {
            Some(l) => start.light = l,
            None => break,
        }
    }
    Ok(())
}

/// The least-squares light of `params` on `target` over `instance` (which holds `params`'
/// instance) with `config`, if the solve succeeds.
fn light_of<const KS: usize, const KC: usize>(
    instance: &Instance<'_, KS, KC>,
    params: &FitParams<KS, KC>,
    w: u32,
    h: u32,
    target: &TargetImage<'_>,
    config: &LightSolveConfig,
) -> Option<ShLight> {
    solve_light(instance.positions(), instance.normals(), instance.albedos(), &params.pose, &params.camera(w, h), target, config).ok()
}

/// [`StartSettings::shape_rounds`](crate::fit::settings::StartSettings) shape-and-light rounds on
/// `start` (step 3 of [`standard_fit`]): the leading shape components by Gauss–Newton on the
/// image, then the light (and, with colour rounds, one colour round). A failed solve ends the
/// rounds and keeps what was found before it. `instance` must hold `start`.
#[inline(never)]
#[allow(clippy::too_many_arguments)]
fn shape_rounds<I: TriIndex, const KS: usize, const KC: usize>(
    model: &MorphableModel<'_, I>,
    image: &TargetImage<'_>,
    landmarks: Option<&LandmarkTarget<'_>>,
    settings: &FitSettings,
    start: &mut FitParams<KS, KC>,
    instance: &mut Instance<'_, KS, KC>,
    w: u32,
    h: u32,
) -> Result<(), FitError> {
    let s = &settings.start;
    if s.shape_rounds == 0 {
        return Ok(());
    }
    let config = ShapeSolveConfig {
        stride: s.shape_stride,
        min_cos: s.shape_min_cos,
        pixel_sigma: settings.image.pixel_sigma,
        weight: s.shape_weight,
        components: s.shape_components,
        iterations: s.shape_iterations,
        pose: s.shape_pose,
    };
    let every_vertex = settings.light.solve_config(settings.light.start_stride);
    for _ in 0..s.shape_rounds {
        if solve_shape(model, instance, start, image, landmarks, &config).is_err() {
            break;
        }
        match light_of(instance, start, w, h, image, &every_vertex) {
            Some(l) => start.light = l,
            None => break,
        }
        color_rounds::<I, KS, KC>(model, image, settings, u32::from(s.color_rounds > 0), start, instance, w, h)?;
    }
    instance.update(model, start, w, h)?;
    Ok(())
}

/// The two phases of the landmark chain (step 2 of [`standard_fit`]): returns the pose phase's
/// proposal counts and the shape phase's result. A function of its own so that its mixtures and
/// σ factors leave the stack before the image chain runs (the M4F's stack is tight).
#[inline(never)]
#[allow(clippy::too_many_arguments)]
fn landmark_phases<R: Rng + ?Sized, I: TriIndex, const KS: usize, const KC: usize>(
    model: &MorphableModel<'_, I>,
    lm: LandmarkTarget<'_>,
    silhouette: Option<&Silhouette<'_>>,
    prior: &Prior,
    init: &FitParams<KS, KC>,
    settings: &FitSettings,
    w: u32,
    h: u32,
    rng: &mut R,
    observer: &mut dyn FitObserver,
) -> Result<(Acceptance, FitResult<KS, KC>), FitError> {
    let n = lm.len();
    let mut factors = [1.0f32; crate::model::MAX_LANDMARKS];
    if n == IBUG68 {
        for f in factors.iter_mut().take(settings.landmarks.contour_landmarks) {
            *f = settings.landmarks.contour_sigma_factor;
        }
    }
    let pose_lm = lm.with_sigma_factors(factors.get(..n).ok_or(FitError::TooManyLandmarks)?)?;
    let pose_mix = Mixture::from_shares(&settings.proposals.landmark_pose, &settings.proposals.drift, w.max(h) as f32)?;
    let pose_problem = Problem { model: *model, landmarks: pose_lm, prior, mixture: &pose_mix, width: w, height: h, silhouette };
    let total = settings.landmarks.steps;
    // The pose phase's share, rounded down (f32 → u32 saturates; the share is checked to be ≤ 1).
    let pose_steps = ((total as f32 * settings.landmarks.pose_share) as u32).min(total);
    let phase =
        PhaseObserver { observer: &mut *observer, stage: Stage::LandmarkChain, offset: 0, total, steps: pose_steps, report_end: false };
    let pose = landmark_chain(&pose_problem, init, pose_steps, rng, phase)?;
    let shape_mix = Mixture::from_shares(&settings.proposals.landmark_shape, &settings.proposals.drift, w.max(h) as f32)?;
    let shape_problem = Problem { landmarks: lm, mixture: &shape_mix, ..pose_problem };
    let shape_steps = total - pose_steps;
    let phase = PhaseObserver { observer, stage: Stage::LandmarkChain, offset: pose_steps, total, steps: shape_steps, report_end: true };
    let landmark = landmark_chain(&shape_problem, &pose.best, shape_steps, rng, phase)?;
    Ok((pose.acceptance, landmark))
}

/// Projects the model landmarks of `params` into a `width × height` image: `out[i]` gets landmark
/// `i` in pixels (NaN if it is behind the camera). Returns the number written.
pub fn project_landmarks<I: TriIndex, const KS: usize, const KC: usize>(
    model: &MorphableModel<'_, I>,
    params: &FitParams<KS, KC>,
    width: u32,
    height: u32,
    out: &mut [[f32; 2]],
) -> Result<usize, FitError> {
    let mut lm = [[0.0f32; 3]; crate::model::MAX_LANDMARKS];
    let n = model.landmark_positions(params.shape_coeffs(), &mut lm)?;
    if out.len() < n {
        return Err(FitError::LengthMismatch);
    }
    let cam = params.camera(width, height);
    for (o, p) in out.iter_mut().zip(lm.iter().take(n)) {
        *o = cam.project(params.pose.transform_point(*p)).map_or([f32::NAN; 2], |s| [s.x, s.y]);
    }
    Ok(n)
}

impl<const KS: usize, const KC: usize> StandardFit<KS, KC> {
    /// Accepted over proposed in the whole landmark chain, its pose and shape phases together
    /// (either may have no steps: by default the pose phase has them all).
    pub fn landmark_acceptance(&self) -> f32 {
        self.pose_acceptance.combined(&self.landmark.acceptance).overall()
    }

    /// The fit record's figures of this fit (`GPFR`) with the pose's `spread` from the landmarks
    /// ([`crate::fit::pose_spread`] of [`Self::params`]; `None`: zero, not measured): the firmware
    /// logs them and the host's parity run writes the same, so two records are equal exactly when
    /// the fits are. The spread is the caller's to compute after the fit, outside the fit's stack
    /// frame.
    pub fn record_figures(&self, spread: Option<&PoseSpread>) -> FitFigures {
        let p = self.params();
        let img = self.image.best_image.unwrap_or(self.start_image);
        FitFigures {
            yaw: p.pose.yaw,
            pitch: p.pose.pitch,
            roll: p.pose.roll,
            focal: p.focal,
            translation: p.pose.translation,
            log_posterior: self.image.best_log_posterior,
            log_likelihood: img.log_likelihood,
            landmark_log_likelihood: self.image.best_landmarks.log_likelihood,
            landmark_rmse_px: self.image.best_landmarks.rmse(),
            pixel_rmse: img.rmse(),
            acceptance_landmark_chain: self.landmark_acceptance(),
            acceptance_image_chain: self.image.acceptance.overall(),
            covered_pixels: img.covered,
            angles_sd: spread.map_or([0.0; 3], |s| s.angles_sd),
            translation_sd: spread.map_or([0.0; 3], |s| s.translation_sd),
            landmark_residual_px: spread.map_or(0.0, |s| s.residual_sigma_px),
        }
    }
}
