//! Clothes and fuller hair for the heads of training scenes. The template is a bald bust with
//! bare shoulders; people in photos wear clothes, and their hair stands off the skull and often
//! falls past the ears. Without them the finder's box on the shared photos came out about twice
//! the face: a head with hair and a body below it is not what it was shown.
//! A dressed scene gets, from a random stream of its own: hair with volume (the covered scalp
//! pushed out along its normals, with strands of varying brightness), sometimes long hair hanging
//! behind the head, and clothes over the shoulders continued down to the frame's edge.

use crate::scene::head::{Hair, HeadContext, HeadedInstance};
use gpmm_core::geometry::Vec3;
use gpmm_host::gp::model::GpModel;
use gpmm_host::render::Instance;
use image::{Rgb, RgbImage};
use rand::{Rng, RngExt};

/// What a dressed head puts behind itself in the frame: long hair and a torso, drawn over the
/// background before the render is composited on it.
#[derive(Debug, Clone, Default)]
pub struct Backdrop {
    /// Long hair: its albedo, how far below the chin it falls (in landmark-box sizes), how much
    /// wider than the covered scalp it stands, and the head vertex ids it hangs from.
    hair: Option<(Vec3, f32, f32, Vec<u32>)>,
    /// Clothes: their albedo and the head vertex ids they cover.
    clothes: Option<(Vec3, Vec<u32>)>,
}

/// Albedos of clothes: dark suits, white shirts, greys, any colour.
fn clothes_tone(rng: &mut impl Rng) -> Vec3 {
    match rng.random_range(0..4) {
        0 => [rng.random_range(0.01f32..0.06), rng.random_range(0.01f32..0.06), rng.random_range(0.02f32..0.09)],
        1 => [rng.random_range(0.6f32..0.85); 3],
        2 => [rng.random_range(0.05f32..0.5); 3],
        _ => std::array::from_fn(|_| rng.random_range(0.02f32..0.7)),
    }
}

impl HeadContext {
    /// [`HeadContext::around`] dressed: the same head and short hair from `rng` (the same draws),
    /// then from `dress` hair for some of the heads that had none, volume and strands for the hair,
    /// clothes below a neckline, and the backdrop (long hair, torso) to draw behind the render.
    pub fn dressed_around(&self, model: &GpModel, face: &Instance, rng: &mut impl Rng, dress: &mut impl Rng) -> (HeadedInstance, Backdrop) {
        let n = face.positions.len();
        let short = self.draw_hair(rng);
        let mut headed = self.around_bare(model, face);
        let hair = short.or_else(|| if dress.random_bool(0.6) { self.draw_hair_always(dress) } else { None });
        let mut backdrop = Backdrop::default();
        if let Some(hair) = hair {
            // Strands: brightness varying across the head (around the vertical axis) and a little
            // along it; volume: the covered scalp pushed out by up to 35 mm (all of it above the
            // hairline, a third to all on the back of the head below it).
            let (freq, phase, depth) = (dress.random_range(0.15f32..0.6), dress.random_range(0.0f32..6.3), dress.random_range(0.1f32..0.5));
            let volume = dress.random_range(0.0f32..35.0);
            let tone = |i: usize| -> Vec3 {
                let p = self.positions[i];
                let s = (p[0].atan2(p[2]) * 40.0 * freq + phase).sin() * (p[1] * 0.05 + phase).cos();
                hair.tone.map(|c| (c * (1.0 + depth * s)).clamp(0.0, 1.0))
            };
            let mut covered = Vec::new();
            for i in self.paint_hair(&mut headed, n, hair, tone) {
                let lift = volume * ((self.positions[i][1] - hair.hairline + 25.0) / 25.0).clamp(0.3, 1.0);
                if let Some(p) = headed.instance.positions.get_mut(n + i) {
                    *p = std::array::from_fn(|k| p[k] + lift * self.normals[i][k]);
                }
                covered.push((n + i) as u32);
            }
            if dress.random_bool(0.45) {
                let (length, width) = (dress.random_range(0.1f32..1.6), dress.random_range(1.0f32..1.4));
                backdrop.hair = Some((hair.tone, length, width, covered));
            }
        }
        if dress.random_bool(0.85) {
            let tone = clothes_tone(dress);
            let (neck, vee) = (dress.random_range(15.0f32..70.0), dress.random_range(0.0f32..60.0));
            let mut covered = Vec::new();
            for (i, p) in self.positions.iter().enumerate() {
                let line = self.chin_y - neck - vee * (1.0 - p[0].abs() / 60.0).max(0.0);
                if p[1] < line {
                    if let Some(c) = headed.instance.albedos.get_mut(n + i) {
                        *c = tone;
                    }
                    covered.push((n + i) as u32);
                }
            }
            backdrop.clothes = Some((tone, covered));
        }
        (headed, backdrop)
    }

