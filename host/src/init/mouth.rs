//! Open mouths painted into training frames. The scan's lips are closed; people in photos often
//! smile with their teeth showing or talk with the mouth open, and a network that has only seen
//! closed lips takes the bright teeth and the dark gap for other features (on the shared photos it
//! put the mouths of smiling faces on their teeth or their chins). Some scenes therefore open the
//! mouth: between the inner lip corners (iBUG 60 and 64) an almond of teeth and dark mouth is
//! drawn into the rendered frame, lit like the lips around it, and the inner lip landmarks move
//! onto its rims. The outer lip points stay: the lips look thinner, as they do in a smile.
//!
//! The mesh is too coarse at the lips for the teeth to be painted into vertex colours (an
//! opening a few millimetres high holds one row of vertices or none), so the almond is drawn in
//! frame pixels, its rims projected from the face's surface.

use crate::gp::model::GpModel;
use crate::init::almond::{mean_landmark, rim, Almond, Opening};
use crate::mesh::geometry::point_in_polygon;
use gpmm_core::geometry::Vec3;
use image::RgbaImage;
use rand::{Rng, RngExt};

/// Inner lip corners (iBUG), upper inner lip points, lower inner lip points.
const INNER_LIPS: ([usize; 2], [usize; 3], [usize; 3]) = ([60, 64], [61, 62, 63], [65, 66, 67]);
/// Chance that a scene's mouth opens.
const OPEN: f64 = 0.35;
/// Points along each rim of the drawn almond.
const RIM_POINTS: usize = 13;

/// The mouth of one model, ready to be opened in its frames.
#[derive(Debug, Clone)]
pub struct OpenMouth {
    mouth: Almond,
    /// Room above and below the shut line at the middle up to the outer lip points 51 and 57
    /// (half widths): an opening stays inside the lips.
    room: [f32; 2],
}

/// How one scene's mouth looks open.
#[derive(Debug, Clone, Copy)]
pub struct MouthLook {
    /// How far it opens.
    pub opening: Opening,
    /// Teeth albedo (linear RGB).
    teeth: Vec3,
    /// The dark inside of the mouth (linear RGB, already lit).
    dark: Vec3,
    /// Share of the opening the upper teeth fill from the top rim.
    upper_teeth: f32,
    /// Share of the opening the lower teeth fill from the bottom rim.
    lower_teeth: f32,
}

/// Distance from `p` to the segment `a`–`b`.
fn to_segment(p: [f32; 2], a: [f32; 2], b: [f32; 2]) -> f32 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 { (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / len2).clamp(0.0, 1.0) } else { 0.0 };
    (p[0] - a[0] - t * dx).hypot(p[1] - a[1] - t * dy)
}

impl OpenMouth {
    /// The mouth of `model` (`None` unless it has the 68 iBUG landmarks).
    pub fn of_model(model: &GpModel) -> Option<Self> {
        if model.landmarks.len() != 68 {
            return None;
        }
        let (corners, upper, lower) = INNER_LIPS;
        let mouth = Almond::of_model(model, corners, &upper, &lower)?;
        let (top, bottom) = (mouth.local(mean_landmark(model, 51)?), mouth.local(mean_landmark(model, 57)?));
        let room = [top[1] - mouth.shut(top[0]), mouth.shut(bottom[0]) - bottom[1]];
        if !(room.iter().all(|r| r.is_finite() && *r > 0.0)) {
            return None;
        }
        Some(Self { mouth, room })
    }

    /// Draws whether and how this scene's mouth is open; `None`: it stays shut.
    pub fn draw(&self, rng: &mut impl Rng) -> Option<MouthLook> {
        if !rng.random_bool(OPEN) {
            return None;
        }
        let upper = rng.random_range(0.4f32..0.6);
        // At most four fifths of the lips' own height above and below the shut line.
        let height = rng.random_range(0.25f32..0.9).min(0.8 * self.room[0] / upper).min(0.8 * self.room[1] / (1.0 - upper));
        let opening = Opening { height, upper };
        let level = rng.random_range(0.6f32..0.9);
        let teeth = [level, level * rng.random_range(0.92f32..0.98), level * rng.random_range(0.75f32..0.92)];
        let dark = [rng.random_range(0.03f32..0.1), rng.random_range(0.01f32..0.04), rng.random_range(0.01f32..0.04)];
        // Upper teeth in most open mouths, lower teeth in some, none in a few.
        let upper_teeth = if rng.random_bool(0.8) { rng.random_range(0.35f32..0.8) } else { 0.0 };
        let lower_teeth = if rng.random_bool(0.35) { rng.random_range(0.15f32..0.4) } else { 0.0 };
        Some(MouthLook { opening, teeth, dark, upper_teeth, lower_teeth })
    }

