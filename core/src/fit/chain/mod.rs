//! Metropolis-Hastings with delayed acceptance: a landmark chain, then an image chain.
//!
//! Target densities: landmark chain `prior × landmarks`; image chain `prior × landmarks × image`.
//! A step draws a mixture component ([`Mixture::choose`]), proposes `x'` and then
//! 1. (both chains) accepts with `min(1, [p(x') L_lm(x') q(x | x')] / [p(x) L_lm(x) q(x' | x)])`
//!    — prior, landmarks and the Hastings term; no rendering. Most bad proposals end here.
//! 2. (image chain only) a survivor is rendered and accepted with `min(1, L_img(x') / L_img(x))`.
//!
//! This two-stage rule (Christen & Fox 2005; scalismo-faces' `MetropolisFilterProposal`) keeps
//! the full posterior invariant. The Hastings term may sit in either stage: with the first stage
//! `min(1, π₀(x')/π₀(x))` the second becomes `min(1, [L_img(x') q(x | x')] / [L_img(x) q(x' | x)])`
//! (the first stage's own ratio cancels). The image chain puts it in the second stage, because
//! the least-squares light proposal's Hastings term is large and only the image term can pay
//! for it; the landmark chain has a single stage. Both chains are one loop ([`run_chain`] over a
//! [`SecondStage`]: none, or the rendered image). Every proposal's outcome goes to a
//! [`ChainObserver`]; [`Acceptance`] counts per mixture component. The best sample
//! (highest log posterior seen) and the last sample are returned. Everything is a deterministic
//! function of the inputs and the generator's state.
//!
//! Its parts: the [`proposal`]s and their mixtures, the [`observer`]s that watch a chain, the
//! [`posterior`]'s moments over its samples, and the [`normal`] samples it draws.

pub mod normal;
pub mod observer;
pub mod posterior;
pub mod proposal;

use crate::error::FitError;
use crate::fit::chain::normal::{uniform, uniform_open0};
use crate::fit::chain::observer::{Acceptance, ChainObserver, ChainSample, ProposalStep, StepOutcome};
use crate::fit::chain::proposal::{Mixture, Proposal, ProposalContext, StandardProposal};
use crate::fit::likelihood::contour::{Silhouette, MAX_CONTOUR, NO_VERTEX};
use crate::fit::likelihood::image::{BackgroundModel, ImageEval, TargetImage};
use crate::fit::likelihood::landmarks::{evaluate_landmarks_rotated, LandmarkEval, LandmarkTarget};
use crate::fit::likelihood::pixel::{BackgroundLikelihood, GaussianPixel, ImageLikelihood, PixelLikelihood};
use crate::fit::likelihood::prior::Prior;
use crate::fit::solve::light::{solve_light, LightSolveConfig};
use crate::fit::start::landmark_pivot;
use crate::geometry::{TriIndex, Vec3};
use crate::model::instance::Instance;
use crate::model::morphable::MorphableModel;
use crate::model::params::FitParams;
use crate::model::MAX_LANDMARKS;
use crate::render::pose::PoseTrig;
use crate::render::{Cull, ShLight, TileRasterizer};
use rand_core::Rng;

/// What both chains need: the model, target landmarks, prior, proposal mixture and image size.
#[derive(Debug, Clone, Copy)]
pub struct Problem<'a, I: TriIndex = u32, P = StandardProposal> {
    /// The model.
    pub model: MorphableModel<'a, I>,
    /// Target landmarks (one per model landmark).
    pub landmarks: LandmarkTarget<'a>,
    /// The prior.
    pub prior: &'a Prior,
    /// The proposal mixture.
    pub mixture: &'a Mixture<P>,
    /// Working image width (the principal point is the image centre).
    pub width: u32,
    /// Working image height.
    pub height: u32,
    /// The jaw contour as a silhouette (its landmarks' outward directions must be the target's):
    /// `None` keeps every landmark on its fixed vertex.
    pub silhouette: Option<&'a Silhouette<'a>>,
}

