//! `gpmm detect`: the face finder and initializer of an init file run on an image through the
//! core.

use anyhow::{bail, Context, Result};
use clap::Args;
use gpmm_core::net::face::Reading;
use gpmm_host::detect::Detector;
use image::{Rgb, RgbImage};
use std::path::{Path, PathBuf};

/// Arguments of `gpmm detect`.
#[derive(Debug, Args)]
pub struct DetectArgs {
    /// Image: PNG, JPEG or PPM.
    pub image: PathBuf,
    /// Init file from `gpmm train-init`.
    #[arg(long, value_name = "INIT")]
    pub init: PathBuf,
    /// Write the 68 landmarks as an iBUG .pts file (0-based, pixel centres at +0.5, as `gpmm fit` reads;
    /// points past the image's edge moved onto it).
    #[arg(short, long, value_name = "PTS")]
    pub output: Option<PathBuf>,
    /// Write the image with the box and landmarks drawn.
    #[arg(long, value_name = "PNG")]
    pub draw: Option<PathBuf>,
    /// Re-centre the crop on the read landmarks this many times.
    #[arg(long, default_value_t = gpmm_core::net::face::DEFAULT_REFINE)]
    pub refine: usize,
    /// Read the face once, without the mirrored second reading that is averaged in by default
    /// (one initializer run fewer; for comparisons and the device's budget).
    #[arg(long)]
    pub single_read: bool,
    /// Smallest finder score (0..1) counted as a face.
    #[arg(long, default_value_t = DEFAULT_MIN_SCORE)]
    pub min_score: f32,
}

/// Runs `gpmm detect`.
pub fn detect(a: DetectArgs) -> Result<()> {
    let mut detector = Detector::load(&a.init)?;
    let image = image::open(&a.image).with_context(|| format!("cannot read image {}", a.image.display()))?.to_rgb8();
    let Some(det) = detector.detect(&image, a.min_score, Reading { refine: a.refine, mirror: !a.single_read })? else {
        bail!("{}: no face found (finder score below --min-score {})", a.image.display(), a.min_score);
    };
    if let Some(path) = &a.output {
        write_pts(path, &det.landmarks, image.width(), image.height())?;
        eprintln!("wrote {}", path.display());
    }
    if let Some(path) = &a.draw {
        let drawn = draw_detection(&image, &det);
        drawn.save(path).with_context(|| format!("cannot write {}", path.display()))?;
        eprintln!("wrote {}", path.display());
    }
    let json = serde_json::json!({
        "image": a.image,
        "box": { "cx": det.face.cx, "cy": det.face.cy, "size": det.face.size, "score": det.face.score },
        "yaw_deg": det.angles[0].to_degrees(),
        "pitch_deg": det.angles[1].to_degrees(),
        "roll_deg": det.angles[2].to_degrees(),
        "landmarks": det.landmarks.iter().map(|p| [p[0], p[1]]).collect::<Vec<_>>(),
    });
    println!("{}", serde_json::to_string_pretty(&json)?);
    Ok(())
}

/// Detects the face in `image_path` with the init file `init_path` (default refinement and
/// score), writes OUTDIR/detected.pts and OUTDIR/detected.png, and returns the .pts path.
pub fn detect_to_dir(image_path: &Path, init_path: &Path, out_dir: &Path) -> Result<PathBuf> {
    let mut detector = Detector::load(init_path)?;
    let image = image::open(image_path).with_context(|| format!("cannot read image {}", image_path.display()))?.to_rgb8();
    let Some(det) = detector.detect(&image, DEFAULT_MIN_SCORE, Reading::DEFAULT)? else {
        bail!("{}: no face found by {}", image_path.display(), init_path.display());
    };
    std::fs::create_dir_all(out_dir).with_context(|| format!("cannot create {}", out_dir.display()))?;
    let pts = out_dir.join("detected.pts");
    write_pts(&pts, &det.landmarks, image.width(), image.height())?;
    let png = out_dir.join("detected.png");
    draw_detection(&image, &det).save(&png).with_context(|| format!("cannot write {}", png.display()))?;
    eprintln!(
        "face at ({:.0}, {:.0}) size {:.0} px (score {:.2}), yaw {:.0} pitch {:.0} roll {:.0} deg; wrote {}",
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

/// Smallest finder score `gpmm fit --init` accepts as a face.
pub const DEFAULT_MIN_SCORE: f32 = 0.05;

/// Writes the initializer's landmarks as an iBUG .pts file for a `width × height` image. Points
/// past the image's edge (a face cut by the frame) are moved onto it, since a fit refuses them in
/// a landmark file; the move is reported.
pub fn write_pts(path: &Path, points: &[[f32; 2]], width: u32, height: u32) -> Result<()> {
    let (inside, moved) = gpmm_host::photo::pts::clamp_to_image(points, width, height);
    std::fs::write(path, gpmm_host::photo::pts::pts_string(&inside)).with_context(|| format!("cannot write {}", path.display()))?;
    if moved > 0 {
        eprintln!("{}: {moved} landmarks lay outside the {width}x{height} image and were moved onto its edge", path.display());
    }
    Ok(())
}

/// The image with the finder's box (blue) and the landmarks (green) drawn.
pub fn draw_detection(image: &RgbImage, det: &gpmm_core::net::face::Detection) -> RgbImage {
    let mut out = image.clone();
    let (w, h) = (out.width() as i64, out.height() as i64);
    let mut put = |x: i64, y: i64, c: Rgb<u8>| {
        if x >= 0 && y >= 0 && x < w && y < h {
            out.put_pixel(x as u32, y as u32, c);
        }
    };
    let blue = Rgb([40, 120, 255]);
    let half = det.face.size * 0.5;
    let (x0, x1) = ((det.face.cx - half) as i64, (det.face.cx + half) as i64);
    let (y0, y1) = ((det.face.cy - half) as i64, (det.face.cy + half) as i64);
    for x in x0..=x1 {
        put(x, y0, blue);
        put(x, y1, blue);
    }
    for y in y0..=y1 {
        put(x0, y, blue);
        put(x1, y, blue);
    }
    let r = (w.max(h) / 200).max(1);
    for p in &det.landmarks {
        let (px, py) = (p[0] as i64, p[1] as i64);
        for d in -r..=r {
            put(px + d, py, Rgb([0, 255, 0]));
            put(px, py + d, Rgb([0, 255, 0]));
        }
    }
    out
}
