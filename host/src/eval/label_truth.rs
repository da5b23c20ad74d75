//! How well an occlusion-aware fit's labels agree with an occluder's true footprint
//! (`NAME.occluder.png` beside a set's image, as `tests/realistic/occlude.py` writes it), over the
//! face's pixels: the intersection over union of the pixels labelled occluded and those truly
//! covered.

use crate::photo::CropBox;
use image::{GrayImage, RgbaImage};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The agreement over the working pixels the fitted face covers.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct LabelAgreement {
    /// Intersection over union of labelled and truly occluded face pixels (1 if both are empty).
    pub iou: f32,
    /// Share of the face's pixels truly occluded.
    pub occluded_fraction: f32,
    /// Share of the face's pixels labelled occluded.
    pub labelled_fraction: f32,
}

/// The truth file of image `image` in `dir`, if there is one: `NAME.occluder.png`.
pub fn truth_file(dir: &Path, image: &str) -> Option<PathBuf> {
    let stem = Path::new(image).file_stem()?.to_string_lossy().into_owned();
    let path = dir.join(format!("{stem}.occluder.png"));
    path.is_file().then_some(path)
}

/// The agreement of `labels` (working image, white: occluded; `None`: nothing labelled) with
/// `truth` (the photo's occluder footprint, white: covered) over the pixels `render` (the fit,
/// transparent where it does not cover) covers; `crop` maps the `size`-pixel working image into
/// the photo.
pub fn label_agreement(labels: Option<&GrayImage>, render: &RgbaImage, crop: &CropBox, size: u32, truth: &GrayImage) -> LabelAgreement {
    let (mut face, mut both, mut either, mut truly, mut labelled) = (0u32, 0u32, 0u32, 0u32, 0u32);
    for (x, y, px) in render.enumerate_pixels() {
        if px.0[3] == 0 {
            continue;
        }
        face += 1;
        let [u, v] = crop.to_original([x as f32 + 0.5, y as f32 + 0.5], size);
        let t = u >= 0.0 && v >= 0.0 && truth.get_pixel_checked(u as u32, v as u32).is_some_and(|p| p.0[0] > 127);
        let l = labels.and_then(|m| m.get_pixel_checked(x, y)).is_some_and(|p| p.0[0] > 127);
        both += u32::from(t && l);
        either += u32::from(t || l);
        truly += u32::from(t);
        labelled += u32::from(l);
    }
    let share = |n: u32| if face == 0 { 0.0 } else { n as f32 / face as f32 };
    LabelAgreement {
        iou: if either == 0 { 1.0 } else { both as f32 / either as f32 },
        occluded_fraction: share(truly),
        labelled_fraction: share(labelled),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::{Luma, Rgba};

    #[test]
    fn agreement_is_counted_on_the_face_in_the_photos_pixels() {
        // A 4 × 4 working image of a 8 × 8 photo (2 photo pixels per working pixel); the face
        // covers the left 2 columns; the truth covers the photo's top half.
        let crop = CropBox { x: 0, y: 0, side: 8 };
        let render = RgbaImage::from_fn(4, 4, |x, _| if x < 2 { Rgba([9, 9, 9, 255]) } else { Rgba([0; 4]) });
        let truth = GrayImage::from_fn(8, 8, |_, y| Luma([if y < 4 { 255 } else { 0 }]));
        // Labels on the top row only (and one pixel off the face, which does not count).
        let labels = GrayImage::from_fn(4, 4, |x, y| Luma([if y == 0 || (x == 3 && y == 3) { 255 } else { 0 }]));
        let a = label_agreement(Some(&labels), &render, &crop, 4, &truth);
        // Face: 8 pixels; truly occluded 4 (rows 0-1), labelled 2 (row 0): IoU 2 / 4.
        assert_eq!((a.occluded_fraction, a.labelled_fraction), (0.5, 0.25));
        assert!((a.iou - 0.5).abs() < 1e-6, "{a:?}");
        // No labels: no agreement unless the truth is empty too.
        assert_eq!(label_agreement(None, &render, &crop, 4, &truth).iou, 0.0);
        let empty = GrayImage::new(8, 8);
        assert_eq!(label_agreement(None, &render, &crop, 4, &empty).iou, 1.0);
    }
}