/// What the image chain needs on top of a [`Problem`]: the target and the likelihood's terms.
#[derive(Debug, Clone, Copy)]
pub struct ImageProblem<'a, L = GaussianPixel, B = BackgroundModel> {
    /// The target image (its size must be the problem's).
    pub image: TargetImage<'a>,
    /// The foreground (pixel) term, e.g. [`GaussianPixel`] with σ [`crate::fit::DEFAULT_PIXEL_SIGMA`].
    pub pixel: L,
    /// The background term.
    pub background: &'a B,
    /// Sampling and ridge of the least-squares light proposal (its `offset` is drawn per use).
    pub light_solve: LightSolveConfig,
}

/// Outcome of a chain.
#[derive(Debug, Clone, PartialEq)]
pub struct FitResult<const KS: usize, const KC: usize> {
    /// The sample with the highest log posterior seen (the start counts).
    pub best: FitParams<KS, KC>,
    /// Its log posterior (up to a constant; includes the image term in the image chain).
    pub best_log_posterior: f32,
    /// Its landmark term.
    pub best_landmarks: LandmarkEval,
    /// Its image term (image chain only).
    pub best_image: Option<ImageEval>,
    /// The chain's final state.
    pub last: FitParams<KS, KC>,
    /// Its log posterior.
    pub last_log_posterior: f32,
    /// Per-component counts.
    pub acceptance: Acceptance,
    /// Steps run.
    pub steps: u32,
}

/// A chain's state: the parameters with their evaluated terms (and the landmark vertices, kept
/// so that a move that leaves the shape alone does not recompute them).
#[derive(Debug, Clone, PartialEq)]
pub struct ChainState<const KS: usize, const KC: usize> {
    /// The parameters.
    pub params: FitParams<KS, KC>,
    lm: [Vec3; MAX_LANDMARKS],
    contour: [u32; MAX_CONTOUR],
    /// The sines and cosines of `params.pose`'s angles.
    trig: PoseTrig,
    /// Log prior.
    pub prior: f32,
    /// The landmark term.
    pub landmarks: LandmarkEval,
    /// The image term (image chain only).
    pub image: Option<ImageEval>,
}

impl<const KS: usize, const KC: usize> ChainState<KS, KC> {
    /// Evaluates the prior and the landmark term of `params` (no image term).
    pub fn new<I: TriIndex, P>(problem: &Problem<'_, I, P>, params: &FitParams<KS, KC>) -> Result<Self, FitError> {
        let mut lm = [[0.0f32; 3]; MAX_LANDMARKS];
        let n = problem.model.landmark_positions(params.shape_coeffs(), &mut lm)?;
        let mut contour = [NO_VERTEX; MAX_CONTOUR];
        silhouette_positions(problem, params, &mut lm, &mut contour, true, true)?;
        let cam = params.camera(problem.width, problem.height);
        let trig = PoseTrig::of(&params.pose);
        let landmarks =
            evaluate_landmarks_rotated(lm.get(..n).unwrap_or(&[]), &trig.rotation(), params.pose.translation, &cam, &problem.landmarks)?;
        Ok(Self { params: params.clone(), lm, contour, trig, prior: problem.prior.log_density(params), landmarks, image: None })
    }

    /// The first stage's log density: prior plus landmarks.
    pub fn filter_term(&self) -> f32 {
        self.prior + self.landmarks.log_likelihood
    }

    /// The log posterior (up to a constant): the first stage's plus the image term if any.
    pub fn log_posterior(&self) -> f32 {
        self.filter_term() + self.image.map_or(0.0, |e| e.log_likelihood)
    }

    /// The model's landmark vertices (model space) of this state's shape (the contour's on the
    /// silhouette, if the problem has one).
    pub fn landmark_vertices(&self) -> &[Vec3] {
        &self.lm
    }

