//! The finder and initializer measured on a real-photo set (`docs/formats.md`, "Real-photo
//! detection set": each image `STEM.EXT` with a `STEM.faces.json` of reference boxes and 68 points):
//! recall and precision at IoU ≥ [`MATCH_IOU`] by face size, false positives per face-free image,
//! and the landmark error of the faces found.

use super::eval::{quantile, score_detection};
use super::{DetectError, Detector};
use gpmm_core::model::ibug::mirrored_ibug68;
use gpmm_core::net::face::{Detection, Reading};
use gpmm_core::net::face_box::{iou, landmark_box, FaceBox};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// A detection matches a reference face when their boxes' intersection over union reaches this.
pub const MATCH_IOU: f32 = 0.5;

/// Face size classes (larger side of the reference box, px): at least 64, 32 to 64, below 32.
pub const SIZE_CLASSES: [(&str, f32, f32); 3] = [(">=64", 64.0, f32::INFINITY), ("32-64", 32.0, 64.0), ("<32", 0.0, 32.0)];

/// A reference face of a `.faces.json` file.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct ReferenceFace {
    /// The reference detector's box: x0, y0, x1, y1 (px, origin at the top-left pixel's corner).
    #[serde(rename = "box")]
    pub bbox: [f32; 4],
    /// The reference's 68 iBUG points (px, same convention), if it read them.
    pub landmarks: Option<Vec<[f32; 2]>>,
}

impl ReferenceFace {
    /// The face's size: the larger side of its box (px).
    pub fn size(&self) -> f32 {
        let [x0, y0, x1, y1] = self.bbox;
        (x1 - x0).max(y1 - y0)
    }

    /// The square box the finder's is compared with: its landmarks' box (centre, larger side),
    /// as the finder's box is defined, or without landmarks the reference box's centre and larger
    /// side.
    pub fn square(&self) -> FaceBox {
        let (cx, cy, size) = match self.landmarks.as_deref() {
            Some(points) if !points.is_empty() => landmark_box(points),
            _ => {
                let [x0, y0, x1, y1] = self.bbox;
                ((x0 + x1) * 0.5, (y0 + y1) * 0.5, self.size())
            }
        };
        FaceBox { cx, cy, size, score: 1.0, looks: 1 }
    }
}

/// The reference faces of a photo `width` px wide as its mirror image shows them: each box
/// mirrored, and each point moved to where its mirror partner lies (the iBUG-68 pairs swapped, so
/// point 36 stays the image-left eye corner).
pub fn mirrored_faces(faces: &[ReferenceFace], width: f32) -> Vec<ReferenceFace> {
    faces
        .iter()
        .map(|f| {
            let [x0, y0, x1, y1] = f.bbox;
            let landmarks = f.landmarks.as_ref().map(|p| mirrored_ibug68(p, width).collect());
            ReferenceFace { bbox: [width - x1, y0, width - x0, y1], landmarks }
        })
        .collect()
}

/// A `.faces.json` file.
#[derive(Debug, Clone, Deserialize)]
pub struct FacesFile {
    /// Where the photo came from.
    #[serde(default)]
    pub source: String,
    /// The reference detector.
    #[serde(default)]
    pub reference: String,
    /// Every face in the photo (empty for a face-free photo).
    pub faces: Vec<ReferenceFace>,
}

/// Reads and checks a `.faces.json` file (68 points or none per face, finite boxes with area).
pub fn read_faces_file(path: &Path) -> Result<FacesFile, DetectError> {
    let bad = |what: String| DetectError::Io { path: path.to_owned(), error: std::io::Error::other(what) };
    let text = std::fs::read_to_string(path).map_err(|error| DetectError::Io { path: path.to_owned(), error })?;
    let file: FacesFile = serde_json::from_str(&text).map_err(|e| bad(format!("not a faces.json file: {e}")))?;
    for (k, f) in file.faces.iter().enumerate() {
        let [x0, y0, x1, y1] = f.bbox;
        if !(f.bbox.iter().all(|v| v.is_finite()) && x1 > x0 && y1 > y0) {
            return Err(bad(format!("face {k}: the box {:?} is not x0, y0, x1, y1 with x1 > x0 and y1 > y0", f.bbox)));
        }
        if let Some(points) = &f.landmarks {
            if points.len() != 68 || !points.iter().flatten().all(|v| v.is_finite()) {
                return Err(bad(format!("face {k}: {} landmarks; 68 finite points or null expected", points.len())));
            }
        }
    }
    Ok(file)
}

