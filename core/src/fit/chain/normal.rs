//! Uniform and standard-normal samples over any [`rand_core::Rng`] (no `rand_distr` in the core).

use rand_core::Rng;

/// A uniform sample in `(0, 1]` with 24 random bits (never 0, so its logarithm is finite).
pub fn uniform_open0<R: Rng + ?Sized>(rng: &mut R) -> f32 {
    ((rng.next_u32() >> 8) + 1) as f32 * (1.0 / 16_777_216.0)
}

/// A uniform sample in `[0, 1)` with 24 random bits.
pub fn uniform<R: Rng + ?Sized>(rng: &mut R) -> f32 {
    (rng.next_u32() >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// Attempts of the polar method before [`standard_normal_pair`] gives up and returns zeros (each
/// attempt succeeds with probability π/4: 64 failures in a row happen with probability 1e-43).
const POLAR_TRIES: u32 = 64;

/// Two independent standard-normal samples by Marsaglia's polar method.
///
/// No trigonometry: one `logf` and one `sqrtf` per pair, all in `f32`. (Box–Muller's `cosf` is
/// computed in `f64` by libm, which a Cortex-M4F emulates in software: it cost more than the
/// rest of a landmark-chain shape proposal.)
pub fn standard_normal_pair<R: Rng + ?Sized>(rng: &mut R) -> [f32; 2] {
    for _ in 0..POLAR_TRIES {
        let u = 2.0 * uniform(rng) - 1.0;
        let v = 2.0 * uniform(rng) - 1.0;
        let s = u * u + v * v;
        if s > 0.0 && s < 1.0 {
            let m = libm::sqrtf(-2.0 * libm::logf(s) / s);
            return [u * m, v * m];
        }
    }
    [0.0; 2]
}

/// One standard-normal sample (the first of a [`standard_normal_pair`]).
pub fn standard_normal<R: Rng + ?Sized>(rng: &mut R) -> f32 {
    standard_normal_pair(rng)[0]
}

/// Adds `scale · z` to every entry of `out`, with independent standard-normal `z` drawn in pairs.
pub fn add_normals<R: Rng + ?Sized>(rng: &mut R, scale: f32, out: &mut [f32]) {
    for chunk in out.chunks_mut(2) {
        let z = standard_normal_pair(rng);
        for (c, z) in chunk.iter_mut().zip(z) {
            *c += scale * z;
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;
    use rand_core::SeedableRng;
    use rand_xoshiro::Xoshiro256PlusPlus;

    #[test]
    fn moments_are_standard() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(7);
        let n = 200_000;
        let (mut s, mut s2, mut s4) = (0.0f64, 0.0f64, 0.0f64);
        for _ in 0..n {
            let x = f64::from(standard_normal(&mut rng));
            assert!(x.is_finite());
            s += x;
            s2 += x * x;
            s4 += x * x * x * x;
        }
        let n = f64::from(n);
        assert!((s / n).abs() < 0.01);
        assert!((s2 / n - 1.0).abs() < 0.02);
        assert!((s4 / n - 3.0).abs() < 0.1);
    }

    #[test]
    fn pairs_are_standard_and_uncorrelated() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
        let n = 100_000;
        let (mut s2, mut cross) = (0.0f64, 0.0f64);
        let mut v = [0.0f32; 5];
        for _ in 0..n {
            v = [0.0; 5];
            add_normals(&mut rng, 2.0, &mut v);
            s2 += v.iter().map(|x| f64::from(*x).powi(2)).sum::<f64>() / 5.0;
            cross += f64::from(v[0]) * f64::from(v[1]);
        }
        let n = f64::from(n);
        assert!((s2 / n - 4.0).abs() < 0.08, "variance of 2z: {}", s2 / n);
        assert!((cross / n).abs() < 0.08, "pair correlation: {}", cross / n);
        assert!(v.iter().all(|x| x.is_finite() && *x != 0.0));
    }

    #[test]
    fn uniform_ranges() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(1);
        for _ in 0..10_000 {
            let a = uniform_open0(&mut rng);
            let b = uniform(&mut rng);
            assert!(a > 0.0 && a <= 1.0);
            assert!((0.0..1.0).contains(&b));
        }
    }
}
