//! The built-in proposals: Gaussian drift, coarse to fine, and their mixtures (after scalismo-faces' standard fit).
//!
//! Every proposal changes one block of parameters and reports its log Hastings term
//! `log q(x | x') − log q(x' | x)` (0 for the symmetric random walks):
//! - **Yaw / Pitch / Roll**: one Euler angle `+= σ·ε`; the translation is compensated so that a
//!   model-space pivot (the landmark centroid) stays where it was in camera space:
//!   `t' = t + R p − R' p`. The shift depends on the angles only, so the map is volume-preserving
//!   and the proposal stays symmetric.
//! - **Distance**: the pivot's depth `w` changes by `σ·ε` mm and the focal length follows,
//!   `f' = f · w'/w`, so the face keeps its size in the image while the perspective changes; the
//!   Jacobian of that map gives the Hastings term `log(w'/w)`.
//! - **Scaling**: `f' = f · exp(σ·ε)` (log-normal random walk), Hastings term `σ·ε = log(f'/f)`.
//! - **Translation**: x and y `+= σ·ε` with σ in pixels converted to mm at the pivot's depth
//!   (which this proposal does not change, so it stays symmetric).
//! - **Shape / Color**: every active coefficient `+= σ·ε` (σ 0.2 / 0.1 / 0.025 as scalismo).
//! - **Light**: every SH coefficient `+= σ·ε`. **LightIntensity**: all 27 scaled by `exp(σ·ε)`,
//!   Hastings term `27·σ·ε`.
//! - **LightSolve**: an independence proposal around the least-squares light `L*` of the current
//!   geometry and albedo ([`crate::fit::solve::light`]): `L' = L* + σ·ε`. `L*` depends only on parameters
//!   a light proposal does not change, so the reverse move draws from the same Gaussian and the
//!   Hastings term is `log N(L; L*, σ) − log N(L'; L*, σ)`. Detailed balance holds exactly; pick σ
//!   wider than the light posterior so a far-away current light can still be left.

use super::{Mixture, Proposal, ProposalContext};
use crate::error::FitError;
use crate::fit::chain::normal::{add_normals, standard_normal};
use crate::fit::settings::{Drift, DriftSettings, MixtureShares};
use crate::geometry::mat_vec;
use crate::geometry::Vec3;
use crate::model::params::FitParams;
use crate::render::pose::PoseTrig;
use rand_core::Rng;

/// Which block a proposal moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ProposalKind {
    /// Yaw angle (pivot-compensated).
    Yaw,
    /// Pitch angle (pivot-compensated).
    Pitch,
    /// Roll angle (pivot-compensated).
    Roll,
    /// Depth with focal-length compensation (σ in mm).
    Distance,
    /// Focal length, multiplicative (σ in log units).
    Scaling,
    /// Translation x and y (σ in pixels).
    Translation,
    /// All active shape coefficients.
    Shape,
    /// All active colour coefficients.
    Color,
    /// All SH light coefficients, additive.
    Light,
    /// All SH light coefficients, common multiplicative factor (σ in log units).
    LightIntensity,
    /// Independence proposal around the least-squares light.
    LightSolve,
}

impl ProposalKind {
    /// A short name for reports.
    pub fn name(self) -> &'static str {
        match self {
            ProposalKind::Yaw => "yaw",
            ProposalKind::Pitch => "pitch",
            ProposalKind::Roll => "roll",
            ProposalKind::Distance => "distance",
            ProposalKind::Scaling => "scaling",
            ProposalKind::Translation => "translation",
            ProposalKind::Shape => "shape",
            ProposalKind::Color => "color",
            ProposalKind::Light => "light",
            ProposalKind::LightIntensity => "light-intensity",
            ProposalKind::LightSolve => "light-solve",
        }
    }

    /// Whether the proposal changes the shape coefficients (landmark positions must be recomputed).
    pub fn changes_shape(self) -> bool {
        self == ProposalKind::Shape
    }

    /// Whether the proposal can move the projected landmarks (pose, focal length or shape).
    pub fn changes_geometry(self) -> bool {
        !matches!(self, ProposalKind::Color | ProposalKind::Light | ProposalKind::LightIntensity | ProposalKind::LightSolve)
    }
}

