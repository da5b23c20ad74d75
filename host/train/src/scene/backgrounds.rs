//! Real photographs behind the rendered heads, and as whole face-free frames: a camera sees rooms,
//! streets and foliage, not only the procedural backgrounds, and a finder that never saw them fires
//! on them. The photos come from folders the user gives (`tests/realphotos/backgrounds.py` makes
//! one from Debian's wallpaper packages, checked face-free by MediaPipe); none ships with the
//! project.
//!
//! A photo with a `STEM.faces.json` beside it (the real-photo set format, `docs/formats.md`) is a
//! photo of people whose faces are known (`tests/realphotos/make_pool.py` makes such a folder):
//! views of it never touch a face, so its hands, clothes and rooms become background, and its
//! faces with points become real faces for the finder ([`Backgrounds::face_view`]).

use gpmm_core::model::ibug::{ibug68_partner, IBUG68_POINTS};
use gpmm_host::detect::photos::{read_faces_file, ReferenceFace};
use image::{imageops, RgbImage};
use rand::{Rng, RngExt};
use std::path::{Path, PathBuf};

/// Face-free photos are kept at most this many pixels on their shorter side (scene frames are
/// 128-256 px; a view can be a tenth of a photo, as a scan's smallest windows are).
const SHORTER_SIDE: u32 = 1024;

/// The smallest part of a photo a background view shows, as a share of the largest window of the
/// view's aspect: a photo scanned for small faces shows the finder windows down to a tenth of its
/// side, whose textures, blown up, it must learn as "no face" too (false positives per face-free
/// development photo of a scan down to 32 px: 1.27 with parts of half a photo or more, 0.64 with
/// this).
const SMALLEST_PART: f32 = 0.1;

/// Photos of people are kept at most this many pixels on their longer side: their faces are
/// often small, and a face view needs the face at 15-80 % of a frame.
const LABELLED_LONGER_SIDE: u32 = 1280;

/// A known face's area, which no background view may touch, is its box grown by this factor
/// about its centre (hair, ears and chin lie outside a detector's box).
const FACE_AREA_GROWTH: f32 = 1.6;

/// The smallest window (shorter side, px of the kept photo) a face view is cut from: smaller ones
/// would be blown up into blur.
const MIN_FACE_WINDOW: f32 = 48.0;

/// Windows tried for one view before giving up.
const ATTEMPTS: usize = 16;

/// Why a folder of backgrounds cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum BackgroundsError {
    /// The folder cannot be listed.
    #[error("cannot read the backgrounds folder {dir}: {error}")]
    Folder {
        /// The folder.
        dir: PathBuf,
        /// The cause.
        error: std::io::Error,
    },
    /// A photo does not decode.
    #[error("cannot read the background photo {path}: {error}")]
    Photo {
        /// The photo.
        path: PathBuf,
        /// The cause.
        error: image::ImageError,
    },
    /// The folder has no photo.
    #[error("the backgrounds folder {0} has no .jpg or .png photo")]
    Empty(PathBuf),
    /// A photo's `.faces.json` cannot be read.
    #[error("{0}")]
    Faces(String),
}

/// A known face of a photo of people, in the kept photo's pixels.
#[derive(Debug, Clone, PartialEq)]
struct KnownFace {
    /// x0, y0, x1, y1 that no background view may touch.
    area: [f32; 4],
    /// The finder's target (centre x, y and side of the landmarks' box), where the reference read
    /// the face's points.
    square: Option<[f32; 3]>,
    /// The reference's points (the initializer's target), where it read them.
    points: Vec<[f32; 2]>,
}

/// A photograph and the faces known in it (none for a face-free photo).
#[derive(Debug, Clone)]
struct Photo {
    image: RgbImage,
    faces: Vec<KnownFace>,
}

/// A view of a real face ([`Backgrounds::face_view`]): the frame and the face's landmark box and
/// points in it.
#[derive(Debug, Clone)]
pub struct FaceView {
    /// The frame.
    pub image: RgbImage,
    /// Centre x, y and side (px) of the face's landmarks' box in the frame.
    pub square: [f32; 3],
    /// The reference's points in the frame, in their scheme's order also when the view is a
    /// mirror image (the iBUG-68 partners swapped; other schemes are not mirrored).
    pub points: Vec<[f32; 2]>,
}

