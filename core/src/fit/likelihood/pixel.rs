//! The image likelihood, composed from a per-pixel foreground term and a background term (as
//! scalismo-faces composes `IndependentPixelEvaluator(pixel, background)`), evaluated as a
//! [`TileSink`] while the model is rendered: no frame is stored.
//!
//! For every pixel the model covers, `log p(I | R) − log b(I)` is added (I: target colour, R:
//! rendered colour, b: the background density of the target's colour); uncovered pixels add 0.
//! This is the foreground/background likelihood ratio of Schönborn et al. (2017): the whole image
//! is explained, by the face where it is drawn and by the background model elsewhere, and the
//! background terms of uncovered pixels cancel in every Metropolis-Hastings ratio. The standard
//! terms are [`GaussianPixel`] (`log N(I | R, σ² I₃)`) and the histogram [`BackgroundModel`].

use crate::error::FitError;
use crate::fit::likelihood::image::{to_linear, BackgroundModel, ImageEval, TargetImage};
use crate::fit::likelihood::occlusion::MaskView;
use crate::geometry::Vec3;
use crate::render::frame_cache::FragmentSink;
use crate::render::tile::{Tile, TileSink, NO_TRIANGLE};

/// The foreground term: how well a rendered colour explains a target colour.
///
/// # Examples
///
/// A Laplace (L1) term of one's own, summed by [`ImageLikelihood`] over the pixels a rendered
/// triangle covers:
///
/// ```
/// use gpmm_core::fit::{BackgroundModel, ImageLikelihood, PixelLikelihood, TargetImage};
/// use gpmm_core::geometry::Vec3;
/// use gpmm_core::render::{Cull, ProjectedVertex, TileRasterizer};
///
/// #[derive(Clone, Copy)]
/// struct Laplace {
///     scale: f32,
/// }
///
/// impl PixelLikelihood for Laplace {
///     fn log_likelihood(&self, target: Vec3, rendered: Vec3, _sq_dist: f32) -> f32 {
///         let l1: f32 = target.iter().zip(rendered).map(|(t, r)| (t - r).abs()).sum();
///         -3.0 * (2.0 * self.scale).ln() - l1 / self.scale
///     }
/// }
///
/// // A white 4 × 4 target and a grey (0.5) triangle covering all of it.
/// let pixels = [[255u8; 3]; 16];
/// let image = TargetImage::new(&pixels, 4, 4)?;
/// let grey = |x, y| ProjectedVertex { x, y, inv_w: 0.01, color: [0.5; 3] };
/// let vertices = [grey(0.0, 0.0), grey(9.0, 0.0), grey(0.0, 9.0)];
///
/// // The likelihood is a tile sink: it sums the terms while the frame is drawn, never stored.
/// let background = BackgroundModel::uniform();
/// let mut sink = ImageLikelihood::with_terms(image, Laplace { scale: 0.5 }, &background);
/// TileRasterizer::<4, 4, 8>::new().render(&vertices, &[[0u32, 1, 2]], 4, 4, Cull::None, &mut sink)?;
///
/// // Each pixel is 3 × 0.5 off: −3 ln(1) − 1.5 / 0.5 = −3 per pixel.
/// let eval = sink.eval();
/// assert_eq!(eval.covered, 16);
/// assert!((eval.log_likelihood - 16.0 * -3.0).abs() < 1e-3, "{}", eval.log_likelihood);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub trait PixelLikelihood {
    /// `log p(target | rendered)` of one covered pixel (colours linear, in [0, 1]); `sq_dist` is
    /// `|target − rendered|²` over the three channels, already computed for the RMSE.
    fn log_likelihood(&self, target: Vec3, rendered: Vec3, sq_dist: f32) -> f32;
}

