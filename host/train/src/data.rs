//! Training samples: a rendered scene cut into the finder's letterboxed frame and the
//! initializer's crop exactly as the core cuts them at run time, with their targets.

use crate::scene::{face_free_frame, photo_face_frame, render_scene, Scene, SceneSource};
use gpmm_core::net::face::mirror_outputs;
use gpmm_core::net::face_box::landmark_box;
use gpmm_core::net::resample::{flip_rows, sample_rgb, Window};
use gpmm_host::render::Renderer;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, Normal};
use rand_xoshiro::Xoshiro256PlusPlus;
use rayon::prelude::*;

/// Sizes of the two networks' inputs and outputs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Geometry {
    /// Side of the finder's square input (px).
    pub frame_side: usize,
    /// Side of the finder's output grid (cells).
    pub grid: usize,
    /// Side of the initializer's crop (px).
    pub crop_side: usize,
    /// Crop side in face sizes.
    pub crop_margin: f32,
    /// Landmarks read.
    pub landmarks: usize,
    /// Light values read.
    pub light: usize,
}

impl Geometry {
    /// Length of the initializer's output.
    pub fn initializer_outputs(&self) -> usize {
        2 * self.landmarks + 3 + self.light
    }
}

/// One training sample.
#[derive(Debug, Clone)]
pub struct Sample {
    /// Finder input, `frame_side² × 3`, channel-last, `pixel − 128`.
    pub frame: Vec<i8>,
    /// The grid cell holding the face's centre.
    pub cell: usize,
    /// Centre within that cell (x, y in 0..1) and ln(face size / frame side).
    pub place: [f32; 3],
    /// Initializer input, `crop_side² × 3`.
    pub crop: Vec<i8>,
    /// Initializer targets: landmarks in crop coordinates (−1..1), yaw/pitch/roll, light.
    pub target: Vec<f32>,
}

/// Cuts a scene into a sample; `jitter` draws the crop's error around the true face box.
pub fn sample_of_scene(scene: &Scene, geo: &Geometry, jitter: &mut impl rand::Rng) -> Option<Sample> {
    let (w, h) = (scene.frame.width() as usize, scene.frame.height() as usize);
    let window = Window::letterbox(w, h, geo.frame_side);
    let mut frame = vec![0i8; geo.frame_side * geo.frame_side * 3];
    sample_rgb(scene.frame.as_raw(), w, h, window, geo.frame_side, &mut frame).ok()?;
    let (cx, cy, size) = landmark_box(&scene.landmarks);
    let (cell, place) = finder_target(window, [cx, cy, size], geo)?;
    let (crop, mut target) = initializer_crop(scene.frame.as_raw(), w, h, &scene.landmarks, geo, jitter)?;
    target.extend(scene.angles);
    target.extend(scene.light.iter().take(geo.light));
    (target.len() == geo.initializer_outputs()).then_some(Sample { frame, cell, place, crop, target })
}

/// The initializer's crop of a `w × h` RGB frame about the box of the face's `points` and the
/// points in it (−1..1 across the crop), as the core cuts it at run time from an imperfect box:
/// `jitter` moves the centre (standard deviation 0.06 face sizes) and scales the size (0.08 in
/// log). `None` without `geo.landmarks` points.
fn initializer_crop(
    rgb: &[u8],
    w: usize,
    h: usize,
    points: &[[f32; 2]],
    geo: &Geometry,
    jitter: &mut impl rand::Rng,
) -> Option<(Vec<i8>, Vec<f32>)> {
    if points.len() < geo.landmarks {
        return None;
    }
    let (cx, cy, size) = landmark_box(points);
    let n = Normal::new(0.0f32, 1.0).ok()?;
    let (shift, spread) = (0.06, 0.08);
    let (jx, jy, js) = (n.sample(jitter) * shift * size, n.sample(jitter) * shift * size, (n.sample(jitter) * spread).exp());
    let crop_window = Window::square(cx + jx, cy + jy, size * js * geo.crop_margin, geo.crop_side);
    let mut crop = vec![0i8; geo.crop_side * geo.crop_side * 3];
    sample_rgb(rgb, w, h, crop_window, geo.crop_side, &mut crop).ok()?;
    let half = geo.crop_side as f32 * 0.5;
    let mut target = Vec::with_capacity(geo.initializer_outputs());
    for p in points.iter().take(geo.landmarks) {
        let (a, b) = crop_window.from_source(p[0], p[1]);
        target.extend([a / half - 1.0, b / half - 1.0]);
    }
    Some((crop, target))
}

/// The finder's target for a face whose landmarks' box is `square` (centre x, y and side in
/// source pixels) in a frame letterboxed through `window`: its grid cell and the centre within
/// it and ln(size / frame side). `None` when the centre falls outside the grid.
fn finder_target(window: Window, [cx, cy, size]: [f32; 3], geo: &Geometry) -> Option<(usize, [f32; 3])> {
    let (u, v) = window.from_source(cx, cy);
    let cell_px = geo.frame_side as f32 / geo.grid as f32;
    let (gx, gy) = ((u / cell_px).floor(), (v / cell_px).floor());
    if !(gx >= 0.0 && gy >= 0.0 && gx < geo.grid as f32 && gy < geo.grid as f32 && size > 2.0) {
        return None;
    }
    let place = [u / cell_px - gx, v / cell_px - gy, (size / window.step / geo.frame_side as f32).ln()];
    Some((gy as usize * geo.grid + gx as usize, place))
}