    /// The silhouette vertex of each contour landmark ([`NO_VERTEX`]: its fixed vertex).
    pub fn contour_vertices(&self) -> &[u32; MAX_CONTOUR] {
        &self.contour
    }
}

/// With a silhouette: selects the contour landmarks' outline vertices for `params`' pose (when
/// `reselect`) and puts their positions under `params`' shape into `lm` (those whose vertex
/// changed, or all after a shape change).
fn silhouette_positions<I: TriIndex, P, const KS: usize, const KC: usize>(
    problem: &Problem<'_, I, P>,
    params: &FitParams<KS, KC>,
    lm: &mut [Vec3; MAX_LANDMARKS],
    ids: &mut [u32; MAX_CONTOUR],
    reselect: bool,
    shape_changed: bool,
) -> Result<(), FitError> {
    let Some(sil) = problem.silhouette else {
        return Ok(());
    };
    let mut next = *ids;
    if reselect {
        let cam = params.camera(problem.width, problem.height);
        sil.select(&params.pose, &cam, &problem.landmarks, &mut next);
    }
    let fixed = problem.model.landmarks();
    for (i, (&id, old)) in next.iter().zip(ids.iter()).enumerate().take(sil.count()) {
        if id != *old || shape_changed {
            let v = if id == NO_VERTEX { *fixed.get(i).ok_or(FitError::IndexOutOfRange)? } else { id };
            *lm.get_mut(i).ok_or(FitError::LengthMismatch)? = problem.model.vertex_position(params.shape_coeffs(), v)?;
        }
    }
    *ids = next;
    Ok(())
}

fn check<I: TriIndex, P, const KS: usize, const KC: usize>(problem: &Problem<'_, I, P>, init: &FitParams<KS, KC>) -> Result<(), FitError> {
    if problem.width == 0 || problem.height == 0 {
        return Err(FitError::EmptyImage);
    }
    if problem.landmarks.len() != problem.model.landmarks().len() {
        return Err(FitError::LengthMismatch);
    }
    if !init.is_valid() {
        return Err(FitError::NonFinite);
    }
    if problem.mixture.entries().is_empty() || !(problem.mixture.total_weight() > 0.0 && problem.mixture.total_weight().is_finite()) {
        return Err(FitError::BadConfig);
    }
    Ok(())
}

/// The first stage for the proposal in `next` (its parameters, drawn by `proposal` from `cur`;
/// the rest of `next` is overwritten): prior and landmarks (recomputing landmark vertices only
/// after a shape change), accepted with `min(1, exp(filter_term(x') − filter_term(x) + hastings))`.
/// Draws one uniform from `rng` first, whatever the outcome; `true` if accepted. The chain keeps
/// two states and swaps their roles instead of moving a state of a few kilobytes per step.
fn filter_into<R: Rng + ?Sized, I: TriIndex, P, Q: Proposal + ?Sized, const KS: usize, const KC: usize>(
    problem: &Problem<'_, I, P>,
    cur: &ChainState<KS, KC>,
    next: &mut ChainState<KS, KC>,
    proposal: &Q,
    hastings: f32,
    rng: &mut R,
) -> Result<bool, FitError> {
    let u = libm::logf(uniform_open0(rng));
    if hastings == f32::NEG_INFINITY {
        return Ok(false);
    }
    let prior = problem.prior.log_density(&next.params);
    if prior == f32::NEG_INFINITY {
        return Ok(false);
    }
    next.prior = prior;
    next.landmarks = cur.landmarks;
    next.image = cur.image;
    next.contour = cur.contour;
    next.trig = cur.trig.to(&next.params.pose);
    if proposal.changes_shape() {
        // Overwrites every landmark (the entries past the model's stay zero in every state).
        problem.model.landmark_positions(next.params.shape_coeffs(), &mut next.lm)?;
    } else {
        next.lm = cur.lm;
    }
    if problem.silhouette.is_some() && proposal.changes_geometry() {
        let moved = next.params.pose != cur.params.pose || next.params.focal != cur.params.focal;
        silhouette_positions(problem, &next.params, &mut next.lm, &mut next.contour, moved, proposal.changes_shape())?;
    }
    if proposal.changes_geometry() {
        let n = problem.model.landmarks().len();
        let cam = next.params.camera(problem.width, problem.height);
        let (r, t) = (next.trig.rotation(), next.params.pose.translation);
        next.landmarks = evaluate_landmarks_rotated(next.lm.get(..n).unwrap_or(&[]), &r, t, &cam, &problem.landmarks)?;
    }
    let log_a = next.filter_term() - cur.filter_term() + hastings;
    Ok(u < log_a)
}

