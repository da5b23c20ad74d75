//! Landmark likelihood: isotropic 2-D Gaussian between target points and projected model landmarks.

use crate::error::FitError;
use crate::geometry::{Mat3, Vec3};
use crate::model::MAX_LANDMARKS;
use crate::render::{Camera, Pose};

/// Target landmarks in pixels (x right, y down, pixel centres at +0.5), a validity mask and σ.
#[derive(Debug, Clone, Copy)]
pub struct LandmarkTarget<'a> {
    points: &'a [[f32; 2]],
    valid: &'a [bool],
    sigma: f32,
    factors: &'a [f32],
    outward: &'a [[f32; 2]],
    nu: f32,
}

/// Every usable point finite, and one usable at all.
fn check_mask(points: &[[f32; 2]], valid: &[bool]) -> Result<(), FitError> {
    if points.iter().zip(valid).any(|(p, &v)| v && !(p[0].is_finite() && p[1].is_finite())) {
        return Err(FitError::NonFinite);
    }
    if !valid.iter().any(|&v| v) {
        return Err(FitError::NoValidLandmarks);
    }
    Ok(())
}

impl<'a> LandmarkTarget<'a> {
    /// Checks that `points` and `valid` have the same length (at most [`MAX_LANDMARKS`]), that
    /// every valid point is finite, that one is valid at all and that `sigma > 0` (pixels).
    pub fn new(points: &'a [[f32; 2]], valid: &'a [bool], sigma: f32) -> Result<Self, FitError> {
        if points.len() != valid.len() {
            return Err(FitError::LengthMismatch);
        }
        if points.len() > MAX_LANDMARKS {
            return Err(FitError::TooManyLandmarks);
        }
        if !(sigma > 0.0 && sigma.is_finite()) {
            return Err(FitError::BadConfig);
        }
        check_mask(points, valid)?;
        Ok(Self { points, valid, sigma, factors: &[], outward: &[], nu: 0.0 })
    }

    /// The same target with landmark `i`'s σ multiplied by `factors[i]` (one finite factor > 0
    /// per landmark; e.g. a larger σ for points whose definition depends on the view).
    pub fn with_sigma_factors(self, factors: &'a [f32]) -> Result<Self, FitError> {
        if factors.len() != self.points.len() {
            return Err(FitError::LengthMismatch);
        }
        if !factors.iter().all(|f| *f > 0.0 && f.is_finite()) {
            return Err(FitError::BadConfig);
        }
        Ok(Self { factors, ..self })
    }

    /// The same target with another mask of usable points (one per point, at least one usable,
    /// every usable point finite).
    pub fn with_valid(self, valid: &'a [bool]) -> Result<Self, FitError> {
        if valid.len() != self.points.len() {
            return Err(FitError::LengthMismatch);
        }
        check_mask(self.points, valid)?;
        Ok(Self { valid, ..self })
    }

