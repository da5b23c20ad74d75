//! The fit itself: the core's standard fit on a prepared photo, with the host's buffers, rasterizer
//! and observer, and what it gives back ([`Outcome`]).

use super::buffers::FitBuffers;
use super::error::FitRunError;
use super::input::{check_landmarks, prepare, Prepared};
use super::observe::{AcceptanceReport, HostObserver};
use super::options::{FitOptions, HostMask};
use super::params::{Params, KC, KS};
use super::posterior::PosteriorSummary;
use super::shape_spread::ShapeSpread;
use crate::gp::model::GpModel;
use crate::mesh::Mesh;
use crate::render::{Background, HostRasterizer, ImageSink};
use gpmm_core::error::FitError;
use gpmm_core::fit::{pose_spread, standard_fit, LandmarkTarget, TargetImage};
use gpmm_core::model::{MorphableModel, MAX_LANDMARKS};
use gpmm_core::render::Cull;
use image::{RgbImage, RgbaImage};
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;

fn core(stage: &'static str) -> impl Fn(FitError) -> FitRunError {
    move |error| FitRunError::Core { stage, error }
}

/// The result of [`fit_prepared`] (working-image units unless stated).
#[derive(Debug, Clone)]
pub struct Outcome {
    /// The best sample of the image chain (the fit).
    pub params: Params,
    /// The landmark-only result: the landmark chain's best sample with the least-squares light.
    pub landmark_params: Params,
    /// Landmark RMSE of the fit (px).
    pub landmark_rmse_px: f32,
    /// Landmark RMSE of the landmark-only result (px).
    pub landmark_rmse_after_landmark_chain_px: f32,
    /// Per-channel colour RMSE over covered pixels of the landmark-only result.
    pub pixel_rmse_after_landmark_chain: f32,
    /// Per-channel colour RMSE over covered pixels of the fit.
    pub pixel_rmse: f32,
    /// Log posterior of the fit (up to a constant).
    pub log_posterior: f32,
    /// Image log likelihood ratio of the fit (foreground against background).
    pub image_log_likelihood: f32,
    /// Landmark log likelihood of the fit.
    pub landmark_log_likelihood: f32,
    /// Pixels the fit covers.
    pub covered_pixels: u32,
    /// Landmark-chain counts.
    pub landmark_acceptance: AcceptanceReport,
    /// Image-chain counts.
    pub image_acceptance: AcceptanceReport,
    /// The image chain's posterior summary (its second half).
    pub posterior: PosteriorSummary,
    /// The fit's projected model landmarks.
    pub fitted_landmarks: Vec<[f32; 2]>,
    /// The fit rendered (transparent where the model does not cover).
    pub render: RgbaImage,
    /// The occlusion labels (white: occluded) and the occluded fraction of the face's pixels
    /// (`None` without occlusion rounds).
    pub occlusion: Option<(image::GrayImage, f32)>,
    /// The shape's posterior from the landmarks (`None` when they do not determine the pose).
    pub shape_spread: Option<ShapeSpread>,
    /// The vertices' spread once [`Outcome::vertex_sd_mm`] has computed it (only callers that
    /// write or measure it pay for it: about 5 % of a fit).
    vertex_sd: std::sync::OnceLock<Vec<f32>>,
    /// Seconds in the landmark chain.
    pub landmark_seconds: f64,
    /// Seconds in the light solve and the image chain.
    pub image_seconds: f64,
}

impl Outcome {
    /// Per vertex of the fitted shape (`model`'s, the model fitted), the standard deviation of its
    /// position along its normal (mm; [`ShapeSpread::vertex_sd_mm`]), computed on the first call;
    /// empty without a shape spread.
    pub fn vertex_sd_mm(&self, model: &GpModel) -> Result<&[f32], FitRunError> {
        if let Some(sd) = self.vertex_sd.get() {
            return Ok(sd);
        }
        let sd = match &self.shape_spread {
            Some(s) => s.vertex_sd_mm(model, &self.params)?,
            None => Vec::new(),
        };
        Ok(self.vertex_sd.get_or_init(|| sd))
    }
}