/// The stage after the prior-and-landmark filter: nothing (the landmark chain) or the rendered
/// image term (the image chain, [`RenderedImage`]).
///
/// # Examples
///
/// A second stage of one's own: the yaw another sensor measured (0.3 ± 0.05 rad) as a term
/// [`run_chain`] evaluates only for the proposals that passed the prior and the landmarks:
///
/// ```
/// use gpmm_core::error::FitError;
/// use gpmm_core::fit::{run_chain, ChainState, ImageEval, Problem, SecondStage};
/// # use gpmm_core::fit::{project_landmarks, LandmarkTarget, Mixture, NoObserver, Prior};
/// # use gpmm_core::model::{Basis, FactoredBasis, MorphableModel};
/// use gpmm_core::geometry::TriIndex;
/// use gpmm_core::model::FitParams;
/// use gpmm_core::render::{Pose, ShLight};
/// use rand_core::{Rng, SeedableRng};
///
/// struct MeasuredYaw {
///     yaw: f32,
///     sigma: f32,
///     calls: u32,
/// }
///
/// impl<I: TriIndex, P, const KS: usize, const KC: usize> SecondStage<I, P, KS, KC> for MeasuredYaw {
///     fn active(&self) -> bool {
///         true
///     }
///     fn start(&mut self, p: &Problem<'_, I, P>, x: &FitParams<KS, KC>) -> Result<Option<ImageEval>, FitError> {
///         self.evaluate(p, x, x).map(Some)
///     }
///     fn light_solution<R: Rng + ?Sized>(&mut self, _: &Problem<'_, I, P>, _: &ChainState<KS, KC>, _: &mut R) -> Option<ShLight> {
///         None
///     }
///     fn evaluate(&mut self, _: &Problem<'_, I, P>, x: &FitParams<KS, KC>, _: &FitParams<KS, KC>) -> Result<ImageEval, FitError> {
///         self.calls += 1;
///         let z = (x.pose.yaw - self.yaw) / self.sigma;
///         Ok(ImageEval { log_likelihood: -0.5 * z * z, covered: 0, sq_err: 0.0 })
///     }
/// }
///
/// # // A tetrahedron (mm) without components, every vertex a landmark.
/// # let shape_mean = [[-10.0, -8.0, 0.0], [10.0, -8.0, 0.0], [0.0, 12.0, 0.0], [0.0, 0.0, 10.0]];
/// # let none = || FactoredBasis::new(&[], &[], 4).map(Basis::Factored);
/// # let triangles: [[u32; 3]; 4] = [[0, 2, 1], [0, 1, 3], [1, 2, 3], [2, 0, 3]];
/// # let model = MorphableModel::new(&shape_mean, &[[0.5; 3]; 4], none()?, none()?, &triangles, &[0, 1, 2, 3])?;
/// # let params = |yaw| FitParams::<0, 0>::new(Pose { yaw, ..Pose::frontal(300.0) }, 400.0, ShLight::ambient_white(), 0, 0);
/// # let mut points = [[0.0f32; 2]; 4];
/// # project_landmarks(&model, &params(0.3), 32, 32, &mut points)?;
/// # let landmarks = LandmarkTarget::new(&points, &[true; 4], 0.5)?;
/// # let start = params(0.0);
/// # let (prior, mixture) = (Prior::around(&start), Mixture::landmark_default(32.0));
/// # let problem = Problem { model, landmarks, prior: &prior, mixture: &mixture, width: 32, height: 32, silhouette: None };
/// // `problem`: the landmarks of a tetrahedron turned by 0.3 rad and the standard mixture;
/// // `start`: frontal (both set up as in the `ChainObserver` example).
/// let mut stage = MeasuredYaw { yaw: 0.3, sigma: 0.05, calls: 0 };
/// let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(1);
/// let fit = run_chain(&problem, &mut stage, &start, 300, &mut rng, NoObserver)?;
/// // The start, then every proposal that passed the first stage.
/// assert_eq!(stage.calls, 1 + fit.acceptance.passed_filter.iter().sum::<u32>());
/// assert!(fit.best_image.is_some());
/// assert!((fit.best.pose.yaw - 0.3).abs() < 0.05, "{}", fit.best.pose.yaw);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub trait SecondStage<I: TriIndex, P, const KS: usize, const KC: usize> {
    /// Whether there is a second stage: the Hastings term then goes to it (see the module docs).
    fn active(&self) -> bool;

    /// The second stage's term of the chain's start (`None` without a second stage).
    fn start(&mut self, problem: &Problem<'_, I, P>, params: &FitParams<KS, KC>) -> Result<Option<ImageEval>, FitError>;

    /// The least-squares light of `cur` for a proposal that needs one (`None` if unavailable).
    fn light_solution<R: Rng + ?Sized>(&mut self, problem: &Problem<'_, I, P>, cur: &ChainState<KS, KC>, rng: &mut R) -> Option<ShLight>;

    /// The second stage's term of a proposal that passed the filter (an error rejects it);
    /// `current` is the chain's state (caches keep what it needs).
    fn evaluate(
        &mut self,
        problem: &Problem<'_, I, P>,
        params: &FitParams<KS, KC>,
        current: &FitParams<KS, KC>,
    ) -> Result<ImageEval, FitError>;
}

/// No second stage: the landmark chain.
#[derive(Debug, Clone, Copy, Default)]
pub struct LandmarksOnly;

impl<I: TriIndex, P, const KS: usize, const KC: usize> SecondStage<I, P, KS, KC> for LandmarksOnly {
    fn active(&self) -> bool {
        false
    }

    fn start(&mut self, _: &Problem<'_, I, P>, _: &FitParams<KS, KC>) -> Result<Option<ImageEval>, FitError> {
        Ok(None)
    }

    fn light_solution<R: Rng + ?Sized>(&mut self, _: &Problem<'_, I, P>, _: &ChainState<KS, KC>, _: &mut R) -> Option<ShLight> {
        None
    }

    fn evaluate(&mut self, _: &Problem<'_, I, P>, _: &FitParams<KS, KC>, _: &FitParams<KS, KC>) -> Result<ImageEval, FitError> {
        Err(FitError::BadConfig)
    }
}

/// The image term as the second stage: renders through `raster` into the likelihood sink, the
/// per-vertex work cached in `instance`.
pub struct RenderedImage<'p, 'd, 'i, 'm, 'r, L, B, const KS: usize, const KC: usize, const TW: usize, const TH: usize, const BIN: usize> {
    /// The target and the likelihood's terms.
    pub image: &'p ImageProblem<'d, L, B>,
    /// The per-vertex buffers.
    pub instance: &'i mut Instance<'m, KS, KC>,
    /// The rasterizer.
    pub raster: &'r mut TileRasterizer<TW, TH, BIN>,
}

