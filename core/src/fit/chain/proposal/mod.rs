//! Proposals: the [`Proposal`] trait, a weighted [`Mixture`] of proposals, and [`OneOf`] to mix
//! proposals of two types (e.g. the built-in [`StandardProposal`]s and one of the user's).
//!
//! A proposal draws `x'` from `q(x' | x)` and reports its log Hastings term
//! `log q(x | x') − log q(x' | x)`; it also says which parts of the state it can move, so the
//! chain recomputes only what changed (landmark vertices after a shape move, landmark positions
//! after a geometric move). The chain picks a mixture component by weight, lets it propose and
//! tells a [`crate::fit::ChainObserver`] the component's index and [`Proposal::name`] with the outcome.

pub mod standard;

pub use standard::{ProposalKind, Scale, StandardProposal};

use crate::geometry::Vec3;
use crate::model::params::FitParams;
use crate::render::pose::PoseTrig;
use crate::render::ShLight;
use rand_core::Rng;

/// What proposals may need beyond the parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProposalContext {
    /// Model-space pivot of rotations and distance changes (e.g. the landmark centroid of the mean).
    pub pivot: Vec3,
    /// The least-squares light for the current state: set by the image chain before a proposal
    /// whose [`Proposal::needs_light_solution`] is true (`None` if the solve failed, and always in
    /// the landmark chain).
    pub light_solution: Option<ShLight>,
    /// The sines and cosines of the current state's angles, if the chain keeps them (then a
    /// proposal's rotations recompute only the angles it changes; the same bits either way).
    pub trig: Option<PoseTrig>,
}

/// A Metropolis-Hastings proposal: draws a new state from the current one.
///
/// # Examples
///
/// A proposal of one's own, a uniform random walk on the yaw alone, finding the yaw of a turned
/// tetrahedron from its landmarks:
///
/// ```
/// use gpmm_core::fit::{landmark_chain, Mixture, NoObserver, Prior, Problem, Proposal, ProposalContext};
/// # use gpmm_core::fit::{project_landmarks, LandmarkTarget};
/// # use gpmm_core::model::{Basis, FactoredBasis, MorphableModel};
/// use gpmm_core::model::FitParams;
/// use gpmm_core::render::{Pose, ShLight};
/// use rand_core::{Rng, SeedableRng};
///
/// struct YawWalk(f32);
///
/// impl Proposal for YawWalk {
///     fn name(&self) -> &'static str {
///         "yaw walk"
///     }
///
///     fn changes_shape(&self) -> bool {
///         false
///     }
///
///     fn propose<R: Rng + ?Sized, const KS: usize, const KC: usize>(
///         &self,
///         current: &FitParams<KS, KC>,
///         _ctx: &ProposalContext,
///         rng: &mut R,
///         out: &mut FitParams<KS, KC>,
///     ) -> f32 {
///         out.clone_from(current);
///         out.pose.yaw += self.0 * (2.0 * (rng.next_u32() as f32 / u32::MAX as f32) - 1.0);
///         0.0 // symmetric: no Hastings term
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
/// // The landmarks of a tetrahedron turned by 0.3 rad, a frontal start, a mixture of one walk.
/// let start = params(0.0);
/// let (prior, mut mixture) = (Prior::around(&start), Mixture::new());
/// assert!(mixture.push(YawWalk(0.05), 1.0).is_ok());
/// let problem = Problem { model, landmarks, prior: &prior, mixture: &mixture, width: 32, height: 32, silhouette: None };
///
/// let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(1);
/// let fit = landmark_chain(&problem, &start, 400, &mut rng, NoObserver)?;
/// assert_eq!(fit.acceptance.proposed[0], 400);
/// assert!((fit.best.pose.yaw - 0.3).abs() < 0.01, "{}", fit.best.pose.yaw);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub trait Proposal {
    /// A short name for reports and acceptance counts (e.g. `"yaw"`).
    fn name(&self) -> &'static str;

    /// Whether it can change the shape coefficients (the landmark vertices are then recomputed).
    fn changes_shape(&self) -> bool {
        true
    }

    /// Whether it can move the projected landmarks (pose, focal length or shape): the landmark
    /// term is then re-evaluated.
    fn changes_geometry(&self) -> bool {
        true
    }

    /// Whether it needs [`ProposalContext::light_solution`] (the image chain then solves the light
    /// of the current state first, drawing one `u32` from the generator for the vertex offset).
    fn needs_light_solution(&self) -> bool {
        false
    }

    /// Draws `x'` from `current` into `out` (every field: start from a copy of `current`);
    /// returns the log Hastings term, `−∞` if the move is impossible.
    fn propose<R: Rng + ?Sized, const KS: usize, const KC: usize>(
        &self,
        current: &FitParams<KS, KC>,
        ctx: &ProposalContext,
        rng: &mut R,
        out: &mut FitParams<KS, KC>,
    ) -> f32;
}

