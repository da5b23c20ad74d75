//! Closest points on triangle meshes: the closest point on one triangle and a uniform grid for
//! nearest-vertex queries (used by the albedo transfer, registration and the simplification error).

use crate::mesh::geometry::{add, dot, mul, norm, sub};

/// The closest point to `p` on triangle `t` and its barycentric coordinates (Ericson, Real-Time Collision Detection 5.1.5).
pub fn closest_on_triangle(p: [f64; 3], t: [[f64; 3]; 3]) -> ([f64; 3], [f64; 3]) {
    let [a, b, c] = t;
    let (ab, ac, ap) = (sub(b, a), sub(c, a), sub(p, a));
    let (d1, d2) = (dot(ab, ap), dot(ac, ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return (a, [1.0, 0.0, 0.0]);
    }
    let bp = sub(p, b);
    let (d3, d4) = (dot(ab, bp), dot(ac, bp));
    if d3 >= 0.0 && d4 <= d3 {
        return (b, [0.0, 1.0, 0.0]);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (add(a, mul(ab, v)), [1.0 - v, v, 0.0]);
    }
    let cp = sub(p, c);
    let (d5, d6) = (dot(ab, cp), dot(ac, cp));
    if d6 >= 0.0 && d5 <= d6 {
        return (c, [0.0, 0.0, 1.0]);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (add(a, mul(ac, w)), [1.0 - w, 0.0, w]);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (add(b, mul(sub(c, b), w)), [0.0, 1.0 - w, w]);
    }
    let denom = va + vb + vc;
    if !(denom.abs() > 0.0 && denom.is_finite()) {
        return (a, [1.0, 0.0, 0.0]);
    }
    let (v, w) = (vb / denom, vc / denom);
    (add(a, add(mul(ab, v), mul(ac, w))), [1.0 - v - w, v, w])
}

/// A uniform grid over points for nearest-neighbour queries.
pub struct Grid {
    lo: [f64; 3],
    cell: f64,
    dims: [usize; 3],
    /// Point indices sorted by cell; `starts[c]..starts[c + 1]` are cell `c`'s.
    order: Vec<u32>,
    starts: Vec<u32>,
}

impl Grid {
    /// Bins `points` into cubic cells of side `cell` (enlarged so that no side has more than 256 cells).
    pub fn new(points: &[[f64; 3]], cell: f64) -> Self {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in points {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        if points.is_empty() {
            lo = [0.0; 3];
            hi = [0.0; 3];
        }
        // At most 256 cells along the longest side (a huge mesh gets larger cells).
        let extent = (0..3).map(|k| hi[k] - lo[k]).fold(0.0f64, f64::max);
        let cell = if cell > 0.0 { cell.max(extent / 256.0) } else { (extent / 256.0).max(1e-9) };
        let dims = [0, 1, 2].map(|k| (((hi[k] - lo[k]) / cell).floor() as usize + 1).min(257));
        let mut grid = Self { lo, cell, dims, order: Vec::new(), starts: Vec::new() };
        let ncell = dims[0] * dims[1] * dims[2];
        let cells: Vec<usize> = points.iter().map(|p| grid.cell_index(grid.coords(*p))).collect();
        let mut counts = vec![0u32; ncell + 1];
        for &c in &cells {
            counts[c + 1] += 1;
        }
        for c in 0..ncell {
            counts[c + 1] += counts[c];
        }
        let mut fill = counts.clone();
        let mut order = vec![0u32; points.len()];
        for (i, &c) in cells.iter().enumerate() {
            order[fill[c] as usize] = i as u32;
            fill[c] += 1;
        }
        grid.order = order;
        grid.starts = counts;
        grid
    }

    fn coords(&self, p: [f64; 3]) -> [i64; 3] {
        [0, 1, 2].map(|k| (((p[k] - self.lo[k]) / self.cell).floor() as i64).clamp(0, self.dims[k] as i64 - 1))
    }

    fn cell_index(&self, c: [i64; 3]) -> usize {
        (c[2] as usize * self.dims[1] + c[1] as usize) * self.dims[0] + c[0] as usize
    }

    /// Index of the point nearest to `q` (searching shells of cells outward).
    pub fn nearest(&self, points: &[[f64; 3]], q: [f64; 3]) -> Option<usize> {
        let c = self.coords(q);
        let maxr = self.dims.iter().copied().max().unwrap_or(1) as i64;
        let mut best: Option<(f64, usize)> = None;
        for r in 0..=maxr {
            for z in (c[2] - r).max(0)..=(c[2] + r).min(self.dims[2] as i64 - 1) {
                for y in (c[1] - r).max(0)..=(c[1] + r).min(self.dims[1] as i64 - 1) {
                    for x in (c[0] - r).max(0)..=(c[0] + r).min(self.dims[0] as i64 - 1) {
                        let on_shell = (x - c[0]).abs() == r || (y - c[1]).abs() == r || (z - c[2]).abs() == r;
                        if !on_shell {
                            continue;
                        }
                        let cell = self.cell_index([x, y, z]);
                        for &i in &self.order[self.starts[cell] as usize..self.starts[cell + 1] as usize] {
                            let d = norm(sub(points[i as usize], q));
                            if best.is_none_or(|(bd, _)| d < bd) {
                                best = Some((d, i as usize));
                            }
                        }
                    }
                }
            }
            // Every point in a shell beyond r lies at least r whole cells away from q.
            if let Some((bd, _)) = best {
                if bd <= r as f64 * self.cell {
                    break;
                }
            }
        }
        best.map(|(_, i)| i)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::geometry::dist2;

    #[test]
    fn distances_to_a_triangle_from_every_region() {
        let t = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let d2 = |p: [f64; 3]| dist2(closest_on_triangle(p, t).0, p);
        assert!((d2([0.2, 0.2, 3.0]) - 9.0).abs() < 1e-12);
        assert!((d2([-1.0, -1.0, 0.0]) - 2.0).abs() < 1e-12);
        assert!((d2([2.0, 0.0, 0.0]) - 1.0).abs() < 1e-12);
        assert!((d2([1.0, 1.0, 0.0]) - 0.5).abs() < 1e-12);
        assert!((d2([0.5, -2.0, 0.0]) - 4.0).abs() < 1e-12);
    }
}