impl<I: TriIndex, P, L, B, const KS: usize, const KC: usize, const TW: usize, const TH: usize, const BIN: usize> SecondStage<I, P, KS, KC>
    for RenderedImage<'_, '_, '_, '_, '_, L, B, KS, KC, TW, TH, BIN>
where
    L: PixelLikelihood + Copy,
    B: BackgroundLikelihood,
{
    fn active(&self) -> bool {
        true
    }

    fn start(&mut self, problem: &Problem<'_, I, P>, params: &FitParams<KS, KC>) -> Result<Option<ImageEval>, FitError> {
        render_eval(problem, self.image, params, None, self.instance, self.raster).map(Some)
    }

    fn light_solution<R: Rng + ?Sized>(&mut self, problem: &Problem<'_, I, P>, cur: &ChainState<KS, KC>, rng: &mut R) -> Option<ShLight> {
        let offset = (rng.next_u32() as usize) % self.image.light_solve.stride;
        let cfg = LightSolveConfig { offset, ..self.image.light_solve };
        let cam = cur.params.camera(problem.width, problem.height);
        // The instance may hold a rejected proposal: bring it back to the current state.
        self.instance.update(&problem.model, &cur.params, problem.width, problem.height).ok()?;
        let inst = &*self.instance;
        solve_light(inst.positions(), inst.normals(), inst.albedos(), &cur.params.pose, &cam, &self.image.image, &cfg).ok()
    }

    fn evaluate(
        &mut self,
        problem: &Problem<'_, I, P>,
        params: &FitParams<KS, KC>,
        current: &FitParams<KS, KC>,
    ) -> Result<ImageEval, FitError> {
        render_eval(problem, self.image, params, Some(current), self.instance, self.raster)
    }
}

