//! The chain's posterior summary: mean and standard deviation of the coefficients and the
//! rotation over the samples after a burn-in, kept by an observer that watches the chain.
//!
//! A chain's best sample is one draw that happened to score highest; where the image says
//! little (a colour direction the light explains as well) it sits wherever the chain's random
//! walk left it. The mean over the chain's samples is the posterior's own estimate, and the
//! standard deviation says how well each coefficient is determined.

use crate::fit::chain::observer::{ChainObserver, ChainSample};

/// Running mean and spread of one value (Welford's update).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct Moment {
    mean: f32,
    m2: f32,
}

impl Moment {
    /// Adds sample `x` as the `n`-th (1-based).
    fn push(&mut self, x: f32, n: u32) {
        let d = x - self.mean;
        self.mean += d / n as f32;
        self.m2 += d * (x - self.mean);
    }

    /// Standard deviation over `n` samples (0 below two).
    fn sd(&self, n: u32) -> f32 {
        if n < 2 {
            0.0
        } else {
            libm::sqrtf((self.m2 / (n - 1) as f32).max(0.0))
        }
    }
}

/// Mean and standard deviation of a chain's states from step `burn_in` on: at most `KS` shape
/// and `KC` colour coefficients, and yaw, pitch and roll. An observer: pass it (or a tuple with
/// it) to a chain.
#[derive(Debug, Clone, PartialEq)]
pub struct PosteriorMoments<const KS: usize, const KC: usize> {
    burn_in: u32,
    samples: u32,
    shape_len: usize,
    color_len: usize,
    shape: [Moment; KS],
    color: [Moment; KC],
    angles: [Moment; 3],
}

impl<const KS: usize, const KC: usize> PosteriorMoments<KS, KC> {
    /// Nothing summed yet; samples of steps before `burn_in` (0-based) are left out.
    pub fn new(burn_in: u32) -> Self {
        Self {
            burn_in,
            samples: 0,
            shape_len: 0,
            color_len: 0,
            shape: [Moment::default(); KS],
            color: [Moment::default(); KC],
            angles: [Moment::default(); 3],
        }
    }

    /// The first step counted.
    pub fn burn_in(&self) -> u32 {
        self.burn_in
    }

    /// Samples summed.
    pub fn samples(&self) -> u32 {
        self.samples
    }

    /// Mean shape coefficients (as many as the chain's samples had, at most `KS`).
    pub fn shape_mean(&self) -> impl Iterator<Item = f32> + '_ {
        self.shape.iter().take(self.shape_len).map(|m| m.mean)
    }

    /// Standard deviations of the shape coefficients.
    pub fn shape_sd(&self) -> impl Iterator<Item = f32> + '_ {
        self.shape.iter().take(self.shape_len).map(|m| m.sd(self.samples))
    }

    /// Mean colour coefficients (at most `KC`).
    pub fn color_mean(&self) -> impl Iterator<Item = f32> + '_ {
        self.color.iter().take(self.color_len).map(|m| m.mean)
    }

    /// Standard deviations of the colour coefficients.
    pub fn color_sd(&self) -> impl Iterator<Item = f32> + '_ {
        self.color.iter().take(self.color_len).map(|m| m.sd(self.samples))
    }

    /// Mean yaw, pitch and roll (radians; the chains' angles stay far from ±π).
    pub fn angles_mean(&self) -> [f32; 3] {
        self.angles.map(|m| m.mean)
    }

    /// Standard deviations of yaw, pitch and roll (radians).
    pub fn angles_sd(&self) -> [f32; 3] {
        self.angles.map(|m| m.sd(self.samples))
    }
}

