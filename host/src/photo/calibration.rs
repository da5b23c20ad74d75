//! A landmark detector's systematic offsets, learned on renders and subtracted before a fit.
//!
//! A real detector does not put its points where the model's landmark vertices project: its own
//! definition of each point differs (a face-mesh vertex mapped to an iBUG-68 index is not the
//! iBUG point), and its errors change with the view (at 45° MediaPipe's eyes and brows sit toward
//! frontal relative to its nose tip). Both are the same for every face, so they can be learned
//! from images whose true landmarks are known (renders) and removed: what is left is the
//! detector's per-face noise, which the landmark σ stands for.
//!
//! The offsets live in the detected face's own frame: origin at the outer eye corners' midpoint,
//! `x` along the eye line (points 36 → 45 of iBUG-68), `y` across it, lengths in inter-ocular
//! distances (IOD). They are polynomials in one number read off the detection itself, the
//! *turn*: the nose tip's (point 30) offset from that midpoint along the eye line, in IOD (about
//! 0 for a frontal face, about ±0.4 at 45°), clamped to the range seen in training. So no pose
//! estimate is needed and the correction is the same whatever the camera.
//!
//! File: JSON, `{"format": "gpmm-landmark-calibration", "version": 1, "detector": …, "degree": d,
//! "turn_range": [lo, hi], "offsets": [[[x0, y0], [x1, y1], …], …]}` (per landmark, the
//! coefficients of `1, t, …, t^d`), plus what it was learned on.

use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The `format` value of a calibration file.
pub const CALIBRATION_FORMAT: &str = "gpmm-landmark-calibration";
/// The version this build reads and writes.
pub const CALIBRATION_VERSION: u32 = 1;
/// iBUG-68 indices of the outer eye corners and the nose tip (the face frame and the turn).
const LEFT_EYE: usize = 36;
const RIGHT_EYE: usize = 45;
const NOSE_TIP: usize = 30;
/// Landmarks of the scheme the frame is defined for.
const IBUG68: usize = 68;
/// Highest polynomial degree accepted.
pub const MAX_DEGREE: usize = 4;

/// Why a calibration could not be read, learned or applied; file errors name the file.
#[derive(Debug, thiserror::Error)]
pub enum CalibrationError {
    /// The file could not be read or written.
    #[error("{}: {message}", path.display())]
    File {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// The file is not a valid calibration.
    #[error("{}: not a landmark calibration: {error}", path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        error: InvalidCalibration,
    },
    /// The landmarks cannot be corrected or learned from.
    #[error("{0}")]
    Landmarks(String),
}

/// What makes a file not a valid calibration.
#[derive(Debug, thiserror::Error)]
pub enum InvalidCalibration {
    /// The JSON does not parse as a calibration.
    #[error("{0}")]
    Json(serde_json::Error),
    /// Another format name.
    #[error("format is {0:?}, expected {CALIBRATION_FORMAT:?}")]
    Format(String),
    /// Another format version.
    #[error("version {0} (this build reads version {CALIBRATION_VERSION})")]
    Version(u32),
    /// The polynomial degree is above [`MAX_DEGREE`].
    #[error("degree {0} is above the maximum {MAX_DEGREE}")]
    Degree(usize),
    /// Offsets for another number of landmarks than iBUG-68's.
    #[error("{0} landmarks' offsets; iBUG-68 has 68")]
    Landmarks(usize),
    /// A landmark's coefficient count does not match the degree.
    #[error("landmark {landmark} has {count} coefficients, degree {degree} needs {}", degree + 1)]
    Coefficients {
        /// The landmark.
        landmark: usize,
        /// Its coefficients.
        count: usize,
        /// The calibration's degree.
        degree: usize,
    },
    /// A number is not finite or the turn range is empty.
    #[error("a coefficient or the turn range is not finite, or the range is empty")]
    NotFinite,
}

/// The true and the detected points of one image (pixels).
pub type LandmarkPair = (Vec<[f32; 2]>, Vec<[f32; 2]>);

/// What a calibration was learned on (for the record; not used to correct).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CalibrationTraining {
    /// Image pairs (exact and detected landmarks) it was learned from.
    pub images: usize,
    /// Median RMS distance detected → exact over those images, pixels, before correction.
    pub median_rms_px_before: f32,
    /// The same after correction (on the training images themselves).
    pub median_rms_px_after: f32,
}

