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

use super::face::{find_faces, run_finder, same_face, second_look, FinderCells};
use super::face_box::{intersection, iou, is_face, FaceBox, SAME_FACE_IOU};
use super::resample::Window;
use super::{NetError, NetScratch};
use crate::format::init_file::{InitFile, MAX_NET_OUTPUT};

/// The face sizes the finder was trained on, as shares of its view's shorter side (the training
/// scenes draw theirs from this range).
pub const TRAINED_FACE_FRACTION: (f32, f32) = (0.15, 0.8);

/// Faces a scan holds before its suppression (the best by score when there are more).
pub const MAX_CANDIDATES: usize = 256;

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

/// The least score in a window's view that makes a face a candidate (or the minimum score, if
/// lower): its confirming look gives the score it keeps, which must reach the minimum. At a
/// minimum of 0.9, candidates from 0.6 instead of 0.9 found 16 more of the 170 faces of 32–64 px
/// of the unseen photos of people (docs/real-photos.md).
pub const WINDOW_CANDIDATE_SCORE: f32 = 0.5;

/// A face mostly inside a face kept before it is part of that face (an eye, a mouth read as a
/// small face): dropped when more than this share of its box lies inside the other's.
pub const WITHIN_SHARE: f32 = 0.6;

/// A face the scan reads smaller than this (px) is not listed: the least of the photo scans'
/// default smallest face (32 px) that the finder, which reads a small face's size within about
/// ±20 %, still reads for it. The boxes below it were mostly textures and parts of things: at a
/// minimum score of 0.9 they were 4 of the 13 false boxes on 46 face-free tuning photos, and 1 of
/// 486 faces of 32 px and more of the unseen photos of people (docs/real-photos.md, "The shipped
/// start"). A scan for smaller faces lists down to [`SMALLEST_FACE_SHARE`] of its `smallest_face`;
/// an infinite `smallest_face` (the whole frame only) lists the frame's faces at any size.
pub const SMALLEST_LISTED_FACE: f32 = 24.0;

/// With a `smallest_face` below [`SMALLEST_LISTED_FACE`]'s, the share of it a face must be read
/// at to be listed.
pub const SMALLEST_FACE_SHARE: f32 = 0.75;

/// The smallest face (px) a photo scan for faces down to `smallest_face` px lists
/// ([`SMALLEST_LISTED_FACE`]; 0, every size, for an infinite one): `scan_faces`'
/// `smallest_listed` for photos.
pub fn smallest_listed(smallest_face: f32) -> f32 {
    if smallest_face.is_finite() {
        SMALLEST_LISTED_FACE.min(SMALLEST_FACE_SHARE * smallest_face)
    } else {
        0.0
    }
}

/// Whether a photo scan for faces down to `smallest_face` px lists `face` ([`smallest_listed`]).
pub fn large_enough(face: &FaceBox, smallest_face: f32) -> bool {
    face.size >= smallest_listed(smallest_face)
}

/// Finds the faces at `min_score` or above in an RGB photo (`w × h`), at most `N`: the whole
/// frame's faces ([`find_faces`], with their second looks), then levels of windows (half the
/// shorter side, a quarter, …), each window's faces kept when their size is in
/// [`TRAINED_FACE_FRACTION`] of the window. Levels are added while the smallest face the last one
/// reads is larger than `smallest_face` pixels, and none is smaller than the finder's input; an
/// infinite `smallest_face` gives [`find_faces`]'s faces.
///
/// Window faces are candidates from [`WINDOW_CANDIDATE_SCORE`]. Then one non-maximum suppression,
/// best score first ([`suppress`], [`overlaps_kept`]), in which each window's face is **confirmed**
/// before it is kept: the finder looks again at a square
/// [`super::face::SECOND_LOOK_ZOOM`] face sizes wide around it, where the face fills a third of
/// its view as in the training scenes, and that look's score and box replace the window's
/// ([`confirmed`]). Textures, hands and parts of faces that score high in a small window mostly do
/// not in that view (docs/real-photos.md). A face read smaller than [`SMALLEST_LISTED_FACE`] (or
/// [`SMALLEST_FACE_SHARE`] of a smaller `smallest_face`) is dropped for photos: a face read smaller
/// than `smallest_listed` px is not listed ([`smallest_listed`] for photos, 0 for every size).
/// Listed best first by the score kept.
pub fn scan_faces<const A: usize, const N: usize>(
    init: &InitFile<'_>,
    rgb: &[u8],
    w: usize,
    h: usize,
    min_score: f32,
    (smallest_face, smallest_listed): (f32, f32),
    scratch: &mut NetScratch<A>,
) -> Result<Vec<FaceBox, N>, NetError> {
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
                for face in cells.faces(WINDOW_CANDIDATE_SCORE.min(min_score)).into_iter().filter(|f| f.size >= lo * s && f.size <= hi * s)
                {
                    keep(&mut candidates, face);
                }
            }
        }
        s *= 0.5;
    }
    let large_enough = |f: &FaceBox| f.size >= smallest_listed;
    let mut faces: Vec<FaceBox, N> = suppress(candidates, |face| -> Result<Option<FaceBox>, NetError> {
        // The whole frame's faces have had their second look; a window's face gets it here.
        match if face.looks == 1 { second_look(face, w, h, side) } else { None } {
            Some(window) => {
                let seen = confirmed(face, &run_finder(init, (rgb, w, h), window, scratch, &mut out)?);
                Ok(seen.filter(|f| is_face(f, min_score) && large_enough(f)))
            }
            None => Ok(Some(*face).filter(large_enough)),
        }
    })?;
    faces.sort_unstable_by(|a, b| b.score.total_cmp(&a.score));
    Ok(faces)
}

