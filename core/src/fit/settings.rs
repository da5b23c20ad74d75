//! The settings of the standard fit in one type: what the CLI, the host, the fit input and the
//! firmware all use. Flat fields for the step counts, ranks and σ's; groups for the proposal
//! mixtures ([`ProposalSettings`]) and the light ([`LightSettings`]). Every knob the standard fit
//! used to hard-code is here, with its old value as the default.

use crate::error::FitError;
use crate::fit::likelihood::image::DEFAULT_PIXEL_SIGMA;
use crate::fit::likelihood::occlusion::OcclusionSettings;
use crate::fit::solve::light::LightSolveConfig;
use crate::geometry::Vec3;
use crate::render::ShLight;

/// Landmark σ (fraction of the fit's image side) for landmarks read by the initializer of a
/// landmark-free fit (`gpmm fit --init`, `gpmm device-fit --init`): looser than a face-mesh
/// detector's default, as its points are (chosen on the Mitsuba development set: median |yaw
/// error| 3.14° at the default 0.005, 2.56° at 0.015, 3.06° at 0.03; docs/evaluation.md,
/// "Landmark-free start").
pub const INIT_LANDMARK_SIGMA: f32 = 0.015;

/// The landmark chain's pose share where the chains fit the shape themselves (no start solve:
/// the m4f's landmark-free fit; [`FitSettings::without_shape_solve`]): 40 % pose, 60 % shape.
pub const CHAIN_SHAPE_POSE_SHARE: f32 = 0.4;

/// Settings of [`crate::fit::standard_fit`] (defaults: the documented default fit), in groups: the
/// landmark chain, the image chain, the ranks fitted, the start, the proposal mixtures and the
/// light solves.
///
/// # Examples
///
/// ```
/// use gpmm_core::error::FitError;
/// use gpmm_core::fit::FitSettings;
///
/// // The default fit with shorter chains, without the start's shape solve (as a device runs it)
/// // and with 50 shape components and no colour.
/// let settings = FitSettings::DEFAULT.with_steps(1000, 100).without_shape_solve().with_ranks(50, 0);
/// assert_eq!((settings.landmarks.steps, settings.image.steps, settings.start.shape_rounds), (1000, 100, 0));
/// assert_eq!((settings.ranks.shape, settings.ranks.color), (50, 0));
/// // Without the solve the chains fit the shape: the landmark chain gives it part of its steps.
/// assert!(settings.landmarks.pose_share < 1.0 && settings.proposals.image.shape > 0.0);
/// assert_eq!(settings.validate(), Ok(()));
///
/// // A setting out of range is refused before anything runs.
/// let mut bad = settings;
/// bad.image.pixel_sigma = 0.0;
/// assert_eq!(bad.validate(), Err(FitError::BadConfig));
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FitSettings {
    /// The landmark chain and the landmark term.
    pub landmarks: LandmarkSettings,
    /// The image chain and the image likelihood.
    pub image: ImageSettings,
    /// How many components are fitted.
    pub ranks: RankSettings,
    /// The start of the landmark chain.
    pub start: StartSettings,
    /// The proposal mixtures of the landmark chain's two phases and of the image chain.
    pub proposals: ProposalSettings,
    /// The start light and the least-squares light solves.
    pub light: LightSettings,
    /// The labels of what the face does not explain (occluders), inferred during the fit.
    pub occlusion: OcclusionSettings,
}

