//! The chain is open: a pixel likelihood, a background term, proposals and an observer written
//! here, outside the crate, plug into the core's image chain next to the built-in proposals.
#![allow(clippy::indexing_slicing, clippy::unwrap_used, clippy::expect_used)]

mod common;
mod fit_support;

use fit_support::*;
use gpmm_core::fit::{
    image_chain, image_log_likelihood, landmark_chain, BackgroundLikelihood, BackgroundModel, ChainObserver, GaussianPixel, ImageProblem,
    LightSolveConfig, Mixture, OneOf, PixelLikelihood, PosteriorMoments, Prior, Problem, Proposal, ProposalContext, ProposalStep,
    StandardProposal, StepOutcome, TargetImage, DEFAULT_PIXEL_SIGMA,
};
use gpmm_core::geometry::Vec3;
use gpmm_core::model::FitParams;
use rand_core::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use std::cell::Cell;
use std::collections::BTreeMap;

/// A Laplace (L1) pixel term that counts its calls.
#[derive(Clone, Copy)]
struct CountingLaplace<'a> {
    scale: f32,
    calls: &'a Cell<u64>,
}

impl PixelLikelihood for CountingLaplace<'_> {
    fn log_likelihood(&self, target: Vec3, rendered: Vec3, _sq_dist: f32) -> f32 {
        self.calls.set(self.calls.get() + 1);
        let l1: f32 = target.iter().zip(rendered).map(|(t, r)| (t - r).abs()).sum();
        -3.0 * (2.0 * self.scale).ln() - l1 / self.scale
    }
}

/// A flat background: every colour equally likely.
struct FlatBackground;

impl BackgroundLikelihood for FlatBackground {
    fn log_density(&self, _target: [u8; 3]) -> f32 {
        0.0
    }
}

/// Two proposals of our own: one that never moves anywhere, one that proposes the current state.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Custom {
    /// Always impossible (Hastings term −∞).
    Never,
    /// Proposes the current state (always accepted: every ratio is 1).
    Stay,
}

impl Proposal for Custom {
    fn name(&self) -> &'static str {
        match self {
            Custom::Never => "never",
            Custom::Stay => "stay",
        }
    }

    fn changes_shape(&self) -> bool {
        false
    }

    fn changes_geometry(&self) -> bool {
        false
    }

    fn propose<R: Rng + ?Sized, const KS: usize, const KC: usize>(
        &self,
        current: &FitParams<KS, KC>,
        _ctx: &ProposalContext,
        _rng: &mut R,
        out: &mut FitParams<KS, KC>,
    ) -> f32 {
        out.clone_from(current);
        match self {
            Custom::Never => f32::NEG_INFINITY,
            Custom::Stay => 0.0,
        }
    }
}

/// Counts outcomes per proposal name, and the components announced before the chain ran.
#[derive(Default)]
struct ByName {
    components: Vec<&'static str>,
    outcomes: BTreeMap<&'static str, Vec<StepOutcome>>,
    progress_calls: u32,
}

impl ChainObserver for ByName {
    fn component(&mut self, _id: usize, name: &'static str) {
        self.components.push(name);
    }

    fn progress(&mut self, _done: u32) {
        self.progress_calls += 1;
    }

    fn proposal(&mut self, step: &ProposalStep) {
        self.outcomes.entry(step.name).or_default().push(step.outcome);
    }
}

fn mixture() -> Mixture<OneOf<StandardProposal, Custom>> {
    let mut m = Mixture::image_default(W as f32).map(|p| OneOf::First(*p));
    m.push(OneOf::Second(Custom::Never), 0.3).unwrap();
    m.push(OneOf::Second(Custom::Stay), 0.3).unwrap();
    m
}

fn count(obs: &ByName, name: &str, outcome: StepOutcome) -> usize {
    obs.outcomes.get(name).map_or(0, |v| v.iter().filter(|o| **o == outcome).count())
}