    /// The same target with its points and σ scaled by `factor` (> 0 and finite: the target of
    /// an image resampled by it), the points written into `buffer` (at least one per point).
    pub fn scaled<'b>(&self, factor: f32, buffer: &'b mut [[f32; 2]]) -> Result<LandmarkTarget<'b>, FitError>
    where
        'a: 'b,
    {
        if !(factor > 0.0 && factor.is_finite()) {
            return Err(FitError::BadConfig);
        }
        let points = buffer.get_mut(..self.points.len()).ok_or(FitError::LengthMismatch)?;
        for (q, p) in points.iter_mut().zip(self.points) {
            *q = [p[0] * factor, p[1] * factor];
        }
        check_mask(points, self.valid)?;
        Ok(LandmarkTarget { points, sigma: self.sigma * factor, ..*self })
    }

    /// The same target with another σ (pixels, > 0 and finite).
    pub fn with_sigma(self, sigma: f32) -> Result<Self, FitError> {
        if !(sigma > 0.0 && sigma.is_finite()) {
            return Err(FitError::BadConfig);
        }
        Ok(Self { sigma, ..self })
    }

    /// The same target with a Student-t term of `nu` degrees of freedom instead of the Gaussian
    /// (`0`: Gaussian): a point `k` σ off costs `(ν + 2)/2 · ln(1 + k²/ν)` instead of `k²/2`, so a
    /// few wrong points of a detector do not pull the fit. `nu` must be 0 or finite and > 0.
    pub fn with_student_t(self, nu: f32) -> Result<Self, FitError> {
        if !(nu == 0.0 || (nu > 0.0 && nu.is_finite())) {
            return Err(FitError::BadConfig);
        }
        Ok(Self { nu, ..self })
    }

    /// The same target with its first `outward.len()` landmarks measured only along the given unit
    /// image directions (silhouette points: see [`crate::fit::likelihood::contour`]).
    pub fn with_outward(self, outward: &'a [[f32; 2]]) -> Result<Self, FitError> {
        if outward.len() > self.points.len() {
            return Err(FitError::LengthMismatch);
        }
        Ok(Self { outward, ..self })
    }

    /// Degrees of freedom of the Student-t term (0: Gaussian).
    pub fn student_t(&self) -> f32 {
        self.nu
    }

    /// The σ factor of landmark `i` (1 unless set by [`Self::with_sigma_factors`]).
    pub fn sigma_factor(&self, i: usize) -> f32 {
        self.factors.get(i).copied().unwrap_or(1.0)
    }

    /// A landmark σ for a `width × height` working image: 1.5 % of the larger side (about 1.9 px at 128).
    pub fn default_sigma(width: u32, height: u32) -> f32 {
        0.015 * width.max(height) as f32
    }

    /// Number of landmarks (valid or not).
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Whether there are no landmarks.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// The target points.
    pub fn points(&self) -> &'a [[f32; 2]] {
        self.points
    }

    /// The validity mask.
    pub fn valid(&self) -> &'a [bool] {
        self.valid
    }

    /// σ in pixels.
    pub fn sigma(&self) -> f32 {
        self.sigma
    }

    /// Centroid and RMS radius (pixels) of the valid points.
    pub fn spread(&self) -> ([f32; 2], f32) {
        let (mut c, mut n) = ([0.0f32; 2], 0.0f32);
        for (p, _) in self.points.iter().zip(self.valid).filter(|(_, &v)| v) {
            c[0] += p[0];
            c[1] += p[1];
            n += 1.0;
        }
        let n = n.max(1.0);
        c = [c[0] / n, c[1] / n];
        let mut r2 = 0.0f32;
        for (p, _) in self.points.iter().zip(self.valid).filter(|(_, &v)| v) {
            r2 += (p[0] - c[0]) * (p[0] - c[0]) + (p[1] - c[1]) * (p[1] - c[1]);
        }
        (c, libm::sqrtf(r2 / n))
    }
}

/// The landmark term of one sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LandmarkEval {
    /// `−½ Σ_valid |x_i − t_i|² / (σ f_i)²` with the per-landmark factors `f_i`, or the Student-t
    /// `−Σ (ν+2)/2 · ln(1 + |x_i − t_i|² / (ν σ² f_i²))` (no normalization constant; `−∞` if a valid
    /// landmark cannot be projected). Silhouette landmarks count only their outward distance.
    pub log_likelihood: f32,
    /// `Σ_valid |x_i − t_i|²` in px² (silhouette landmarks: the outward distance squared; `∞` if a
    /// landmark cannot be projected).
    pub sq_err: f32,
    /// Number of valid landmarks.
    pub count: u32,
}

impl LandmarkEval {
    /// Root-mean-square landmark distance in pixels.
    pub fn rmse(&self) -> f32 {
        libm::sqrtf(self.sq_err / (self.count.max(1) as f32))
    }
}

/// Evaluates the landmark likelihood of model landmark positions (`positions[i]` is landmark `i`,
/// model space) under `pose` and `camera`.
pub fn evaluate_landmarks(positions: &[Vec3], pose: &Pose, camera: &Camera, target: &LandmarkTarget<'_>) -> Result<LandmarkEval, FitError> {
    evaluate_landmarks_rotated(positions, &pose.rotation(), pose.translation, camera, target)
}