/// The landmark chain and the landmark term.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LandmarkSettings {
    /// Landmark-chain steps, both phases: the first [`Self::pose_share`] of them move the pose, the
    /// rest the shape.
    pub steps: u32,
    /// Fraction of the landmark steps spent on the pose phase (0 to 1; the rest fit the shape
    /// with yaw and distance held).
    pub pose_share: f32,
    /// Leading landmarks that follow the face's silhouette (17 for iBUG-68: the jaw contour);
    /// only used when the model has exactly 68 landmarks.
    pub contour_landmarks: usize,
    /// σ factor of the contour landmarks in the pose phase (their 3-D definition is view
    /// dependent, so they say less about the pose than the inner points).
    pub contour_sigma_factor: f32,
    /// Landmark σ as a fraction of the larger image side (0.005: 0.64 px at 128; 1.5 % left 5 %
    /// inter-ocular landmark error on synthetic faces).
    pub sigma: f32,
    /// Degrees of freedom of a Student-t landmark term (0: Gaussian); small values let a few
    /// wrong detector points go.
    pub student_t: f32,
    /// Whether the contour landmarks follow the model's silhouette ([`crate::fit::likelihood::contour`]) instead
    /// of fixed vertices.
    pub silhouette: bool,
    /// After the pose phase, contour landmarks whose model vertex faces away from the camera
    /// (cosine between its normal and the direction to the camera below this) are left out of
    /// the shape solve and the image chain: a detector puts them on the visible outline. −1 or
    /// less keeps all. 0 (the default) removed the 30–45° frontal pull with exact and detector
    /// landmarks on the development set (docs/evaluation.md, "Fitting accuracy", "What did not help").
    pub hidden_contour_min_cos: f32,
}

impl LandmarkSettings {
    /// The settings for landmarks read by the initializer of a landmark-free fit (`gpmm fit
    /// --init`, `gpmm device-fit --init`) with σ `sigma`: every contour point kept after the pose
    /// phase, since the initializer learned the contour vertices' projections (hidden or not),
    /// not the visible outline a detector marks (development set, the initializer's points:
    /// median |yaw error| 3.10° with the turned-away points left out, 2.71° kept;
    /// docs/evaluation.md, "Landmark-free start").
    pub const fn for_initializer(self, sigma: f32) -> Self {
        Self { sigma, hidden_contour_min_cos: -1.0, ..self }
    }
}

/// The image chain and the image likelihood.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ImageSettings {
    /// Image-chain steps (each renders the model at most once).
    pub steps: u32,
    /// How many of [`Self::steps`] come first at half the working resolution (the target's 2 × 2
    /// block means, a quarter of the pixels to render and compare); the rest at full resolution
    /// from the best sample of those (0: none).
    pub coarse_steps: u32,
    /// Foreground σ of the image likelihood on [0, 1] colours.
    pub pixel_sigma: f32,
    /// Uniform floor mixed into the background colour histogram.
    pub background_floor: f32,
    /// Colour-and-light rounds (as [`StartSettings::color_rounds`]) on the image chain's best
    /// sample, kept if its log posterior is higher (0: none).
    pub color_polish_rounds: u32,
    /// Factor on the landmark σ in the image chain (> 0; 1: the landmark chain's σ). Large values
    /// leave the landmarks to the start alone (the pose chain and the shape solve), the image
    /// chain then following the image.
    pub landmark_sigma_factor: f32,
}

/// How many of the model's components are fitted (the leading ones; capped by the model's rank
/// and the coefficient capacities `KS`, `KC`).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RankSettings {
    /// Shape components. All of a default model's 200: on synthetic ICT faces (three seeds, 52
    /// faces each) 50 components left 3.5 % inter-ocular landmark error and compressed yaw (the
    /// template's jaw-corner landmarks sit up to 20 mm deeper than ICT's mean face); 200 gave
    /// 2.8 % and a median yaw error of 2°, for about 15 % more time per fit.
    pub shape: usize,
    /// Colour components.
    pub color: usize,
}

