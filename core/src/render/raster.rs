//! Tile-based, fixed-memory triangle rasterizer.
//!
//! Per frame, one scan over the triangle list sets every triangle up once (validation, fixed-point
//! snapping, winding, bounding box; it also classifies every triangle for [`FrameStats`]) and
//! collects the drawn ones, in list order, into a fixed-capacity bin of `BIN` entries (index and
//! box). The image is then walked in rows of `TH`-pixel tiles; each `TW × TH` tile rasterizes the
//! binned triangles whose box overlaps it into the tile buffers, and the finished tile is handed
//! to a [`TileSink`]. If the frame's drawn triangles do not fit, each tile row bins its own
//! (a float pre-test on the vertices' y, then the set-up); if a row's do not fit either, every
//! tile of that row scans the whole triangle list (slower, never lossy; counted in
//! [`FrameStats::overflow_rows`]). `BIN = 0` always takes that path ("iterate over all triangles
//! per tile"). The three paths draw the same triangles in the same order: the same tiles. Memory
//! is the tile buffers plus the bin: nothing scales with the image or the mesh.
//!
//! Rasterization:
//! - Vertices snap to fixed point with [`SUBPIXEL_BITS`] fractional bits (round half away from
//!   zero); edge functions are exact integers, stepped incrementally across the tile: `i32` for
//!   triangles under 64 px in x and y (fast on Cortex-M4, where `i64` arithmetic and `i64 → f32`
//!   are library calls), `i64` otherwise; both convert to the same `f32`. A pixel is covered if
//!   its centre `(i + 0.5, j + 0.5)` is strictly inside, or on an edge that is a *top* or *left*
//!   edge (Direct3D rule). Triangles sharing an edge therefore never both
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

use crate::geometry::{TriIndex, Vec3};
use crate::render::shading::ProjectedVertex;
use crate::render::tile::{Tile, TileSink, NO_TRIANGLE};

pub use super::fragment::{fragment_weights, FragmentSetup};

/// Fractional bits of the fixed-point vertex coordinates (1/256 pixel).
pub const SUBPIXEL_BITS: u32 = 8;
pub(super) const ONE: i32 = 1 << SUBPIXEL_BITS;
pub(super) const HALF: i32 = ONE / 2;
/// Vertices farther than this from the image origin (in pixels) reject their triangle (keeps `i64` exact).
pub const GUARD_BAND: f32 = 2_097_152.0;
/// Largest accepted image width or height in pixels.
pub const MAX_IMAGE_SIZE: u32 = 1 << 15;
/// Triangles whose fixed-point extent is below this in x and y (64 px) evaluate their edge
/// functions exactly in `i32` (|E| < 2 · extent² < 2^29); larger ones use `i64`.
pub(super) const SMALL_EXTENT: i32 = 1 << 14;

/// Which on-screen winding to discard.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
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
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
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
    /// Inclusive pixel bounds of the triangle's box in the image.
    x0: u16,
    x1: u16,
    y0: u16,
    y1: u16,
}

impl BinEntry {
    const EMPTY: Self = Self { tri: 0, x0: 0, x1: 0, y0: 0, y1: 0 };

    /// The entry of triangle `tri` with set-up `s` (bounds are below [`MAX_IMAGE_SIZE`]).
    fn new(tri: u32, s: &Setup) -> Self {
        let [x0, x1, y0, y1] = s.bbox.map(|b| b as u16);
        Self { tri, x0, x1, y0, y1 }
    }
}

/// Fixed-point triangle, oriented to positive area, with its pixel bounding box in the image.
pub(super) struct Setup {
    /// Vertices in fixed point (`|p| <= 2^29`), reordered to positive area if `swapped`.
    pub(super) p: [[i32; 2]; 3],
    pub(super) swapped: bool,
    pub(super) area: i64,
    /// Inclusive pixel bounds `x0, x1, y0, y1`, clamped to the image.
    bbox: [i32; 4],
    /// Extent below [`SMALL_EXTENT`]: edge functions fit `i32`.
    pub(super) small: bool,
}

#[derive(Debug, Clone, Copy)]
pub(super) enum Reject {
    Invalid,
    Guard,
    Culled,
    Degenerate,
    OffScreen,
}