    /// Short hair for certain (the tone, hairline and back drawn as [`HeadContext::draw_hair`]
    /// does).
    fn draw_hair_always(&self, rng: &mut impl Rng) -> Option<Hair> {
        (0..8).find_map(|_| self.draw_hair(rng))
    }
}

impl Backdrop {
    /// Draws the backdrop into `back` (the scene's background, gamma-encoded): long hair as a
    /// rounded column behind the head's covered scalp, down past the chin by its length; the torso
    /// from the clothed vertices down to the frame's bottom edge. `projected` gives a vertex's
    /// frame position, `face_px` the landmark box's size, `chin` the chin's frame position.
    pub fn draw(
        &self,
        back: &mut RgbImage,
        projected: impl Fn(u32) -> Option<[f32; 2]>,
        (face_px, chin): (f32, [f32; 2]),
        rng: &mut impl Rng,
    ) {
        let level = rng.random_range(0.5f32..1.1);
        let encode = |c: Vec3, v: f32| Rgb(c.map(|x| ((x * level * v).clamp(0.0, 1.0).powf(1.0 / 2.2) * 255.0).round() as u8));
        let bounds = |ids: &[u32]| -> Option<[f32; 4]> {
            let mut b = [f32::INFINITY, f32::INFINITY, f32::NEG_INFINITY, f32::NEG_INFINITY];
            for p in ids.iter().filter_map(|&i| projected(i)) {
                b = [b[0].min(p[0]), b[1].min(p[1]), b[2].max(p[0]), b[3].max(p[1])];
            }
            (b[0] < b[2] && b[1] < b[3]).then_some(b)
        };
        let (w, h) = back.dimensions();
        if let Some((tone, ids)) = &self.clothes {
            if let Some([x0, y0, x1, _]) = bounds(ids) {
                // From the clothes' top (a little below, under the neckline) to the bottom edge,
                // as wide as the shoulders, widening a little downwards.
                let top = y0 + 0.25 * face_px;
                let (cx, half) = (0.5 * (x0 + x1), 0.5 * (x1 - x0));
                for y in (top.max(0.0) as u32)..h {
                    let spread = half * (1.0 + 0.15 * (y as f32 - top) / face_px.max(1.0));
                    let (a, b) = ((cx - spread).max(0.0) as u32, ((cx + spread).max(0.0) as u32).min(w));
                    for x in a..b {
                        back.put_pixel(x, y, encode(*tone, 0.8));
                    }
                }
            }
        }
        if let Some((tone, length, width, ids)) = &self.hair {
            if let Some([x0, y0, x1, _]) = bounds(ids) {
                let (cx, half) = (0.5 * (x0 + x1), 0.5 * (x1 - x0) * width);
                let bottom = chin[1] + length * face_px;
                let (freq, phase) = (rng.random_range(0.2f32..0.8), rng.random_range(0.0f32..6.3));
                for y in (y0.max(0.0) as u32)..(bottom.max(0.0) as u32).min(h) {
                    // Round at the top: the half-width grows over the first half-width of height.
                    let dy = (y as f32 - y0) / half.max(1.0);
                    let round = if dy < 1.0 { (1.0 - (1.0 - dy).powi(2)).max(0.0).sqrt() } else { 1.0 };
                    let (a, b) = ((cx - half * round).max(0.0) as u32, ((cx + half * round).max(0.0) as u32).min(w));
                    for x in a..b {
                        let strand = 1.0 + 0.3 * (x as f32 * freq + phase).sin() * (y as f32 * 0.05 + phase).cos();
                        back.put_pixel(x, y, encode(*tone, strand));
                    }
                }
            }
        }
    }
}