impl<const KS: usize, const KC: usize> ChainObserver for PosteriorMoments<KS, KC> {
    fn sample(&mut self, s: &ChainSample<'_>) {
        if s.step < self.burn_in {
            return;
        }
        // A chain keeps its lengths; a sample with other lengths restarts the summary.
        let (ns, nc) = (s.shape.len().min(KS), s.color.len().min(KC));
        if self.samples > 0 && (ns != self.shape_len || nc != self.color_len) {
            *self = Self::new(self.burn_in);
        }
        self.shape_len = ns;
        self.color_len = nc;
        self.samples = self.samples.saturating_add(1);
        let n = self.samples;
        self.shape.iter_mut().zip(s.shape).for_each(|(m, &x)| m.push(x, n));
        self.color.iter_mut().zip(s.color).for_each(|(m, &x)| m.push(x, n));
        let angles = [s.pose.yaw, s.pose.pitch, s.pose.roll];
        self.angles.iter_mut().zip(angles).for_each(|(m, x)| m.push(x, n));
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::render::{Pose, ShLight};

    fn sample<'a>(step: u32, pose: &'a Pose, light: &'a ShLight, shape: &'a [f32], color: &'a [f32]) -> ChainSample<'a> {
        ChainSample { step, pose, light, shape, color }
    }

    #[test]
    fn mean_and_sd_of_the_samples_after_the_burn_in() {
        let light = ShLight::ambient([0.5; 3]);
        let mut m = PosteriorMoments::<4, 2>::new(2);
        let values = [(100.0f32, 0.3f32), (100.0, 0.3), (1.0, 0.1), (2.0, 0.2), (3.0, 0.3), (6.0, 0.6)];
        for (step, &(a, yaw)) in values.iter().enumerate() {
            let pose = Pose { yaw, ..Pose::frontal(500.0) };
            m.sample(&sample(step as u32, &pose, &light, &[a, -a, 0.0], &[2.0 * a]));
        }
        assert_eq!((m.samples(), m.burn_in()), (4, 2));
        let mean: [f32; 3] = core::array::from_fn(|i| m.shape_mean().nth(i).unwrap());
        assert_eq!(m.shape_mean().count(), 3);
        assert!((mean[0] - 3.0).abs() < 1e-6 && (mean[1] + 3.0).abs() < 1e-6 && mean[2] == 0.0, "{mean:?}");
        // Sample standard deviation of 1, 2, 3, 6: sqrt(14 / 3).
        let sd = m.shape_sd().next().unwrap();
        assert!((sd - (14.0f32 / 3.0).sqrt()).abs() < 1e-5, "{sd}");
        assert!((m.color_mean().next().unwrap() - 6.0).abs() < 1e-6);
        assert!((m.color_sd().next().unwrap() - 2.0 * sd).abs() < 1e-5);
        assert!((m.angles_mean()[0] - 0.3).abs() < 1e-6 && m.angles_mean()[1] == 0.0);
        assert!((m.angles_sd()[0] - sd / 10.0).abs() < 1e-6);
    }

    #[test]
    fn nothing_before_the_burn_in_and_capacity_bounds_the_lengths() {
        let (light, pose) = (ShLight::ambient([0.5; 3]), Pose::frontal(500.0));
        let mut m = PosteriorMoments::<2, 1>::new(5);
        m.sample(&sample(4, &pose, &light, &[1.0, 2.0, 3.0], &[1.0, 1.0]));
        assert_eq!((m.samples(), m.shape_mean().count(), m.shape_sd().next()), (0, 0, None));
        m.sample(&sample(5, &pose, &light, &[1.0, 2.0, 3.0], &[1.0, 1.0]));
        assert_eq!((m.samples(), m.shape_mean().count(), m.color_mean().count()), (1, 2, 1));
        assert_eq!(m.shape_sd().collect::<heapless::Vec<f32, 2>>().as_slice(), &[0.0, 0.0]);
        // Other lengths start the summary again.
        m.sample(&sample(6, &pose, &light, &[4.0], &[2.0]));
        assert_eq!((m.samples(), m.shape_mean().collect::<heapless::Vec<f32, 2>>().as_slice()), (1, &[4.0][..]));
    }
}
