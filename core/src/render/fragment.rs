//! A drawn triangle's perspective-correct weights at any of its pixels, derived exactly as the
//! rasterizer derives them (the same integers and the same float operations, so the same bits):
//! re-shading a cached frame ([`crate::render::frame_cache`]) uses them instead of rasterizing.

use super::raster::{fetch, interpolated_inv_w, perspective_weights, setup, snap, Cull, EdgeInt, HALF, ONE, SMALL_EXTENT};
use crate::geometry::TriIndex;
use crate::render::shading::ProjectedVertex;

/// The vertex ids (in the rasterizer's set-up order) and perspective-correct weights with which
/// triangle `tri` colours pixel `(x, y)` of a `width × height` frame, exactly as
/// [`crate::render::TileRasterizer::render`] computes them (edge functions evaluated directly instead of
/// stepped: the same integers, so the same bits). `None` if the triangle would not be drawn.
pub fn fragment_weights<I: TriIndex>(
    vertices: &[ProjectedVertex],
    tri: &[I; 3],
    x: u32,
    y: u32,
    width: u32,
    height: u32,
) -> Option<([u32; 3], [f32; 3])> {
    let f = FragmentSetup::new(vertices, tri, width, height)?;
    Some((f.ids, f.weights_at(x, y)?))
}

/// One triangle's set-up for [`fragment_weights`], reusable for all its pixels.
#[derive(Debug, Clone, Copy)]
pub struct FragmentSetup {
    /// Vertex ids in the rasterizer's set-up order.
    pub ids: [u32; 3],
    inv_w: [f32; 3],
    p: [[i32; 2]; 3],
    small: bool,
    inv_area: f32,
}

impl FragmentSetup {
    /// The set-up of triangle `tri` in a `width × height` frame (`None` if it would not be drawn).
    pub fn new<I: TriIndex>(vertices: &[ProjectedVertex], tri: &[I; 3], width: u32, height: u32) -> Option<Self> {
        let v = fetch(vertices, tri)?;
        let s = setup(v, Cull::None, width, height).ok()?;
        let [va, vb, vc] = v;
        let [ia, ib, ic] = tri.map(|i| i.index() as u32);
        let (ids, inv_w) =
            if s.swapped { ([ia, ic, ib], [va.inv_w, vc.inv_w, vb.inv_w]) } else { ([ia, ib, ic], [va.inv_w, vb.inv_w, vc.inv_w]) };
        // (The same value either way; `i64 as f32` is a library call on Cortex-M4.)
        let area = if s.small { s.area as i32 as f32 } else { s.area as f32 };
        Some(Self { ids, inv_w, p: s.p, small: s.small, inv_area: 1.0 / area })
    }

