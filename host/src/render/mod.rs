//! Host rendering: a model instance through the core's [`TileRasterizer`] into an image.
//!
//! The per-vertex stage ([`gpmm_core::render::vertex_stage`]: normals, SH Lambert shading, projection) and
//! the tile rasterizer are the same code the device runs; the host only adds an [`ImageSink`] that
//! copies each finished tile into an [`RgbaImage`], and a default [`Framing`] (camera focal length
//! from a field of view, model distance from its bounding box). Colours are linear RGB in [0, 1]
//! written as-is (no gamma, docs/design.md), rounded to 8 bits. Back faces are culled: the model's
//! triangles are counter-clockwise seen from outside, so [`Cull::Clockwise`] keeps the front faces.

pub mod figure;
pub mod light;

use crate::gp::model::GpModel;
use crate::mesh::Mesh;
use gpmm_core::geometry::Vec3;
use gpmm_core::model::ModelError;
use gpmm_core::render::frame_cache::{CachedFragment, FrameBuffers, FrameCache};
use gpmm_core::render::{
    vertex_stage, Camera, Cull, FrameStats, Pose, ProjectedVertex, RasterError, ShLight, Tile, TileRasterizer, TileSink, VertexError,
};
use image::{Rgba, RgbaImage};

/// Tile width and height of the host rasterizer (pixels): the devices' (`gpmm_core::profile`), so
/// host and device sum the image likelihood tile by tile in the same order.
pub const TILE: usize = gpmm_core::profile::M4F.tile;
/// Triangle capacity of the host rasterizer's per-tile-row bin.
pub const BIN: usize = 8192;
/// The rasterizer configuration the host uses.
pub type HostRasterizer = TileRasterizer<TILE, TILE, BIN>;
/// Largest image side [`RenderSettings`] accept (pixels).
pub const MAX_SIDE: u32 = 8192;

/// Why a render was refused.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// Width or height is 0 or above [`MAX_SIDE`].
    #[error("image size {0}x{1} is invalid: each side must be 1 to {MAX_SIDE} pixels")]
    BadSize(u32, u32),
    /// The field of view is not in (0°, 180°).
    #[error("field of view {0}° is invalid: it must be between 0 and 180 degrees (exclusive)")]
    BadFov(f32),
    /// The framing margin is not in [0, 1).
    #[error("margin {0} is invalid: it must be in [0, 1)")]
    BadMargin(f32),
    /// An angle, position, colour or light coefficient is NaN or infinite.
    #[error("a pose angle, position, colour or light coefficient is not a finite number")]
    NonFinite,
    /// The mesh has no vertices.
    #[error("the mesh has no vertices")]
    EmptyMesh,
    /// More coefficients than the model part has components.
    #[error("{given} {part} coefficients given, but the model has only {rank} {part} components")]
    TooManyCoefficients {
        /// `shape` or `colour`.
        part: &'static str,
        /// Number given.
        given: usize,
        /// The part's rank.
        rank: usize,
    },
    /// The model's arrays are inconsistent.
    #[error("the model's arrays are inconsistent: {0}")]
    Model(ModelError),
    /// The per-vertex stage refused its input.
    #[error("vertex stage: {0}")]
    Vertex(VertexError),
    /// The rasterizer refused the frame.
    #[error("rasterizer: {0}")]
    Raster(RasterError),
}

/// What uncovered pixels become.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Background {
    /// Alpha 0 (colour 0).
    Transparent,
    /// An opaque linear RGB colour in [0, 1].
    Color(Vec3),
}

impl Background {
    /// The background as an RGBA pixel.
    pub fn pixel(self) -> Rgba<u8> {
        match self {
            Background::Transparent => Rgba([0, 0, 0, 0]),
            Background::Color(c) => Rgba([to_u8(c[0]), to_u8(c[1]), to_u8(c[2]), 255]),
        }
    }
}

