//! The mesh calculus of shape from shading: vertex normals and their gradient (back through the
//! area-weighted sums of the one-rings, as the core computes normals), the gradient of an SH
//! irradiance in the normal, the mesh Laplacian of the offsets, and spike removal.

use gpmm_core::render::light::{LAMBERT_KERNEL, N1, N2_0, N2_1, N2_2};
use gpmm_core::render::ShLight;

type Vec3 = [f32; 3];

fn sub(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: Vec3, b: Vec3) -> Vec3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

fn dot(a: Vec3, b: Vec3) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Each vertex's neighbours (the vertices it shares an edge with), sorted.
pub fn neighbours(vertices: usize, triangles: &[[u32; 3]]) -> Vec<Vec<u32>> {
    let mut out = vec![Vec::new(); vertices];
    for t in triangles {
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            if let (Some(_), Some(_)) = (out.get(a as usize), out.get(b as usize)) {
                out[a as usize].push(b);
                out[b as usize].push(a);
            }
        }
    }
    for n in &mut out {
        n.sort_unstable();
        n.dedup();
    }
    out
}

/// The summed (unnormalized) area-weighted normals of `positions`: the core's `vertex_normals`
/// before it makes them unit.
pub fn summed_normals(positions: &[Vec3], triangles: &[[u32; 3]]) -> Vec<Vec3> {
    let mut m = vec![[0.0f32; 3]; positions.len()];
    for t in triangles {
        let [a, b, c] = t.map(|i| positions[i as usize]);
        let f = cross(sub(b, a), sub(c, a));
        for i in t {
            let s = &mut m[*i as usize];
            s[0] += f[0];
            s[1] += f[1];
            s[2] += f[2];
        }
    }
    m
}

/// `v / |v|`, zero for a zero vector.
pub fn unit(v: Vec3) -> Vec3 {
    let len = dot(v, v).sqrt();
    if len > 0.0 && len.is_finite() {
        [v[0] / len, v[1] / len, v[2] / len]
    } else {
        [0.0; 3]
    }
}

/// The gradient in the positions of a function of the unit normals, given its gradient `g[v]` in
/// each unit normal (zero where it does not depend on one) and the summed normals `m`: through
/// `n = m / |m|` and `m = Σ (b − a) × (c − a)` over the one-ring. Added to `out`.
pub fn normal_gradient(positions: &[Vec3], triangles: &[[u32; 3]], m: &[Vec3], g: &[Vec3], out: &mut [Vec3]) {
    // The gradient in each summed normal.
    let gm: Vec<Vec3> = m
        .iter()
        .zip(g)
        .map(|(m, g)| {
            let len = dot(*m, *m).sqrt();
            if len.is_nan() || len <= 0.0 || *g == [0.0; 3] {
                return [0.0; 3];
            }
            let n = [m[0] / len, m[1] / len, m[2] / len];
            let along = dot(n, *g);
            [(g[0] - n[0] * along) / len, (g[1] - n[1] * along) / len, (g[2] - n[2] * along) / len]
        })
        .collect();
    for t in triangles {
        let [ia, ib, ic] = t.map(|i| i as usize);
        let s = [gm[ia], gm[ib], gm[ic]];
        let big_g = [s[0][0] + s[1][0] + s[2][0], s[0][1] + s[1][1] + s[2][1], s[0][2] + s[1][2] + s[2][2]];
        if big_g == [0.0; 3] {
            continue;
        }
        let (u, w) = (sub(positions[ib], positions[ia]), sub(positions[ic], positions[ia]));
        // d((u × w)·G) = du·(w × G) + dw·(G × u).
        let (db, dc) = (cross(w, big_g), cross(big_g, u));
        for (i, d) in [(ia, [-db[0] - dc[0], -db[1] - dc[1], -db[2] - dc[2]]), (ib, db), (ic, dc)] {
            out[i][0] += d[0];
            out[i][1] += d[1];
            out[i][2] += d[2];
        }
    }
}

/// The SH irradiance of the unit camera-space normal `n` and its gradient in `n`, per channel:
/// `(e, [∂e_r/∂n, ∂e_g/∂n, ∂e_b/∂n])`.
pub fn irradiance_and_gradient(light: &ShLight, n: Vec3) -> (Vec3, [Vec3; 3]) {
    let [x, y, z] = n;
    // ∇Y_i for the real SH basis of the core (order: 1, y, z, x, xy, yz, 3z²−1, zx, x²−y²).
    let grads: [Vec3; 9] = [
        [0.0; 3],
        [0.0, N1, 0.0],
        [0.0, 0.0, N1],
        [N1, 0.0, 0.0],
        [N2_1 * y, N2_1 * x, 0.0],
        [0.0, N2_1 * z, N2_1 * y],
        [-2.0 * N2_0 * x, -2.0 * N2_0 * y, 4.0 * N2_0 * z],
        [N2_1 * z, 0.0, N2_1 * x],
        [2.0 * N2_2 * x, -2.0 * N2_2 * y, 0.0],
    ];
    let e = light.irradiance(n);
    let mut de = [[0.0f32; 3]; 3];
    for ((gi, k), c) in grads.iter().zip(LAMBERT_KERNEL).zip(&light.coeffs) {
        for (ch, d) in de.iter_mut().enumerate() {
            for (dj, gij) in d.iter_mut().zip(gi) {
                *dj += k * c[ch] * gij;
            }
        }
    }
    (e, de)
}