/// The images of a real-photo set: every .jpg/.jpeg/.png/.ppm with a `.faces.json` of its stem,
/// sorted by name.
pub fn list_photo_set(dir: &Path) -> Result<Vec<(PathBuf, PathBuf)>, DetectError> {
    Ok(list_photos(dir)?.into_iter().filter_map(|(photo, json)| Some((photo, json?))).collect())
}

/// Every .jpg/.jpeg/.png/.ppm of `dir`, sorted by name, with its `STEM.faces.json` if it has one.
pub fn list_photos(dir: &Path) -> Result<Vec<(PathBuf, Option<PathBuf>)>, DetectError> {
    let io = |error| DetectError::Io { path: dir.to_owned(), error };
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir).map_err(io)?.filter_map(|e| e.ok().map(|e| e.path())).collect();
    entries.sort();
    Ok(entries
        .into_iter()
        .filter(|p| {
            matches!(p.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref(), Some("png" | "jpg" | "jpeg" | "ppm"))
        })
        .map(|p| {
            let json = p.file_stem().and_then(|s| s.to_str()).map(|stem| p.with_file_name(format!("{stem}.faces.json")));
            let json = json.filter(|j| j.exists());
            (p, json)
        })
        .collect())
}

/// One detection of an image, scored.
#[derive(Debug, Clone, Serialize)]
pub struct PhotoDetection {
    /// Finder's box centre and side (px) and score.
    pub cx: f32,
    /// Centre, y (px).
    pub cy: f32,
    /// Side (px).
    pub size: f32,
    /// Finder score.
    pub score: f32,
    /// The reference face it matched (index in the faces.json), if any.
    pub matched: Option<usize>,
    /// Its IoU with that face's square box.
    pub iou: Option<f32>,
    /// Mean landmark distance over the reference's outer-eye-corner distance, when matched to a
    /// face with reference points.
    pub landmark_error: Option<f64>,
}

/// One image's result.
#[derive(Debug, Clone, Serialize)]
pub struct PhotoImage {
    /// Image file name.
    pub image: String,
    /// Reference faces' sizes (px), in the file's order.
    pub face_sizes: Vec<f32>,
    /// Whether each reference face was found.
    pub found: Vec<bool>,
    /// Every detection, best first.
    pub detections: Vec<PhotoDetection>,
}

/// Recall and precision in one face-size class.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SizeClassRow {
    /// The class (reference box's larger side, px).
    pub size: &'static str,
    /// Reference faces of this size.
    pub faces: usize,
    /// Of them, found.
    pub found: usize,
    /// found / faces (NaN without faces).
    pub recall: f64,
    /// Detections counted in this class: matched ones by their face's size, others by their own.
    pub detections: usize,
    /// Matched detections / detections (NaN without detections).
    pub precision: f64,
}

/// Summary over a real-photo set.
#[derive(Debug, Clone, Serialize)]
pub struct PhotoSummary {
    /// Images measured.
    pub images: usize,
    /// Of them, with no face.
    pub face_free_images: usize,
    /// Reference faces.
    pub faces: usize,
    /// Smallest finder score counted as a face.
    pub min_score: f32,
    /// Whether each photo's mirror image was scored too (counted in `images` and `faces`).
    pub mirror_images: bool,
    /// IoU a match needs.
    pub match_iou: f32,
    /// Over all sizes.
    pub all: SizeClassRow,
    /// Per size class ([`SIZE_CLASSES`]).
    pub by_size: Vec<SizeClassRow>,
    /// Detections on face-free images per face-free image (NaN without one).
    pub false_positives_per_face_free_image: f64,
    /// Found faces with reference points whose landmark error was measured.
    pub landmark_faces: usize,
    /// Median landmark error / IOD of found faces.
    pub median_landmark_error: f64,
    /// 90th percentile of it.
    pub p90_landmark_error: f64,
}