/// Fits `model` to a prepared photo; `progress(phase, done, total)` reports steps per chain.
pub fn fit_prepared(
    model: &GpModel,
    prepared: &Prepared,
    settings: &FitOptions,
    progress: &mut dyn FnMut(&str, u64, u64),
) -> Result<Outcome, FitRunError> {
    settings.validate()?;
    let (w, h) = (settings.size, settings.size);
    if prepared.image.dimensions() != (w, h) {
        return Err(FitRunError::Settings(format!("the prepared image is {:?}, not {w}x{h}", prepared.image.dimensions())));
    }
    let n_lm = model.landmarks.len();
    if n_lm == 0 || n_lm > MAX_LANDMARKS {
        return Err(FitRunError::Model(format!("it has {n_lm} landmarks (1 to {MAX_LANDMARKS} are needed)")));
    }
    if prepared.landmarks.len() != n_lm {
        return Err(FitRunError::Settings(format!("{} target landmarks for a model with {n_lm}", prepared.landmarks.len())));
    }
    // The shape basis at the landmarks, contiguous: every shape proposal's landmark sums read it.
    let full = morphable(model)?;
    let mut landmark_fields = vec![0.0f32; full.shape_rank() * full.landmarks().len()];
    let mm = match full.landmark_fields(&mut landmark_fields) {
        Some(()) => full.with_landmark_fields(&landmark_fields).map_err(core("landmark fields"))?,
        None => full,
    };
    let core_settings = settings.core();
    let pixels: Vec<[u8; 3]> = prepared.image.pixels().map(|p| p.0).collect();
    let target = TargetImage::new(&pixels, w, h).and_then(|t| t.with_covered(prepared.covered)).map_err(core("target image"))?;
    let valid = vec![true; n_lm];
    let mut buffers = FitBuffers::host(mm.vertices(), w, h);
    let mut inst = buffers.instance::<KS, KC>().map_err(core("instance"))?;
    let mut raster: Box<HostRasterizer> = Box::new(HostRasterizer::new());
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(settings.seed);

    // One run of the core's standard fit; the observer reports progress, splits the time and
    // counts the proposals by name.
    let mut observer = HostObserver::new(progress, core_settings.image.steps / 2);
    let mut mask: Box<HostMask> = Box::default();
    let result =
        standard_fit(&mm, target, &prepared.landmarks, &valid, &core_settings, &mut inst, &mut raster, &mut mask, &mut rng, &mut observer)
            .map_err(core("fit"))?;
    let landmark_seconds = observer.landmark_seconds;
    let image_seconds = observer.elapsed() - landmark_seconds;
    // The pose's spread from what the fit left of the landmarks (none if they do not determine it).
    let target = LandmarkTarget::new(&prepared.landmarks, &valid, 1.0).map_err(core("landmarks"))?;
    let spread = pose_spread(&mm, &result.image.best, &target, w, h).ok();
    // The shape's spread from the same residual and the coefficients' prior.
    let shape_spread =
        spread.and_then(|p| ShapeSpread::of(model, &mm, &result.image.best, &prepared.landmarks, w, h, p.residual_sigma_px).ok());
    let posterior = PosteriorSummary::of(&observer.posterior)
        .with_pose_spread(spread)
        .with_translation(result.image.best.pose.translation, spread)
        .with_shape_spread(shape_spread.as_ref());
    let (landmark_acceptance, image_acceptance) = (observer.landmark, observer.image);
    let best = result.image;
    let start = result.start;
    let start_eval = result.start_image;
    let fit = best.best;
    let img_eval = best.best_image.ok_or(FitRunError::Core { stage: "image chain", error: FitError::BadConfig })?;

    // The fit's render and landmarks.
    inst.update(&mm, &fit, w, h).map_err(core("final render"))?;
    let mut sink = ImageSink::new(w, h, Background::Transparent);
    raster.render(inst.projected(), mm.triangles(), w, h, Cull::Clockwise, &mut sink).map_err(|e| core("final render")(e.into()))?;
    let fitted_landmarks = project_landmarks(&mm, &fit, w, h)?;

    let occlusion = result.occlusion.map(|o| {
        let labels = image::GrayImage::from_fn(w, h, |x, y| image::Luma([if mask.get(x, y) { 255 } else { 0 }]));
        (labels, o.fraction())
    });

    Ok(Outcome {
        params: fit,
        landmark_params: start,
        landmark_rmse_px: best.best_landmarks.rmse(),
        landmark_rmse_after_landmark_chain_px: result.start_landmarks.rmse(),
        pixel_rmse_after_landmark_chain: start_eval.rmse(),
        pixel_rmse: img_eval.rmse(),
        log_posterior: best.best_log_posterior,
        image_log_likelihood: img_eval.log_likelihood,
        landmark_log_likelihood: best.best_landmarks.log_likelihood,
        covered_pixels: img_eval.covered,
        landmark_acceptance,
        image_acceptance,
        posterior,
        fitted_landmarks,
        render: sink.into_image(),
        occlusion,
        shape_spread,
        vertex_sd: std::sync::OnceLock::new(),
        landmark_seconds,
        image_seconds,
    })
}