/// A linear colour channel in [0, 1] to 8 bits (clamped, rounded; no gamma).
pub fn to_u8(c: f32) -> u8 {
    if c.is_nan() {
        return 0;
    }
    (c.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// A [`TileSink`] that copies every finished tile into a full RGBA image.
#[derive(Debug, Clone)]
pub struct ImageSink {
    image: RgbaImage,
    background: Rgba<u8>,
}

impl ImageSink {
    /// A `width × height` image filled with `background`.
    pub fn new(width: u32, height: u32, background: Background) -> Self {
        let bg = background.pixel();
        Self { image: RgbaImage::from_pixel(width, height, bg), background: bg }
    }

    /// The image so far.
    pub fn image(&self) -> &RgbaImage {
        &self.image
    }

    /// The finished image.
    pub fn into_image(self) -> RgbaImage {
        self.image
    }
}

impl<const TW: usize, const TH: usize> TileSink<TW, TH> for ImageSink {
    fn consume(&mut self, tile: &Tile<TW, TH>) {
        let (x0, y0) = tile.origin();
        let (w, h) = tile.size();
        for ly in 0..h as usize {
            for lx in 0..w as usize {
                let (x, y) = (x0 + lx as u32, y0 + ly as u32);
                if x >= self.image.width() || y >= self.image.height() {
                    continue;
                }
                let px = match tile.fragment(lx, ly) {
                    Some(f) => Rgba([to_u8(f.color[0]), to_u8(f.color[1]), to_u8(f.color[2]), 255]),
                    None => self.background,
                };
                self.image.put_pixel(x, y, px);
            }
        }
    }
}

/// Viewing direction as Euler angles in **degrees** (the conventions of [`Pose`]).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct View {
    /// Positive turns the face toward the image right.
    pub yaw: f32,
    /// Positive tilts the nose down.
    pub pitch: f32,
    /// Positive turns the face counter-clockwise in the image.
    pub roll: f32,
}

impl View {
    /// Looking straight at the face.
    pub const FRONTAL: View = View { yaw: 0.0, pitch: 0.0, roll: 0.0 };

    /// A view turned by `yaw` degrees.
    pub const fn yaw(yaw: f32) -> View {
        View { yaw, pitch: 0.0, roll: 0.0 }
    }

    /// The rotation-only pose of this view.
    pub fn rotation(self) -> Pose {
        Pose { yaw: self.yaw.to_radians(), pitch: self.pitch.to_radians(), roll: self.roll.to_radians(), translation: [0.0; 3] }
    }

    fn finite(self) -> bool {
        self.yaw.is_finite() && self.pitch.is_finite() && self.roll.is_finite()
    }
}

/// Image size, light, background and framing of a render.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderSettings {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Illumination (camera space).
    pub light: ShLight,
    /// Colour of uncovered pixels.
    pub background: Background,
    /// Field of view across the shorter image side, degrees.
    pub fov_deg: f32,
    /// Fraction of the half-image left free around the model (the model fills `1 − margin`).
    pub margin: f32,
    /// Which winding to discard.
    pub cull: Cull,
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            width: 256,
            height: 256,
            light: ShLight::frontal(),
            background: Background::Color([0.0; 3]),
            fov_deg: 20.0,
            margin: 0.08,
            cull: Cull::Clockwise,
        }
    }
}

impl RenderSettings {
    /// Checks size, field of view, margin and light.
    pub fn validate(&self) -> Result<(), RenderError> {
        check_size(self.width, self.height)?;
        if !(self.fov_deg > 0.0 && self.fov_deg < 180.0) {
            return Err(RenderError::BadFov(self.fov_deg));
        }
        if !(self.margin >= 0.0 && self.margin < 1.0) {
            return Err(RenderError::BadMargin(self.margin));
        }
        if !self.light.coeffs.iter().flatten().all(|c| c.is_finite()) {
            return Err(RenderError::NonFinite);
        }
        if let Background::Color(c) = self.background {
            if !c.iter().all(|v| v.is_finite()) {
                return Err(RenderError::NonFinite);
            }
        }
        Ok(())
    }

