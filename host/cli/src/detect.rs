//! `gpmm detect`: the face finder and initializer of an init file run on an image through the
//! core.

use anyhow::{bail, Context, Result};
use clap::Args;
use gpmm_core::net::face::{Detection, Reading};
use gpmm_host::detect::record::FaceRecord;
use gpmm_host::detect::{shipped, CheckedFaces, Detector};
use image::{Rgb, RgbImage};
use std::path::{Path, PathBuf};

/// Arguments of `gpmm detect`.
#[derive(Debug, Args)]
pub struct DetectArgs {
    /// Image: PNG, JPEG or PPM.
    pub image: PathBuf,
    /// Init file from `gpmm train-init`. Default: the start gpmm ships, trained on real photos
    /// for the default model (it reads the 68 iBUG points of any face; docs/real-photos.md).
    #[arg(long, value_name = "INIT")]
    pub init: Option<PathBuf>,
    /// Write the 68 landmarks of one face (the largest, or --face) as an iBUG .pts file (0-based,
    /// pixel centres at +0.5, as `gpmm fit` reads; a point beyond the margin a fit accepts outside
    /// the image is moved onto its edge).
    #[arg(short, long, value_name = "PTS")]
    pub output: Option<PathBuf>,
    /// Which face --output writes: its place in the printed list (from 0; faces are listed by the
    /// finder's score, best first). Default: the largest of those scoring within 5 % of the best.
    #[arg(long, value_name = "N")]
    pub face: Option<usize>,
    /// Write the image with every face's box and landmarks drawn.
    #[arg(long, value_name = "PNG")]
    pub draw: Option<PathBuf>,
    /// Re-centre the crop on the read landmarks this many times.
    #[arg(long, default_value_t = gpmm_core::net::face::DEFAULT_REFINE)]
    pub refine: usize,
    /// Read the face once, without the mirrored second reading that is averaged in by default
    /// (one initializer run fewer; for comparisons and the device's budget).
    #[arg(long)]
    pub single_read: bool,
    /// Smallest finder score (0..1) counted as a face. Default: 0.9 with an init file trained on
    /// real photos (one with a face check, as the shipped start), else 0.05.
    #[arg(long, value_name = "S")]
    pub min_score: Option<f32>,
    /// Smallest face (px) looked for: beside the finder's view of the whole image, windows half
    /// its shorter side wide, a quarter, … are scanned while a face this small still fills too
    /// little of the last one (small images: none); a window's face is kept only if the finder,
    /// looking again at three face sizes around it, still scores it. `inf`: the whole image only,
    /// as a board does.
    #[arg(long, value_name = "PX", default_value_t = gpmm_host::detect::DEFAULT_SMALLEST_FACE)]
    pub smallest_face: f32,
    /// Keep photos' faces that fail the init file's face check (`gpmm check-init`), for
    /// comparisons; files without a check are not checked anyway.
    #[arg(long)]
    pub no_face_check: bool,
}

/// Runs `gpmm detect`.
pub fn detect(a: DetectArgs) -> Result<()> {
    let mut detector = shipped::open(a.init.as_deref())?;
    let init_name = shipped::init_name(a.init.as_deref());
    let min_score = a.min_score.unwrap_or(detector.advised_min_score());
    if a.no_face_check {
        detector.set_check(None);
    }
    let image = image::open(&a.image).with_context(|| format!("cannot read image {}", a.image.display()))?.to_rgb8();
    let reading = Reading { refine: a.refine, mirror: !a.single_read };
    let CheckedFaces { kept: faces, refused } = detector.scan_split(&image, min_score, a.smallest_face, reading)?;
    if faces.is_empty() {
        let Some(best) = refused.first() else {
            bail!("{}: no face found by {init_name} (finder score below --min-score {min_score})", a.image.display());
        };
        bail!(
            "{}: no face passed the face check of {}: {} box(es) scored at least --min-score {} (the best {:.2}, {:.0} px at ({:.0}, {:.0})) \
             but their readings did not look like a face's; --no-face-check lists them",
            a.image.display(),
            init_name,
            refused.len(),
            min_score,
            best.face.score,
            best.face.size,
            best.face.cx,
            best.face.cy
        );
    }
    if !refused.is_empty() {
        eprintln!("{} more box(es) failed the face check and are left out (--no-face-check lists them)", refused.len());
    }
    let chosen = pick(&a.image, &faces, a.face)?;
    if let Some(path) = &a.output {
        write_pts(path, &faces[chosen].landmarks, image.width(), image.height())?;
        eprintln!("wrote face {chosen}'s landmarks to {}", path.display());
    }
    if let Some(path) = &a.draw {
        let drawn = faces.iter().fold(image.clone(), |img, det| draw_detection(&img, det));
        drawn.save(path).with_context(|| format!("cannot write {}", path.display()))?;
        eprintln!("wrote {}", path.display());
    }
    let list: Vec<FaceRecord> = faces.iter().map(FaceRecord::from).collect();
    let json = serde_json::json!({ "image": a.image, "init": init_name, "min_score": min_score, "chosen": chosen, "faces": list });
    println!("{}", serde_json::to_string_pretty(&json)?);
    Ok(())
}

