//! The target image, its colour-histogram background model and the result of one image
//! evaluation. The likelihood itself (pixel and background terms composed into a [`crate::render::tile::TileSink`])
//! is in [`crate::fit::likelihood`].

use crate::error::FitError;
use crate::fit::likelihood::occlusion::MaskView;
use crate::geometry::CoveredPixels;
use crate::geometry::Vec3;

/// The foreground σ of Schönborn et al. on colours in [0, 1].
pub const DEFAULT_PIXEL_SIGMA: f32 = 0.043;

/// Bins per channel of the background histogram.
pub const BG_BINS: usize = 8;
const BG_SHIFT: u32 = 5; // 256 / 8 = 32 = 1 << 5
const BG_TOTAL: usize = BG_BINS * BG_BINS * BG_BINS;

/// A borrowed 8-bit RGB target image, row-major, top row first, linear colours (value / 255),
/// with the pixels the photo covers: the others (a crop past the photo's edge) read as absent,
/// as do the pixels an occlusion mask labels ([`TargetImage::with_mask`]). It may be a view at
/// half the resolution of its pixels ([`TargetImage::half`]).
#[derive(Debug, Clone, Copy)]
pub struct TargetImage<'a> {
    pixels: &'a [[u8; 3]],
    width: u32,
    height: u32,
    covered: CoveredPixels,
    /// Whether some pixel reads as absent: past the photo's edge, or labelled by `mask` (one test
    /// per pixel read while neither is), or the image is a half-resolution view.
    partial: bool,
    mask: Option<MaskView<'a>>,
    /// Whether each pixel is the mean of a 2 × 2 block of `pixels` (whose rows are `2 · width`
    /// long), the mask then being the full-resolution one.
    half: bool,
}

impl<'a> TargetImage<'a> {
    /// Checks `pixels.len() == width · height` and that the image is not empty.
    pub fn new(pixels: &'a [[u8; 3]], width: u32, height: u32) -> Result<Self, FitError> {
        if width == 0 || height == 0 {
            return Err(FitError::EmptyImage);
        }
        if (width as usize).checked_mul(height as usize) != Some(pixels.len()) {
            return Err(FitError::LengthMismatch);
        }
        if width > crate::render::raster::MAX_IMAGE_SIZE || height > crate::render::raster::MAX_IMAGE_SIZE {
            return Err(FitError::BadConfig);
        }
        Ok(Self { pixels, width, height, covered: CoveredPixels::whole(width, height), partial: false, mask: None, half: false })
    }

    /// The image with `partial` as its other fields say: some pixel reads as absent.
    fn with_partial(self) -> Self {
        let partial = self.half || self.mask.is_some() || self.covered != CoveredPixels::whole(self.width, self.height);
        Self { partial, ..self }
    }

    /// The image at half the resolution (`⌊width / 2⌋ × ⌊height / 2⌋`, each pixel the rounded mean
    /// of a 2 × 2 block), without copying: a coarse target for the first steps of a chain. A
    /// pixel reads as absent unless its whole block is covered and unlabelled. `BadConfig` for an
    /// image already halved or smaller than 2 × 2.
    pub fn half(&self) -> Result<Self, FitError> {
        let (width, height) = (self.width / 2, self.height / 2);
        if self.half || width == 0 || height == 0 {
            return Err(FitError::BadConfig);
        }
        let c = self.covered;
        let covered = CoveredPixels { x0: c.x0.div_ceil(2), y0: c.y0.div_ceil(2), x1: c.x1 / 2, y1: c.y1 / 2 };
        let covered = if covered.fits(width, height) { covered } else { CoveredPixels { x0: 0, y0: 0, x1: 0, y1: 0 } };
        Ok(Self { width, height, covered, half: true, ..*self }.with_partial())
    }

    /// Whether this is a half-resolution view ([`Self::half`]).
    pub fn is_half(&self) -> bool {
        self.half
    }

