//! Every face of a photo fitted (`gpmm fit --faces all`): the photo and the model read once,
//! each face's landmarks (from a detector) cropped and fitted on its own, each fit's files in a
//! folder of its own, and one picture of the whole photo with every fit drawn in.

use super::error::FitRunError;
use super::input::{check_landmarks, prepare, Prepared};
use super::job::write_fit_files;
use super::options::FitOptions;
use super::overlay::put;
use super::pipeline::{fit_prepared, Outcome};
use super::report::{report, FitReport, ReportInputs};
use crate::gp::model::GpModel;
use image::{RgbImage, Rgba, RgbaImage};
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// Share of the fitted face's colour in [`draw_fit`]'s blend (the photo's is the rest).
pub const DRAWN_FIT_SHARE: f32 = 0.7;

/// One face to fit: its landmarks in the photo and what names it.
#[derive(Debug, Clone)]
pub struct FaceToFit {
    /// Its folder under the output directory (e.g. `face-00`).
    pub folder: String,
    /// Landmarks in the photo (continuous pixels).
    pub landmarks: Vec<[f32; 2]>,
}

/// What fitting one face gave: its folder and report, or why it failed.
#[derive(Debug)]
pub struct FaceFitted {
    /// The face's folder (under the output directory).
    pub dir: PathBuf,
    /// The fit's report (as in its `fit.json`), or the error.
    pub result: Result<FitReport, String>,
}

/// The fit of one face and what its picture needs.
struct Done {
    prepared: Prepared,
    outcome: Outcome,
}

/// Fits every face of `photo` (read from `image_path`) in parallel, one fit per thread, writing
/// each face's `fit.json`, `overlay.png` and `fit.ply` into `out_dir/FOLDER`; returns each face's
/// result in the given order and the photo with every fit drawn in ([`draw_fit`]).
/// `progress(done, total)` is called as faces finish.
#[allow(clippy::too_many_arguments)]
pub fn fit_faces(
    model: &GpModel,
    model_path: &Path,
    image_path: &Path,
    photo: &RgbImage,
    faces: &[FaceToFit],
    settings: &FitOptions,
    out_dir: &Path,
    timing: bool,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<(Vec<FaceFitted>, RgbImage), FitRunError> {
    settings.validate()?;
    check_landmarks(model)?;
    let finished = AtomicUsize::new(0);
    let results: Vec<(FaceFitted, Option<Done>)> = faces
        .par_iter()
        .map(|face| {
            let dir = out_dir.join(&face.folder);
            let run = || -> Result<(FitReport, Done), String> {
                let t0 = std::time::Instant::now();
                let prepared = prepare(photo, &face.landmarks, settings.size).map_err(|e| e.to_string())?;
                let outcome = fit_prepared(model, &prepared, settings, &mut |_, _, _| {}).map_err(|e| e.to_string())?;
                let pts_path = dir.join("detected.pts");
                let inputs = ReportInputs {
                    model_path: &model_path.display().to_string(),
                    image_path: &image_path.display().to_string(),
                    pts_path: &pts_path.display().to_string(),
                    pts_one_based: false,
                    landmark_calibration: None,
                };
                let seconds = t0.elapsed().as_secs_f64();
                let rep = report(model, &inputs, &prepared, settings, &outcome, timing.then_some(seconds));
                write_fit_files(model, &prepared, &outcome, &rep, &dir).map_err(|e| e.to_string())?;
                Ok((rep, Done { prepared, outcome }))
            };
            let out = match run() {
                Ok((rep, done)) => (FaceFitted { dir, result: Ok(rep) }, Some(done)),
                Err(e) => (FaceFitted { dir, result: Err(e) }, None),
            };
            progress(finished.fetch_add(1, Ordering::Relaxed) + 1, faces.len());
            out
        })
        .collect();
    let mut picture = image::DynamicImage::ImageRgb8(photo.clone()).to_rgba8();
    for (i, (_, done)) in results.iter().enumerate() {
        if let Some(d) = done {
            draw_fit(&mut picture, &d.prepared, &d.outcome.render, &i.to_string());
        }
    }
    let picture = image::DynamicImage::ImageRgba8(picture).to_rgb8();
    Ok((results.into_iter().map(|(f, _)| f).collect(), picture))
}

/// Draws a fit into the photo it was fitted to: the rendered face blended over the photo where
/// it covers the crop ([`DRAWN_FIT_SHARE`]), the crop's square outlined, and `label` above it.
pub fn draw_fit(photo: &mut RgbaImage, prepared: &Prepared, render: &RgbaImage, label: &str) {
    let crop = &prepared.crop;
    let size = render.width();
    let (w, h) = (i64::from(photo.width()), i64::from(photo.height()));
    let (x0, y0) = (crop.x.max(0), crop.y.max(0));
    let (x1, y1) = ((crop.x + i64::from(crop.side)).min(w), (crop.y + i64::from(crop.side)).min(h));
    for y in y0..y1 {
        for x in x0..x1 {
            let p = crop.to_working([x as f32 + 0.5, y as f32 + 0.5], size);
            let (u, v) = (p[0].floor(), p[1].floor());
            if u < 0.0 || v < 0.0 || u >= size as f32 || v >= render.height() as f32 {
                continue;
            }
            let r = render.get_pixel(u as u32, v as u32).0;
            if r[3] == 0 {
                continue;
            }
            let px = photo.get_pixel_mut(x as u32, y as u32);
            for (c, fit) in px.0.iter_mut().zip(r).take(3) {
                *c = (DRAWN_FIT_SHARE * f32::from(fit) + (1.0 - DRAWN_FIT_SHARE) * f32::from(*c)).round() as u8;
            }
        }
    }
    let ink = Rgba([255, 220, 40, 255]);
    let thick = (crop.side / 200).max(1) as i64;
    for t in 0..thick {
        let (ax, ay, bx, by) = (crop.x + t, crop.y + t, crop.x + i64::from(crop.side) - 1 - t, crop.y + i64::from(crop.side) - 1 - t);
        for x in ax..=bx {
            put(photo, x, ay, ink);
            put(photo, x, by, ink);
        }
        for y in ay..=by {
            put(photo, ax, y, ink);
            put(photo, bx, y, ink);
        }
    }
    let scale = (crop.side / 120).clamp(1, 4);
    let ty = (crop.y - 9 * i64::from(scale)).max(0) as u32;
    crate::render::figure::draw_text(photo, crop.x.max(0) as u32, ty, label, scale, ink);
}