/// Real faces `start..start + count` of the stream `seed` ([`crate::scene::photo_face_frame`]):
/// the frame and the finder's target, and, where the reference read the face's points, the
/// initializer's crop with those points as its target; a photo's pose and light are not known,
/// so their targets are NaN, which [`crate::train::output_loss`] leaves out. Empty without photos
/// of people.
pub fn photo_face_samples(source: SceneSource<'_>, geo: &Geometry, seed: u64, start: u64, count: u64) -> Vec<Sample> {
    (start..start + count)
        .into_par_iter()
        .filter_map(|i| {
            let view = photo_face_frame(source, seed, i)?;
            let (w, h) = (view.image.width() as usize, view.image.height() as usize);
            let window = Window::letterbox(w, h, geo.frame_side);
            let mut frame = vec![0i8; geo.frame_side * geo.frame_side * 3];
            sample_rgb(view.image.as_raw(), w, h, window, geo.frame_side, &mut frame).ok()?;
            let (cell, place) = finder_target(window, view.square, geo)?;
            let mut jitter = Xoshiro256PlusPlus::seed_from_u64(seed.wrapping_add(0x9E0) ^ i.wrapping_mul(0xA24B_AED4_963E_E407));
            let (crop, target) = match initializer_crop(view.image.as_raw(), w, h, &view.points, geo, &mut jitter) {
                Some((crop, mut target)) => {
                    target.resize(geo.initializer_outputs(), f32::NAN);
                    (crop, target)
                }
                None => (Vec::new(), Vec::new()),
            };
            Some(Sample { frame, cell, place, crop, target })
        })
        .collect()
}

/// Samples `start..start + count` of the stream drawn with `seed` (rendered in parallel; the
/// result depends on the seed and the indices only). Scenes that cannot be cut are skipped.
pub fn samples(source: SceneSource<'_>, geo: &Geometry, seed: u64, start: u64, count: u64) -> Vec<Sample> {
    (start..start + count)
        .into_par_iter()
        .map_init(Renderer::new, |renderer, i| {
            let scene = render_scene(source, seed, i, renderer)?;
            let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed.wrapping_add(0x5EED) ^ i.wrapping_mul(0xA24B_AED4_963E_E407));
            let _: u32 = rng.random();
            sample_of_scene(&scene, geo, &mut rng)
        })
        .filter_map(|s| s)
        .collect()
}

/// Face-free frames `start..start + count` of the stream `seed` ([`face_free_frame`]),
/// letterboxed into the finder's input as scenes are.
pub fn face_free_frames(source: SceneSource<'_>, geo: &Geometry, seed: u64, start: u64, count: u64) -> Vec<Vec<i8>> {
    (start..start + count)
        .into_par_iter()
        .filter_map(|i| {
            let img = face_free_frame(source, seed, i);
            let (w, h) = (img.width() as usize, img.height() as usize);
            let window = Window::letterbox(w, h, geo.frame_side);
            let mut frame = vec![0i8; geo.frame_side * geo.frame_side * 3];
            sample_rgb(img.as_raw(), w, h, window, geo.frame_side, &mut frame).ok()?;
            Some(frame)
        })
        .collect()
}