/// The starts of the chains: the landmark chain's distance, the image chain's colour and light solve.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StartSettings {
    /// Distance of the start pose (mm); the start focal length is chosen to match it.
    pub nominal_distance_mm: f32,
    /// Rounds of the image chain's start solve: each solves the colour coefficients for the
    /// light, then the light for the colour (0: the light alone, colour coefficients zero).
    pub color_rounds: u32,
    /// Vertex stride of the colour solve (≥ 1).
    pub color_stride: usize,
    /// Pixels a sampled vertex stands for in the colour solve's data term (> 0).
    pub color_weight: f32,
    /// Conjugate-gradient iterations of one colour solve.
    pub color_iterations: u32,
    /// Rounds of the start's shape solve (after the colour rounds): each moves the leading shape
    /// components by Gauss–Newton on the image ([`crate::fit::solve::shape`]), then solves the light and
    /// (with colour rounds) the colour again.
    pub shape_rounds: u32,
    /// Leading shape components the shape solve moves (at most [`crate::fit::solve::shape::MAX_SHAPE_SOLVE`]).
    pub shape_components: usize,
    /// Gauss–Newton iterations of one shape solve.
    pub shape_iterations: u32,
    /// Vertex stride of the shape solve (≥ 1).
    pub shape_stride: usize,
    /// Minimum cosine between a sampled vertex's normal and the direction to the camera in the
    /// shape solve (in [−1, 1)): grazing vertices (near the outline, where the image shows hair,
    /// ears or background and a pixel's error is large) are left out.
    pub shape_min_cos: f32,
    /// Pixels a sampled vertex stands for in the shape solve's data term (> 0). Small (0.003):
    /// the landmark term leads the solve and the image refines it (chosen on the development set,
    /// docs/evaluation.md, "Fitting accuracy", "What did not help").
    pub shape_weight: f32,
    /// Whether the shape solve's objective has the landmark term (Gaussian, the chain's σ).
    pub shape_landmarks: bool,
    /// Whether the shape solve moves the pose (yaw, pitch, roll, translation) with the shape.
    pub shape_pose: bool,
}

impl StartSettings {
    /// Start at 500 mm; no colour solve; two shape-solve rounds (64 components, weight 0.05, the
    /// landmark term, the pose held, vertices facing the camera within ~37° (cosine 0.8): see
    /// docs/evaluation.md for what each did on the test set). A device turns them off.
    pub const DEFAULT: Self = Self {
        nominal_distance_mm: 500.0,
        color_rounds: 0,
        color_stride: 2,
        color_weight: 1.0,
        color_iterations: 12,
        shape_rounds: 2,
        shape_components: 64,
        shape_iterations: 3,
        shape_stride: 2,
        shape_min_cos: 0.8,
        shape_weight: 0.003,
        shape_landmarks: true,
        shape_pose: false,
    };
}

impl FitSettings {
    /// The default fit: 5000 landmark steps on the pose (contour σ × 3), the start's shape solve
    /// (the shape), 600 image steps without shape moves, 200 shape and 50 colour components,
    /// landmark σ 0.5 % of the image side, pixel σ 0.043, background floor 0.01, start at 500 mm;
    /// the default mixtures and light. Without the solve (a device) see [`Self::without_shape_solve`].
    pub const DEFAULT: Self = Self {
        landmarks: LandmarkSettings {
            steps: 5000,
            pose_share: 1.0,
            contour_landmarks: 17,
            contour_sigma_factor: 3.0,
            sigma: 0.005,
            student_t: 0.0,
            silhouette: false,
            hidden_contour_min_cos: 0.0,
        },
        image: ImageSettings {
            steps: 600,
            coarse_steps: 0,
            pixel_sigma: DEFAULT_PIXEL_SIGMA,
            background_floor: 0.01,
            color_polish_rounds: 0,
            landmark_sigma_factor: 1.0,
        },
        ranks: RankSettings { shape: 200, color: 50 },
        start: StartSettings::DEFAULT,
        proposals: ProposalSettings::DEFAULT,
        light: LightSettings::DEFAULT,
        occlusion: OcclusionSettings::OFF,
    };

    /// A device's default fit (`gpmm device-fit`): [`Self::DEFAULT`] in under a third of the
    /// instructions (0.36 × 10⁹ against 1.2 × 10⁹ on the m4f, the astronaut and a 16-bit blob):
    /// 1000 landmark steps (past 1000 the image chain's pose did not improve), one shape-solve
    /// round of two iterations on every fourth vertex, and 330 image steps all at half resolution
    /// ([`ImageSettings::coarse_steps`]: a quarter of the pixels, the same yaw error), the pose's
    /// steps mostly fine (rotation weights 0.02 / 0.18 / 0.8, translation 0.05 / 0.25 / 0.7:
    /// most coarse pose steps fail the landmark stage). Chosen on the Mitsuba development set
    /// (docs/evaluation.md, "Instructions and memory").
    pub const DEVICE: Self = {
        let mut s = Self::DEFAULT.with_steps(1000, 330);
        s.image.coarse_steps = 330;
        s.start.shape_rounds = 1;
        s.start.shape_iterations = 2;
        s.start.shape_stride = 4;
        s.proposals.drift.rotation.weights = [0.02, 0.18, 0.8];
        s.proposals.drift.translation.weights = [0.05, 0.25, 0.7];
        s
    };