pub(super) fn fetch<'a, I: TriIndex>(vertices: &'a [ProjectedVertex], tri: &[I; 3]) -> Option<[&'a ProjectedVertex; 3]> {
    let [a, b, c] = *tri;
    Some([vertices.get(a.index())?, vertices.get(b.index())?, vertices.get(c.index())?])
}

/// `roundf(x · 2^SUBPIXEL_BITS)` (half away from zero) for `|x| <= GUARD_BAND`, without `libm`
/// or `i64`: the truncation and the fraction `s − trunc(s)` are exact in `f32`.
#[inline(always)]
pub(super) fn snap(x: f32) -> i32 {
    let s = x * ONE as f32;
    let t = s as i32;
    let f = s - t as f32;
    t + i32::from(f >= 0.5) - i32::from(f <= -0.5)
}

/// Checks every vertex (finite, in front, inside the guard band).
#[inline(always)]
fn validate(v: [&ProjectedVertex; 3]) -> Result<(), Reject> {
    // Fast path, exactly equivalent to `validate_slow(v).is_ok()`: `|x| <= GUARD_BAND` is false for
    // NaN, and a sum of floats is finite only if every term is (a sum of finite terms that overflows
    // only sends the triangle down the exact path).
    let [a, b, c] = v;
    let inside = |p: &ProjectedVertex| p.x.abs() <= GUARD_BAND && p.y.abs() <= GUARD_BAND && p.inv_w > 0.0;
    let sum = a.inv_w
        + b.inv_w
        + c.inv_w
        + (a.color[0] + a.color[1] + a.color[2])
        + (b.color[0] + b.color[1] + b.color[2])
        + (c.color[0] + c.color[1] + c.color[2]);
    if inside(a) && inside(b) && inside(c) && sum.is_finite() {
        return Ok(());
    }
    validate_slow(v)
}

/// Classifies an invalid vertex: [`Reject::Invalid`] before [`Reject::Guard`], in vertex order.
fn validate_slow(v: [&ProjectedVertex; 3]) -> Result<(), Reject> {
    for vi in v {
        let finite = vi.x.is_finite() && vi.y.is_finite() && vi.inv_w.is_finite() && vi.color.iter().all(|c| c.is_finite());
        if !finite || vi.inv_w <= 0.0 {
            return Err(Reject::Invalid);
        }
        if vi.x.abs() > GUARD_BAND || vi.y.abs() > GUARD_BAND {
            return Err(Reject::Guard);
        }
    }
    Ok(())
}

/// Vertices checked once per frame instead of once per triangle (each is in about six): a bit
/// per vertex, set if it passes [`validate_slow`]'s tests (finite, in front, inside the guard
/// band). A triangle of three such vertices passes [`validate`]. Frames of more vertices than
/// the bits validate per triangle.
struct ValidVertices {
    bits: [u32; VALID_WORDS],
}

/// Words of [`ValidVertices`]: 2,048 vertices (256 bytes of stack) on the devices, 8,192 (1 KiB)
/// elsewhere, for the host's full-resolution models.
const VALID_WORDS: usize = if cfg!(target_os = "none") { 64 } else { 256 };

impl ValidVertices {
    /// The flags of `vertices` (`None` if there are too many).
    fn of(vertices: &[ProjectedVertex]) -> Option<Self> {
        let mut bits = [0u32; VALID_WORDS];
        if vertices.len() > bits.len() * 32 {
            return None;
        }
        for (word, chunk) in bits.iter_mut().zip(vertices.chunks(32)) {
            for (k, p) in chunk.iter().enumerate() {
                let ok = validate_slow([p, p, p]).is_ok();
                *word |= u32::from(ok) << k;
            }
        }
        Some(Self { bits })
    }

    /// Whether all three vertices of `tri` are valid.
    #[inline(always)]
    fn all<I: TriIndex>(&self, tri: &[I; 3]) -> bool {
        tri.iter().all(|i| {
            let i = i.index();
            self.bits.get(i / 32).is_some_and(|w| w >> (i % 32) & 1 == 1)
        })
    }
}

