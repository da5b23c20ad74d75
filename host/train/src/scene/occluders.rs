//! Things people wear over their faces, drawn over a training frame from the face's 68 points:
//! dark glasses and face masks. Neither the scan nor the photos of people show many, and a finder
//! that never saw one reads a face in dark glasses or a mask as no face. The points keep their
//! places under the occluder: the initializer learns where the hidden ones are.

use gpmm_host::mesh::geometry::point_in_polygon;
use image::{Rgb, RgbImage};
use rand::{Rng, RngExt};

/// The share of faces given dark glasses.
pub const GLASSES_SHARE: f64 = 0.1;
/// The share of faces given a face mask.
pub const MASK_SHARE: f64 = 0.05;
/// The points a face needs for occluders (iBUG-68).
const POINTS: usize = 68;

/// Draws dark glasses over the eyes of the face at `points` ([`GLASSES_SHARE`] of calls) and,
/// independently, a mask over its mouth and chin ([`MASK_SHARE`]). Faces without 68 finite points
/// are left alone.
pub fn draw_occluders(frame: &mut RgbImage, points: &[[f32; 2]], rng: &mut impl Rng) {
    if points.len() != POINTS || points.iter().flatten().any(|v| !v.is_finite()) {
        return;
    }
    if rng.random_bool(GLASSES_SHARE) {
        glasses(frame, points, rng);
    }
    if rng.random_bool(MASK_SHARE) {
        mask(frame, points, rng);
    }
}

/// Two dark lenses around the eyes (points 36–41 and 42–47) and a bridge between them.
fn glasses(frame: &mut RgbImage, points: &[[f32; 2]], rng: &mut impl Rng) {
    let tone = rng.random_range(5u8..60);
    let tint = [rng.random_range(0u8..15), rng.random_range(0u8..15), rng.random_range(0u8..25)];
    let colour = Rgb(tint.map(|t| tone.saturating_add(t)));
    let scale = rng.random_range(1.3f32..1.8);
    let eye_distance = distance(centre(&points[36..42]), centre(&points[42..48])).max(1.0);
    for eye in [&points[36..42], &points[42..48]] {
        let c = centre(eye);
        let half_w = 0.5 * distance(eye[0], eye[3]).max(0.15 * eye_distance) * scale;
        let half_h = half_w * rng.random_range(0.65f32..0.9);
        fill(frame, colour, |x, y| ((x - c[0]) / half_w).powi(2) + ((y - c[1]) / half_h).powi(2) <= 1.0, bounds(c, half_w, half_h));
    }
    let (a, b) = (points[39], points[42]);
    let thickness = (0.04 * eye_distance).max(1.0);
    let mid = [(a[0] + b[0]) * 0.5, (a[1] + b[1]) * 0.5];
    let reach = distance(a, b) * 0.5 + thickness;
    fill(frame, colour, |x, y| segment_distance([x, y], a, b) <= thickness, bounds(mid, reach, reach));
}

/// A mask of one colour from the nose's middle (point 29) down over the jaw line (points 1–15).
fn mask(frame: &mut RgbImage, points: &[[f32; 2]], rng: &mut impl Rng) {
    let colours = [[235, 238, 240], [150, 190, 225], [30, 30, 35], [200, 200, 195]];
    let base = colours[rng.random_range(0..colours.len())];
    let shade = rng.random_range(0.75f32..1.05);
    let colour = Rgb(base.map(|v: i32| (v as f32 * shade).clamp(0.0, 255.0) as u8));
    let corners: Vec<[f32; 2]> = points[1..16].iter().chain([&points[29]]).copied().collect();
    let outline: Vec<[f64; 2]> = corners.iter().map(|p| p.map(f64::from)).collect();
    let (lo, hi) = corners
        .iter()
        .fold(([f32::MAX; 2], [f32::MIN; 2]), |(lo, hi), p| ([lo[0].min(p[0]), lo[1].min(p[1])], [hi[0].max(p[0]), hi[1].max(p[1])]));
    let covered = |x: f32, y: f32| point_in_polygon(&outline, [f64::from(x), f64::from(y)]);
    fill(frame, colour, covered, [lo[0], lo[1], hi[0], hi[1]]);
}

/// The pixel box around `c` reaching `rx`, `ry`.
fn bounds(c: [f32; 2], rx: f32, ry: f32) -> [f32; 4] {
    [c[0] - rx, c[1] - ry, c[0] + rx, c[1] + ry]
}

/// Paints `colour` on the pixels of `area` (x0, y0, x1, y1; clipped to the frame) whose centres
/// satisfy `covered`.
fn fill(frame: &mut RgbImage, colour: Rgb<u8>, covered: impl Fn(f32, f32) -> bool, area: [f32; 4]) {
    let (w, h) = frame.dimensions();
    let clip = |v: f32, n: u32| if v.is_finite() { v.floor().clamp(0.0, n as f32) as u32 } else { 0 };
    let (x0, y0, x1, y1) = (clip(area[0], w), clip(area[1], h), clip(area[2] + 1.0, w), clip(area[3] + 1.0, h));
    for y in y0..y1 {
        for x in x0..x1 {
            if covered(x as f32 + 0.5, y as f32 + 0.5) {
                frame.put_pixel(x, y, colour);
            }
        }
    }
}