/// Non-maximum suppression of a scan's candidates, best score first, at most `N` kept
/// ([`overlaps_kept`]). A candidate is settled by `settle` when it first comes up: `None` drops
/// it (a window's face its confirming look does not hold), `Some` gives the box and score it
/// keeps, and it goes back among the rest with that score. So a face is ranked by the score it
/// keeps, not by its window's: a window face that confirms weakly no longer displaces a
/// neighbour that confirms strongly. Candidates lying on a kept face are dropped unsettled (no
/// confirming look is spent on them).
pub fn suppress<const N: usize, E>(
    candidates: Vec<FaceBox, MAX_CANDIDATES>,
    mut settle: impl FnMut(&FaceBox) -> Result<Option<FaceBox>, E>,
) -> Result<Vec<FaceBox, N>, E> {
    let mut open: Vec<(FaceBox, bool), MAX_CANDIDATES> = Vec::new();
    for face in candidates {
        let _ = open.push((face, false));
    }
    let mut faces: Vec<FaceBox, N> = Vec::new();
    while !faces.is_full() {
        let best = open.iter().enumerate().max_by(|a, b| a.1 .0.score.total_cmp(&b.1 .0.score)).map(|(i, _)| i);
        let Some((face, settled)) = best.map(|i| open.swap_remove(i)) else { break };
        if overlaps_kept(&faces, &face) {
            continue;
        }
        if settled {
            let _ = faces.push(face);
        } else if let Some(face) = settle(&face)? {
            // Room: the candidate it settles was just taken out.
            let _ = open.push((face, true));
        }
    }
    Ok(faces)
}

/// A window's face as its confirming look (`second`, the finder's view around it) reads it: the
/// best of that look's cells that is the same face ([`same_face`]), with its box and score;
/// `None` if no cell is.
pub fn confirmed(face: &FaceBox, second: &FinderCells<'_>) -> Option<FaceBox> {
    second.best(|f| same_face(face, f)).map(|f| FaceBox { looks: 2, ..f })
}

/// Whether `face` is one of `kept`: their boxes overlap by an intersection over union above
/// [`SAME_FACE_IOU`], or more than [`WITHIN_SHARE`] of its box lies inside a kept one.
pub fn overlaps_kept(kept: &[FaceBox], face: &FaceBox) -> bool {
    kept.iter().any(|k| iou(k, face) > SAME_FACE_IOU || share_within(face, k) > WITHIN_SHARE)
}

