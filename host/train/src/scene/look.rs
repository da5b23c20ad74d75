//! A photograph's look over a whole training frame: black and white, contrast, brightness, colour
//! saturation and colour casts as cameras, lights, film and editing give them. Real photos of people come with
//! their one look each, and a finder shown only those learns faces in colour and of middling
//! contrast; the look is applied to every kind of frame alike (renders, real faces, face-free
//! views) so that it never tells a face from a background.

use image::RgbImage;
use rand::{Rng, RngExt};

/// The share of frames shown in black and white.
pub const GREY_SHARE: f64 = 0.1;
/// Contrast factors around the frame's mean drawn from (×).
pub const CONTRAST: (f32, f32) = (0.6, 1.4);
/// Brightness offsets drawn from (of full scale).
pub const BRIGHTNESS: (f32, f32) = (-0.12, 0.12);
/// Saturation factors drawn from (×; 0 is black and white).
pub const SATURATION: (f32, f32) = (0.5, 1.5);
/// Gains of the red and blue channels against the green drawn from (×): a colour cast, as stage
/// lights, screens, tungsten and shade give faces.
pub const CAST: (f32, f32) = (0.75, 1.25);

/// Gives `frame` a random look: with probability `share` contrast, brightness, saturation and a
/// colour cast drawn from their ranges, and among those frames [`GREY_SHARE`] / `share` in black and white
/// (so that [`GREY_SHARE`] of all frames are, when `share` ≥ it). `share` 0 leaves the frame as it is
/// and draws nothing.
pub fn apply_look(frame: &mut RgbImage, share: f64, rng: &mut impl Rng) {
    if share <= 0.0 || !rng.random_bool(share.min(1.0)) {
        return;
    }
    let grey = rng.random_bool((GREY_SHARE / share).clamp(0.0, 1.0));
    let contrast = rng.random_range(CONTRAST.0..CONTRAST.1);
    let brightness = rng.random_range(BRIGHTNESS.0..BRIGHTNESS.1);
    let saturation = if grey { 0.0 } else { rng.random_range(SATURATION.0..SATURATION.1) };
    let cast = if grey { [1.0; 3] } else { [rng.random_range(CAST.0..CAST.1), 1.0, rng.random_range(CAST.0..CAST.1)] };
    let pixels = (frame.width() as f32 * frame.height() as f32).max(1.0);
    let mean = frame.pixels().map(|p| luma(p.0)).sum::<f32>() / pixels;
    for p in frame.pixels_mut() {
        let y = luma(p.0);
        let c = p.0;
        p.0 = std::array::from_fn(|k| {
            let v = (y + (c[k] as f32 / 255.0 - y) * saturation) * cast[k];
            ((mean + (v - mean) * contrast + brightness).clamp(0.0, 1.0) * 255.0).round() as u8
        });
    }
}

/// Luma of an 8-bit RGB pixel (BT.601 weights), 0 to 1.
fn luma([r, g, b]: [u8; 3]) -> f32 {
    (0.299 * r as f32 + 0.587 * g as f32 + 0.114 * b as f32) / 255.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::Rgb;
    use rand::SeedableRng;
    use rand_xoshiro::Xoshiro256PlusPlus;

    fn colourful() -> RgbImage {
        RgbImage::from_fn(16, 12, |x, y| Rgb([(x * 15) as u8, (y * 20) as u8, 200 - (x * 5) as u8]))
    }

    fn is_grey(img: &RgbImage) -> bool {
        img.pixels().all(|p| p.0[0] == p.0[1] && p.0[1] == p.0[2])
    }

    #[test]
    fn no_share_leaves_the_frame_and_the_stream_alone() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
        let mut img = colourful();
        apply_look(&mut img, 0.0, &mut rng);
        assert_eq!(img, colourful());
        assert_eq!(rng, Xoshiro256PlusPlus::seed_from_u64(3));
    }

    #[test]
    fn the_grey_share_of_frames_is_black_and_white_and_the_rest_changes() {
        let (mut grey, mut changed, n) = (0, 0, 2000);
        for seed in 0..n {
            let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
            let mut img = colourful();
            apply_look(&mut img, 0.5, &mut rng);
            assert_eq!(img.dimensions(), (16, 12));
            grey += usize::from(is_grey(&img));
            changed += usize::from(img != colourful());
        }
        let share = grey as f64 / n as f64;
        assert!((share - GREY_SHARE).abs() < 0.03, "{share}");
        assert!((changed as f64 / n as f64 - 0.5).abs() < 0.05, "{changed}");
    }

    #[test]
    fn a_uniform_frame_stays_uniform_and_its_green_moves_by_the_brightness_alone() {
        for seed in 0..200 {
            let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
            let mut img = RgbImage::from_pixel(8, 8, Rgb([128, 128, 128]));
            apply_look(&mut img, 1.0, &mut rng);
            let first = img.get_pixel(0, 0).0;
            assert!(img.pixels().all(|p| p.0 == first), "seed {seed}: no longer uniform");
            // Green carries no cast and sits at the mean the contrast turns around.
            let reach = BRIGHTNESS.1 * 255.0 + 1.0;
            assert!((first[1] as f32 - 128.0).abs() <= reach, "seed {seed}: {first:?}");
        }
    }
}
