//! Watching a chain: every proposal's outcome goes to a [`ChainObserver`] (as scalismo-faces'
//! chain loggers watch a chain). [`Acceptance`] counts per mixture component; users count by
//! name, log or trace with their own observers.

use crate::fit::chain::proposal::MAX_PROPOSALS;
use crate::render::{Pose, ShLight};

/// What became of one proposal.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StepOutcome {
    /// The proposal itself refused the move (Hastings term `−∞`, e.g. a distance behind the camera).
    Impossible,
    /// Rejected by the first stage (prior and landmarks; in the landmark chain the only stage).
    RejectedByFilter,
    /// Passed the first stage, rejected by the image term (image chain only).
    RejectedByImage,
    /// Accepted: the proposal is the chain's new state.
    Accepted,
}

impl StepOutcome {
    /// Whether it passed the prior-and-landmark stage (an accepted landmark-chain step did).
    pub fn passed_filter(self) -> bool {
        matches!(self, StepOutcome::RejectedByImage | StepOutcome::Accepted)
    }

    /// Whether it was accepted.
    pub fn accepted(self) -> bool {
        self == StepOutcome::Accepted
    }
}

/// One proposal as the chain saw it.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ProposalStep {
    /// The step's index in its chain (0-based).
    pub step: u32,
    /// The component's index in the mixture.
    pub id: usize,
    /// The component's [`crate::fit::Proposal::name`].
    pub name: &'static str,
    /// What became of it.
    pub outcome: StepOutcome,
    /// The chain's log posterior after the step (up to a constant; the current state's).
    pub log_posterior: f32,
}

/// The chain's current state after a step (borrowed: an observer copies what it keeps; its log
/// posterior is the step's [`ProposalStep::log_posterior`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChainSample<'a> {
    /// The step's index in its chain (0-based).
    pub step: u32,
    /// The rigid pose.
    pub pose: &'a Pose,
    /// The light.
    pub light: &'a ShLight,
    /// The active shape coefficients.
    pub shape: &'a [f32],
    /// The active colour coefficients.
    pub color: &'a [f32],
}

/// Watches a chain: progress before each step, the outcome of every proposal and the state
/// after it.
///
/// # Examples
///
/// An observer of one's own that counts the proposals and the accepted ones of a short
/// landmark chain:
///
/// ```
/// use gpmm_core::fit::{landmark_chain, ChainObserver, Mixture, Prior, Problem, ProposalStep};
/// # use gpmm_core::fit::{project_landmarks, LandmarkTarget};
/// # use gpmm_core::model::{Basis, FactoredBasis, MorphableModel};
/// use gpmm_core::model::FitParams;
/// use gpmm_core::render::{Pose, ShLight};
/// use rand_core::SeedableRng;
///
/// #[derive(Default)]
/// struct Counts {
///     proposed: u32,
///     accepted: u32,
/// }
///
/// impl ChainObserver for Counts {
///     fn proposal(&mut self, step: &ProposalStep) {
///         self.proposed += 1;
///         self.accepted += u32::from(step.outcome.accepted());
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
/// // The landmarks of a tetrahedron turned by 0.3 rad, a frontal start, the standard mixture.
/// let start = params(0.0);
/// let (prior, mixture) = (Prior::around(&start), Mixture::landmark_default(32.0));
/// let problem = Problem { model, landmarks, prior: &prior, mixture: &mixture, width: 32, height: 32, silhouette: None };
///
/// let mut counts = Counts::default();
/// let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(1);
/// let fit = landmark_chain(&problem, &start, 300, &mut rng, &mut counts)?;
/// assert_eq!(counts.proposed, 300);
/// assert!(counts.accepted > 0);
/// assert_eq!(counts.accepted, fit.acceptance.accepted.iter().sum::<u32>());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub trait ChainObserver {
    /// Called once per mixture component before the first step (index and
    /// [`crate::fit::Proposal::name`]), so that reports can list components never drawn.
    fn component(&mut self, _id: usize, _name: &'static str) {}

    /// Called with the number of finished steps before each step and once at the end.
    fn progress(&mut self, _done: u32) {}

    /// Called once per proposal, after the chain decided.
    fn proposal(&mut self, _step: &ProposalStep) {}

    /// Called after each step with the chain's current state (the accepted proposal or the
    /// state it stayed in): what a posterior summary averages.
    fn sample(&mut self, _sample: &ChainSample<'_>) {}
}

/// Observes nothing.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct NoObserver;

impl ChainObserver for NoObserver {}

/// A progress callback `FnMut(done)` as an observer (proposals are not reported to it).
#[derive(Debug, Clone, Copy)]
pub struct Progress<F>(pub F);

impl<F: FnMut(u32)> ChainObserver for Progress<F> {
    fn progress(&mut self, done: u32) {
        (self.0)(done)
    }
}

impl<O: ChainObserver + ?Sized> ChainObserver for &mut O {
    fn component(&mut self, id: usize, name: &'static str) {
        (**self).component(id, name)
    }

    fn progress(&mut self, done: u32) {
        (**self).progress(done)
    }

    fn proposal(&mut self, step: &ProposalStep) {
        (**self).proposal(step)
    }

    fn sample(&mut self, sample: &ChainSample<'_>) {
        (**self).sample(sample)
    }
}

/// Two observers, both told everything (first `.0`, then `.1`).
impl<A: ChainObserver, B: ChainObserver> ChainObserver for (A, B) {
    fn component(&mut self, id: usize, name: &'static str) {
        self.0.component(id, name);
        self.1.component(id, name);
    }

    fn progress(&mut self, done: u32) {
        self.0.progress(done);
        self.1.progress(done);
    }

    fn proposal(&mut self, step: &ProposalStep) {
        self.0.proposal(step);
        self.1.proposal(step);
    }

    fn sample(&mut self, sample: &ChainSample<'_>) {
        self.0.sample(sample);
        self.1.sample(sample);
    }
}

/// Per-component proposal counts (index = position in the [`crate::fit::Mixture`]); an observer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Acceptance {
    /// Times the component was drawn.
    pub proposed: [u32; MAX_PROPOSALS],
    /// Times it passed the prior-and-landmark stage.
    pub passed_filter: [u32; MAX_PROPOSALS],
    /// Times it was accepted.
    pub accepted: [u32; MAX_PROPOSALS],
}

impl Default for Acceptance {
    fn default() -> Self {
        Self::new()
    }
}

impl Acceptance {
    /// No counts.
    pub const fn new() -> Self {
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

    /// The counts of `self` and `other` together (two phases of one chain, say).
    pub fn combined(&self, other: &Acceptance) -> Acceptance {
        let mut out = *self;
        for (mine, theirs) in
            [(&mut out.proposed, &other.proposed), (&mut out.passed_filter, &other.passed_filter), (&mut out.accepted, &other.accepted)]
        {
            mine.iter_mut().zip(theirs).for_each(|(a, b)| *a = a.saturating_add(*b));
        }
        out
    }

    /// Counts one proposal of component `id` (ids beyond [`MAX_PROPOSALS`] are ignored).
    pub fn count(&mut self, id: usize, passed: bool, accepted: bool) {
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

impl ChainObserver for Acceptance {
    fn proposal(&mut self, step: &ProposalStep) {
        self.count(step.id, step.outcome.passed_filter(), step.outcome.accepted());
    }
}
