//! Training scenes for the finder and the initializer, rendered from the morphable model itself:
//! a random face (shape, colour, pose, light, camera, framing) over a procedural background, with
//! camera effects. Labels come from the model (landmark vertices, pose, light); nothing is
//! labelled by hand. One scene is a pure function of `(seed, index)`; given several models of one
//! template, the pair also picks the model its face comes from ([`face_model_index`]).
//!
//! Around the model's face: the template's whole head ([`head`]), dressed with hair and clothes
//! ([`dress`]), and open eyes painted over the scan's shut ones ([`eyes`]). Behind it, when the
//! user gives a folder of them, real face-free photographs ([`backgrounds`]).

mod almond;
pub mod backgrounds;
pub mod dress;
pub mod eyes;
pub mod head;
pub mod look;
pub mod occluders;

use backgrounds::{Backgrounds, FaceView};
use eyes::OpenEyes;
use gpmm_core::net::face_box::landmark_box;
use gpmm_core::render::light::SH_COEFFS;
use gpmm_core::render::{Cull, ShLight};
use gpmm_host::gp::model::GpModel;
use gpmm_host::render::{Background, Instance, RenderSettings, Renderer, View};
use head::HeadContext;
use image::{Rgb, RgbImage, RgbaImage};
use rand::{Rng, RngExt, SeedableRng};
use rand_distr::{Distribution, Normal};
use rand_xoshiro::Xoshiro256PlusPlus;

/// The ranges scenes are drawn from.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneRanges {
    /// Largest |yaw| (degrees).
    pub yaw: f32,
    /// Largest |pitch| (degrees).
    pub pitch: f32,
    /// Largest |roll| (degrees).
    pub roll: f32,
    /// Horizontal field of view range (degrees), as common cameras have.
    pub fov: (f32, f32),
    /// Longer frame side range (px).
    pub frame_side: (u32, u32),
    /// Frame aspect ratios (width / height) drawn from, landscape and portrait as cameras and
    /// phones give them.
    pub aspects: Vec<f32>,
    /// Face size (larger side of the landmarks' box) over the shorter frame side.
    pub face_fraction: (f32, f32),
    /// Shape and colour components drawn (standard normal; the rest zero).
    pub components: usize,
    /// Paint open eyes over the scan's shut ones in most scenes (`crate::scene::eyes`).
    pub open_eyes: bool,
    /// Dress the heads (`crate::scene::dress`: fuller and long hair, clothes, a torso).
    pub dressed: bool,
    /// The share of frames given a random photographic look (`crate::scene::look`: black and
    /// white, contrast, brightness, saturation, colour cast), from a stream of its own.
    pub look_share: f64,
    /// Draw dark glasses and masks over some faces (`crate::scene::occluders`).
    pub occluders: bool,
}

impl Default for SceneRanges {
    fn default() -> Self {
        Self {
            yaw: 70.0,
            pitch: 30.0,
            roll: 30.0,
            fov: (20.0, 70.0),
            frame_side: (128, 256),
            // Portrait 9:16 and 1:2 too: without them the finder found 71-79 % of the
            // development faces on frames twice as tall as wide, with them 75 and 88 % on two
            // seeds.
            aspects: vec![1.0, 4.0 / 3.0, 3.0 / 4.0, 16.0 / 9.0, 9.0 / 16.0, 0.5],
            face_fraction: gpmm_core::net::scan::TRAINED_FACE_FRACTION,
            components: 60,
            open_eyes: true,
            dressed: true,
            look_share: 0.5,
            occluders: true,
        }
    }
}

/// One rendered scene and its labels.
#[derive(Debug, Clone)]
pub struct Scene {
    /// The frame (8-bit RGB, gamma-encoded like a camera's).
    pub frame: RgbImage,
    /// Landmarks in frame pixels (the model's landmark vertices projected).
    pub landmarks: Vec<[f32; 2]>,
    /// Yaw, pitch, roll (radians).
    pub angles: [f32; 3],
    /// The light's bands 0 and 1 (4 coefficients × RGB, coefficient-major).
    pub light: Vec<f32>,
}

/// Number of light values a scene labels (SH bands 0 and 1, RGB).
pub const LIGHT_LABELS: usize = 12;

