//! The covered pixels of recent frames, kept so that a change of colour or light is re-shaded
//! without the rasterizer.
//!
//! A colour or light change moves no vertex on screen: coverage, visibility and each pixel's
//! triangle and weights stay as they were; only the vertex colours change. While a frame is
//! rendered, [`FrameCache::recorder`] wraps the sink and notes, tile by tile, every covered pixel
//! and its triangle. The first re-shade of that geometry derives each pixel's vertex ids and
//! perspective-correct weights ([`crate::render::raster::fragment_weights`], the rasterizer's own
//! arithmetic); every later one blends the new vertex colours with them ([`crate::render::raster::blend`])
//! and hands the pixels, tile by tile and in the rasterizer's order, to a [`FragmentSink`]: the
//! same colours in the same order, so the same sums to the bit.
//!
//! Two slots (two geometries) are kept, the last two recorded: after a rejected pose or shape
//! proposal the chain's own frame is still there. Memory is the caller's: per slot one
//! [`CachedFragment`] per pixel that may be covered and one entry per tile. A frame that does
//! not fit is simply not kept.
//!
//! A small device keeps one compact slot instead ([`FrameCache::compact`]): a coverage bit per
//! pixel and a 16-bit triangle id per covered pixel (2 bytes instead of 32); each re-shade then
//! derives the weights again, pixel by pixel ([`crate::render::raster::FragmentSetup`], kept for 128
//! recent triangles on the stack), which still skips binning, the set-up of hidden triangles and
//! the tile buffers.

use crate::geometry::{TriIndex, Vec3};
use crate::render::pose::Pose;
use crate::render::raster::{blend, fragment_weights, FragmentSetup};
use crate::render::shading::ProjectedVertex;
use crate::render::tile::{Tile, TileSink, NO_TRIANGLE};

/// What a frame's geometry depends on: the shape instance (by serial number), the pose and focal
/// length (bit patterns) and the image size.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GeometryKey {
    shape: u64,
    pose: [u32; 6],
    focal: u32,
    size: [u32; 2],
}

impl GeometryKey {
    /// The key of shape instance `shape` seen with `pose` and `focal` in a `width × height` image.
    pub fn new(shape: u64, pose: &Pose, focal: f32, width: u32, height: u32) -> Self {
        let t = pose.translation;
        Self {
            shape,
            pose: [pose.yaw, pose.pitch, pose.roll, t[0], t[1], t[2]].map(f32::to_bits),
            focal: focal.to_bits(),
            size: [width, height],
        }
    }
}

/// One covered pixel of a cached frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CachedFragment {
    /// Row-major pixel index in the frame.
    pixel: u32,
    /// The triangle covering it.
    triangle: u32,
    /// The triangle's vertex ids in the rasterizer's set-up order (after derivation).
    vertices: [u32; 3],
    /// Their perspective-correct weights (after derivation).
    weights: [f32; 3],
}

impl CachedFragment {
    /// An unused entry (for initializing buffers).
    pub const EMPTY: Self = Self { pixel: 0, triangle: NO_TRIANGLE, vertices: [0; 3], weights: [0.0; 3] };
}

/// Caller-provided memory of one slot: fragments (at most one per pixel) and one end index per tile.
#[derive(Debug)]
pub struct FrameBuffers<'c> {
    /// Covered pixels, in the order the rasterizer hands them over.
    pub fragments: &'c mut [CachedFragment],
    /// Per tile, the end of its fragments.
    pub tile_ends: &'c mut [u32],
}

/// Caller-provided memory of a compact slot: one bit per pixel (row-major, 32 a word) and one
/// triangle id per covered pixel.
#[derive(Debug)]
pub struct CompactBuffers<'c> {
    /// Coverage bits: at least `width · height / 32` words (rounded up).
    pub covered: &'c mut [u32],
    /// The covering triangle of each covered pixel, in the rasterizer's order.
    pub triangles: &'c mut [u16],
}

#[derive(Debug)]
enum Store<'c> {
    Full(FrameBuffers<'c>),
    Compact(CompactBuffers<'c>),
    Unused,
}

#[derive(Debug)]
struct Slot<'c> {
    store: Store<'c>,
    fragments: usize,
    tiles: usize,
    /// The recorded frame's tile size.
    tile: (u32, u32),
    key: Option<GeometryKey>,
    derived: bool,
}

