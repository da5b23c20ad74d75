//! The finder and initializer measured on images with reference landmarks (a `gpmm synth` set,
//! an independent renderer's set, or photos with .pts files): found rate, landmark error over
//! the inter-ocular distance, yaw error per |yaw| where a truth.json gives the yaw.

use super::{DetectError, Detector};
use crate::photo::pts::read_pts;
use gpmm_core::net::face::Detection;
use gpmm_core::net::face_box::landmark_box;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// One image's result.
#[derive(Debug, Clone, Serialize)]
pub struct DetectImage {
    /// Image file name.
    pub image: String,
    /// The box's centre lies within half a face size of the reference landmarks' box centre.
    pub found: bool,
    /// Finder score.
    pub score: f32,
    /// The finder's box size over the reference landmarks' box size (larger sides).
    pub box_size_ratio: Option<f64>,
    /// Mean landmark distance over the reference's outer-eye-corner distance (points 36, 45).
    pub landmark_error: Option<f64>,
    /// The truth's yaw (degrees), if known.
    pub yaw_deg: Option<f64>,
    /// Initializer's yaw minus the truth's (degrees).
    pub yaw_error_deg: Option<f64>,
    /// The detected landmarks (image pixels; empty when nothing was detected).
    #[serde(skip)]
    pub landmarks: Vec<[f32; 2]>,
}

/// Per-|yaw| medians.
#[derive(Debug, Clone, Serialize)]
pub struct DetectYawRow {
    /// |yaw| (degrees).
    pub abs_yaw_deg: f64,
    /// Images.
    pub images: usize,
    /// Median landmark error / IOD.
    pub median_landmark_error: f64,
    /// Median |yaw error| (degrees).
    pub median_abs_yaw_error_deg: f64,
    /// Mean signed yaw error (degrees, the initializer's yaw minus the truth's, with the sign of
    /// the truth's yaw: negative means turned toward frontal).
    pub mean_yaw_bias_deg: f64,
}

/// Summary over a directory.
#[derive(Debug, Clone, Serialize)]
pub struct DetectSummary {
    /// Images measured.
    pub images: usize,
    /// Fraction where the face was found.
    pub found: f64,
    /// Median landmark error / IOD over found faces.
    pub median_landmark_error: f64,
    /// 90th percentile of it.
    pub p90_landmark_error: f64,
    /// Median |yaw error| (degrees) where the yaw is known.
    pub median_abs_yaw_error_deg: f64,
    /// The finder's box size over the reference's: 10th, 50th and 90th percentile over all
    /// images (1 is right; the initializer is trained for crops within about ±16 %).
    pub box_size_ratio: [f64; 3],
    /// Per |yaw| (sets with a truth.json).
    pub per_yaw: Vec<DetectYawRow>,
}