/// Scores an image's detections (best first) against its reference faces: each detection in turn
/// takes the unmatched face whose square box overlaps it most, if by at least [`MATCH_IOU`].
pub fn score_image(image: String, faces: &[ReferenceFace], dets: &[Detection]) -> PhotoImage {
    let mut found = vec![false; faces.len()];
    let mut detections = Vec::new();
    for det in dets {
        let best = faces
            .iter()
            .enumerate()
            .filter(|(k, _)| !found[*k])
            .map(|(k, f)| (k, iou(&det.face, &f.square())))
            .filter(|(_, o)| *o >= MATCH_IOU)
            .max_by(|a, b| a.1.total_cmp(&b.1).then(b.0.cmp(&a.0)));
        if let Some((k, _)) = best {
            found[k] = true;
        }
        let landmark_error = best.and_then(|(k, _)| faces[k].landmarks.as_deref().and_then(|r| score_detection(det, r).1));
        detections.push(PhotoDetection {
            cx: det.face.cx,
            cy: det.face.cy,
            size: det.face.size,
            score: det.face.score,
            matched: best.map(|b| b.0),
            iou: best.map(|b| b.1),
            landmark_error,
        });
    }
    PhotoImage { image, face_sizes: faces.iter().map(ReferenceFace::size).collect(), found, detections }
}

/// Sums scored images into the set's figures (`mirror_images`: whether they include the photos'
/// mirror images).
pub fn summarize(rows: &[PhotoImage], min_score: f32, mirror_images: bool) -> PhotoSummary {
    let row = |size: &'static str, lo: f32, hi: f32| {
        let within = |s: f32| s >= lo && s < hi;
        let (mut faces, mut found, mut detections, mut matched) = (0, 0, 0, 0);
        for r in rows {
            for (s, f) in r.face_sizes.iter().zip(&r.found) {
                faces += usize::from(within(*s));
                found += usize::from(within(*s) && *f);
            }
            for d in &r.detections {
                let s = d.matched.and_then(|k| r.face_sizes.get(k).copied()).unwrap_or(d.size);
                detections += usize::from(within(s));
                matched += usize::from(within(s) && d.matched.is_some());
            }
        }
        let ratio = |a: usize, b: usize| if b == 0 { f64::NAN } else { a as f64 / b as f64 };
        SizeClassRow { size, faces, found, recall: ratio(found, faces), detections, precision: ratio(matched, detections) }
    };
    let free: Vec<&PhotoImage> = rows.iter().filter(|r| r.face_sizes.is_empty()).collect();
    let errors: Vec<f64> = rows.iter().flat_map(|r| r.detections.iter().filter_map(|d| d.landmark_error)).collect();
    PhotoSummary {
        images: rows.len(),
        face_free_images: free.len(),
        faces: rows.iter().map(|r| r.face_sizes.len()).sum(),
        min_score,
        mirror_images,
        match_iou: MATCH_IOU,
        all: row("all", 0.0, f32::INFINITY),
        by_size: SIZE_CLASSES.iter().map(|&(n, lo, hi)| row(n, lo, hi)).collect(),
        false_positives_per_face_free_image: if free.is_empty() {
            f64::NAN
        } else {
            free.iter().map(|r| r.detections.len()).sum::<usize>() as f64 / free.len() as f64
        },
        landmark_faces: errors.len(),
        median_landmark_error: quantile(errors.clone(), 0.5),
        p90_landmark_error: quantile(errors, 0.9),
    }
}

/// A real-photo set's image, its reference faces and what the detector found in it.
#[derive(Debug, Clone)]
pub struct PhotoResult {
    /// The image file.
    pub path: PathBuf,
    /// Its reference faces (mirrored with the image).
    pub faces: Vec<ReferenceFace>,
    /// Whether this is the image's mirror image.
    pub mirrored: bool,
    /// The scored detections.
    pub scored: PhotoImage,
}