/// The share of `a`'s area that lies inside `b` (0 for boxes that are not numbers or have no area).
pub fn share_within(a: &FaceBox, b: &FaceBox) -> f32 {
    let area = a.size * a.size;
    if !(area > 0.0 && area.is_finite() && [a.cx, a.cy, b.cx, b.cy, b.size].iter().all(|v| v.is_finite())) {
        return 0.0;
    }
    intersection(a, b) / area
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    #[test]
    fn faces_well_below_the_smallest_face_are_not_listed() {
        let face = |size| FaceBox { cx: 50.0, cy: 50.0, size, score: 0.99, looks: 2 };
        assert!(large_enough(&face(32.0), 32.0) && large_enough(&face(24.0), 32.0));
        assert!(!large_enough(&face(23.0), 32.0));
        // A shallower scan (one that looks for large faces only) still lists faces from 24 px.
        assert!(large_enough(&face(30.0), 96.0) && !large_enough(&face(23.0), 96.0));
        // A deeper one lists smaller faces.
        assert!(large_enough(&face(13.0), 16.0) && !large_enough(&face(11.0), 16.0));
        assert!(large_enough(&face(3.0), f32::INFINITY), "the whole frame only: every size");
        assert!(!large_enough(&face(f32::NAN), 32.0), "a size that is not a number is no face");
    }

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

    fn face(cx: f32, cy: f32, size: f32, score: f32) -> FaceBox {
        FaceBox { cx, cy, size, score, looks: 1 }
    }

    #[test]
    fn a_part_of_a_kept_face_is_the_same_face_but_a_neighbour_is_not() {
        let kept = [face(100.0, 100.0, 80.0, 0.99)];
        // An eye read as a small face: wholly inside, tiny IoU.
        let eye = face(85.0, 90.0, 20.0, 0.95);
        assert!(iou(&kept[0], &eye) < SAME_FACE_IOU && share_within(&eye, &kept[0]) == 1.0);
        assert!(overlaps_kept(&kept, &eye));
        // A face beside it touching its edge: a quarter inside, kept.
        let beside = face(150.0, 100.0, 40.0, 0.9);
        assert_eq!(share_within(&beside, &kept[0]), 0.25);
        assert!(!overlaps_kept(&kept, &beside));
        // Boxes that are not numbers overlap nothing.
        assert!(!overlaps_kept(&kept, &face(f32::NAN, 100.0, 20.0, 0.9)));
        assert_eq!(share_within(&face(100.0, 100.0, 0.0, 0.9), &kept[0]), 0.0);
    }

    /// A confirming look: a 4 × 4 grid over a 64 px input seeing a 64 px frame 1:1, every cell's
    /// logit `rest`, but for `cells` (index, logit); each cell's face 16 px at its centre.
    fn look(cells: &[(usize, f32)], rest: f32) -> [f32; 64] {
        let mut values = [0f32; 64];
        for c in values.chunks_exact_mut(4) {
            c.copy_from_slice(&[rest, 0.5, 0.5, libm::logf(0.25)]);
        }
        for &(i, logit) in cells {
            values[i * 4] = logit;
        }
        values
    }

    #[test]
    fn the_confirming_look_gives_the_window_face_its_score_and_box() {
        fn cells(values: &[f32]) -> FinderCells<'_> {
            FinderCells { values, grid_w: 4, side: 64, window: Window { x0: 0.0, y0: 0.0, step: 1.0 } }
        }
        // A window's face at (24, 24), 16 px, score 0.99.
        let small = face(24.0, 24.0, 16.0, 0.99);
        // The closer look scores it low: the window's score is replaced, and a low one then fails
        // the minimum score.
        let values = look(&[(5, -2.0)], -6.0);
        let seen = confirmed(&small, &cells(&values)).unwrap();
        assert_eq!((seen.cx, seen.cy, seen.looks), (24.0, 24.0, 2));
        assert!(seen.score < 0.2 && !is_face(&seen, 0.5));
        // A stronger face elsewhere in the look does not stand in for it: the best cell that is
        // the same face (centre within half its size) is taken.
        let values = look(&[(5, 3.0), (15, 6.0)], -6.0);
        let seen = confirmed(&small, &cells(&values)).unwrap();
        assert_eq!((seen.cx, seen.cy), (24.0, 24.0));
        assert!(seen.score > 0.9 && seen.score < 0.99);
        // A look with no cell near it confirms nothing.
        let far = face(200.0, 200.0, 16.0, 0.99);
        assert!(confirmed(&far, &cells(&values)).is_none());
    }

    #[test]
    fn a_face_is_ranked_by_the_score_its_confirming_look_gives_it() {
        // Two window faces on one person: the first scores higher in its window, but its closer
        // look holds it only weakly; the second's look holds it strongly. A third lies beside them.
        let mut candidates: Vec<FaceBox, MAX_CANDIDATES> = Vec::new();
        for f in [face(100.0, 100.0, 40.0, 0.99), face(104.0, 100.0, 40.0, 0.95), face(300.0, 100.0, 40.0, 0.9)] {
            candidates.push(f).unwrap();
        }
        let mut looks = 0;
        let settle = |f: &FaceBox| -> Result<Option<FaceBox>, ()> {
            looks += 1;
            let score = if f.score == 0.99 { 0.5 } else { 0.97 };
            Ok(Some(FaceBox { score, looks: 2, ..*f }))
        };
        let kept: Vec<FaceBox, 8> = suppress(candidates.clone(), settle).unwrap();
        assert_eq!(kept.len(), 2);
        assert_eq!((kept[0].cx, kept[0].score), (104.0, 0.97), "the strongly confirmed box wins");
        assert_eq!(kept[1].cx, 300.0);
        assert_eq!(looks, 3);
        // A look that drops a face frees its place for the neighbour it covered; the cap holds.
        let kept: Vec<FaceBox, 1> = suppress(candidates, |f| Ok::<_, ()>((f.score != 0.99).then_some(*f))).unwrap();
        assert_eq!((kept.len(), kept[0].cx), (1, 104.0));
    }
}