/// Step size class (for reports).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Scale {
    /// Large steps.
    Coarse,
    /// Medium steps.
    Intermediate,
    /// Small steps.
    Fine,
}

impl Scale {
    /// A short name for reports.
    pub fn name(self) -> &'static str {
        match self {
            Scale::Coarse => "coarse",
            Scale::Intermediate => "intermediate",
            Scale::Fine => "fine",
        }
    }
}

/// One built-in proposal: a kind (the block it moves), a step class and a σ (units per
/// [`ProposalKind`]).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StandardProposal {
    /// The block it moves.
    pub kind: ProposalKind,
    /// Its step class.
    pub scale: Scale,
    /// Standard deviation (units per [`ProposalKind`]; finite, > 0).
    pub sigma: f32,
    /// Shape and colour moves: how many of the leading coefficients it moves (0: all active ones).
    pub leading: u16,
}

impl StandardProposal {
    /// Checks σ (finite, > 0); `BadConfig` otherwise. Shape and colour moves move every active
    /// coefficient ([`Self::with_leading`] limits them).
    pub fn new(kind: ProposalKind, scale: Scale, sigma: f32) -> Result<Self, FitError> {
        if !(sigma > 0.0 && sigma.is_finite()) {
            return Err(FitError::BadConfig);
        }
        Ok(Self { kind, scale, sigma, leading: 0 })
    }

    /// The same proposal moving only the leading `leading` coefficients (shape and colour moves;
    /// 0: all): a block of the coarse components, whose moves change the face most per unit of
    /// prior, is accepted far more often than an isotropic step in all 200 dimensions.
    pub fn with_leading(self, leading: u16) -> Self {
        Self { leading, ..self }
    }
}

impl Mixture<StandardProposal> {
    /// Adds one built-in component (σ finite and > 0, weight finite and ≥ 0; `BadConfig`
    /// otherwise or when the mixture is full).
    pub fn push_standard(&mut self, kind: ProposalKind, scale: Scale, sigma: f32, weight: f32) -> Result<(), FitError> {
        let p = StandardProposal::new(kind, scale, sigma)?;
        self.push(p, weight).map_err(|_| FitError::BadConfig)
    }

    /// Adds coarse, intermediate and fine components of one kind with weights `share · w_i`.
    pub fn push3(&mut self, kind: ProposalKind, sigmas: [f32; 3], weights: [f32; 3], share: f32) -> Result<(), FitError> {
        let sum: f32 = weights.iter().sum();
        for ((s, w), scale) in sigmas.iter().zip(weights).zip([Scale::Coarse, Scale::Intermediate, Scale::Fine]) {
            self.push_standard(kind, scale, *s, share * w / sum)?;
        }
        Ok(())
    }

    /// Adds coarse, intermediate and fine components of one kind from a [`Drift`], weights `share · w_i`.
    fn push_drift(&mut self, kind: ProposalKind, drift: &Drift, share: f32) -> Result<(), FitError> {
        self.push3(kind, drift.sigmas, drift.weights, share)
    }

    /// As [`Self::push_drift`], the coarse, intermediate and fine steps moving the leading
    /// `leading[i]` coefficients (0: all).
    fn push_drift_leading(&mut self, kind: ProposalKind, drift: &Drift, share: f32, leading: [u16; 3]) -> Result<(), FitError> {
        let sum: f32 = drift.weights.iter().sum();
        for (((s, w), scale), n) in
            drift.sigmas.iter().zip(drift.weights).zip([Scale::Coarse, Scale::Intermediate, Scale::Fine]).zip(leading)
        {
            let p = StandardProposal::new(kind, scale, *s)?.with_leading(n);
            self.push(p, share * w / sum).map_err(|_| FitError::BadConfig)?;
        }
        Ok(())
    }

