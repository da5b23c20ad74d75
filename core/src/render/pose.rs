//! Rigid pose of the model in camera space: Euler angles plus a translation.
//!
//! Conventions (shared with scalismo-faces' `Pose`/`RenderTransforms.modelTransform`):
//! - Model space: x to the image right in a frontal view, y up, z toward the camera, millimetres.
//! - Camera space: the camera sits at the origin looking down −z with y up (see [`crate::render::camera`]).
//! - `p_camera = R · p_model + t` with `R = Rz(roll) · Ry(yaw) · Rx(pitch)`: pitch is applied first,
//!   then yaw, then roll. All rotations are right-handed (counter-clockwise looking down the axis
//!   toward the origin).
//! - Signs: positive **yaw** turns the nose (+z) toward +x, i.e. the face turns toward the
//!   **image right** (the subject's own left); positive **pitch** tilts the nose down (toward −y);
//!   positive **roll** turns the face counter-clockwise as seen in the image.

use crate::geometry::{mat_mul, mat_vec, Mat3, Vec3};

/// Pose of the model: Euler angles in radians and a translation in mm (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Rotation about the model's y axis (radians); positive turns the face toward the image right.
    pub yaw: f32,
    /// Rotation about the x axis (radians); positive tilts the nose down.
    pub pitch: f32,
    /// Rotation about the z axis (radians); positive is counter-clockwise in the image.
    pub roll: f32,
    /// Translation in camera space (mm); a face 1 m in front of the camera has `z = -1000`.
    pub translation: Vec3,
}

impl Pose {
    /// No rotation, the model `distance_mm` in front of the camera (translation `(0, 0, -distance_mm)`).
    pub const fn frontal(distance_mm: f32) -> Self {
        Self { yaw: 0.0, pitch: 0.0, roll: 0.0, translation: [0.0, 0.0, -distance_mm] }
    }

    /// The rotation matrix `R = Rz(roll) · Ry(yaw) · Rx(pitch)`.
    pub fn rotation(&self) -> Mat3 {
        PoseTrig::of(self).rotation()
    }

    /// Maps a model-space point to camera space: `R · p + t`.
    pub fn transform_point(&self, p: Vec3) -> Vec3 {
        let r = mat_vec(&self.rotation(), p);
        [r[0] + self.translation[0], r[1] + self.translation[1], r[2] + self.translation[2]]
    }
}

/// The sines and cosines of a pose's three angles, kept so that a pose differing in one angle
/// (a rotation proposal) or none (any other) computes only what changed: `sinf`/`cosf` are
/// double-precision library code on a Cortex-M4. The same values, so the same rotation bits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseTrig {
    /// Bit patterns of yaw, pitch and roll.
    angles: [u32; 3],
    /// `(sin, cos)` of each.
    sc: [[f32; 2]; 3],
}

impl PoseTrig {
    /// The sines and cosines of `pose`'s angles.
    pub fn of(pose: &Pose) -> Self {
        let sc = |a: f32| [libm::sinf(a), libm::cosf(a)];
        Self { angles: [pose.yaw, pose.pitch, pose.roll].map(f32::to_bits), sc: [sc(pose.yaw), sc(pose.pitch), sc(pose.roll)] }
    }

    /// Those of `pose`, reusing the angles whose bits are this one's.
    pub fn to(&self, pose: &Pose) -> Self {
        let mut next = *self;
        for ((bits, sc), a) in next.angles.iter_mut().zip(next.sc.iter_mut()).zip([pose.yaw, pose.pitch, pose.roll]) {
            if *bits != a.to_bits() {
                *bits = a.to_bits();
                *sc = [libm::sinf(a), libm::cosf(a)];
            }
        }
        next
    }

    /// The rotation matrix `R = Rz(roll) · Ry(yaw) · Rx(pitch)` (see [`Pose::rotation`]).
    pub fn rotation(&self) -> Mat3 {
        let [[sy, cy], [sp, cp], [sr, cr]] = self.sc;
        let rz = [[cr, -sr, 0.0], [sr, cr, 0.0], [0.0, 0.0, 1.0]];
        let ry = [[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]];
        let rx = [[1.0, 0.0, 0.0], [0.0, cp, -sp], [0.0, sp, cp]];
        mat_mul(&mat_mul(&rz, &ry), &rx)
    }
}

#[cfg(test)]
#[allow(clippy::indexing_slicing)]
mod tests {
    use super::*;

    fn close(a: Vec3, b: Vec3) -> bool {
        a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 1e-5)
    }

    #[test]
    fn yaw_turns_nose_to_image_right() {
        let p = Pose { yaw: core::f32::consts::FRAC_PI_2, ..Pose::frontal(0.0) };
        assert!(close(p.transform_point([0.0, 0.0, 1.0]), [1.0, 0.0, 0.0]));
    }

    #[test]
    fn pitch_tilts_nose_down() {
        let p = Pose { pitch: core::f32::consts::FRAC_PI_2, ..Pose::frontal(0.0) };
        assert!(close(p.transform_point([0.0, 0.0, 1.0]), [0.0, -1.0, 0.0]));
    }

    #[test]
    fn roll_is_counter_clockwise() {
        let p = Pose { roll: core::f32::consts::FRAC_PI_2, ..Pose::frontal(0.0) };
        assert!(close(p.transform_point([1.0, 0.0, 0.0]), [0.0, 1.0, 0.0]));
    }

    #[test]
    fn order_is_pitch_then_yaw_then_roll() {
        let p = Pose { yaw: 0.3, pitch: -0.2, roll: 0.5, translation: [1.0, 2.0, 3.0] };
        let v = [0.3, -0.7, 0.9];
        let x = Pose { pitch: p.pitch, ..Pose::frontal(0.0) }.transform_point(v);
        let y = Pose { yaw: p.yaw, ..Pose::frontal(0.0) }.transform_point(x);
        let z = Pose { roll: p.roll, ..Pose::frontal(0.0) }.transform_point(y);
        assert!(close(p.transform_point(v), [z[0] + 1.0, z[1] + 2.0, z[2] + 3.0]));
    }
}