    /// The pinhole camera: principal point at the image centre, focal length from [`Self::fov_deg`].
    pub fn camera(&self) -> Camera {
        let short = self.width.min(self.height);
        Camera::centered(self.width, self.height, Camera::focal_from_fov(short, self.fov_deg.to_radians()))
    }
}

/// Checks an image size against `1..=`[`MAX_SIDE`].
pub fn check_size(width: u32, height: u32) -> Result<(), RenderError> {
    if width == 0 || height == 0 || width > MAX_SIDE || height > MAX_SIDE {
        return Err(RenderError::BadSize(width, height));
    }
    Ok(())
}

/// Where the model sits in front of the camera: a pivot (model space) and a distance (mm).
///
/// Every view rotates the model about `center` and puts `center` on the optical axis at depth
/// `distance`, so renders of the same framing share their scale.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Framing {
    /// Rotation pivot, model space (mm): the centre of the bounding box.
    pub center: Vec3,
    /// Depth of `center` in camera space (mm).
    pub distance: f32,
}

impl Framing {
    /// The smallest distance at which `positions` fit inside the image with the settings' margin in every one of `views`.
    ///
    /// The fit is conservative: each view's rotated bounding box is placed with its front face at the nearest depth.
    pub fn fit(positions: &[Vec3], views: &[View], settings: &RenderSettings) -> Result<Self, RenderError> {
        settings.validate()?;
        if positions.is_empty() {
            return Err(RenderError::EmptyMesh);
        }
        if !positions.iter().flatten().all(|c| c.is_finite()) || !views.iter().all(|v| v.finite()) {
            return Err(RenderError::NonFinite);
        }
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for p in positions {
            for ((l, h), v) in lo.iter_mut().zip(hi.iter_mut()).zip(p) {
                *l = l.min(*v);
                *h = h.max(*v);
            }
        }
        let center = [(lo[0] + hi[0]) * 0.5, (lo[1] + hi[1]) * 0.5, (lo[2] + hi[2]) * 0.5];
        let camera = settings.camera();
        let fill = 1.0 - settings.margin;
        let tan_x = settings.width as f32 * 0.5 / camera.focal * fill;
        let tan_y = settings.height as f32 * 0.5 / camera.focal * fill;
        let mut distance = 0.0f32;
        for view in if views.is_empty() { &[View::FRONTAL][..] } else { views } {
            let r = view.rotation();
            let (mut hx, mut hy, mut hz) = (0.0f32, 0.0f32, 0.0f32);
            for p in positions {
                let q = r.transform_point([p[0] - center[0], p[1] - center[1], p[2] - center[2]]);
                hx = hx.max(q[0].abs());
                hy = hy.max(q[1].abs());
                hz = hz.max(q[2]);
            }
            distance = distance.max(hz + (hx / tan_x).max(hy / tan_y));
        }
        // A degenerate (single point) mesh still needs a positive distance beyond the near plane.
        Ok(Self { center, distance: distance.max(camera.near * 2.0) })
    }

    /// The pose that shows the model from `view` with this framing.
    pub fn pose(&self, view: View) -> Pose {
        let mut pose = view.rotation();
        let rc = pose.transform_point(self.center);
        pose.translation = [-rc[0], -rc[1], -rc[2] - self.distance];
        pose
    }
}

/// Vertex positions (mm) and albedos (linear RGB) of one model instance, in `f32`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Instance {
    /// Positions, model space (mm).
    pub positions: Vec<Vec3>,
    /// Albedos, linear RGB clamped to [0, 1].
    pub albedos: Vec<Vec3>,
}

