//! The landmark-free start of a fit: the finder locates the face in the whole frame, the
//! initializer reads the 68 landmarks, the head pose and the low-order light from a crop around it
//! (both networks come from an init file, [`crate::format::init_file`]).

use super::agreement::{mean_gap, ReadingAgreement};
use super::face_box::{iou, is_face, landmark_box, FaceBox, SAME_FACE_IOU};
use super::resample::{flip_rows, sample_rgb, Window};
use super::{NetError, NetScratch};
use crate::format::detection::DetectionFigures;
use crate::format::init_file::{InitFile, FINDER_CHANNELS, MAX_INIT_LANDMARKS, MAX_INIT_LIGHT, MAX_NET_OUTPUT};
use crate::model::ibug::{IBUG68_MIRROR_PAIRS, IBUG68_POINTS};
use heapless::Vec;

/// What the initializer read from a face.
#[derive(Debug, Clone, PartialEq)]
pub struct Detection {
    /// The finder's box (before refinement).
    pub face: FaceBox,
    /// Landmarks in frame pixels, `(x, y)`.
    pub landmarks: Vec<[f32; 2], MAX_INIT_LANDMARKS>,
    /// Yaw, pitch, roll (radians, the fit's pose convention).
    pub angles: [f32; 3],
    /// Light coefficients as trained (`docs/init-format.md`).
    pub light: Vec<f32, MAX_INIT_LIGHT>,
}

impl Detection {
    /// A detection of `face` before the initializer has read it (no landmarks or light).
    fn unread(face: FaceBox) -> Self {
        Self { face, landmarks: Vec::new(), angles: [0.0; 3], light: Vec::new() }
    }
}

fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + libm::expf(-x))
}

/// A second look's window side, in the first look's face sizes.
pub const SECOND_LOOK_ZOOM: f32 = 3.0;
/// The second look is taken when its window is smaller than this share of the frame's longer
/// side (else it would see about what the first saw).
pub const SECOND_LOOK_BELOW: f32 = 0.9;

/// Runs the finder on an RGB frame (`w × h`); the best cell's box, whatever its score.
///
/// The finder first sees the whole frame letterboxed. A face small in that view (a few cells) has
/// its size read poorly (up to 1.7× too large at 12 px of 96; docs/evaluation.md, "Landmark-free start"), so
/// when the face is small the finder looks again at a square [`SECOND_LOOK_ZOOM`] face sizes wide
/// around it, where the face fills a third of its view. That look's box is the result when its
/// centre lies within the first box (half its size from the first centre); a second look that
/// settles on something else keeps the first box.
pub fn find_face<const A: usize>(
    init: &InitFile<'_>,
    rgb: &[u8],
    w: usize,
    h: usize,
    scratch: &mut NetScratch<A>,
) -> Result<FaceBox, NetError> {
    let side = init.finder.input().w;
    let first = look(init, rgb, w, h, Window::letterbox(w, h, side), scratch)?;
    looked_again(init, rgb, w, h, first, scratch)
}

/// `first` after its second look ([`second_look`]): that look's box if it settled on the same
/// face ([`same_face`]), else `first`; `first` itself when no second look is taken.
fn looked_again<const A: usize>(
    init: &InitFile<'_>,
    rgb: &[u8],
    w: usize,
    h: usize,
    first: FaceBox,
    scratch: &mut NetScratch<A>,
) -> Result<FaceBox, NetError> {
    let Some(window) = second_look(&first, w, h, init.finder.input().w) else { return Ok(first) };
    let second = look(init, rgb, w, h, window, scratch)?;
    Ok(FaceBox { looks: 2, ..if same_face(&first, &second) { second } else { first } })
}

/// Where the finder looks a second time after finding `first` in a `w × h` frame (a `side`-pixel
/// input): a square [`SECOND_LOOK_ZOOM`] face sizes wide around it, if that is less than
/// [`SECOND_LOOK_BELOW`] of the frame's longer side (and the box is a number).
pub fn second_look(first: &FaceBox, w: usize, h: usize, side: usize) -> Option<Window> {
    let window = SECOND_LOOK_ZOOM * first.size;
    let frame = w.max(h) as f32;
    let usable = window.is_finite() && first.cx.is_finite() && first.cy.is_finite() && window >= 1.0;
    (usable && window < SECOND_LOOK_BELOW * frame).then(|| Window::square(first.cx, first.cy, window, side))
}

