//! Frame checksums (a [`TileSink`]) and CRC-32, identical on the host and on the device.
//!
//! [`FrameChecksum`] folds every covered pixel of a frame into a 32-bit checksum that the host
//! and the firmware compare. Each covered pixel contributes a 64-bit hash of its position and its
//! colour quantized to 8 bits per channel ([`quantize`]); the contributions are added (wrapping),
//! so the result does **not** depend on the order the tiles arrive in, nor on the tile size: a
//! host renderer with 64×64 tiles and the firmware with 16×16 tiles agree on the same frame.
//! Uncovered pixels contribute nothing; [`FrameChecksum::covered`] counts the covered ones and
//! [`FrameChecksum::color_sum`] sums the quantized channels (for diagnosing a mismatch).
//!
//! Why quantize: colours are `f32`. The core's arithmetic is IEEE single precision with no fused
//! multiply-add (Rust never contracts `a * b + c`), and `libm` is the same code on both sides, so
//! host and Cortex-M4F compute the same bits in practice. If a platform ever differed in the last
//! bit of a colour, rounding to `u8` hides it except when the value sits on a rounding boundary:
//! a rare ±1 in one channel of one pixel. That is the only source of tolerance this checksum
//! would need (compare [`FrameChecksum::covered`] and [`FrameChecksum::color_sum`] then).
//!
//! [`crc32`] is the standard CRC-32 (IEEE 802.3, reflected, polynomial `0xEDB88320`; the same as
//! zlib's and `crc32fast`'s), table-driven with a table computed at compile time (1 KiB of flash).

use crate::geometry::Vec3;
use crate::render::tile::{Tile, TileSink};

