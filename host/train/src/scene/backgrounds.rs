//! Real face-free photographs behind the rendered heads, and as whole face-free frames: a camera
//! sees rooms, streets and foliage, not only the procedural backgrounds, and a finder that never
//! saw them fires on them. The photos come from a folder the user gives
//! (`tests/realphotos/backgrounds.py` makes one from Debian's wallpaper packages, checked face-free
//! by MediaPipe); none ships with the project.

use image::{imageops, RgbImage};
use rand::{Rng, RngExt};
use std::path::{Path, PathBuf};

/// Photos are kept at most this many pixels on their shorter side (scene frames are 128-256 px).
const SHORTER_SIDE: u32 = 512;

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
}

/// Face-free photographs, decoded and scaled down once.
#[derive(Debug, Clone)]
pub struct Backgrounds {
    photos: Vec<RgbImage>,
    /// Fraction of scenes drawn over a photo instead of a procedural background.
    pub share: f64,
}

impl Backgrounds {
    /// Every .jpg/.jpeg/.png of `dir` (not its subfolders), in name order.
    pub fn load(dir: &Path, share: f64) -> Result<Self, BackgroundsError> {
        let entries = std::fs::read_dir(dir).map_err(|error| BackgroundsError::Folder { dir: dir.to_path_buf(), error })?;
        let mut paths: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                p.extension().and_then(|x| x.to_str()).is_some_and(|x| ["jpg", "jpeg", "png"].contains(&x.to_ascii_lowercase().as_str()))
            })
            .collect();
        paths.sort();
        let photos = paths
            .iter()
            .map(|path| {
                let img = image::open(path).map_err(|error| BackgroundsError::Photo { path: path.clone(), error })?.to_rgb8();
                Ok(shrunk(img))
            })
            .collect::<Result<Vec<_>, BackgroundsError>>()?;
        if photos.is_empty() {
            return Err(BackgroundsError::Empty(dir.to_path_buf()));
        }
        Ok(Self { photos, share })
    }

    /// Backgrounds from photos already in memory (tests, examples).
    pub fn from_photos(photos: Vec<RgbImage>, share: f64) -> Self {
        Self { photos: photos.into_iter().map(shrunk).collect(), share }
    }

    /// Number of photos.
    pub fn len(&self) -> usize {
        self.photos.len()
    }

    /// Whether there is no photo.
    pub fn is_empty(&self) -> bool {
        self.photos.is_empty()
    }

    /// A `w × h` view of a random photo: a random part (a quarter to all of the largest window of
    /// that aspect the photo holds), sometimes mirrored, scaled to the frame.
    pub fn view(&self, w: u32, h: u32, rng: &mut impl Rng) -> Option<RgbImage> {
        let photo = self.photos.get(rng.random_range(0..self.photos.len().max(1)))?;
        let (pw, ph) = photo.dimensions();
        let aspect = w as f32 / h.max(1) as f32;
        let (fw, fh) =
            if pw as f32 / ph.max(1) as f32 > aspect { (ph as f32 * aspect, ph as f32) } else { (pw as f32, pw as f32 / aspect) };
        let s = rng.random_range(0.5f32..=1.0);
        let (cw, ch) = (((fw * s) as u32).clamp(1, pw), ((fh * s) as u32).clamp(1, ph));
        let (x, y) = (rng.random_range(0..=pw - cw), rng.random_range(0..=ph - ch));
        let part = imageops::crop_imm(photo, x, y, cw, ch).to_image();
        let mut out = imageops::resize(&part, w, h, imageops::FilterType::Triangle);
        if rng.random_bool(0.5) {
            imageops::flip_horizontal_in_place(&mut out);
        }
        Some(out)
    }
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