/// Whether a second look's box is the first look's face: its centre within half the first box's
/// size of the first centre.
pub fn same_face(first: &FaceBox, second: &FaceBox) -> bool {
    libm::hypotf(second.cx - first.cx, second.cy - first.cy) < 0.5 * first.size
}

/// One run of the finder on `window` of the frame: the best cell's box in frame pixels.
fn look<const A: usize>(
    init: &InitFile<'_>,
    rgb: &[u8],
    w: usize,
    h: usize,
    window: Window,
    scratch: &mut NetScratch<A>,
) -> Result<FaceBox, NetError> {
    let mut out = [0f32; MAX_NET_OUTPUT];
    let cells = run_finder(init, (rgb, w, h), window, scratch, &mut out)?;
    cells.best(|_| true).ok_or(NetError::LengthMismatch)
}

/// Runs the finder on `window` of the frame into `out`; its cells.
pub(crate) fn run_finder<'o, const A: usize>(
    init: &InitFile<'_>,
    (rgb, w, h): (&[u8], usize, usize),
    window: Window,
    scratch: &mut NetScratch<A>,
    out: &'o mut [f32; MAX_NET_OUTPUT],
) -> Result<FinderCells<'o>, NetError> {
    let net = &init.finder;
    let side = net.input().w;
    sample_rgb(rgb, w, h, window, side, scratch.input_mut(net.input().len())?)?;
    let grid = net.output();
    let values = out.get_mut(..grid.len()).ok_or(NetError::LengthMismatch)?;
    net.run(scratch, values)?;
    Ok(FinderCells { values, grid_w: grid.w, side, window })
}

/// One finder run's output: [`FINDER_CHANNELS`] values per cell of a `grid_w`-wide square grid over
/// a `side`-pixel input sampled from `window` of the frame.
#[derive(Debug, Clone, Copy)]
pub struct FinderCells<'a> {
    /// The values, cell by cell in rows.
    pub values: &'a [f32],
    /// Cells per row.
    pub grid_w: usize,
    /// The finder's input side (px).
    pub side: usize,
    /// Where the input was sampled from.
    pub window: Window,
}

impl FinderCells<'_> {
    /// Cell `i`'s box in frame pixels (`None` past the grid).
    pub fn cell(&self, i: usize) -> Option<FaceBox> {
        let (dx, dy, log_size, logit) = match self.values.get(i * FINDER_CHANNELS..(i + 1) * FINDER_CHANNELS)? {
            [logit, dx, dy, s] => (dx.clamp(0.0, 1.0), dy.clamp(0.0, 1.0), s.clamp(-6.0, 2.0), *logit),
            _ => return None,
        };
        let grid_w = self.grid_w.max(1);
        let cell = self.side as f32 / grid_w as f32;
        let (u, v) = (((i % grid_w) as f32 + dx) * cell, ((i / grid_w) as f32 + dy) * cell);
        let (cx, cy) = self.window.to_source(u, v);
        let size = libm::expf(log_size) * self.side as f32 * self.window.step;
        Some(FaceBox { cx, cy, size, score: sigmoid(logit), looks: 1 })
    }

    /// The box of the cell with the highest face logit among those `keep` accepts (the first such
    /// cell on a tie); `None` if it accepts none.
    pub fn best(&self, keep: impl Fn(&FaceBox) -> bool) -> Option<FaceBox> {
        let mut best: Option<(f32, FaceBox)> = None;
        for (i, v) in self.values.chunks_exact(FINDER_CHANNELS).enumerate() {
            let logit = v.first().copied().unwrap_or(f32::NEG_INFINITY);
            if best.is_none_or(|(b, _)| logit > b) {
                if let Some(face) = self.cell(i).filter(|f| keep(f)) {
                    best = Some((logit, face));
                }
            }
        }
        best.map(|(_, face)| face)
    }

    /// Non-maximum suppression: the best cell at `min_score` or above, then again and again the
    /// best whose box overlaps no box taken before by more than [`SAME_FACE_IOU`], up to
    /// [`MAX_FACES`], best first.
    pub fn faces(&self, min_score: f32) -> Faces {
        let mut faces = Faces::new();
        while !faces.is_full() {
            let Some(face) = self.best(|f| is_face(f, min_score) && !faces.iter().any(|k| iou(k, f) > SAME_FACE_IOU)) else {
                break;
            };
            let _ = faces.push(face);
        }
        faces
    }
}

/// Most faces the finder reports in one frame.
pub const MAX_FACES: usize = 8;

