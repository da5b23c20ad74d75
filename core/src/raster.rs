//! Tile-based, fixed-memory triangle rasterizer.
//!
//! Per frame, the image (any size up to [`MAX_IMAGE_SIZE`]) is walked in rows of `TH`-pixel tiles.
//! For each tile row, one scan over the triangle list collects the triangles whose bounding box
//! meets the row into a fixed-capacity bin of `BIN` entries; each `TW × TH` tile of the row then
//! rasterizes the binned triangles that overlap it into the tile buffers, and the finished tile is
//! handed to a [`TileSink`]. If a row's bin overflows, every tile of that row falls back to
//! scanning the whole triangle list (slower, never lossy; counted in [`FrameStats::overflow_rows`]).
//! `BIN = 0` always takes that path ("iterate over all triangles per tile"). Memory is the tile
//! buffers plus the bin: nothing scales with the image or the mesh.
//!
//! Rasterization:
//! - Vertices snap to fixed point with [`SUBPIXEL_BITS`] fractional bits; edge functions are exact
//!   `i64`; a pixel is covered if its centre `(i + 0.5, j + 0.5)` is strictly inside, or on an edge
//!   that is a *top* or *left* edge (Direct3D rule). Triangles sharing an edge therefore never both
//!   cover, nor both miss, a pixel centre on it: the result is watertight.
//! - Winding: a triangle is counter-clockwise if its vertices go counter-clockwise as the image is
//!   viewed (y up on screen). The model's triangles are counter-clockwise seen from outside, so the
//!   default [`Cull::Clockwise`] removes back faces. Zero-area triangles (after snapping) are skipped.
//! - Depth test on the interpolated `1 / w` (linear in screen space; larger is closer; ties keep the
//!   earlier triangle). Colours and the stored barycentrics are perspective-correct.
//! - Triangles crossing the image border are clipped by the tile bounds. Triangles with a vertex in
//!   front of the near plane (`inv_w == 0`, see [`ProjectedVertex`]), a non-finite value, or a vertex
//!   outside the guard band `|x|, |y| > `[`GUARD_BAND`] px are **rejected whole** (not clipped) and
//!   counted in [`FrameStats`]; for a face in front of the camera this happens only when the camera
//!   is inside or right next to the mesh.

use crate::shading::{ProjectedVertex, TriIndex};
use crate::tile::{Tile, TileSink, NO_TRIANGLE};
use crate::Vec3;

/// Fractional bits of the fixed-point vertex coordinates (1/256 pixel).
pub const SUBPIXEL_BITS: u32 = 8;
const ONE: i64 = 1 << SUBPIXEL_BITS;
const HALF: i64 = ONE / 2;
/// Vertices farther than this from the image origin (in pixels) reject their triangle (keeps `i64` exact).
pub const GUARD_BAND: f32 = 2_097_152.0;
/// Largest accepted image width or height in pixels.
pub const MAX_IMAGE_SIZE: u32 = 1 << 15;

/// Which on-screen winding to discard.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cull {
    /// Draw both windings.
    None,
    /// Discard clockwise triangles (back faces of a counter-clockwise-outward mesh); the default.
    Clockwise,
    /// Discard counter-clockwise triangles.
    CounterClockwise,
}

/// Why a frame was refused (before any tile is handed to the sink).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RasterError {
    /// A triangle refers to a vertex index `>=` the number of vertices.
    IndexOutOfRange,
    /// Width or height exceeds [`MAX_IMAGE_SIZE`].
    ImageTooLarge,
    /// More than `u32::MAX - 1` triangles.
    TooManyTriangles,
    /// `TW` or `TH` is zero.
    ZeroTileSize,
}

/// What happened to the triangles of one frame (each triangle counted once).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FrameStats {
    /// Triangles in the list.
    pub triangles: u32,
    /// Triangles that passed every test and may cover pixel centres.
    pub drawn: u32,
    /// Discarded by the winding test.
    pub culled: u32,
    /// Zero area after snapping to fixed point.
    pub degenerate: u32,
    /// A vertex in front of the near plane or with a non-finite value.
    pub near_or_invalid: u32,
    /// A vertex outside the guard band.
    pub guard_band: u32,
    /// Bounding box contains no pixel centre of the image.
    pub off_screen: u32,
    /// Tile rows whose bin overflowed (those tiles scanned the whole list).
    pub overflow_rows: u32,
    /// Tiles handed to the sink.
    pub tiles: u32,
    /// Covered pixels in the frame.
    pub covered_pixels: u32,
}

