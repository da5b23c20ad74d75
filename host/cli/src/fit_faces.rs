//! `gpmm fit --faces all`: every face of a photo found, read and fitted, each into a folder of its
//! own, with a summary (`faces.json`) and the whole photo with every fit drawn in (`faces.png`).

use crate::detect::{draw_detection, faces_for_fit, write_pts};
use anyhow::{Context, Result};
use gpmm_host::detect::record::FaceRecord;
use gpmm_host::fit::{fit_faces, FaceToFit, FitOptions};
use gpmm_host::gp::model_io;
use std::path::Path;
use std::time::Instant;

/// What `gpmm fit --faces all` is given.
#[derive(Debug)]
pub struct AllFaces<'a> {
    /// Model file.
    pub model: &'a Path,
    /// Photo.
    pub image: &'a Path,
    /// Init file (`None`: the shipped start).
    pub init: Option<&'a Path>,
    /// Smallest finder score (`None`: the file's advised one).
    pub min_score: Option<f32>,
    /// Fit settings.
    pub settings: &'a FitOptions,
    /// Output directory.
    pub out_dir: &'a Path,
    /// Record timing in each fit.json.
    pub timing: bool,
}

/// The folder of face `i` under the output directory.
pub fn face_folder(i: usize) -> String {
    format!("face-{i:02}")
}

/// Runs `gpmm fit --faces all`.
pub fn fit_all_faces(job: &AllFaces<'_>) -> Result<()> {
    let t0 = Instant::now();
    let model = model_io::load(job.model)?;
    let (photo, faces) = faces_for_fit(job.image, job.init, job.min_score, true)?;
    let (w, h) = photo.dimensions();
    std::fs::create_dir_all(job.out_dir).with_context(|| format!("cannot create {}", job.out_dir.display()))?;
    let detected = job.out_dir.join("detected.png");
    faces
        .iter()
        .fold(photo.clone(), |img, d| draw_detection(&img, d))
        .save(&detected)
        .with_context(|| format!("cannot write {}", detected.display()))?;
    let mut to_fit = Vec::with_capacity(faces.len());
    for (i, det) in faces.iter().enumerate() {
        let dir = job.out_dir.join(face_folder(i));
        std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
        write_pts(&dir.join("detected.pts"), &det.landmarks, w, h)?;
        let (inside, _) = gpmm_host::photo::pts::within_margin(&det.landmarks, w, h);
        to_fit.push(FaceToFit { folder: face_folder(i), landmarks: inside });
    }
    eprintln!(
        "{}: {} faces found; fitting each ({} + {} steps)",
        job.image.display(),
        faces.len(),
        job.settings.fit.landmarks.steps,
        job.settings.fit.image.steps
    );
    let bar = crate::progress::counter(faces.len(), "faces fitted");
    let progress = |done: usize, _: usize| bar.set_position(done as u64);
    let (fitted, picture) = fit_faces(&model, job.model, job.image, &photo, &to_fit, job.settings, job.out_dir, job.timing, &progress)?;
    bar.finish_and_clear();
    let picture_path = job.out_dir.join("faces.png");
    picture.save(&picture_path).with_context(|| format!("cannot write {}", picture_path.display()))?;
    let mut rows = Vec::with_capacity(faces.len());
    let mut failed = 0;
    for (i, (det, fit)) in faces.iter().zip(&fitted).enumerate() {
        let face = FaceRecord::from(det);
        let mut row = serde_json::json!({ "index": i, "folder": face_folder(i), "box": face.face_box });
        match &fit.result {
            Ok(rep) => {
                row["fit"] = serde_json::json!({
                    "yaw_deg": rep.yaw_deg, "pitch_deg": rep.pitch_deg, "roll_deg": rep.roll_deg,
                    "landmark_rmse_px": rep.landmark_rmse_original_px, "pixel_rmse": rep.pixel_rmse,
                });
                eprintln!(
                    "  {}: {:.0} px at ({:.0}, {:.0}), yaw {:+.0} pitch {:+.0} roll {:+.0} deg, landmark RMSE {:.1} px, pixel RMSE {:.3}",
                    face_folder(i),
                    det.face.size,
                    det.face.cx,
                    det.face.cy,
                    rep.yaw_deg,
                    rep.pitch_deg,
                    rep.roll_deg,
                    rep.landmark_rmse_original_px,
                    rep.pixel_rmse
                );
            }
            Err(e) => {
                failed += 1;
                row["error"] = serde_json::Value::String(e.clone());
                eprintln!("  {}: not fitted: {e}", face_folder(i));
            }
        }
        rows.push(row);
    }
    let summary = serde_json::json!({
        "image": job.image,
        "model": job.model,
        "init": gpmm_host::detect::shipped::init_name(job.init),
        "faces_found": faces.len(),
        "faces_fitted": faces.len() - failed,
        "faces": rows,
    });
    let summary_path = job.out_dir.join("faces.json");
    std::fs::write(&summary_path, serde_json::to_string_pretty(&summary)? + "\n")
        .with_context(|| format!("cannot write {}", summary_path.display()))?;
    eprintln!(
        "fitted {} of {} faces in {:.1} s; wrote faces.json, faces.png, detected.png and face-00/ … to {}",
        faces.len() - failed,
        faces.len(),
        t0.elapsed().as_secs_f64(),
        job.out_dir.display()
    );
    Ok(())
}