    /// Pitch, roll, scaling and translation components, and yaw and distance ones if asked;
    /// weights are fractions of `share` ([`DriftSettings::pose_fractions`]: yaw, pitch, roll,
    /// distance, scaling, translation), so leaving parts out lowers the total. Translation σ's
    /// are fractions of `image_size`.
    fn add_pose_parts(&mut self, drift: &DriftSettings, image_size: f32, share: f32, yaw: bool, distance: bool) -> Result<(), FitError> {
        let [f_yaw, f_pitch, f_roll, f_distance, f_scaling, f_translation] = drift.pose_fractions;
        if yaw {
            self.push_drift(ProposalKind::Yaw, &drift.rotation, f_yaw * share)?;
        }
        self.push_drift(ProposalKind::Pitch, &drift.rotation, f_pitch * share)?;
        self.push_drift(ProposalKind::Roll, &drift.rotation, f_roll * share)?;
        if distance {
            self.push_drift(ProposalKind::Distance, &drift.distance, f_distance * share)?;
        }
        self.push_drift(ProposalKind::Scaling, &drift.scaling, f_scaling * share)?;
        let px = image_size.max(1.0);
        let t = drift.translation.sigmas;
        self.push3(ProposalKind::Translation, [t[0] * px, t[1] * px, t[2] * px], drift.translation.weights, f_translation * share)
    }

    /// The mixture with `shares` of the built-in kinds and the step sizes `drift`, for a working
    /// image whose larger side is `image_size` px (kinds with share 0 are left out). `BadConfig`
    /// if a σ or weight is invalid or the components exceed the capacity.
    pub fn from_shares(shares: &MixtureShares, drift: &DriftSettings, image_size: f32) -> Result<Self, FitError> {
        let mut m = Self::new();
        if shares.shape_first && shares.shape > 0.0 {
            m.push_drift_leading(ProposalKind::Shape, &drift.shape, shares.shape, drift.shape_leading)?;
        }
        if shares.pose > 0.0 {
            m.add_pose_parts(drift, image_size, shares.pose, shares.yaw, shares.distance)?;
        }
        if !shares.shape_first && shares.shape > 0.0 {
            m.push_drift_leading(ProposalKind::Shape, &drift.shape, shares.shape, drift.shape_leading)?;
        }
        if shares.color > 0.0 {
            m.push_drift_leading(ProposalKind::Color, &drift.color, shares.color, drift.color_leading)?;
        }
        if shares.light > 0.0 {
            m.push_drift(ProposalKind::Light, &drift.light, shares.light)?;
        }
        if shares.light_intensity > 0.0 {
            m.push_standard(ProposalKind::LightIntensity, Scale::Intermediate, drift.light_intensity_sigma, shares.light_intensity)?;
        }
        if shares.light_solve > 0.0 {
            m.push_standard(ProposalKind::LightSolve, Scale::Fine, drift.light_solve_sigma, shares.light_solve)?;
        }
        Ok(m)
    }

    /// The pose phase of the landmark chain ([`MixtureShares::LANDMARK_POSE`]): rotation, scaling
    /// (focal length) and translation, no distance changes (landmarks hardly tell perspective
    /// from shape) and no shape.
    pub fn landmark_pose(image_size: f32) -> Self {
        Self::from_shares(&MixtureShares::LANDMARK_POSE, &DriftSettings::DEFAULT, image_size).unwrap_or_default()
    }

    /// The shape phase of the landmark chain ([`MixtureShares::LANDMARK_SHAPE`]): shape drift
    /// (60 %) with the pose free except for yaw and distance, the directions along which the
    /// landmarks trade pose for shape.
    pub fn landmark_shape(image_size: f32) -> Self {
        Self::from_shares(&MixtureShares::LANDMARK_SHAPE, &DriftSettings::DEFAULT, image_size).unwrap_or_default()
    }

