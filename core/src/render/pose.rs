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

use crate::Vec3;
use nalgebra::{Matrix3, Vector3};

/// A row-major 3×3 matrix.
pub type Mat3 = [[f32; 3]; 3];

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

/// The nalgebra matrix of a row-major [`Mat3`].
pub fn to_matrix3(m: &Mat3) -> Matrix3<f32> {
    let [[a, b, c], [d, e, f], [g, h, i]] = *m;
    Matrix3::new(a, b, c, d, e, f, g, h, i)
}

/// The row-major [`Mat3`] of an nalgebra matrix.
pub fn from_matrix3(m: &Matrix3<f32>) -> Mat3 {
    [[m.m11, m.m12, m.m13], [m.m21, m.m22, m.m23], [m.m31, m.m32, m.m33]]
}

/// `a · b` for 3×3 matrices (nalgebra's product: the same operations, in the same order, as the
/// row-by-column sums written out; `tests::nalgebra_products_match_the_written_out_sums`).
pub fn mat_mul(a: &Mat3, b: &Mat3) -> Mat3 {
    from_matrix3(&(to_matrix3(a) * to_matrix3(b)))
}

/// `m · v`.
pub fn mat_vec(m: &Mat3, v: Vec3) -> Vec3 {
    let r = to_matrix3(m) * Vector3::new(v[0], v[1], v[2]);
    [r.x, r.y, r.z]
}

#[cfg(test)]
#[allow(clippy::indexing_slicing)]
mod tests {
    use super::*;

    fn close(a: Vec3, b: Vec3) -> bool {
        a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 1e-5)
    }

    /// The written-out sums nalgebra's products replaced (left to right, row by column).
    fn mat_mul_written_out(a: &Mat3, b: &Mat3) -> Mat3 {
        let [b0, b1, b2] = *b;
        a.map(|[x, y, z]| [x * b0[0] + y * b1[0] + z * b2[0], x * b0[1] + y * b1[1] + z * b2[1], x * b0[2] + y * b1[2] + z * b2[2]])
    }

    #[test]
    fn nalgebra_products_match_the_written_out_sums() {
        // A simple LCG: many matrices with mixed signs and magnitudes, compared bit for bit.
        let mut state = 0x1234_5678_u32;
        let mut next = || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) as f32 / (1u32 << 24) as f32 * 4.0 - 2.0
        };
        for _ in 0..20_000 {
            let a: Mat3 = [[next(), next(), next()], [next(), next(), next()], [next(), next(), next()]];
            let b: Mat3 = [[next(), next(), next()], [next(), next(), next()], [next(), next(), next()]];
            let v = [next() * 300.0, next() * 300.0, next() * 300.0];
            let (p, q) = (mat_mul(&a, &b), mat_mul_written_out(&a, &b));
            assert_eq!(p.map(|r| r.map(f32::to_bits)), q.map(|r| r.map(f32::to_bits)));
            let w = [
                a[0][0] * v[0] + a[0][1] * v[1] + a[0][2] * v[2],
                a[1][0] * v[0] + a[1][1] * v[1] + a[1][2] * v[2],
                a[2][0] * v[0] + a[2][1] * v[1] + a[2][2] * v[2],
            ];
            assert_eq!(mat_vec(&a, v).map(f32::to_bits), w.map(f32::to_bits));
        }
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