/// The scene's light as drawn (a tinted ambient part and one directional light), and the small
/// band-2 coefficients real light has (one per coefficient, the same in R, G and B).
fn random_light(rng: &mut impl Rng) -> (ShLight, [f32; SH_COEFFS - 4]) {
    // Indoor to outdoor: a tinted ambient part and one directional light from anywhere in front.
    let level = rng.random_range(0.35f32..1.1);
    let tint = [rng.random_range(0.8f32..1.2), 1.0, rng.random_range(0.8f32..1.2)];
    let ambient = tint.map(|t| level * t * rng.random_range(0.3f32..0.9));
    let strength = level * rng.random_range(0.0f32..0.9);
    let diffuse = tint.map(|t| t * strength);
    let dir = [rng.random_range(-1.0f32..1.0), rng.random_range(-1.0f32..1.0), rng.random_range(0.0f32..1.0)];
    let band2 = std::array::from_fn(|_| rng.random_range(-0.08f32..0.08));
    (ShLight::from_ambient_diffuse(ambient, diffuse, dir), band2)
}

/// A procedural background: a gradient, value noise at a random scale, and a few shapes.
fn background(w: u32, h: u32, rng: &mut impl Rng) -> RgbImage {
    // Colours as rooms and streets have them: mostly greyish, some saturated.
    let saturation = rng.random_range(0.0f32..1.0).powi(2);
    let colour = |rng: &mut dyn rand::Rng| -> [f32; 3] {
        let c: [f32; 3] = [rng.random(), rng.random(), rng.random()];
        let g = (c[0] + c[1] + c[2]) / 3.0;
        c.map(|v| g + (v - g) * saturation)
    };
    let base = colour(rng);
    let grad: [f32; 3] = [rng.random_range(-0.5..0.5), rng.random_range(-0.5..0.5), rng.random_range(-0.5..0.5)];
    let cells = rng.random_range(2u32..24);
    let grid: Vec<[f32; 3]> = (0..(cells + 2) * (cells + 2)).map(|_| colour(rng)).collect();
    let noise_amount = rng.random_range(0.0f32..0.6);
    let cell = w.max(h) as f32 / cells as f32;
    let shapes: Vec<(f32, f32, f32, f32, [f32; 3], bool)> = (0..rng.random_range(0..8))
        .map(|_| {
            let (x, y) = (rng.random_range(0.0..w as f32), rng.random_range(0.0..h as f32));
            let (a, b) = (rng.random_range(3.0..w as f32 * 0.4), rng.random_range(3.0..h as f32 * 0.4));
            (x, y, a, b, colour(rng), rng.random_bool(0.5))
        })
        .collect();
    RgbImage::from_fn(w, h, |x, y| {
        let (fx, fy) = (x as f32 / cell, y as f32 / cell);
        let (ix, iy) = (fx as usize, fy as usize);
        let (ax, ay) = (fx - ix as f32, fy - iy as f32);
        let g = |i: usize, j: usize| grid[(j.min(cells as usize + 1)) * (cells as usize + 2) + i.min(cells as usize + 1)];
        let mut c = [0.0f32; 3];
        for (k, v) in c.iter_mut().enumerate() {
            let n = (g(ix, iy)[k] * (1.0 - ax) + g(ix + 1, iy)[k] * ax) * (1.0 - ay)
                + (g(ix, iy + 1)[k] * (1.0 - ax) + g(ix + 1, iy + 1)[k] * ax) * ay;
            let t = (x as f32 / w as f32 - 0.5) * grad[k] + (y as f32 / h as f32 - 0.5) * grad[(k + 1) % 3];
            *v = base[k] * (1.0 - noise_amount) + n * noise_amount + t;
        }
        for &(sx, sy, a, b, col, ellipse) in &shapes {
            let (dx, dy) = ((x as f32 - sx) / a, (y as f32 - sy) / b);
            let inside = if ellipse { dx * dx + dy * dy < 1.0 } else { dx.abs() < 1.0 && dy.abs() < 1.0 };
            if inside {
                c = col;
            }
        }
        Rgb(c.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8))
    })
}