#[test]
fn a_user_pixel_likelihood_and_user_proposals_run_in_the_image_chain() {
    let synth = Synth::new(11);
    let model = synth.model();
    let truth = truth();
    let pixels = render_target(&synth, &truth);
    let points = project_landmarks(&model, &truth);
    let valid = all_valid(points.len());
    let lm = target(&points, &valid);
    let prior = Prior::around(&truth);
    let mix = mixture();
    let problem = Problem { model, landmarks: lm, prior: &prior, mixture: &mix, width: W, height: H, silhouette: None };
    let image = TargetImage::new(&pixels, W, H).unwrap();
    let calls = Cell::new(0u64);
    let laplace = CountingLaplace { scale: 0.05, calls: &calls };
    let ip = ImageProblem { image, pixel: laplace, background: &FlatBackground, light_solve: LightSolveConfig::default() };
    let mut bufs = Buffers::new(synth.vertices());
    let mut inst = bufs.instance();
    let mut raster = Raster::new();
    let prior_yaw = truth.pose.yaw;
    let mut start = truth;
    start.pose.yaw += 3f32.to_radians();
    let steps = 120;
    let mut obs = ByName::default();
    let mut moments = PosteriorMoments::<{ fit_support::KS }, { fit_support::KC }>::new(40);
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(21);
    let fit = image_chain(&problem, &ip, &start, steps, &mut inst, &mut raster, &mut rng, (&mut obs, &mut moments)).unwrap();

    // A second observer beside the first summarized the states after the burn-in.
    assert_eq!(moments.samples(), steps - 40);
    assert_eq!(moments.color_mean().count(), fit.best.color_coeffs().len());
    let yaw = moments.angles_mean()[0];
    assert!((yaw - prior_yaw).abs() < 5f32.to_radians(), "{yaw} {prior_yaw}");
    // A yaw that stopped moving before the burn-in is the last state's, with no spread.
    assert!(moments.angles_sd()[0] > 0.0 || yaw == fit.last.pose.yaw);

    // The observer was told about every component, every step and every proposal.
    assert_eq!(obs.components.len(), mix.entries().len());
    assert!(obs.components.contains(&"never") && obs.components.contains(&"stay") && obs.components.contains(&"yaw"));
    assert_eq!(obs.progress_calls, steps + 1);
    let seen: usize = obs.outcomes.values().map(Vec::len).sum();
    assert_eq!(seen, steps as usize);
    // It agrees with the chain's own per-component counts.
    let accepted: u32 = fit.acceptance.accepted.iter().sum();
    let seen_accepted: usize = obs.outcomes.values().flatten().filter(|o| o.accepted()).count();
    assert_eq!(seen_accepted, accepted as usize);

    // Our proposals were drawn, and the chain treated them as their Hastings terms demand.
    let never = obs.outcomes.get("never").map_or(0, Vec::len);
    let stay = obs.outcomes.get("stay").map_or(0, Vec::len);
    assert!(never > 5 && stay > 5, "never {never}, stay {stay}");
    assert_eq!(count(&obs, "never", StepOutcome::Impossible), never);
    assert_eq!(count(&obs, "stay", StepOutcome::Accepted), stay);
    let never_id = mix.entries().iter().position(|e| e.proposal == OneOf::Second(Custom::Never)).unwrap();
    assert_eq!(fit.acceptance.proposed[never_id] as usize, never);
    assert_eq!(fit.acceptance.passed_filter[never_id], 0);

    // The chain evaluated our likelihood: its image term is ours, not the Gaussian one.
    assert!(calls.get() > 0);
    let best_image = fit.best_image.unwrap();
    let ours = image_log_likelihood(&problem, &ip, &fit.best, &mut inst, &mut raster).unwrap();
    assert_eq!(best_image.log_likelihood, ours.log_likelihood);
    let bg = BackgroundModel::uniform();
    let gaussian =
        ImageProblem { image, pixel: GaussianPixel::new(DEFAULT_PIXEL_SIGMA).unwrap(), background: &bg, light_solve: ip.light_solve };
    let theirs = image_log_likelihood(&problem, &gaussian, &fit.best, &mut inst, &mut raster).unwrap();
    assert_eq!(theirs.covered, ours.covered);
    assert_ne!(theirs.log_likelihood, ours.log_likelihood);
    let calls_before = calls.get();
    image_log_likelihood(&problem, &ip, &fit.best, &mut inst, &mut raster).unwrap();
    assert_eq!(calls.get() - calls_before, u64::from(ours.covered), "one call per covered pixel");
}

#[test]
fn user_proposals_run_in_the_landmark_chain() {
    let synth = Synth::new(11);
    let model = synth.model();
    let truth = truth();
    let points = project_landmarks(&model, &truth);
    let valid = all_valid(points.len());
    let prior = Prior::around(&truth);
    // Only our proposals: the state never changes, and the impossible one is never accepted.
    let mut mix = Mixture::new();
    mix.push(Custom::Never, 1.0).unwrap();
    mix.push(Custom::Stay, 3.0).unwrap();
    let problem =
        Problem { model, landmarks: target(&points, &valid), prior: &prior, mixture: &mix, width: W, height: H, silhouette: None };
    let mut obs = ByName::default();
    let mut moments = PosteriorMoments::<{ fit_support::KS }, { fit_support::KC }>::new(150);
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(5);
    let fit = landmark_chain(&problem, &truth, 200, &mut rng, (&mut obs, &mut moments)).unwrap();
    assert_eq!(fit.best, truth);
    assert_eq!(fit.last, truth);
    // The state never moved: its mean is the state, its spread zero.
    assert_eq!(moments.samples(), 50);
    assert!(moments.shape_mean().eq(truth.shape_coeffs().iter().copied()));
    assert!(moments.shape_sd().all(|s| s == 0.0) && moments.angles_sd() == [0.0; 3]);
    let (never, stay) = (obs.outcomes["never"].len(), obs.outcomes["stay"].len());
    assert_eq!(never + stay, 200);
    // Weights 1 : 3.
    assert!((30..=70).contains(&never), "{never}");
    assert_eq!(count(&obs, "never", StepOutcome::Impossible), never);
    assert_eq!(count(&obs, "stay", StepOutcome::Accepted), stay);
    assert_eq!(fit.acceptance.accepted[1] as usize, stay);
}