#[derive(Debug, Clone, Copy)]
struct BinEntry {
    tri: u32,
    x0: u16,
    x1: u16,
}

impl BinEntry {
    const EMPTY: Self = Self { tri: 0, x0: 0, x1: 0 };
}

/// Fixed-point triangle, oriented to positive area, with its pixel bounding box in the image.
struct Setup {
    p: [[i64; 2]; 3],
    inv_w: [f32; 3],
    color: [Vec3; 3],
    swapped: bool,
    area: i64,
    /// Inclusive pixel bounds `x0, x1, y0, y1`, clamped to the image.
    bbox: [i64; 4],
}

enum Reject {
    Invalid,
    Guard,
    Culled,
    Degenerate,
    OffScreen,
}

fn fetch<'a, I: TriIndex>(vertices: &'a [ProjectedVertex], tri: &[I; 3]) -> Option<[&'a ProjectedVertex; 3]> {
    let [a, b, c] = *tri;
    Some([vertices.get(a.index())?, vertices.get(b.index())?, vertices.get(c.index())?])
}

fn setup(v: [&ProjectedVertex; 3], cull: Cull, width: u32, height: u32) -> Result<Setup, Reject> {
    let mut p = [[0i64; 2]; 3];
    for (pi, vi) in p.iter_mut().zip(v) {
        let finite = vi.x.is_finite() && vi.y.is_finite() && vi.inv_w.is_finite() && vi.color.iter().all(|c| c.is_finite());
        if !finite || vi.inv_w <= 0.0 {
            return Err(Reject::Invalid);
        }
        if vi.x.abs() > GUARD_BAND || vi.y.abs() > GUARD_BAND {
            return Err(Reject::Guard);
        }
        *pi = [libm::roundf(vi.x * ONE as f32) as i64, libm::roundf(vi.y * ONE as f32) as i64];
    }
    let [[x0, y0], [x1, y1], [x2, y2]] = p;
    let area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0);
    if area == 0 {
        return Err(Reject::Degenerate);
    }
    // y points down: area < 0 is counter-clockwise as the image is viewed.
    let ccw = area < 0;
    match cull {
        Cull::Clockwise if !ccw => return Err(Reject::Culled),
        Cull::CounterClockwise if ccw => return Err(Reject::Culled),
        _ => {}
    }
    let [va, vb, vc] = v;
    let (p, inv_w, color, area) = if ccw {
        ([p[0], p[2], p[1]], [va.inv_w, vc.inv_w, vb.inv_w], [va.color, vc.color, vb.color], -area)
    } else {
        (p, [va.inv_w, vb.inv_w, vc.inv_w], [va.color, vb.color, vc.color], area)
    };
    let (min_x, max_x) = (x0.min(x1).min(x2), x0.max(x1).max(x2));
    let (min_y, max_y) = (y0.min(y1).min(y2), y0.max(y1).max(y2));
    // Pixel i's centre is i·ONE + HALF: the first centre >= min is ceil((min − HALF) / ONE).
    let bx0 = ((min_x - HALF + ONE - 1) >> SUBPIXEL_BITS).max(0);
    let bx1 = ((max_x - HALF) >> SUBPIXEL_BITS).min(i64::from(width) - 1);
    let by0 = ((min_y - HALF + ONE - 1) >> SUBPIXEL_BITS).max(0);
    let by1 = ((max_y - HALF) >> SUBPIXEL_BITS).min(i64::from(height) - 1);
    if bx0 > bx1 || by0 > by1 {
        return Err(Reject::OffScreen);
    }
    Ok(Setup { p, inv_w, color, swapped: ccw, area, bbox: [bx0, bx1, by0, by1] })
}