impl Instance {
    /// The instance of `model` for the given coefficients (missing ones are zero; too many is an error).
    pub fn of_model(model: &GpModel, shape: &[f32], color: &[f32]) -> Result<Self, RenderError> {
        check_coefficients(model, shape, color)?;
        let positions = model.shape.instance(shape).map_err(RenderError::Model)?;
        let mut albedos = model.color.instance(color).map_err(RenderError::Model)?;
        for a in albedos.iter_mut() {
            *a = a.map(|c| c.clamp(0.0, 1.0));
        }
        Ok(Self { positions, albedos })
    }

    /// The positions and colours of a mesh (e.g. [`GpModel::sample`]'s output or a template).
    pub fn of_mesh(mesh: &Mesh) -> Self {
        Self {
            positions: mesh.positions.iter().map(|p| p.map(|v| v as f32)).collect(),
            albedos: mesh.colors.iter().map(|c| c.map(|v| v as f32)).collect(),
        }
    }
}

/// Checks that no more coefficients are given than the model has components.
pub fn check_coefficients(model: &GpModel, shape: &[f32], color: &[f32]) -> Result<(), RenderError> {
    if shape.len() > model.shape.rank() {
        return Err(RenderError::TooManyCoefficients { part: "shape", given: shape.len(), rank: model.shape.rank() });
    }
    if color.len() > model.color.rank() {
        return Err(RenderError::TooManyCoefficients { part: "colour", given: color.len(), rank: model.color.rank() });
    }
    if !shape.iter().chain(color).all(|c| c.is_finite()) {
        return Err(RenderError::NonFinite);
    }
    Ok(())
}

/// Reusable render state: the tile rasterizer and the per-vertex scratch buffers.
#[derive(Debug, Clone)]
pub struct Renderer {
    raster: Box<HostRasterizer>,
    normals: Vec<Vec3>,
    projected: Vec<ProjectedVertex>,
}

impl Default for Renderer {
    fn default() -> Self {
        Self::new()
    }
}

impl Renderer {
    /// A renderer with empty buffers.
    pub fn new() -> Self {
        Self { raster: Box::new(HostRasterizer::new()), normals: Vec::new(), projected: Vec::new() }
    }

    /// The per-vertex stage (normals, shading, projection) into the internal vertex buffer.
    #[allow(clippy::too_many_arguments)]
    pub fn vertex_stage(
        &mut self,
        instance: &Instance,
        triangles: &[[u32; 3]],
        pose: &Pose,
        camera: &Camera,
        light: &ShLight,
    ) -> Result<(), RenderError> {
        let n = instance.positions.len();
        self.normals.resize(n, [0.0; 3]);
        self.projected.resize(n, ProjectedVertex::INVALID);
        vertex_stage(&instance.positions, &instance.albedos, triangles, pose, camera, light, &mut self.normals, &mut self.projected)
            .map_err(|e| match e {
                VertexError::NonFinite => RenderError::NonFinite,
                e => RenderError::Vertex(e),
            })
    }

    /// The vertices after the last [`Self::vertex_stage`].
    pub fn projected(&self) -> &[ProjectedVertex] {
        &self.projected
    }

    /// Rasterizes the last vertex stage's output into any tile sink.
    pub fn rasterize_into<S: TileSink<TILE, TILE>>(
        &mut self,
        triangles: &[[u32; 3]],
        width: u32,
        height: u32,
        cull: Cull,
        sink: &mut S,
    ) -> Result<FrameStats, RenderError> {
        self.raster.render(&self.projected, triangles, width, height, cull, sink).map_err(RenderError::Raster)
    }

    /// Rasterizes the last vertex stage's output into an image.
    pub fn rasterize(
        &mut self,
        triangles: &[[u32; 3]],
        width: u32,
        height: u32,
        cull: Cull,
        background: Background,
    ) -> Result<(RgbaImage, FrameStats), RenderError> {
        check_size(width, height)?;
        let mut sink = ImageSink::new(width, height, background);
        let stats = self.rasterize_into(triangles, width, height, cull, &mut sink)?;
        Ok((sink.into_image(), stats))
    }

