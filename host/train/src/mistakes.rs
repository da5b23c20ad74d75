//! The finder's own mistakes on real photos, as "no face" frames for fine-tuning it.
//!
//! Random views of face-free photos teach the finder most backgrounds, but a scan of a photo
//! ([`gpmm_core::net::scan`]) shows it many small windows, and a few of them (a clock's hands, a
//! track in grass, a fold of cloth) still score as faces. Scanning the training's own background
//! photos with the init file being fine-tuned finds exactly those: every box the scan keeps on a
//! face-free photo, or away from the known faces of a photo of people, is a mistake. Each is cut
//! as the finder sees it at a few zooms, and mirrored, and the fine-tuning shows these frames with
//! every cell "no face".

use crate::error::TrainError;
use crate::scene::backgrounds::{overlaps, Backgrounds};
use gpmm_core::net::face_box::FaceBox;
use gpmm_core::net::resample::{flip_rows, sample_rgb, Window};
use gpmm_host::detect::Detector;
use image::RgbImage;
use rayon::prelude::*;

/// The windows a mistake is cut in, in its box sizes: nearly filling the view as a scan's window
/// sees a small face, at the confirming look's three sizes, and small in a wide view.
pub const MISTAKE_ZOOMS: [f32; 3] = [1.6, 3.0, 5.0];

/// How a scan looks for mistakes: its minimum score and smallest face.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MistakeScan {
    /// Boxes scoring at least this are mistakes (below the scores a user keeps, so the finder
    /// also learns those that nearly pass).
    pub min_score: f32,
    /// The scan's smallest face (px of the photos as kept).
    pub smallest_face: f32,
    /// Mistake frames per scene in the finder's batches.
    pub per_scene: f64,
}

/// Mistake frames per scene of a batch by default (2 in a batch of 64). Chosen on photos no
/// training saw (docs/real-photos.md): with 8 or 16 the finder also lost many true faces.
pub const MISTAKES_PER_SCENE: f64 = 0.03125;

impl Default for MistakeScan {
    /// Scores from 0.5, faces down to the scan's default smallest face, [`MISTAKES_PER_SCENE`].
    fn default() -> Self {
        Self { min_score: 0.5, smallest_face: gpmm_host::detect::DEFAULT_SMALLEST_FACE, per_scene: MISTAKES_PER_SCENE }
    }
}

/// The mistakes found: their frames and counts.
#[derive(Debug, Clone, Default)]
pub struct Mistakes {
    /// Finder inputs (`side × side × 3`), every cell "no face".
    pub frames: Vec<Vec<i8>>,
    /// Boxes found on face-free parts of the photos.
    pub boxes: usize,
    /// Photos scanned.
    pub photos: usize,
}

/// Scans every photo of `backgrounds` with the finder of init file `init` and cuts each box that
/// touches no known face into `side`-pixel frames ([`mistake_frames`]); photos in parallel, the
/// result in photo order. A refused file ([`TrainError::InitFile`]) or a photo the networks refuse
/// ([`TrainError::Detect`]) is an error.
pub fn scan_mistakes(init: &[u8], backgrounds: &Backgrounds, side: usize, scan: MistakeScan) -> Result<Mistakes, TrainError> {
    // Refused files are refused once, here, not per photo.
    Detector::from_bytes(init).map_err(TrainError::InitFile)?;
    let photos: Vec<(&RgbImage, Vec<[f32; 4]>)> = backgrounds.photos_and_face_areas().collect();
    let found = photos
        .par_iter()
        .map_init(
            || Detector::from_bytes(init),
            |detector, (image, areas)| -> Result<Vec<FaceBox>, TrainError> {
                let detector = detector.as_mut().map_err(|e| TrainError::InitFile(*e))?;
                let boxes = detector.scan_boxes(image, scan.min_score, scan.smallest_face).map_err(TrainError::Detect)?;
                Ok(boxes.into_iter().filter(|b| !areas.iter().any(|&a| overlaps(a, b.corners()))).collect())
            },
        )
        .collect::<Result<Vec<_>, _>>()?;
    let mut out = Mistakes { photos: photos.len(), ..Mistakes::default() };
    for ((image, areas), boxes) in photos.iter().zip(&found) {
        for b in boxes {
            out.boxes += 1;
            out.frames.extend(mistake_frames(image, b, areas, side));
        }
    }
    Ok(out)
}

/// The finder's views of `mistake` in `image`: a square of each of [`MISTAKE_ZOOMS`] box sizes
/// around it that touches none of the known faces' `areas` (x0, y0, x1, y1; a wide view of a
/// mistake beside a face would show that face), and each mirrored (none for a box that is not a
/// number).
pub fn mistake_frames(image: &RgbImage, mistake: &FaceBox, areas: &[[f32; 4]], side: usize) -> Vec<Vec<i8>> {
    let (w, h) = (image.width() as usize, image.height() as usize);
    let mut frames = Vec::with_capacity(2 * MISTAKE_ZOOMS.len());
    for zoom in MISTAKE_ZOOMS {
        let size = zoom * mistake.size;
        if !(size.is_finite() && size >= 1.0 && mistake.cx.is_finite() && mistake.cy.is_finite()) {
            continue;
        }
        let view = FaceBox { size, ..*mistake }.corners();
        if areas.iter().any(|&a| overlaps(a, view)) {
            continue;
        }
        let mut frame = vec![0i8; side * side * 3];
        if sample_rgb(image.as_raw(), w, h, Window::square(mistake.cx, mistake.cy, size, side), side, &mut frame).is_err() {
            continue;
        }
        let mut mirrored = frame.clone();
        flip_rows(&mut mirrored, side);
        frames.push(frame);
        frames.push(mirrored);
    }
    frames
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use image::Rgb;

    #[test]
    fn a_mistake_is_cut_at_each_zoom_and_mirrored() {
        // Left half dark, right half bright: the mirror swaps them.
        let image = RgbImage::from_fn(400, 300, |x, _| if x < 200 { Rgb([0, 0, 0]) } else { Rgb([255, 255, 255]) });
        let b = FaceBox { cx: 200.0, cy: 150.0, size: 40.0, score: 0.9, looks: 2 };
        let frames = mistake_frames(&image, &b, &[], 32);
        assert_eq!(frames.len(), 2 * MISTAKE_ZOOMS.len());
        let left = |f: &[i8]| f[..3].iter().map(|&v| i32::from(v)).sum::<i32>();
        for pair in frames.chunks(2) {
            assert_eq!(pair[0].len(), 32 * 32 * 3);
            assert!(left(&pair[0]) < left(&pair[1]), "the first frame's left is the dark half, the mirror's the bright");
        }
        // A box that is not a number gives no frame.
        assert!(mistake_frames(&image, &FaceBox { size: f32::NAN, ..b }, &[], 32).is_empty());
        // A known face just beside the box: the wider views, which would show it, are not cut.
        let beside = [[235.0, 140.0, 300.0, 200.0]];
        assert_eq!(mistake_frames(&image, &b, &beside, 32).len(), 2, "only the closest view");
    }

    #[test]
    fn a_refused_init_file_is_an_error_not_an_empty_list() {
        let b = Backgrounds::from_photos(vec![RgbImage::new(64, 64)], 1.0);
        assert!(scan_mistakes(b"not an init file", &b, 32, MistakeScan::default()).is_err());
    }
}