    /// The light falling on the lips: shaded colour over albedo, summed over the mouth's
    /// vertices; `shaded(v)` gives face vertex `v`'s shaded colour and albedo.
    pub fn irradiance(&self, shaded: impl Fn(u32) -> Option<(Vec3, Vec3)>) -> Vec3 {
        let (mut lit, mut albedo) = ([0.0f32; 3], [0.0f32; 3]);
        for &(v, [s, t]) in &self.mouth.vertices {
            if s.abs() > 1.0 || t.abs() > 0.5 {
                continue;
            }
            if let Some((c, a)) = shaded(v) {
                for k in 0..3 {
                    lit[k] += c[k];
                    albedo[k] += a[k];
                }
            }
        }
        std::array::from_fn(|k| if albedo[k] > 1e-6 { lit[k] / albedo[k] } else { 1.0 })
    }

    /// Draws the open mouth into `frame` (the linear render, alpha 0 off the face) under light
    /// `irradiance` and moves the inner lip landmarks of `landmarks` (iBUG order) onto its rims;
    /// `projected(v)` is face vertex `v` in frame pixels.
    pub fn paint(
        &self,
        look: &MouthLook,
        irradiance: Vec3,
        projected: impl Fn(u32) -> Option<[f32; 2]>,
        frame: &mut RgbaImage,
        landmarks: &mut [[f32; 2]],
    ) {
        let mut top = Vec::with_capacity(RIM_POINTS);
        let mut bottom = Vec::with_capacity(RIM_POINTS);
        for j in 0..RIM_POINTS {
            let s = -1.0 + 2.0 * j as f32 / (RIM_POINTS - 1) as f32;
            let (up, down) = self.mouth.rims(look.opening, s);
            match (self.mouth.project([s, up], &projected), self.mouth.project([s, down], &projected)) {
                (Some(a), Some(b)) => {
                    top.push(a);
                    bottom.push(b);
                }
                _ => return,
            }
        }
        let polygon: Vec<[f32; 2]> = top.iter().chain(bottom.iter().rev()).copied().collect();
        let outline: Vec<[f64; 2]> = polygon.iter().map(|p| p.map(f64::from)).collect();
        let (w, h) = frame.dimensions();
        let lo = polygon.iter().fold([f32::INFINITY; 2], |m, p| [m[0].min(p[0]), m[1].min(p[1])]);
        let hi = polygon.iter().fold([f32::NEG_INFINITY; 2], |m, p| [m[0].max(p[0]), m[1].max(p[1])]);
        if !(lo[0].is_finite() && hi[0].is_finite() && lo[1].is_finite() && hi[1].is_finite()) {
            return;
        }
        let (x0, x1) = (lo[0].floor().max(0.0) as u32, (hi[0].ceil().max(0.0) as u32).min(w));
        let (y0, y1) = (lo[1].floor().max(0.0) as u32, (hi[1].ceil().max(0.0) as u32).min(h));
        for y in y0..y1 {
            for x in x0..x1 {
                let p = [x as f32 + 0.5, y as f32 + 0.5];
                let pixel = frame.get_pixel_mut(x, y);
                if pixel[3] == 0 || !point_in_polygon(&outline, p.map(f64::from)) {
                    continue;
                }
                // Nearest rim segments: how far down the opening the pixel lies, and where along it.
                let (mut d_top, mut d_bottom, mut along) = (f32::INFINITY, f32::INFINITY, 0.0f32);
                for j in 0..RIM_POINTS - 1 {
                    let dt = to_segment(p, top[j], top[j + 1]);
                    if dt < d_top {
                        d_top = dt;
                        along = -1.0 + 2.0 * (j as f32 + 0.5) / (RIM_POINTS - 1) as f32;
                    }
                    d_bottom = d_bottom.min(to_segment(p, bottom[j], bottom[j + 1]));
                }
                let from_top = d_top / (d_top + d_bottom).max(1e-6);
                let tooth = from_top < look.upper_teeth || from_top > 1.0 - look.lower_teeth;
                let colour: Vec3 = if tooth {
                    // The teeth darken toward the corners, where the cheeks shade them.
                    let shade = 0.45 + 0.55 * rim(along);
                    std::array::from_fn(|k| look.teeth[k] * shade * irradiance[k])
                } else {
                    look.dark
                };
                for k in 0..3 {
                    pixel[k] = (colour[k].clamp(0.0, 1.0) * 255.0).round() as u8;
                }
            }
        }
        self.mouth.relabel(look.opening, &projected, landmarks);
    }
}
