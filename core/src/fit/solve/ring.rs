//! The triangles around sampled vertices, gathered a chunk of samples at a time in one pass over
//! the mesh: a vertex normal depends on its one-ring only, so the shape solve recomputes a
//! sample's normal under a moved shape from its ring instead of over the whole mesh, and needs no
//! per-vertex or per-sample storage beyond one chunk.

use crate::geometry::{TriIndex, Vec3};
use crate::render::shading::{face_normal, unit_or_zero};

/// Most triangle corners at one sampled vertex; a vertex in more is left out of the solve.
pub(super) const RING: usize = 16;
/// Most distinct vertices of one ring: the centre and two more per triangle.
pub(super) const RING_VERTICES: usize = 2 * RING + 1;
/// Samples whose rings one pass over the triangles gathers.
const CHUNK: usize = 32;

/// Up to [`CHUNK`] samples (ascending vertex ids) with their base residuals and the triangles
/// around each, in mesh order.
pub(super) struct Chunk {
    vertices: [u32; CHUNK],
    residuals: [Vec3; CHUNK],
    triangles: [[u32; RING]; CHUNK],
    /// Corners gathered per sample; `RING + 1` marks a vertex in more than [`RING`].
    corners: [usize; CHUNK],
    count: usize,
}

impl Chunk {
    /// An empty chunk.
    pub(super) fn new() -> Self {
        Self { vertices: [0; CHUNK], residuals: [[0.0; 3]; CHUNK], triangles: [[0; RING]; CHUNK], corners: [0; CHUNK], count: 0 }
    }

    /// Forgets the samples.
    pub(super) fn clear(&mut self) {
        self.count = 0;
    }

    /// Whether the chunk holds [`CHUNK`] samples.
    pub(super) fn is_full(&self) -> bool {
        self.count >= CHUNK
    }

    /// Adds sample `vertex` (above every one held) with its residual; ignored when full.
    pub(super) fn push(&mut self, vertex: usize, residual: Vec3) {
        if let (Some(v), Some(r), Some(c)) =
            (self.vertices.get_mut(self.count), self.residuals.get_mut(self.count), self.corners.get_mut(self.count))
        {
            *v = vertex as u32;
            *r = residual;
            *c = 0;
            self.count += 1;
        }
    }

    /// Gathers the triangles around the samples: each triangle once per corner at a sample, in
    /// mesh order (the order [`crate::render::shading::vertex_normals`] sums them in).
    pub(super) fn gather<I: TriIndex>(&mut self, triangles: &[[I; 3]]) {
        let held = self.vertices.get(..self.count).unwrap_or(&[]);
        let (Some(&first), Some(&last)) = (held.first(), held.last()) else { return };
        for (t, tri) in triangles.iter().enumerate() {
            for corner in tri {
                let v = corner.index();
                if v < first as usize || v > last as usize {
                    continue;
                }
                let Ok(s) = held.binary_search(&(v as u32)) else { continue };
                let (Some(n), Some(list)) = (self.corners.get_mut(s), self.triangles.get_mut(s)) else { continue };
                if let Some(slot) = list.get_mut(*n) {
                    *slot = t as u32;
                }
                *n = (*n + 1).min(RING + 1);
            }
        }
    }

    /// The samples: vertex, base residual and ring (those in more than [`RING`] triangles left out).
    pub(super) fn samples<'c, I: TriIndex>(&'c self, triangles: &'c [[I; 3]]) -> impl Iterator<Item = (usize, Vec3, Ring)> + 'c {
        let held = self.vertices.iter().zip(self.residuals.iter()).zip(self.triangles.iter().zip(self.corners.iter()));
        held.take(self.count).filter_map(move |((&v, &r), (list, &n))| {
            let list = list.get(..n)?;
            Some((v as usize, r, Ring::new(v, list, triangles)?))
        })
    }
}