/// The background term: how well the background explains a target colour.
///
/// # Examples
///
/// A background of one's own for a green screen: a green target pixel is well explained by the
/// background, so the face covering it earns less than with the uniform background.
///
/// ```
/// use gpmm_core::fit::{BackgroundLikelihood, BackgroundModel, GaussianPixel, ImageLikelihood, TargetImage};
/// use gpmm_core::render::{Cull, ProjectedVertex, TileRasterizer};
///
/// struct GreenScreen;
///
/// impl BackgroundLikelihood for GreenScreen {
///     fn log_density(&self, [r, g, b]: [u8; 3]) -> f32 {
///         if g > 200 && r < 50 && b < 50 { 4.0 } else { 0.0 }
///     }
/// }
///
/// // A 4 × 4 target, green in its left half, grey in its right; a grey triangle covering it all.
/// let pixels: Vec<[u8; 3]> = (0..16).map(|i| if i % 4 < 2 { [0, 255, 0] } else { [128; 3] }).collect();
/// let image = TargetImage::new(&pixels, 4, 4)?;
/// let grey = |x, y| ProjectedVertex { x, y, inv_w: 0.01, color: [0.5; 3] };
/// let vertices = [grey(0.0, 0.0), grey(9.0, 0.0), grey(0.0, 9.0)];
///
/// // The image term with a given background (any `BackgroundLikelihood`, here as a trait object).
/// let image_term = |background: &dyn BackgroundLikelihood| -> Result<f32, Box<dyn std::error::Error>> {
///     let mut sink = ImageLikelihood::with_terms(image, GaussianPixel::new(0.1)?, background);
///     TileRasterizer::<4, 4, 8>::new().render(&vertices, &[[0u32, 1, 2]], 4, 4, Cull::None, &mut sink)?;
///     Ok(sink.eval().log_likelihood)
/// };
///
/// // Each of the 8 green pixels the face covers costs the green screen's log density, 4.
/// let (uniform, green) = (image_term(&BackgroundModel::uniform())?, image_term(&GreenScreen)?);
/// assert!((uniform - green - 8.0 * 4.0).abs() < 1e-3, "{uniform} {green}");
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub trait BackgroundLikelihood {
    /// `log b(target)` of an 8-bit target colour.
    fn log_density(&self, target: [u8; 3]) -> f32;
}

/// One covered pixel's `log p(I | R) − log b(I)` under `pixel` and `background`, and `|I − R|²`
/// (target `p`, rendered `c`): what the image term sums and the occlusion labels threshold.
#[inline(always)]
pub fn pixel_terms<P: PixelLikelihood, B: BackgroundLikelihood + ?Sized>(pixel: &P, background: &B, p: [u8; 3], c: Vec3) -> (f32, f32) {
    let i = to_linear(p);
    let (d0, d1, d2) = (i[0] - c[0], i[1] - c[1], i[2] - c[2]);
    let d2sum = d0 * d0 + d1 * d1 + d2 * d2;
    (pixel.log_likelihood(i, c, d2sum) - background.log_density(p), d2sum)
}

impl BackgroundLikelihood for BackgroundModel {
    #[inline]
    fn log_density(&self, target: [u8; 3]) -> f32 {
        BackgroundModel::log_density(self, target)
    }
}

/// The standard foreground term: an isotropic Gaussian on the colour difference,
/// `log N(I | R, σ² I₃) = −3 log(σ √(2π)) − |I − R|² / (2σ²)`.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GaussianPixel {
    inv_two_var: f32,
    log_norm: f32,
}

impl GaussianPixel {
    /// The term for standard deviation `sigma` on [0, 1] colours (finite, > 0; `BadConfig` otherwise).
    pub fn new(sigma: f32) -> Result<Self, FitError> {
        if !(sigma > 0.0 && sigma.is_finite()) {
            return Err(FitError::BadConfig);
        }
        let log_norm = -3.0 * libm::logf(sigma * libm::sqrtf(core::f32::consts::TAU));
        Ok(Self { inv_two_var: 0.5 / (sigma * sigma), log_norm })
    }
}

