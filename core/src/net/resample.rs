//! Network inputs cut from an RGB frame: the whole frame letterboxed into the finder's square, or
//! a square around a face resampled to the initializer's crop, as `i8` (`pixel − 128`).
//!
//! Each output pixel averages `n × n` bilinear samples of its footprint (`n = ceil(step)`, at most
//! 4), so a large downscale does not alias. Positions are `f32`, the interpolation is integer:
//! the host and the device give the same bytes. Samples outside the frame are mid-grey (0).

use super::NetError;

/// Where an output grid lies in the source frame: output pixel `(u, v)` covers the source square
/// `[x0 + u·step, x0 + (u+1)·step) × [y0 + v·step, y0 + (v+1)·step)` (pixel units, origin at the
/// frame's top-left corner).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Window {
    /// Left edge of output column 0 in the source (px).
    pub x0: f32,
    /// Top edge of output row 0 in the source (px).
    pub y0: f32,
    /// Source pixels per output pixel.
    pub step: f32,
}

impl Window {
    /// The whole `w × h` frame centred in a `side × side` square (the longer side fills it).
    pub fn letterbox(w: usize, h: usize, side: usize) -> Self {
        let step = w.max(h) as f32 / side.max(1) as f32;
        let span = side as f32 * step;
        Self { x0: (w as f32 - span) * 0.5, y0: (h as f32 - span) * 0.5, step }
    }

    /// A square of side `size` source pixels centred on `(cx, cy)`, sampled into `side` pixels.
    pub fn square(cx: f32, cy: f32, size: f32, side: usize) -> Self {
        Self { x0: cx - size * 0.5, y0: cy - size * 0.5, step: size / side.max(1) as f32 }
    }

    /// The source position (px) of output position `(u, v)` (output pixel units, corners at integers).
    pub fn to_source(&self, u: f32, v: f32) -> (f32, f32) {
        (self.x0 + u * self.step, self.y0 + v * self.step)
    }

    /// The output position of source position `(x, y)`.
    pub fn from_source(&self, x: f32, y: f32) -> (f32, f32) {
        ((x - self.x0) / self.step, (y - self.y0) / self.step)
    }
}

/// Fixed-point fraction bits of the bilinear weights.
const FRAC: u32 = 8;

/// Flips channel-last `side`-wide RGB rows (a network input) left-right in place.
pub fn flip_rows(pixels: &mut [i8], side: usize) {
    if side == 0 {
        return;
    }
    for row in pixels.chunks_exact_mut(side * 3) {
        let (left, right) = row.split_at_mut(side / 2 * 3);
        for (a, b) in left.chunks_exact_mut(3).zip(right.chunks_exact_mut(3).rev()) {
            a.swap_with_slice(b);
        }
    }
}

/// Samples `src` (RGB, `w × h`, row-major) into `out` (`side × side × 3`, `i8`) through `window`.
pub fn sample_rgb(src: &[u8], w: usize, h: usize, window: Window, side: usize, out: &mut [i8]) -> Result<(), NetError> {
    if out.len() != side * side * 3 {
        return Err(NetError::LengthMismatch);
    }
    sample(src, w, h, window, side, out.chunks_exact_mut(3), |o, v| *o = (v - 128) as i8)
}

/// Samples `src` (RGB, `w × h`, row-major) into `out` (`side × side` RGB8 pixels) through `window`:
/// the same samples as [`sample_rgb`], stored as bytes (the fit's working image, `net::crop`).
pub fn sample_rgb8(src: &[u8], w: usize, h: usize, window: Window, side: usize, out: &mut [[u8; 3]]) -> Result<(), NetError> {
    if out.len() != side * side {
        return Err(NetError::LengthMismatch);
    }
    sample(src, w, h, window, side, out.iter_mut().map(|p| &mut p[..]), |o, v| *o = v as u8)
}

/// The one sampler: each output pixel's three channel values (0..=255) go to `store`.
#[inline(always)]
fn sample<'o, T: 'o>(
    src: &[u8],
    w: usize,
    h: usize,
    window: Window,
    side: usize,
    out: impl Iterator<Item = &'o mut [T]>,
    store: impl Fn(&mut T, i32),
) -> Result<(), NetError> {
    if w == 0 || h == 0 || w.checked_mul(h).and_then(|n| n.checked_mul(3)) != Some(src.len()) {
        return Err(NetError::BadImage);
    }
    if !(window.x0.is_finite() && window.y0.is_finite() && window.step.is_finite() && window.step > 0.0) {
        return Err(NetError::BadImage);
    }
    let n = (libm::ceilf(window.step) as usize).clamp(1, 4);
    let one = 1i32 << FRAC;
    let texel = |x: i32, y: i32| -> [i32; 3] {
        if x < 0 || y < 0 || x as usize >= w || y as usize >= h {
            return [128; 3];
        }
        let i = (y as usize * w + x as usize) * 3;
        match src.get(i..i + 3) {
            Some(&[r, g, b]) => [i32::from(r), i32::from(g), i32::from(b)],
            _ => [128; 3],
        }
    };
    for (p, px) in out.enumerate() {
        let (u, v) = ((p % side) as f32, (p / side) as f32);
        let mut sum = [0i32; 3];
        for j in 0..n {
            for i in 0..n {
                // Sample centre in the source, in pixel-centre coordinates (pixel k's centre is k).
                let (sx, sy) = window.to_source(u + (i as f32 + 0.5) / n as f32, v + (j as f32 + 0.5) / n as f32);
                let fx = libm::floorf((sx - 0.5) * one as f32);
                let fy = libm::floorf((sy - 0.5) * one as f32);
                // Far outside the frame: grey without interpolating (also keeps the casts in range).
                if !(fx.abs() < 1.0e9 && fy.abs() < 1.0e9) {
                    sum.iter_mut().for_each(|s| *s += 128 * one * one);
                    continue;
                }
                let (fx, fy) = (fx as i32, fy as i32);
                let (x, y) = (fx >> FRAC, fy >> FRAC);
                let (ax, ay) = (fx & (one - 1), fy & (one - 1));
                let (t00, t10, t01, t11) = (texel(x, y), texel(x + 1, y), texel(x, y + 1), texel(x + 1, y + 1));
                for (c, s) in sum.iter_mut().enumerate() {
                    let at = |t: [i32; 3]| t.get(c).copied().unwrap_or(128);
                    let top = at(t00) * (one - ax) + at(t10) * ax;
                    let bottom = at(t01) * (one - ax) + at(t11) * ax;
                    *s += top * (one - ay) + bottom * ay;
                }
            }
        }
        let count = (n * n) as i32 * one * one;
        for (o, s) in px.iter_mut().zip(sum) {
            let value = (s + count / 2) / count;
            store(o, value.clamp(0, 255));
        }
    }
    Ok(())
}