/// Faces found in a frame, at most [`MAX_FACES`].
pub type Faces = Vec<FaceBox, MAX_FACES>;

/// Runs the finder on an RGB frame (`w × h`) and keeps every face at `min_score` or above: the
/// first look's cells after non-maximum suppression ([`FinderCells::faces`]), each then given its
/// own second look as [`find_face`] gives the best one, and dropped if that moved it onto a face
/// kept before it. Best first (by the first look's score): the first is [`find_face`]'s box.
pub fn find_faces<const A: usize>(
    init: &InitFile<'_>,
    rgb: &[u8],
    w: usize,
    h: usize,
    min_score: f32,
    scratch: &mut NetScratch<A>,
) -> Result<Faces, NetError> {
    let side = init.finder.input().w;
    let mut out = [0f32; MAX_NET_OUTPUT];
    let firsts = run_finder(init, (rgb, w, h), Window::letterbox(w, h, side), scratch, &mut out)?.faces(min_score);
    let mut faces = Faces::new();
    for first in &firsts {
        let face = looked_again(init, rgb, w, h, *first, scratch)?;
        if !faces.iter().any(|k| iou(k, &face) > SAME_FACE_IOU) {
            let _ = faces.push(face);
        }
    }
    Ok(faces)
}

/// Runs the initializer on the crop around `(cx, cy, size)`; fills `det` (landmarks in frame px).
/// `mirrored` shows it the crop flipped left-right and mirrors its reading back
/// ([`mirror_outputs`], as the training mirrors its targets).
fn read_face<const A: usize>(
    init: &InitFile<'_>,
    (rgb, w, h): (&[u8], usize, usize),
    (cx, cy, size): (f32, f32, f32),
    mirrored: bool,
    scratch: &mut NetScratch<A>,
    det: &mut Detection,
) -> Result<(), NetError> {
    let net = &init.initializer;
    let side = net.input().w;
    let window = Window::square(cx, cy, size * init.crop_margin, side);
    let input = scratch.input_mut(net.input().len())?;
    sample_rgb(rgb, w, h, window, side, input)?;
    if mirrored {
        flip_rows(input, side);
    }
    let mut out = [0f32; MAX_NET_OUTPUT];
    let out = out.get_mut(..net.output().len()).ok_or(NetError::LengthMismatch)?;
    net.run(scratch, out)?;
    if mirrored {
        mirror_outputs(out, init.landmarks);
    }
    det.landmarks.clear();
    let half = side as f32 * 0.5;
    let (points, rest) = out.split_at(2 * init.landmarks);
    for p in points.chunks_exact(2) {
        if let [x, y] = p {
            let _ = det.landmarks.push(window.to_source((x + 1.0) * half, (y + 1.0) * half).into());
        }
    }
    let (angles, light) = rest.split_at(3);
    det.angles.iter_mut().zip(angles).for_each(|(a, &v)| *a = v);
    det.light.clear();
    light.iter().for_each(|&v| {
        let _ = det.light.push(v);
    });
    Ok(())
}

/// Band 1's x coefficient among the initializer's light values (`Y11`, RGB; coefficient-major):
/// the light values a left-right mirror negates.
pub const LIGHT_X_VALUES: core::ops::Range<usize> = 9..12;

/// Mirrors an initializer output (or a training target) of `landmarks` points in place, as a
/// left-right flip of its crop changes it: each iBUG-68 point trades places with its mirror
/// partner and its x (crop coordinates, −1..1) is negated, yaw and roll are negated, and so are
/// the [`LIGHT_X_VALUES`]. `false`, and nothing changed, unless there are 68 points and `values`
/// holds them and the three angles.
pub fn mirror_outputs(values: &mut [f32], landmarks: usize) -> bool {
    let points = 2 * landmarks;
    if landmarks != IBUG68_POINTS || values.len() < points + 3 {
        return false;
    }
    for &(a, b) in &IBUG68_MIRROR_PAIRS {
        values.swap(2 * a, 2 * b);
        values.swap(2 * a + 1, 2 * b + 1);
    }
    values.iter_mut().take(points).step_by(2).for_each(|x| *x = -*x);
    if let Some(rest) = values.get_mut(points..) {
        // Yaw and roll (values 0 and 2 after the points); pitch is its own mirror image.
        rest.iter_mut().step_by(2).take(2).for_each(|angle| *angle = -*angle);
        rest.iter_mut().skip(3 + LIGHT_X_VALUES.start).take(LIGHT_X_VALUES.len()).for_each(|v| *v = -*v);
    }
    true
}