/// One sample's triangles as corners into the ring's distinct vertices (the sample first).
pub(super) struct Ring {
    vertices: [u32; RING_VERTICES],
    vertex_count: usize,
    corners: [[u8; 3]; RING],
    triangle_count: usize,
}

impl Ring {
    /// The ring of `centre` made of `list` (triangle ids into `triangles`); `None` if one is missing.
    fn new<I: TriIndex>(centre: u32, list: &[u32], triangles: &[[I; 3]]) -> Option<Self> {
        let mut ring = Self { vertices: [0; RING_VERTICES], vertex_count: 1, corners: [[0; 3]; RING], triangle_count: 0 };
        *ring.vertices.first_mut()? = centre;
        for (&t, corners) in list.iter().zip(ring.corners.iter_mut()) {
            let tri = triangles.get(t as usize)?;
            for (corner, v) in corners.iter_mut().zip(tri.iter().map(|i| i.index() as u32)) {
                let held = ring.vertices.get(..ring.vertex_count)?;
                let at = match held.iter().position(|&u| u == v) {
                    Some(at) => at,
                    None => {
                        *ring.vertices.get_mut(ring.vertex_count)? = v;
                        ring.vertex_count += 1;
                        ring.vertex_count - 1
                    }
                };
                *corner = at as u8;
            }
            ring.triangle_count += 1;
        }
        Some(ring)
    }

    /// The ring's distinct vertices, the sample first.
    pub(super) fn vertices(&self) -> &[u32] {
        self.vertices.get(..self.vertex_count).unwrap_or(&[])
    }

    /// The sample's unit normal with the ring's vertices at `at` (one per [`Self::vertices`]):
    /// the same sums as [`crate::render::shading::vertex_normals`] over the whole mesh.
    pub(super) fn normal(&self, at: &[Vec3]) -> Vec3 {
        let mut sum = [0.0f32; 3];
        for c in self.corners.iter().take(self.triangle_count) {
            let (Some(&a), Some(&b), Some(&c)) = (at.get(c[0] as usize), at.get(c[1] as usize), at.get(c[2] as usize)) else {
                continue;
            };
            let f = face_normal(a, b, c);
            sum[0] += f[0];
            sum[1] += f[1];
            sum[2] += f[2];
        }
        unit_or_zero(sum)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;
    use crate::render::shading::vertex_normals;

    #[test]
    fn ring_normals_equal_the_whole_mesh_normals_bit_for_bit() {
        // A bumpy 6 × 6 grid of vertices, two triangles a cell.
        let side = 6usize;
        let positions: [Vec3; 36] = core::array::from_fn(|i| {
            let (x, y) = ((i % side) as f32, (i / side) as f32);
            [x * 10.0, y * 10.0, libm::sinf(x * 1.3) * libm::cosf(y * 0.7) * 4.0]
        });
        let mut triangles = [[0u16; 3]; 50];
        for (c, pair) in triangles.chunks_exact_mut(2).enumerate() {
            let (x, y) = (c % (side - 1), c / (side - 1));
            let v = (y * side + x) as u16;
            pair[0] = [v, v + 1, v + side as u16];
            pair[1] = [v + 1, v + side as u16 + 1, v + side as u16];
        }
        let mut normals = [[0.0f32; 3]; 36];
        vertex_normals(&positions, &triangles, &mut normals).unwrap();
        let mut chunk = Chunk::new();
        for v in (0..36).step_by(5) {
            chunk.push(v, [v as f32; 3]);
        }
        chunk.gather(&triangles);
        let mut seen = 0;
        for (v, r, ring) in chunk.samples(&triangles) {
            let at: heapless::Vec<Vec3, RING_VERTICES> = ring.vertices().iter().map(|&u| positions[u as usize]).collect();
            assert_eq!(ring.normal(&at), normals[v], "vertex {v}");
            assert_eq!(r, [v as f32; 3]);
            seen += 1;
        }
        assert_eq!(seen, 8);
    }
}