/// The fitted face in camera space: the fitted instance (mm) moved by the fitted pose, with its
/// fitted albedo and the model's triangles (the frame whose points the camera projects).
pub fn camera_space_mesh(model: &GpModel, params: &Params) -> Result<Mesh, FitRunError> {
    let mut mesh =
        model.instance(params.shape_coeffs(), params.color_coeffs()).map_err(|e| FitRunError::Model(format!("instance: {e}")))?;
    for p in &mut mesh.positions {
        let q = params.pose.transform_point([p[0] as f32, p[1] as f32, p[2] as f32]);
        *p = q.map(f64::from);
    }
    Ok(mesh)
}

/// The core's view of a model.
pub fn morphable(model: &GpModel) -> Result<MorphableModel<'_>, FitRunError> {
    let shape_basis = model.shape.core_basis().map_err(|e| FitRunError::Model(format!("shape basis: {e}")))?;
    let color_basis = model.color.core_basis().map_err(|e| FitRunError::Model(format!("colour basis: {e}")))?;
    MorphableModel::new(&model.shape.mean, &model.color.mean, shape_basis, color_basis, &model.triangles, &model.landmarks)
        .map_err(|e| FitRunError::Model(format!("{e}")))
}

/// [`project_landmarks`] for a [`GpModel`] and a square `size × size` image.
pub fn project_landmarks_of(model: &GpModel, params: &Params, size: u32) -> Result<Vec<[f32; 2]>, FitRunError> {
    project_landmarks(&morphable(model)?, params, size, size)
}

/// The model landmarks of `params` projected into a `width × height` image (NaN if behind the camera).
pub fn project_landmarks(mm: &MorphableModel<'_>, params: &Params, width: u32, height: u32) -> Result<Vec<[f32; 2]>, FitRunError> {
    let mut out = vec![[0.0f32; 2]; mm.landmarks().len()];
    let n = gpmm_core::fit::project_landmarks(mm, params, width, height, &mut out).map_err(core("landmarks"))?;
    out.truncate(n);
    Ok(out)
}