    /// The image with only `covered` observed (see [`crate::fit::frame`]); the rectangle must lie
    /// in the image and cover a pixel.
    pub fn with_covered(self, covered: CoveredPixels) -> Result<Self, FitError> {
        if !covered.fits(self.width, self.height) {
            return Err(FitError::EmptyImage);
        }
        Ok(Self { covered, ..self }.with_partial())
    }

    /// The image with the pixels `mask` labels occluded read as absent (the mask must be this
    /// image's size): every use of the target (the image term, the light, colour and shape
    /// solves) then leaves them to the non-face model.
    pub fn with_mask<'m>(self, mask: MaskView<'m>) -> Result<TargetImage<'m>, FitError>
    where
        'a: 'm,
    {
        let scale = if self.half { 2 } else { 1 };
        if mask.width() != self.width * scale || mask.height() != self.height * scale {
            return Err(FitError::LengthMismatch);
        }
        Ok(TargetImage { mask: Some(mask), ..self }.with_partial())
    }

    /// The image with every pixel the photo covers observed.
    pub fn without_mask(self) -> Self {
        Self { mask: None, ..self }.with_partial()
    }

    /// The occlusion mask read, if any.
    #[inline(always)]
    pub fn mask(&self) -> Option<MaskView<'a>> {
        self.mask
    }

    /// The pixels the photo covers.
    pub fn covered(&self) -> CoveredPixels {
        self.covered
    }

    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The pixel at `(x, y)`, if inside, covered and not masked.
    #[inline]
    pub fn pixel(&self, x: u32, y: u32) -> Option<[u8; 3]> {
        if x >= self.width || y >= self.height {
            return None;
        }
        if self.partial {
            if self.half {
                return self.half_pixel(x, y);
            }
            if self.absent(x, y) {
                return None;
            }
        }
        self.pixels.get(y as usize * self.width as usize + x as usize).copied()
    }

    /// A half-resolution view's pixel `(x, y)` (inside): the rounded mean of its 2 × 2 block, if
    /// the block is covered and no pixel of it labelled.
    #[inline(never)]
    fn half_pixel(&self, x: u32, y: u32) -> Option<[u8; 3]> {
        if !self.covered.contains(x, y) {
            return None;
        }
        let (u, v) = (2 * x, 2 * y);
        if self.mask.is_some_and(|m| m.get(u, v) || m.get(u + 1, v) || m.get(u, v + 1) || m.get(u + 1, v + 1)) {
            return None;
        }
        let stride = 2 * self.width as usize;
        let at = v as usize * stride + u as usize;
        let (&[a, b], &[c, d]) = (self.pixels.get(at..at + 2)?, self.pixels.get(at + stride..at + stride + 2)?) else {
            return None;
        };
        let mean = |a: u8, b: u8, c: u8, d: u8| ((u16::from(a) + u16::from(b) + u16::from(c) + u16::from(d) + 2) >> 2) as u8;
        Some([mean(a[0], b[0], c[0], d[0]), mean(a[1], b[1], c[1], d[1]), mean(a[2], b[2], c[2], d[2])])
    }

    /// The linear colour in [0, 1] nearest to the continuous pixel position `(x, y)` (pixel centres at +0.5).
    pub fn sample(&self, x: f32, y: f32) -> Option<Vec3> {
        if !(x >= 0.0 && y >= 0.0) {
            return None;
        }
        let p = self.pixel(x as u32, y as u32)?;
        Some(to_linear(p))
    }

    /// The linear colour at the continuous position `(x, y)`, interpolated bilinearly between the
    /// four nearest pixel centres (the covered pixels' edge pixels repeated), if `(x, y)` lies in
    /// a covered pixel.
    pub fn sample_bilinear(&self, x: f32, y: f32) -> Option<Vec3> {
        let cov = self.covered;
        if !(x >= cov.x0 as f32 && y >= cov.y0 as f32 && x < cov.x1 as f32 && y < cov.y1 as f32) {
            return None;
        }
        let (fx, fy) = (x - 0.5, y - 0.5);
        let (x0, y0) = (libm::floorf(fx), libm::floorf(fy));
        let (tx, ty) = (fx - x0, fy - y0);
        let clamp = |v: f32, lo: u32, hi: u32| -> u32 { (v.max(lo as f32) as u32).clamp(lo, hi.saturating_sub(1).max(lo)) };
        let (xa, xb) = (clamp(x0, cov.x0, cov.x1), clamp(x0 + 1.0, cov.x0, cov.x1));
        let (ya, yb) = (clamp(y0, cov.y0, cov.y1), clamp(y0 + 1.0, cov.y0, cov.y1));
        let px = |xx: u32, yy: u32| self.pixel(xx, yy).map(to_linear);
        let (a, b, c, d) = (px(xa, ya)?, px(xb, ya)?, px(xa, yb)?, px(xb, yb)?);
        let mut out = [0.0f32; 3];
        for (i, o) in out.iter_mut().enumerate() {
            let g = |v: &Vec3| v.get(i).copied().unwrap_or(0.0);
            let top = g(&a) + tx * (g(&b) - g(&a));
            let bottom = g(&c) + tx * (g(&d) - g(&c));
            *o = top + ty * (bottom - top);
        }
        Some(out)
    }

    /// The pixel at row-major index `index`, if inside; `Some(None)` if inside but not covered or masked.
    #[inline(always)]
    pub fn pixel_at(&self, index: u32) -> Option<Option<[u8; 3]>> {
        let p = self.pixels.get(index as usize).copied()?;
        if self.partial {
            let (x, y) = (index % self.width, index / self.width);
            if self.half {
                return (y < self.height).then(|| self.half_pixel(x, y));
            }
            if self.absent(x, y) {
                return Some(None);
            }
        }
        Some(Some(p))
    }

    /// Whether pixel `(x, y)` of the image lies past the photo's edge or is labelled occluded.
    #[inline(always)]
    fn absent(&self, x: u32, y: u32) -> bool {
        !self.covered.contains(x, y) || self.mask.is_some_and(|m| m.get(x, y))
    }

    /// Row `y` (`width` pixels), covered or not (see [`TargetImage::covered`]), masked or not;
    /// `None` for a half-resolution view (its pixels are not stored: [`Self::pixel`]).
    pub fn row(&self, y: u32) -> Option<&'a [[u8; 3]]> {
        if self.half {
            return None;
        }
        let w = self.width as usize;
        let start = (y as usize).checked_mul(w)?;
        self.pixels.get(start..start.checked_add(w)?)
    }
}