/// The `q` quantile of the finite values of `v` (NaN if there is none).
pub fn quantile(mut v: Vec<f64>, q: f64) -> f64 {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

/// A detection against reference landmarks: whether the face was found (the box's centre within
/// half a face size of the reference box's) and the mean landmark distance over the outer-eye-
/// corner distance (points 36 and 45; `None` if the point counts differ).
pub fn score_detection(det: &Detection, refs: &[[f32; 2]]) -> (bool, Option<f64>) {
    let (cx, cy, size) = landmark_box(refs);
    let found = (det.face.cx - cx).hypot(det.face.cy - cy) < 0.5 * size;
    let iod = refs.get(36).zip(refs.get(45)).map(|(a, b)| (a[0] - b[0]).hypot(a[1] - b[1])).unwrap_or(size).max(1e-3);
    let error = (det.landmarks.len() == refs.len()).then(|| {
        det.landmarks.iter().zip(refs).map(|(a, b)| f64::from((a[0] - b[0]).hypot(a[1] - b[1]))).sum::<f64>()
            / refs.len() as f64
            / f64::from(iod)
    });
    (found, error)
}

/// An image to measure the detector on and its reference landmarks.
#[derive(Debug, Clone, PartialEq)]
pub struct EvalImage {
    /// The image file.
    pub image: PathBuf,
    /// Reference .pts files, one per face (several for a photo of several people).
    pub references: Vec<PathBuf>,
    /// The truth's yaw (degrees), if known.
    pub yaw_deg: Option<f64>,
}

/// The images of a directory: from its truth.json (a `gpmm synth` set), else every image with a
/// .pts of the same stem (`NAME.pts`, or one per face: `NAME_0.pts`, `NAME_1.pts`, …).
pub fn list_images(dir: &Path, reference_dir: Option<&Path>) -> Result<Vec<EvalImage>, DetectError> {
    let io = |error| DetectError::Io { path: dir.to_owned(), error };
    let refdir = reference_dir.unwrap_or(dir);
    let truth = dir.join("truth.json");
    if let Ok(text) = std::fs::read_to_string(&truth) {
        let json: serde_json::Value = serde_json::from_str(&text).map_err(|e| io(std::io::Error::other(format!("truth.json: {e}"))))?;
        let images = json["images"].as_array().cloned().unwrap_or_default();
        return Ok(images
            .iter()
            .filter_map(|im| {
                let name = im["image"].as_str()?;
                let pts = refdir.join(Path::new(name).with_extension("pts"));
                Some(EvalImage { image: dir.join(name), references: vec![pts], yaw_deg: im["yaw_deg"].as_f64() })
            })
            .collect());
    }
    let mut out = Vec::new();
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir).map_err(io)?.filter_map(|e| e.ok().map(|e| e.path())).collect();
    entries.sort();
    for p in entries {
        let ext = p.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
        if !matches!(ext.as_str(), "png" | "jpg" | "jpeg" | "ppm") {
            continue;
        }
        let stem = p.file_stem().and_then(|s| s.to_str()).unwrap_or("");
        let single = refdir.join(format!("{stem}.pts"));
        let references: Vec<PathBuf> = if single.exists() {
            vec![single]
        } else {
            (0..).map(|k| refdir.join(format!("{stem}_{k}.pts"))).take_while(|q| q.exists()).collect()
        };
        if !references.is_empty() {
            out.push(EvalImage { image: p, references, yaw_deg: None });
        }
    }
    Ok(out)
}