/// Rasterizes one set-up triangle into the part of `tile` it overlaps; returns newly covered pixels.
fn raster<const TW: usize, const TH: usize>(tile: &mut Tile<TW, TH>, s: &Setup, tri_id: u32) -> u32 {
    let (tx0, ty0) = (i64::from(tile.x0), i64::from(tile.y0));
    let x0 = s.bbox[0].max(tx0);
    let x1 = s.bbox[1].min(tx0 + i64::from(tile.width) - 1);
    let y0 = s.bbox[2].max(ty0);
    let y1 = s.bbox[3].min(ty0 + i64::from(tile.height) - 1);
    if x0 > x1 || y0 > y1 {
        return 0;
    }
    // Edge k is opposite vertex k, from a = p[k+1] to b = p[k+2]:
    // E_k(q) = (bx − ax)(qy − ay) − (by − ay)(qx − ax), positive inside, sum = area.
    let (cx, cy) = (x0 * ONE + HALF, y0 * ONE + HALF);
    let mut e_row = [0i64; 3];
    let mut step_x = [0i64; 3];
    let mut step_y = [0i64; 3];
    let mut bias = [0i64; 3];
    for k in 0..3 {
        let (Some(a), Some(b)) = (s.p.get((k + 1) % 3), s.p.get((k + 2) % 3)) else {
            return 0;
        };
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let top_left = dy < 0 || (dy == 0 && dx > 0);
        if let (Some(e), Some(sx), Some(sy), Some(t)) = (e_row.get_mut(k), step_x.get_mut(k), step_y.get_mut(k), bias.get_mut(k)) {
            *e = dx * (cy - a[1]) - dy * (cx - a[0]);
            *sx = -dy * ONE;
            *sy = dx * ONE;
            *t = if top_left { 0 } else { 1 };
        }
    }
    let inv_area = 1.0 / s.area as f32;
    let [iw0, iw1, iw2] = s.inv_w;
    let [c0, c1, c2] = s.color;
    let mut newly = 0u32;
    for py in y0..=y1 {
        let ly = (py - ty0) as usize;
        let (Some(crow), Some(drow), Some(trow), Some(brow)) =
            (tile.color.get_mut(ly), tile.inv_w.get_mut(ly), tile.tri.get_mut(ly), tile.bary.get_mut(ly))
        else {
            break;
        };
        let mut e = e_row;
        for px in x0..=x1 {
            if ((e[0] - bias[0]) | (e[1] - bias[1]) | (e[2] - bias[2])) >= 0 {
                let lx = (px - tx0) as usize;
                let (l0, l1, l2) = (e[0] as f32 * inv_area, e[1] as f32 * inv_area, e[2] as f32 * inv_area);
                let iw = l0 * iw0 + l1 * iw1 + l2 * iw2;
                if let (Some(d), Some(c), Some(t), Some(b)) = (drow.get_mut(lx), crow.get_mut(lx), trow.get_mut(lx), brow.get_mut(lx)) {
                    if iw > *d {
                        let r = 1.0 / iw;
                        let (p0, p1, p2) = (l0 * iw0 * r, l1 * iw1 * r, l2 * iw2 * r);
                        *d = iw;
                        *c = [
                            p0 * c0[0] + p1 * c1[0] + p2 * c2[0],
                            p0 * c0[1] + p1 * c1[1] + p2 * c2[1],
                            p0 * c0[2] + p1 * c1[2] + p2 * c2[2],
                        ];
                        if *t == NO_TRIANGLE {
                            newly += 1;
                        }
                        *t = tri_id;
                        *b = if s.swapped { [p2, p1] } else { [p1, p2] };
                    }
                }
            }
            e[0] += step_x[0];
            e[1] += step_x[1];
            e[2] += step_x[2];
        }
        e_row[0] += step_y[0];
        e_row[1] += step_y[1];
        e_row[2] += step_y[2];
    }
    newly
}

/// The tile rasterizer: one `TW × TH` tile of buffers and a per-tile-row bin of `BIN` triangles.
///
/// RAM: `size_of::<Self>()` ≈ `28 · TW · TH + 8 · BIN` bytes (colour 12, depth 4, triangle id 4 and
/// barycentrics 8 bytes per tile pixel; 8 bytes per bin entry). Create it once (it can live in a
/// `static`, see [`TileRasterizer::new`]) and reuse it for every frame.
#[derive(Debug, Clone)]
pub struct TileRasterizer<const TW: usize, const TH: usize, const BIN: usize> {
    tile: Tile<TW, TH>,
    bin: [BinEntry; BIN],
}

impl<const TW: usize, const TH: usize, const BIN: usize> Default for TileRasterizer<TW, TH, BIN> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const TW: usize, const TH: usize, const BIN: usize> TileRasterizer<TW, TH, BIN> {
    /// A rasterizer with cleared buffers (`const`, so it can initialise a `static`).
    pub const fn new() -> Self {
        Self { tile: Tile::new(), bin: [BinEntry::EMPTY; BIN] }
    }