impl<'c> Slot<'c> {
    fn new(store: Store<'c>) -> Self {
        Self { store, fragments: 0, tiles: 0, tile: (0, 0), key: None, derived: false }
    }

    fn clear(&mut self) {
        self.fragments = 0;
        self.tiles = 0;
        self.key = None;
        self.derived = false;
    }
}

/// Receives a re-shaded frame: covered pixels tile by tile, in the rasterizer's order.
///
/// # Examples
///
/// A frame recorded while it was rendered, re-shaded in new colours into a sink of one's own that
/// keeps the pixels and counts the tiles:
///
/// ```
/// use gpmm_core::geometry::Vec3;
/// use gpmm_core::render::frame_cache::{CachedFragment, FragmentSink, FrameBuffers, FrameCache, GeometryKey};
/// use gpmm_core::render::{Cull, Pose, ProjectedVertex, Tile, TileRasterizer};
///
/// #[derive(Default)]
/// struct Pixels {
///     colors: Vec<(u32, Vec3)>,
///     tiles: u32,
/// }
///
/// impl FragmentSink for Pixels {
///     fn fragment(&mut self, pixel: u32, color: Vec3) {
///         self.colors.push((pixel, color));
///     }
///     fn end_tile(&mut self) {
///         self.tiles += 1;
///     }
/// }
///
/// // Two slots for an 8 × 8 frame in 4 × 4 tiles: a fragment per pixel and an end per tile each.
/// # let (mut fa, mut fb) = ([CachedFragment::EMPTY; 64], [CachedFragment::EMPTY; 64]);
/// # let (mut ta, mut tb) = ([0u32; 4], [0u32; 4]);
/// # let slot_a = FrameBuffers { fragments: &mut fa, tile_ends: &mut ta };
/// # let slot_b = FrameBuffers { fragments: &mut fb, tile_ends: &mut tb };
/// let mut cache = FrameCache::new(slot_a, slot_b);
/// let key = GeometryKey::new(0, &Pose::frontal(100.0), 50.0, 8, 8);
///
/// // A white triangle rendered once through the recorder, which keeps its covered pixels.
/// let white = |x, y| ProjectedVertex { x, y, inv_w: 0.01, color: [1.0; 3] };
/// let (mut vertices, triangles) = ([white(0.0, 0.0), white(8.5, 0.0), white(0.0, 8.5)], [[0u32, 1, 2]]);
/// let mut display = |_: &Tile<4, 4>| {};
/// let mut recorder = cache.recorder(key, None, &mut display);
/// TileRasterizer::<4, 4, 16>::new().render(&vertices, &triangles, 8, 8, Cull::None, &mut recorder)?;
/// recorder.finish();
///
/// // New vertex colours, the same geometry: re-shaded without the rasterizer.
/// vertices.iter_mut().for_each(|v| v.color = [0.2, 0.4, 0.6]);
/// let mut pixels = Pixels::default();
/// assert!(cache.reshade(&key, &vertices, &triangles, &mut pixels));
/// assert_eq!((pixels.colors.len(), pixels.tiles), (36, 4));
/// assert!(pixels.colors.iter().all(|(_, c)| c.iter().zip([0.2, 0.4, 0.6]).all(|(a, b)| (a - b).abs() < 1e-6)));
///
/// // A geometry the cache does not hold is refused: render it instead.
/// assert!(!cache.reshade(&GeometryKey::new(0, &Pose::frontal(120.0), 50.0, 8, 8), &vertices, &triangles, &mut pixels));
/// # Ok::<(), gpmm_core::render::RasterError>(())
/// ```
pub trait FragmentSink {
    /// One covered pixel (row-major index in the frame) and its colour.
    fn fragment(&mut self, pixel: u32, color: Vec3);

    /// The end of a tile (after its fragments, also for a tile without any).
    fn end_tile(&mut self);
}

/// The covered pixels of the last two frames (see the module docs).
#[derive(Debug)]
pub struct FrameCache<'c> {
    slots: [Slot<'c>; 2],
    /// The slot recorded last.
    newest: usize,
    /// Frames re-shaded from the cache.
    pub reshaded: u32,
    /// Frames recorded (rendered by the rasterizer).
    pub recorded: u32,
}

