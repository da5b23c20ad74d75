//! A photo scanned in windows at several scales, for faces too small for the finder's view of the
//! whole frame.
//!
//! The finder learned faces that fill [`TRAINED_FACE_FRACTION`] of its view's shorter side. In a
//! whole photo letterboxed into its 96-pixel input, a face of 100 of 1,280 pixels is 7 input pixels,
//! below what it ever saw: it reports such faces at two to three times their size, or not at all.
//! The scan adds the finder's view of overlapping square windows, half the shorter side wide, then
//! a quarter, and so on (each overlapping its neighbours by half), and keeps from each window only
//! the faces whose size lies in the trained range for that window. All the views' faces then go
//! through one non-maximum suppression, best score first. A camera frame of a board (160 × 120,
//! the face large in it) needs no scan: [`crate::net::face::find_faces`] is that path.

use heapless::Vec;

use super::face::{find_faces, iou, run_finder, FaceBox, Faces, InitFile, MAX_NET_OUTPUT, SAME_FACE_IOU};
use super::resample::Window;
use super::{NetError, NetScratch};

/// The face sizes the finder was trained on, as shares of its view's shorter side (the training
/// scenes draw theirs from this range).
pub const TRAINED_FACE_FRACTION: (f32, f32) = (0.15, 0.8);

/// Faces a scan holds before its suppression (the best by score when there are more).
pub const MAX_CANDIDATES: usize = 64;

/// Smallest window a scan looks at, in finder input pixels: a smaller one would be upsampled and
/// show the finder nothing the larger window did not.
const SMALLEST_WINDOW_INPUTS: f32 = 1.0;

/// The centres of windows of side `s` along a frame side of `n` pixels, overlapping by half (the
/// last one flush with the far edge); `count` of them.
fn centres(n: f32, s: f32) -> impl Iterator<Item = f32> {
    let stride = 0.5 * s;
    let count = if n <= s { 1 } else { libm::ceilf((n - s) / stride) as usize + 1 };
    (0..count).map(move |i| (0.5 * s + i as f32 * stride).min(n - 0.5 * s).max(0.5 * s.min(n)))
}

/// Adds `face` to `faces`, displacing the lowest-scoring one when full (if `face` scores higher).
fn keep(faces: &mut Vec<FaceBox, MAX_CANDIDATES>, face: FaceBox) {
    if faces.push(face).is_ok() {
        return;
    }
    let lowest = faces.iter().enumerate().min_by(|a, b| a.1.score.total_cmp(&b.1.score)).map(|(i, f)| (i, f.score));
    if let Some((i, score)) = lowest {
        if face.score > score {
            if let Some(slot) = faces.get_mut(i) {
                *slot = face;
            }
        }
    }
}

/// Finds the faces at `min_score` or above in an RGB photo (`w × h`): the whole frame's faces
/// ([`find_faces`], with their second looks), then levels of windows (half the shorter side, a
/// quarter, …), each window's faces kept when their size is in [`TRAINED_FACE_FRACTION`] of the
/// window; then one non-maximum suppression (intersection over union above [`SAME_FACE_IOU`] is
/// one face), best first, at most [`super::face::MAX_FACES`]. Levels are added while the smallest face the
/// last one reads is larger than `smallest_face` pixels, and none is smaller than the finder's
/// input; an infinite `smallest_face` gives [`find_faces`]'s faces.
pub fn scan_faces<const A: usize>(
    init: &InitFile<'_>,
    rgb: &[u8],
    w: usize,
    h: usize,
    min_score: f32,
    smallest_face: f32,
    scratch: &mut NetScratch<A>,
) -> Result<Faces, NetError> {
    let mut candidates: Vec<FaceBox, MAX_CANDIDATES> = Vec::new();
    for face in find_faces(init, rgb, w, h, min_score, scratch)? {
        keep(&mut candidates, face);
    }
    let side = init.finder.input().w;
    let (fw, fh) = (w as f32, h as f32);
    let (lo, hi) = TRAINED_FACE_FRACTION;
    let mut s = 0.5 * fw.min(fh);
    let mut out = [0f32; MAX_NET_OUTPUT];
    // Each level reads faces down to `lo · s`; the next one is needed while the one before it
    // (twice as wide) could not read a face of `smallest_face`.
    while lo * 2.0 * s > smallest_face && s >= SMALLEST_WINDOW_INPUTS * side as f32 {
        for cy in centres(fh, s) {
            for cx in centres(fw, s) {
                let cells = run_finder(init, (rgb, w, h), Window::square(cx, cy, s, side), scratch, &mut out)?;
                for face in cells.faces(min_score).into_iter().filter(|f| f.size >= lo * s && f.size <= hi * s) {
                    keep(&mut candidates, face);
                }
            }
        }
        s *= 0.5;
    }
    candidates.sort_unstable_by(|a, b| b.score.total_cmp(&a.score));
    let mut faces = Faces::new();
    for face in candidates {
        if faces.is_full() {
            break;
        }
        if !faces.iter().any(|k| iou(k, &face) > SAME_FACE_IOU) {
            let _ = faces.push(face);
        }
    }
    Ok(faces)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn windows_cover_the_side_and_overlap_by_half() {
        let c: heapless::Vec<f32, 16> = centres(1000.0, 400.0).collect();
        assert_eq!(c.as_slice(), &[200.0, 400.0, 600.0, 800.0]);
        // A side that is not a multiple: the last window sits flush with the far edge.
        let c: heapless::Vec<f32, 16> = centres(900.0, 400.0).collect();
        assert_eq!(c.as_slice(), &[200.0, 400.0, 600.0, 700.0]);
        // A window as large as the side: one, centred.
        let c: heapless::Vec<f32, 16> = centres(300.0, 300.0).collect();
        assert_eq!(c.as_slice(), &[150.0]);
    }

    #[test]
    fn a_full_candidate_list_keeps_the_best() {
        let face = |score: f32| FaceBox { cx: 0.0, cy: 0.0, size: 1.0, score, looks: 1 };
        let mut v: Vec<FaceBox, MAX_CANDIDATES> = Vec::new();
        for i in 0..MAX_CANDIDATES {
            keep(&mut v, face(0.5 + i as f32 * 1e-3));
        }
        keep(&mut v, face(0.1));
        assert!(v.iter().all(|f| f.score >= 0.5), "a worse face does not displace one");
        keep(&mut v, face(0.99));
        assert!(v.iter().any(|f| f.score == 0.99) && !v.iter().any(|f| f.score == 0.5));
    }
}