/// A detector's learned systematic offsets (see the module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LandmarkCalibration {
    /// Always [`CALIBRATION_FORMAT`].
    pub format: String,
    /// Always [`CALIBRATION_VERSION`].
    pub version: u32,
    /// Free text: which detector and landmark mapping this belongs to.
    pub detector: String,
    /// Polynomial degree in the turn.
    pub degree: usize,
    /// The turns seen in training; others are clamped into it.
    pub turn_range: [f32; 2],
    /// Per landmark, `degree + 1` coefficients `[x, y]` (face frame, IOD).
    pub offsets: Vec<Vec<[f32; 2]>>,
    /// What it was learned on.
    pub training: CalibrationTraining,
}

/// A detection's face frame: the eye-line direction, the IOD, the eyes' midpoint and the turn.
#[derive(Debug, Clone, Copy, PartialEq)]
struct FaceFrame {
    axis: [f32; 2],
    iod: f32,
    turn: f32,
}

impl FaceFrame {
    /// The frame of 68 detected points; `None` if the eye corners coincide or a point is not finite.
    fn of(points: &[[f32; 2]]) -> Option<Self> {
        let (l, r, n) = (points.get(LEFT_EYE)?, points.get(RIGHT_EYE)?, points.get(NOSE_TIP)?);
        let d = [r[0] - l[0], r[1] - l[1]];
        let iod = d[0].hypot(d[1]);
        if !(iod.is_finite() && iod > 1e-3 && n[0].is_finite() && n[1].is_finite()) {
            return None;
        }
        let axis = [d[0] / iod, d[1] / iod];
        let mid = [(l[0] + r[0]) / 2.0, (l[1] + r[1]) / 2.0];
        let turn = ((n[0] - mid[0]) * axis[0] + (n[1] - mid[1]) * axis[1]) / iod;
        Some(Self { axis, iod, turn })
    }

    /// An image-space displacement in face-frame IOD units.
    fn to_face(self, v: [f32; 2]) -> [f32; 2] {
        let [c, s] = self.axis;
        [(c * v[0] + s * v[1]) / self.iod, (-s * v[0] + c * v[1]) / self.iod]
    }

    /// A face-frame offset (IOD units) as an image-space displacement.
    fn to_image(self, o: [f32; 2]) -> [f32; 2] {
        let [c, s] = self.axis;
        [(c * o[0] - s * o[1]) * self.iod, (s * o[0] + c * o[1]) * self.iod]
    }
}

/// The powers `1, t, …, t^degree`.
fn powers(t: f64, degree: usize) -> Vec<f64> {
    (0..=degree)
        .scan(1.0, |p, _| {
            let v = *p;
            *p *= t;
            Some(v)
        })
        .collect()
}