/// The mean of `points`.
fn centre(points: &[[f32; 2]]) -> [f32; 2] {
    let n = points.len().max(1) as f32;
    let s = points.iter().fold([0.0f32; 2], |a, p| [a[0] + p[0], a[1] + p[1]]);
    [s[0] / n, s[1] / n]
}

/// Euclidean distance.
fn distance(a: [f32; 2], b: [f32; 2]) -> f32 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// Distance from `p` to the segment `a`–`b`.
fn segment_distance(p: [f32; 2], a: [f32; 2], b: [f32; 2]) -> f32 {
    let d = [b[0] - a[0], b[1] - a[1]];
    let len2 = d[0] * d[0] + d[1] * d[1];
    let t = if len2 > 0.0 { (((p[0] - a[0]) * d[0] + (p[1] - a[1]) * d[1]) / len2).clamp(0.0, 1.0) } else { 0.0 };
    distance(p, [a[0] + t * d[0], a[1] + t * d[1]])
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_xoshiro::Xoshiro256PlusPlus;

    /// A frontal face's 68 points, roughly, in a 200 × 200 frame: jaw, brows, nose, eyes, mouth.
    fn face() -> Vec<[f32; 2]> {
        let mut p = vec![[0.0f32; 2]; POINTS];
        for (i, q) in p.iter_mut().enumerate().take(17) {
            let t = std::f32::consts::PI * i as f32 / 16.0;
            *q = [100.0 - 60.0 * t.cos(), 90.0 + 70.0 * t.sin()];
        }
        for (i, q) in p.iter_mut().enumerate().skip(17).take(10) {
            *q = [50.0 + 11.0 * (i - 17) as f32, 70.0];
        }
        for (i, q) in p.iter_mut().enumerate().skip(27).take(9) {
            *q = [100.0, 85.0 + 5.0 * (i - 27) as f32];
        }
        for (e, cx) in [(36, 75.0f32), (42, 125.0)] {
            for k in 0..6 {
                let t = std::f32::consts::TAU * k as f32 / 6.0;
                p[e + k] = [cx - 12.0 * t.cos(), 88.0 + 5.0 * t.sin()];
            }
        }
        for (i, q) in p.iter_mut().enumerate().skip(48) {
            let t = std::f32::consts::TAU * (i - 48) as f32 / 20.0;
            *q = [100.0 - 22.0 * t.cos(), 135.0 + 8.0 * t.sin()];
        }
        p
    }

    fn dark(img: &RgbImage, x: u32, y: u32) -> bool {
        img.get_pixel(x, y).0.iter().all(|&v| v < 90)
    }

    #[test]
    fn glasses_cover_the_eyes_and_a_mask_the_mouth_but_not_the_forehead() {
        let points = face();
        let white = RgbImage::from_pixel(200, 200, Rgb([255, 255, 255]));
        let (mut with_glasses, mut with_mask) = (0, 0);
        for seed in 0..400 {
            let mut img = white.clone();
            draw_occluders(&mut img, &points, &mut Xoshiro256PlusPlus::seed_from_u64(seed));
            if dark(&img, 75, 88) {
                assert!(dark(&img, 125, 88) && dark(&img, 100, 88), "seed {seed}: one lens or no bridge");
                with_glasses += 1;
            }
            if *img.get_pixel(100, 135) != Rgb([255, 255, 255]) {
                assert!(*img.get_pixel(100, 150) != Rgb([255, 255, 255]), "seed {seed}: the mask misses the chin");
                with_mask += 1;
            }
            assert_eq!(*img.get_pixel(100, 30), Rgb([255, 255, 255]), "seed {seed}: the forehead was painted");
        }
        assert!((20..=60).contains(&with_glasses), "{with_glasses} of 400 with glasses");
        assert!((6..=35).contains(&with_mask), "{with_mask} of 400 with masks");
    }

    #[test]
    fn faces_without_68_finite_points_and_points_off_the_frame_are_safe() {
        let white = RgbImage::from_pixel(50, 40, Rgb([255, 255, 255]));
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(1);
        let mut img = white.clone();
        draw_occluders(&mut img, &face()[..60], &mut rng);
        let mut nan = face();
        nan[40] = [f32::NAN, 1.0];
        draw_occluders(&mut img, &nan, &mut rng);
        assert_eq!(img, white);
        // The face lies mostly beyond this small frame: drawing clips, never panics.
        for seed in 0..100 {
            draw_occluders(&mut img, &face(), &mut Xoshiro256PlusPlus::seed_from_u64(seed));
        }
    }
}