    /// A device's default landmark-free fit (`gpmm device-fit --init`): [`Self::DEVICE`] without
    /// the start's shape solve ([`Self::without_shape_solve`]: it does not fit beside the m4f's
    /// crop), with 2000 landmark steps, as its chain fits the shape too, and 310 image steps, all
    /// at half resolution, so that detection and fit stay within 0.5 × 10⁹ instructions on the
    /// m4f (development set, the device's landmark-free fit, median |yaw error| over seeds 0–2:
    /// 2.26°; 2.24° with the host's schedule).
    pub const DEVICE_FRAME: Self = {
        let mut s = Self::DEVICE.without_shape_solve().with_steps(2000, 310);
        s.image.coarse_steps = 310;
        s
    };

    /// These settings with other step counts (landmark chain, image chain).
    pub const fn with_steps(self, landmark_steps: u32, image_steps: u32) -> Self {
        let mut s = self;
        s.landmarks.steps = landmark_steps;
        s.image.steps = image_steps;
        s
    }

    /// These settings without the start's shape solve (`start.shape_rounds = 0`, as the m4f's
    /// landmark-free fit runs them: the solve does not fit beside its crop), the chains fitting
    /// the shape instead: a landmark chain that fits the pose only gets
    /// [`CHAIN_SHAPE_POSE_SHARE`], an image chain without shape moves gets [`MixtureShares::IMAGE`]'s
    /// shape share; shares that already fit the shape are kept.
    pub const fn without_shape_solve(self) -> Self {
        let mut s = self;
        s.start.shape_rounds = 0;
        if s.landmarks.pose_share >= 1.0 {
            s.landmarks.pose_share = CHAIN_SHAPE_POSE_SHARE;
        }
        if s.proposals.image.shape <= 0.0 {
            s.proposals.image.shape = MixtureShares::IMAGE.shape;
        }
        s
    }

    /// These settings with an image chain of `image_steps` steps that fits the shape as well
    /// (with [`MixtureShares::IMAGE`]'s shape share unless it already does): the shape then
    /// answers to the pixels, not to the landmarks alone, as the learning loop's fits need.
    pub const fn with_image_shape(self, image_steps: u32) -> Self {
        let mut s = self;
        s.image.steps = image_steps;
        if s.proposals.image.shape <= 0.0 {
            s.proposals.image.shape = MixtureShares::IMAGE.shape;
        }
        s
    }

    /// These settings with other ranks (shape and colour components fitted).
    pub const fn with_ranks(self, shape: usize, color: usize) -> Self {
        let mut s = self;
        s.ranks = RankSettings { shape, color };
        s
    }

    /// Checks every group (σ's and factors > 0 and finite, distance > 0, pose share in [0, 1],
    /// mixtures and light); `BadConfig` otherwise.
    pub fn validate(&self) -> Result<(), FitError> {
        let positive = |v: f32| v > 0.0 && v.is_finite();
        let (l, i) = (&self.landmarks, &self.image);
        if positive(l.sigma)
            && positive(i.pixel_sigma)
            && positive(i.landmark_sigma_factor)
            && l.hidden_contour_min_cos.is_finite()
            && positive(l.sigma * i.landmark_sigma_factor)
            && positive(self.start.nominal_distance_mm)
            && self.start.color_stride >= 1
            && positive(self.start.color_weight)
            && self.start.shape_stride >= 1
            && (-1.0..1.0).contains(&self.start.shape_min_cos)
            && positive(self.start.shape_weight)
            && self.start.shape_components <= crate::fit::solve::shape::MAX_SHAPE_SOLVE
            && positive(l.contour_sigma_factor)
            && i.background_floor >= 0.0
            && (0.0..=1.0).contains(&l.pose_share)
            && (l.student_t == 0.0 || positive(l.student_t))
        {
            self.proposals.validate()?;
            self.occlusion.validate()?;
            self.light.validate()
        } else {
            Err(FitError::BadConfig)
        }
    }
}

