//! Rank-1 identification of the probes against the gallery, and its accuracy per probe yaw.
//!
//! The gallery is every yaw-0 image, the probes every other image. A probe is identified as the
//! gallery identity of the highest score ([`crate::eval::models::kde::score`]: the best cosine
//! similarity over the components whose fits exist); a probe whose fit failed, or that has no
//! scored gallery image, is identified as nobody and counts as wrong.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::eval::models::kde::score;
use crate::eval::wilson_interval;

use super::fits::{Feature, FitSet};
pub use super::set::LabeledImage;

/// The normal quantile of the reported Wilson intervals (95 %).
const Z95: f64 = 1.96;

/// How one probe was identified.
#[derive(Debug, Clone, PartialEq)]
pub struct Probe {
    /// Image file name.
    pub image: String,
    /// True identity.
    pub identity: usize,
    /// Yaw (degrees).
    pub yaw_deg: f32,
    /// The gallery identity of the highest score (`None`: no score, e.g. the probe's fit failed).
    pub predicted: Option<usize>,
}

impl Probe {
    /// Whether the probe was identified as its own identity.
    pub fn correct(&self) -> bool {
        self.predicted == Some(self.identity)
    }
}

/// A probe as the report records it: image, true identity, predicted identity (written as a
/// JSON array of the three).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(from = "(String, usize, Option<usize>)", into = "(String, usize, Option<usize>)")]
pub struct ProbeOutcome {
    /// Image file name.
    pub image: String,
    /// True identity.
    pub identity: usize,
    /// Predicted identity.
    pub predicted: Option<usize>,
}

impl From<(String, usize, Option<usize>)> for ProbeOutcome {
    fn from((image, identity, predicted): (String, usize, Option<usize>)) -> Self {
        Self { image, identity, predicted }
    }
}

impl From<ProbeOutcome> for (String, usize, Option<usize>) {
    fn from(p: ProbeOutcome) -> Self {
        (p.image, p.identity, p.predicted)
    }
}

impl From<Probe> for ProbeOutcome {
    fn from(p: Probe) -> Self {
        Self { image: p.image, identity: p.identity, predicted: p.predicted }
    }
}

/// Accuracy at one probe yaw.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct YawAccuracy {
    /// Probe yaw (degrees).
    pub yaw_deg: f32,
    /// Probes identified correctly (rank 1).
    pub correct: usize,
    /// Probes.
    pub total: usize,
    /// correct / total.
    pub accuracy: f64,
    /// Wilson 95 % interval of the accuracy.
    pub wilson95: [f64; 2],
}

impl YawAccuracy {
    /// The accuracy of `probes` (all counted; labelled with `yaw_deg`).
    fn of<'a>(yaw_deg: f32, probes: impl Iterator<Item = &'a Probe>) -> Self {
        let (mut correct, mut total) = (0, 0);
        for p in probes {
            correct += usize::from(p.correct());
            total += 1;
        }
        let (lo, hi) = wilson_interval(correct, total, Z95);
        Self { yaw_deg, correct, total, accuracy: if total > 0 { correct as f64 / total as f64 } else { 0.0 }, wilson95: [lo, hi] }
    }
}

/// Every probe's identification and the accuracy per probe yaw and pooled.
#[derive(Debug, Clone, PartialEq)]
pub struct Identification {
    /// Every probe, in the order of the images.
    pub probes: Vec<Probe>,
    /// Accuracy per probe yaw (in the order asked for).
    pub per_yaw: Vec<YawAccuracy>,
    /// Accuracy over all probes (every probe yaw pooled; `yaw_deg` is NaN).
    pub pooled: YawAccuracy,
}