/// Snapping, area, winding and bounding box of a triangle whose vertices passed [`validate`].
#[inline(always)]
fn geometry(v: [&ProjectedVertex; 3], cull: Cull, width: u32, height: u32) -> Result<Setup, Reject> {
    let [va, vb, vc] = v;
    let (x0, y0, x1, y1, x2, y2) = (snap(va.x), snap(va.y), snap(vb.x), snap(vb.y), snap(vc.x), snap(vc.y));
    let (min_x, max_x) = (x0.min(x1).min(x2), x0.max(x1).max(x2));
    let (min_y, max_y) = (y0.min(y1).min(y2), y0.max(y1).max(y2));
    // |p| <= 2^29, so differences fit i32; products need i64 unless the triangle is small.
    let small = max_x - min_x < SMALL_EXTENT && max_y - min_y < SMALL_EXTENT;
    let area = if small {
        i64::from((x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0))
    } else {
        i64::from(x1 - x0) * i64::from(y2 - y0) - i64::from(x2 - x0) * i64::from(y1 - y0)
    };
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
    let (p, area) = if ccw { ([[x0, y0], [x2, y2], [x1, y1]], -area) } else { ([[x0, y0], [x1, y1], [x2, y2]], area) };
    // Pixel i's centre is i·ONE + HALF: the first centre >= min is ceil((min − HALF) / ONE).
    // (`MAX_IMAGE_SIZE` = 2^15, so the image bounds fit i32.)
    let bx0 = ((min_x - HALF + ONE - 1) >> SUBPIXEL_BITS).max(0);
    let bx1 = ((max_x - HALF) >> SUBPIXEL_BITS).min(width as i32 - 1);
    let by0 = ((min_y - HALF + ONE - 1) >> SUBPIXEL_BITS).max(0);
    let by1 = ((max_y - HALF) >> SUBPIXEL_BITS).min(height as i32 - 1);
    if bx0 > bx1 || by0 > by1 {
        return Err(Reject::OffScreen);
    }
    Ok(Setup { p, swapped: ccw, area, bbox: [bx0, bx1, by0, by1], small })
}

/// Full set-up: [`validate`], then [`geometry`].
pub(super) fn setup(v: [&ProjectedVertex; 3], cull: Cull, width: u32, height: u32) -> Result<Setup, Reject> {
    validate(v)?;
    geometry(v, cull, width, height)
}

/// Integer type of the edge functions: `i32` for small triangles, `i64` otherwise (both exact, so
/// the `f32` conversions give the same bits).
pub(super) trait EdgeInt:
    Copy
    + core::ops::Add<Output = Self>
    + core::ops::Sub<Output = Self>
    + core::ops::Mul<Output = Self>
    + core::ops::BitOr<Output = Self>
    + core::ops::AddAssign
    + PartialOrd
{
    const ZERO: Self;
    fn from_i32(v: i32) -> Self;
    fn to_f32(self) -> f32;
}

impl EdgeInt for i32 {
    const ZERO: Self = 0;
    #[inline(always)]
    fn from_i32(v: i32) -> Self {
        v
    }
    #[inline(always)]
    fn to_f32(self) -> f32 {
        self as f32
    }
}

impl EdgeInt for i64 {
    const ZERO: Self = 0;
    #[inline(always)]
    fn from_i32(v: i32) -> Self {
        i64::from(v)
    }
    #[inline(always)]
    fn to_f32(self) -> f32 {
        self as f32
    }
}

/// Per-triangle shading inputs, in the set-up's vertex order.
struct Attrs {
    inv_area: f32,
    inv_w: [f32; 3],
    color: [Vec3; 3],
    swapped: bool,
    tri_id: u32,
}

