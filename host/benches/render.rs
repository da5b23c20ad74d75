//! Host rendering benchmark: one frame of the cropped template (mean, frontal pose, frontal light)
//! at 128x128 and 256x256 through the core vertex stage and the `TileRasterizer` (32x32 tiles),
//! the two stages separately and together.
//!
//! `cargo bench -p gpmm-host --bench render` (data from `$GPMM_DATA` or `../shared/data`).

use criterion::{criterion_group, criterion_main, Criterion};
use gpmm_host::mesh::template::{load_template, TemplateOptions};
use gpmm_host::render::{Background, Framing, Instance, RenderSettings, Renderer, View, TILE};
use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::time::Duration;

fn data_dir() -> PathBuf {
    std::env::var_os("GPMM_DATA").map(PathBuf::from).unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data"))
}

/// Counts covered pixels: the cheapest possible tile consumer (isolates the rasterizer).
struct Count(u64);

impl gpmm_core::render::TileSink<TILE, TILE> for Count {
    fn consume(&mut self, tile: &gpmm_core::render::Tile<TILE, TILE>) {
        let (w, h) = tile.size();
        for y in 0..h as usize {
            for x in 0..w as usize {
                self.0 += u64::from(tile.is_covered(x, y));
            }
        }
    }
}

fn bench(c: &mut Criterion) {
    let dir = data_dir().join("template/lee-perry-smith");
    let template = load_template(&dir.join("lee-perry-smith.ply"), &dir.join("landmarks_ibug68.json"), &TemplateOptions::default())
        .unwrap_or_else(|e| panic!("the benchmark needs the template ({e}); set GPMM_DATA"));
    let inst = Instance::of_mesh(&template.mesh);
    let tris = &template.mesh.triangles;
    eprintln!("cropped template: {} vertices, {} triangles", inst.positions.len(), tris.len());
    let mut g = c.benchmark_group("render");
    g.warm_up_time(Duration::from_millis(500)).measurement_time(Duration::from_secs(3));
    for size in [128u32, 256] {
        let s = RenderSettings { width: size, height: size, background: Background::Color([0.0; 3]), ..RenderSettings::default() };
        let framing = Framing::fit(&inst.positions, &[View::FRONTAL], &s).unwrap_or_else(|e| panic!("{e}"));
        let pose = framing.pose(View::FRONTAL);
        let camera = s.camera();
        let mut r = Renderer::new();
        g.bench_function(format!("vertex_stage/{size}x{size}"), |b| {
            b.iter(|| r.vertex_stage(black_box(&inst), tris, &pose, &camera, &s.light).unwrap_or_else(|e| panic!("{e}")))
        });
        r.vertex_stage(&inst, tris, &pose, &camera, &s.light).unwrap_or_else(|e| panic!("{e}"));
        g.bench_function(format!("raster_count_sink/{size}x{size}"), |b| {
            b.iter(|| {
                let mut sink = Count(0);
                r.rasterize_into(tris, size, size, s.cull, &mut sink).unwrap_or_else(|e| panic!("{e}"));
                sink.0
            })
        });
        g.bench_function(format!("raster_image_sink/{size}x{size}"), |b| {
            b.iter(|| r.rasterize(tris, size, size, s.cull, s.background).unwrap_or_else(|e| panic!("{e}")))
        });
        g.bench_function(format!("frame/{size}x{size}"), |b| {
            b.iter(|| r.render(black_box(&inst), tris, &pose, &s).unwrap_or_else(|e| panic!("{e}")))
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
