//! Kernel matrices a column at a time: every kernel of a [`KernelBank`] between one point and a
//! run of points, with the points stored as columns (structure of arrays) and an exponential
//! the compiler vectorizes, so a column costs a few SIMD instructions per entry instead of a
//! libm call per term (the model build's kernel matrices; docs/design.md, "Model building").
//!
//! The values equal [`KernelBank::eval_into`]'s up to the exponential ([`exp_neg`] is within
//! 2 ulp of libm's; the sums run in the same order).

use crate::gp::kernel::{KernelBank, KernelPoint, Space};
use faer::traits::pulp::{Arch, Simd, WithSimd};
use std::ops::Range;

/// The coordinates of many points as separate arrays (x, y, z and r, g, b).
#[derive(Debug, Clone, PartialEq)]
pub struct PointColumns {
    position: [Vec<f64>; 3],
    color: [Vec<f64>; 3],
}

impl PointColumns {
    /// The columns of `points`.
    pub fn new(points: &[KernelPoint]) -> Self {
        let column = |f: &dyn Fn(&KernelPoint) -> f64| points.iter().map(f).collect::<Vec<_>>();
        Self {
            position: [column(&|p| p.position[0]), column(&|p| p.position[1]), column(&|p| p.position[2])],
            color: [column(&|p| p.color[0]), column(&|p| p.color[1]), column(&|p| p.color[2])],
        }
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.position[0].len()
    }

    /// Whether there are no points.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Entries per inner pass: the distances, one exponential and the outputs stay in L1.
const CHUNK: usize = 256;

/// Arguments above this give a zero term, as in the scalar kernel (`exp(-40)` is 4e-18 of the weight).
const CUTOFF: f64 = 40.0;

/// `exp(x)` for `x` in `[-CUTOFF - 1, 0]`, in plain arithmetic the compiler vectorizes: `x = k ln 2 + r`
/// with `|r| ≤ ln 2 / 2` (Cody–Waite, fdlibm's split of ln 2), the degree-13 Taylor polynomial of
/// `e^r` (truncation below 2e-17), and `2^k` written into the exponent bits. Within 2 ulp of libm
/// on that range (tested).
#[inline(always)]
pub fn exp_neg(x: f64) -> f64 {
    // fdlibm's ln2_hi (low 32 bits zero, so k · LN2_HI is exact) and ln2_lo.
    const LN2_HI: f64 = f64::from_bits(0x3fe6_2e42_fee0_0000);
    const LN2_LO: f64 = f64::from_bits(0x3dea_39ef_3579_3c76);
    // 1.5 · 2^52: adding it rounds to an integer held in the low mantissa bits.
    const SHIFTER: f64 = 6_755_399_441_055_744.0;
    let t = x * std::f64::consts::LOG2_E + SHIFTER;
    let k = t - SHIFTER;
    let r = (x - k * LN2_HI) - k * LN2_LO;
    let mut p = 1.0 / 6_227_020_800.0; // 1/13!
    for c in [
        1.0 / 479_001_600.0,
        1.0 / 39_916_800.0,
        1.0 / 3_628_800.0,
        1.0 / 362_880.0,
        1.0 / 40_320.0,
        1.0 / 5_040.0,
        1.0 / 720.0,
        1.0 / 120.0,
        1.0 / 24.0,
        1.0 / 6.0,
        0.5,
        1.0,
        1.0,
    ] {
        p = p * r + c;
    }
    // t's bits are SHIFTER's plus k (k ≥ -60 here), so this is the biased exponent of 2^k.
    let scale = f64::from_bits(t.to_bits().wrapping_sub(SHIFTER.to_bits()).wrapping_add(1023) << 52);
    p * scale
}

/// `d²` between point `b` and the points `start..start + out.len()` in `space`.
#[inline(always)]
fn squared_distances(points: &PointColumns, start: usize, b: &KernelPoint, space: Space, out: &mut [f64]) {
    let (columns, target) = match space {
        Space::Position => (&points.position, b.position),
        Space::MirroredPosition => (&points.position, [-b.position[0], b.position[1], b.position[2]]),
        Space::Color => (&points.color, b.color),
    };
    let end = start + out.len();
    let (xs, ys, zs) = (&columns[0][start..end], &columns[1][start..end], &columns[2][start..end]);
    for (((o, x), y), z) in out.iter_mut().zip(xs).zip(ys).zip(zs) {
        let (dx, dy, dz) = (x - target[0], y - target[1], z - target[2]);
        *o = dx * dx + dy * dy + dz * dz;
    }
}

impl KernelBank {
    /// Every kernel of the bank between the points `rows` and `b`: kernel `k`'s values go to
    /// `out[k * rows.len()..(k + 1) * rows.len()]` (the column of `b` in each kernel matrix).
    pub fn eval_column(&self, points: &PointColumns, rows: Range<usize>, b: &KernelPoint, out: &mut [f64]) {
        assert!(rows.end <= points.len() && out.len() >= rows.len() * self.len(), "eval_column: rows or output out of range");
        Arch::new().dispatch(Column { bank: self, points, rows, b, out });
    }
}

/// One [`KernelBank::eval_column`] call, compiled for the best instruction set the CPU has
/// (pulp inlines `with_simd` into a function with those target features).
struct Column<'a> {
    bank: &'a KernelBank,
    points: &'a PointColumns,
    rows: Range<usize>,
    b: &'a KernelPoint,
    out: &'a mut [f64],
}

