//! The check a face found in a photo passes before it is listed: the finder's score and how well
//! the initializer's reading agrees with its mirror image and the box
//! ([`gpmm_core::net::agreement::ReadingAgreement`]), combined by a logistic regression learned from
//! photos with known faces ([`FaceCheck::fit`], `gpmm check-init`) and kept in the init file's
//! metadata under [`METADATA_KEY`]. Hands, textures and parts of faces that the finder scores
//! high mostly read unlike a face (docs/real-photos.md, "The reading's check").

use gpmm_core::net::agreement::ReadingAgreement;
use serde::{Deserialize, Serialize};

/// The init file's metadata key that holds the check.
pub const METADATA_KEY: &str = "face_check";

/// The share of the fitting photos' true faces the check keeps: its threshold is set so that this
/// many pass. Chosen on photos of people and face-free photos that no training or fitting saw
/// (docs/real-photos.md).
pub const KEPT_FACE_SHARE: f64 = 0.98;

/// Fewest true faces and other boxes a fit needs.
pub const MIN_FIT_SAMPLES: usize = 10;

/// A learned check: `p = sigmoid(weights · features + bias)`, passed when `p ≥ threshold`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FaceCheck {
    /// Weights of [`features`]: the finder's score as a logit, the logarithms of the mirror gap and
    /// of the fill, the offset.
    pub weights: [f64; 4],
    /// The regression's constant.
    pub bias: f64,
    /// The least probability a face needs.
    pub threshold: f64,
    /// True faces it was fitted on.
    pub faces: usize,
    /// Other boxes (false faces) it was fitted on.
    pub others: usize,
}

/// Why a check could not be fitted or read.
#[derive(Debug, thiserror::Error)]
pub enum CheckError {
    /// Too few true faces or other boxes to fit.
    #[error("too few boxes to fit a face check: {faces} true faces and {others} others (at least {MIN_FIT_SAMPLES} of each)")]
    TooFew {
        /// True faces given.
        faces: usize,
        /// Other boxes given.
        others: usize,
    },
    /// The initializer does not read the 68 iBUG points, so it has no mirrored reading to compare.
    #[error("a face check needs an initializer of the 68 iBUG points (its mirrored reading); this one reads {0}")]
    NoMirror(usize),
    /// The regression did not converge to finite weights.
    #[error("the face check's regression did not converge")]
    Diverged,
    /// The metadata's check is not readable.
    #[error("the init file's face_check is not readable: {0}")]
    Metadata(String),
}

/// The regression's inputs for a box of finder score `score` whose reading measured `a`.
pub fn features(score: f32, a: &ReadingAgreement) -> [f64; 4] {
    let p = f64::from(score).clamp(1e-6, 1.0 - 1e-6);
    let floor = 1e-4;
    [(p / (1.0 - p)).ln(), (f64::from(a.mirror_gap) + floor).ln(), f64::from(a.fill).max(floor).ln(), f64::from(a.offset)]
}

fn sigmoid(z: f64) -> f64 {
    1.0 / (1.0 + (-z).exp())
}

impl FaceCheck {
    /// The probability the regression gives a box with these features.
    pub fn probability(&self, x: &[f64; 4]) -> f64 {
        sigmoid(self.weights.iter().zip(x).map(|(w, v)| w * v).sum::<f64>() + self.bias)
    }

    /// Whether a box of finder score `score` whose reading measured `a` is a face. A reading that
    /// could not be measured (no mirrored reading) or is not a number is not checked: it passes.
    pub fn passes(&self, score: f32, a: Option<&ReadingAgreement>) -> bool {
        match a {
            Some(a) if a.is_finite() => self.probability(&features(score, a)) >= self.threshold,
            _ => true,
        }
    }

    /// Fits the regression to `samples` (features, true face or not) by Newton's method with a
    /// small ridge, and sets the threshold so that `kept_share` of the true faces pass.
    pub fn fit(samples: &[([f64; 4], bool)], kept_share: f64) -> Result<Self, CheckError> {
        let faces = samples.iter().filter(|s| s.1).count();
        let others = samples.len() - faces;
        if faces < MIN_FIT_SAMPLES || others < MIN_FIT_SAMPLES {
            return Err(CheckError::TooFew { faces, others });
        }
        const N: usize = 5;
        let row = |x: &[f64; 4]| [x[0], x[1], x[2], x[3], 1.0];
        let ridge = 1e-2;
        let mut w = [0.0f64; N];
        for _ in 0..50 {
            let mut grad = [0.0f64; N];
            let mut hess = faer::Mat::<f64>::zeros(N, N);
            for (x, face) in samples {
                let r = row(x);
                let p = sigmoid(r.iter().zip(&w).map(|(a, b)| a * b).sum());
                let y = if *face { 1.0 } else { 0.0 };
                for a in 0..N {
                    grad[a] += r[a] * (p - y);
                    for b in 0..N {
                        hess[(a, b)] += r[a] * r[b] * p * (1.0 - p);
                    }
                }
            }
            for a in 0..N {
                grad[a] += ridge * w[a];
                hess[(a, a)] += ridge;
            }
            let llt = hess.llt(faer::Side::Lower).map_err(|_| CheckError::Diverged)?;
            let rhs = faer::Mat::from_fn(N, 1, |a, _| grad[a]);
            let step = faer::linalg::solvers::Solve::solve(&llt, &rhs);
            let mut largest = 0.0f64;
            for (a, wa) in w.iter_mut().enumerate() {
                *wa -= step[(a, 0)];
                largest = largest.max(step[(a, 0)].abs());
            }
            if largest < 1e-9 {
                break;
            }
        }
        if !w.iter().all(|v| v.is_finite()) {
            return Err(CheckError::Diverged);
        }
        let mut check = Self { weights: [w[0], w[1], w[2], w[3]], bias: w[4], threshold: 0.0, faces, others };
        let mut kept: Vec<f64> = samples.iter().filter(|s| s.1).map(|s| check.probability(&s.0)).collect();
        kept.sort_by(f64::total_cmp);
        let drop = ((1.0 - kept_share.clamp(0.0, 1.0)) * faces as f64).floor() as usize;
        check.threshold = kept.get(drop.min(faces - 1)).copied().unwrap_or(0.0);
        Ok(check)
    }