/// Photographs, decoded and scaled down once: face-free ones, and photos of people whose faces
/// are known.
#[derive(Debug, Clone)]
pub struct Backgrounds {
    photos: Vec<Photo>,
    /// (photo, face) of every face a face view can show.
    targets: Vec<(usize, usize)>,
    /// Fraction of scenes drawn over a photo instead of a procedural background.
    pub share: f64,
}

impl Backgrounds {
    /// Every .jpg/.jpeg/.png of `dir` (not its subfolders), in name order; one with a
    /// `STEM.faces.json` beside it is a photo of people.
    pub fn load(dir: &Path, share: f64) -> Result<Self, BackgroundsError> {
        Self::load_all(&[dir], share)
    }

    /// The photos of every folder of `dirs`, as [`Backgrounds::load`] reads one.
    pub fn load_all(dirs: &[&Path], share: f64) -> Result<Self, BackgroundsError> {
        let mut photos = Vec::new();
        for &dir in dirs {
            let entries = std::fs::read_dir(dir).map_err(|error| BackgroundsError::Folder { dir: dir.to_path_buf(), error })?;
            let mut paths: Vec<PathBuf> = entries
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| {
                    p.extension()
                        .and_then(|x| x.to_str())
                        .is_some_and(|x| ["jpg", "jpeg", "png"].contains(&x.to_ascii_lowercase().as_str()))
                })
                .collect();
            paths.sort();
            if paths.is_empty() {
                return Err(BackgroundsError::Empty(dir.to_path_buf()));
            }
            for path in paths {
                let img = image::open(&path).map_err(|error| BackgroundsError::Photo { path: path.clone(), error })?.to_rgb8();
                let json = path.file_stem().and_then(|s| s.to_str()).map(|stem| path.with_file_name(format!("{stem}.faces.json")));
                match json.filter(|j| j.exists()) {
                    Some(json) => {
                        let file = read_faces_file(&json).map_err(|e| BackgroundsError::Faces(e.to_string()))?;
                        photos.push(labelled(img, &file.faces));
                    }
                    None => photos.push(Photo { image: shrunk(img), faces: Vec::new() }),
                }
            }
        }
        Ok(Self::of(photos, share))
    }

    /// Backgrounds from face-free photos already in memory (tests, examples).
    pub fn from_photos(photos: Vec<RgbImage>, share: f64) -> Self {
        Self::of(photos.into_iter().map(|p| Photo { image: shrunk(p), faces: Vec::new() }).collect(), share)
    }

    /// Backgrounds from photos of people already in memory, each with its reference faces.
    pub fn from_labelled(photos: Vec<(RgbImage, Vec<ReferenceFace>)>, share: f64) -> Self {
        Self::of(photos.into_iter().map(|(image, faces)| labelled(image, &faces)).collect(), share)
    }

    fn of(photos: Vec<Photo>, share: f64) -> Self {
        let targets = photos
            .iter()
            .enumerate()
            .flat_map(|(p, photo)| photo.faces.iter().enumerate().filter(|(_, f)| f.square.is_some()).map(move |(k, _)| (p, k)))
            .collect();
        Self { photos, targets, share }
    }

    /// Number of photos.
    pub fn len(&self) -> usize {
        self.photos.len()
    }

    /// Whether there is no photo.
    pub fn is_empty(&self) -> bool {
        self.photos.is_empty()
    }

    /// Number of photos of people (photos with known faces).
    pub fn people_photos(&self) -> usize {
        self.photos.iter().filter(|p| !p.faces.is_empty()).count()
    }

    /// Number of faces a face view can show.
    pub fn faces(&self) -> usize {
        self.targets.len()
    }

    /// Every photo with the areas of its known faces (x0, y0, x1, y1 in its pixels: a reference
    /// box grown by [`FACE_AREA_GROWTH`]), which no face-free part of it may touch.
    pub fn photos_and_face_areas(&self) -> impl Iterator<Item = (&RgbImage, Vec<[f32; 4]>)> + '_ {
        self.photos.iter().map(|p| (&p.image, p.faces.iter().map(|f| f.area).collect()))
    }

    /// A `w × h` view of a random photo: a random part ([`SMALLEST_PART`] to all of the side of
    /// the largest window of that aspect the photo holds; on a photo of people a part that
    /// touches none of its faces), sometimes mirrored, scaled to the frame. `None` when no part
    /// without a face was found.
    pub fn view(&self, w: u32, h: u32, rng: &mut impl Rng) -> Option<RgbImage> {
        let aspect = w as f32 / h.max(1) as f32;
        for _ in 0..ATTEMPTS {
            let photo = self.photos.get(rng.random_range(0..self.photos.len().max(1)))?;
            let (pw, ph) = photo.image.dimensions();
            let (fw, fh) =
                if pw as f32 / ph.max(1) as f32 > aspect { (ph as f32 * aspect, ph as f32) } else { (pw as f32, pw as f32 / aspect) };
            let s = rng.random_range(SMALLEST_PART..=1.0);
            let (cw, ch) = (((fw * s) as u32).clamp(1, pw), ((fh * s) as u32).clamp(1, ph));
            let (x, y) = (rng.random_range(0..=pw - cw), rng.random_range(0..=ph - ch));
            let window = [x as f32, y as f32, (x + cw) as f32, (y + ch) as f32];
            if photo.faces.iter().any(|f| overlaps(f.area, window)) {
                continue;
            }
            return Some(cut(&photo.image, (x, y, cw, ch), w, h, rng.random_bool(0.5)));
        }
        None
    }

    /// A `w × h` view of a random known face: the face's side a random share `face_fraction` of
    /// the frame's shorter side, its centre anywhere in the middle 70 % of the frame, no other
    /// face's centre in the frame, sometimes mirrored. `None` without faces or when no such
    /// window fits the photo.
    pub fn face_view(&self, w: u32, h: u32, face_fraction: (f32, f32), rng: &mut impl Rng) -> Option<FaceView> {
        if self.targets.is_empty() || w == 0 || h == 0 || face_fraction.0 <= 0.0 || face_fraction.1 <= face_fraction.0 {
            return None;
        }
        for _ in 0..ATTEMPTS {
            let &(p, k) = self.targets.get(rng.random_range(0..self.targets.len()))?;
            let photo = self.photos.get(p)?;
            let [cx, cy, size] = photo.faces.get(k)?.square?;
            let short = size / rng.random_range(face_fraction.0..face_fraction.1);
            let (cw, ch) = if w <= h { (short, short * h as f32 / w as f32) } else { (short * w as f32 / h as f32, short) };
            let (fx, fy) = (rng.random_range(0.15f32..0.85), rng.random_range(0.15f32..0.85));
            let (x0, y0) = ((cx - fx * cw).round(), (cy - fy * ch).round());
            let (pw, ph) = photo.image.dimensions();
            if short < MIN_FACE_WINDOW || x0 < 0.0 || y0 < 0.0 || x0 + cw > pw as f32 || y0 + ch > ph as f32 {
                continue;
            }
            let inside = |f: &KnownFace| {
                let (ox, oy) = ((f.area[0] + f.area[2]) * 0.5, (f.area[1] + f.area[3]) * 0.5);
                ox >= x0 && ox < x0 + cw && oy >= y0 && oy < y0 + ch
            };
            if photo.faces.iter().enumerate().any(|(j, f)| j != k && inside(f)) {
                continue;
            }
            let (cwu, chu) = ((cw as u32).max(1), (ch as u32).max(1));
            let flip = rng.random_bool(0.5);
            let image = cut(&photo.image, (x0 as u32, y0 as u32, cwu, chu), w, h, flip);
            let (sx, sy) = (w as f32 / cwu as f32, h as f32 / chu as f32);
            let (vx, vy) = ((cx - x0) * sx, (cy - y0) * sy);
            let place = |p: &[f32; 2]| {
                let (px, py) = ((p[0] - x0) * sx, (p[1] - y0) * sy);
                [if flip { w as f32 - px } else { px }, py]
            };
            let known = &photo.faces.get(k)?.points;
            let points = match (flip, known.len()) {
                (false, _) => known.iter().map(place).collect(),
                (true, IBUG68_POINTS) => (0..IBUG68_POINTS).filter_map(|i| known.get(ibug68_partner(i)).map(place)).collect(),
                (true, _) => Vec::new(),
            };
            return Some(FaceView { image, square: [if flip { w as f32 - vx } else { vx }, vy, size * sx.max(sy)], points });
        }
        None
    }
}