fn pick<R: Rng + ?Sized, P>(mixture: &Mixture<P>, rng: &mut R) -> Result<usize, FitError> {
    mixture.choose(uniform(rng)).ok_or(FitError::BadConfig)
}

/// One step's decision after the proposal drew `prop` with Hastings term `h`.
#[allow(clippy::too_many_arguments)]
fn decide<R: Rng + ?Sized, I: TriIndex, P: Proposal, S: SecondStage<I, P, KS, KC>, const KS: usize, const KC: usize>(
    problem: &Problem<'_, I, P>,
    stage: &mut S,
    cur: &ChainState<KS, KC>,
    next: &mut ChainState<KS, KC>,
    proposal: &P,
    h: f32,
    rng: &mut R,
) -> Result<StepOutcome, FitError> {
    if !stage.active() {
        return Ok(if filter_into(problem, cur, next, proposal, h, rng)? {
            StepOutcome::Accepted
        } else if h == f32::NEG_INFINITY {
            StepOutcome::Impossible
        } else {
            StepOutcome::RejectedByFilter
        });
    }
    if h == f32::NEG_INFINITY {
        return Ok(StepOutcome::Impossible);
    }
    // The Hastings term goes to the second stage (see the module docs).
    if !filter_into(problem, cur, next, proposal, 0.0, rng)? {
        return Ok(StepOutcome::RejectedByFilter);
    }
    let u = libm::logf(uniform_open0(rng));
    // A proposal the renderer refuses (e.g. non-finite positions) is rejected, not an error:
    // the start was rendered, so the inputs themselves are sound.
    let accepted = match stage.evaluate(problem, &next.params, &cur.params) {
        Ok(e) => {
            let old = cur.image.map_or(0.0, |c| c.log_likelihood);
            next.image = Some(e);
            u < e.log_likelihood - old + h
        }
        Err(_) => false,
    };
    Ok(if accepted { StepOutcome::Accepted } else { StepOutcome::RejectedByImage })
}