fn rms(a: &[[f32; 2]], b: &[[f32; 2]]) -> f32 {
    let s: f32 = a.iter().zip(b).map(|(p, q)| (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sum();
    (s / a.len().max(1) as f32).sqrt()
}

fn median(mut v: Vec<f32>) -> f32 {
    v.sort_by(f32::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(0.0)
}

impl LandmarkCalibration {
    /// Learns the offsets from pairs of (exact, detected) iBUG-68 landmarks of the same images, by
    /// least squares per landmark and coordinate. Errors on fewer than `4 (degree + 1)` pairs, a
    /// pair that is not 68 + 68 finite points with distinct eye corners, or a degree above
    /// [`MAX_DEGREE`].
    pub fn learn(pairs: &[LandmarkPair], degree: usize, detector: &str) -> Result<Self, CalibrationError> {
        if degree > MAX_DEGREE {
            return Err(CalibrationError::Landmarks(format!("degree {degree} is above the maximum {MAX_DEGREE}")));
        }
        let terms = degree + 1;
        if pairs.len() < 4 * terms {
            return Err(CalibrationError::Landmarks(format!(
                "{} image pairs are too few to learn a degree-{degree} calibration (at least {})",
                pairs.len(),
                4 * terms
            )));
        }
        let mut frames = Vec::with_capacity(pairs.len());
        for (i, (exact, detected)) in pairs.iter().enumerate() {
            if exact.len() != IBUG68 || detected.len() != IBUG68 {
                return Err(CalibrationError::Landmarks(format!(
                    "pair {i}: {} exact and {} detected points; both must be iBUG-68 (68)",
                    exact.len(),
                    detected.len()
                )));
            }
            if exact.iter().chain(detected).any(|p| !(p[0].is_finite() && p[1].is_finite())) {
                return Err(CalibrationError::Landmarks(format!("pair {i}: a point is not finite")));
            }
            frames.push(
                FaceFrame::of(detected)
                    .ok_or_else(|| CalibrationError::Landmarks(format!("pair {i}: the detected outer eye corners (36, 45) coincide")))?,
            );
        }
        let mut turns: Vec<f32> = frames.iter().map(|f| (f.turn * 1e3).round()).collect();
        turns.sort_by(f32::total_cmp);
        turns.dedup();
        if turns.len() < terms {
            return Err(CalibrationError::Landmarks(format!(
                "the training turns do not determine a degree-{degree} polynomial (too few distinct views: {})",
                turns.len()
            )));
        }
        // Normal equations, shared by every landmark and coordinate: (F^T F) W = F^T Y.
        let rows: Vec<Vec<f64>> = frames.iter().map(|f| powers(f64::from(f.turn), degree)).collect();
        let gram = faer::Mat::from_fn(terms, terms, |a, b| rows.iter().map(|r| r[a] * r[b]).sum::<f64>());
        let rhs = faer::Mat::from_fn(terms, 2 * IBUG68, |a, c| {
            rows.iter()
                .zip(pairs.iter().zip(&frames))
                .map(|(r, ((exact, detected), f))| {
                    let (e, d) = (exact[c / 2], detected[c / 2]);
                    r[a] * f64::from(f.to_face([e[0] - d[0], e[1] - d[1]])[c % 2])
                })
                .sum::<f64>()
        });
        let llt = gram.llt(faer::Side::Lower).map_err(|_| {
            CalibrationError::Landmarks(format!(
                "the training turns do not determine a degree-{degree} polynomial (too few distinct views)"
            ))
        })?;
        let w = faer::linalg::solvers::Solve::solve(&llt, &rhs);
        let offsets = (0..IBUG68).map(|l| (0..terms).map(|a| [w[(a, 2 * l)] as f32, w[(a, 2 * l + 1)] as f32]).collect()).collect();
        let lo = frames.iter().map(|f| f.turn).fold(f32::INFINITY, f32::min);
        let hi = frames.iter().map(|f| f.turn).fold(f32::NEG_INFINITY, f32::max);
        let mut cal = Self {
            format: CALIBRATION_FORMAT.into(),
            version: CALIBRATION_VERSION,
            detector: detector.into(),
            degree,
            turn_range: [lo, hi],
            offsets,
            training: CalibrationTraining { images: pairs.len(), median_rms_px_before: 0.0, median_rms_px_after: 0.0 },
        };
        let mut before = Vec::with_capacity(pairs.len());
        let mut after = Vec::with_capacity(pairs.len());
        for (exact, detected) in pairs {
            before.push(rms(detected, exact));
            after.push(rms(&cal.correct(detected)?, exact));
        }
        cal.training.median_rms_px_before = median(before);
        cal.training.median_rms_px_after = median(after);
        Ok(cal)
    }

    /// The detected points with the learned offsets added. Errors unless there are 68 finite
    /// points with distinct outer eye corners.
    pub fn correct(&self, detected: &[[f32; 2]]) -> Result<Vec<[f32; 2]>, CalibrationError> {
        if detected.len() != self.offsets.len() {
            return Err(CalibrationError::Landmarks(format!(
                "{} landmarks, but the calibration is for {}",
                detected.len(),
                self.offsets.len()
            )));
        }
        let frame = FaceFrame::of(detected).ok_or_else(|| {
            CalibrationError::Landmarks("the landmarks' outer eye corners (36, 45) coincide or a point is not finite".into())
        })?;
        let t = f64::from(frame.turn.clamp(self.turn_range[0], self.turn_range[1]));
        let p = powers(t, self.degree);
        Ok(detected
            .iter()
            .zip(&self.offsets)
            .map(|(d, c)| {
                let o = c.iter().zip(&p).fold([0.0f64; 2], |s, (k, &w)| [s[0] + w * f64::from(k[0]), s[1] + w * f64::from(k[1])]);
                let v = frame.to_image([o[0] as f32, o[1] as f32]);
                [d[0] + v[0], d[1] + v[1]]
            })
            .collect())
    }

    /// [`Self::correct`] for the points of a `width × height` image: corrected points are kept
    /// inside it; a point that was already outside stays as it was (so the usual check refuses it).
    pub fn correct_in_image(&self, detected: &[[f32; 2]], width: f32, height: f32) -> Result<Vec<[f32; 2]>, CalibrationError> {
        let inside = |p: &[f32; 2]| p[0] >= 0.0 && p[1] >= 0.0 && p[0] <= width && p[1] <= height;
        Ok(detected
            .iter()
            .zip(self.correct(detected)?)
            .map(|(d, c)| if inside(d) { [c[0].clamp(0.0, width), c[1].clamp(0.0, height)] } else { *d })
            .collect())
    }

    /// Checks the fields a file could get wrong (format, version, shapes, finite numbers).
    fn validate(&self) -> Result<(), InvalidCalibration> {
        if self.format != CALIBRATION_FORMAT {
            return Err(InvalidCalibration::Format(self.format.clone()));
        }
        if self.version != CALIBRATION_VERSION {
            return Err(InvalidCalibration::Version(self.version));
        }
        if self.degree > MAX_DEGREE {
            return Err(InvalidCalibration::Degree(self.degree));
        }
        if self.offsets.len() != IBUG68 {
            return Err(InvalidCalibration::Landmarks(self.offsets.len()));
        }
        if let Some(landmark) = self.offsets.iter().position(|c| c.len() != self.degree + 1) {
            return Err(InvalidCalibration::Coefficients { landmark, count: self.offsets[landmark].len(), degree: self.degree });
        }
        let finite = self.offsets.iter().flatten().flatten().chain(&self.turn_range).all(|v| v.is_finite());
        if !finite || self.turn_range[0] > self.turn_range[1] {
            return Err(InvalidCalibration::NotFinite);
        }
        Ok(())
    }

    /// Reads and checks a calibration file.
    pub fn read(path: &Path) -> Result<Self, CalibrationError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| CalibrationError::File { path: path.to_path_buf(), message: format!("cannot read: {e}") })?;
        let cal: Self = serde_json::from_str(&text)
            .map_err(|e| CalibrationError::Invalid { path: path.to_path_buf(), error: InvalidCalibration::Json(e) })?;
        cal.validate().map_err(|error| CalibrationError::Invalid { path: path.to_path_buf(), error })?;
        Ok(cal)
    }

    /// Writes the calibration as pretty JSON.
    pub fn write(&self, path: &Path) -> Result<(), CalibrationError> {
        let text =
            serde_json::to_string_pretty(self).map_err(|e| CalibrationError::File { path: path.to_path_buf(), message: e.to_string() })?;
        std::fs::write(path, text + "\n")
            .map_err(|e| CalibrationError::File { path: path.to_path_buf(), message: format!("cannot write: {e}") })
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    /// A face-like set of 68 points turned by `turn` (the nose tip moves along the eye line).
    fn face(turn: f32, scale: f32, angle: f32, shift: [f32; 2]) -> Vec<[f32; 2]> {
        let (s, c) = angle.sin_cos();
        (0..IBUG68)
            .map(|i| {
                let mut p = [((i * 37) % 11) as f32 / 10.0 - 0.5, ((i * 53) % 13) as f32 / 12.0 - 0.3];
                if i == LEFT_EYE {
                    p = [-0.5, 0.0];
                }
                if i == RIGHT_EYE {
                    p = [0.5, 0.0];
                }
                if i == NOSE_TIP {
                    p = [turn, 0.4];
                }
                [shift[0] + scale * (c * p[0] - s * p[1]), shift[1] + scale * (s * p[0] + c * p[1])]
            })
            .collect()
    }

    /// A detector whose offsets are a known quadratic in the turn (face frame), except at the
    /// points that define the frame.
    fn detect(exact: &[[f32; 2]]) -> Vec<[f32; 2]> {
        let f = FaceFrame::of(exact).unwrap();
        exact
            .iter()
            .enumerate()
            .map(|(i, e)| {
                if [LEFT_EYE, RIGHT_EYE, NOSE_TIP].contains(&i) {
                    return *e;
                }
                let t = f.turn;
                let o = [0.02 * (i % 5) as f32 - 0.1 * t + 0.2 * t * t, -0.03 + 0.05 * t];
                let v = f.to_image(o);
                [e[0] - v[0], e[1] - v[1]]
            })
            .collect()
    }

    #[test]
    fn learns_and_removes_a_view_dependent_offset() {
        let pairs: Vec<_> = (0..24)
            .map(|k| {
                let exact = face(-0.4 + 0.035 * k as f32, 30.0 + k as f32, 0.05 * (k % 3) as f32, [64.0, 60.0 + k as f32]);
                let d = detect(&exact);
                (exact, d)
            })
            .collect();
        let cal = LandmarkCalibration::learn(&pairs, 2, "test").unwrap();
        assert!(cal.training.median_rms_px_before > 1.0, "{:?}", cal.training);
        assert!(cal.training.median_rms_px_after < 1e-3, "{:?}", cal.training);
        // A face it was not learned on, at another scale and roll.
        let exact = face(0.23, 41.0, -0.1, [70.0, 50.0]);
        let fixed = cal.correct(&detect(&exact)).unwrap();
        assert!(rms(&fixed, &exact) < 1e-3, "{}", rms(&fixed, &exact));
        // Round trip through a file.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cal.json");
        cal.write(&path).unwrap();
        assert_eq!(LandmarkCalibration::read(&path).unwrap(), cal);
    }

    #[test]
    fn refuses_bad_input_with_clear_errors() {
        let pairs: Vec<_> =
            (0..3).map(|k| (face(0.1 * k as f32, 30.0, 0.0, [50.0, 50.0]), face(0.1 * k as f32, 30.0, 0.0, [50.0, 50.0]))).collect();
        let e = LandmarkCalibration::learn(&pairs, 2, "x").unwrap_err().to_string();
        assert!(e.contains("too few"), "{e}");
        let same: Vec<_> = (0..12).map(|_| (face(0.1, 30.0, 0.0, [50.0, 50.0]), face(0.1, 30.0, 0.0, [50.0, 50.0]))).collect();
        let e = LandmarkCalibration::learn(&same, 2, "x").unwrap_err().to_string();
        assert!(e.contains("distinct views"), "{e}");
        let cal = LandmarkCalibration::learn(&same, 0, "x").unwrap();
        // In an image: a corrected point stays inside it, one already outside is left for the check.
        let mut shifted = cal.clone();
        shifted.offsets = vec![vec![[1.0, 0.0]]; IBUG68];
        let mut pts = face(0.0, 30.0, 0.0, [50.0, 50.0]);
        pts[0] = [200.0, 50.0];
        let fixed = shifted.correct_in_image(&pts, 70.0, 100.0).unwrap();
        assert_eq!(fixed[0], [200.0, 50.0]);
        assert!(fixed.iter().skip(1).all(|p| p[0] <= 70.0) && fixed.iter().any(|p| p[0] == 70.0), "{fixed:?}");
        assert!(cal.correct(&face(0.0, 30.0, 0.0, [1.0, 1.0])[..60]).unwrap_err().to_string().contains("60 landmarks"));
        let mut nan = face(0.0, 30.0, 0.0, [1.0, 1.0]);
        nan[NOSE_TIP][0] = f32::NAN;
        assert!(cal.correct(&nan).is_err());
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.json");
        let mut broken = cal.clone();
        broken.offsets.pop();
        std::fs::write(&path, serde_json::to_string(&broken).unwrap()).unwrap();
        let e = LandmarkCalibration::read(&path).unwrap_err().to_string();
        assert!(e.contains("bad.json") && e.contains("67 landmarks"), "{e}");
        std::fs::write(&path, "{ not json").unwrap();
        assert!(LandmarkCalibration::read(&path).unwrap_err().to_string().contains("not a landmark calibration"));
        assert!(LandmarkCalibration::read(&dir.path().join("missing.json")).unwrap_err().to_string().contains("cannot read"));
    }
}
