//! Labelling what the face does not explain ([`crate::fit::likelihood::occlusion`]): a tile sink
//! that judges every pixel a rendered frame covers.

use crate::error::FitError;
use crate::fit::likelihood::image::TargetImage;
use crate::fit::likelihood::occlusion::OcclusionMask;
use crate::fit::likelihood::pixel::{pixel_terms, BackgroundLikelihood, PixelLikelihood};
use crate::render::tile::{Tile, TileSink, NO_TRIANGLE};

/// A [`TileSink`] that labels the covered pixels of a rendered frame: occluded where the pixel
/// term against the background falls below the threshold, not occluded elsewhere.
pub struct Labeller<'m, 'a, 'b, P, B: ?Sized, const WORDS: usize> {
    /// The labels written.
    mask: &'m mut OcclusionMask<WORDS>,
    image: TargetImage<'a>,
    pixel: P,
    background: &'b B,
    threshold: f32,
    covered: u32,
}

impl<'m, 'a, 'b, P: PixelLikelihood, B: BackgroundLikelihood + ?Sized, const WORDS: usize> Labeller<'m, 'a, 'b, P, B, WORDS> {
    /// Clears `mask` for `image` (unmasked: every pixel is judged) and labels what the frame rendered into it covers.
    pub fn new(
        mask: &'m mut OcclusionMask<WORDS>,
        image: TargetImage<'a>,
        pixel: P,
        background: &'b B,
        threshold: f32,
    ) -> Result<Self, FitError> {
        mask.reset(image.width(), image.height())?;
        Ok(Self { mask, image: image.without_mask(), pixel, background, threshold, covered: 0 })
    }

    /// Covered pixels of the photo seen so far.
    pub fn covered(&self) -> u32 {
        self.covered
    }
}

impl<P: PixelLikelihood, B: BackgroundLikelihood + ?Sized, const WORDS: usize, const TW: usize, const TH: usize> TileSink<TW, TH>
    for Labeller<'_, '_, '_, P, B, WORDS>
{
    fn consume(&mut self, tile: &Tile<TW, TH>) {
        let (x0, y0) = tile.origin();
        let (w, h) = tile.size();
        for ((tri_row, col_row), y) in tile.triangles().iter().zip(tile.colors()).zip(y0..y0 + h) {
            for ((t, c), x) in tri_row.iter().zip(col_row).zip(x0..x0 + w) {
                if *t == NO_TRIANGLE {
                    continue;
                }
                let Some(p) = self.image.pixel(x, y) else { continue };
                let (term, _) = pixel_terms(&self.pixel, self.background, p, *c);
                self.mask.set(x, y, term < self.threshold);
                self.covered += 1;
            }
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    #[test]
    fn the_labeller_marks_what_the_face_explains_badly_and_the_image_term_then_ignores_it() {
        use crate::fit::{BackgroundModel, GaussianPixel, ImageLikelihood};
        use crate::render::{Cull, ProjectedVertex, TileRasterizer};
        // An 8 × 8 grey target (0.5) with a black 3 × 8 band on the left (the occluder), and a
        // grey square of a face covering all of it.
        let pixels: [[u8; 3]; 64] = core::array::from_fn(|i| if i % 8 < 3 { [0; 3] } else { [128; 3] });
        let image = TargetImage::new(&pixels, 8, 8).unwrap();
        let grey = |x, y| ProjectedVertex { x, y, inv_w: 0.01, color: [0.5; 3] };
        let vertices = [grey(0.0, 0.0), grey(8.0, 0.0), grey(0.0, 8.0), grey(8.0, 8.0)];
        let triangles = [[0u32, 1, 2], [1, 3, 2]];
        let (bg, pixel) = (BackgroundModel::uniform(), GaussianPixel::new(0.05).unwrap());
        let mut mask = OcclusionMask::<8>::new(); // a word per row
        let mut raster = TileRasterizer::<4, 4, 8>::new();
        let mut labeller = Labeller::new(&mut mask, image, pixel, &bg, -8.0).unwrap();
        raster.render(&vertices, &triangles, 8, 8, Cull::None, &mut labeller).unwrap();
        assert_eq!(labeller.covered(), 64);
        assert_eq!(mask.count(), 24);
        assert!((0..8).all(|y| mask.get(0, y) && mask.get(2, y) && !mask.get(3, y) && !mask.get(7, y)));
        // The image term of the masked target sums the 40 grey pixels only, each a perfect match.
        let masked = image.with_mask(mask.view()).unwrap();
        assert_eq!(masked.pixel(1, 1), None);
        assert_eq!(masked.pixel_at(1), Some(None));
        assert_eq!(masked.pixel(5, 1), Some([128; 3]));
        let mut sink = ImageLikelihood::with_terms(masked, pixel, &bg);
        raster.render(&vertices, &triangles, 8, 8, Cull::None, &mut sink).unwrap();
        let eval = sink.eval();
        assert_eq!(eval.covered, 40);
        assert!(eval.rmse() < 0.01, "{}", eval.rmse());
        // A mask of another size is refused.
        let mut other = OcclusionMask::<4>::new();
        other.reset(4, 4).unwrap();
        assert_eq!(image.with_mask(other.view()).err(), Some(FitError::LengthMismatch));
    }
}
