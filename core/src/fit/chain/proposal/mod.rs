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