#[inline]
pub(crate) fn to_linear(p: [u8; 3]) -> Vec3 {
    p.map(|c| f32::from(c) * (1.0 / 255.0))
}

#[inline]
fn bin(p: [u8; 3]) -> usize {
    (usize::from(p[0] >> BG_SHIFT) * BG_BINS + usize::from(p[1] >> BG_SHIFT)) * BG_BINS + usize::from(p[2] >> BG_SHIFT)
}

/// Background colour model: an `8 × 8 × 8` histogram of the target image as a density on the
/// RGB unit cube, mixed with a uniform floor so no colour has zero density (2 KiB).
#[derive(Debug, Clone)]
pub struct BackgroundModel {
    log_density: [f32; BG_TOTAL],
}

impl BackgroundModel {
    /// The histogram of `image`, mixed as `(1 − floor) · histogram + floor · uniform` (`floor` in (0, 1]).
    pub fn from_image(image: &TargetImage<'_>, floor: f32) -> Result<Self, FitError> {
        if !(floor > 0.0 && floor <= 1.0) {
            return Err(FitError::BadConfig);
        }
        let mut counts = [0u32; BG_TOTAL];
        let cov = image.covered;
        let unmasked = image.without_mask();
        let mut count = |p: [u8; 3]| {
            if let Some(c) = counts.get_mut(bin(p)) {
                *c = c.saturating_add(1);
            }
        };
        for y in cov.y0..cov.y1 {
            match image.row(y) {
                Some(row) => row.get(cov.x0 as usize..cov.x1 as usize).unwrap_or(&[]).iter().for_each(|p| count(*p)),
                // A half-resolution view: its block means, masked or not.
                None => (cov.x0..cov.x1).filter_map(|x| unmasked.pixel(x, y)).for_each(&mut count),
            }
        }
        let n = cov.count().max(1) as f32;
        let mut log_density = [0.0f32; BG_TOTAL];
        for (l, c) in log_density.iter_mut().zip(counts) {
            // Density on the unit cube: probability / bin volume, bin volume = 1 / 512.
            let d = (1.0 - floor) * (c as f32 / n) * BG_TOTAL as f32 + floor;
            *l = libm::logf(d);
        }
        Ok(Self { log_density })
    }