impl PixelLikelihood for GaussianPixel {
    #[inline]
    fn log_likelihood(&self, _target: Vec3, _rendered: Vec3, sq_dist: f32) -> f32 {
        self.log_norm - sq_dist * self.inv_two_var
    }
}

/// A [`TileSink`] accumulating the image likelihood (pixel term `P` against background `B`)
/// while the model is rendered.
#[derive(Debug)]
pub struct ImageLikelihood<'a, 'b, P = GaussianPixel, B: ?Sized = BackgroundModel> {
    image: TargetImage<'a>,
    pixel: P,
    background: &'b B,
    sum: f64,
    sq: f64,
    covered: u32,
    /// The open tile's sums while a re-shaded frame arrives (log-likelihood, squared error, pixels).
    tile: (f32, f32, u32),
}

impl<'a, 'b> ImageLikelihood<'a, 'b> {
    /// The standard sink: Gaussian foreground with σ `sigma` (> 0) against the histogram `background`.
    pub fn new(image: TargetImage<'a>, background: &'b BackgroundModel, sigma: f32) -> Result<Self, FitError> {
        Ok(Self::with_terms(image, GaussianPixel::new(sigma)?, background))
    }
}

impl<'a, 'b, P: PixelLikelihood, B: BackgroundLikelihood + ?Sized> ImageLikelihood<'a, 'b, P, B> {
    /// A sink comparing renders with `image` through the given pixel and background terms.
    pub fn with_terms(image: TargetImage<'a>, pixel: P, background: &'b B) -> Self {
        Self { image, pixel, background, sum: 0.0, sq: 0.0, covered: 0, tile: (0.0, 0.0, 0) }
    }

    /// Clears the sums before the next frame.
    pub fn reset(&mut self) {
        self.sum = 0.0;
        self.sq = 0.0;
        self.covered = 0;
        self.tile = (0.0, 0.0, 0);
    }

    /// The sums of the frame(s) consumed since the last reset.
    pub fn eval(&self) -> ImageEval {
        let ll = self.sum as f32;
        ImageEval { log_likelihood: if ll.is_nan() { f32::NEG_INFINITY } else { ll }, covered: self.covered, sq_err: self.sq as f32 }
    }
}

impl<const TW: usize, const TH: usize, P: PixelLikelihood, B: BackgroundLikelihood + ?Sized> TileSink<TW, TH>
    for ImageLikelihood<'_, '_, P, B>
{
    fn consume(&mut self, tile: &Tile<TW, TH>) {
        // Two copies of the loop, the one with labels out of line: without labels it reads none.
        // A half-resolution target stores no rows: its pixels are read one by one.
        if self.image.is_half() {
            self.sum_tile_by_pixel(tile);
            return;
        }
        match self.image.mask() {
            None => self.sum_tile(tile, |_, _| false),
            Some(m) => self.sum_tile_masked(tile, m),
        }
    }
}

impl<P: PixelLikelihood, B: BackgroundLikelihood + ?Sized> ImageLikelihood<'_, '_, P, B> {
    /// [`Self::sum_tile`] leaving out the pixels `mask` labels occluded.
    #[inline(never)]
    fn sum_tile_masked<const TW: usize, const TH: usize>(&mut self, tile: &Tile<TW, TH>, mask: MaskView<'_>) {
        let x0 = tile.origin().0;
        self.sum_tile(tile, |x, y| mask.get(x0.wrapping_add(x as u32), y))
    }

