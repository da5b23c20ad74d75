//! The true pose of a `gpmm synth` image expressed in the fitted model's own frame.
//!
//! `gpmm synth` gives each ICT identity's pose relative to that identity's iBUG face frame
//! ([`crate::mesh::template::ibug_frame`]: x from the mirror pairs, jaw included; y from the chin
//! to the nose bridge), and `gpmm build` puts the template in its own. Two faces of different
//! proportions sit differently in frames defined that way (a chin further forward tilts "up"; an
//! asymmetric jaw turns "right"), so even a perfect fit differs from the truth by a rotation that
//! comes from the two face models, not from the fitter. Here that rotation is the least-squares
//! one taking the model's mean inner landmarks (iBUG 17–67; the jaw contour left out: its points
//! are not the same anatomy on two faces) onto the world's mean face's (the ICT neutral): one
//! rotation `R₀` per model and world, the truth in the model's frame being `R · R₀`. (Aligning to
//! each identity instead was measured too: it moves the truth by identity-dependent amounts the
//! fit does not follow, widening the pitch spread on the test set from 1.5–1.8° to 1.8–2.1°.)

use crate::eval::synth::{SynthOptions, SynthWorld};
use crate::gp::model::GpModel;
use crate::mesh::align::Similarity;

/// The iBUG-68 points used for the alignment: all but the jaw contour (0–16).
pub const ALIGNED_LANDMARKS: std::ops::Range<usize> = 17..68;

/// The rotation `R₀` (rows) with `p_world_mean ≈ s R₀ p_model_mean + t` on the inner landmarks.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelFrame {
    rotation: [[f64; 3]; 3],
}

impl ModelFrame {
    /// Aligns `model`'s mean to the mean face of the world of `options` (the set's `truth.json`
    /// options: the ICT data must be where they say). Errors name what is missing.
    pub fn new(model: &GpModel, options: &SynthOptions) -> Result<Self, String> {
        if model.landmarks.len() != 68 {
            return Err(format!("the model has {} landmarks, not the 68 of iBUG-68", model.landmarks.len()));
        }
        let mean = &model.shape.mean;
        let src: Vec<[f64; 3]> = ALIGNED_LANDMARKS
            .map(|k| {
                let v = model.landmarks[k] as usize;
                mean.get(v).map(|p| p.map(f64::from)).ok_or_else(|| format!("model landmark {k} is vertex {v}, past the mesh"))
            })
            .collect::<Result<_, _>>()?;
        let world = SynthWorld::load(options).map_err(|e| e.to_string())?;
        let (positions, _) = world.mean_face();
        let dst: Vec<[f64; 3]> = ALIGNED_LANDMARKS
            .map(|k| {
                let v = world.landmarks()[k] as usize;
                positions.get(v).map(|p| p.map(f64::from)).ok_or_else(|| format!("world landmark {k} is vertex {v}, past the mesh"))
            })
            .collect::<Result<_, _>>()?;
        let s = Similarity::fit(&src, &dst).ok_or("the mean faces' landmarks cannot be aligned")?;
        Ok(Self { rotation: s.rot })
    }

    /// The true yaw, pitch, roll (degrees) in the model's frame, given the truth in the world's face frame.
    pub fn truth_in_model_frame(&self, truth_deg: [f32; 3]) -> [f32; 3] {
        compose_deg(truth_deg, &self.rotation)
    }
}

/// Euler angles (degrees) of `R(angles) · r0`.
fn compose_deg(angles_deg: [f32; 3], r0: &[[f64; 3]; 3]) -> [f32; 3] {
    let [yaw, pitch, roll] = angles_deg.map(f32::to_radians);
    let r = gpmm_core::Pose { yaw, pitch, roll, translation: [0.0; 3] }.rotation();
    let m = gpmm_core::render::pose::mat_mul(&r, &r0.map(|row| row.map(|v| v as f32)));
    crate::photo::euler_angles(&m.map(|row| row.map(f64::from))).map(|a| a.to_degrees() as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn composing_with_the_identity_keeps_the_angles_and_a_yaw_adds() {
        let id = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let a = compose_deg([30.0, -4.0, 2.0], &id);
        assert!(a.iter().zip([30.0, -4.0, 2.0]).all(|(x, y)| (x - y).abs() < 1e-4), "{a:?}");
        // R₀ = Ry(1°): with no pitch or roll, yaws add.
        let t = 1f64.to_radians();
        let ry = [[t.cos(), 0.0, t.sin()], [0.0, 1.0, 0.0], [-t.sin(), 0.0, t.cos()]];
        let b = compose_deg([30.0, 0.0, 0.0], &ry);
        assert!((b[0] - 31.0).abs() < 1e-4 && b[1].abs() < 1e-4 && b[2].abs() < 1e-4, "{b:?}");
    }
}
