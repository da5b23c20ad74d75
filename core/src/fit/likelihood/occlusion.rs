//! What the face does not explain: a label per working pixel saying that the photo shows
//! something else there (glasses, a hand, hair, another photo's patch), inferred during the fit.
//!
//! Occlusion-aware fitting after Egger et al. (IJCV 2018): every pixel is explained either by the
//! face or by a non-face model, and the fit alternates between labelling the pixels and fitting
//! the face to the pixels labelled face. The non-face model is the image's own background
//! histogram ([`crate::fit::BackgroundModel`]), so a covered pixel labelled occluded adds the
//! same to the likelihood ratio as an uncovered one: nothing. A covered pixel is labelled
//! occluded where the face explains it worse than the non-face model by more than the prior
//! odds allow (`log p(I | R) − log b(I) <` [`OcclusionSettings::threshold`]); the labels are then
//! made spatially coherent by 3 × 3 majority passes (an occluder is a region, not scattered
//! pixels). The labels are read by every use of the target image
//! ([`crate::fit::TargetImage::with_mask`]):
//! the image term, the least-squares light and colour, the shape solve. The labelling itself is
//! the [`crate::fit::likelihood::labeller`]'s.
//!
//! Memory: one bit per working pixel, in a fixed-capacity [`OcclusionMask`] (2 KiB at 128 × 128).

use crate::error::FitError;

/// The occlusion-aware fit's settings: how often the labels are inferred, and how.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct OcclusionSettings {
    /// Labelling rounds (0: every pixel is believed, no labels). The start labels the pixels
    /// after its least-squares light and before each of its solves; the image chain runs in this
    /// many parts, the labels inferred again from the best sample before each.
    pub rounds: u32,
    /// A covered pixel whose `log p(I | R) − log b(I)` is below this is labelled occluded: the
    /// log prior odds of face against non-face. −8 (the default) segmented glasses, masks and
    /// photo patches best on the development renders (IoU 0.5–0.8); −32 labels only strong outliers.
    pub threshold: f32,
    /// 3 × 3 majority passes over the labels after each labelling.
    pub smoothing: u32,
}

impl OcclusionSettings {
    /// Every pixel believed (rounds 0); with rounds set, threshold −8 and 2 majority passes.
    pub const OFF: Self = Self { rounds: 0, threshold: -8.0, smoothing: 2 };

    /// Checks a finite threshold and at most 16 rounds and passes.
    pub fn validate(&self) -> Result<(), FitError> {
        if self.threshold.is_finite() && self.rounds <= 16 && self.smoothing <= 16 {
            Ok(())
        } else {
            Err(FitError::BadConfig)
        }
    }

    /// Whether the fit infers labels.
    pub fn enabled(&self) -> bool {
        self.rounds > 0
    }
}

/// A label per pixel of a working image of at most `32 · WORDS` pixels (rows start on a word):
/// set where the face is occluded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OcclusionMask<const WORDS: usize> {
    bits: [u32; WORDS],
    width: u32,
    height: u32,
}

/// A mask's labels borrowed without its capacity (what a [`TargetImage`] reads).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MaskView<'a> {
    bits: &'a [u32],
    stride: u32,
    width: u32,
    height: u32,
}

/// Words per row of a `width`-pixel mask.
fn stride(width: u32) -> u32 {
    width.div_ceil(32)
}

impl<const WORDS: usize> OcclusionMask<WORDS> {
    /// An empty mask (no pixel labelled) of no size; [`Self::reset`] sizes it.
    pub const fn new() -> Self {
        Self { bits: [0; WORDS], width: 0, height: 0 }
    }

    /// Clears every label and sizes the mask for a `width × height` image (`BadConfig` beyond its capacity).
    pub fn reset(&mut self, width: u32, height: u32) -> Result<(), FitError> {
        let words = (stride(width) as usize).checked_mul(height as usize).ok_or(FitError::BadConfig)?;
        if words > WORDS {
            return Err(FitError::BadConfig);
        }
        self.bits.iter_mut().take(words).for_each(|w| *w = 0);
        self.width = width;
        self.height = height;
        Ok(())
    }

    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Whether pixel `(x, y)` is labelled occluded (`false` outside).
    pub fn get(&self, x: u32, y: u32) -> bool {
        self.view().get(x, y)
    }