/// `Ok` when a group's checks hold, else [`FitError::BadConfig`].
fn config_ok(ok: bool) -> Result<(), FitError> {
    if ok {
        Ok(())
    } else {
        Err(FitError::BadConfig)
    }
}

impl Default for FitSettings {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Coarse, intermediate and fine steps of one proposal kind: σ's and relative weights.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Drift {
    /// σ of the coarse, intermediate and fine steps (units per proposal kind).
    pub sigmas: [f32; 3],
    /// Their relative weights (normalized within the kind).
    pub weights: [f32; 3],
}

impl Drift {
    fn validate(&self) -> Result<(), FitError> {
        let sum: f32 = self.weights.iter().sum();
        let ok = self.sigmas.iter().all(|s| *s > 0.0 && s.is_finite())
            && self.weights.iter().all(|w| *w >= 0.0 && w.is_finite())
            && sum > 0.0
            && sum.is_finite();
        config_ok(ok)
    }
}

/// The step sizes of every built-in proposal kind, shared by all mixtures.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DriftSettings {
    /// Yaw, pitch and roll (radians).
    pub rotation: Drift,
    /// Distance (mm).
    pub distance: Drift,
    /// Focal-length scaling (log units).
    pub scaling: Drift,
    /// Translation, σ as a fraction of the larger image side.
    pub translation: Drift,
    /// Shape coefficients.
    pub shape: Drift,
    /// Colour coefficients.
    pub color: Drift,
    /// SH light coefficients.
    pub light: Drift,
    /// σ of the light-intensity proposal (log units).
    pub light_intensity_sigma: f32,
    /// σ of the least-squares light proposal around the solved light.
    pub light_solve_sigma: f32,
    /// Fractions of a mixture's pose share: yaw, pitch, roll, distance, scaling, translation.
    pub pose_fractions: [f32; 6],
    /// How many leading shape coefficients the coarse, intermediate and fine shape steps move (0: all).
    pub shape_leading: [u16; 3],
    /// How many leading colour coefficients the coarse, intermediate and fine colour steps move (0: all).
    pub color_leading: [u16; 3],
}

impl DriftSettings {
    /// The step sizes of scalismo-faces' standard fit as gpmm uses them.
    pub const DEFAULT: Self = Self {
        rotation: Drift { sigmas: [0.75, 0.10, 0.01], weights: [0.1, 0.4, 0.5] },
        distance: Drift { sigmas: [200.0, 50.0, 5.0], weights: [0.2, 0.6, 0.2] },
        scaling: Drift { sigmas: [0.15, 0.05, 0.01], weights: [0.2, 0.6, 0.2] },
        translation: Drift { sigmas: [0.1, 0.02, 0.004], weights: [0.2, 0.2, 0.6] },
        shape: Drift { sigmas: [0.2, 0.1, 0.025], weights: [0.1, 0.5, 0.2] },
        color: Drift { sigmas: [0.2, 0.1, 0.025], weights: [0.1, 0.5, 0.2] },
        light: Drift { sigmas: [0.05, 0.01, 0.002], weights: [0.2, 0.5, 0.3] },
        light_intensity_sigma: 0.05,
        light_solve_sigma: 0.02,
        pose_fractions: [0.3, 0.2, 0.1, 0.05, 0.15, 0.2],
        shape_leading: [0; 3],
        color_leading: [0; 3],
    };

    fn validate(&self) -> Result<(), FitError> {
        for d in [&self.rotation, &self.distance, &self.scaling, &self.translation, &self.shape, &self.color, &self.light] {
            d.validate()?;
        }
        let positive = |v: f32| v > 0.0 && v.is_finite();
        config_ok(
            positive(self.light_intensity_sigma)
                && positive(self.light_solve_sigma)
                && self.pose_fractions.iter().all(|f| *f >= 0.0 && f.is_finite()),
        )
    }
}