    /// The set-up of triangle `tri` as drawn in a frame already rendered with these vertex
    /// positions (a re-shade): [`Self::new`] without the checks that frame passed (validity,
    /// winding, bounding box), the same values. `None` if degenerate (never for a drawn one).
    /// Colours are not looked at: a non-finite one shows in the blended colour.
    pub fn of_drawn<I: TriIndex>(vertices: &[ProjectedVertex], tri: &[I; 3], width: u32, height: u32) -> Option<Self> {
        let [va, vb, vc] = fetch(vertices, tri)?;
        let (x0, y0, x1, y1, x2, y2) = (snap(va.x), snap(va.y), snap(vb.x), snap(vb.y), snap(vc.x), snap(vc.y));
        let (min_x, max_x) = (x0.min(x1).min(x2), x0.max(x1).max(x2));
        let (min_y, max_y) = (y0.min(y1).min(y2), y0.max(y1).max(y2));
        let small = max_x - min_x < SMALL_EXTENT && max_y - min_y < SMALL_EXTENT;
        let [ia, ib, ic] = tri.map(|i| i.index() as u32);
        if small {
            let area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0);
            let (ids, inv_w, p, area) = if area < 0 {
                ([ia, ic, ib], [va.inv_w, vc.inv_w, vb.inv_w], [[x0, y0], [x2, y2], [x1, y1]], -area)
            } else {
                ([ia, ib, ic], [va.inv_w, vb.inv_w, vc.inv_w], [[x0, y0], [x1, y1], [x2, y2]], area)
            };
            (area != 0).then(|| Self { ids, inv_w, p, small, inv_area: 1.0 / area as f32 })
        } else {
            Self::new(vertices, tri, width, height)
        }
    }

    /// The perspective-correct weights at pixel `(x, y)` (`None` if the triangle does not cover it).
    pub fn weights_at(&self, x: u32, y: u32) -> Option<[f32; 3]> {
        match self.small_edges(x, y) {
            Some(e) => self.weights_from(e),
            None => {
                let l = self.edges::<i64>(x, y)?;
                let iw = interpolated_inv_w(l, self.inv_w);
                Some(perspective_weights(l, self.inv_w, iw))
            }
        }
    }

    /// The exact edge functions at the centre of `(x, y)` in `i32`, if the triangle is small and
    /// the pixel near it (else `None`: use [`Self::weights_at`]). A run of pixels to the right
    /// steps them with [`Self::step_right`] (the same integers) instead of evaluating each.
    #[inline(always)]
    pub fn small_edges(&self, x: u32, y: u32) -> Option<[i32; 3]> {
        // i32 only near the triangle, where its products cannot overflow (a small triangle's
        // pixels are within 2^14 of its vertices; a far pixel is simply not covered).
        let [px, py] = self.p[0];
        let near = |c: u32, p: i32| (i64::from(c) * i64::from(ONE) + i64::from(HALF) - i64::from(p)).abs() < 1 << 15;
        if !(self.small && near(x, px) && near(y, py)) {
            return None;
        }
        let (cx, cy) = (x as i32 * ONE + HALF, y as i32 * ONE + HALF);
        let [a, b, c] = self.p;
        let e = |pa: [i32; 2], pb: [i32; 2]| (pb[0] - pa[0]) * (cy - pa[1]) - (pb[1] - pa[1]) * (cx - pa[0]);
        Some([e(b, c), e(c, a), e(a, b)])
    }

    /// Small edge values `e` of a pixel, one pixel to the right (see [`Self::small_edges`]).
    #[inline(always)]
    pub fn step_right(&self, e: [i32; 3]) -> [i32; 3] {
        let [a, b, c] = self.p;
        [e[0] - (c[1] - b[1]) * ONE, e[1] - (a[1] - c[1]) * ONE, e[2] - (b[1] - a[1]) * ONE]
    }

    /// The perspective-correct weights from a pixel's [`Self::small_edges`] (`None` if the
    /// triangle does not cover it): [`Self::weights_at`]'s values.
    #[inline(always)]
    pub fn weights_from(&self, e: [i32; 3]) -> Option<[f32; 3]> {
        if (e[0] | e[1] | e[2]) < 0 {
            return None;
        }
        let l = e.map(|v| v as f32 * self.inv_area);
        let iw = interpolated_inv_w(l, self.inv_w);
        Some(perspective_weights(l, self.inv_w, iw))
    }

    /// The normalized edge functions at the centre of `(x, y)`, in `E` (exact in either type for
    /// a small triangle, so the same `f32`s as the rasterizer's).
    #[inline(always)]
    fn edges<E: EdgeInt>(&self, x: u32, y: u32) -> Option<[f32; 3]> {
        let (cx, cy) =
            (E::from_i32(x as i32) * E::from_i32(ONE) + E::from_i32(HALF), E::from_i32(y as i32) * E::from_i32(ONE) + E::from_i32(HALF));
        let mut l = [0.0f32; 3];
        for (k, lk) in l.iter_mut().enumerate() {
            let (pa, pb) = (self.p.get((k + 1) % 3)?, self.p.get((k + 2) % 3)?);
            let (dx, dy) = (E::from_i32(pb[0] - pa[0]), E::from_i32(pb[1] - pa[1]));
            let e = dx * (cy - E::from_i32(pa[1])) - dy * (cx - E::from_i32(pa[0]));
            if e < E::ZERO {
                return None;
            }
            *lk = e.to_f32() * self.inv_area;
        }
        Some(l)
    }
}
