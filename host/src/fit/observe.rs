//! The host's observer of the core's standard fit: progress reports in chunks, the landmark
//! chain's wall time, acceptance counts per proposal name as the chains report them, and the
//! image chain's posterior moments.

use super::params::{KC, KS};
use gpmm_core::fit::{ChainObserver, ChainSample, FitObserver, PosteriorMoments, ProposalStep, Stage};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::time::Instant;

/// Proposal counts of one proposal kind.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct KindCounts {
    /// Times drawn.
    pub proposed: u64,
    /// Times it passed the prior-and-landmark stage.
    pub passed: u64,
    /// Times accepted.
    pub accepted: u64,
}

/// Counts per proposal kind name (`yaw`, `shape`, `light-solve`, ...).
pub type AcceptanceReport = BTreeMap<String, KindCounts>;

/// Landmark-chain steps between progress reports.
const LANDMARK_CHUNK: u32 = 1000;
/// Image-chain steps between progress reports.
const IMAGE_CHUNK: u32 = 25;

/// Watches one standard fit.
pub(crate) struct HostObserver<'p> {
    progress: &'p mut dyn FnMut(&str, u64, u64),
    t0: Instant,
    /// Seconds from the start to the end of the landmark chain.
    pub landmark_seconds: f64,
    /// Counts of both landmark-chain phases, by proposal name.
    pub landmark: AcceptanceReport,
    /// Counts of the image chain, by proposal name.
    pub image: AcceptanceReport,
    /// The image chain's samples from its burn-in on.
    pub posterior: Box<PosteriorMoments<KS, KC>>,
}

impl<'p> HostObserver<'p> {
    /// Starts the clock now; the posterior summary leaves out the image chain's first `burn_in` steps.
    pub fn new(progress: &'p mut dyn FnMut(&str, u64, u64), burn_in: u32) -> Self {
        Self {
            progress,
            t0: Instant::now(),
            landmark_seconds: 0.0,
            landmark: AcceptanceReport::new(),
            image: AcceptanceReport::new(),
            posterior: Box::new(PosteriorMoments::new(burn_in)),
        }
    }

    /// Seconds since [`Self::new`].
    pub fn elapsed(&self) -> f64 {
        self.t0.elapsed().as_secs_f64()
    }

    fn report(&mut self, stage: Stage) -> &mut AcceptanceReport {
        match stage {
            Stage::LandmarkChain => &mut self.landmark,
            Stage::ImageChain => &mut self.image,
        }
    }
}

impl FitObserver for HostObserver<'_> {
    fn step(&mut self, stage: Stage, done: u32, total: u32) {
        match stage {
            Stage::LandmarkChain => {
                if done.is_multiple_of(LANDMARK_CHUNK) || done == total {
                    (self.progress)("landmark chain", u64::from(done), u64::from(total));
                }
                if done == total {
                    self.landmark_seconds = self.elapsed();
                }
            }
            Stage::ImageChain => {
                if done.is_multiple_of(IMAGE_CHUNK) || done == total {
                    (self.progress)("image chain", u64::from(done), u64::from(total));
                }
            }
        }
    }

    fn component(&mut self, stage: Stage, _id: usize, name: &'static str) {
        self.report(stage).entry(name.to_string()).or_default();
    }

    fn proposal(&mut self, stage: Stage, step: &ProposalStep) {
        let c: &mut KindCounts = self.report(stage).entry(step.name.to_string()).or_default();
        c.proposed += 1;
        c.passed += u64::from(step.outcome.passed_filter());
        c.accepted += u64::from(step.outcome.accepted());
    }

    fn sample(&mut self, stage: Stage, sample: &ChainSample<'_>) {
        if stage == Stage::ImageChain {
            self.posterior.sample(sample);
        }
    }
}
