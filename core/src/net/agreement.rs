//! How well the initializer's reading of a face agrees with itself and with the finder's box.
//!
//! A face reads alike in the crop and in its mirror image, and its landmarks fill the finder's box
//! around their centre; a hand, a texture or a part of a face that the finder took for a face
//! mostly does not (docs/real-photos.md, "The reading's check"). These are the measures; the host
//! combines them with the finder's score into one check learned from photos with known faces.

use super::face_box::{landmark_box, FaceBox};

/// The measures of one reading, each over the finder's box size.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ReadingAgreement {
    /// Mean distance between the landmarks read in the crop and those read in its mirror image
    /// (mirrored back).
    pub mirror_gap: f32,
    /// The landmarks' bounding box (its larger side) over the box size.
    pub fill: f32,
    /// Distance from the box's centre to the landmarks' bounding box's centre.
    pub offset: f32,
}

impl ReadingAgreement {
    /// The measures of `face` whose reading `averaged` (frame pixels) is the mean of two that lay
    /// `gap` pixels apart on average ([`mean_gap`]). `None` when the box has no size or there are
    /// no landmarks.
    pub fn measure(face: &FaceBox, gap: f32, averaged: &[[f32; 2]]) -> Option<Self> {
        if averaged.is_empty() || !(face.size > 0.0 && face.size.is_finite()) {
            return None;
        }
        let (cx, cy, side) = landmark_box(averaged);
        let offset = libm::hypotf(cx - face.cx, cy - face.cy) / face.size;
        Some(Self { mirror_gap: gap / face.size, fill: side / face.size, offset })
    }

    /// Whether every measure is a finite number.
    pub fn is_finite(&self) -> bool {
        self.mirror_gap.is_finite() && self.fill.is_finite() && self.offset.is_finite()
    }
}

/// The mean distance between two readings' landmarks (frame pixels); `None` when they are empty
/// or of different lengths.
pub fn mean_gap(a: &[[f32; 2]], b: &[[f32; 2]]) -> Option<f32> {
    if a.is_empty() || a.len() != b.len() {
        return None;
    }
    Some(a.iter().zip(b).map(|(p, q)| libm::hypotf(p[0] - q[0], p[1] - q[1])).sum::<f32>() / a.len() as f32)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn a_reading_that_agrees_with_its_mirror_and_fills_the_box_measures_small() {
        let face = FaceBox { cx: 50.0, cy: 50.0, size: 40.0, score: 0.9, looks: 2 };
        let square = [[30.0, 30.0], [70.0, 30.0], [30.0, 70.0], [70.0, 70.0]];
        let a = ReadingAgreement::measure(&face, mean_gap(&square, &square).unwrap(), &square).unwrap();
        assert_eq!((a.mirror_gap, a.fill, a.offset), (0.0, 1.0, 0.0));
        // The mirrored reading 4 px off everywhere, the landmarks half the box and off its centre.
        let moved = square.map(|p| [p[0] + 4.0, p[1]]);
        let small = [[50.0, 50.0], [70.0, 50.0], [50.0, 70.0], [70.0, 70.0]];
        let a = ReadingAgreement::measure(&face, mean_gap(&square, &moved).unwrap(), &small).unwrap();
        assert_eq!((a.mirror_gap, a.fill), (0.1, 0.5));
        assert!((a.offset - libm::hypotf(10.0, 10.0) / 40.0).abs() < 1e-6);
        assert!(a.is_finite());
        // Nothing to measure: no size, no points, readings of different lengths.
        assert!(ReadingAgreement::measure(&FaceBox { size: 0.0, ..face }, 0.0, &square).is_none());
        assert!(ReadingAgreement::measure(&face, 0.0, &[]).is_none());
        assert!(mean_gap(&square, &square[..3]).is_none() && mean_gap(&[], &[]).is_none());
    }
}