impl WithSimd for Column<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, _simd: S) {
        let Column { bank, points, rows, b, out } = self;
        let len = rows.len();
        let mut d2 = [[0.0; CHUNK]; 3];
        let mut e = [0.0; CHUNK];
        for chunk_start in (0..len).step_by(CHUNK) {
            let size = CHUNK.min(len - chunk_start);
            let first = rows.start + chunk_start;
            let mut have = [false; 3];
            for k in 0..bank.len() {
                out[k * len + chunk_start..][..size].fill(0.0);
            }
            for (t, &(space, inv_s2)) in bank.terms().iter().enumerate() {
                let s = space_index(space);
                if !have[s] {
                    squared_distances(points, first, b, space, &mut d2[s][..size]);
                    have[s] = true;
                }
                for (v, &d) in e[..size].iter_mut().zip(&d2[s][..size]) {
                    let arg = d * inv_s2;
                    let value = exp_neg(-arg.min(CUTOFF + 1.0));
                    *v = if arg < CUTOFF { value } else { 0.0 };
                }
                for (k, weights) in bank.weights().iter().enumerate() {
                    let w = weights[t];
                    if w != 0.0 {
                        for (o, v) in out[k * len + chunk_start..][..size].iter_mut().zip(&e[..size]) {
                            *o += w * v;
                        }
                    }
                }
            }
        }
    }
}

fn space_index(space: Space) -> usize {
    match space {
        Space::Position => 0,
        Space::MirroredPosition => 1,
        Space::Color => 2,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gp::kernel::{Hyperparameters, ModelKernel, ScalarKernel};

    #[test]
    fn exp_neg_is_within_two_ulp_of_libm() {
        let mut worst = 0u64;
        for i in 0..=2_000_000u32 {
            let x = -(CUTOFF + 1.0) * f64::from(i) / 2_000_000.0;
            let (a, b) = (exp_neg(x), libm::exp(x));
            worst = worst.max(a.to_bits().abs_diff(b.to_bits()));
        }
        assert!(worst <= 2, "{worst} ulp");
        assert_eq!(exp_neg(0.0), 1.0);
    }

    #[test]
    fn columns_match_the_pairwise_bank() {
        let points: Vec<KernelPoint> = (0..700)
            .map(|i| {
                let t = i as f64 / 700.0;
                KernelPoint { position: [90.0 * (7.0 * t).sin(), 120.0 * t - 60.0, 30.0 * (3.0 * t).cos()], color: [t, 0.4 + 0.2 * t, 0.3] }
            })
            .collect();
        let hp = Hyperparameters::default();
        let kernels: Vec<ScalarKernel> = ModelKernel::SymmetricFull.albedo_kernel(&hp).classes().into_iter().map(|c| c.kernel).collect();
        let bank = KernelBank::new(&kernels);
        let cols = PointColumns::new(&points);
        let rows = 13..700;
        let mut out = vec![f64::NAN; rows.len() * bank.len()];
        let (mut scratch, mut vals) = (vec![0.0; bank.term_count()], vec![0.0; bank.len()]);
        let mut zeros = 0;
        for b in [0, 345, 699] {
            bank.eval_column(&cols, rows.clone(), &points[b], &mut out);
            for (i, r) in rows.clone().enumerate() {
                bank.eval_into(&points[r], &points[b], &mut scratch, &mut vals);
                for (k, want) in vals.iter().enumerate() {
                    let got = out[k * rows.len() + i];
                    assert!((got - want).abs() <= 1e-15 * want.abs(), "kernel {k}, rows {r}/{b}: {got} vs {want}");
                    zeros += usize::from(*want == 0.0);
                }
            }
        }
        assert!(zeros < out.len(), "the test must compare non-zero values");
    }
}