/// A colour channel in [0, 1] rounded to `0..=255` (clamped; NaN gives 0).
pub fn quantize(c: f32) -> u8 {
    // `clamp` keeps NaN as NaN (its bounds are constants, so it cannot panic); `as` maps NaN to 0.
    (c.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

/// An RGB colour quantized with [`quantize`].
pub fn quantize_rgb(c: Vec3) -> [u8; 3] {
    [quantize(c[0]), quantize(c[1]), quantize(c[2])]
}

/// splitmix64's finalizer: a bijective 64-bit mix.
fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The hash one covered pixel at image `(x, y)` with quantized colour `rgb` adds to the checksum.
pub fn pixel_hash(x: u32, y: u32, rgb: [u8; 3]) -> u64 {
    // x and y are below 2^15 (the rasterizer's largest image), so the packing is injective.
    let packed = u64::from(x & 0xffff)
        | (u64::from(y & 0xffff) << 16)
        | (u64::from(rgb[0]) << 32)
        | (u64::from(rgb[1]) << 40)
        | (u64::from(rgb[2]) << 48);
    mix64(packed ^ 0x6770_6d6d_0000_0000)
}

/// Order-independent checksum of a frame's covered pixels (position + colour quantized to `u8`).
///
/// # Examples
///
/// The same frame rendered in 4 × 4 tiles (as a small device would) and in one 8 × 8 tile gives
/// the same checksum; another colour gives another:
///
/// ```
/// use gpmm_core::checksum::FrameChecksum;
/// use gpmm_core::render::{Cull, ProjectedVertex, RasterError, TileRasterizer};
///
/// let triangle = |color| {
///     let vertex = |x, y| ProjectedVertex { x, y, inv_w: 0.01, color };
///     [vertex(0.0, 0.0), vertex(8.5, 0.0), vertex(0.0, 8.5)]
/// };
/// let (orange, blue) = (triangle([1.0, 0.6, 0.2]), triangle([0.2, 0.4, 1.0]));
/// let (mut small, mut large, mut other) = (FrameChecksum::new(), FrameChecksum::new(), FrameChecksum::new());
/// TileRasterizer::<4, 4, 16>::new().render(&orange, &[[0u32, 1, 2]], 8, 8, Cull::None, &mut small)?;
/// TileRasterizer::<8, 8, 16>::new().render(&orange, &[[0u32, 1, 2]], 8, 8, Cull::None, &mut large)?;
/// TileRasterizer::<8, 8, 16>::new().render(&blue, &[[0u32, 1, 2]], 8, 8, Cull::None, &mut other)?;
///
/// assert_eq!(small.value(), large.value());
/// assert_eq!((small.covered, small.color_sum), (36, [36 * 255, 36 * 153, 36 * 51]));
/// assert_ne!(small.value(), other.value());
/// # Ok::<(), RasterError>(())
/// ```
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FrameChecksum {
    /// Wrapping sum of [`pixel_hash`] over the covered pixels.
    pub sum: u64,
    /// Covered pixels.
    pub covered: u32,
    /// Sum of the quantized red, green and blue values over the covered pixels.
    pub color_sum: [u64; 3],
}

impl FrameChecksum {
    /// An empty checksum (no pixel yet).
    pub const fn new() -> Self {
        Self { sum: 0, covered: 0, color_sum: [0; 3] }
    }

    /// Adds one covered pixel.
    pub fn add_pixel(&mut self, x: u32, y: u32, color: Vec3) {
        let rgb = quantize_rgb(color);
        self.sum = self.sum.wrapping_add(pixel_hash(x, y, rgb));
        self.covered = self.covered.wrapping_add(1);
        for (s, c) in self.color_sum.iter_mut().zip(rgb) {
            *s = s.wrapping_add(u64::from(c));
        }
    }

    /// The 32-bit checksum that is logged and compared: the two halves of [`Self::sum`] xor-ed.
    pub fn value(&self) -> u32 {
        (self.sum ^ (self.sum >> 32)) as u32
    }
}

impl<const TW: usize, const TH: usize> TileSink<TW, TH> for FrameChecksum {
    fn consume(&mut self, tile: &Tile<TW, TH>) {
        let (x0, y0) = tile.origin();
        let (w, h) = tile.size();
        for ((ly, crow), trow) in (0u32..h).zip(tile.colors()).zip(tile.triangles()) {
            for ((lx, c), t) in (0u32..w).zip(crow).zip(trow) {
                if *t != crate::render::tile::NO_TRIANGLE {
                    self.add_pixel(x0.wrapping_add(lx), y0.wrapping_add(ly), *c);
                }
            }
        }
    }
}

/// The CRC-32 lookup table (reflected polynomial `0xEDB88320`), computed at compile time.
// Indexing in a const initializer: evaluated by the compiler, an out-of-range index would be a
// compile error, never a run-time panic.
#[allow(clippy::indexing_slicing)]
const CRC_TABLE: [u32; 256] = {
    let mut table = [0u32; 256];
    let mut i = 0;
    while i < 256 {
        let mut c = i as u32;
        let mut k = 0;
        while k < 8 {
            c = if c & 1 != 0 { 0xedb8_8320 ^ (c >> 1) } else { c >> 1 };
            k += 1;
        }
        table[i] = c;
        i += 1;
    }
    table
};

/// Continues a CRC-32 over `bytes` from a previous [`crc32`] value (start from 0).
pub fn crc32_update(crc: u32, bytes: &[u8]) -> u32 {
    let mut c = !crc;
    for &b in bytes {
        let t = CRC_TABLE.get(usize::from((c as u8) ^ b)).copied().unwrap_or(0);
        c = t ^ (c >> 8);
    }
    !c
}

/// The standard CRC-32 (zlib, PNG, `crc32fast`) of `bytes`.
///
/// # Examples
///
/// ```
/// use gpmm_core::checksum::{crc32, crc32_update};
///
/// // The standard check value of CRC-32 (IEEE 802.3).
/// assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
/// // Over data that arrives in pieces: continue from the previous value.
/// assert_eq!(crc32_update(crc32(b"1234"), b"56789"), crc32(b"123456789"));
/// assert_eq!(crc32(b""), 0);
/// ```
pub fn crc32(bytes: &[u8]) -> u32 {
    crc32_update(0, bytes)
}

#[cfg(test)]
#[allow(clippy::indexing_slicing, clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::render::{Cull, ProjectedVertex, TileRasterizer};

    #[test]
    fn crc32_check_value() {
        assert_eq!(crc32(b"123456789"), 0xcbf4_3926);
        assert_eq!(crc32(b""), 0);
        assert_eq!(crc32_update(crc32(b"1234"), b"56789"), 0xcbf4_3926);
    }

    #[test]
    fn quantize_rounds_and_clamps() {
        assert_eq!(quantize(0.0), 0);
        assert_eq!(quantize(1.0), 255);
        assert_eq!(quantize(-3.0), 0);
        assert_eq!(quantize(7.0), 255);
        assert_eq!(quantize(f32::NAN), 0);
        assert_eq!(quantize(f32::INFINITY), 255);
        assert_eq!(quantize(0.5), 128);
        assert_eq!(quantize(1.4 / 255.0), 1);
        assert_eq!(quantize(1.6 / 255.0), 2);
    }

    #[test]
    fn pixel_order_does_not_matter_but_content_does() {
        let px = [(3, 4, [0.1, 0.2, 0.3]), (100, 7, [0.9, 0.0, 1.0]), (0, 0, [0.5, 0.5, 0.5])];
        let mut a = FrameChecksum::new();
        for &(x, y, c) in &px {
            a.add_pixel(x, y, c);
        }
        let mut b = FrameChecksum::new();
        for &(x, y, c) in px.iter().rev() {
            b.add_pixel(x, y, c);
        }
        assert_eq!(a, b);
        assert_eq!(a.covered, 3);
        assert_eq!(a.color_sum, [26 + 230 + 128, 51 + 128, 77 + 255 + 128]);
        let mut c = FrameChecksum::new();
        c.add_pixel(3, 4, [0.1, 0.2, 0.3]);
        c.add_pixel(100, 7, [0.9, 0.0, 1.0]);
        c.add_pixel(0, 0, [0.5, 0.5, 130.0 / 255.0]);
        assert_ne!(a.value(), c.value());
        // Swapped coordinates are different pixels.
        let (mut d, mut e) = (FrameChecksum::new(), FrameChecksum::new());
        d.add_pixel(1, 2, [0.0; 3]);
        e.add_pixel(2, 1, [0.0; 3]);
        assert_ne!(d.value(), e.value());
    }

    /// The same frame gives the same checksum whatever the tile size or bin capacity.
    #[test]
    fn independent_of_tiling() {
        let c = |r: f32, g: f32| [r, g, 0.25];
        let v = [
            ProjectedVertex { x: 3.2, y: 4.1, inv_w: 0.01, color: c(1.0, 0.0) },
            ProjectedVertex { x: 40.7, y: 60.3, inv_w: 0.02, color: c(0.0, 1.0) },
            ProjectedVertex { x: 70.1, y: 2.9, inv_w: 0.015, color: c(0.3, 0.6) },
            ProjectedVertex { x: 10.0, y: 70.0, inv_w: 0.01, color: c(0.8, 0.8) },
        ];
        let tris: [[u16; 3]; 2] = [[0, 1, 2], [0, 3, 1]];
        let mut a = FrameChecksum::new();
        let sa = TileRasterizer::<16, 16, 8>::new().render(&v, &tris, 72, 72, Cull::None, &mut a).unwrap();
        let mut b = FrameChecksum::new();
        TileRasterizer::<7, 5, 0>::new().render(&v, &tris, 72, 72, Cull::None, &mut b).unwrap();
        let mut d = FrameChecksum::new();
        TileRasterizer::<64, 64, 1>::new().render(&v, &tris, 72, 72, Cull::None, &mut d).unwrap();
        assert!(a.covered > 1000);
        assert_eq!(a.covered, sa.covered_pixels);
        assert_eq!(a, b);
        assert_eq!(a, d);
    }
}
