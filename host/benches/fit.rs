//! Fit benchmark: one default `gpmm fit` (crop, 5000 landmark steps, least-squares light, 600 image
//! steps at 128x128, one thread) of a synthetic face at yaw 30, and the landmark chain alone.
//!
//! `cargo bench -p gpmm-host --bench fit` (data from `$GPMM_DATA` or `../shared/data`). The model
//! is the cropped template at full resolution, symmetric-full, ranks 200/50 (the ranks a default fit uses).

use criterion::{criterion_group, criterion_main, Criterion};
use gpmm_host::fit::{fit_prepared, prepare, FitOptions};
use gpmm_host::gp::kernel::ModelKernel;
use gpmm_host::gp::lowrank::{NystromOptions, RankSpec};
use gpmm_host::gp::model::{build_model, BuildOptions};
use gpmm_host::mesh::template::{load_template, TemplateOptions};
use gpmm_host::synth::{synthesize, SynthOptions};
use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::time::Duration;

fn data_dir() -> PathBuf {
    std::env::var_os("GPMM_DATA").map(PathBuf::from).unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data"))
}

fn bench(c: &mut Criterion) {
    let data = data_dir();
    let dir = data.join("template/lee-perry-smith");
    let template = load_template(&dir.join("lee-perry-smith.ply"), &dir.join("landmarks_ibug68.json"), &TemplateOptions::default())
        .unwrap_or_else(|e| panic!("the benchmark needs the template ({e}); set GPMM_DATA"));
    let opts = BuildOptions {
        kernel: ModelKernel::SymmetricFull,
        hyperparameters: Default::default(),
        rank_shape: RankSpec::Count(200),
        rank_color: RankSpec::Count(50),
        nystrom: NystromOptions { points: 1000, ..Default::default() },
    };
    let model = build_model(&template, &opts, |_, _, _| {});
    let synth = SynthOptions { count: 1, yaws_deg: vec![30.0], seed: 1, ..SynthOptions::with_data_dir(&data) };
    let faces = synthesize(&synth, |_, _| {}).unwrap_or_else(|e| panic!("cannot render the synthetic face: {e}"));
    let face = &faces[0];
    let settings = FitOptions::default();
    let prepared = prepare(&face.image, &face.truth.landmarks, settings.size).unwrap_or_else(|e| panic!("{e}"));
    eprintln!("model: {} vertices, {} triangles; settings {settings:?}", model.vertices(), model.triangles.len());

    let mut g = c.benchmark_group("fit");
    g.sample_size(10).warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(12));
    g.bench_function("default_fit_128", |b| {
        b.iter(|| black_box(fit_prepared(&model, &prepared, &settings, &mut |_, _, _| {}).map(|o| o.pixel_rmse).unwrap_or(f32::NAN)))
    });
    let lm_only = FitOptions { fit: settings.fit.with_steps(settings.fit.landmarks.steps, 0), ..settings };
    g.bench_function("landmark_chain_5000_steps", |b| {
        b.iter(|| black_box(fit_prepared(&model, &prepared, &lm_only, &mut |_, _, _| {}).map(|o| o.landmark_rmse_px).unwrap_or(f32::NAN)))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