/// Rasterizes one set-up triangle into the part of `tile` it overlaps; returns newly covered pixels.
fn raster<const TW: usize, const TH: usize>(tile: &mut Tile<TW, TH>, s: &Setup, v: [&ProjectedVertex; 3], tri_id: u32) -> u32 {
    let (tx0, ty0) = (tile.x0 as i32, tile.y0 as i32);
    let x0 = s.bbox[0].max(tx0);
    let x1 = s.bbox[1].min(tx0 + tile.width as i32 - 1);
    let y0 = s.bbox[2].max(ty0);
    let y1 = s.bbox[3].min(ty0 + tile.height as i32 - 1);
    if x0 > x1 || y0 > y1 {
        return 0;
    }
    let [va, vb, vc] = v;
    let (inv_w, color) = if s.swapped {
        ([va.inv_w, vc.inv_w, vb.inv_w], [va.color, vc.color, vb.color])
    } else {
        ([va.inv_w, vb.inv_w, vc.inv_w], [va.color, vb.color, vc.color])
    };
    // (The same value either way; `i64 as f32` is a library call on Cortex-M4.)
    let area = if s.small { s.area as i32 as f32 } else { s.area as f32 };
    let attrs = Attrs { inv_area: 1.0 / area, inv_w, color, swapped: s.swapped, tri_id };
    let clip = [x0 - tx0, x1 - tx0, y0 - ty0, y1 - ty0];
    if s.small {
        raster_edges::<TW, TH, i32>(tile, &s.p, [x0, y0], clip, &attrs)
    } else {
        raster_edges::<TW, TH, i64>(tile, &s.p, [x0, y0], clip, &attrs)
    }
}