/// Root-mean-square distance between two point lists (px).
pub fn rmse(a: &[[f32; 2]], b: &[[f32; 2]]) -> f32 {
    let n = a.len().min(b.len()).max(1) as f32;
    let s: f32 = a.iter().zip(b).map(|(p, q)| (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sum();
    (s / n).sqrt()
}

/// Checks in-memory landmarks (`name` stands for their source in messages) against the model and
/// the photo as a landmark file is checked, prepares the photo and fits: what `gpmm fit` does
/// after reading its files, for callers that hold the image and points already (the Python package).
///
/// # Example
///
/// A model built from a tiny closed mesh (no data files) fitted to its own mean face, rendered,
/// with its four landmarks where the render puts them:
///
/// ```
/// use gpmm_host::fit::{fit_image, FitFlags};
/// use gpmm_host::gp::kernel::ModelKernel;
/// use gpmm_host::gp::lowrank::{NystromOptions, RankSpec};
/// use gpmm_host::gp::model::{build_model, BuildOptions};
/// use gpmm_host::mesh::template::{Mesh, Provenance, Template};
/// use gpmm_host::render::{render_model, RenderSettings, View};
///
/// // An octahedron, 120 × 160 × 100 mm, each face cut in four twice; landmarks at its corners.
/// let mut positions = vec![[60.0, 0.0, 0.0], [-60.0, 0.0, 0.0], [0.0, 80.0, 0.0], [0.0, -80.0, 0.0], [0.0, 0.0, 50.0], [0.0, 0.0, -50.0]];
/// let mut triangles: Vec<[u32; 3]> = vec![[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]];
/// for _ in 0..2 {
///     let mut midpoints = std::collections::HashMap::new();
///     let mut next = Vec::new();
///     for t in &triangles {
///         let mut mid = |a: u32, b: u32| -> u32 {
///             *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
///                 let (p, q): ([f64; 3], [f64; 3]) = (positions[a as usize], positions[b as usize]);
///                 positions.push([(p[0] + q[0]) / 2.0, (p[1] + q[1]) / 2.0, (p[2] + q[2]) / 2.0]);
///                 (positions.len() - 1) as u32
///             })
///         };
///         let (ab, bc, ca) = (mid(t[0], t[1]), mid(t[1], t[2]), mid(t[2], t[0]));
///         next.extend([[t[0], ab, ca], [ab, t[1], bc], [ca, bc, t[2]], [ab, bc, ca]]);
///     }
///     triangles = next;
/// }
/// let colors = positions.iter().map(|p| [0.6 + p[0] / 300.0, 0.45, 0.35]).collect();
/// let template = Template {
///     mesh: Mesh { positions, colors, triangles },
///     landmarks: vec![0, 1, 2, 3],
///     scheme: "corners".into(),
///     provenance: Provenance { source: "octahedron".into(), scale_mm_per_unit: 1.0, ..Default::default() },
/// };
/// let build = BuildOptions {
///     kernel: ModelKernel::SymmetricFull,
///     hyperparameters: Default::default(),
///     rank_shape: RankSpec::Count(8),
///     rank_color: RankSpec::Count(4),
///     nystrom: NystromOptions { points: 60, ..Default::default() },
/// };
/// let model = build_model(&template, &build, |_, _, _| {});
///
/// // The photo: the mean face rendered at 128 × 128 (x right, y up: the top corner near the top).
/// let settings = RenderSettings { width: 128, height: 128, ..RenderSettings::default() };
/// let render = render_model(&model, &[], &[], View::default(), &settings)?;
/// let photo = image::DynamicImage::ImageRgba8(render).to_rgb8();
/// let landmarks = [[104.0, 64.0], [24.0, 64.0], [64.0, 11.0], [64.0, 117.0]];
///
/// // Short chains on a 64 × 64 working image: what the user gave, resolved into the options once.
/// let flags = FitFlags { size: Some(64), landmark_steps: Some(300), image_steps: Some(20), ..FitFlags::default() };
/// let options = flags.resolve()?;
/// let (prepared, outcome) = fit_image(&model, &photo, &landmarks, "corners", &options, &mut |_, _, _| {})?;
/// assert_eq!(prepared.image.dimensions(), (64, 64));
/// assert_eq!(outcome.fitted_landmarks.len(), 4);
/// assert!(outcome.pixel_rmse.is_finite() && outcome.landmark_rmse_px.is_finite());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn fit_image(
    model: &GpModel,
    photo: &RgbImage,
    points: &[[f32; 2]],
    name: &str,
    settings: &FitOptions,
    progress: &mut dyn FnMut(&str, u64, u64),
) -> Result<(Prepared, Outcome), FitRunError> {
    settings.validate()?;
    check_landmarks(model)?;
    let path = std::path::Path::new(name);
    if let Some(i) = points.iter().position(|p| !(p[0].is_finite() && p[1].is_finite())) {
        return Err(FitRunError::Settings(format!("{name}: landmark {i} is not finite")));
    }
    let pts = crate::photo::pts::Pts { points: points.to_vec(), lines: (1..=points.len()).collect() };
    pts.check(path, model.landmarks.len(), &model.metadata.landmark_scheme, photo.width(), photo.height(), true)?;
    let prepared = prepare(photo, points, settings.size)?;
    let outcome = fit_prepared(model, &prepared, settings, progress)?;
    Ok((prepared, outcome))
}