    /// A joint landmark mixture ([`MixtureShares::LANDMARK_JOINT`]): pose (70 %) and shape (30 %).
    /// [`crate::fit::standard_fit`] does not use it: moving yaw and shape together biases yaw, so
    /// it runs [`Self::landmark_pose`] and then [`Self::landmark_shape`].
    pub fn landmark_default(image_size: f32) -> Self {
        Self::from_shares(&MixtureShares::LANDMARK_JOINT, &DriftSettings::DEFAULT, image_size).unwrap_or_default()
    }

    /// The image chain's default ([`MixtureShares::IMAGE`]): pose 30 %, shape 25 %, colour 20 %,
    /// light 25 % (a fifth of it the least-squares light).
    pub fn image_default(image_size: f32) -> Self {
        Self::from_shares(&MixtureShares::IMAGE, &DriftSettings::DEFAULT, image_size).unwrap_or_default()
    }
}

/// `p`'s camera-space image of model point `v` (its angles' sines and cosines from `trig` where they match).
fn camera_point<const KS: usize, const KC: usize>(p: &FitParams<KS, KC>, v: Vec3, trig: Option<&PoseTrig>) -> Vec3 {
    let trig = trig.map_or_else(|| PoseTrig::of(&p.pose), |t| t.to(&p.pose));
    let q = mat_vec(&trig.rotation(), v);
    let t = p.pose.translation;
    [q[0] + t[0], q[1] + t[1], q[2] + t[2]]
}

/// The leading `leading` entries of `c` (all of them for 0).
fn leading_part(c: &mut [f32], leading: u16) -> &mut [f32] {
    let n = if leading == 0 { c.len() } else { c.len().min(usize::from(leading)) };
    c.get_mut(..n).unwrap_or(&mut [])
}