    /// Renders `triangles` over `vertices` into a `width × height` frame, tile by tile, into `sink`.
    ///
    /// Tiles arrive in row-major order, each exactly once, covering the whole image. Errors are
    /// reported before the first tile is consumed.
    pub fn render<I: TriIndex, S: TileSink<TW, TH>>(
        &mut self,
        vertices: &[ProjectedVertex],
        triangles: &[[I; 3]],
        width: u32,
        height: u32,
        cull: Cull,
        sink: &mut S,
    ) -> Result<FrameStats, RasterError> {
        if TW == 0 || TH == 0 {
            return Err(RasterError::ZeroTileSize);
        }
        if width > MAX_IMAGE_SIZE || height > MAX_IMAGE_SIZE {
            return Err(RasterError::ImageTooLarge);
        }
        let count = u32::try_from(triangles.len()).ok().filter(|&n| n < NO_TRIANGLE).ok_or(RasterError::TooManyTriangles)?;
        let mut stats = FrameStats { triangles: count, ..FrameStats::default() };
        // Pass 0: validate indices and classify every triangle once (for the statistics).
        for tri in triangles {
            let v = fetch(vertices, tri).ok_or(RasterError::IndexOutOfRange)?;
            match setup(v, cull, width, height) {
                Ok(_) => stats.drawn += 1,
                Err(Reject::Invalid) => stats.near_or_invalid += 1,
                Err(Reject::Guard) => stats.guard_band += 1,
                Err(Reject::Culled) => stats.culled += 1,
                Err(Reject::Degenerate) => stats.degenerate += 1,
                Err(Reject::OffScreen) => stats.off_screen += 1,
            }
        }
        let (tw, th) = (TW as u32, TH as u32);
        let mut ty0 = 0u32;
        while ty0 < height {
            let rows = th.min(height - ty0);
            let (ry0, ry1) = (i64::from(ty0), i64::from(ty0 + rows - 1));
            // Bin the triangles meeting this tile row.
            let mut n = 0usize;
            let mut overflow = false;
            for (id, tri) in (0u32..).zip(triangles) {
                let Some(v) = fetch(vertices, tri) else { continue };
                if !may_meet_rows(v, ry0, ry1) {
                    continue;
                }
                let Ok(s) = setup(v, cull, width, height) else { continue };
                if s.bbox[3] < ry0 || s.bbox[2] > ry1 {
                    continue;
                }
                match self.bin.get_mut(n) {
                    Some(slot) => {
                        *slot = BinEntry { tri: id, x0: s.bbox[0] as u16, x1: s.bbox[1] as u16 };
                        n += 1;
                    }
                    None => {
                        overflow = true;
                        break;
                    }
                }
            }
            if overflow {
                stats.overflow_rows += 1;
            }
            let mut tx0 = 0u32;
            while tx0 < width {
                let cols = tw.min(width - tx0);
                self.tile.reset(tx0, ty0, cols, rows);
                let tx1 = tx0 + cols - 1;
                if overflow {
                    for (id, tri) in (0u32..).zip(triangles) {
                        let Some(v) = fetch(vertices, tri) else { continue };
                        if !may_meet_rows(v, ry0, ry1) {
                            continue;
                        }
                        if let Ok(s) = setup(v, cull, width, height) {
                            stats.covered_pixels += raster(&mut self.tile, &s, id);
                        }
                    }
                } else {
                    for e in self.bin.iter().take(n) {
                        if u32::from(e.x1) < tx0 || u32::from(e.x0) > tx1 {
                            continue;
                        }
                        let Some(v) = triangles.get(e.tri as usize).and_then(|t| fetch(vertices, t)) else { continue };
                        if let Ok(s) = setup(v, cull, width, height) {
                            stats.covered_pixels += raster(&mut self.tile, &s, e.tri);
                        }
                    }
                }
                sink.consume(&self.tile);
                stats.tiles += 1;
                tx0 += cols;
            }
            ty0 += rows;
        }
        Ok(stats)
    }
}

/// Cheap float pre-test: can the triangle reach pixel rows `ry0..=ry1`? (`setup` decides exactly.)
fn may_meet_rows(v: [&ProjectedVertex; 3], ry0: i64, ry1: i64) -> bool {
    let [a, b, c] = v;
    let lo = a.y.min(b.y).min(c.y);
    let hi = a.y.max(b.y).max(c.y);
    !(hi < ry0 as f32 - 1.0 || lo > ry1 as f32 + 2.0)
}