impl<'c> FrameCache<'c> {
    /// A cache over two slots of caller memory.
    pub fn new(a: FrameBuffers<'c>, b: FrameBuffers<'c>) -> Self {
        Self { slots: [Slot::new(Store::Full(a)), Slot::new(Store::Full(b))], newest: 0, reshaded: 0, recorded: 0 }
    }

    /// A cache of one compact slot (see the module docs): the last frame recorded.
    pub fn compact(bufs: CompactBuffers<'c>) -> Self {
        Self { slots: [Slot::new(Store::Compact(bufs)), Slot::new(Store::Unused)], newest: 0, reshaded: 0, recorded: 0 }
    }

    /// Forgets every frame.
    pub fn clear(&mut self) {
        for s in self.slots.iter_mut() {
            s.clear();
        }
    }

    /// Lends the compact slot's triangle ids as scratch memory (`None` for a cache of full slots),
    /// forgetting every frame first: nothing written there is ever read back as a frame.
    pub fn scratch(&mut self) -> Option<&mut [u16]> {
        self.clear();
        self.slots.iter_mut().find_map(|s| match &mut s.store {
            Store::Compact(c) => Some(&mut *c.triangles),
            _ => None,
        })
    }

    /// Whether a frame of geometry `key` is kept.
    pub fn contains(&self, key: &GeometryKey) -> bool {
        self.slots.iter().any(|s| s.key.as_ref() == Some(key))
    }

    /// A sink that passes every tile to `inner` and records the frame for geometry `key` in a
    /// slot that does not hold `keep` (the chain's own frame), else the older one; a compact
    /// cache (one slot) records only the chain's own frame (`keep` is `None` or `key`). Call
    /// [`Recorder::finish`] after a successful render: only then is the frame kept.
    pub fn recorder<'r, S>(&'r mut self, key: GeometryKey, keep: Option<GeometryKey>, inner: &'r mut S) -> Recorder<'r, 'c, S> {
        let [a, b] = &self.slots;
        let single = matches!(b.store, Store::Unused);
        if single && keep.is_some() && keep != Some(key) {
            // One slot: keep the chain's frame, do not record a proposal's (most are rejected,
            // and a colour or light proposal after a rejection re-shades the chain's frame).
            let [a, _] = &mut self.slots;
            return Recorder { slot: a, inner, key, overflow: true, counter: &mut self.recorded };
        }
        let older = if single {
            0
        } else if keep.is_some() && a.key == keep {
            1
        } else if keep.is_some() && b.key == keep {
            0
        } else {
            usize::from(self.newest == 0)
        };
        self.newest = older;
        let [a, b] = &mut self.slots;
        let slot = if older == 0 { a } else { b };
        slot.clear();
        let mut overflow = false;
        if let Store::Compact(c) = &mut slot.store {
            let words = (key.size[0] as usize * key.size[1] as usize).div_ceil(32);
            match c.covered.get_mut(..words) {
                Some(bits) => bits.fill(0),
                None => overflow = true,
            }
        }
        Recorder { slot, inner, key, overflow, counter: &mut self.recorded }
    }

    /// Re-shades the kept frame of geometry `key` with the colours of `vertices` (whose positions
    /// must be that geometry's) into `sink`. `false` (nothing or part of a frame sent) if no frame
    /// of that geometry is kept or a colour is not finite: then render instead.
    pub fn reshade<I: TriIndex, S: FragmentSink>(
        &mut self,
        key: &GeometryKey,
        vertices: &[ProjectedVertex],
        triangles: &[[I; 3]],
        sink: &mut S,
    ) -> bool {
        let Some(slot) = self.slots.iter_mut().find(|s| s.key.as_ref() == Some(key)) else {
            return false;
        };
        let done = match &slot.store {
            Store::Full(_) => reshade_full(slot, key, vertices, triangles, sink),
            Store::Compact(c) => reshade_compact(c, slot.fragments, slot.tiles, slot.tile, key, vertices, triangles, sink),
            Store::Unused => false,
        };
        if done {
            self.reshaded = self.reshaded.wrapping_add(1);
        }
        done
    }
}