    /// A uniform background (density 1, log density 0 everywhere).
    pub fn uniform() -> Self {
        Self { log_density: [0.0; BG_TOTAL] }
    }

    /// `log b(colour)` of an 8-bit colour.
    #[inline]
    pub fn log_density(&self, p: [u8; 3]) -> f32 {
        self.log_density.get(bin(p)).copied().unwrap_or(0.0)
    }
}

/// Result of one image evaluation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImageEval {
    /// `Σ_covered [log N(I | R, σ) − log b(I)]` (a proper log-likelihood ratio, constants included).
    pub log_likelihood: f32,
    /// Covered pixels.
    pub covered: u32,
    /// `Σ_covered |I − R|²` over the three channels.
    pub sq_err: f32,
}

impl ImageEval {
    /// Root-mean-square colour error per channel over covered pixels (0 if none is covered).
    pub fn rmse(&self) -> f32 {
        if self.covered == 0 {
            return 0.0;
        }
        libm::sqrtf(self.sq_err / (3.0 * self.covered as f32))
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    #[test]
    fn a_half_view_reads_the_block_means_of_whole_blocks() {
        let px: [[u8; 3]; 16] = core::array::from_fn(|i| [(i * 10) as u8, (255 - i) as u8, (i % 2) as u8]);
        let full = TargetImage::new(&px, 4, 4).unwrap();
        let half = full.half().unwrap();
        assert!(half.is_half() && !full.is_half());
        assert_eq!((half.width(), half.height()), (2, 2));
        // Pixels 0, 1, 4, 5: rounded means.
        assert_eq!(half.pixel(0, 0), Some([25, 253, 1]));
        assert_eq!(half.pixel_at(3), Some(half.pixel(1, 1)));
        assert_eq!(half.pixel(1, 1), Some([125, 243, 1]));
        assert_eq!((half.pixel_at(4), half.pixel(2, 0), half.row(0)), (None, None, None));
        // A block partly past the photo's edge is absent.
        let edge = full.with_covered(CoveredPixels { x0: 1, y0: 0, x1: 4, y1: 4 }).unwrap().half().unwrap();
        assert_eq!((edge.pixel(0, 0), edge.pixel_at(0), edge.pixel(1, 0)), (None, Some(None), half.pixel(1, 0)));
        // So is a block with a labelled pixel (the labels are the full image's).
        let mut mask = crate::fit::OcclusionMask::<4>::new();
        mask.reset(4, 4).unwrap();
        mask.set(3, 3, true);
        let masked = half.with_mask(mask.view()).unwrap();
        assert_eq!((masked.pixel(1, 1), masked.pixel(0, 1)), (None, half.pixel(0, 1)));
        assert_eq!(masked.without_mask().pixel(1, 1), half.pixel(1, 1));
        let mut small = crate::fit::OcclusionMask::<4>::new();
        small.reset(2, 2).unwrap();
        assert_eq!(half.with_mask(small.view()).err(), Some(FitError::LengthMismatch));
        // The background of a half view counts its block means.
        let bg = BackgroundModel::from_image(&half, 0.5).unwrap();
        assert!(bg.log_density([25, 253, 1]) > bg.log_density([128, 0, 128]));
        // Halved once only, and not below a pixel.
        assert_eq!(half.half().err(), Some(FitError::BadConfig));
        let one = [[0u8; 3]; 2];
        assert_eq!(TargetImage::new(&one, 2, 1).unwrap().half().err(), Some(FitError::BadConfig));
    }

    #[test]
    fn bad_images_are_errors() {
        let px = [[0u8; 3]; 6];
        assert_eq!(TargetImage::new(&px, 0, 6).err(), Some(FitError::EmptyImage));
        assert_eq!(TargetImage::new(&px, 4, 2).err(), Some(FitError::LengthMismatch));
        let img = TargetImage::new(&px, 3, 2).unwrap();
        assert_eq!(BackgroundModel::from_image(&img, 0.0).err(), Some(FitError::BadConfig));
        let bg = BackgroundModel::uniform();
        assert_eq!(crate::fit::ImageLikelihood::new(img, &bg, f32::NAN).err(), Some(FitError::BadConfig));
        assert_eq!(img.pixel(3, 0), None);
        assert_eq!(img.sample(-0.5, 0.0), None);
    }

    #[test]
    fn pixels_past_the_photo_are_absent_and_not_in_the_background() {
        // 2 × 2: the right column lies past the photo (white padding).
        let px: [[u8; 3]; 4] = [[0, 0, 0], [255, 255, 255], [0, 0, 0], [255, 255, 255]];
        let whole = TargetImage::new(&px, 2, 2).unwrap();
        let img = whole.with_covered(CoveredPixels { x0: 0, y0: 0, x1: 1, y1: 2 }).unwrap();
        assert_eq!(img.pixel(1, 0), None);
        assert_eq!(img.pixel(0, 1), Some([0, 0, 0]));
        assert_eq!(img.pixel_at(1), Some(None));
        assert_eq!(img.pixel_at(2), Some(Some([0, 0, 0])));
        assert_eq!(img.pixel_at(4), None);
        assert_eq!(img.sample(1.5, 0.5), None);
        // Bilinear samples repeat the covered edge: at the edge pixel's right border, its colour.
        assert_eq!(img.sample_bilinear(0.99, 0.5), Some([0.0; 3]));
        assert_eq!(img.sample_bilinear(1.5, 0.5), None);
        // The background sees only the covered black pixels.
        let bg = BackgroundModel::from_image(&img, 0.01).unwrap();
        let bg_whole = BackgroundModel::from_image(&whole, 0.01).unwrap();
        assert!(bg.log_density([255, 255, 255]) < bg_whole.log_density([255, 255, 255]));
        assert!((bg.log_density([255, 255, 255]) - libm::logf(0.01)).abs() < 1e-5);
        // A rectangle outside the image or covering nothing is refused.
        assert!(whole.with_covered(CoveredPixels { x0: 0, y0: 0, x1: 3, y1: 2 }).is_err());
        assert!(whole.with_covered(CoveredPixels { x0: 1, y0: 0, x1: 1, y1: 2 }).is_err());
    }

    #[test]
    fn histogram_is_a_density() {
        let px: [[u8; 3]; 4] = [[0, 0, 0], [0, 0, 0], [255, 255, 255], [10, 200, 30]];
        let img = TargetImage::new(&px, 2, 2).unwrap();
        let bg = BackgroundModel::from_image(&img, 0.01).unwrap();
        // Integrates to 1 over the cube: Σ density · (1/512).
        let total: f32 = bg.log_density.iter().map(|l| libm::expf(*l) / 512.0).sum();
        assert!((total - 1.0).abs() < 1e-4, "{total}");
        assert!(bg.log_density([0, 0, 0]) > bg.log_density([255, 255, 255]));
        assert!(bg.log_density([100, 100, 100]) < 0.0);
    }
}