    /// [`Self::sum_tile`] reading the target pixel by pixel ([`TargetImage::pixel`]: covered,
    /// unlabelled pixels only), for targets without rows.
    #[inline(never)]
    fn sum_tile_by_pixel<const TW: usize, const TH: usize>(&mut self, tile: &Tile<TW, TH>) {
        let (x0, y0) = tile.origin();
        let (mut sum, mut sq, mut covered) = (0.0f32, 0.0f32, 0u32);
        for ((tri_row, col_row), y) in tile.triangles().iter().zip(tile.colors()).zip(y0..y0 + tile.size().1) {
            for ((t, c), x) in tri_row.iter().zip(col_row).zip(x0..x0 + tile.size().0) {
                if *t == NO_TRIANGLE {
                    continue;
                }
                let Some(p) = self.image.pixel(x, y) else { continue };
                let (term, d2sum) = self.pixel_terms(p, *c);
                sq += d2sum;
                sum += term;
                covered += 1;
            }
        }
        self.add_tile(sum, sq, covered);
    }

    /// Sums a rendered tile's covered pixels, leaving out those `occluded(x, y)` labels (`x`: the
    /// column in the tile, `y`: the image row).
    #[inline(always)]
    fn sum_tile<const TW: usize, const TH: usize>(&mut self, tile: &Tile<TW, TH>, occluded: impl Fn(usize, u32) -> bool) {
        let (x0, y0) = tile.origin();
        let (w, h) = tile.size();
        let (mut sum, mut sq, mut covered) = (0.0f32, 0.0f32, 0u32);
        // The photo's pixels in this tile's columns (a crop past the photo's edge observes nothing there).
        let photo = self.image.covered();
        let (first, end) = (photo.x0.saturating_sub(x0) as usize, photo.x1.saturating_sub(x0) as usize);
        for ((tri_row, col_row), y) in tile.triangles().iter().zip(tile.colors()).zip(y0..y0 + h) {
            if y < photo.y0 || y >= photo.y1 {
                continue;
            }
            let Some(target_row) = self.image.row(y) else { continue };
            let Some(target_row) = target_row.get(x0 as usize..) else { continue };
            // Colours and targets are read only where the model covers.
            for (x, t) in tri_row.iter().enumerate().take((w as usize).min(end)).skip(first) {
                if *t == NO_TRIANGLE || occluded(x, y) {
                    continue;
                }
                let (Some(c), Some(p)) = (col_row.get(x), target_row.get(x)) else {
                    break;
                };
                let (term, d2sum) = self.pixel_terms(*p, *c);
                sq += d2sum;
                sum += term;
                covered += 1;
            }
        }
        self.add_tile(sum, sq, covered);
    }

    /// One covered pixel's terms ([`pixel_terms`]).
    #[inline(always)]
    fn pixel_terms(&self, p: [u8; 3], c: Vec3) -> (f32, f32) {
        pixel_terms(&self.pixel, self.background, p, c)
    }

    /// Adds one tile's sums (accumulated in `f32` within the tile, in `f64` across tiles).
    #[inline(always)]
    fn add_tile(&mut self, sum: f32, sq: f32, covered: u32) {
        self.sum += f64::from(sum);
        self.sq += f64::from(sq);
        self.covered = self.covered.saturating_add(covered);
    }
}

/// Re-shaded frames ([`crate::render::frame_cache::FrameCache::reshade`]) give the same sums as
/// rendered ones: the same per-pixel terms, accumulated tile by tile in the same order.
impl<P: PixelLikelihood, B: BackgroundLikelihood + ?Sized> FragmentSink for ImageLikelihood<'_, '_, P, B> {
    fn fragment(&mut self, pixel: u32, color: Vec3) {
        let Some(p) = self.image.pixel_at(pixel) else {
            // Not a pixel of this image: the frame is not this image's (never for a matching key).
            self.tile.0 = f32::NAN;
            return;
        };
        // Past the photo's edge or labelled occluded: nothing observed.
        let Some(p) = p else { return };
        let (term, d2sum) = self.pixel_terms(p, color);
        self.tile.1 += d2sum;
        self.tile.0 += term;
        self.tile.2 += 1;
    }

    fn end_tile(&mut self) {
        let (sum, sq, covered) = self.tile;
        self.tile = (0.0, 0.0, 0);
        self.add_tile(sum, sq, covered);
    }
}