/// The shares of one mixture (unnormalized weights; a share of 0 leaves the kind out).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MixtureShares {
    /// The pose's share, split by [`DriftSettings::pose_fractions`].
    pub pose: f32,
    /// Whether the pose part includes yaw.
    pub yaw: bool,
    /// Whether the pose part includes distance changes.
    pub distance: bool,
    /// The shape's share.
    pub shape: f32,
    /// Whether the shape components come before the pose ones (the order matters for which
    /// component a uniform draw picks, so it is part of the mixture).
    pub shape_first: bool,
    /// The colour's share.
    pub color: f32,
    /// The additive SH light's share.
    pub light: f32,
    /// The light-intensity proposal's weight.
    pub light_intensity: f32,
    /// The least-squares light proposal's weight.
    pub light_solve: f32,
}

impl MixtureShares {
    /// Nothing: every share 0.
    pub const NONE: Self = Self {
        pose: 0.0,
        yaw: false,
        distance: false,
        shape: 0.0,
        shape_first: false,
        color: 0.0,
        light: 0.0,
        light_intensity: 0.0,
        light_solve: 0.0,
    };

    /// The landmark chain's pose phase: rotation, scaling and translation; no distance, no shape.
    pub const LANDMARK_POSE: Self = Self { pose: 1.0, yaw: true, ..Self::NONE };

    /// The landmark chain's shape phase: shape 60 %, the pose without yaw and distance 60 %.
    pub const LANDMARK_SHAPE: Self = Self { pose: 0.6, shape: 0.6, shape_first: true, ..Self::NONE };

    /// A joint landmark mixture: the whole pose 70 %, shape 30 %.
    pub const LANDMARK_JOINT: Self = Self { pose: 0.7, yaw: true, distance: true, shape: 0.3, ..Self::NONE };

    /// The image chain after the start's shape solve ([`ProposalSettings::DEFAULT`]): no shape
    /// moves (the solve fits the shape; the chain's random shape moves added no identity and made
    /// it depend on the seed, docs/evaluation.md, "Fitting accuracy"); the other
    /// shares of [`Self::IMAGE`].
    pub const IMAGE_AFTER_SOLVE: Self = Self { shape: 0.0, ..Self::IMAGE };

    /// The image chain that fits the shape itself (no start solve, as on a device): pose 30 %,
    /// shape 25 %, colour 20 %, light 25 % (a fifth of it the least-squares light).
    pub const IMAGE: Self = Self {
        pose: 0.3,
        yaw: true,
        distance: true,
        shape: 0.25,
        shape_first: false,
        color: 0.2,
        light: 0.12,
        light_intensity: 0.08,
        light_solve: 0.05,
    };

    fn validate(&self) -> Result<(), FitError> {
        let shares = [self.pose, self.shape, self.color, self.light, self.light_intensity, self.light_solve];
        config_ok(shares.iter().all(|s| *s >= 0.0 && s.is_finite()) && shares.iter().any(|s| *s > 0.0))
    }
}

/// The proposal mixtures of the standard fit.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ProposalSettings {
    /// The landmark chain's pose phase.
    pub landmark_pose: MixtureShares,
    /// The landmark chain's shape phase.
    pub landmark_shape: MixtureShares,
    /// The image chain.
    pub image: MixtureShares,
    /// Step sizes shared by the three.
    pub drift: DriftSettings,
}

impl ProposalSettings {
    /// The standard fit's mixtures.
    pub const DEFAULT: Self = Self {
        landmark_pose: MixtureShares::LANDMARK_POSE,
        landmark_shape: MixtureShares::LANDMARK_SHAPE,
        image: MixtureShares::IMAGE_AFTER_SOLVE,
        drift: DriftSettings::DEFAULT,
    };

    /// Checks every share and step size.
    pub fn validate(&self) -> Result<(), FitError> {
        self.landmark_pose.validate()?;
        self.landmark_shape.validate()?;
        self.image.validate()?;
        self.drift.validate()
    }
}