/// Part `(x, y, cw, ch)` of `photo` scaled to `w × h`, mirrored if `flip`.
fn cut(photo: &RgbImage, (x, y, cw, ch): (u32, u32, u32, u32), w: u32, h: u32, flip: bool) -> RgbImage {
    let part = imageops::crop_imm(photo, x, y, cw, ch).to_image();
    let mut out = imageops::resize(&part, w, h, imageops::FilterType::Triangle);
    if flip {
        imageops::flip_horizontal_in_place(&mut out);
    }
    out
}

/// Whether two x0, y0, x1, y1 boxes share any area.
pub(crate) fn overlaps(a: [f32; 4], b: [f32; 4]) -> bool {
    a[0] < b[2] && b[0] < a[2] && a[1] < b[3] && b[1] < a[3]
}

/// A photo of people, scaled to at most [`LABELLED_LONGER_SIDE`], with its faces.
fn labelled(img: RgbImage, faces: &[ReferenceFace]) -> Photo {
    let (w, h) = img.dimensions();
    let s = (LABELLED_LONGER_SIDE as f32 / w.max(h).max(1) as f32).min(1.0);
    let image = if s < 1.0 {
        imageops::resize(&img, ((w as f32 * s) as u32).max(1), ((h as f32 * s) as u32).max(1), imageops::FilterType::Triangle)
    } else {
        img
    };
    let faces = faces
        .iter()
        .map(|f| {
            let [x0, y0, x1, y1] = f.bbox;
            let square = f.square();
            let (cx, cy) = (((x0 + x1) * 0.5 + square.cx) * 0.5, ((y0 + y1) * 0.5 + square.cy) * 0.5);
            let half = 0.5 * FACE_AREA_GROWTH * f.size().max(square.size);
            KnownFace {
                area: [cx - half, cy - half, cx + half, cy + half].map(|v| v * s),
                square: f.landmarks.is_some().then_some([square.cx * s, square.cy * s, square.size * s]),
                points: f.landmarks.iter().flatten().map(|p| p.map(|v| v * s)).collect(),
            }
        })
        .collect();
    Photo { image, faces }
}