/// Re-shades a full slot (deriving the weights on first use).
fn reshade_full<I: TriIndex, S: FragmentSink>(
    slot: &mut Slot<'_>,
    key: &GeometryKey,
    vertices: &[ProjectedVertex],
    triangles: &[[I; 3]],
    sink: &mut S,
) -> bool {
    if !slot.derived && !derive(slot, vertices, triangles, key.size) {
        slot.clear();
        return false;
    }
    let Store::Full(bufs) = &slot.store else {
        return false;
    };
    let (Some(frags), Some(ends)) = (bufs.fragments.get(..slot.fragments), bufs.tile_ends.get(..slot.tiles)) else {
        return false;
    };
    let mut start = 0usize;
    for &end in ends {
        let end = end as usize;
        for f in frags.get(start..end).unwrap_or(&[]) {
            let [a, b, c] = f.vertices;
            let (Some(va), Some(vb), Some(vc)) = (vertices.get(a as usize), vertices.get(b as usize), vertices.get(c as usize)) else {
                return false;
            };
            let color = blend(f.weights, [va.color, vb.color, vc.color]);
            if !color.iter().all(|v| v.is_finite()) {
                return false;
            }
            sink.fragment(f.pixel, color);
        }
        sink.end_tile();
        start = end;
    }
    true
}

/// Triangle set-ups a compact re-shade keeps (about 60 bytes each, on the stack).
const SETUPS: usize = 128;

/// Re-shades a compact slot: walks the tiles in the rasterizer's order, and within each its
/// covered pixels, deriving each pixel's weights from its triangle.
#[allow(clippy::too_many_arguments)]
fn reshade_compact<I: TriIndex, S: FragmentSink>(
    c: &CompactBuffers<'_>,
    fragments: usize,
    tiles: usize,
    (tw, th): (u32, u32),
    key: &GeometryKey,
    vertices: &[ProjectedVertex],
    triangles: &[[I; 3]],
    sink: &mut S,
) -> bool {
    let [w, h] = key.size;
    if tw == 0 || th == 0 || (w.div_ceil(tw) * h.div_ceil(th)) as usize != tiles {
        return false;
    }
    let Some(ids) = c.triangles.get(..fragments) else {
        return false;
    };
    let mut next = ids.iter();
    // The set-ups of recently seen triangles, direct-mapped by id: a pixel row of a tile crosses
    // a handful of triangles, and the next row mostly the same ones.
    let mut recent: [Option<(u16, FragmentSetup)>; SETUPS] = [None; SETUPS];
    // The last pixel's triangle (its set-up and vertex colours), position and small edge
    // values: the next pixel of the same triangle in the same row steps them instead of
    // evaluating them, and the triangle is not looked up again.
    let (mut cur, mut colors) = (None::<u16>, [[0.0f32; 3]; 3]);
    let mut run: Option<(u32, [i32; 3])> = None;
    for ty0 in (0..h).step_by(th as usize) {
        for tx0 in (0..w).step_by(tw as usize) {
            for y in ty0..(ty0 + th).min(h) {
                let row = y * w;
                let (start, end) = (row + tx0, row + (tx0 + tw).min(w));
                // The covered pixels of [start, end), a mask word at a time.
                let mut at = start;
                while at < end {
                    let (word, shift) = ((at / 32) as usize, at % 32);
                    let span = (32 - shift).min(end - at);
                    let Some(&bits) = c.covered.get(word) else {
                        return false;
                    };
                    let mut bits = (bits >> shift) & (u32::MAX >> (32 - span));
                    while bits != 0 {
                        let pixel = at + bits.trailing_zeros();
                        bits &= bits - 1;
                        let Some(&t) = next.next() else {
                            return false;
                        };
                        let Some(entry) = recent.get_mut(usize::from(t) % SETUPS) else {
                            return false;
                        };
                        let f = match entry {
                            Some((id, f)) if *id == t => &*f,
                            _ => {
                                let Some(f) = triangles.get(usize::from(t)).and_then(|tri| FragmentSetup::of_drawn(vertices, tri, w, h))
                                else {
                                    return false;
                                };
                                &entry.insert((t, f)).1
                            }
                        };
                        if cur != Some(t) {
                            run = None;
                            let [a, b, cc] = f.ids;
                            let (Some(va), Some(vb), Some(vc)) =
                                (vertices.get(a as usize), vertices.get(b as usize), vertices.get(cc as usize))
                            else {
                                return false;
                            };
                            (cur, colors) = (Some(t), [va.color, vb.color, vc.color]);
                        }
                        let edges = match run {
                            Some((rp, e)) if rp + 1 == pixel && pixel > row => Some(f.step_right(e)),
                            _ => f.small_edges(pixel - row, y),
                        };
                        run = edges.map(|e| (pixel, e));
                        let weights = match edges {
                            Some(e) => f.weights_from(e),
                            None => f.weights_at(pixel - row, y),
                        };
                        let Some(weights) = weights else {
                            return false;
                        };
                        let color = blend(weights, colors);
                        if !color.iter().all(|v| v.is_finite()) {
                            return false;
                        }
                        sink.fragment(pixel, color);
                    }
                    at += span;
                }
            }
            sink.end_tile();
        }
    }
    next.next().is_none()
}

