//! Plainer skin for some training scenes: the scan's albedo (pores, stubble, its own blotches)
//! diffused over the mesh, so that the networks also learn faces whose colour says less than the
//! one scan's does and read them from their shape and shading (make-up, smooth skin, other
//! renderers' skin models).

use gpmm_core::geometry::Vec3;
use rand::{Rng, RngExt};

/// How plain the skin of a scene is drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlainSkin {
    /// Fraction of scenes whose skin is made plainer (0: none, the default).
    pub fraction: f32,
    /// Largest number of diffusion steps (each averages every vertex with its mesh neighbours).
    pub max_steps: usize,
}

impl Default for PlainSkin {
    fn default() -> Self {
        Self { fraction: 0.0, max_steps: 30 }
    }
}

impl PlainSkin {
    /// Makes `albedos` (the vertices of `triangles`) plainer in a fraction of draws: between 4 and
    /// `max_steps` diffusion steps, blended in by 0.5..1. Returns whether it did.
    pub fn apply(&self, albedos: &mut [Vec3], triangles: &[[u32; 3]], rng: &mut impl Rng) -> bool {
        if self.fraction <= 0.0 || rng.random_range(0.0f32..1.0) >= self.fraction {
            return false;
        }
        let steps = rng.random_range(4..=self.max_steps.max(4));
        let amount = rng.random_range(0.5f32..=1.0);
        let smooth = diffused(albedos, triangles, steps);
        for (a, s) in albedos.iter_mut().zip(&smooth) {
            *a = std::array::from_fn(|k| a[k] + (s[k] - a[k]) * amount);
        }
        true
    }
}

/// `albedos` after `steps` rounds of averaging each vertex with its edge neighbours (vertices no
/// triangle uses keep their colour; indices past the slice are ignored).
pub fn diffused(albedos: &[Vec3], triangles: &[[u32; 3]], steps: usize) -> Vec<Vec3> {
    let n = albedos.len();
    let mut neighbours: Vec<Vec<u32>> = vec![Vec::new(); n];
    for t in triangles {
        if t.iter().any(|&v| v as usize >= n) {
            continue;
        }
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            neighbours[a as usize].push(b);
            neighbours[b as usize].push(a);
        }
    }
    for list in &mut neighbours {
        list.sort_unstable();
        list.dedup();
    }
    let mut current = albedos.to_vec();
    let mut next = current.clone();
    for _ in 0..steps {
        for (v, out) in next.iter_mut().enumerate() {
            let mut sum = current[v];
            for &u in &neighbours[v] {
                let c = current[u as usize];
                sum = [sum[0] + c[0], sum[1] + c[1], sum[2] + c[2]];
            }
            let k = 1.0 / (neighbours[v].len() + 1) as f32;
            *out = sum.map(|s| s * k);
        }
        std::mem::swap(&mut current, &mut next);
    }
    current
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use rand::SeedableRng;
    use rand_xoshiro::Xoshiro256PlusPlus;

    /// A strip of `n` squares (2 triangles each) along x.
    fn strip(n: u32) -> Vec<[u32; 3]> {
        (0..n).flat_map(|i| [[2 * i, 2 * i + 2, 2 * i + 1], [2 * i + 1, 2 * i + 2, 2 * i + 3]]).collect()
    }

    #[test]
    fn diffusion_spreads_a_spot_and_keeps_a_flat_colour() {
        let tris = strip(10);
        let mut albedos = vec![[0.5f32; 3]; 22];
        albedos[10] = [1.0, 0.0, 0.5];
        let out = diffused(&albedos, &tris, 4);
        // The spot spreads: it dims, its neighbours take some of it.
        assert!(out[10][0] < 0.8 && out[10][1] > 0.2, "{:?}", out[10]);
        assert!(out[12][0] > 0.5 && out[8][0] > 0.5);
        // Far vertices have not seen it yet (4 steps reach 4 edges; vertex 0 is 5 away).
        assert_eq!(out[0], [0.5; 3]);
        // A flat colour stays flat.
        let flat = diffused(&[[0.3f32; 3]; 22], &tris, 7);
        assert!(flat.iter().all(|c| c.iter().all(|v| (v - 0.3).abs() < 1e-6)));
    }

    #[test]
    fn bad_triangles_are_ignored_and_the_default_changes_nothing() {
        let mut albedos = vec![[0.2f32; 3], [0.8; 3], [0.5; 3]];
        let out = diffused(&albedos, &[[0, 1, 7]], 3);
        assert_eq!(out, albedos);
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
        let before = albedos.clone();
        assert!(!PlainSkin::default().apply(&mut albedos, &[[0, 1, 2]], &mut rng));
        assert_eq!(albedos, before);
        let always = PlainSkin { fraction: 1.0, max_steps: 8 };
        assert!(always.apply(&mut albedos, &[[0, 1, 2]], &mut rng));
        let spread = |a: &[Vec3]| a.iter().map(|c| c[0]).fold(0.0f32, f32::max) - a.iter().map(|c| c[0]).fold(1.0f32, f32::min);
        assert!(spread(&albedos) < 0.5 * spread(&before));
    }
}