/// The device's reading of a face after `face`'s looks, within `refine + 2` network runs: a
/// second look of the finder takes one pass's place, and the last pass left is spent on the
/// mirrored reading of the same crop instead of a re-centred one when the initializer reads the
/// 68 iBUG points (`landmarks`, [`InitFile::landmarks`]; same runs, points as good or better:
/// docs/evaluation.md, "Landmark-free start"). The firmware runs this (its instruction bound,
/// docs/init-format.md); the host's `gpmm detect` runs all `refine` passes and the mirrored
/// reading.
pub fn bounded_reading(face: &FaceBox, refine: usize, landmarks: usize) -> Reading {
    let passes = refine.saturating_sub(usize::from(face.looks.saturating_sub(1)));
    if passes > 0 && landmarks == IBUG68_POINTS {
        Reading { refine: passes - 1, mirror: true }
    } else {
        Reading::passes(passes)
    }
}

/// How the initializer reads a face: re-centred passes, and a mirrored second reading.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Reading {
    /// Passes after the first, each on a crop re-centred on the previous pass's landmarks.
    pub refine: usize,
    /// Read the last crop a second time, flipped left-right, and average the two readings
    /// (68 iBUG landmarks only; one more initializer run).
    pub mirror: bool,
}

impl Reading {
    /// The host commands' reading: [`DEFAULT_REFINE`] refinement passes and the mirrored second
    /// reading.
    pub const DEFAULT: Self = Self { refine: DEFAULT_REFINE, mirror: true };

    /// `refine` passes and no mirrored reading (the device's bounded runs).
    pub const fn passes(refine: usize) -> Self {
        Self { refine, mirror: false }
    }

    /// Initializer runs this reading takes for an initializer of `landmarks` points.
    pub fn runs(&self, landmarks: usize) -> usize {
        self.refine + 1 + usize::from(self.mirror && landmarks == IBUG68_POINTS)
    }
}

/// The initializer's part of [`detect`]: reads the face in `face`'s box, then `reading.refine`
/// more times, each time on a crop re-centred on the previous pass's landmarks; with
/// `reading.mirror` (and 68 landmarks) the last crop once more, mirrored, averaged in.
pub fn read_landmarks<const A: usize>(
    init: &InitFile<'_>,
    rgb: &[u8],
    w: usize,
    h: usize,
    face: FaceBox,
    reading: Reading,
    scratch: &mut NetScratch<A>,
) -> Result<Detection, NetError> {
    read_landmarks_measured(init, rgb, w, h, face, reading, scratch).map(|(det, _)| det)
}

/// [`read_landmarks`], with how well the reading agrees with its mirror image and the box
/// ([`ReadingAgreement`]; `None` without the mirrored reading). The same runs, the same bits.
pub fn read_landmarks_measured<const A: usize>(
    init: &InitFile<'_>,
    rgb: &[u8],
    w: usize,
    h: usize,
    face: FaceBox,
    reading: Reading,
    scratch: &mut NetScratch<A>,
) -> Result<(Detection, Option<ReadingAgreement>), NetError> {
    let mut det = Detection::unread(face);
    let mut crop = (face.cx, face.cy, face.size);
    for pass in 0..=reading.refine {
        read_face(init, (rgb, w, h), crop, false, scratch, &mut det)?;
        if pass < reading.refine {
            let (cx, cy, size) = landmark_box(&det.landmarks);
            // Only move to a plausible box: a broken read keeps the crop, and no chain of reads
            // walks the crop off the finder's box (a network that reads every face smaller than
            // it is would otherwise shrink it to a point over the passes).
            let near = libm::hypotf(cx - face.cx, cy - face.cy) < face.size;
            let scale = size > face.size / MAX_RECENTRE_SCALE && size < face.size * MAX_RECENTRE_SCALE;
            if cx.is_finite() && cy.is_finite() && size.is_finite() && size > 1.0 && near && scale {
                crop = (cx, cy, size);
            }
        }
    }
    let mut agreement = None;
    if reading.mirror && init.landmarks == IBUG68_POINTS {
        let mut seen = Detection::unread(face);
        read_face(init, (rgb, w, h), crop, true, scratch, &mut seen)?;
        let gap = mean_gap(&det.landmarks, &seen.landmarks);
        let mean = |a: &mut f32, b: f32| *a = 0.5 * (*a + b);
        for (p, q) in det.landmarks.iter_mut().zip(&seen.landmarks) {
            mean(&mut p[0], q[0]);
            mean(&mut p[1], q[1]);
        }
        det.angles.iter_mut().zip(seen.angles).for_each(|(a, b)| mean(a, b));
        det.light.iter_mut().zip(&seen.light).for_each(|(a, &b)| mean(a, b));
        agreement = gap.and_then(|gap| ReadingAgreement::measure(&face, gap, &det.landmarks));
    }
    Ok((det, agreement))
}