impl Identification {
    /// Identifies the probes among `images` from the fits of each component (by `feature`) and
    /// scores them at each of `yaws`.
    pub fn new(images: &[LabeledImage<'_>], components: &[FitSet], feature: Feature, yaws: &[f32]) -> Self {
        let probes = identify(images, components, feature);
        Self { per_yaw: accuracy_by_yaw(&probes, yaws), pooled: pooled(&probes), probes }
    }
}

/// Rank-1 identification of every probe (non-zero yaw) among `images` against the gallery (yaw 0)
/// from the fits of each component.
pub fn identify(images: &[LabeledImage<'_>], components: &[FitSet], feature: Feature) -> Vec<Probe> {
    let maps: Vec<BTreeMap<&str, Vec<f32>>> =
        components.iter().map(|c| c.fits.iter().map(|f| (f.image.as_str(), f.features(feature))).collect()).collect();
    let features = |image: &str| -> Vec<Option<&[f32]>> { maps.iter().map(|m| m.get(image).map(Vec::as_slice)).collect() };
    let gallery: Vec<(usize, Vec<Option<&[f32]>>)> =
        images.iter().filter(|t| t.yaw_deg == 0.0).map(|g| (g.identity, features(g.image))).collect();
    images
        .iter()
        .filter(|t| t.yaw_deg != 0.0)
        .map(|p| {
            let probe = features(p.image);
            let mut best: Option<(f64, usize)> = None;
            for (identity, gal) in &gallery {
                if let Some(s) = score(&probe, gal) {
                    if best.is_none_or(|(bs, _)| s > bs) {
                        best = Some((s, *identity));
                    }
                }
            }
            Probe { image: p.image.to_string(), identity: p.identity, yaw_deg: p.yaw_deg, predicted: best.map(|b| b.1) }
        })
        .collect()
}

/// Accuracy per probe yaw of identified probes (a yaw without probes: 0 of 0).
pub fn accuracy_by_yaw(probes: &[Probe], yaws: &[f32]) -> Vec<YawAccuracy> {
    yaws.iter().map(|&y| YawAccuracy::of(y, probes.iter().filter(|p| p.yaw_deg == y))).collect()
}

/// Accuracy over all identified probes (every probe yaw pooled; `yaw_deg` is NaN).
pub fn pooled(probes: &[Probe]) -> YawAccuracy {
    YawAccuracy::of(f32::NAN, probes.iter())
}

#[cfg(test)]
mod tests {
    use super::super::fits::ImageFit;
    use super::*;

    fn fit(image: &str, identity: usize, yaw_deg: f32, shape: &[f32], color: &[f32]) -> ImageFit {
        ImageFit {
            image: image.into(),
            identity,
            yaw_deg,
            shape: shape.to_vec(),
            color: color.to_vec(),
            pixel_rmse: 0.0,
            seconds: 0.0,
            vertex_sd_mm: Vec::new(),
        }
    }

    fn fit_set(fits: Vec<ImageFit>) -> FitSet {
        FitSet { key: serde_json::Value::Null, fits, failures: Vec::new(), wall_seconds: 0.0, jobs: 1 }
    }

    fn labeled(fits: &[ImageFit]) -> Vec<LabeledImage<'_>> {
        fits.iter().map(|f| LabeledImage { image: &f.image, identity: f.identity, yaw_deg: f.yaw_deg }).collect()
    }

    /// Three identities along the three axes (gallery at yaw 0); at 15° every probe points near its
    /// own axis, at 30° identity 2's probe points nearest identity 0's.
    fn gallery_and_probes() -> Vec<ImageFit> {
        vec![
            fit("0_00", 0, 0.0, &[1.0, 0.0, 0.0], &[1.0]),
            fit("1_00", 1, 0.0, &[0.0, 1.0, 0.0], &[1.0]),
            fit("2_00", 2, 0.0, &[0.0, 0.0, 1.0], &[1.0]),
            fit("0_15", 0, 15.0, &[0.9, 0.1, 0.0], &[1.0]),
            fit("1_15", 1, 15.0, &[0.1, 0.9, 0.1], &[1.0]),
            fit("2_15", 2, 15.0, &[0.0, 0.2, 0.8], &[1.0]),
            fit("0_30", 0, 30.0, &[0.7, 0.3, 0.0], &[1.0]),
            fit("1_30", 1, 30.0, &[0.2, 0.8, 0.0], &[1.0]),
            fit("2_30", 2, 30.0, &[0.9, 0.0, 0.3], &[1.0]),
        ]
    }

    #[test]
    fn identification_picks_the_most_similar_gallery_identity() {
        let fits = gallery_and_probes();
        let images = labeled(&fits);
        let probes = identify(&images, &[fit_set(fits.clone())], Feature::Shape);
        let got: Vec<(&str, Option<usize>)> = probes.iter().map(|p| (p.image.as_str(), p.predicted)).collect();
        assert_eq!(got, [("0_15", Some(0)), ("1_15", Some(1)), ("2_15", Some(2)), ("0_30", Some(0)), ("1_30", Some(1)), ("2_30", Some(0))]);
        assert_eq!(probes.iter().filter(|p| p.correct()).count(), 5);
        // The colour coefficients are all the same: every gallery identity ties and the first wins.
        let by_color = identify(&images, &[fit_set(fits.clone())], Feature::Color);
        assert!(by_color.iter().all(|p| p.predicted == Some(0)));
        // The joint vector appends the colour: the same ranking as the shape here.
        let joint = identify(&images, &[fit_set(fits.clone())], Feature::Joint);
        assert_eq!(joint.iter().map(|p| p.predicted).collect::<Vec<_>>(), probes.iter().map(|p| p.predicted).collect::<Vec<_>>());
    }

    #[test]
    fn a_failed_fit_identifies_nobody() {
        let fits = gallery_and_probes();
        let images = labeled(&fits);
        // The 15° probe of identity 1 was not fitted, nor was identity 2's gallery image.
        let kept: Vec<ImageFit> = fits.iter().filter(|f| f.image != "1_15" && f.image != "2_00").cloned().collect();
        let probes = identify(&images, &[fit_set(kept)], Feature::Shape);
        let p = probes.iter().find(|p| p.image == "1_15").unwrap();
        assert_eq!(p.predicted, None);
        assert!(!p.correct());
        // Without its gallery image, identity 2's probes cannot be right.
        assert!(probes.iter().filter(|p| p.identity == 2).all(|p| !p.correct()));
    }

    #[test]
    fn several_components_take_the_best_cosine() {
        let fits = gallery_and_probes();
        let images = labeled(&fits);
        // A second component in which every image matches its own gallery image exactly: identity
        // 2's 30° probe, wrong in the first, is right with both.
        let mut second = fits.clone();
        for f in second.iter_mut() {
            f.shape = if f.identity == 2 { vec![-1.0, 5.0] } else { vec![f.identity as f32 + 1.0, 1.0] };
        }
        let probes = identify(&images, &[fit_set(fits.clone()), fit_set(second)], Feature::Shape);
        assert!(probes.iter().all(Probe::correct), "{probes:?}");
    }

    #[test]
    fn accuracy_per_yaw_counts_and_brackets_the_probes() {
        let fits = gallery_and_probes();
        let images = labeled(&fits);
        let result = Identification::new(&images, &[fit_set(fits.clone())], Feature::Shape, &[15.0, 30.0, 45.0]);
        let counts: Vec<(f32, usize, usize)> = result.per_yaw.iter().map(|a| (a.yaw_deg, a.correct, a.total)).collect();
        assert_eq!(counts, [(15.0, 3, 3), (30.0, 2, 3), (45.0, 0, 0)]);
        assert_eq!(result.per_yaw[0].accuracy, 1.0);
        assert!((result.per_yaw[1].accuracy - 2.0 / 3.0).abs() < 1e-12);
        // Wilson 95 %: 3 of 3 is [0.4385, 1], 2 of 3 is [0.2077, 0.9385]; no probes: [0, 1].
        let [lo, hi] = result.per_yaw[0].wilson95;
        assert!((lo - 0.4385).abs() < 1e-3 && hi == 1.0, "{lo} {hi}");
        let [lo, hi] = result.per_yaw[1].wilson95;
        assert!((lo - 0.2077).abs() < 1e-3 && (hi - 0.9385).abs() < 1e-3, "{lo} {hi}");
        assert_eq!((result.per_yaw[2].accuracy, result.per_yaw[2].wilson95), (0.0, [0.0, 1.0]));
        for a in &result.per_yaw {
            assert!(a.wilson95[0] <= a.accuracy && a.accuracy <= a.wilson95[1]);
        }
        assert_eq!((result.pooled.correct, result.pooled.total), (5, 6));
        assert!(result.pooled.yaw_deg.is_nan());
        assert_eq!(result.pooled.wilson95, {
            let (l, h) = wilson_interval(5, 6, 1.96);
            [l, h]
        });
    }

    #[test]
    fn a_probe_outcome_is_written_as_an_array() {
        let p = ProbeOutcome { image: "0001_yaw15.png".into(), identity: 1, predicted: None };
        let json = serde_json::to_string(&p).unwrap();
        assert_eq!(json, r#"["0001_yaw15.png",1,null]"#);
        assert_eq!(serde_json::from_str::<ProbeOutcome>(&json).unwrap(), p);
    }
}