impl Proposal for StandardProposal {
    fn name(&self) -> &'static str {
        self.kind.name()
    }

    fn changes_shape(&self) -> bool {
        self.kind.changes_shape()
    }

    fn changes_geometry(&self) -> bool {
        self.kind.changes_geometry()
    }

    fn needs_light_solution(&self) -> bool {
        self.kind == ProposalKind::LightSolve
    }

    /// Draws `x'` into `out`; returns the log Hastings term (`−∞` if the move is impossible, e.g.
    /// a distance behind the camera, or needs a light solution that is missing).
    fn propose<R: Rng + ?Sized, const KS: usize, const KC: usize>(
        &self,
        current: &FitParams<KS, KC>,
        ctx: &ProposalContext,
        rng: &mut R,
        out: &mut FitParams<KS, KC>,
    ) -> f32 {
        out.clone_from(current);
        let s = self.sigma;
        match self.kind {
            ProposalKind::Yaw | ProposalKind::Pitch | ProposalKind::Roll => {
                let before = camera_point(current, ctx.pivot, ctx.trig.as_ref());
                let d = s * standard_normal(rng);
                match self.kind {
                    ProposalKind::Yaw => out.pose.yaw += d,
                    ProposalKind::Pitch => out.pose.pitch += d,
                    _ => out.pose.roll += d,
                }
                let after = camera_point(out, ctx.pivot, ctx.trig.as_ref());
                for ((t, b), a) in out.pose.translation.iter_mut().zip(before).zip(after) {
                    *t += b - a;
                }
                0.0
            }
            ProposalKind::Distance => {
                let w = -camera_point(current, ctx.pivot, ctx.trig.as_ref())[2];
                let d = s * standard_normal(rng);
                let w2 = w + d;
                if !(w > 0.0 && w2 > 0.0) {
                    return f32::NEG_INFINITY;
                }
                out.pose.translation[2] -= d;
                out.focal = current.focal * w2 / w;
                libm::logf(w2 / w)
            }
            ProposalKind::Scaling => {
                let d = s * standard_normal(rng);
                out.focal = current.focal * libm::expf(d);
                d
            }
            ProposalKind::Translation => {
                let w = -camera_point(current, ctx.pivot, ctx.trig.as_ref())[2];
                let mm_per_px = if current.focal > 0.0 { libm::fabsf(w) / current.focal } else { 0.0 };
                add_normals(rng, s * mm_per_px, out.pose.translation.get_mut(..2).unwrap_or(&mut []));
                0.0
            }
            ProposalKind::Shape => {
                add_normals(rng, s, leading_part(out.shape_coeffs_mut(), self.leading));
                0.0
            }
            ProposalKind::Color => {
                add_normals(rng, s, leading_part(out.color_coeffs_mut(), self.leading));
                0.0
            }
            ProposalKind::Light => {
                add_normals(rng, s, out.light.coeffs.as_flattened_mut());
                0.0
            }
            ProposalKind::LightIntensity => {
                let d = s * standard_normal(rng);
                let f = libm::expf(d);
                for c in out.light.coeffs.iter_mut().flatten() {
                    *c *= f;
                }
                27.0 * d
            }
            ProposalKind::LightSolve => {
                let Some(ls) = ctx.light_solution else {
                    return f32::NEG_INFINITY;
                };
                let (mut back, mut fwd) = (0.0f32, 0.0f32);
                for ((o, c), m) in
                    out.light.coeffs.iter_mut().flatten().zip(current.light.coeffs.iter().flatten()).zip(ls.coeffs.iter().flatten())
                {
                    let e = standard_normal(rng);
                    *o = m + s * e;
                    fwd += e * e;
                    back += (c - m) * (c - m);
                }
                // log N(L; L*, σ) − log N(L'; L*, σ)
                -0.5 * back / (s * s) + 0.5 * fwd
            }
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;
    use crate::fit::chain::proposal::MAX_PROPOSALS;
    use crate::render::{Pose, ShLight};
    use rand_core::SeedableRng;
    use rand_xoshiro::Xoshiro256PlusPlus;

    fn params() -> FitParams<4, 4> {
        FitParams::new(Pose { yaw: 0.2, pitch: -0.1, roll: 0.05, translation: [5.0, -3.0, -600.0] }, 500.0, ShLight::frontal(), 4, 4)
    }

    #[test]
    fn rotations_keep_the_pivot_fixed() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
        let ctx = ProposalContext { pivot: [10.0, 20.0, 30.0], light_solution: None, trig: None };
        let p = params();
        let mut out = p.clone();
        for kind in [ProposalKind::Yaw, ProposalKind::Pitch, ProposalKind::Roll] {
            let h = StandardProposal::new(kind, Scale::Coarse, 0.5).unwrap().propose(&p, &ctx, &mut rng, &mut out);
            assert_eq!(h, 0.0);
            let (a, b) = (camera_point(&p, ctx.pivot, None), camera_point(&out, ctx.pivot, None));
            for i in 0..3 {
                assert!((a[i] - b[i]).abs() < 1e-3, "{kind:?} {a:?} {b:?}");
            }
            assert_ne!(out.pose, p.pose);
        }
    }

    #[test]
    fn leading_blocks_move_only_the_leading_coefficients() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(5);
        let ctx = ProposalContext { pivot: [0.0; 3], light_solution: None, trig: None };
        let p = params();
        for kind in [ProposalKind::Shape, ProposalKind::Color] {
            let coeffs =
                |q: &FitParams<4, 4>| if kind == ProposalKind::Shape { q.shape_coeffs().to_vec() } else { q.color_coeffs().to_vec() };
            let mut out = p.clone();
            let prop = StandardProposal::new(kind, Scale::Coarse, 0.5).unwrap().with_leading(2);
            assert_eq!(prop.propose(&p, &ctx, &mut rng, &mut out), 0.0);
            let (a, b) = (coeffs(&p), coeffs(&out));
            assert!(a[..2].iter().zip(&b[..2]).all(|(x, y)| x != y), "{kind:?}: {b:?}");
            assert_eq!(a[2..], b[2..], "{kind:?}");
            // 0 moves all of them; more than the active ones moves all of them too.
            for leading in [0, 9] {
                let prop = StandardProposal::new(kind, Scale::Coarse, 0.5).unwrap().with_leading(leading);
                prop.propose(&p, &ctx, &mut rng, &mut out);
                assert!(coeffs(&p).iter().zip(coeffs(&out)).all(|(x, y)| *x != y), "{kind:?} leading {leading}");
            }
        }
        // The mixture carries the settings' blocks per step class.
        let mut drift = DriftSettings::DEFAULT;
        drift.shape_leading = [10, 40, 0];
        let m = Mixture::from_shares(&MixtureShares::IMAGE, &drift, 128.0).unwrap();
        let blocks: Vec<u16> = m.entries().iter().filter(|e| e.proposal.kind == ProposalKind::Shape).map(|e| e.proposal.leading).collect();
        assert_eq!(blocks, [10, 40, 0]);
    }

    #[test]
    fn distance_keeps_image_scale_and_reports_jacobian() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(4);
        let ctx = ProposalContext { pivot: [0.0; 3], light_solution: None, trig: None };
        let p = params();
        let mut out = p.clone();
        let h = StandardProposal::new(ProposalKind::Distance, Scale::Coarse, 50.0).unwrap().propose(&p, &ctx, &mut rng, &mut out);
        let (w, w2) = (-p.pose.translation[2], -out.pose.translation[2]);
        assert!((out.focal / w2 - p.focal / w).abs() < 1e-4);
        assert!((h - libm::logf(w2 / w)).abs() < 1e-5);
    }

    #[test]
    fn landmark_phases_split_pose_and_shape() {
        let has = |m: &Mixture, k: ProposalKind| m.entries().iter().any(|e| e.proposal.kind == k && e.weight > 0.0);
        let pose = Mixture::landmark_pose(128.0);
        for k in [ProposalKind::Yaw, ProposalKind::Pitch, ProposalKind::Roll, ProposalKind::Scaling, ProposalKind::Translation] {
            assert!(has(&pose, k), "pose phase lacks {}", k.name());
        }
        assert!(!has(&pose, ProposalKind::Shape) && !has(&pose, ProposalKind::Distance));
        let shape = Mixture::landmark_shape(128.0);
        assert!(has(&shape, ProposalKind::Shape) && has(&shape, ProposalKind::Pitch));
        // Yaw and distance are what the landmarks trade for shape: the shape phase holds them.
        assert!(!has(&shape, ProposalKind::Yaw) && !has(&shape, ProposalKind::Distance));
        let share: f32 = shape.entries().iter().filter(|e| e.proposal.kind == ProposalKind::Shape).map(|e| e.weight).sum();
        assert!((share / shape.total_weight() - 0.6 / 0.99).abs() < 1e-4, "{share}");
    }

    /// The mixtures as they were written out before they became settings: same components,
    /// same order, same σ's and weights bit for bit (the fits depend on every one).
    #[test]
    fn presets_from_settings_match_the_written_out_mixtures() {
        fn push3(m: &mut Vec<(ProposalKind, Scale, f32, f32)>, kind: ProposalKind, sigmas: [f32; 3], weights: [f32; 3], share: f32) {
            let sum: f32 = weights.iter().sum();
            for ((s, w), scale) in sigmas.iter().zip(weights).zip([Scale::Coarse, Scale::Intermediate, Scale::Fine]) {
                m.push((kind, scale, *s, share * w / sum));
            }
        }
        fn pose(m: &mut Vec<(ProposalKind, Scale, f32, f32)>, px: f32, share: f32, yaw: bool, distance: bool) {
            let (rot_w, rot_s) = ([0.1, 0.4, 0.5], [0.75, 0.10, 0.01]);
            if yaw {
                push3(m, ProposalKind::Yaw, rot_s, rot_w, 0.3 * share);
            }
            push3(m, ProposalKind::Pitch, rot_s, rot_w, 0.2 * share);
            push3(m, ProposalKind::Roll, rot_s, rot_w, 0.1 * share);
            if distance {
                push3(m, ProposalKind::Distance, [200.0, 50.0, 5.0], [0.2, 0.6, 0.2], 0.05 * share);
            }
            push3(m, ProposalKind::Scaling, [0.15, 0.05, 0.01], [0.2, 0.6, 0.2], 0.15 * share);
            let px = px.max(1.0);
            push3(m, ProposalKind::Translation, [0.1 * px, 0.02 * px, 0.004 * px], [0.2, 0.2, 0.6], 0.2 * share);
        }
        let shape = |m: &mut Vec<_>, share| push3(m, ProposalKind::Shape, [0.2, 0.1, 0.025], [0.1, 0.5, 0.2], share);
        let flat = |m: &Mixture| -> Vec<(ProposalKind, Scale, f32, f32)> {
            m.entries().iter().map(|e| (e.proposal.kind, e.proposal.scale, e.proposal.sigma, e.weight)).collect()
        };
        for px in [128.0f32, 256.0, 97.0] {
            let mut lm_pose = Vec::new();
            pose(&mut lm_pose, px, 1.0, true, false);
            assert_eq!(flat(&Mixture::landmark_pose(px)), lm_pose);
            let mut lm_shape = Vec::new();
            shape(&mut lm_shape, 0.6);
            pose(&mut lm_shape, px, 0.6, false, false);
            assert_eq!(flat(&Mixture::landmark_shape(px)), lm_shape);
            let mut joint = Vec::new();
            pose(&mut joint, px, 0.7, true, true);
            shape(&mut joint, 0.3);
            assert_eq!(flat(&Mixture::landmark_default(px)), joint);
            let mut image = Vec::new();
            pose(&mut image, px, 0.3, true, true);
            shape(&mut image, 0.25);
            push3(&mut image, ProposalKind::Color, [0.2, 0.1, 0.025], [0.1, 0.5, 0.2], 0.2);
            push3(&mut image, ProposalKind::Light, [0.05, 0.01, 0.002], [0.2, 0.5, 0.3], 0.12);
            image.push((ProposalKind::LightIntensity, Scale::Intermediate, 0.05, 0.08));
            image.push((ProposalKind::LightSolve, Scale::Fine, 0.02, 0.05));
            let m = Mixture::image_default(px);
            assert_eq!(flat(&m), image);
            let total: f32 = image.iter().map(|e| e.3).fold(0.0, |a, w| a + w);
            assert_eq!(m.total_weight().to_bits(), total.to_bits());
        }
    }

    #[test]
    fn light_solve_without_solution_is_impossible_and_mixture_chooses_by_weight() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(5);
        let ctx = ProposalContext { pivot: [0.0; 3], light_solution: None, trig: None };
        let p = params();
        let mut out = p.clone();
        let pr = StandardProposal::new(ProposalKind::LightSolve, Scale::Fine, 0.1).unwrap();
        assert!(pr.needs_light_solution());
        assert_eq!(pr.propose(&p, &ctx, &mut rng, &mut out), f32::NEG_INFINITY);
        let mut m = Mixture::new();
        m.push(pr, 1.0).unwrap();
        m.push(pr, 3.0).unwrap();
        assert_eq!(m.choose(0.2), Some(0));
        assert_eq!(m.choose(0.3), Some(1));
        assert_eq!(m.choose(0.9999), Some(1));
        assert!(m.push_standard(ProposalKind::Shape, Scale::Fine, -1.0, 1.0).is_err());
        assert_eq!(m.push(pr, f32::NAN).err().map(|e| e.proposal), Some(pr));
        assert_eq!(Mixture::<StandardProposal>::new().choose(0.5), None);
        let mut full = Mixture::new();
        for _ in 0..MAX_PROPOSALS {
            full.push(pr, 1.0).unwrap();
        }
        // A full mixture hands the component back.
        assert_eq!(full.push(pr, 2.0).err().map(|e| e.weight), Some(2.0));
        assert!(Mixture::image_default(128.0).entries().len() <= MAX_PROPOSALS);
        assert!(Mixture::landmark_default(128.0).total_weight() > 0.99);
    }
}