/// The light: the start light and the least-squares solves (the image chain's start light on
/// every `start_stride`-th vertex; the light-solve proposal on every `solve_stride`-th).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LightSettings {
    /// Ambient RGB irradiance of the start light (before the landmark chain).
    pub start_ambient: Vec3,
    /// Vertex stride of the light solved for the image chain's start (≥ 1).
    pub start_stride: usize,
    /// Vertex stride of the least-squares light proposal (≥ 1; its offset is drawn per use).
    pub solve_stride: usize,
    /// Minimum cosine between a sampled vertex's normal and the direction to the camera.
    pub min_cos: f32,
    /// Ridge weight per sample toward the ridge light.
    pub lambda: f32,
    /// Ambient RGB irradiance of the light the ridge pulls toward.
    pub ridge_ambient: Vec3,
}

impl LightSettings {
    /// Start at ambient 0.8; the start light on every vertex, the proposal on every 7th; cosine
    /// ≥ 0.2, ridge 1e-3 toward ambient 0.8.
    pub const DEFAULT: Self =
        Self { start_ambient: [0.8; 3], start_stride: 1, solve_stride: 7, min_cos: 0.2, lambda: 1e-3, ridge_ambient: [0.8; 3] };

    /// Checks strides ≥ 1, a finite cosine, a finite ridge ≥ 0 and finite ambient colours.
    pub fn validate(&self) -> Result<(), FitError> {
        let finite3 = |v: &Vec3| v.iter().all(|c| c.is_finite());
        config_ok(
            self.start_stride >= 1
                && self.solve_stride >= 1
                && self.min_cos.is_finite()
                && self.lambda >= 0.0
                && self.lambda.is_finite()
                && finite3(&self.start_ambient)
                && finite3(&self.ridge_ambient),
        )
    }

    /// The start light: ambient [`Self::start_ambient`].
    pub fn start_light(&self) -> ShLight {
        ShLight::ambient(self.start_ambient)
    }

    /// The least-squares solve on every `stride`-th vertex from offset 0.
    pub fn solve_config(&self, stride: usize) -> LightSolveConfig {
        LightSolveConfig { stride, offset: 0, min_cos: self.min_cos, lambda: self.lambda, mean: ShLight::ambient(self.ridge_ambient) }
    }
}

