//! A face's box in a frame and the geometry of boxes: overlap, the box around landmarks, and
//! whether a finder's box counts as a face.

/// A face found in a frame: a square box in frame pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FaceBox {
    /// Centre, x (px).
    pub cx: f32,
    /// Centre, y (px).
    pub cy: f32,
    /// Side: the larger side of the landmarks' bounding box (px).
    pub size: f32,
    /// The finder's confidence, 0..1.
    pub score: f32,
    /// Finder runs spent on it: 1, or 2 after a second look (taken or not).
    pub looks: u8,
}

impl FaceBox {
    /// The box's left, top, right and bottom edges (px).
    pub fn corners(&self) -> [f32; 4] {
        let half = 0.5 * self.size;
        [self.cx - half, self.cy - half, self.cx + half, self.cy + half]
    }
}

/// Two boxes whose intersection over union exceeds this are one face (the lesser is dropped).
pub const SAME_FACE_IOU: f32 = 0.3;

/// Intersection over union of two square boxes (0 for boxes that are not numbers or have no area).
pub fn iou(a: &FaceBox, b: &FaceBox) -> f32 {
    if ![a.cx, a.cy, a.size, b.cx, b.cy, b.size].iter().all(|v| v.is_finite()) {
        return 0.0;
    }
    let inter = intersection(a, b);
    let union = a.size * a.size + b.size * b.size - inter;
    if union > 0.0 {
        inter / union
    } else {
        0.0
    }
}

/// The area two square boxes share (px²; their coordinates taken as numbers).
pub(crate) fn intersection(a: &FaceBox, b: &FaceBox) -> f32 {
    let overlap = |ca: f32, cb: f32| {
        let lo = (ca - 0.5 * a.size).max(cb - 0.5 * b.size);
        let hi = (ca + 0.5 * a.size).min(cb + 0.5 * b.size);
        (hi - lo).max(0.0)
    };
    overlap(a.cx, b.cx) * overlap(a.cy, b.cy)
}

/// The larger side of the points' bounding box and its centre.
pub fn landmark_box(points: &[[f32; 2]]) -> (f32, f32, f32) {
    let (mut lo, mut hi) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
    for p in points {
        for ((l, h), v) in lo.iter_mut().zip(hi.iter_mut()).zip(p) {
            *l = l.min(*v);
            *h = h.max(*v);
        }
    }
    let [lx, ly] = lo;
    let [hx, hy] = hi;
    ((lx + hx) * 0.5, (ly + hy) * 0.5, (hx - lx).max(hy - ly))
}

/// Whether the finder's box counts as a face for `min_score` (a NaN score never does).
pub fn is_face(face: &FaceBox, min_score: f32) -> bool {
    !(face.score.is_nan() || face.score < min_score)
}
