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

use crate::fit::FitRunError;
use crate::gp::model::GpModel;
use crate::mesh::align::Similarity;
use crate::synth::{SynthError, SynthOptions, SynthWorld};

/// The iBUG-68 points used for the alignment: all but the jaw contour (0–16).
pub const ALIGNED_LANDMARKS: std::ops::Range<usize> = 17..68;

/// Why a pose could not be put into a model's or a face's frame.
#[derive(Debug, thiserror::Error)]
pub enum FrameError {
    /// The model does not have the 68 iBUG landmarks.
    #[error("the model has {0} landmarks, not the 68 of iBUG-68")]
    Landmarks(usize),
    /// A landmark refers to a vertex past its mesh.
    #[error("{mesh} landmark {landmark} is vertex {vertex}, past the mesh")]
    PastMesh {
        /// Which mesh: "model" or "world".
        mesh: &'static str,
        /// The landmark number.
        landmark: usize,
        /// Its vertex.
        vertex: usize,
    },
    /// The world of the set's options could not be loaded (the error names the file).
    #[error(transparent)]
    World(#[from] SynthError),
    /// The two mean faces' landmarks admit no similarity transform.
    #[error("the mean faces' landmarks cannot be aligned")]
    Alignment,
    /// The landmarks define no face frame.
    #[error("{0}")]
    Frame(&'static str),
    /// The model cannot be fitted.
    #[error(transparent)]
    Model(#[from] FitRunError),
    /// The core refused the fitted shape's coefficients.
    #[error("{0}")]
    Shape(gpmm_core::error::FitError),
}

/// The rotation `R₀` (rows) with `p_world_mean ≈ s R₀ p_model_mean + t` on the inner landmarks.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelFrame {
    rotation: [[f64; 3]; 3],
}

impl ModelFrame {
    /// Aligns `model`'s mean to the mean face of the world of `options` (the set's `truth.json`
    /// options: the ICT data must be where they say). Errors name what is missing.
    pub fn new(model: &GpModel, options: &SynthOptions) -> Result<Self, FrameError> {
        if model.landmarks.len() != 68 {
            return Err(FrameError::Landmarks(model.landmarks.len()));
        }
        let mean = &model.shape.mean;
        let src: Vec<[f64; 3]> = ALIGNED_LANDMARKS
            .map(|k| {
                let v = model.landmarks[k] as usize;
                mean.get(v).map(|p| p.map(f64::from)).ok_or(FrameError::PastMesh { mesh: "model", landmark: k, vertex: v })
            })
            .collect::<Result<_, _>>()?;
        let world = SynthWorld::load(options)?;
        let (positions, _) = world.mean_face();
        let dst: Vec<[f64; 3]> = ALIGNED_LANDMARKS
            .map(|k| {
                let v = world.landmarks()[k] as usize;
                positions.get(v).map(|p| p.map(f64::from)).ok_or(FrameError::PastMesh { mesh: "world", landmark: k, vertex: v })
            })
            .collect::<Result<_, _>>()?;
        let s = Similarity::fit(&src, &dst).ok_or(FrameError::Alignment)?;
        Ok(Self { rotation: s.rot })
    }

    /// The true yaw, pitch, roll (degrees) in the model's frame, given the truth in the world's face frame.
    pub fn truth_in_model_frame(&self, truth_deg: [f32; 3]) -> [f32; 3] {
        compose_deg(truth_deg, &self.rotation)
    }
}

/// The fit's yaw, pitch, roll (radians) turned to the fitted face's own iBUG frame
/// ([`crate::mesh::template::ibug_frame`] of the fitted shape's 68 landmarks, the rule `gpmm
/// synth` defines its truth by; see [`pose_of_face_frame`]).
pub fn fit_in_face_frame(model: &GpModel, shape_coeffs: &[f32], fit_rad: [f32; 3]) -> Result<[f32; 3], FrameError> {
    pose_of_face_frame(&fitted_landmarks(model, shape_coeffs)?, fit_rad)
}

/// The 68 iBUG landmarks of `model`'s shape with `shape_coeffs` (model coordinates, mm): the
/// landmark vertices only, as the fitter computes them.
pub fn fitted_landmarks(model: &GpModel, shape_coeffs: &[f32]) -> Result<[[f64; 3]; 68], FrameError> {
    if model.landmarks.len() != 68 {
        return Err(FrameError::Landmarks(model.landmarks.len()));
    }
    let mut lm = [[0.0f32; 3]; 68];
    crate::fit::morphable(model)?.landmark_positions(shape_coeffs, &mut lm).map_err(FrameError::Shape)?;
    Ok(lm.map(|p| p.map(f64::from)))
}

/// The yaw, pitch, roll (radians) of the iBUG frame of landmarks `lm` (model coordinates) when
/// the model is turned by `pose_rad`: `R · Aᵀ`, with `A` the frame's axes (rows) in model
/// coordinates.
pub fn pose_of_face_frame(lm: &[[f64; 3]], pose_rad: [f32; 3]) -> Result<[f32; 3], FrameError> {
    let axes = crate::mesh::template::ibug_frame(lm).map_err(FrameError::Frame)?.axes;
    let transposed = [0, 1, 2].map(|i| [axes[0][i], axes[1][i], axes[2][i]]);
    Ok(compose_deg(pose_rad.map(f32::to_degrees), &transposed).map(f32::to_radians))
}

/// Euler angles (degrees) of `R(angles) · r0`.
fn compose_deg(angles_deg: [f32; 3], r0: &[[f64; 3]; 3]) -> [f32; 3] {
    let [yaw, pitch, roll] = angles_deg.map(f32::to_radians);
    let r = gpmm_core::render::Pose { yaw, pitch, roll, translation: [0.0; 3] }.rotation();
    let m = gpmm_core::geometry::mat_mul(&r, &r0.map(|row| row.map(|v| v as f32)));
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

    /// 68 landmarks in their own iBUG frame: mirror pairs symmetric about x = 0, the other
    /// points on the midline, chin (8) straight below the nose bridge (27).
    fn landmarks_in_own_frame() -> Vec<[f64; 3]> {
        let mut lm: Vec<[f64; 3]> = (0..68).map(|i| [0.0, -50.0 + 1.5 * i as f64, 5.0 + (i % 7) as f64]).collect();
        for (k, &(l, r)) in crate::mesh::template::IBUG68_MIRROR_PAIRS.iter().enumerate() {
            let (y, z) = (-40.0 + 3.0 * k as f64, 10.0 + (k % 5) as f64);
            lm[l] = [-(20.0 + k as f64), y, z];
            lm[r] = [20.0 + k as f64, y, z];
        }
        lm[8] = [0.0, -60.0, 10.0];
        lm[27] = [0.0, 40.0, 10.0];
        lm
    }

    #[test]
    fn a_face_in_its_own_frame_keeps_the_pose_and_a_tilted_one_adds_its_tilt() {
        let lm = landmarks_in_own_frame();
        let pose = [30f32.to_radians(), -4f32.to_radians(), 2f32.to_radians()];
        let same = pose_of_face_frame(&lm, pose).unwrap().map(f32::to_degrees);
        assert!(same.iter().zip([30.0, -4.0, 2.0]).all(|(a, b)| (a - b).abs() < 1e-3), "{same:?}");
        // The same face tilted 10° about x (forehead toward the camera, as in a nod): its frame is
        // the model's turned by Rx(10°), so a fit turned by yaw 30° alone shows a face frame at
        // yaw 30°, pitch 10°.
        let t = 10f64.to_radians();
        let tilted: Vec<[f64; 3]> = lm.iter().map(|p| [p[0], t.cos() * p[1] - t.sin() * p[2], t.sin() * p[1] + t.cos() * p[2]]).collect();
        let a = pose_of_face_frame(&tilted, [30f32.to_radians(), 0.0, 0.0]).unwrap().map(f32::to_degrees);
        assert!((a[0] - 30.0).abs() < 1e-3 && (a[1] - 10.0).abs() < 1e-3 && a[2].abs() < 1e-3, "{a:?}");
        // Landmarks with no left-right direction are refused, not a panic.
        assert!(pose_of_face_frame(&[[0.0; 3]; 68], pose).is_err());
    }
}