impl Default for LightSettings {
    fn default() -> Self {
        Self::DEFAULT
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn without_the_solve_the_chains_fit_the_shape() {
        let d = FitSettings::DEFAULT;
        // The host's default: the solve fits the shape, the chains do not.
        assert!(d.start.shape_rounds > 0 && d.landmarks.pose_share >= 1.0 && d.proposals.image.shape == 0.0);
        let device = d.without_shape_solve();
        assert_eq!(device.start.shape_rounds, 0);
        assert_eq!(device.landmarks.pose_share, CHAIN_SHAPE_POSE_SHARE);
        assert_eq!(device.proposals.image, MixtureShares::IMAGE);
        assert_eq!(device.validate(), Ok(()));
        // Shares that already fit the shape stay as they were.
        let mut own = d;
        own.landmarks.pose_share = 0.7;
        own.proposals.image.shape = 0.1;
        let kept = own.without_shape_solve();
        assert_eq!((kept.landmarks.pose_share, kept.proposals.image.shape), (0.7, 0.1));
    }

    #[test]
    fn a_devices_defaults_are_the_hosts_recipe_on_a_shorter_schedule() {
        let (host, device, frame) = (FitSettings::DEFAULT, FitSettings::DEVICE, FitSettings::DEVICE_FRAME);
        for s in [device, frame] {
            assert_eq!(s.validate(), Ok(()));
            // Every image step at half resolution, fewer steps than the host's.
            assert!(s.image.coarse_steps == s.image.steps && s.image.steps < host.image.steps);
            assert!(s.landmarks.steps < host.landmarks.steps);
            // The likelihood, ranks and light are the host's.
            assert_eq!(
                (s.image.pixel_sigma, s.ranks, s.light, s.occlusion),
                (host.image.pixel_sigma, host.ranks, host.light, host.occlusion)
            );
        }
        assert_eq!(host.image.coarse_steps, 0, "the host's default fit keeps full resolution");
        assert!(device.start.shape_rounds > 0 && device.start.shape_rounds < host.start.shape_rounds);
        // Without landmarks the chains fit the shape: no solve, a longer landmark chain.
        assert_eq!(frame.start.shape_rounds, 0);
        assert!(frame.landmarks.pose_share < 1.0 && frame.landmarks.steps > device.landmarks.steps);
    }

    #[test]
    fn the_image_chain_can_fit_the_shape_too() {
        let d = FitSettings::DEFAULT;
        let s = d.with_image_shape(10_000);
        assert_eq!((s.image.steps, s.proposals.image.shape), (10_000, MixtureShares::IMAGE.shape));
        // The start's solve and the landmark chain are as they were.
        assert_eq!((s.start, s.landmarks), (d.start, d.landmarks));
        assert_eq!(s.validate(), Ok(()));
        let mut own = d;
        own.proposals.image.shape = 0.1;
        assert_eq!(own.with_image_shape(50).proposals.image.shape, 0.1);
    }

    #[test]
    fn settings_are_checked() {
        assert_eq!(FitSettings::DEFAULT.validate(), Ok(()));
        let d = FitSettings::DEFAULT;
        let bad = [
            FitSettings { landmarks: LandmarkSettings { pose_share: 1.5, ..d.landmarks }, ..d },
            FitSettings { landmarks: LandmarkSettings { pose_share: -0.1, ..d.landmarks }, ..d },
            FitSettings { landmarks: LandmarkSettings { pose_share: f32::NAN, ..d.landmarks }, ..d },
            FitSettings { landmarks: LandmarkSettings { contour_sigma_factor: 0.0, ..d.landmarks }, ..d },
            FitSettings { landmarks: LandmarkSettings { contour_sigma_factor: f32::INFINITY, ..d.landmarks }, ..d },
            FitSettings { landmarks: LandmarkSettings { sigma: -1.0, ..d.landmarks }, ..d },
            FitSettings { image: ImageSettings { background_floor: -0.5, ..d.image }, ..d },
            FitSettings { image: ImageSettings { landmark_sigma_factor: 0.0, ..d.image }, ..d },
            FitSettings { landmarks: LandmarkSettings { hidden_contour_min_cos: f32::NAN, ..d.landmarks }, ..d },
            FitSettings { image: ImageSettings { landmark_sigma_factor: f32::INFINITY, ..d.image }, ..d },
            FitSettings { start: StartSettings { nominal_distance_mm: 0.0, ..d.start }, ..d },
            FitSettings { start: StartSettings { color_stride: 0, ..d.start }, ..d },
            FitSettings { start: StartSettings { color_weight: f32::NAN, ..d.start }, ..d },
            FitSettings { light: LightSettings { solve_stride: 0, ..d.light }, ..d },
            FitSettings { light: LightSettings { lambda: f32::NAN, ..d.light }, ..d },
            FitSettings { proposals: ProposalSettings { image: MixtureShares::NONE, ..d.proposals }, ..d },
            FitSettings {
                proposals: ProposalSettings { image: MixtureShares { color: -1.0, ..MixtureShares::IMAGE }, ..d.proposals },
                ..d
            },
            FitSettings {
                proposals: ProposalSettings {
                    drift: DriftSettings { shape: Drift { sigmas: [0.0, 0.1, 0.1], weights: [1.0; 3] }, ..d.proposals.drift },
                    ..d.proposals
                },
                ..d
            },
        ];
        for s in bad {
            assert_eq!(s.validate(), Err(FitError::BadConfig), "{s:?}");
        }
        // The extremes of the pose share are allowed: all pose or all shape.
        assert_eq!(FitSettings { landmarks: LandmarkSettings { pose_share: 0.0, ..d.landmarks }, ..d }.validate(), Ok(()));
        assert_eq!(FitSettings { landmarks: LandmarkSettings { pose_share: 1.0, ..d.landmarks }, ..d }.validate(), Ok(()));
    }

    #[test]
    fn the_default_light_solves_are_the_old_ones() {
        let l = LightSettings::DEFAULT;
        assert_eq!(l.solve_config(l.solve_stride), LightSolveConfig::default());
        assert_eq!(l.solve_config(l.start_stride), LightSolveConfig { stride: 1, ..LightSolveConfig::default() });
        assert_eq!(l.start_light(), ShLight::ambient([0.8; 3]));
    }
}
