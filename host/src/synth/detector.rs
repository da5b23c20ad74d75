//! Detector-like landmark noise: what a real landmark detector adds to the true points, so that a
//! synthetic set can be fitted with landmarks that resemble a detector's (`gpmm synth
//! --detector-noise`, written to `DIR/detector/`, read back with `gpmm bench-fit --landmarks-dir`).
//!
//! Not independent per point: a detector defines its points differently from the model (a fixed
//! offset per landmark, the same in every image of the set), jitters per image, and places the
//! jaw contour anywhere along the silhouette (a slide along the contour's tangent). All three
//! scale with the inter-ocular distance (outer eye corners, iBUG 36 and 45), so they are the
//! same relative error at every image size.

use super::stream;
use rand::RngExt;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

/// Jaw-contour landmarks of iBUG-68 (0-16).
const CONTOUR: usize = 17;
/// Stream tag of the noise (distinct from the identities' and views' streams).
const NOISE_TAG: u64 = 0x6465_7465_6374_6f72;

/// How much detector-like noise, as fractions of the inter-ocular distance.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DetectorNoise {
    /// σ of each landmark's fixed offset (x and y; the same in every image of the set).
    pub systematic: f32,
    /// σ of the per-image jitter of every point (x and y).
    pub jitter: f32,
    /// σ of the jaw points' slide along the contour.
    pub contour_slide: f32,
}

impl DetectorNoise {
    /// About 2 px RMSE at 128×128 with faces of 60-70 % of the image height (a face-mesh detector's
    /// 68-point subset measured 2.0 px on such images): offsets 3 %, jitter 2.5 %, jaw slide 6 %.
    pub const DEFAULT: Self = Self { systematic: 0.03, jitter: 0.025, contour_slide: 0.06 };
}

/// The landmarks a detector would report for an image of the set made with `seed`: `truth` (68
/// iBUG points, pixels) plus the set's fixed offsets, this image's jitter (its own stream, from
/// `identity` and `view`) and the jaw slide. Other point counts get offsets and jitter only.
pub fn detector_landmarks(truth: &[[f32; 2]], noise: &DetectorNoise, seed: u64, identity: u64, view: u64) -> Vec<[f32; 2]> {
    let iod = match (truth.get(36), truth.get(45)) {
        (Some(a), Some(b)) => (a[0] - b[0]).hypot(a[1] - b[1]),
        _ => 0.0,
    };
    let mut fixed = stream(seed ^ NOISE_TAG, u64::MAX, u64::MAX);
    let mut image = stream(seed ^ NOISE_TAG, identity, view);
    let normal = |r: &mut rand_xoshiro::Xoshiro256PlusPlus| -> f32 { r.sample(StandardNormal) };
    (0..truth.len())
        .map(|i| {
            let p = truth[i];
            let offset = [normal(&mut fixed), normal(&mut fixed)].map(|v| v * noise.systematic * iod);
            let jitter = [normal(&mut image), normal(&mut image)].map(|v| v * noise.jitter * iod);
            let slide = normal(&mut image) * noise.contour_slide * iod;
            let tangent = if truth.len() == 68 && i < CONTOUR {
                let (a, b) = (truth[i.saturating_sub(1)], truth[(i + 1).min(CONTOUR - 1)]);
                let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
                let len = dx.hypot(dy);
                if len > 0.0 {
                    [dx / len, dy / len]
                } else {
                    [0.0; 2]
                }
            } else {
                [0.0; 2]
            };
            [p[0] + offset[0] + jitter[0] + slide * tangent[0], p[1] + offset[1] + jitter[1] + slide * tangent[1]]
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn face() -> Vec<[f32; 2]> {
        // A rough iBUG-68 layout: jaw on a half circle, the rest inside; eye corners 36/45 40 px apart.
        let mut p: Vec<[f32; 2]> = (0..68).map(|i| [44.0 + (i % 10) as f32 * 4.0, 50.0 + (i / 10) as f32 * 4.0]).collect();
        for (i, q) in p.iter_mut().enumerate().take(CONTOUR) {
            let t = std::f32::consts::PI * i as f32 / 16.0;
            *q = [64.0 - 40.0 * t.cos(), 60.0 + 40.0 * t.sin()];
        }
        p[36] = [44.0, 55.0];
        p[45] = [84.0, 55.0];
        p
    }

    #[test]
    fn noise_is_deterministic_systematic_and_of_the_stated_size() {
        let truth = face();
        let n = DetectorNoise::DEFAULT;
        let a = detector_landmarks(&truth, &n, 7, 0, 0);
        assert_eq!(a, detector_landmarks(&truth, &n, 7, 0, 0), "deterministic for a seed");
        let b = detector_landmarks(&truth, &n, 7, 1, 0);
        assert_ne!(a, b, "each image jitters on its own");
        // The fixed offsets are shared: two images' errors correlate on the inner points.
        let err = |v: &[[f32; 2]]| -> Vec<f32> { v.iter().zip(&truth).skip(CONTOUR).map(|(p, q)| p[0] - q[0]).collect() };
        let (ea, eb) = (err(&a), err(&b));
        let dot: f32 = ea.iter().zip(&eb).map(|(x, y)| x * y).sum();
        assert!(dot > 0.0, "systematic offsets make the errors agree: {dot}");
        // RMSE of all points ~ IOD × sqrt(0.03² + 0.025² + jaw slide share): 1-3 px for a 40 px IOD.
        let rmse = (a.iter().zip(&truth).map(|(p, q)| (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sum::<f32>() / 68.0).sqrt();
        assert!((1.0..3.5).contains(&rmse), "rmse {rmse}");
        let none = DetectorNoise { systematic: 0.0, jitter: 0.0, contour_slide: 0.0 };
        assert_eq!(detector_landmarks(&truth, &none, 7, 0, 0), truth);
    }
}