/// How far re-centring may take the crop's size from the finder's box, either way (a factor: the
/// finder's box was up to 2.6× the face on the shared photos, docs/evaluation.md, "Landmark-free start").
pub const MAX_RECENTRE_SCALE: f32 = 3.0;

/// Refinement passes the host's commands use unless told otherwise (three: a crop cut from a box
/// too large for the face, as photos of people give, needs more than one re-centring to close in;
/// no change where the box is good; development sets, docs/evaluation.md, "Landmark-free start").
pub const DEFAULT_REFINE: usize = 3;

/// Refinement passes the device commands ask the firmware for unless told otherwise: one, which
/// [`bounded_reading`] spends on the mirrored reading or a second look (the 100 M instruction
/// bound, docs/init-format.md).
pub const DEVICE_REFINE: usize = 1;

/// Finds the face and reads it: [`find_face`], then [`read_landmarks`] if [`is_face`] at
/// `min_score` (else `None`).
pub fn detect<const A: usize>(
    init: &InitFile<'_>,
    rgb: &[u8],
    w: usize,
    h: usize,
    min_score: f32,
    reading: Reading,
    scratch: &mut NetScratch<A>,
) -> Result<Option<Detection>, NetError> {
    let face = find_face(init, rgb, w, h, scratch)?;
    if !is_face(&face, min_score) {
        return Ok(None);
    }
    read_landmarks(init, rgb, w, h, face, reading, scratch).map(Some)
}

/// Finds every face at `min_score` or above and reads each ([`find_faces`], then
/// [`read_landmarks`] on each box); best first, as [`find_faces`] orders them.
pub fn detect_faces<const A: usize>(
    init: &InitFile<'_>,
    rgb: &[u8],
    w: usize,
    h: usize,
    min_score: f32,
    reading: Reading,
    scratch: &mut NetScratch<A>,
) -> Result<Vec<Detection, MAX_FACES>, NetError> {
    let mut out = Vec::new();
    for face in find_faces(init, rgb, w, h, min_score, scratch)? {
        let det = read_landmarks(init, rgb, w, h, face, reading, scratch)?;
        if out.push(det).is_err() {
            break;
        }
    }
    Ok(out)
}

