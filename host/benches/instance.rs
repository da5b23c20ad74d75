//! Model instance benchmark: `Σ_k c_k · b_k` over 50 components of 4249 vertices (the template
//! model's size) for each basis layout: factored (the template's kernels), dense (learned and
//! imported models) and the dense layout quantized to 8 and 16 bits (such models on a device).
//!
//! `cargo bench -p gpmm-host --bench instance` (no data needed: the values are generated).

use criterion::{criterion_group, criterion_main, Criterion};
use gpmm_core::model::{DenseBasis, FactoredBasis, QuantValues, QuantizedBasis};
use std::hint::black_box;
use std::time::Duration;

const RANK: usize = 50;
const VERTICES: usize = 4249;

/// A deterministic value in [-1, 1) for index `i` of stream `s`.
fn value(s: usize, i: usize) -> f32 {
    ((s.wrapping_mul(2_654_435_761) ^ i.wrapping_mul(40_503)) % 20_000) as f32 / 10_000.0 - 1.0
}

fn bench(c: &mut Criterion) {
    let coeffs: Vec<f32> = (0..RANK).map(|k| value(1, k)).collect();
    let dense: Vec<f32> = (0..RANK * VERTICES * 3).map(|i| value(2, i)).collect();
    let fields: Vec<f32> = (0..RANK * VERTICES).map(|i| value(3, i)).collect();
    let directions: Vec<[f32; 3]> = (0..RANK).map(|k| [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]][k % 3]).collect();
    let i16s: Vec<i16> = dense.iter().map(|x| (x * 32_000.0) as i16).collect();
    let i8s: Vec<i8> = dense.iter().map(|x| (x * 127.0) as i8).collect();
    let scales = vec![1.0 / 32_000.0; RANK];
    let mut out = vec![[0.0f32; 3]; VERTICES];
    let mut g = c.benchmark_group("instance");
    g.warm_up_time(Duration::from_millis(500)).measurement_time(Duration::from_secs(3));
    let d = DenseBasis::new(&dense, RANK, VERTICES).unwrap_or_else(|e| panic!("{e:?}"));
    g.bench_function("dense_f32", |b| b.iter(|| d.add_instance(black_box(&coeffs), &mut out)));
    let f = FactoredBasis::new(&fields, &directions, VERTICES).unwrap_or_else(|e| panic!("{e:?}"));
    g.bench_function("factored_f32", |b| b.iter(|| f.add_instance(black_box(&coeffs), &mut out)));
    let q16 = QuantizedBasis::new(QuantValues::I16(&i16s), &scales, None, VERTICES).unwrap_or_else(|e| panic!("{e:?}"));
    g.bench_function("dense_i16", |b| b.iter(|| q16.add_instance(black_box(&coeffs), &mut out)));
    let q8 = QuantizedBasis::new(QuantValues::I8(&i8s), &scales, None, VERTICES).unwrap_or_else(|e| panic!("{e:?}"));
    g.bench_function("dense_i8", |b| b.iter(|| q8.add_instance(black_box(&coeffs), &mut out)));
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