    /// Vertex stage and rasterization of `instance` seen with `pose` under `settings`.
    pub fn render(
        &mut self,
        instance: &Instance,
        triangles: &[[u32; 3]],
        pose: &Pose,
        settings: &RenderSettings,
    ) -> Result<(RgbaImage, FrameStats), RenderError> {
        settings.validate()?;
        self.vertex_stage(instance, triangles, pose, &settings.camera(), &settings.light)?;
        self.rasterize(triangles, settings.width, settings.height, settings.cull, settings.background)
    }
}

/// Renders the model for the given coefficients from `view`, framed by its mean shape.
pub fn render_model(
    model: &GpModel,
    shape: &[f32],
    color: &[f32],
    view: View,
    settings: &RenderSettings,
) -> Result<RgbaImage, RenderError> {
    let instance = Instance::of_model(model, shape, color)?;
    let framing = Framing::fit(&model.shape.mean, &[view], settings)?;
    let (image, _) = Renderer::new().render(&instance, &model.triangles, &framing.pose(view), settings)?;
    Ok(image)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn framing_centres_and_fits() {
        let s = RenderSettings { width: 100, height: 100, fov_deg: 30.0, margin: 0.0, ..Default::default() };
        let pts = [[-50.0, -50.0, 0.0], [50.0, 50.0, 0.0], [150.0, 50.0, 0.0]];
        let f = Framing::fit(&pts, &[View::FRONTAL], &s).unwrap();
        assert_eq!(f.center, [50.0, 0.0, 0.0]);
        let cam = s.camera();
        let pose = f.pose(View::FRONTAL);
        let p = cam.project(pose.transform_point([150.0, 50.0, 0.0])).unwrap();
        assert!((p.x - 100.0).abs() < 1e-3, "{p:?}");
        let c = cam.project(pose.transform_point(f.center)).unwrap();
        assert!((c.x - 50.0).abs() < 1e-3 && (c.y - 50.0).abs() < 1e-3);
    }

    #[test]
    fn settings_reject_bad_values() {
        let ok = RenderSettings::default();
        assert!(ok.validate().is_ok());
        assert!(RenderSettings { width: 0, ..ok }.validate().is_err());
        assert!(RenderSettings { height: MAX_SIDE + 1, ..ok }.validate().is_err());
        assert!(RenderSettings { fov_deg: 180.0, ..ok }.validate().is_err());
        assert!(RenderSettings { margin: f32::NAN, ..ok }.validate().is_err());
        assert!(Framing::fit(&[], &[], &ok).is_err());
    }

    #[test]
    fn to_u8_clamps_and_rounds() {
        assert_eq!(to_u8(-1.0), 0);
        assert_eq!(to_u8(2.0), 255);
        assert_eq!(to_u8(0.5), 128);
        assert_eq!(to_u8(f32::NAN), 0);
    }
}

/// Memory for the core's [`FrameCache`]: two frames of a `width × height` image (every pixel may
/// be covered), allocated once per fit.
#[derive(Debug)]
pub struct FrameMemory {
    fragments: [Vec<CachedFragment>; 2],
    tile_ends: [Vec<u32>; 2],
}

impl FrameMemory {
    /// Memory for frames of `width × height` pixels.
    pub fn new(width: u32, height: u32) -> Self {
        let pixels = width as usize * height as usize;
        let tiles = (width as usize).div_ceil(TILE) * (height as usize).div_ceil(TILE);
        Self {
            fragments: [vec![CachedFragment::EMPTY; pixels], vec![CachedFragment::EMPTY; pixels]],
            tile_ends: [vec![0; tiles], vec![0; tiles]],
        }
    }

    /// A cache over this memory (empty).
    pub fn cache(&mut self) -> FrameCache<'_> {
        let [fa, fb] = &mut self.fragments;
        let [ta, tb] = &mut self.tile_ends;
        FrameCache::new(FrameBuffers { fragments: fa, tile_ends: ta }, FrameBuffers { fragments: fb, tile_ends: tb })
    }
}
