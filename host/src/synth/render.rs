//! The frame sink that turns the core's tiles into an RGB image and a depth buffer.

use super::*;

/// Collects finished tiles into full-image colour (None = uncovered) and depth buffers.
pub(super) struct FrameSink {
    width: u32,
    height: u32,
    /// Per pixel, row-major: the colour of the covered pixels.
    pub(super) color: Vec<Option<Vec3>>,
    inv_w: Vec<f32>,
}

impl FrameSink {
    pub(super) fn new(width: u32, height: u32) -> Self {
        let n = width as usize * height as usize;
        Self { width, height, color: vec![None; n], inv_w: vec![0.0; n] }
    }

    /// Whether a point at pixel position (x, y) and depth `w` (mm) is not hidden: some covered pixel of the
    /// 3×3 neighbourhood shows a surface no more than `tol` mm in front of it.
    pub(super) fn visible(&self, x: f32, y: f32, w: f32, tol: f32) -> bool {
        if !(x >= 0.0 && y >= 0.0 && x < self.width as f32 && y < self.height as f32) {
            return false;
        }
        let (xi, yi) = (x.floor() as i64, y.floor() as i64);
        for dy in -1..=1 {
            for dx in -1..=1 {
                let (px, py) = (xi + dx, yi + dy);
                if px < 0 || py < 0 || px >= i64::from(self.width) || py >= i64::from(self.height) {
                    continue;
                }
                let inv = self.inv_w[py as usize * self.width as usize + px as usize];
                if inv > 0.0 && 1.0 / inv >= w - tol {
                    return true;
                }
            }
        }
        false
    }
}

impl TileSink<TILE, TILE> for FrameSink {
    fn consume(&mut self, tile: &Tile<TILE, TILE>) {
        let (x0, y0) = tile.origin();
        let (w, h) = tile.size();
        for ly in 0..h as usize {
            for lx in 0..w as usize {
                let (x, y) = (x0 as usize + lx, y0 as usize + ly);
                if x >= self.width as usize || y >= self.height as usize {
                    continue;
                }
                if let Some(f) = tile.fragment(lx, ly) {
                    let i = y * self.width as usize + x;
                    self.color[i] = Some(f.color);
                    self.inv_w[i] = f.inv_w;
                }
            }
        }
    }
}
