//! Open eyes painted over the template's closed ones in training scenes. The template scan was
//! captured with its eyes shut, so every face a model built from it renders has them shut, while
//! faces in photos mostly have them open: a dark iris in a light sclera, framed by lash lines. A
//! network that has only seen shut lids reads an open eye's dark opening as a crease and puts the
//! eye (and the brows above it) too low. Here each scene may open the eyes: the albedo of the face
//! vertices inside an almond between the eye corners is repainted (sclera, iris, pupil, lash line),
//! and the lid landmarks follow the painted lids, so the labels still say where the lids are.
//! Each eye is an [`Almond`] between its corners (`s`, `t` in half eye widths).

use crate::scene::almond::{rim, Almond, Opening};
use gpmm_core::geometry::Vec3;
use gpmm_host::gp::model::GpModel;
use rand::{Rng, RngExt};

/// Each eye's corners (iBUG), upper lid points and lower lid points.
const EYES: [([usize; 2], [usize; 2], [usize; 2]); 2] = [([36, 39], [37, 38], [40, 41]), ([42, 45], [43, 44], [46, 47])];
/// Chance that a scene's eyes stay shut as in the scan (blinks, squints, smiles).
const SHUT: f64 = 0.2;

/// The eyes of one model, ready to be opened in its instances.
#[derive(Debug, Clone)]
pub struct OpenEyes {
    eyes: Vec<Almond>,
}

impl OpenEyes {
    /// The eye regions of `model` (`None` unless it has the 68 iBUG landmarks).
    pub fn of_model(model: &GpModel) -> Option<Self> {
        if model.landmarks.len() != 68 {
            return None;
        }
        let eyes = EYES.iter().map(|(corners, upper, lower)| Almond::of_model(model, *corners, upper, lower)).collect::<Option<_>>()?;
        Some(Self { eyes })
    }

    /// Face vertices near each eye (for tests and reports).
    pub fn region_sizes(&self) -> Vec<usize> {
        self.eyes.iter().map(|e| e.vertices.len()).collect()
    }

    /// Draws whether and how this scene's eyes are open and repaints the face's `albedos` (the
    /// model's vertex order) accordingly; `None`: they stay shut.
    pub fn paint(&self, albedos: &mut [Vec3], rng: &mut impl Rng) -> Option<Opening> {
        if rng.random_bool(SHUT) {
            return None;
        }
        let opening = Opening { height: rng.random_range(0.45f32..0.9), upper: rng.random_range(0.5f32..0.7) };
        // Iris colours (linear albedo): dark brown, brown, hazel, blue-grey, green.
        let irises = [[0.03f32, 0.016, 0.008], [0.08, 0.04, 0.018], [0.12, 0.085, 0.04], [0.09, 0.12, 0.15], [0.07, 0.09, 0.05]];
        let iris = irises[rng.random_range(0..irises.len())].map(|c| c * rng.random_range(0.6f32..1.5));
        let sclera_level = rng.random_range(0.35f32..0.75);
        let sclera = [sclera_level, sclera_level * rng.random_range(0.9f32..1.0), sclera_level * rng.random_range(0.85f32..1.0)];
        let iris_r = rng.random_range(0.35f32..0.55);
        let pupil_r = iris_r * rng.random_range(0.25f32..0.5);
        let gaze = [rng.random_range(-0.3f32..0.3), rng.random_range(-0.1f32..0.1)];
        let lash = rng.random_range(0.25f32..0.8);
        for eye in &self.eyes {
            // Both eyes' `s` run along the model's +x, so one gaze moves both irises alike.
            let gaze_s = gaze[0];
            for &(v, [s, t]) in &eye.vertices {
                let Some(a) = albedos.get_mut(v as usize) else { continue };
                let (top, bottom) = eye.rims(opening, s);
                if s.abs() >= 1.0 {
                    continue;
                }
                if t <= top && t >= bottom {
                    let centre_t = eye.shut(gaze_s) + opening.height * (opening.upper - 0.5) * rim(gaze_s) + gaze[1] * opening.height;
                    let d = ((s - gaze_s).powi(2) + (t - centre_t).powi(2)).sqrt();
                    *a = if d < pupil_r {
                        [0.01; 3]
                    } else if d < iris_r {
                        iris
                    } else {
                        // The sclera darkens toward the corners and under the upper lid.
                        let shade = (0.55 + 0.45 * rim(s)) * (0.7 + 0.3 * ((top - t) / (0.3 * opening.height)).clamp(0.0, 1.0));
                        sclera.map(|c| c * shade)
                    };
                } else if t > top && t < top + 0.12 {
                    *a = a.map(|c| c * lash);
                }
            }
        }
        Some(opening)
    }

    /// Moves the lid landmarks of `landmarks` (frame pixels, iBUG order) onto the painted lids:
    /// `projected(v)` is face vertex `v` in frame pixels.
    pub fn relabel_lids(&self, opening: Opening, projected: impl Fn(u32) -> Option<[f32; 2]>, landmarks: &mut [[f32; 2]]) {
        for eye in &self.eyes {
            eye.relabel(opening, &projected, landmarks);
        }
    }
}