/// Derives the vertex ids and weights of every fragment of `slot` (`false` if one is not drawn).
fn derive<I: TriIndex>(slot: &mut Slot<'_>, vertices: &[ProjectedVertex], triangles: &[[I; 3]], size: [u32; 2]) -> bool {
    let [w, h] = size;
    if w == 0 {
        return false;
    }
    let Store::Full(bufs) = &mut slot.store else {
        return false;
    };
    let Some(frags) = bufs.fragments.get_mut(..slot.fragments) else {
        return false;
    };
    for f in frags.iter_mut() {
        let Some(tri) = triangles.get(f.triangle as usize) else {
            return false;
        };
        let Some((ids, weights)) = fragment_weights(vertices, tri, f.pixel % w, f.pixel / w, w, h) else {
            return false;
        };
        f.vertices = ids;
        f.weights = weights;
    }
    slot.derived = true;
    true
}

/// A [`TileSink`] that forwards to an inner sink and records the frame (see [`FrameCache::recorder`]).
#[derive(Debug)]
pub struct Recorder<'r, 'c, S> {
    slot: &'r mut Slot<'c>,
    inner: &'r mut S,
    key: GeometryKey,
    overflow: bool,
    counter: &'r mut u32,
}

impl<S> Recorder<'_, '_, S> {
    /// Keeps the recorded frame (unless it did not fit).
    pub fn finish(self) {
        if !self.overflow {
            self.slot.key = Some(self.key);
            *self.counter = self.counter.wrapping_add(1);
        }
    }
}

impl<const TW: usize, const TH: usize, S: TileSink<TW, TH>> TileSink<TW, TH> for Recorder<'_, '_, S> {
    fn consume(&mut self, tile: &Tile<TW, TH>) {
        self.inner.consume(tile);
        if self.overflow {
            return;
        }
        let (x0, y0) = tile.origin();
        let (w, h) = tile.size();
        let width = self.key.size[0];
        self.slot.tile = (TW as u32, TH as u32);
        let mut n = self.slot.fragments;
        match &mut self.slot.store {
            Store::Full(bufs) => {
                for (row, y) in tile.triangles().iter().zip(y0..y0 + h) {
                    for (t, x) in row.iter().zip(x0..x0 + w) {
                        if *t == NO_TRIANGLE {
                            continue;
                        }
                        let Some(f) = bufs.fragments.get_mut(n) else {
                            self.overflow = true;
                            return;
                        };
                        *f = CachedFragment { pixel: y * width + x, triangle: *t, vertices: [0; 3], weights: [0.0; 3] };
                        n += 1;
                    }
                }
                match bufs.tile_ends.get_mut(self.slot.tiles) {
                    Some(e) => *e = n as u32,
                    None => {
                        self.overflow = true;
                        return;
                    }
                }
            }
            Store::Compact(c) => {
                for (row, y) in tile.triangles().iter().zip(y0..y0 + h) {
                    for (t, x) in row.iter().zip(x0..x0 + w) {
                        if *t == NO_TRIANGLE {
                            continue;
                        }
                        let pixel = y * width + x;
                        let (Some(slot), Ok(id), Some(bits)) =
                            (c.triangles.get_mut(n), u16::try_from(*t), c.covered.get_mut((pixel / 32) as usize))
                        else {
                            self.overflow = true;
                            return;
                        };
                        *slot = id;
                        *bits |= 1 << (pixel % 32);
                        n += 1;
                    }
                }
            }
            Store::Unused => {
                self.overflow = true;
                return;
            }
        }
        self.slot.fragments = n;
        self.slot.tiles += 1;
    }
}