/// One of two proposal types: mixes proposals of different types in one [`Mixture`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum OneOf<A, B> {
    /// A proposal of the first type.
    First(A),
    /// A proposal of the second type.
    Second(B),
}

impl<A: Proposal, B: Proposal> Proposal for OneOf<A, B> {
    fn name(&self) -> &'static str {
        match self {
            OneOf::First(a) => a.name(),
            OneOf::Second(b) => b.name(),
        }
    }

    fn changes_shape(&self) -> bool {
        match self {
            OneOf::First(a) => a.changes_shape(),
            OneOf::Second(b) => b.changes_shape(),
        }
    }

    fn changes_geometry(&self) -> bool {
        match self {
            OneOf::First(a) => a.changes_geometry(),
            OneOf::Second(b) => b.changes_geometry(),
        }
    }

    fn needs_light_solution(&self) -> bool {
        match self {
            OneOf::First(a) => a.needs_light_solution(),
            OneOf::Second(b) => b.needs_light_solution(),
        }
    }

    fn propose<R: Rng + ?Sized, const KS: usize, const KC: usize>(
        &self,
        current: &FitParams<KS, KC>,
        ctx: &ProposalContext,
        rng: &mut R,
        out: &mut FitParams<KS, KC>,
    ) -> f32 {
        match self {
            OneOf::First(a) => a.propose(current, ctx, rng, out),
            OneOf::Second(b) => b.propose(current, ctx, rng, out),
        }
    }
}

/// Capacity of a [`Mixture`].
pub const MAX_PROPOSALS: usize = 32;

/// One mixture component: a proposal and its unnormalized weight.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MixtureEntry<P> {
    /// The proposal.
    pub proposal: P,
    /// Its unnormalized weight (finite, ≥ 0).
    pub weight: f32,
}

/// A mixture of at most [`MAX_PROPOSALS`] proposals; the index of a component is its proposal id.
#[derive(Debug, Clone, PartialEq)]
pub struct Mixture<P = StandardProposal> {
    entries: heapless::Vec<MixtureEntry<P>, MAX_PROPOSALS>,
    total: f32,
}

impl<P> Default for Mixture<P> {
    fn default() -> Self {
        Self::new()
    }
}

impl<P> Mixture<P> {
    /// An empty mixture.
    pub const fn new() -> Self {
        Self { entries: heapless::Vec::new(), total: 0.0 }
    }

    /// Adds a component; hands it back if the weight is negative or not finite or the mixture is full.
    pub fn push(&mut self, proposal: P, weight: f32) -> Result<(), MixtureEntry<P>> {
        let entry = MixtureEntry { proposal, weight };
        if !(weight >= 0.0 && weight.is_finite()) {
            return Err(entry);
        }
        self.entries.push(entry)?;
        self.total += weight;
        Ok(())
    }

    /// The components.
    pub fn entries(&self) -> &[MixtureEntry<P>] {
        &self.entries
    }

    /// Sum of the weights.
    pub fn total_weight(&self) -> f32 {
        self.total
    }

    /// The component for a uniform `u` in `[0, 1)` (by cumulative weight); `None` if the mixture is empty.
    pub fn choose(&self, u: f32) -> Option<usize> {
        let mut acc = 0.0f32;
        let target = u * self.total;
        let mut last = None;
        for (i, e) in self.entries().iter().enumerate() {
            if e.weight <= 0.0 {
                continue;
            }
            acc += e.weight;
            last = Some(i);
            if target < acc {
                return Some(i);
            }
        }
        last
    }

    /// The same components and weights with each proposal mapped (e.g. into a [`OneOf`]).
    pub fn map<Q>(&self, mut f: impl FnMut(&P) -> Q) -> Mixture<Q> {
        let mut out = Mixture::new();
        for e in self.entries() {
            // Same length and the weights were valid when pushed: cannot fail.
            let _ = out.push(f(&e.proposal), e.weight);
        }
        out
    }
}