    /// Labels pixel `(x, y)` (ignored outside).
    pub fn set(&mut self, x: u32, y: u32, occluded: bool) {
        if x >= self.width || y >= self.height {
            return;
        }
        let i = (y * stride(self.width) + x / 32) as usize;
        if let Some(w) = self.bits.get_mut(i) {
            let bit = 1u32 << (x % 32);
            if occluded {
                *w |= bit;
            } else {
                *w &= !bit;
            }
        }
    }

    /// The labels without the capacity.
    pub fn view(&self) -> MaskView<'_> {
        let used = (stride(self.width) * self.height) as usize;
        MaskView { bits: self.bits.get(..used).unwrap_or(&[]), stride: stride(self.width), width: self.width, height: self.height }
    }

    /// Pixels labelled occluded.
    pub fn count(&self) -> u32 {
        self.view().bits.iter().map(|w| w.count_ones()).sum()
    }

    /// `passes` 3 × 3 majority passes: a pixel is labelled occluded where at least 5 of the 9
    /// pixels around it (itself included; outside the image counts as not occluded) are.
    pub fn smooth(&mut self, passes: u32) {
        let (w, h) = (self.width, self.height);
        let s = stride(w) as usize;
        const ROW: usize = 32;
        if s > ROW {
            return;
        }
        for _ in 0..passes {
            // The rows above and at `y` as they were before this pass.
            let (mut above, mut here) = ([0u32; ROW], [0u32; ROW]);
            if let (Some(d), Some(r)) = (here.get_mut(..s), self.bits.get(..s)) {
                d.copy_from_slice(r);
            }
            for y in 0..h {
                let below_start = (y as usize + 1) * s;
                let mut below = [0u32; ROW];
                if y + 1 < h {
                    if let (Some(d), Some(r)) = (below.get_mut(..s), self.bits.get(below_start..below_start + s)) {
                        d.copy_from_slice(r);
                    }
                }
                let bit = |row: &[u32; ROW], x: i64| -> u32 {
                    if x < 0 || x >= i64::from(w) {
                        return 0;
                    }
                    row.get(x as usize / 32).map_or(0, |v| (v >> (x as usize % 32)) & 1)
                };
                for x in 0..i64::from(w) {
                    let mut n = 0;
                    for row in [&above, &here, &below] {
                        n += bit(row, x - 1) + bit(row, x) + bit(row, x + 1);
                    }
                    self.set(x as u32, y, n >= 5);
                }
                above = here;
                here = below;
            }
        }
    }
}

impl<const WORDS: usize> Default for OcclusionMask<WORDS> {
    fn default() -> Self {
        Self::new()
    }
}

impl MaskView<'_> {
    /// Whether pixel `(x, y)` is labelled occluded (`false` outside).
    #[inline(always)]
    pub fn get(&self, x: u32, y: u32) -> bool {
        if x >= self.width || y >= self.height {
            return false;
        }
        self.bits.get((y * self.stride + x / 32) as usize).is_some_and(|w| (w >> (x % 32)) & 1 == 1)
    }

    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    #[test]
    fn labels_are_bits_in_rows_and_the_capacity_is_checked() {
        let mut m = OcclusionMask::<4>::new();
        assert_eq!(m.reset(40, 3).err(), Some(FitError::BadConfig));
        m.reset(33, 2).unwrap();
        m.set(32, 1, true);
        m.set(0, 0, true);
        m.set(33, 0, true); // outside: ignored
        assert!(m.get(32, 1) && m.get(0, 0) && !m.get(1, 0) && !m.get(33, 0));
        assert_eq!(m.count(), 2);
        m.set(0, 0, false);
        assert_eq!(m.count(), 1);
        assert!(m.view().get(32, 1));
    }

    #[test]
    fn majority_passes_remove_specks_and_fill_holes() {
        let mut m = OcclusionMask::<{ 40 * 2 }>::new();
        m.reset(40, 40).unwrap();
        // A 10 × 10 block with a hole, and a lone speck.
        for y in 10..20 {
            for x in 20..30 {
                m.set(x, y, !(x == 25 && y == 15));
            }
        }
        m.set(3, 3, true);
        m.smooth(1);
        assert!(!m.get(3, 3), "the speck stays");
        assert!(m.get(25, 15), "the hole stays");
        // The block's corners go, its edges stay.
        assert!(!m.get(20, 10) && m.get(25, 10) && m.get(20, 15));
        assert_eq!(m.count(), 100 - 4);
    }
}