/// `L h`: each value minus the mean of its neighbours' (zero for a vertex without neighbours).
pub fn laplacian(h: &[f32], neighbours: &[Vec<u32>]) -> Vec<f32> {
    h.iter()
        .zip(neighbours)
        .map(|(hv, nb)| if nb.is_empty() { 0.0 } else { hv - nb.iter().map(|&u| h[u as usize]).sum::<f32>() / nb.len() as f32 })
        .collect()
}

/// Adds the gradient of `μ |L h|²` (given `lh = L h`) to `out`.
pub fn laplacian_gradient(lh: &[f32], neighbours: &[Vec<u32>], mu: f32, out: &mut [f32]) {
    for (v, (l, nb)) in lh.iter().zip(neighbours).enumerate() {
        if nb.is_empty() {
            continue;
        }
        let g = 2.0 * mu * l;
        out[v] += g;
        let share = g / nb.len() as f32;
        for &u in nb {
            out[u as usize] -= share;
        }
    }
}

/// `values` with every spike removed: a value outside the range of its neighbours' values is
/// clamped into that range (a single vertex cannot stand out of its ring; a broad detail, whose
/// neighbours rise with it, is kept).
pub fn despike(values: &[f32], neighbours: &[Vec<u32>]) -> Vec<f32> {
    values
        .iter()
        .zip(neighbours)
        .map(|(&x, nb)| {
            let (lo, hi) =
                nb.iter().map(|&u| values[u as usize]).fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), y| (lo.min(y), hi.max(y)));
            if lo <= hi {
                x.clamp(lo, hi)
            } else {
                x
            }
        })
        .collect()
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// A small pyramid: the analytic gradients agree with central differences.
    #[test]
    fn gradients_agree_with_differences() {
        let positions = vec![[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.2, 0.1], [-1.0, 0.1, 0.0], [0.1, -1.0, 0.2]];
        let triangles = vec![[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 1]];
        let light = ShLight {
            coeffs: [
                [0.9, 0.8, 0.7],
                [0.1, 0.2, 0.0],
                [0.3, 0.2, 0.4],
                [-0.2, 0.1, 0.1],
                [0.05, 0.0, 0.1],
                [0.0, 0.1, 0.0],
                [0.1, 0.1, 0.1],
                [0.0, -0.1, 0.05],
                [0.02, 0.0, 0.0],
            ],
        };
        // f(positions) = Σ_v weight_v · e_ch(n_v) for a fixed channel mix.
        let weights = [[1.0, 0.5, -0.3], [0.2, 0.1, 0.4], [-0.5, 0.3, 0.2], [0.3, 0.3, 0.3], [0.1, -0.2, 0.6]];
        let f = |p: &[Vec3]| -> f64 {
            let m = summed_normals(p, &triangles);
            m.iter().zip(&weights).map(|(m, w)| f64::from(dot(light.irradiance(unit(*m)), *w))).sum()
        };
        let m = summed_normals(&positions, &triangles);
        let g: Vec<Vec3> = m
            .iter()
            .zip(&weights)
            .map(|(m, w)| {
                let (_, de) = irradiance_and_gradient(&light, unit(*m));
                [0, 1, 2].map(|j| w[0] * de[0][j] + w[1] * de[1][j] + w[2] * de[2][j])
            })
            .collect();
        let mut analytic = vec![[0.0f32; 3]; positions.len()];
        normal_gradient(&positions, &triangles, &m, &g, &mut analytic);
        for v in 0..positions.len() {
            for j in 0..3 {
                let h = 1e-3f32;
                let (mut plus, mut minus) = (positions.clone(), positions.clone());
                plus[v][j] += h;
                minus[v][j] -= h;
                let numeric = (f(&plus) - f(&minus)) / f64::from(2.0 * h);
                assert!((numeric - f64::from(analytic[v][j])).abs() < 2e-3, "vertex {v} axis {j}: {numeric} vs {}", analytic[v][j]);
            }
        }
        // The Laplacian's gradient, likewise.
        let nb = neighbours(positions.len(), &triangles);
        assert_eq!(nb[0], vec![1, 2, 3, 4]);
        let h = [0.3f32, -0.2, 0.5, 0.1, 0.0];
        let energy = |h: &[f32]| laplacian(h, &nb).iter().map(|x| f64::from(x * x)).sum::<f64>();
        let mut grad = vec![0.0f32; 5];
        laplacian_gradient(&laplacian(&h, &nb), &nb, 1.0, &mut grad);
        for v in 0..5 {
            let (mut plus, mut minus) = (h, h);
            plus[v] += 1e-3;
            minus[v] -= 1e-3;
            let numeric = (energy(&plus) - energy(&minus)) / 2e-3;
            assert!((numeric - f64::from(grad[v])).abs() < 1e-3, "vertex {v}: {numeric} vs {}", grad[v]);
        }
    }

    #[test]
    fn despike_clamps_a_lone_vertex_only() {
        // A fan: vertex 0 in the middle, 1..4 around.
        let nb = neighbours(5, &[[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 1]]);
        let spike = despike(&[9.0, 0.0, 0.1, 0.2, 0.0], &nb);
        assert_eq!(spike[0], 0.2);
        let broad = [1.0, 0.9, 1.0, 1.1, 1.0];
        assert_eq!(despike(&broad, &nb)[0], 1.0);
    }
}