/// Camera effects on a linear render composited over its background: blur, white balance, gamma,
/// sensor noise, 8 bits, sometimes JPEG.
fn camera_effects(render: &RgbaImage, back: &RgbImage, rng: &mut impl Rng) -> RgbImage {
    let (w, h) = render.dimensions();
    let gamma = if rng.random_bool(0.8) { 1.0 / rng.random_range(1.8f32..2.5) } else { 1.0 };
    let wb = [rng.random_range(0.85f32..1.15), 1.0, rng.random_range(0.85f32..1.15)];
    let gain = rng.random_range(0.7f32..1.3);
    let noise = Normal::new(0.0f32, rng.random_range(0.0f32..0.03)).unwrap_or_else(|_| Normal::new(0.0, 0.01).expect("valid"));
    let mut out = RgbImage::from_fn(w, h, |x, y| {
        let p = render.get_pixel(x, y);
        let b = back.get_pixel(x, y);
        let c: [f32; 3] = std::array::from_fn(|k| {
            if p[3] > 0 {
                let lin = (p[k] as f32 / 255.0 * wb[k] * gain).clamp(0.0, 1.0);
                lin.powf(gamma)
            } else {
                b[k] as f32 / 255.0
            }
        });
        Rgb(c.map(|v| ((v + noise.sample(rng)).clamp(0.0, 1.0) * 255.0).round() as u8))
    });
    let sigma = rng.random_range(0.0f32..1.3);
    if sigma > 0.3 {
        out = image::imageops::blur(&out, sigma);
    }
    if rng.random_bool(0.4) {
        let quality = rng.random_range(30u8..90);
        let mut bytes = Vec::new();
        let enc = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, quality);
        if out.write_with_encoder(enc).is_ok() {
            if let Ok(img) = image::load_from_memory(&bytes) {
                out = img.to_rgb8();
            }
        }
    }
    out
}

/// `frame` finished from a stream of its own for `(seed, key)`, so that the rest of a scene is the
/// same with or without: occluders over the face at `points` (when `ranges.occluders`), then a
/// random look ([`look::apply_look`]).
fn finished(mut frame: RgbImage, points: &[[f32; 2]], ranges: &SceneRanges, seed: u64, key: u64) -> RgbImage {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed ^ key.wrapping_mul(0xD6E8_FEB8_6659_FD93) ^ 0x100C);
    if ranges.occluders {
        occluders::draw_occluders(&mut frame, points, &mut rng);
    }
    look::apply_look(&mut frame, ranges.look_share, &mut rng);
    frame
}

/// The eyes a model's scenes may open, found once on its mean shape.
#[derive(Debug, Clone, Default)]
pub struct Openings {
    eyes: Option<OpenEyes>,
}

impl Openings {
    /// Those of `model` that `ranges` opens (`open_eyes`).
    pub fn of_model(model: &GpModel, ranges: &SceneRanges) -> Self {
        Self { eyes: if ranges.open_eyes { OpenEyes::of_model(model) } else { None } }
    }
}

/// A model scenes draw faces from, with its openings.
#[derive(Debug, Clone, Copy)]
pub struct FaceModel<'a> {
    /// The model whose faces are rendered (its landmark vertices are the labels).
    pub model: &'a GpModel,
    /// The model's openings for the scenes' ranges ([`Openings::of_model`]).
    pub openings: &'a Openings,
}

/// What scenes are drawn from: the models, the head put around their faces (if any), the ranges.
#[derive(Debug, Clone, Copy)]
pub struct SceneSource<'a> {
    /// The models each scene draws its face from ([`face_model_index`]); all in the first one's
    /// topology (same vertices and landmarks), the head being linked to the first.
    pub faces: &'a [FaceModel<'a>],
    /// The whole head around each face; `None` renders the face alone.
    pub head: Option<&'a HeadContext>,
    /// The ranges of pose, camera and framing.
    pub ranges: &'a SceneRanges,
    /// Real face-free photos some scenes are drawn over (and face-free frames are cut from).
    pub backgrounds: Option<&'a Backgrounds>,
}

/// Which of `models` models scene `index` of the stream `seed` draws its face from: uniform, fixed
/// for a seed and index, from a stream of its own (so one model's scenes are as they always were).
pub fn face_model_index(seed: u64, index: u64, models: usize) -> usize {
    if models <= 1 {
        return 0;
    }
    // SplitMix64's finalizer of the pair.
    let mut z = (seed ^ 0x3C6E_F372_FE94_F82B).wrapping_add(index.wrapping_mul(0x9E37_79B9_7F4A_7C15));
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z % models as u64) as usize
}

/// Width and height of a frame whose longer side is `long` px.
fn frame_size(long: u32, aspect: f32) -> (u32, u32) {
    if aspect >= 1.0 {
        (long, (long as f32 / aspect).round() as u32)
    } else {
        ((long as f32 * aspect).round() as u32, long)
    }
}

