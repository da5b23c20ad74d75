//! Where the photo ends: landmarks a little outside the image, and the working pixels the photo
//! covers when the fit's crop leaves it.
//!
//! Detectors return points outside the frame whenever a face touches its edge (a 150 × 150 chip
//! whose chin point sits a pixel below the last row, a close-up with the chin cut off). Such
//! points are data: a landmark may lie up to [`LANDMARK_MARGIN`] landmark-box sizes outside the
//! image ([`first_beyond_margin`]); farther out it is refused as a file that does not belong to
//! the image. The fit's square crop then leaves the photo; its working pixels whose centres fall
//! outside the photo carry no observation and are left out of the image likelihood and of the
//! background histogram ([`CoveredPixels`], carried by [`crate::fit::TargetImage`]).

/// How far outside the image a landmark may lie, in landmark-box sizes (the larger side of the
/// landmarks' bounding box, the crop's unit): 0.2, half an inter-ocular distance on an iBUG-68
/// face (the eyes' centres are about 0.4 box apart). It admits a chin or jaw cut by the frame by
/// up to a fifth of the face, while a point of another image or another scale lies far beyond it.
pub const LANDMARK_MARGIN: f32 = 0.2;

/// The margin in pixels for `points`: [`LANDMARK_MARGIN`] times the larger side of their bounding
/// box (0 if the box is not finite).
pub fn landmark_margin(points: &[[f32; 2]]) -> f32 {
    let (mut lo, mut hi) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
    for p in points {
        for ((l, h), v) in lo.iter_mut().zip(hi.iter_mut()).zip(p) {
            *l = l.min(*v);
            *h = h.max(*v);
        }
    }
    let e = (hi[0] - lo[0]).max(hi[1] - lo[1]);
    if e.is_finite() && e > 0.0 {
        LANDMARK_MARGIN * e
    } else {
        0.0
    }
}

/// The index of the first of `points` farther than [`landmark_margin`] outside the
/// `width × height` image (continuous pixel coordinates, the border included; a non-finite point
/// is always beyond), or `None` when every point is within the margin.
pub fn first_beyond_margin(points: &[[f32; 2]], width: f32, height: f32) -> Option<usize> {
    let m = landmark_margin(points);
    points.iter().position(|p| !(p[0] >= -m && p[1] >= -m && p[0] <= width + m && p[1] <= height + m))
}

/// The working pixels the photo covers (defined with the geometry, which the formats may use).
pub use crate::geometry::CoveredPixels;

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    #[test]
    fn points_within_the_margin_pass_and_far_ones_do_not() {
        // A 100 px box: the margin is 20 px.
        let mut pts = [[25.0f32, 20.0], [125.0, 60.0], [75.0, 120.0]];
        assert!((landmark_margin(&pts) - 20.0).abs() < 1e-5);
        assert_eq!(first_beyond_margin(&pts, 150.0, 150.0), None);
        // The chin a pixel below a 100-row image, a jaw point at x = -1.
        assert_eq!(first_beyond_margin(&pts, 150.0, 100.0), None);
        pts[0][0] = -1.0;
        assert_eq!(first_beyond_margin(&pts, 150.0, 101.0), None);
        // Beyond the margin: 30 px below a 90-row image (the box grows to 126, the margin to 25.2).
        assert_eq!(first_beyond_margin(&pts, 150.0, 90.0), Some(2));
        pts[1] = [99999.0, 99999.0];
        assert_eq!(first_beyond_margin(&pts, 150.0, 150.0), Some(1));
        pts[1] = [f32::NAN, 3.0];
        assert_eq!(first_beyond_margin(&pts, 150.0, 150.0), Some(1));
    }

    #[test]
    fn covered_pixels_are_those_whose_centres_lie_in_the_photo() {
        // Inside: everything.
        assert_eq!(CoveredPixels::of_crop(10.0, 10.0, 2.0, 64, 200, 200), CoveredPixels::whole(64, 64));
        // 10 photo px left of the photo at 2 px a pixel: pixels 0..5 have centres at -9, -7, ..., -1.
        let c = CoveredPixels::of_crop(-10.0, 0.0, 2.0, 64, 200, 100);
        assert_eq!((c.x0, c.x1), (5, 64));
        // Bottom: the photo ends at 100; pixel v's centre is 2v + 1 < 100 for v < 50.
        assert_eq!((c.y0, c.y1), (0, 50));
        assert!(c.contains(5, 49) && !c.contains(4, 0) && !c.contains(5, 50));
        assert_eq!(c.count(), 59 * 50);
        assert!(c.fits(64, 64) && !c.fits(32, 64));
        // A centre exactly on the edge belongs to the pixel on its right (half-open).
        let c = CoveredPixels::of_crop(-0.5, 0.0, 1.0, 8, 8, 8);
        assert_eq!((c.x0, c.x1), (0, 8));
        // Nothing covered, and no panic on a bad step.
        assert_eq!(CoveredPixels::of_crop(500.0, 0.0, 1.0, 8, 8, 8).count(), 0);
        assert_eq!(CoveredPixels::of_crop(0.0, 0.0, f32::NAN, 8, 8, 8).count(), 0);
    }
}