/// Detects every face of every image of the set in `dir` ([`list_photo_set`]) at `min_score`,
/// scanning for faces down to `smallest_face` px ([`Detector::scan_all`]), and scores them, on
/// all local cores ([`on_each_photo`]); `progress(done, total)` after each photo. With `mirror`,
/// each photo's mirror image is scored too ([`mirrored_faces`]), listed after it as
/// `STEM.mirrored.EXT`: a face turned one way and the same face turned the other count alike, so
/// figures depend less on which way a set's faces happen to turn. Results keep the set's order.
pub fn evaluate_photos(
    detector: &Detector,
    dir: &Path,
    (min_score, smallest_face): (f32, f32),
    reading: Reading,
    mirror: bool,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<(PhotoSummary, Vec<PhotoResult>), DetectError> {
    let photos = list_photo_set(dir)?.into_iter().map(|(photo, json)| (photo, Some(json))).collect();
    let views = on_each_photo(detector, photos, progress, |detector, path, faces, image| {
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        // The mirror image's view, made before the photo's own takes its faces.
        let mirror_view = mirror.then(|| {
            let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
            let ext = path.extension().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
            (image::imageops::flip_horizontal(image), mirrored_faces(&faces, image.width() as f32), format!("{stem}.mirrored.{ext}"))
        });
        let mut score = |image: &image::RgbImage, faces: Vec<ReferenceFace>, name: String, mirrored: bool| {
            let dets = detector.scan_all(image, min_score, smallest_face, reading)?;
            let scored = score_image(name, &faces, &dets);
            Ok::<_, DetectError>(PhotoResult { path: path.to_owned(), faces, mirrored, scored })
        };
        let mut views = vec![score(image, faces, name, false)?];
        if let Some((flipped, faces, name)) = mirror_view {
            views.push(score(&flipped, faces, name, true)?);
        }
        Ok(views)
    })?;
    let results: Vec<PhotoResult> = views.into_iter().flatten().collect();
    let rows: Vec<PhotoImage> = results.iter().map(|r| r.scored.clone()).collect();
    Ok((summarize(&rows, min_score, mirror), results))
}

/// Runs `work` on every photo of `photos` (an image and its faces file, or `None`: face-free)
/// with its reference faces and pixels, on the local cores, each with its own copy of
/// `detector`'s networks; `progress(done, total)` after each photo. Results keep the photos'
/// order; the first unreadable photo or faces file is the error.
pub fn on_each_photo<T: Send>(
    detector: &Detector,
    photos: Vec<(PathBuf, Option<PathBuf>)>,
    progress: &(dyn Fn(usize, usize) + Sync),
    work: impl Fn(&mut Detector, &Path, Vec<ReferenceFace>, &image::RgbImage) -> Result<T, DetectError> + Sync + Send,
) -> Result<Vec<T>, DetectError> {
    use rayon::prelude::*;
    let total = photos.len();
    let done = std::sync::atomic::AtomicUsize::new(0);
    photos
        .into_par_iter()
        .map_init(
            || detector.clone(),
            |detector, (path, json)| {
                let faces = match &json {
                    Some(json) => read_faces_file(json)?.faces,
                    None => Vec::new(),
                };
                let image =
                    image::open(&path).map_err(|e| DetectError::Io { path: path.clone(), error: std::io::Error::other(e) })?.to_rgb8();
                let result = work(detector, &path, faces, &image);
                progress(done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1, total);
                result
            },
        )
        .collect()
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    fn reference(x0: f32, y0: f32, side: f32) -> ReferenceFace {
        ReferenceFace { bbox: [x0, y0, x0 + side, y0 + side], landmarks: None }
    }

    fn detection(cx: f32, cy: f32, size: f32) -> Detection {
        Detection {
            face: FaceBox { cx, cy, size, score: 0.9, looks: 1 },
            landmarks: Default::default(),
            angles: [0.0; 3],
            light: Default::default(),
        }
    }

    #[test]
    fn a_hand_made_set_gives_known_recall_precision_and_false_positives() {
        // Image a: a 100 px face found, a 40 px face found twice (the duplicate is a false
        // positive), a 20 px face missed. Image b: a 70 px face missed, one false positive.
        // Images c and d: face-free, with 1 and 0 detections.
        let a = score_image(
            "a".into(),
            &[reference(0.0, 0.0, 100.0), reference(200.0, 0.0, 40.0), reference(300.0, 0.0, 20.0)],
            &[detection(50.0, 50.0, 100.0), detection(220.0, 20.0, 40.0), detection(222.0, 20.0, 40.0)],
        );
        assert_eq!(a.found, [true, true, false]);
        assert_eq!(a.detections.iter().map(|d| d.matched).collect::<Vec<_>>(), [Some(0), Some(1), None]);
        let b = score_image("b".into(), &[reference(0.0, 0.0, 70.0)], &[detection(500.0, 500.0, 30.0)]);
        let c = score_image("c".into(), &[], &[detection(10.0, 10.0, 80.0)]);
        let d = score_image("d".into(), &[], &[]);
        let s = summarize(&[a, b, c, d], 0.5, false);
        assert_eq!((s.images, s.face_free_images, s.faces), (4, 2, 4));
        assert_eq!((s.all.faces, s.all.found, s.all.detections), (4, 2, 5));
        assert_eq!(s.all.recall, 0.5);
        assert_eq!(s.all.precision, 2.0 / 5.0);
        let by: Vec<(usize, usize, usize)> = s.by_size.iter().map(|r| (r.faces, r.found, r.detections)).collect();
        // ≥ 64: the 100 and 70 px faces, the 100 px match and the 80 px false positive;
        // 32–64: the 40 px face, its match and duplicate, and the 30 px false positive counts below 32.
        assert_eq!(by, [(2, 1, 2), (1, 1, 2), (1, 0, 1)]);
        assert_eq!(s.by_size[0].recall, 0.5);
        assert_eq!(s.by_size[1].precision, 0.5);
        assert!(s.by_size[2].recall == 0.0 && s.by_size[2].precision == 0.0);
        assert_eq!(s.false_positives_per_face_free_image, 0.5);
        assert_eq!(s.landmark_faces, 0);
    }

    #[test]
    fn landmarks_define_the_reference_square_and_are_scored() {
        let mut points: Vec<[f32; 2]> = (0..68).map(|i| [10.0 + i as f32, 20.0 + (i % 2) as f32 * 60.0]).collect();
        points[36] = [30.0, 40.0];
        points[45] = [50.0, 40.0];
        let face = ReferenceFace { bbox: [0.0, 0.0, 200.0, 200.0], landmarks: Some(points.clone()) };
        let sq = face.square();
        assert_eq!((sq.cx, sq.cy, sq.size), (43.5, 50.0, 67.0));
        assert_eq!(face.size(), 200.0);
        let mut det = detection(43.5, 50.0, 67.0);
        det.landmarks = points.iter().map(|p| [p[0] + 2.0, p[1]]).collect();
        let scored = score_image("x".into(), &[face], &[det]);
        // Every point 2 px off over an IOD of 20 px.
        assert!((scored.detections[0].landmark_error.unwrap() - 0.1).abs() < 1e-9);
    }

    #[test]
    fn mirrored_faces_swap_sides_and_partners_and_mirror_back() {
        let points: Vec<[f32; 2]> = (0..68).map(|i| [10.0 + i as f32, 5.0 + (i % 7) as f32]).collect();
        let face = ReferenceFace { bbox: [10.0, 20.0, 40.0, 60.0], landmarks: Some(points.clone()) };
        let m = mirrored_faces(&[face.clone(), reference(0.0, 0.0, 8.0)], 100.0);
        assert_eq!(m[0].bbox, [60.0, 20.0, 90.0, 60.0]);
        assert_eq!(m[1].bbox, [92.0, 0.0, 100.0, 8.0]);
        assert!(m[1].landmarks.is_none());
        let mp = m[0].landmarks.as_ref().unwrap();
        // Point 36 (image-left outer eye corner) is where 45 was, mirrored; the nose tip stays 30.
        assert_eq!(mp[36], [100.0 - points[45][0], points[45][1]]);
        assert_eq!(mp[30], [100.0 - points[30][0], points[30][1]]);
        assert_eq!(mirrored_faces(&m, 100.0), vec![face, reference(0.0, 0.0, 8.0)]);
    }

    #[test]
    fn a_faces_file_with_a_bad_box_or_point_count_is_refused_with_its_name() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("p.faces.json");
        std::fs::write(&path, r#"{"source": "s", "reference": "r", "faces": [{"box": [10, 10, 5, 20], "landmarks": null}]}"#).unwrap();
        let err = read_faces_file(&path).unwrap_err().to_string();
        assert!(err.contains("p.faces.json") && err.contains("face 0"), "{err}");
        std::fs::write(&path, r#"{"faces": [{"box": [0, 0, 5, 5], "landmarks": [[1, 2]]}]}"#).unwrap();
        assert!(read_faces_file(&path).unwrap_err().to_string().contains("1 landmarks"));
        std::fs::write(&path, r#"{"faces": []}"#).unwrap();
        assert!(read_faces_file(&path).unwrap().faces.is_empty());
        std::fs::write(dir.path().join("p.png"), b"").unwrap();
        std::fs::write(dir.path().join("q.png"), b"").unwrap();
        let listed = list_photo_set(dir.path()).unwrap();
        assert_eq!(listed.len(), 1);
        assert!(listed[0].0.ends_with("p.png"));
    }
}
