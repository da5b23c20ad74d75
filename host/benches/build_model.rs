//! Model-building benchmark: symmetric-full from the cropped full-resolution template,
//! rank 200/200, 2000 Nyström points (the build's budget: ≤ 2 s, ≤ 1 GiB on 2 cores).
//!
//! `cargo bench -p gpmm-host --bench build_model` (data from `$GPMM_DATA` or `../shared/data`).

use criterion::{criterion_group, criterion_main, Criterion};
use gpmm_host::gp::kernel::ModelKernel;
use gpmm_host::gp::lowrank::{NystromOptions, RankSpec};
use gpmm_host::gp::model::{build_model, BuildOptions};
use gpmm_host::mesh::template::{load_template, TemplateOptions};
use std::path::{Path, PathBuf};
use std::time::Duration;

fn data_dir() -> PathBuf {
    std::env::var_os("GPMM_DATA").map(PathBuf::from).unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data"))
}

fn bench(c: &mut Criterion) {
    let dir = data_dir().join("template/lee-perry-smith");
    let template = load_template(&dir.join("lee-perry-smith.ply"), &dir.join("landmarks_ibug68.json"), &TemplateOptions::default())
        .unwrap_or_else(|e| panic!("the benchmark needs the template ({e}); set GPMM_DATA"));
    let opts = BuildOptions {
        kernel: ModelKernel::SymmetricFull,
        hyperparameters: Default::default(),
        rank_shape: RankSpec::Count(200),
        rank_color: RankSpec::Count(200),
        nystrom: NystromOptions { points: 2000, ..Default::default() },
    };
    let model = build_model(&template, &opts, |_, _, _| {});
    eprintln!(
        "symmetric-full, {} vertices: captured {:.4} shape, {:.4} colour",
        template.mesh.positions.len(),
        model.captured_shape(),
        model.captured_color()
    );
    let mut g = c.benchmark_group("build_model");
    g.sample_size(10).measurement_time(Duration::from_secs(100)).warm_up_time(Duration::from_secs(1));
    g.bench_function("symmetric_full_rank200_nystrom2000", |b| b.iter(|| build_model(&template, &opts, |_, _, _| {})));
    g.finish();
    if let Some(peak) = gpmm_host::process::peak_memory_bytes() {
        eprintln!("peak resident memory: {:.1} MiB", peak as f64 / 1048576.0);
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