impl Sample {
    /// The initializer's half of the sample seen in a mirror: the crop flipped left-right and the
    /// target mirrored as the core mirrors a reading (`mirror_outputs`: iBUG pairs swapped, x, yaw,
    /// roll and the light's x coefficient negated). `None` unless the landmarks are the 68 iBUG
    /// points. The finder's half is kept.
    pub fn mirrored(&self, geo: &Geometry) -> Option<Sample> {
        if self.crop.len() != geo.crop_side * geo.crop_side * 3 || self.target.len() != geo.initializer_outputs() {
            return None;
        }
        let mut crop = self.crop.clone();
        flip_rows(&mut crop, geo.crop_side);
        let mut target = self.target.clone();
        mirror_outputs(&mut target, geo.landmarks).then(|| Sample {
            frame: self.frame.clone(),
            cell: self.cell,
            place: self.place,
            crop,
            target,
        })
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn sample(geo: &Geometry) -> Sample {
        let n = geo.crop_side * geo.crop_side * 3;
        Sample {
            frame: Vec::new(),
            cell: 0,
            place: [0.0; 3],
            crop: (0..n).map(|i| (i % 251) as i8).collect(),
            target: (0..geo.initializer_outputs()).map(|i| (i as f32 * 0.37).sin()).collect(),
        }
    }

    #[test]
    fn a_real_face_sample_targets_the_face_and_its_points() {
        use crate::scene::backgrounds::Backgrounds;
        use crate::scene::SceneRanges;
        use gpmm_host::detect::photos::ReferenceFace;
        use image::{Rgb, RgbImage};
        // A blue photo with a red square face whose 68 points span the square.
        let img = RgbImage::from_fn(900, 700, |x, y| {
            if (400..480).contains(&x) && (300..380).contains(&y) {
                Rgb([230, 30, 30])
            } else {
                Rgb([30, 30, 230])
            }
        });
        let mut points: Vec<[f32; 2]> = (0..68).map(|i| [400.0 + (i % 9) as f32 * 10.0, 300.0 + (i / 9) as f32 * 80.0 / 7.0]).collect();
        // The outer eye corners: 36 on the photo's left, 45 on its right.
        (points[36], points[45]) = ([410.0, 320.0], [470.0, 320.0]);
        let face = ReferenceFace { bbox: [405.0, 310.0, 475.0, 380.0], landmarks: Some(points) };
        let b = Backgrounds::from_labelled(vec![(img, vec![face])], 0.5);
        // Colours are checked below: no black and white looks, no masks over the red face.
        let ranges = SceneRanges { look_share: 0.0, occluders: false, ..SceneRanges::default() };
        let source = SceneSource { faces: &[], head: None, ranges: &ranges, backgrounds: Some(&b) };
        let geo = crate::train::geometry(68);
        let got = photo_face_samples(source, &geo, 4, 0, 40);
        assert!(got.len() >= 30, "{} of 40", got.len());
        let cell_px = geo.frame_side as f32 / geo.grid as f32;
        for s in &got {
            assert_eq!(s.crop.len(), geo.crop_side * geo.crop_side * 3);
            assert_eq!(s.target.len(), geo.initializer_outputs());
            let (points, rest) = s.target.split_at(2 * geo.landmarks);
            assert!(points.iter().all(|v| v.abs() < 1.3), "every point in or near the crop (jittered): {points:?}");
            assert!(rest.iter().all(|v| v.is_nan()), "pose and light unknown");
            // Mirrored views swap the partners: 36 stays left of 45.
            assert!(points[72] < points[90] - 0.3, "36 at x {} left of 45 at {}", points[72], points[90]);
            // The crop's centre is on the red face.
            let c = (geo.crop_side / 2 * geo.crop_side + geo.crop_side / 2) * 3;
            assert!(s.crop[c] as i32 > s.crop[c + 2] as i32 + 60, "crop centre red: {:?}", &s.crop[c..c + 3]);
            let (gx, gy) = ((s.cell % geo.grid) as f32, (s.cell / geo.grid) as f32);
            let (u, v) = (((gx + s.place[0]) * cell_px) as usize, ((gy + s.place[1]) * cell_px) as usize);
            let px = &s.frame[(v * geo.frame_side + u) * 3..(v * geo.frame_side + u) * 3 + 3];
            assert!(px[0] as i32 > px[2] as i32 + 60, "the target's centre is on the red face: {px:?}");
            let size = s.place[2].exp() * geo.frame_side as f32;
            assert!(size > 5.0 && size < 0.9 * geo.frame_side as f32, "face side {size} px of the frame");
        }
        // Without photos of people there are none.
        let plain = Backgrounds::from_photos(vec![RgbImage::new(300, 300)], 0.5);
        let source = SceneSource { faces: &[], head: None, ranges: &ranges, backgrounds: Some(&plain) };
        assert!(photo_face_samples(source, &geo, 4, 0, 10).is_empty());
    }

    #[test]
    fn a_mirror_image_of_a_mirror_image_is_the_sample() {
        let geo = crate::train::geometry(68);
        let s = sample(&geo);
        let m = s.mirrored(&geo).unwrap();
        assert_ne!(m.crop, s.crop);
        assert_ne!(m.target, s.target);
        let back = m.mirrored(&geo).unwrap();
        assert_eq!(back.crop, s.crop);
        assert_eq!(back.target, s.target);
    }

    #[test]
    fn a_mirror_swaps_the_eye_corners_and_flips_the_pixels() {
        let geo = crate::train::geometry(68);
        let s = sample(&geo);
        let m = s.mirrored(&geo).unwrap();
        // Outer eye corners 36 and 45 trade places, x negated.
        assert_eq!(m.target[72], -s.target[90]);
        assert_eq!(m.target[91], s.target[73]);
        // The nose tip (30) is its own mirror image.
        assert_eq!(m.target[60], -s.target[60]);
        // Yaw and roll change sign, pitch does not; the light's x coefficient changes sign.
        assert_eq!(m.target[136], -s.target[136]);
        assert_eq!(m.target[137], s.target[137]);
        assert_eq!(m.target[138], -s.target[138]);
        assert_eq!(m.target[139 + 9..139 + 12], s.target[139 + 9..139 + 12].iter().map(|v| -v).collect::<Vec<_>>()[..]);
        assert_eq!(m.target[139..139 + 9], s.target[139..139 + 9]);
        // Pixel (row 5, column 0) is the source's (row 5, last column).
        let side = geo.crop_side;
        assert_eq!(m.crop[5 * side * 3..5 * side * 3 + 3], s.crop[(5 * side + side - 1) * 3..(5 * side + side) * 3]);
        assert!(s.mirrored(&crate::train::geometry(5)).is_none());
    }
}