/// Detects every listed image and compares with its reference (with several, the face whose
/// landmarks' box centre is nearest the finder's box: a photo of two people counts the one found).
pub fn evaluate(
    detector: &mut Detector,
    images: &[EvalImage],
    one_based: bool,
    reading: gpmm_core::net::face::Reading,
) -> Result<(DetectSummary, Vec<DetectImage>), DetectError> {
    let mut rows = Vec::new();
    for EvalImage { image, references, yaw_deg: yaw } in images {
        let img = image::open(image).map_err(|e| DetectError::Io { path: image.clone(), error: std::io::Error::other(e) })?.to_rgb8();
        let mut faces = Vec::new();
        for pts in references {
            let reference =
                read_pts(pts, one_based).map_err(|e| DetectError::Io { path: pts.clone(), error: std::io::Error::other(e.to_string()) })?;
            faces.push(reference.points.iter().map(|p| [p[0], p[1]]).collect::<Vec<[f32; 2]>>());
        }
        let det = detector.detect(&img, 0.0, reading)?;
        let refs = nearest_face(&faces, det.as_ref().map(|d| (d.face.cx, d.face.cy)));
        let name = image.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let Some(det) = det else {
            rows.push(DetectImage {
                image: name,
                found: false,
                score: 0.0,
                box_size_ratio: None,
                landmark_error: None,
                yaw_deg: *yaw,
                yaw_error_deg: None,
                landmarks: Vec::new(),
            });
            continue;
        };
        let (found, landmark_error) = score_detection(&det, &refs);
        let yaw_error_deg = yaw.map(|y| f64::from(det.angles[0].to_degrees()) - y);
        let landmarks = det.landmarks.to_vec();
        let box_size_ratio = Some(f64::from(det.face.size / landmark_box(&refs).2.max(1e-3)));
        rows.push(DetectImage {
            image: name,
            found,
            score: det.face.score,
            box_size_ratio,
            landmark_error,
            yaw_deg: *yaw,
            yaw_error_deg,
            landmarks,
        });
    }
    let found: Vec<&DetectImage> = rows.iter().filter(|r| r.found).collect();
    let errs: Vec<f64> = found.iter().filter_map(|r| r.landmark_error).collect();
    let mut yaws: Vec<f64> = rows.iter().filter_map(|r| r.yaw_deg.map(f64::abs)).collect();
    yaws.sort_by(f64::total_cmp);
    yaws.dedup();
    let per_yaw = yaws
        .iter()
        .map(|&a| {
            let at: Vec<&&DetectImage> = found.iter().filter(|r| r.yaw_deg.map(f64::abs) == Some(a)).collect();
            DetectYawRow {
                abs_yaw_deg: a,
                images: at.len(),
                median_landmark_error: quantile(at.iter().filter_map(|r| r.landmark_error).collect(), 0.5),
                median_abs_yaw_error_deg: quantile(at.iter().filter_map(|r| r.yaw_error_deg.map(f64::abs)).collect(), 0.5),
                mean_yaw_bias_deg: {
                    let b: Vec<f64> =
                        at.iter().filter_map(|r| Some(r.yaw_error_deg? * r.yaw_deg?.signum())).filter(|v| v.is_finite()).collect();
                    if b.is_empty() {
                        f64::NAN
                    } else {
                        b.iter().sum::<f64>() / b.len() as f64
                    }
                },
            }
        })
        .collect();
    let summary = DetectSummary {
        images: rows.len(),
        found: found.len() as f64 / rows.len().max(1) as f64,
        median_landmark_error: quantile(errs.clone(), 0.5),
        p90_landmark_error: quantile(errs, 0.9),
        median_abs_yaw_error_deg: quantile(found.iter().filter_map(|r| r.yaw_error_deg.map(f64::abs)).collect(), 0.5),
        box_size_ratio: {
            let r: Vec<f64> = rows.iter().filter_map(|r| r.box_size_ratio).collect();
            [0.1, 0.5, 0.9].map(|q| quantile(r.clone(), q))
        },
        per_yaw,
    };
    Ok((summary, rows))
}

/// The reference face whose landmarks' box centre is nearest `at` (the first without a point, or
/// none given).
fn nearest_face(faces: &[Vec<[f32; 2]>], at: Option<(f32, f32)>) -> Vec<[f32; 2]> {
    let distance = |f: &Vec<[f32; 2]>| {
        let (cx, cy, _) = landmark_box(f);
        at.map_or(0.0, |(x, y)| (cx - x).hypot(cy - y))
    };
    faces.iter().min_by(|a, b| distance(a).total_cmp(&distance(b))).cloned().unwrap_or_default()
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn a_photo_of_several_people_lists_every_face_and_is_scored_on_the_nearest() {
        let dir = std::env::temp_dir().join(format!("gpmm-eval-list-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        for f in ["two.jpg", "two_0.pts", "two_1.pts", "one.png", "one.pts", "none.png"] {
            std::fs::write(dir.join(f), b"").unwrap();
        }
        let list = list_images(&dir, None).unwrap();
        let names: Vec<(String, usize)> =
            list.iter().map(|e| (e.image.file_name().unwrap().to_string_lossy().into_owned(), e.references.len())).collect();
        assert_eq!(names, [("one.png".to_string(), 1), ("two.jpg".to_string(), 2)]);
        std::fs::remove_dir_all(&dir).unwrap();
        let left = vec![[10.0f32, 10.0], [30.0, 30.0]];
        let right = vec![[110.0f32, 10.0], [130.0, 30.0]];
        let faces = [left.clone(), right.clone()];
        assert_eq!(nearest_face(&faces, Some((118.0, 22.0))), right);
        assert_eq!(nearest_face(&faces, Some((25.0, 15.0))), left);
        assert_eq!(nearest_face(&faces, None), left);
    }
}
