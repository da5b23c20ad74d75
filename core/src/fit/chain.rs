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
//! for it; the landmark chain has a single stage. Acceptance is counted per mixture component. The best sample
//! (highest log posterior seen) and the last sample are returned. Everything is a deterministic
//! function of the inputs and the generator's state.

use super::image::{BackgroundModel, ImageEval, ImageLikelihood, TargetImage};
use super::init::landmark_pivot;
use super::landmarks::{evaluate_landmarks, LandmarkEval, LandmarkTarget, MAX_LANDMARKS};
use super::light_fit::{solve_light, LightSolveConfig};
use super::normal::{uniform, uniform_open0};
use super::params::FitParams;
use super::prior::Prior;
use super::proposal::{propose, Mixture, ProposalContext, ProposalKind, MAX_PROPOSALS};
use super::FitError;
use crate::model::morphable::{Instance, MorphableModel};
use crate::render::shading::TriIndex;
use crate::{Cull, TileRasterizer, Vec3};
use rand_core::Rng;

/// What both chains need: the model, target landmarks, prior, proposal mixture and image size.
#[derive(Debug, Clone, Copy)]
pub struct Problem<'a, I: TriIndex = u32> {
    /// The model.
    pub model: MorphableModel<'a, I>,
    /// Target landmarks (one per model landmark).
    pub landmarks: LandmarkTarget<'a>,
    /// The prior.
    pub prior: &'a Prior,
    /// The proposal mixture.
    pub mixture: &'a Mixture,
    /// Working image width (the principal point is the image centre).
    pub width: u32,
    /// Working image height.
    pub height: u32,
}

/// What the image chain needs on top of a [`Problem`].
#[derive(Debug, Clone, Copy)]
pub struct ImageProblem<'a> {
    /// The target image (its size must be the problem's).
    pub image: TargetImage<'a>,
    /// Background model of the target.
    pub background: &'a BackgroundModel,
    /// Foreground σ on [0, 1] colours (see [`super::DEFAULT_PIXEL_SIGMA`]).
    pub sigma: f32,
    /// Sampling and ridge of the least-squares light proposal (its `offset` is drawn per use).
    pub light_solve: LightSolveConfig,
}

/// Per-component proposal counts (index = position in the [`Mixture`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Acceptance {
    /// Times the component was drawn.
    pub proposed: [u32; MAX_PROPOSALS],
    /// Times it passed the prior-and-landmark stage.
    pub passed_filter: [u32; MAX_PROPOSALS],
    /// Times it was accepted.
    pub accepted: [u32; MAX_PROPOSALS],
}

impl Acceptance {
    const fn new() -> Self {
        Self { proposed: [0; MAX_PROPOSALS], passed_filter: [0; MAX_PROPOSALS], accepted: [0; MAX_PROPOSALS] }
    }

    /// Acceptance rate of component `id` (0 if never drawn).
    pub fn rate(&self, id: usize) -> f32 {
        let p = self.proposed.get(id).copied().unwrap_or(0);
        let a = self.accepted.get(id).copied().unwrap_or(0);
        if p == 0 {
            0.0
        } else {
            a as f32 / p as f32
        }
    }

    /// Accepted over proposed, all components.
    pub fn overall(&self) -> f32 {
        let p: u32 = self.proposed.iter().sum();
        let a: u32 = self.accepted.iter().sum();
        if p == 0 {
            0.0
        } else {
            a as f32 / p as f32
        }
    }

    fn count(&mut self, id: usize, passed: bool, accepted: bool) {
        if let Some(v) = self.proposed.get_mut(id) {
            *v = v.saturating_add(1);
        }
        if let (true, Some(v)) = (passed, self.passed_filter.get_mut(id)) {
            *v = v.saturating_add(1);
        }
        if let (true, Some(v)) = (accepted, self.accepted.get_mut(id)) {
            *v = v.saturating_add(1);
        }
    }
}

/// Outcome of a chain.
#[derive(Debug, Clone, Copy, PartialEq)]
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

#[derive(Clone, Copy)]
struct State<const KS: usize, const KC: usize> {
    params: FitParams<KS, KC>,
    lm: [Vec3; MAX_LANDMARKS],
    prior: f32,
    landmarks: LandmarkEval,
    image: Option<ImageEval>,
}

impl<const KS: usize, const KC: usize> State<KS, KC> {
    fn filter_term(&self) -> f32 {
        self.prior + self.landmarks.log_likelihood
    }

    fn posterior(&self) -> f32 {
        self.filter_term() + self.image.map_or(0.0, |e| e.log_likelihood)
    }
}