/// [`evaluate_landmarks`] with the pose given as its rotation matrix `r` and translation `t`.
pub fn evaluate_landmarks_rotated(
    positions: &[Vec3],
    r: &Mat3,
    t: Vec3,
    camera: &Camera,
    target: &LandmarkTarget<'_>,
) -> Result<LandmarkEval, FitError> {
    if positions.len() != target.len() {
        return Err(FitError::LengthMismatch);
    }
    let mut sq = 0.0f32;
    let mut weighted = 0.0f32;
    let mut count = 0u32;
    let nu = target.nu;
    let nu_s2 = nu * target.sigma * target.sigma;
    for (i, ((p, tp), _)) in positions.iter().zip(target.points).zip(target.valid).enumerate().filter(|(_, (_, &v))| v) {
        let q = crate::geometry::mat_vec(r, *p);
        let Some(s) = camera.project([q[0] + t[0], q[1] + t[1], q[2] + t[2]]) else {
            return Ok(LandmarkEval { log_likelihood: f32::NEG_INFINITY, sq_err: f32::INFINITY, count: count + 1 });
        };
        let (dx, dy) = (s.x - tp[0], s.y - tp[1]);
        let d2 = match target.outward.get(i) {
            Some(n) => {
                let a = dx * n[0] + dy * n[1];
                a * a
            }
            None => dx * dx + dy * dy,
        };
        sq += d2;
        if nu > 0.0 {
            let f = target.sigma_factor(i);
            weighted += libm::log1pf(d2 / (nu_s2 * f * f));
        } else if let Some(f) = target.factors.get(i) {
            weighted += d2 / (f * f);
        }
        count += 1;
    }
    let ll = if nu > 0.0 {
        -0.5 * (nu + 2.0) * weighted
    } else {
        // Without factors (every chain but the pose phase) no per-landmark division is needed.
        let weighted = if target.factors.is_empty() { sq } else { weighted };
        -0.5 * weighted / (target.sigma * target.sigma)
    };
    let ll = if ll.is_nan() { f32::NEG_INFINITY } else { ll };
    Ok(LandmarkEval { log_likelihood: ll, sq_err: sq, count })
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    #[test]
    fn a_scaled_target_is_the_same_target_in_a_resampled_image() {
        let points = [[10.0f32, 20.0], [30.0, f32::NAN]];
        let valid = [true, false];
        let factors = [1.0f32, 3.0];
        let t = LandmarkTarget::new(&points, &valid, 2.0).unwrap().with_sigma_factors(&factors).unwrap();
        let mut buffer = [[0.0f32; 2]; 4];
        let half = t.scaled(0.5, &mut buffer).unwrap();
        assert_eq!(half.points()[0], [5.0, 10.0]);
        assert_eq!((half.sigma(), half.sigma_factor(1), half.valid()), (1.0, 3.0, &valid[..]));
        assert_eq!(t.scaled(0.0, &mut [[0.0; 2]; 4]).err(), Some(FitError::BadConfig));
        assert_eq!(t.scaled(0.5, &mut [[0.0; 2]; 1]).err(), Some(FitError::LengthMismatch));
    }

    #[test]
    fn another_sigma_keeps_the_rest_and_refuses_bad_values() {
        let (points, valid, factors) = ([[1.0f32, 2.0], [3.0, 4.0]], [true, false], [2.0f32, 1.0]);
        let t = LandmarkTarget::new(&points, &valid, 0.5).unwrap().with_sigma_factors(&factors).unwrap().with_student_t(4.0).unwrap();
        let wide = t.with_sigma(5.0).unwrap();
        assert_eq!((wide.sigma(), wide.sigma_factor(0), wide.student_t(), wide.len()), (5.0, 2.0, 4.0, 2));
        for bad in [0.0, -1.0, f32::NAN, f32::INFINITY] {
            assert_eq!(t.with_sigma(bad).err(), Some(FitError::BadConfig), "{bad}");
        }
    }

    #[test]
    fn another_mask_keeps_the_rest_and_needs_a_usable_point() {
        let (points, valid) = ([[1.0f32, 2.0], [3.0, 4.0]], [true, true]);
        let t = LandmarkTarget::new(&points, &valid, 0.5).unwrap().with_student_t(4.0).unwrap();
        let one = t.with_valid(&[false, true]).unwrap();
        assert_eq!((one.valid(), one.sigma(), one.student_t()), (&[false, true][..], 0.5, 4.0));
        assert_eq!(t.with_valid(&[false, false]).err(), Some(FitError::NoValidLandmarks));
        assert_eq!(t.with_valid(&[true]).err(), Some(FitError::LengthMismatch));
    }

    #[test]
    fn exact_projection_has_zero_error() {
        let cam = Camera::centered(100, 100, 200.0);
        let pose = Pose::frontal(500.0);
        let pts = [[0.0, 0.0, 0.0], [50.0, 0.0, 0.0]];
        let target = [[50.0, 50.0], [70.0, 50.0]];
        let t = LandmarkTarget::new(&target, &[true, true], 2.0).unwrap();
        let e = evaluate_landmarks(&pts, &pose, &cam, &t).unwrap();
        assert!(e.sq_err < 1e-6, "{e:?}");
        let shifted = [[52.0, 50.0], [70.0, 50.0]];
        let t = LandmarkTarget::new(&shifted, &[true, true], 2.0).unwrap();
        let e = evaluate_landmarks(&pts, &pose, &cam, &t).unwrap();
        assert!((e.log_likelihood + 0.5).abs() < 1e-4);
        assert!((e.rmse() - libm::sqrtf(2.0)).abs() < 1e-4);
        // A masked point does not count.
        let t = LandmarkTarget::new(&shifted, &[false, true], 2.0).unwrap();
        assert!(evaluate_landmarks(&pts, &pose, &cam, &t).unwrap().sq_err < 1e-6);
        // A σ factor of 2 on the shifted point quarters its log-likelihood but not its error.
        let t = LandmarkTarget::new(&shifted, &[true, true], 2.0).unwrap().with_sigma_factors(&[2.0, 1.0]).unwrap();
        let e = evaluate_landmarks(&pts, &pose, &cam, &t).unwrap();
        assert!((e.log_likelihood + 0.125).abs() < 1e-4, "{e:?}");
        assert!((e.rmse() - libm::sqrtf(2.0)).abs() < 1e-4);
        assert_eq!(t.with_sigma_factors(&[1.0]).err(), Some(FitError::LengthMismatch));
        assert_eq!(t.with_sigma_factors(&[1.0, 0.0]).err(), Some(FitError::BadConfig));
        assert_eq!(t.with_sigma_factors(&[1.0, f32::NAN]).err(), Some(FitError::BadConfig));
    }

    #[test]
    fn student_t_and_outward_terms() {
        let cam = Camera::centered(100, 100, 200.0);
        let pose = Pose::frontal(500.0);
        let pts = [[0.0, 0.0, 0.0], [50.0, 0.0, 0.0]];
        // Point 0 is 10 px off in x, 3 px in y; σ = 1 px.
        let target = [[60.0, 53.0], [70.0, 50.0]];
        let valid = [true, true];
        let g = LandmarkTarget::new(&target, &valid, 1.0).unwrap();
        let gauss = evaluate_landmarks(&pts, &pose, &cam, &g).unwrap();
        assert!((gauss.log_likelihood + 0.5 * 109.0).abs() < 1e-3, "{gauss:?}");
        // Student-t with ν = 4: (ν + 2)/2 · ln(1 + d²/ν) = 3 ln(1 + 109/4), far less than 54.5.
        let t = evaluate_landmarks(&pts, &pose, &cam, &g.with_student_t(4.0).unwrap()).unwrap();
        assert!((t.log_likelihood + 3.0 * libm::log1pf(109.0 / 4.0)).abs() < 1e-3, "{t:?}");
        assert_eq!(t.sq_err, gauss.sq_err);
        // A large ν comes back to the Gaussian (up to the factor (ν + 2)/ν).
        let big = evaluate_landmarks(&pts, &pose, &cam, &g.with_student_t(1e5).unwrap()).unwrap();
        assert!((big.log_likelihood - gauss.log_likelihood).abs() < 0.1, "{big:?}");
        assert_eq!(g.with_student_t(-1.0).err(), Some(FitError::BadConfig));
        assert_eq!(g.with_student_t(f32::INFINITY).err(), Some(FitError::BadConfig));
        // Measured along (0, 1) only, point 0 is 3 px off.
        let o = evaluate_landmarks(&pts, &pose, &cam, &g.with_outward(&[[0.0, 1.0]]).unwrap()).unwrap();
        assert!((o.log_likelihood + 4.5).abs() < 1e-3 && (o.sq_err - 9.0).abs() < 1e-3, "{o:?}");
        assert_eq!(g.with_outward(&[[0.0, 1.0]; 3]).err(), Some(FitError::LengthMismatch));
    }

    #[test]
    fn bad_targets_are_errors() {
        let p = [[f32::NAN, 0.0], [1.0, 1.0]];
        assert_eq!(LandmarkTarget::new(&p, &[true, true], 1.0).err(), Some(FitError::NonFinite));
        assert!(LandmarkTarget::new(&p, &[false, true], 1.0).is_ok());
        assert_eq!(LandmarkTarget::new(&p, &[true], 1.0).err(), Some(FitError::LengthMismatch));
        assert_eq!(LandmarkTarget::new(&p, &[false, false], 1.0).err(), Some(FitError::NoValidLandmarks));
        assert_eq!(LandmarkTarget::new(&p, &[false, true], 0.0).err(), Some(FitError::BadConfig));
        assert_eq!(LandmarkTarget::new(&p, &[false, true], f32::NAN).err(), Some(FitError::BadConfig));
    }

    #[test]
    fn behind_camera_is_impossible() {
        let cam = Camera::centered(100, 100, 200.0);
        let t = LandmarkTarget::new(&[[1.0, 1.0]], &[true], 1.0).unwrap();
        let e = evaluate_landmarks(&[[0.0, 0.0, 0.0]], &Pose::frontal(-100.0), &cam, &t).unwrap();
        assert_eq!(e.log_likelihood, f32::NEG_INFINITY);
    }
}
