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

/// A standard-normal sample by the Box–Muller transform (one of the pair is used; two `u32` draws per sample).
pub fn standard_normal<R: Rng + ?Sized>(rng: &mut R) -> f32 {
    let u1 = uniform_open0(rng);
    let u2 = uniform(rng);
    libm::sqrtf(-2.0 * libm::logf(u1)) * libm::cosf(core::f32::consts::TAU * u2)
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
