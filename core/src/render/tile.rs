//! A finished image tile handed to a [`TileSink`]: colour, depth, triangle id and barycentrics.

use crate::geometry::Vec3;

/// Triangle id of a pixel no triangle covers.
pub const NO_TRIANGLE: u32 = u32::MAX;

/// One covered pixel of a tile.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fragment {
    /// Perspective-correct interpolated vertex colour (linear RGB).
    pub color: Vec3,
    /// Interpolated `1 / w` (1/mm); larger is closer.
    pub inv_w: f32,
    /// Index of the triangle in the triangle list.
    pub triangle: u32,
    /// Perspective-correct barycentric weights of the triangle's vertices, in the list's order.
    pub bary: [f32; 3],
}

/// A `TW × TH` tile of the frame: buffers in tile-local coordinates `[y][x]`.
///
/// Only the top-left `size()` part is valid (tiles at the right/bottom border may be smaller).
/// Uncovered pixels have depth 0 and triangle [`NO_TRIANGLE`] (their colours and barycentrics
/// are left from earlier tiles: read them only where a triangle covers).
#[derive(Debug, Clone)]
pub struct Tile<const TW: usize, const TH: usize> {
    pub(crate) x0: u32,
    pub(crate) y0: u32,
    pub(crate) width: u32,
    pub(crate) height: u32,
    pub(crate) color: [[Vec3; TW]; TH],
    pub(crate) inv_w: [[f32; TW]; TH],
    pub(crate) tri: [[u32; TW]; TH],
    pub(crate) bary: [[[f32; 2]; TW]; TH],
}

impl<const TW: usize, const TH: usize> Tile<TW, TH> {
    /// An empty tile at the origin with zero size.
    pub const fn new() -> Self {
        Self {
            x0: 0,
            y0: 0,
            width: 0,
            height: 0,
            color: [[[0.0; 3]; TW]; TH],
            inv_w: [[0.0; TW]; TH],
            tri: [[NO_TRIANGLE; TW]; TH],
            bary: [[[0.0; 2]; TW]; TH],
        }
    }

    /// Image coordinates `(x, y)` of the tile's top-left pixel.
    pub fn origin(&self) -> (u32, u32) {
        (self.x0, self.y0)
    }

    /// Valid `(width, height)` of this tile (at most `(TW, TH)`).
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// The fragment at tile-local `(x, y)`; `None` outside the valid size or if not covered.
    pub fn fragment(&self, x: usize, y: usize) -> Option<Fragment> {
        if x >= self.width as usize || y >= self.height as usize {
            return None;
        }
        let triangle = *self.tri.get(y)?.get(x)?;
        if triangle == NO_TRIANGLE {
            return None;
        }
        let [b1, b2] = *self.bary.get(y)?.get(x)?;
        Some(Fragment { color: *self.color.get(y)?.get(x)?, inv_w: *self.inv_w.get(y)?.get(x)?, triangle, bary: [1.0 - b1 - b2, b1, b2] })
    }

    /// Whether tile-local `(x, y)` is inside the valid size and covered by a triangle.
    pub fn is_covered(&self, x: usize, y: usize) -> bool {
        x < self.width as usize && y < self.height as usize && self.tri.get(y).and_then(|r| r.get(x)).is_some_and(|&t| t != NO_TRIANGLE)
    }

    /// Colour buffer `[y][x]` (valid only where covered: see [`Tile::triangles`]).
    pub fn colors(&self) -> &[[Vec3; TW]; TH] {
        &self.color
    }

    /// Reciprocal-depth buffer `[y][x]` (`1 / w`, 0 where uncovered).
    pub fn depths(&self) -> &[[f32; TW]; TH] {
        &self.inv_w
    }

    /// Triangle-id buffer `[y][x]` ([`NO_TRIANGLE`] where uncovered): the coverage mask.
    pub fn triangles(&self) -> &[[u32; TW]; TH] {
        &self.tri
    }

    /// Perspective-correct barycentrics `[y][x]` of the triangle's 2nd and 3rd vertex (the 1st is
    /// `1 − b1 − b2`); meaningful only where [`Tile::triangles`] is not [`NO_TRIANGLE`].
    pub fn barycentrics(&self) -> &[[[f32; 2]; TW]; TH] {
        &self.bary
    }

    /// Resets the buffers and places the tile at `(x0, y0)` with the given valid size.
    pub(crate) fn reset(&mut self, x0: u32, y0: u32, width: u32, height: u32) {
        self.x0 = x0;
        self.y0 = y0;
        self.width = width;
        self.height = height;
        for row in self.inv_w.iter_mut() {
            row.fill(0.0);
        }
        for row in self.tri.iter_mut() {
            row.fill(NO_TRIANGLE);
        }
        // Colours and barycentrics are read only where a triangle covers (written there): not cleared.
    }
}

impl<const TW: usize, const TH: usize> Default for Tile<TW, TH> {
    fn default() -> Self {
        Self::new()
    }
}

/// Consumer of finished tiles (likelihood accumulation, copying into an image, checksums, …).
///
/// # Examples
///
/// A sink of one's own that copies the covered pixels into an RGB8 frame (a display's buffer):
///
/// ```
/// use gpmm_core::checksum::quantize_rgb;
/// use gpmm_core::render::{Cull, ProjectedVertex, Tile, TileRasterizer, TileSink};
///
/// struct Frame {
///     width: usize,
///     pixels: Vec<[u8; 3]>,
/// }
///
/// impl<const TW: usize, const TH: usize> TileSink<TW, TH> for Frame {
///     fn consume(&mut self, tile: &Tile<TW, TH>) {
///         let (x0, y0) = tile.origin();
///         let (w, h) = tile.size();
///         for (x, y) in (0..h as usize).flat_map(|y| (0..w as usize).map(move |x| (x, y))) {
///             if let Some(f) = tile.fragment(x, y) {
///                 self.pixels[(y0 as usize + y) * self.width + x0 as usize + x] = quantize_rgb(f.color);
///             }
///         }
///     }
/// }
///
/// // An orange triangle over the upper-left half of an 8 × 8 frame, drawn in 4 × 4 tiles.
/// let vertex = |x, y| ProjectedVertex { x, y, inv_w: 0.01, color: [1.0, 0.6, 0.2] };
/// let vertices = [vertex(0.0, 0.0), vertex(8.5, 0.0), vertex(0.0, 8.5)];
/// let mut frame = Frame { width: 8, pixels: vec![[0; 3]; 64] };
/// TileRasterizer::<4, 4, 16>::new().render(&vertices, &[[0u32, 1, 2]], 8, 8, Cull::None, &mut frame)?;
///
/// assert_eq!(frame.pixels[0], [255, 153, 51]); // the top-left pixel is inside
/// assert_eq!(frame.pixels[63], [0, 0, 0]); // the bottom-right one is not
/// assert_eq!(frame.pixels.iter().filter(|p| **p != [0; 3]).count(), 36);
/// # Ok::<(), gpmm_core::render::RasterError>(())
/// ```
pub trait TileSink<const TW: usize, const TH: usize> {
    /// Called once per tile per frame, in row-major tile order, with the finished tile.
    fn consume(&mut self, tile: &Tile<TW, TH>);
}

impl<const TW: usize, const TH: usize, F: FnMut(&Tile<TW, TH>)> TileSink<TW, TH> for F {
    fn consume(&mut self, tile: &Tile<TW, TH>) {
        self(tile)
    }
}