/// The face a command takes ([`gpmm_host::detect::choose_face`]), or an error naming the image
/// and how many faces it has.
fn pick(image: &Path, faces: &[Detection], index: Option<usize>) -> Result<usize> {
    gpmm_host::detect::choose_face(faces, index).with_context(|| {
        let last = faces.len().saturating_sub(1);
        format!("{}: --face {} asked for, but {} faces were found (0 to {last})", image.display(), index.unwrap_or(0), faces.len())
    })
}

/// Detects the faces in `image_path` with the init file `init` (the shipped start if `None`;
/// default refinement; `min_score` or the file's advised one), writes the chosen face's
/// ([`gpmm_host::detect::choose_face`]) landmarks to OUTDIR/detected.pts and every face to
/// OUTDIR/detected.png, and returns the .pts path. When no face reaches the advised score the
/// best weaker one is taken, with a warning: the photo was given as a face's.
pub fn detect_to_dir(
    image_path: &Path,
    init: Option<&Path>,
    out_dir: &Path,
    face: Option<usize>,
    min_score: Option<f32>,
) -> Result<PathBuf> {
    let (image, faces) = faces_for_fit(image_path, init, min_score, false)?;
    let chosen = pick(image_path, &faces, face)?;
    let det = &faces[chosen];
    std::fs::create_dir_all(out_dir).with_context(|| format!("cannot create {}", out_dir.display()))?;
    let pts = out_dir.join("detected.pts");
    write_pts(&pts, &det.landmarks, image.width(), image.height())?;
    let png = out_dir.join("detected.png");
    let drawn = faces.iter().fold(image.clone(), |img, d| draw_detection(&img, d));
    drawn.save(&png).with_context(|| format!("cannot write {}", png.display()))?;
    eprintln!(
        "face {chosen} of {} at ({:.0}, {:.0}) size {:.0} px (score {:.2}), yaw {:.0} pitch {:.0} roll {:.0} deg; wrote {}",
        faces.len(),
        det.face.cx,
        det.face.cy,
        det.face.size,
        det.face.score,
        det.angles[0].to_degrees(),
        det.angles[1].to_degrees(),
        det.angles[2].to_degrees(),
        pts.display()
    );
    Ok(pts)
}

/// The photo at `image_path` and the faces a fit takes from it: those the init file (the shipped
/// start if `None`) finds at `min_score` (default: the file's advised score) that pass its face
/// check. With `all` that is every such face; otherwise, when there are none, every face of the
/// check's or of the lowest default score instead, with a warning (the photo was given as a face's).
pub fn faces_for_fit(image_path: &Path, init: Option<&Path>, min_score: Option<f32>, all: bool) -> Result<(RgbImage, Vec<Detection>)> {
    let mut detector = shipped::open(init)?;
    let name = shipped::init_name(init);
    let image = image::open(image_path).with_context(|| format!("cannot read image {}", image_path.display()))?.to_rgb8();
    let found = gpmm_host::detect::for_fit::faces_for_fit(&mut detector, &image, min_score, all)?;
    if let (true, Some(best)) = (found.weaker, found.faces.first()) {
        eprintln!(
            "warning: {}: no face scores {} or more with {name}; fitting the best box, which scores {:.2} (check detected.png)",
            image_path.display(),
            found.min_score,
            best.face.score
        );
    }
    if found.faces.is_empty() {
        bail!("{}: no face found by {name} (finder score below {}; --min-score sets it)", image_path.display(), found.min_score);
    }
    Ok((image, found.faces))
}

pub use gpmm_host::detect::DEFAULT_MIN_SCORE;

/// Writes the initializer's landmarks as an iBUG .pts file for a `width × height` image. Points a
/// little past the image's edge (a face cut by the frame) are written as read; one beyond the
/// margin a fit accepts is moved onto the edge, and the move is reported.
pub fn write_pts(path: &Path, points: &[[f32; 2]], width: u32, height: u32) -> Result<()> {
    let (inside, moved) = gpmm_host::photo::pts::within_margin(points, width, height);
    std::fs::write(path, gpmm_host::photo::pts::pts_string(&inside)).with_context(|| format!("cannot write {}", path.display()))?;
    if moved > 0 {
        eprintln!(
            "{}: {moved} landmarks lay beyond the margin around the {width}x{height} image and were moved onto its edge",
            path.display()
        );
    }
    Ok(())
}