/// The Metropolis-Hastings / delayed-acceptance loop: `steps` steps from `init`, the first stage
/// prior and landmarks, then `stage`. `observer` sees progress and every proposal's outcome.
pub fn run_chain<R, I, P, S, O, const KS: usize, const KC: usize>(
    problem: &Problem<'_, I, P>,
    stage: &mut S,
    init: &FitParams<KS, KC>,
    steps: u32,
    rng: &mut R,
    mut observer: O,
) -> Result<FitResult<KS, KC>, FitError>
where
    R: Rng + ?Sized,
    I: TriIndex,
    P: Proposal,
    S: SecondStage<I, P, KS, KC>,
    O: ChainObserver,
{
    check(problem, init)?;
    let mut ctx = ProposalContext { pivot: landmark_pivot(&problem.model, Some(&problem.landmarks))?, light_solution: None, trig: None };
    let mut start = ChainState::new(problem, init)?;
    start.image = stage.start(problem, init)?;
    if !start.log_posterior().is_finite() {
        return Err(FitError::ImpossibleStart);
    }
    for (id, e) in problem.mixture.entries().iter().enumerate() {
        observer.component(id, e.proposal.name());
    }
    let mut best = start.clone();
    let mut acc = Acceptance::new();
    // The current state and the next one (the proposal), in turns: an accepted proposal
    // becomes the current state by swapping the roles, not by a copy.
    let mut states = [start.clone(), start];
    let mut c = 0usize;
    for step in 0..steps {
        observer.progress(step);
        let id = pick(problem.mixture, rng)?;
        let Some(entry) = problem.mixture.entries().get(id) else { return Err(FitError::BadConfig) };
        let proposal = &entry.proposal;
        let [a, b] = &mut states;
        let (cur, next) = if c == 0 { (&*a, b) } else { (&*b, a) };
        ctx.light_solution = if proposal.needs_light_solution() { stage.light_solution(problem, cur, rng) } else { None };
        ctx.trig = Some(cur.trig);
        let h = proposal.propose(&cur.params, &ctx, rng, &mut next.params);
        let outcome = decide(problem, stage, cur, next, proposal, h, rng)?;
        let cur = if outcome.accepted() {
            c ^= 1;
            &*next
        } else {
            cur
        };
        if outcome.accepted() && cur.log_posterior() > best.log_posterior() {
            best.clone_from(cur);
        }
        let report = ProposalStep { step, id, name: proposal.name(), outcome, log_posterior: cur.log_posterior() };
        acc.proposal(&report);
        observer.proposal(&report);
        let p = &cur.params;
        observer.sample(&ChainSample { step, pose: &p.pose, light: &p.light, shape: p.shape_coeffs(), color: p.color_coeffs() });
    }
    observer.progress(steps);
    let [a, b] = states;
    let cur = if c == 0 { a } else { b };
    let (best_log_posterior, last_log_posterior) = (best.log_posterior(), cur.log_posterior());
    Ok(FitResult {
        best: best.params,
        best_log_posterior,
        best_landmarks: best.landmarks,
        best_image: best.image,
        last: cur.params,
        last_log_posterior,
        acceptance: acc,
        steps,
    })
}

/// Runs `steps` Metropolis-Hastings steps on `prior × landmarks` from `init`: no rendering, no
/// per-vertex buffers (the landmark vertices are computed alone). `observer` sees progress and
/// every proposal's outcome ([`NoObserver`](observer::NoObserver) for none, [`Progress`](observer::Progress) for a step count).
pub fn landmark_chain<R: Rng + ?Sized, I: TriIndex, P: Proposal, O: ChainObserver, const KS: usize, const KC: usize>(
    problem: &Problem<'_, I, P>,
    init: &FitParams<KS, KC>,
    steps: u32,
    rng: &mut R,
    observer: O,
) -> Result<FitResult<KS, KC>, FitError> {
    run_chain(problem, &mut LandmarksOnly, init, steps, rng, observer)
}