/// A detection record's figures, landmarks and light for the finder's box and, when it was
/// taken as a face, the initializer's reading (the firmware and the host build records alike).
pub fn record_parts<'a>(face: &FaceBox, det: Option<&'a Detection>) -> (DetectionFigures, &'a [[f32; 2]], &'a [f32]) {
    let figures = DetectionFigures {
        found: det.is_some(),
        cx: face.cx,
        cy: face.cy,
        size: face.size,
        score: face.score,
        angles: det.map_or([0.0; 3], |d| d.angles),
    };
    match det {
        Some(d) => (figures, &d.landmarks, &d.light),
        None => (figures, &[], &[]),
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    fn face(cx: f32, cy: f32, size: f32) -> FaceBox {
        FaceBox { cx, cy, size, score: 0.9, looks: 1 }
    }

    #[test]
    fn a_second_look_takes_the_place_of_a_pass_and_the_last_pass_reads_in_a_mirror() {
        let once = face(1.0, 1.0, 10.0);
        let twice = FaceBox { looks: 2, ..once };
        let runs = |f: &FaceBox, l: usize| [0, 1, 2].map(|r| bounded_reading(f, r, l).runs(l));
        // Whatever the reading, the runs stay refine + 1 (one look) or refine (two looks, at least 1).
        assert_eq!(runs(&once, 68), [1, 2, 3]);
        assert_eq!(runs(&twice, 68), [1, 1, 2]);
        assert_eq!(runs(&once, 5), [1, 2, 3]);
        assert_eq!(bounded_reading(&once, 1, 68), Reading { refine: 0, mirror: true });
        assert_eq!(bounded_reading(&once, 1, 5), Reading::passes(1));
        assert_eq!(bounded_reading(&twice, 1, 68), Reading::passes(0));
    }

    #[test]
    fn a_small_face_gets_a_second_look_around_it_and_a_large_one_does_not() {
        // 40 px in a 640 × 480 frame: a 120 px square centred on it, sampled into 96 px.
        let w = second_look(&face(300.0, 200.0, 40.0), 640, 480, 96).unwrap();
        assert_eq!((w.x0, w.y0, w.step), (240.0, 140.0, 120.0 / 96.0));
        // 200 px: the window (600 px) would be most of the frame.
        assert!(second_look(&face(300.0, 200.0, 200.0), 640, 480, 96).is_none());
        // Boxes that are not numbers, or smaller than a pixel's third, get none.
        for f in [face(f32::NAN, 1.0, 10.0), face(1.0, f32::INFINITY, 10.0), face(1.0, 1.0, f32::NAN), face(1.0, 1.0, 0.1)] {
            assert!(second_look(&f, 640, 480, 96).is_none(), "{f:?}");
        }
    }

    /// A 4 × 4 grid over a 64 px input seeing a 64 px frame 1:1: every cell's logit −5 and size
    /// log(0.25) (16 px), but for `cells` (index, logit, log size over the side).
    fn grid(cells: &[(usize, f32, f32)]) -> [f32; 64] {
        let mut values = [0f32; 64];
        for c in values.chunks_exact_mut(FINDER_CHANNELS) {
            c.copy_from_slice(&[-5.0, 0.5, 0.5, libm::logf(0.25)]);
        }
        for &(i, logit, log_size) in cells {
            values[i * FINDER_CHANNELS] = logit;
            values[i * FINDER_CHANNELS + 3] = log_size;
        }
        values
    }

    fn cells(values: &[f32]) -> FinderCells<'_> {
        FinderCells { values, grid_w: 4, side: 64, window: Window { x0: 0.0, y0: 0.0, step: 1.0 } }
    }

    #[test]
    fn two_faces_are_found_and_an_overlapping_duplicate_is_suppressed() {
        let big = libm::logf(0.5);
        // Cell 5 (centre 24, 24) and its neighbour 6 (40, 24) both see a 32 px face; cell 15
        // (56, 56) a second, 16 px face; cell 0 a weak one below the threshold.
        let values = grid(&[(5, 3.0, big), (6, 2.0, big), (15, 1.0, libm::logf(0.25)), (0, -3.0, libm::logf(0.25))]);
        let faces = cells(&values).faces(0.5);
        let boxes: std::vec::Vec<[i32; 3]> = faces.iter().map(|f| [f.cx, f.cy, f.size].map(|v| libm::roundf(v) as i32)).collect();
        assert_eq!(boxes, [[24, 24, 32], [56, 56, 16]]);
        assert!(iou(&faces[0], &cells(&values).cell(6).unwrap()) > SAME_FACE_IOU);
        // A lower threshold lets the weak cell in too; the best is always the single-face box.
        let all = cells(&values).faces(0.04);
        assert_eq!(all.len(), 3);
        assert_eq!(all[0], cells(&values).best(|_| true).unwrap());
        // Sixteen separate faces: MAX_FACES of them, best first.
        let many: std::vec::Vec<(usize, f32, f32)> = (0..16).map(|i| (i, i as f32, libm::logf(0.2))).collect();
        let values = grid(&many);
        let faces = cells(&values).faces(0.5);
        assert_eq!(faces.len(), MAX_FACES);
        assert!(faces.windows(2).all(|p| p[0].score >= p[1].score));
    }

    #[test]
    fn iou_of_square_boxes() {
        let a = face(10.0, 10.0, 10.0);
        assert_eq!(iou(&a, &a), 1.0);
        assert_eq!(iou(&a, &face(15.0, 10.0, 10.0)), 50.0 / 150.0);
        assert_eq!(iou(&a, &face(30.0, 10.0, 10.0)), 0.0);
        assert_eq!(iou(&a, &face(f32::NAN, 10.0, 10.0)), 0.0);
        assert_eq!(face(15.0, 10.0, 10.0).corners(), [10.0, 5.0, 20.0, 15.0]);
    }

    #[test]
    fn a_second_look_counts_only_when_it_stays_on_the_first_face() {
        let first = face(100.0, 100.0, 40.0);
        assert!(same_face(&first, &face(110.0, 95.0, 30.0)));
        assert!(!same_face(&first, &face(100.0, 125.0, 30.0)));
        assert!(!same_face(&first, &face(f32::NAN, 100.0, 30.0)));
    }
}