/// Walks the clipped box `clip` (tile-local inclusive `x0, x1, y0, y1`; `start` = its top-left
/// pixel in image coordinates) with incremental edge functions of type `E`.
#[inline(always)]
fn raster_edges<const TW: usize, const TH: usize, E: EdgeInt>(
    tile: &mut Tile<TW, TH>,
    p: &[[i32; 2]; 3],
    start: [i32; 2],
    clip: [i32; 4],
    a: &Attrs,
) -> u32 {
    // Edge k is opposite vertex k, from a = p[k+1] to b = p[k+2]:
    // E_k(q) = (bx − ax)(qy − ay) − (by − ay)(qx − ax), positive inside, sum = area.
    // A pixel is covered if E_k − bias_k >= 0 for all k (bias 1 on edges that are not top-left):
    // the loop carries E_k − bias_k and adds the bias back for the interpolation.
    let (cx, cy) = (start[0] * ONE + HALF, start[1] * ONE + HALF);
    let mut e_row = [E::ZERO; 3];
    let mut step_x = [E::ZERO; 3];
    let mut step_y = [E::ZERO; 3];
    let mut bias = [E::ZERO; 3];
    for (k, (((e, sx), sy), t)) in e_row.iter_mut().zip(step_x.iter_mut()).zip(step_y.iter_mut()).zip(bias.iter_mut()).enumerate() {
        let (Some(pa), Some(pb)) = (p.get((k + 1) % 3), p.get((k + 2) % 3)) else {
            return 0;
        };
        let (dx, dy) = (pb[0] - pa[0], pb[1] - pa[1]);
        let top_left = dy < 0 || (dy == 0 && dx > 0);
        *t = E::from_i32(i32::from(!top_left));
        *e = E::from_i32(dx) * E::from_i32(cy - pa[1]) - E::from_i32(dy) * E::from_i32(cx - pa[0]) - *t;
        *sx = E::ZERO - E::from_i32(dy) * E::from_i32(ONE);
        *sy = E::from_i32(dx) * E::from_i32(ONE);
    }
    let [c0, c1, c2] = a.color;
    let inv_area = a.inv_area;
    // Exclusive ranges (an inclusive range's iterator costs more per step), and the tile rows
    // touched only at pixels inside the triangle.
    let (lx0, lx1) = (clip[0] as usize, clip[1] as usize + 1);
    let mut newly = 0u32;
    for ly in clip[2] as usize..clip[3] as usize + 1 {
        let (Some(crow), Some(drow), Some(trow), Some(brow)) =
            (tile.color.get_mut(ly), tile.inv_w.get_mut(ly), tile.tri.get_mut(ly), tile.bary.get_mut(ly))
        else {
            break;
        };
        let mut e = e_row;
        for lx in lx0..lx1 {
            if (e[0] | e[1] | e[2]) >= E::ZERO {
                let l = [(e[0] + bias[0]).to_f32() * inv_area, (e[1] + bias[1]).to_f32() * inv_area, (e[2] + bias[2]).to_f32() * inv_area];
                let iw = interpolated_inv_w(l, a.inv_w);
                let (Some(c), Some(d), Some(t), Some(b)) = (crow.get_mut(lx), drow.get_mut(lx), trow.get_mut(lx), brow.get_mut(lx)) else {
                    break;
                };
                if iw > *d {
                    let [p0, p1, p2] = perspective_weights(l, a.inv_w, iw);
                    *d = iw;
                    *c = blend([p0, p1, p2], [c0, c1, c2]);
                    if *t == NO_TRIANGLE {
                        newly += 1;
                    }
                    *t = a.tri_id;
                    *b = if a.swapped { [p2, p1] } else { [p1, p2] };
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

/// `1 / w` at a pixel with screen-space barycentrics `l` of vertices with reciprocal depths `inv_w`.
#[inline(always)]
pub(super) fn interpolated_inv_w(l: [f32; 3], inv_w: [f32; 3]) -> f32 {
    l[0] * inv_w[0] + l[1] * inv_w[1] + l[2] * inv_w[2]
}

/// Perspective-correct weights from screen-space barycentrics `l` (`iw`: [`interpolated_inv_w`]).
#[inline(always)]
pub(super) fn perspective_weights(l: [f32; 3], inv_w: [f32; 3], iw: f32) -> [f32; 3] {
    let r = 1.0 / iw;
    [l[0] * inv_w[0] * r, l[1] * inv_w[1] * r, l[2] * inv_w[2] * r]
}

/// The colour of a pixel: the vertex colours `c` blended with weights `p` (in the set-up's vertex
/// order). The rasterizer and re-shading from a [`crate::render::frame_cache::FrameCache`] both
/// use it, so both give the same bits.
#[inline(always)]
pub fn blend(p: [f32; 3], c: [Vec3; 3]) -> Vec3 {
    let [p0, p1, p2] = p;
    let [c0, c1, c2] = c;
    [p0 * c0[0] + p1 * c1[0] + p2 * c2[0], p0 * c0[1] + p1 * c1[1] + p2 * c2[1], p0 * c0[2] + p1 * c1[2] + p2 * c2[2]]
}

/// The tile rasterizer: one `TW × TH` tile of buffers and a per-tile-row bin of `BIN` triangles.
///
/// RAM: `size_of::<Self>()` ≈ `28 · TW · TH + 12 · BIN` bytes (colour 12, depth 4, triangle id 4 and
/// barycentrics 8 bytes per tile pixel; 12 bytes per bin entry). Create it once (it can live in a
/// `static`, see [`TileRasterizer::new`]) and reuse it for every frame.
///
/// ```
/// use gpmm_core::render::{Cull, ProjectedVertex, Tile, TileRasterizer};
///
/// // One triangle in screen space (pixels, y down, 100 mm deep) over an 8 × 8 image.
/// let vertex = |x, y| ProjectedVertex { x, y, inv_w: 0.01, color: [1.0, 0.5, 0.25] };
/// let vertices = [vertex(0.0, 0.0), vertex(8.5, 0.0), vertex(0.0, 8.5)];
/// let triangles = [[0u32, 1, 2]];
///
/// // The sink sees each finished 4 × 4 tile (any `FnMut(&Tile)` is one); this one counts the
/// // covered pixels.
/// let mut covered = 0;
/// let mut count = |tile: &Tile<4, 4>| {
///     let (w, h) = tile.size();
///     covered += (0..h as usize).flat_map(|y| (0..w as usize).map(move |x| (x, y))).filter(|&(x, y)| tile.is_covered(x, y)).count();
/// };
/// let mut raster = TileRasterizer::<4, 4, 16>::new();
/// let stats = raster.render(&vertices, &triangles, 8, 8, Cull::None, &mut count)?;
///
/// // The pixels whose centre (x + 0.5, y + 0.5) lies inside, x + y + 1 < 8.5: 8 + 7 + … + 1.
/// assert_eq!(covered, 36);
/// assert_eq!((stats.drawn, stats.covered_pixels), (1, 36));
/// # Ok::<(), gpmm_core::render::RasterError>(())
/// ```
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
        if height == 0 {
            // No tile row: validate and classify here (the first row's scan does it otherwise).
            for tri in triangles {
                let v = fetch(vertices, tri).ok_or(RasterError::IndexOutOfRange)?;
                classify_into(&mut stats, setup(v, cull, width, height).map(|_| ()));
            }
            return Ok(stats);
        }
        let th = TH as u32;
        let frame = Frame { vertices, triangles, width, height, cull };
        // One set-up per triangle: validation, statistics and, if they all fit, the bin of the frame.
        let listed = self.bin_frame(&frame, &mut stats)?;
        let mut ty0 = 0u32;
        while ty0 < height {
            let row = RowSpan { y0: ty0, rows: th.min(height - ty0) };
            match listed {
                Some(n) => self.tile_row(&frame, row, Binned::Frame(n), &mut stats, sink),
                None => {
                    let binned = self.bin_row(&frame, row);
                    self.tile_row(&frame, row, binned, &mut stats, sink);
                }
            }
            ty0 += row.rows;
        }
        Ok(stats)
    }

    /// Sets up every triangle once: checks the indices, classifies each triangle for the
    /// statistics and bins, in list order, the drawn ones with their boxes. `None` if they do not
    /// all fit (the rows then bin for themselves).
    fn bin_frame<I: TriIndex>(&mut self, f: &Frame<'_, I>, stats: &mut FrameStats) -> Result<Option<usize>, RasterError> {
        let mut n = 0usize;
        let mut overflow = false;
        let valid = ValidVertices::of(f.vertices);
        for (id, tri) in (0u32..).zip(f.triangles) {
            let v = fetch(f.vertices, tri).ok_or(RasterError::IndexOutOfRange)?;
            // Three valid vertices pass `validate`: only the geometry is left to do.
            let s = if valid.as_ref().is_some_and(|ok| ok.all(tri)) {
                geometry(v, f.cull, f.width, f.height)
            } else {
                setup(v, f.cull, f.width, f.height)
            };
            classify_into(stats, s.as_ref().map(|_| ()).map_err(|r| *r));
            let Ok(s) = s else { continue };
            if overflow {
                continue;
            }
            match self.bin.get_mut(n) {
                Some(slot) => {
                    *slot = BinEntry::new(id, &s);
                    n += 1;
                }
                // Keep scanning (indices and statistics), without binning.
                None => overflow = true,
            }
        }
        Ok((!overflow).then_some(n))
    }

    /// Scans the triangle list and bins, in list order, the triangles meeting tile row `row`
    /// (after the frame's bin overflowed); [`Binned::Overflow`] if they do not fit either.
    fn bin_row<I: TriIndex>(&mut self, f: &Frame<'_, I>, row: RowSpan) -> Binned {
        let (ry0, ry1) = row.bounds();
        let mut n = 0usize;
        for (id, tri) in (0u32..).zip(f.triangles) {
            let Some(v) = fetch(f.vertices, tri) else { continue };
            if !may_meet_rows(v, ry0, ry1) {
                continue;
            }
            let Ok(s) = setup(v, f.cull, f.width, f.height) else { continue };
            if s.bbox[3] < ry0 || s.bbox[2] > ry1 {
                continue;
            }
            match self.bin.get_mut(n) {
                Some(slot) => {
                    *slot = BinEntry::new(id, &s);
                    n += 1;
                }
                None => return Binned::Overflow,
            }
        }
        Binned::Row(n)
    }

    /// Renders the tiles of one tile row from the bin's first entries (the frame's or the row's),
    /// or, if the row's bin overflowed, from a scan of the whole list per tile.
    fn tile_row<I: TriIndex, S: TileSink<TW, TH>>(
        &mut self,
        f: &Frame<'_, I>,
        row: RowSpan,
        binned: Binned,
        stats: &mut FrameStats,
        sink: &mut S,
    ) {
        let (ry0, ry1) = row.bounds();
        let tw = TW as u32;
        if binned == Binned::Overflow {
            stats.overflow_rows += 1;
        }
        let meets_row = |e: &BinEntry| i32::from(e.y1) >= ry0 && i32::from(e.y0) <= ry1;
        // The frame's entries meeting this row, copied (in order) into the bin's unused tail if
        // they fit there: the row's tiles then scan those instead of the whole frame's.
        let (first, entries) = match binned {
            Binned::Frame(n) => {
                let (head, tail) = self.bin.split_at_mut(n.min(BIN));
                let mut m = 0usize;
                let mut fits = true;
                for e in head.iter().filter(|e| meets_row(e)) {
                    match tail.get_mut(m) {
                        Some(slot) => *slot = *e,
                        None => {
                            fits = false;
                            break;
                        }
                    }
                    m += 1;
                }
                if fits {
                    (n, m)
                } else {
                    (0, n)
                }
            }
            Binned::Row(n) => (0, n),
            Binned::Overflow => (0, 0),
        };
        let mut tx0 = 0u32;
        while tx0 < f.width {
            let cols = tw.min(f.width - tx0);
            self.tile.reset(tx0, row.y0, cols, row.rows);
            let tx1 = tx0 + cols - 1;
            if binned == Binned::Overflow {
                for (id, tri) in (0u32..).zip(f.triangles) {
                    let Some(v) = fetch(f.vertices, tri) else { continue };
                    if !may_meet_rows(v, ry0, ry1) {
                        continue;
                    }
                    if let Ok(s) = setup(v, f.cull, f.width, f.height) {
                        stats.covered_pixels += raster(&mut self.tile, &s, v, id);
                    }
                }
            }
            for e in self.bin.iter().skip(first).take(entries) {
                if !meets_row(e) || u32::from(e.x1) < tx0 || u32::from(e.x0) > tx1 {
                    continue;
                }
                let Some(v) = f.triangles.get(e.tri as usize).and_then(|t| fetch(f.vertices, t)) else { continue };
                // Binned triangles passed `validate` and the winding test: only the geometry is redone.
                if let Ok(s) = geometry(v, f.cull, f.width, f.height) {
                    stats.covered_pixels += raster(&mut self.tile, &s, v, e.tri);
                }
            }
            sink.consume(&self.tile);
            stats.tiles += 1;
            tx0 += cols;
        }
    }
}

/// What the bin holds for a tile row.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Binned {
    /// The first `n` entries are every drawn triangle of the frame.
    Frame(usize),
    /// The first `n` entries are the triangles meeting this row.
    Row(usize),
    /// The row's triangles did not fit: its tiles scan the whole list.
    Overflow,
}

/// The inputs of one frame.
struct Frame<'a, I> {
    vertices: &'a [ProjectedVertex],
    triangles: &'a [[I; 3]],
    width: u32,
    height: u32,
    cull: Cull,
}

/// A tile row: first pixel row and number of rows.
#[derive(Clone, Copy)]
struct RowSpan {
    y0: u32,
    rows: u32,
}

impl RowSpan {
    /// Inclusive pixel rows.
    fn bounds(self) -> (i32, i32) {
        (self.y0 as i32, (self.y0 + self.rows) as i32 - 1)
    }
}

fn classify_into(stats: &mut FrameStats, r: Result<(), Reject>) {
    match r {
        Ok(()) => stats.drawn += 1,
        Err(Reject::Invalid) => stats.near_or_invalid += 1,
        Err(Reject::Guard) => stats.guard_band += 1,
        Err(Reject::Culled) => stats.culled += 1,
        Err(Reject::Degenerate) => stats.degenerate += 1,
        Err(Reject::OffScreen) => stats.off_screen += 1,
    }
}

/// Cheap float pre-test: can the triangle reach pixel rows `ry0..=ry1`? (`setup` decides exactly.)
/// Comparisons only (no `f32::min`, a library call on Cortex-M4); a NaN passes (`setup` rejects it).
#[inline(always)]
fn may_meet_rows(v: [&ProjectedVertex; 3], ry0: i32, ry1: i32) -> bool {
    let [a, b, c] = v;
    let (lo, hi) = (ry0 as f32 - 1.0, ry1 as f32 + 2.0);
    !((a.y < lo && b.y < lo && c.y < lo) || (a.y > hi && b.y > hi && c.y > hi))
}
