//! The covered pixels of recent frames, kept so that a change of colour or light is re-shaded
//! without the rasterizer.
//!
//! A colour or light change moves no vertex on screen: coverage, visibility and each pixel's
//! triangle and weights stay as they were; only the vertex colours change. While a frame is
//! rendered, [`FrameCache::recorder`] wraps the sink and notes, tile by tile, every covered pixel
//! and its triangle. The first re-shade of that geometry derives each pixel's vertex ids and
//! perspective-correct weights ([`crate::raster::fragment_weights`], the rasterizer's own
//! arithmetic); every later one blends the new vertex colours with them ([`crate::raster::blend`])
//! and hands the pixels, tile by tile and in the rasterizer's order, to a [`FragmentSink`]: the
//! same colours in the same order, so the same sums to the bit.
//!
//! Two slots (two geometries) are kept, the last two recorded: after a rejected pose or shape
//! proposal the chain's own frame is still there. Memory is the caller's: per slot one
//! [`CachedFragment`] per pixel that may be covered and one entry per tile. A frame that does
//! not fit is simply not kept.

use crate::raster::{blend, fragment_weights};
use crate::render::pose::Pose;
use crate::render::shading::{ProjectedVertex, TriIndex};
use crate::render::tile::{Tile, TileSink, NO_TRIANGLE};
use crate::Vec3;

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

#[derive(Debug)]
struct Slot<'c> {
    bufs: FrameBuffers<'c>,
    fragments: usize,
    tiles: usize,
    key: Option<GeometryKey>,
    derived: bool,
}

impl Slot<'_> {
    fn clear(&mut self) {
        self.fragments = 0;
        self.tiles = 0;
        self.key = None;
        self.derived = false;
    }
}

/// Receives a re-shaded frame: covered pixels tile by tile, in the rasterizer's order.
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
        let slot = |bufs| Slot { bufs, fragments: 0, tiles: 0, key: None, derived: false };
        Self { slots: [slot(a), slot(b)], newest: 0, reshaded: 0, recorded: 0 }
    }

    /// Forgets every frame.
    pub fn clear(&mut self) {
        for s in self.slots.iter_mut() {
            s.clear();
        }
    }

    /// Whether a frame of geometry `key` is kept.
    pub fn contains(&self, key: &GeometryKey) -> bool {
        self.slots.iter().any(|s| s.key.as_ref() == Some(key))
    }

    /// A sink that passes every tile to `inner` and records the frame for geometry `key` in a
    /// slot that does not hold `keep` (the chain's own frame), else the older one. Call
    /// [`Recorder::finish`] after a successful render: only then is the frame kept.
    pub fn recorder<'r, S>(&'r mut self, key: GeometryKey, keep: Option<GeometryKey>, inner: &'r mut S) -> Recorder<'r, 'c, S> {
        let [a, b] = &self.slots;
        let older = if keep.is_some() && a.key == keep {
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
        Recorder { slot, inner, key, overflow: false, counter: &mut self.recorded }
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
        if !slot.derived && !derive(slot, vertices, triangles, key.size) {
            slot.clear();
            return false;
        }
        let (Some(frags), Some(ends)) = (slot.bufs.fragments.get(..slot.fragments), slot.bufs.tile_ends.get(..slot.tiles)) else {
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
        self.reshaded = self.reshaded.wrapping_add(1);
        true
    }
}

/// Derives the vertex ids and weights of every fragment of `slot` (`false` if one is not drawn).
fn derive<I: TriIndex>(slot: &mut Slot<'_>, vertices: &[ProjectedVertex], triangles: &[[I; 3]], size: [u32; 2]) -> bool {
    let [w, h] = size;
    if w == 0 {
        return false;
    }
    let Some(frags) = slot.bufs.fragments.get_mut(..slot.fragments) else {
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
        let mut n = self.slot.fragments;
        for (row, y) in tile.triangles().iter().zip(y0..y0 + h) {
            for (t, x) in row.iter().zip(x0..x0 + w) {
                if *t == NO_TRIANGLE {
                    continue;
                }
                let Some(f) = self.slot.bufs.fragments.get_mut(n) else {
                    self.overflow = true;
                    return;
                };
                *f = CachedFragment { pixel: y * width + x, triangle: *t, vertices: [0; 3], weights: [0.0; 3] };
                n += 1;
            }
        }
        self.slot.fragments = n;
        match self.slot.bufs.tile_ends.get_mut(self.slot.tiles) {
            Some(e) => {
                *e = n as u32;
                self.slot.tiles += 1;
            }
            None => self.overflow = true,
        }
    }
}