/// Face-free frame `index` of the stream `seed`: a view of a background photo (a procedural
/// background without photos) at a scene's size, through the same camera effects.
pub fn face_free_frame(source: SceneSource<'_>, seed: u64, index: u64) -> RgbImage {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed ^ index.wrapping_mul(0x2545_F491_4F6C_DD1D) ^ 0xF4EE);
    let ranges = source.ranges;
    let long = rng.random_range(ranges.frame_side.0..=ranges.frame_side.1);
    let aspect = ranges.aspects.get(rng.random_range(0..ranges.aspects.len().max(1))).copied().unwrap_or(1.0);
    let (w, h) = frame_size(long, aspect);
    let back = match source.backgrounds.and_then(|b| b.view(w, h, &mut rng)) {
        Some(photo) => photo,
        None => background(w, h, &mut rng),
    };
    finished(camera_effects(&RgbaImage::new(w, h), &back, &mut rng), &[], ranges, seed, index ^ 0xF4EE)
}

/// Real face `index` of the stream `seed`: a view of a known face of a photo of people
/// ([`Backgrounds::face_view`]) at a scene's size and face size, through the same camera effects,
/// with the face's landmarks' box and points in it. `None` without photos of people or when no
/// window fits.
pub fn photo_face_frame(source: SceneSource<'_>, seed: u64, index: u64) -> Option<FaceView> {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed ^ index.wrapping_mul(0x5851_F42D_4C95_7F2D) ^ 0xFACE);
    let ranges = source.ranges;
    let long = rng.random_range(ranges.frame_side.0..=ranges.frame_side.1);
    let aspect = ranges.aspects.get(rng.random_range(0..ranges.aspects.len().max(1))).copied().unwrap_or(1.0);
    let (w, h) = frame_size(long, aspect);
    let view = source.backgrounds?.face_view(w, h, ranges.face_fraction, &mut rng)?;
    let image = finished(camera_effects(&RgbaImage::new(w, h), &view.image, &mut rng), &view.points, ranges, seed, index ^ 0xFACE);
    Some(FaceView { image, ..view })
}