fn shrunk(img: RgbImage) -> RgbImage {
    let (w, h) = img.dimensions();
    let short = w.min(h);
    if short <= SHORTER_SIDE {
        return img;
    }
    let s = SHORTER_SIDE as f32 / short as f32;
    imageops::resize(&img, ((w as f32 * s) as u32).max(1), ((h as f32 * s) as u32).max(1), imageops::FilterType::Triangle)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use image::Rgb;
    use rand::SeedableRng;
    use rand_xoshiro::Xoshiro256PlusPlus;

    #[test]
    fn a_view_has_the_frame_size_and_the_photo_colours() {
        let left_red = RgbImage::from_fn(900, 600, |x, _| if x < 450 { Rgb([200, 10, 10]) } else { Rgb([10, 10, 200]) });
        let b = Backgrounds::from_photos(vec![left_red], 1.0);
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
        for (w, h) in [(128, 96), (96, 192), (256, 256)] {
            let v = b.view(w, h, &mut rng).unwrap();
            assert_eq!(v.dimensions(), (w, h));
            assert!(v.pixels().all(|p| p[1] < 40), "only the photo's red and blue");
        }
    }

    /// A blue 800 × 600 photo with a red 60 px "face" at (500, 200) whose reference box and
    /// points the test knows.
    fn photo_of_one_face() -> (RgbImage, Vec<ReferenceFace>) {
        let img = RgbImage::from_fn(800, 600, |x, y| {
            if (470..530).contains(&x) && (170..230).contains(&y) {
                Rgb([220, 20, 20])
            } else {
                Rgb([20, 20, 220])
            }
        });
        // 68 points spread over the red square: their box is the square.
        let landmarks = (0..68).map(|i| [470.0 + (i % 9) as f32 * 7.5, 170.0 + (i / 9) as f32 * 60.0 / 7.0]).collect();
        (img, vec![ReferenceFace { bbox: [475.0, 180.0, 525.0, 230.0], landmarks: Some(landmarks) }])
    }

    #[test]
    fn views_of_a_photo_of_people_never_show_a_face() {
        let b = Backgrounds::from_labelled(vec![photo_of_one_face()], 1.0);
        assert_eq!((b.len(), b.people_photos(), b.faces()), (1, 1, 1));
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(5);
        let views: Vec<RgbImage> = (0..200).filter_map(|_| b.view(96, 128, &mut rng)).collect();
        assert!(views.len() > 100, "most draws find a part without the face: {}", views.len());
        assert!(views.iter().all(|v| v.pixels().all(|p| p[0] < 100)), "no red pixel in any view");
    }

    #[test]
    fn a_face_view_puts_the_target_box_on_the_face() {
        let b = Backgrounds::from_labelled(vec![photo_of_one_face()], 1.0);
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(9);
        let mut seen = 0;
        for (w, h) in [(128, 96), (96, 192), (200, 200)] {
            for _ in 0..20 {
                let Some(v) = b.face_view(w, h, (0.2, 0.6), &mut rng) else { continue };
                seen += 1;
                assert_eq!(v.image.dimensions(), (w, h));
                let [cx, cy, size] = v.square;
                let short = w.min(h) as f32;
                assert!(size >= 0.2 * short * 0.95 && size <= 0.6 * short * 1.05, "face {size} px in a {w}x{h} frame");
                assert!(cx > 0.1 * w as f32 && cx < 0.9 * w as f32 && cy > 0.1 * h as f32 && cy < 0.9 * h as f32);
                let centre = v.image.get_pixel(cx as u32, cy as u32);
                assert!(centre[0] > 150 && centre[2] < 100, "the box's centre is on the red face: {centre:?}");
                // Just outside the box (a tenth of its side beyond) is the blue photo.
                let out = v.image.get_pixel(((cx + 0.6 * size) as u32).min(w - 1), cy as u32);
                assert!(cx + 0.6 * size >= w as f32 || out[2] > 150, "outside the box: {out:?}");
            }
        }
        assert!(seen >= 30, "face views found: {seen}");
    }

    #[test]
    fn a_face_without_points_is_avoided_but_never_shown() {
        let (img, mut faces) = photo_of_one_face();
        faces[0].landmarks = None;
        let b = Backgrounds::from_labelled(vec![(img, faces)], 1.0);
        assert_eq!(b.faces(), 0);
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(2);
        assert!(b.face_view(128, 128, (0.2, 0.6), &mut rng).is_none());
        let views: Vec<RgbImage> = (0..50).filter_map(|_| b.view(128, 128, &mut rng)).collect();
        assert!(!views.is_empty() && views.iter().all(|v| v.pixels().all(|p| p[0] < 100)));
    }

    #[test]
    fn a_broken_faces_file_is_an_error_naming_it() {
        let dir = std::env::temp_dir().join(format!("gpmm-people-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        photo_of_one_face().0.save(dir.join("group.png")).unwrap();
        std::fs::write(dir.join("group.faces.json"), r#"{"faces": [{"box": [10, 10, 5, 5], "landmarks": null}]}"#).unwrap();
        let e = Backgrounds::load(&dir, 0.5).unwrap_err().to_string();
        assert!(e.contains("group.faces.json") && e.contains("x1 > x0"), "{e}");
        std::fs::write(dir.join("group.faces.json"), r#"{"faces": [{"box": [475, 180, 525, 230], "landmarks": null}]}"#).unwrap();
        let b = Backgrounds::load(&dir, 0.5).unwrap();
        assert_eq!((b.people_photos(), b.faces()), (1, 0));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_folder_without_photos_is_an_error_naming_it() {
        let dir = std::env::temp_dir().join(format!("gpmm-no-backgrounds-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let e = Backgrounds::load(&dir, 0.5).unwrap_err().to_string();
        assert!(e.contains("no .jpg or .png") && e.contains(&dir.display().to_string()), "{e}");
        let missing = Backgrounds::load(&dir.join("missing"), 0.5).unwrap_err().to_string();
        assert!(missing.contains("cannot read the backgrounds folder"), "{missing}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