/// The image with the finder's box (blue) and the landmarks (green) drawn.
pub fn draw_detection(image: &RgbImage, det: &Detection) -> RgbImage {
    let mut out = image.clone();
    draw_box(&mut out, det.face.corners(), Rgb([40, 120, 255]), 1);
    let (w, h) = (out.width() as i64, out.height() as i64);
    let r = (w.max(h) / 200).max(1);
    for p in &det.landmarks {
        let (px, py) = (p[0] as i64, p[1] as i64);
        for d in -r..=r {
            put(&mut out, px + d, py, Rgb([0, 255, 0]));
            put(&mut out, px, py + d, Rgb([0, 255, 0]));
        }
    }
    out
}

/// Sets a pixel if it lies in the image.
fn put(out: &mut RgbImage, x: i64, y: i64, c: Rgb<u8>) {
    if x >= 0 && y >= 0 && x < i64::from(out.width()) && y < i64::from(out.height()) {
        out.put_pixel(x as u32, y as u32, c);
    }
}

/// Draws the outline of the box `[x0, y0, x1, y1]` (px), `thick` pixels wide, inward.
pub fn draw_box(out: &mut RgbImage, [x0, y0, x1, y1]: [f32; 4], color: Rgb<u8>, thick: i64) {
    let (x0, x1, y0, y1) = (x0 as i64, x1 as i64, y0 as i64, y1 as i64);
    for t in 0..thick {
        for x in x0..=x1 {
            put(out, x, y0 + t, color);
            put(out, x, y1 - t, color);
        }
        for y in y0..=y1 {
            put(out, x0 + t, y, color);
            put(out, x1 - t, y, color);
        }
    }
}

/// What `gpmm eval detect` does on a real-photo set.
#[derive(Debug)]
pub struct PhotoSetRun<'a> {
    /// The set.
    pub dir: &'a Path,
    /// The init file's name (in detect.json).
    pub init: &'a str,
    /// Smallest finder score counted as a face.
    pub min_score: f32,
    /// Smallest face (px) the scan looks for.
    pub smallest_face: f32,
    /// How the initializer reads each face.
    pub reading: Reading,
    /// Score each photo's mirror image too.
    pub mirror: bool,
    /// Where to draw each photo's boxes, if anywhere.
    pub draw_dir: Option<&'a Path>,
    /// Write DIR/detect.json.
    pub write: bool,
}

/// `gpmm eval detect` on a real-photo set: prints the summary, writes DIR/detect.json (unless
/// --no-write) and the pictures (--draw-dir).
pub fn eval_photo_set(detector: &Detector, a: &PhotoSetRun<'_>) -> Result<()> {
    let total = gpmm_host::detect::photos::list_photo_set(a.dir)?.len();
    let pb = crate::progress::counter(total, "photos");
    let progress = |done: usize, _: usize| pb.set_position(done as u64);
    let (summary, results) =
        gpmm_host::detect::photos::evaluate_photos(detector, a.dir, (a.min_score, a.smallest_face), a.reading, a.mirror, &progress)?;
    pb.finish_and_clear();
    if let Some(dir) = a.draw_dir {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        for r in &results {
            let mut image = image::open(&r.path).with_context(|| format!("cannot read image {}", r.path.display()))?.to_rgb8();
            if r.mirrored {
                image = image::imageops::flip_horizontal(&image);
            }
            let path = dir.join(Path::new(&r.scored.image).with_extension("png"));
            draw_photo_result(&image, r).save(&path).with_context(|| format!("cannot write {}", path.display()))?;
        }
        eprintln!("wrote {} pictures to {}", results.len(), dir.display());
    }
    if a.write {
        let path = a.dir.join("detect.json");
        let rows: Vec<_> = results.iter().map(|r| &r.scored).collect();
        let body = serde_json::json!({ "init": a.init, "summary": summary, "images": rows });
        std::fs::write(&path, serde_json::to_string_pretty(&body)? + "\n").with_context(|| format!("cannot write {}", path.display()))?;
        eprintln!("wrote {}", path.display());
    }
    println!("{}", serde_json::to_string_pretty(&summary)?);
    Ok(())
}

/// A real-photo set's image with its reference boxes (found green, missed red) and the false
/// positives' boxes (orange).
pub fn draw_photo_result(image: &RgbImage, r: &gpmm_host::detect::photos::PhotoResult) -> RgbImage {
    let mut out = image.clone();
    let thick = i64::from(out.width().max(out.height()) / 300).max(2);
    for (face, found) in r.faces.iter().zip(&r.scored.found) {
        let color = if *found { Rgb([0, 220, 0]) } else { Rgb([230, 0, 0]) };
        draw_box(&mut out, face.bbox, color, thick);
    }
    for d in r.scored.detections.iter().filter(|d| d.matched.is_none()) {
        let half = d.size * 0.5;
        draw_box(&mut out, [d.cx - half, d.cy - half, d.cx + half, d.cy + half], Rgb([255, 150, 0]), thick);
    }
    out
}