fn check<I: TriIndex, const KS: usize, const KC: usize>(problem: &Problem<'_, I>, init: &FitParams<KS, KC>) -> Result<(), FitError> {
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

fn landmark_state<I: TriIndex, const KS: usize, const KC: usize>(
    problem: &Problem<'_, I>,
    params: &FitParams<KS, KC>,
) -> Result<State<KS, KC>, FitError> {
    let mut lm = [[0.0f32; 3]; MAX_LANDMARKS];
    let n = problem.model.landmark_positions(params.shape_coeffs(), &mut lm)?;
    let cam = params.camera(problem.width, problem.height);
    let landmarks = evaluate_landmarks(lm.get(..n).unwrap_or(&[]), &params.pose, &cam, &problem.landmarks)?;
    Ok(State { params: *params, lm, prior: problem.prior.log_density(params), landmarks, image: None })
}

/// Stage 1 for `prop` drawn from `cur`: prior and landmarks (recomputing landmark positions only
/// after a shape change). `Ok(None)`: rejected.
fn filter_stage<R: Rng + ?Sized, I: TriIndex, const KS: usize, const KC: usize>(
    problem: &Problem<'_, I>,
    cur: &State<KS, KC>,
    prop: &FitParams<KS, KC>,
    kind: ProposalKind,
    hastings: f32,
    rng: &mut R,
) -> Result<Option<State<KS, KC>>, FitError> {
    let u = libm::logf(uniform_open0(rng));
    if hastings == f32::NEG_INFINITY {
        return Ok(None);
    }
    let prior = problem.prior.log_density(prop);
    if prior == f32::NEG_INFINITY {
        return Ok(None);
    }
    let mut next = State { params: *prop, lm: cur.lm, prior, landmarks: cur.landmarks, image: cur.image };
    if kind.changes_shape() {
        problem.model.landmark_positions(prop.shape_coeffs(), &mut next.lm)?;
    }
    if kind.changes_geometry() {
        let n = problem.model.landmarks().len();
        let cam = prop.camera(problem.width, problem.height);
        next.landmarks = evaluate_landmarks(next.lm.get(..n).unwrap_or(&[]), &prop.pose, &cam, &problem.landmarks)?;
    }
    let log_a = next.filter_term() - cur.filter_term() + hastings;
    Ok(if u < log_a { Some(next) } else { None })
}

fn pick<R: Rng + ?Sized>(mixture: &Mixture, rng: &mut R) -> Result<usize, FitError> {
    mixture.choose(uniform(rng)).ok_or(FitError::BadConfig)
}

fn result<const KS: usize, const KC: usize>(
    best: &State<KS, KC>,
    last: &State<KS, KC>,
    acceptance: Acceptance,
    steps: u32,
) -> FitResult<KS, KC> {
    FitResult {
        best: best.params,
        best_log_posterior: best.posterior(),
        best_landmarks: best.landmarks,
        best_image: best.image,
        last: last.params,
        last_log_posterior: last.posterior(),
        acceptance,
        steps,
    }
}

/// Runs `steps` Metropolis-Hastings steps on `prior × landmarks` from `init`: no rendering, no
/// per-vertex buffers (the landmark vertices are computed alone).
pub fn landmark_chain<R: Rng + ?Sized, I: TriIndex, const KS: usize, const KC: usize>(
    problem: &Problem<'_, I>,
    init: &FitParams<KS, KC>,
    steps: u32,
    rng: &mut R,
) -> Result<FitResult<KS, KC>, FitError> {
    landmark_chain_observed(problem, init, steps, rng, |_| {})
}

/// [`landmark_chain`], calling `on_step(done)` with the number of finished steps before each
/// step and once at the end (for progress reports).
pub fn landmark_chain_observed<R: Rng + ?Sized, I: TriIndex, const KS: usize, const KC: usize>(
    problem: &Problem<'_, I>,
    init: &FitParams<KS, KC>,
    steps: u32,
    rng: &mut R,
    mut on_step: impl FnMut(u32),
) -> Result<FitResult<KS, KC>, FitError> {
    check(problem, init)?;
    let ctx = ProposalContext { pivot: landmark_pivot(&problem.model, Some(&problem.landmarks))?, light_solution: None };
    let mut cur = landmark_state(problem, init)?;
    if !cur.posterior().is_finite() {
        return Err(FitError::ImpossibleStart);
    }
    let mut best = cur;
    let mut acc = Acceptance::new();
    let mut prop = *init;
    for step in 0..steps {
        on_step(step);
        let id = pick(problem.mixture, rng)?;
        let Some(entry) = problem.mixture.entries().get(id) else { return Err(FitError::BadConfig) };
        let h = propose(entry, &cur.params, &ctx, rng, &mut prop);
        let next = filter_stage(problem, &cur, &prop, entry.kind, h, rng)?;
        acc.count(id, next.is_some(), next.is_some());
        if let Some(n) = next {
            cur = n;
            if cur.posterior() > best.posterior() {
                best = cur;
            }
        }
    }
    on_step(steps);
    Ok(result(&best, &cur, acc, steps))
}

fn render_eval<I: TriIndex, const KS: usize, const KC: usize, const TW: usize, const TH: usize, const BIN: usize>(
    problem: &Problem<'_, I>,
    image: &ImageProblem<'_>,
    params: &FitParams<KS, KC>,
    instance: &mut Instance<'_, KS, KC>,
    raster: &mut TileRasterizer<TW, TH, BIN>,
) -> Result<ImageEval, FitError> {
    instance.update(&problem.model, params, problem.width, problem.height)?;
    let mut sink = ImageLikelihood::new(image.image, image.background, image.sigma)?;
    raster.render(instance.projected(), problem.model.triangles(), problem.width, problem.height, Cull::Clockwise, &mut sink)?;
    Ok(sink.eval())
}

/// Evaluates the image term of `params` alone (renders once).
pub fn image_log_likelihood<I: TriIndex, const KS: usize, const KC: usize, const TW: usize, const TH: usize, const BIN: usize>(
    problem: &Problem<'_, I>,
    image: &ImageProblem<'_>,
    params: &FitParams<KS, KC>,
    instance: &mut Instance<'_, KS, KC>,
    raster: &mut TileRasterizer<TW, TH, BIN>,
) -> Result<ImageEval, FitError> {
    if image.image.width() != problem.width || image.image.height() != problem.height {
        return Err(FitError::LengthMismatch);
    }
    render_eval(problem, image, params, instance, raster)
}

/// Runs `steps` delayed-acceptance steps on `prior × landmarks × image` from `init`, rendering
/// each proposal that passes the prior-and-landmark stage through `raster` into the likelihood
/// sink, with the per-vertex work cached in `instance`.
pub fn image_chain<R: Rng + ?Sized, I: TriIndex, const KS: usize, const KC: usize, const TW: usize, const TH: usize, const BIN: usize>(
    problem: &Problem<'_, I>,
    image: &ImageProblem<'_>,
    init: &FitParams<KS, KC>,
    steps: u32,
    instance: &mut Instance<'_, KS, KC>,
    raster: &mut TileRasterizer<TW, TH, BIN>,
    rng: &mut R,
) -> Result<FitResult<KS, KC>, FitError> {
    image_chain_observed(problem, image, init, steps, instance, raster, rng, |_| {})
}

/// [`image_chain`], calling `on_step(done)` with the number of finished steps before each step
/// and once at the end: progress reports without restarting the chain (a restart re-renders
/// its start).
#[allow(clippy::too_many_arguments)]
pub fn image_chain_observed<
    R: Rng + ?Sized,
    I: TriIndex,
    const KS: usize,
    const KC: usize,
    const TW: usize,
    const TH: usize,
    const BIN: usize,
>(
    problem: &Problem<'_, I>,
    image: &ImageProblem<'_>,
    init: &FitParams<KS, KC>,
    steps: u32,
    instance: &mut Instance<'_, KS, KC>,
    raster: &mut TileRasterizer<TW, TH, BIN>,
    rng: &mut R,
    mut on_step: impl FnMut(u32),
) -> Result<FitResult<KS, KC>, FitError> {
    check(problem, init)?;
    if image.image.width() != problem.width || image.image.height() != problem.height {
        return Err(FitError::LengthMismatch);
    }
    if image.light_solve.stride == 0 {
        return Err(FitError::BadConfig);
    }
    let mut ctx = ProposalContext { pivot: landmark_pivot(&problem.model, Some(&problem.landmarks))?, light_solution: None };
    let mut cur = landmark_state(problem, init)?;
    cur.image = Some(render_eval(problem, image, init, instance, raster)?);
    if !cur.posterior().is_finite() {
        return Err(FitError::ImpossibleStart);
    }
    let mut best = cur;
    let mut acc = Acceptance::new();
    let mut prop = *init;
    for step in 0..steps {
        on_step(step);
        let id = pick(problem.mixture, rng)?;
        let Some(entry) = problem.mixture.entries().get(id) else { return Err(FitError::BadConfig) };
        ctx.light_solution = None;
        if entry.kind == ProposalKind::LightSolve {
            let offset = (rng.next_u32() as usize) % image.light_solve.stride;
            let cfg = LightSolveConfig { offset, ..image.light_solve };
            let cam = cur.params.camera(problem.width, problem.height);
            // The instance may hold a rejected proposal: bring it back to the current state.
            if instance.update(&problem.model, &cur.params, problem.width, problem.height).is_ok() {
                let solved =
                    solve_light(instance.positions(), instance.normals(), instance.albedos(), &cur.params.pose, &cam, &image.image, &cfg);
                ctx.light_solution = solved.ok();
            }
        }
        let h = propose(entry, &cur.params, &ctx, rng, &mut prop);
        if h == f32::NEG_INFINITY {
            acc.count(id, false, false);
            continue;
        }
        // The Hastings term goes to the second stage (see the module docs).
        let Some(mut next) = filter_stage(problem, &cur, &prop, entry.kind, 0.0, rng)? else {
            acc.count(id, false, false);
            continue;
        };
        let u = libm::logf(uniform_open0(rng));
        // A proposal the renderer refuses (e.g. non-finite positions) is rejected, not an error:
        // the start was rendered, so the inputs themselves are sound.
        let accepted = match render_eval(problem, image, &next.params, instance, raster) {
            Ok(e) => {
                let old = cur.image.map_or(0.0, |c| c.log_likelihood);
                next.image = Some(e);
                u < e.log_likelihood - old + h
            }
            Err(_) => false,
        };
        acc.count(id, true, accepted);
        if accepted {
            cur = next;
            if cur.posterior() > best.posterior() {
                best = cur;
            }
        }
    }
    on_step(steps);
    Ok(result(&best, &cur, acc, steps))
}