fn render_eval<I: TriIndex, P, L, B, const KS: usize, const KC: usize, const TW: usize, const TH: usize, const BIN: usize>(
    problem: &Problem<'_, I, P>,
    image: &ImageProblem<'_, L, B>,
    params: &FitParams<KS, KC>,
    keep: Option<&FitParams<KS, KC>>,
    instance: &mut Instance<'_, KS, KC>,
    raster: &mut TileRasterizer<TW, TH, BIN>,
) -> Result<ImageEval, FitError>
where
    L: PixelLikelihood + Copy,
    B: BackgroundLikelihood,
{
    let (w, h) = (problem.width, problem.height);
    instance.update_keeping(&problem.model, params, keep, w, h)?;
    let keep = keep.and_then(|k| instance.geometry_of(k, w, h));
    let key = instance.geometry().ok_or(FitError::BadConfig)?;
    let triangles = problem.model.triangles();
    let (projected, frames) = instance.projected_and_frames();
    let mut sink = ImageLikelihood::with_terms(image.image, image.pixel, image.background);
    let Some(frames) = frames else {
        raster.render(projected, triangles, w, h, Cull::Clockwise, &mut sink)?;
        return Ok(sink.eval());
    };
    // The same geometry as a kept frame (a colour or light change): re-shade it, same bits.
    if frames.contains(&key) {
        if frames.reshade(&key, projected, triangles, &mut sink) {
            return Ok(sink.eval());
        }
        sink.reset();
    }
    let mut recorder = frames.recorder(key, keep, &mut sink);
    raster.render(projected, triangles, w, h, Cull::Clockwise, &mut recorder)?;
    recorder.finish();
    Ok(sink.eval())
}

/// Evaluates the image term of `params` alone (renders once).
pub fn image_log_likelihood<I: TriIndex, P, L, B, const KS: usize, const KC: usize, const TW: usize, const TH: usize, const BIN: usize>(
    problem: &Problem<'_, I, P>,
    image: &ImageProblem<'_, L, B>,
    params: &FitParams<KS, KC>,
    instance: &mut Instance<'_, KS, KC>,
    raster: &mut TileRasterizer<TW, TH, BIN>,
) -> Result<ImageEval, FitError>
where
    L: PixelLikelihood + Copy,
    B: BackgroundLikelihood,
{
    if image.image.width() != problem.width || image.image.height() != problem.height {
        return Err(FitError::LengthMismatch);
    }
    render_eval(problem, image, params, None, instance, raster)
}

/// Runs `steps` delayed-acceptance steps on `prior × landmarks × image` from `init`, rendering
/// each proposal that passes the prior-and-landmark stage through `raster` into the likelihood
/// sink, with the per-vertex work cached in `instance`. `observer` sees progress and every
/// proposal's outcome ([`NoObserver`](observer::NoObserver) for none, [`Progress`](observer::Progress) for a step count: progress reports
/// without restarting the chain, whose restart re-renders its start).
#[allow(clippy::too_many_arguments)]
pub fn image_chain<R, I, P, L, B, O, const KS: usize, const KC: usize, const TW: usize, const TH: usize, const BIN: usize>(
    problem: &Problem<'_, I, P>,
    image: &ImageProblem<'_, L, B>,
    init: &FitParams<KS, KC>,
    steps: u32,
    instance: &mut Instance<'_, KS, KC>,
    raster: &mut TileRasterizer<TW, TH, BIN>,
    rng: &mut R,
    observer: O,
) -> Result<FitResult<KS, KC>, FitError>
where
    R: Rng + ?Sized,
    I: TriIndex,
    P: Proposal,
    L: PixelLikelihood + Copy,
    B: BackgroundLikelihood,
    O: ChainObserver,
{
    check(problem, init)?;
    if image.image.width() != problem.width || image.image.height() != problem.height {
        return Err(FitError::LengthMismatch);
    }
    if image.light_solve.stride == 0 {
        return Err(FitError::BadConfig);
    }
    run_chain(problem, &mut RenderedImage { image, instance, raster }, init, steps, rng, observer)
}