    /// The check in an init file's metadata JSON; `Ok(None)` if it has none.
    pub fn from_metadata(metadata: &str) -> Result<Option<Self>, CheckError> {
        let value: serde_json::Value = match serde_json::from_str(metadata) {
            Ok(v) => v,
            Err(_) => return Ok(None),
        };
        match value.get(METADATA_KEY) {
            None => Ok(None),
            Some(v) => serde_json::from_value(v.clone()).map(Some).map_err(|e| CheckError::Metadata(e.to_string())),
        }
    }

    /// `metadata` (JSON) with this check under [`METADATA_KEY`], replacing one it had.
    pub fn into_metadata(&self, metadata: &str) -> Result<String, CheckError> {
        let mut value: serde_json::Value = serde_json::from_str(metadata).unwrap_or_else(|_| serde_json::json!({}));
        let Some(map) = value.as_object_mut() else {
            return Err(CheckError::Metadata("the metadata is not a JSON object".into()));
        };
        map.insert(METADATA_KEY.into(), serde_json::to_value(self).map_err(|e| CheckError::Metadata(e.to_string()))?);
        serde_json::to_string(&value).map_err(|e| CheckError::Metadata(e.to_string()))
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn reading(gap: f32, fill: f32, offset: f32) -> ReadingAgreement {
        ReadingAgreement { mirror_gap: gap, fill, offset }
    }

    #[test]
    fn a_check_fitted_on_faces_and_false_faces_tells_them_apart() {
        // True faces read alike in the mirror and fill the box; false ones score as high but read
        // apart and small. A deterministic spread of each.
        let mut samples = Vec::new();
        for i in 0..60 {
            let t = i as f32 / 60.0;
            samples.push((features(0.9 + 0.09 * t, &reading(0.015 + 0.02 * t, 0.9 + 0.15 * t, 0.03 + 0.05 * t)), true));
            samples.push((features(0.9 + 0.09 * (1.0 - t), &reading(0.04 + 0.05 * t, 0.5 + 0.3 * t, 0.1 + 0.1 * t)), false));
        }
        let check = FaceCheck::fit(&samples, 0.95).unwrap();
        assert_eq!((check.faces, check.others), (60, 60));
        let passed = samples.iter().filter(|s| s.1 && check.probability(&s.0) >= check.threshold).count();
        assert!(passed >= 57, "95 % of the true faces pass: {passed}");
        let false_passed = samples.iter().filter(|s| !s.1 && check.probability(&s.0) >= check.threshold).count();
        assert!(false_passed <= 3, "the false faces fail: {false_passed} passed");
        assert!(check.passes(0.95, Some(&reading(0.02, 1.0, 0.04))));
        assert!(!check.passes(0.99, Some(&reading(0.08, 0.55, 0.2))));
        // Unmeasured or broken readings are not checked.
        assert!(check.passes(0.99, None) && check.passes(0.99, Some(&reading(f32::NAN, 1.0, 0.0))));
        // Through the metadata and back.
        let meta = check.into_metadata(r#"{"chunks": 40}"#).unwrap();
        assert!(meta.contains("\"chunks\":40"));
        assert_eq!(FaceCheck::from_metadata(&meta).unwrap(), Some(check));
        assert_eq!(FaceCheck::from_metadata(r#"{"chunks": 40}"#).unwrap(), None);
        assert!(FaceCheck::from_metadata(r#"{"face_check": {"bias": "x"}}"#).is_err());
    }

    #[test]
    fn too_few_boxes_are_refused() {
        let samples = vec![(features(0.9, &reading(0.02, 1.0, 0.0)), true); 20];
        assert!(matches!(FaceCheck::fit(&samples, 0.99), Err(CheckError::TooFew { faces: 20, others: 0 })));
    }
}