/// Renders scene `index` of the set drawn with `seed`.
pub fn render_scene(source: SceneSource<'_>, seed: u64, index: u64, renderer: &mut Renderer) -> Option<Scene> {
    let SceneSource { faces, head, ranges, backgrounds } = source;
    let FaceModel { model, openings } = *faces.get(face_model_index(seed, index, faces.len()))?;
    // The head is linked to the first model: other models' faces are changes of its mean.
    let head_model = faces.first()?.model;
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed ^ index.wrapping_mul(0x9E37_79B9_7F4A_7C15));
    let normal = Normal::new(0.0f32, 1.0).ok()?;
    let k = ranges.components;
    let shape: Vec<f32> = (0..model.shape.rank().min(k)).map(|_| normal.sample(&mut rng)).collect();
    let color: Vec<f32> = (0..model.color.rank().min(k)).map(|_| normal.sample(&mut rng) * 0.8).collect();
    let mut instance = Instance::of_model(model, &shape, &color).ok()?;
    let view = View {
        yaw: rng.random_range(-ranges.yaw..=ranges.yaw),
        pitch: rng.random_range(-ranges.pitch..=ranges.pitch),
        roll: rng.random_range(-ranges.roll..=ranges.roll),
    };
    let long = rng.random_range(ranges.frame_side.0..=ranges.frame_side.1);
    let aspect = ranges.aspects.get(rng.random_range(0..ranges.aspects.len().max(1))).copied().unwrap_or(1.0);
    let (w, h) = frame_size(long, aspect);
    let fov_h = rng.random_range(ranges.fov.0..=ranges.fov.1);
    // The settings' field of view is across the shorter side.
    let fov_short = 2.0 * ((fov_h.to_radians() * 0.5).tan() * w.min(h) as f32 / w as f32).atan().to_degrees();
    let (mut light, band2) = random_light(&mut rng);
    light.coeffs.iter_mut().skip(4).zip(band2).for_each(|(c, b)| *c = [b; 3]);
    let settings = RenderSettings {
        width: w,
        height: h,
        light,
        background: Background::Transparent,
        fov_deg: fov_short,
        margin: 0.0,
        cull: Cull::Clockwise,
    };
    let camera = settings.camera();
    // Place the head: the landmark box's size is a random fraction of the shorter side, the
    // centre anywhere that keeps the box's centre inside the frame.
    let lm_model: Vec<[f32; 3]> = model.landmarks.iter().filter_map(|&i| instance.positions.get(i as usize).copied()).collect();
    let centre =
        lm_model.iter().fold([0.0f32; 3], |a, p| [a[0] + p[0], a[1] + p[1], a[2] + p[2]]).map(|v| v / lm_model.len().max(1) as f32);
    let mut pose = view.rotation();
    let rc = pose.transform_point(centre);
    let face_mm = {
        let pts: Vec<[f32; 2]> = lm_model.iter().map(|p| pose.transform_point(*p)).map(|q| [q[0], q[1]]).collect();
        landmark_box(&pts).2
    };
    let want = rng.random_range(ranges.face_fraction.0..ranges.face_fraction.1) * w.min(h) as f32;
    let depth = camera.focal * face_mm / want.max(1.0);
    let (px, py) = (rng.random_range(0.15f32..0.85) * w as f32, rng.random_range(0.15f32..0.85) * h as f32);
    let (ox, oy) = ((px - camera.principal[0]) / camera.focal * depth, -(py - camera.principal[1]) / camera.focal * depth);
    pose.translation = [ox - rc[0], oy - rc[1], -depth - rc[2]];
    // Clothes and fuller hair from a stream of their own (the undressed scene is unchanged).
    let mut dress_rng = Xoshiro256PlusPlus::seed_from_u64(seed ^ index.wrapping_mul(0xBF58_476D_1CE4_E5B9) ^ 0xD2E5);
    let (mut headed, backdrop) = match head {
        Some(h) if ranges.dressed => {
            let (headed, backdrop) = h.dressed_around(head_model, &instance, &mut rng, &mut dress_rng);
            (Some(headed), Some(backdrop))
        }
        Some(h) => (Some(h.around(head_model, &instance, &mut rng)), None),
        None => (None, None),
    };
    // Open eyes (the scan's are shut) from a stream of their own, so the rest of the scene is the
    // same with or without them.
    let mut eye_rng = Xoshiro256PlusPlus::seed_from_u64(seed ^ index.wrapping_mul(0xD1B5_4A32_D192_ED03) ^ 0xE7E5);
    let eyes = openings.eyes.as_ref();
    let opening = eyes.and_then(|e| {
        let albedos = match &mut headed {
            Some(h) => &mut h.instance.albedos[..instance.positions.len()],
            None => &mut instance.albedos[..],
        };
        e.paint(albedos, &mut eye_rng)
    });
    let (render, _) = match &headed {
        Some(h) => renderer.render(&h.instance, &h.triangles, &pose, &settings).ok()?,
        None => renderer.render(&instance, &model.triangles, &pose, &settings).ok()?,
    };
    let projected = |v: u32| renderer.projected().get(v as usize).map(|p| [p.x, p.y]);
    let mut landmarks: Vec<[f32; 2]> = model.landmarks.iter().filter_map(|&i| projected(i)).collect();
    if let (Some(eyes), Some(opening)) = (eyes, opening) {
        eyes.relabel_lids(opening, projected, &mut landmarks);
    }
    if landmarks.len() != model.landmarks.len() || landmarks.iter().flatten().any(|v| !v.is_finite()) {
        return None;
    }
    let mut back = background(w, h, &mut rng);
    // A photo instead, from a stream of its own (the rest of the scene is the same without one).
    let mut photo_rng = Xoshiro256PlusPlus::seed_from_u64(seed ^ index.wrapping_mul(0x94D0_49BB_1331_11EB) ^ 0xBAC0);
    if let Some(b) = backgrounds.filter(|b| photo_rng.random_bool(b.share.clamp(0.0, 1.0))) {
        back = b.view(w, h, &mut photo_rng).unwrap_or(back);
    }
    if let (Some(backdrop), Some(&chin)) = (&backdrop, landmarks.get(8)) {
        backdrop.draw(&mut back, projected, (landmark_box(&landmarks).2, chin), &mut dress_rng);
    }
    let frame = finished(camera_effects(&render, &back, &mut rng), &landmarks, ranges, seed, index);
    let light = settings.light.coeffs.iter().take(4).flat_map(|c| c.iter().copied()).collect();
    Some(Scene { frame, landmarks, angles: [view.yaw.to_radians(), view.pitch.to_radians(), view.roll.to_radians()], light })
}
