//! Shape from shading on renders of a known instance of the template model: a bump a few mm high
//! on a cheek, outside the model's span, is recovered from the image; where the image says
//! nothing (the far side of a turned face, pixels the photo does not cover) the result stays at
//! the model's instance.

use std::sync::OnceLock;

use gpmm_core::fit::{CoveredPixels, TargetImage};
use gpmm_core::render::{Pose, ShLight};
use gpmm_host::data::{data_dir_for_tests, template_dir};
use gpmm_host::fit::{FitOptions, Params};
use gpmm_host::gp::kernel::ModelKernel;
use gpmm_host::gp::lowrank::{NystromOptions, RankSpec};
use gpmm_host::gp::model::{build_model, BuildOptions, GpModel};
use gpmm_host::learn::shading::{shape_from_shading, Detail, ShadingModel, ShadingSettings};
use gpmm_host::learn::silhouette::render_params;
use gpmm_host::mesh::template::{load_template, TemplateOptions};

const RANK: usize = 20;
const SIZE: u32 = 128;
/// The bump's height at its centre (mm) and its Gaussian radius (mm).
const BUMP_MM: f32 = 4.0;
const BUMP_RADIUS_MM: f32 = 12.0;

fn model() -> Option<&'static GpModel> {
    static MODEL: OnceLock<Option<GpModel>> = OnceLock::new();
    MODEL
        .get_or_init(|| {
            let data = data_dir_for_tests()?;
            let dir = template_dir(&data);
            let opts = TemplateOptions { vertices: Some(4000), ..Default::default() };
            let template = load_template(&dir.join("lee-perry-smith.ply"), &dir.join("landmarks_ibug68.json"), &opts).unwrap();
            let build = BuildOptions {
                kernel: ModelKernel::SymmetricFull,
                hyperparameters: Default::default(),
                rank_shape: RankSpec::Count(RANK),
                rank_color: RankSpec::Count(RANK),
                nystrom: NystromOptions { points: 300, ..Default::default() },
            };
            Some(build_model(&template, &build, |_, _, _| {}))
        })
        .as_ref()
}

/// A known instance seen at `yaw` degrees under a light from the upper right.
fn params(model: &GpModel, yaw: f32) -> Params {
    let pose = Pose { yaw: yaw.to_radians(), pitch: 0.05, roll: 0.0, translation: [0.0, 0.0, -500.0] };
    let light = ShLight::from_ambient_diffuse([0.45, 0.42, 0.4], [0.6, 0.58, 0.55], [0.5, 0.4, 0.75]);
    let mut p = Params::new(pose, 330.0, light, model.shape.rank(), model.color.rank());
    for (i, c) in p.shape_coeffs_mut().iter_mut().enumerate() {
        *c = [0.6, -0.4, 0.3, 0.2][i % 4];
    }
    for (i, c) in p.color_coeffs_mut().iter_mut().enumerate() {
        *c = [-0.3, 0.2][i % 2];
    }
    p
}

/// The front-most vertex in the middle of the subject's left cheek (halfway between iBUG point
/// 13, the jaw, and 35, the nose's side, in x and y).
fn cheek(model: &GpModel) -> usize {
    let (a, b) = (model.shape.mean[model.landmarks[13] as usize], model.shape.mean[model.landmarks[35] as usize]);
    let mid = [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0];
    let near = |p: &[f32; 3]| (p[0] - mid[0]).powi(2) + (p[1] - mid[1]).powi(2) < 16.0;
    let front = |v: &usize| model.shape.mean[*v][2];
    (0..model.shape.mean.len()).filter(|&v| near(&model.shape.mean[v])).max_by(|i, j| front(i).total_cmp(&front(j))).unwrap()
}

fn distance(a: [f32; 3], b: [f32; 3]) -> f32 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// A Gaussian bump at `centre` along the mean's normals, with its part in the span of the
/// model's components removed (Gram–Schmidt in f64), so that no coefficient can explain it.
fn bump(model: &GpModel, centre: usize, normals: &[[f32; 3]]) -> Vec<[f32; 3]> {
    let c = model.shape.mean[centre];
    let mut d: Vec<f64> = model
        .shape
        .mean
        .iter()
        .zip(normals)
        .flat_map(|(p, n)| {
            let r = distance(*p, c);
            let h = BUMP_MM * (-0.5 * (r / BUMP_RADIUS_MM).powi(2)).exp();
            n.map(|x| f64::from(h * x))
        })
        .collect();
    let mut basis: Vec<Vec<f64>> = Vec::new();
    for k in 0..model.shape.rank() {
        let mut coeffs = vec![0.0f32; k + 1];
        coeffs[k] = 1.0;
        let inst = model.shape.instance(&coeffs).unwrap();
        let mut b: Vec<f64> = inst.iter().zip(&model.shape.mean).flat_map(|(p, m)| [0, 1, 2].map(|j| f64::from(p[j] - m[j]))).collect();
        for q in &basis {
            let s: f64 = b.iter().zip(q).map(|(x, y)| x * y).sum();
            b.iter_mut().zip(q).for_each(|(x, y)| *x -= s * y);
        }
        let norm = b.iter().map(|x| x * x).sum::<f64>().sqrt();
        b.iter_mut().for_each(|x| *x /= norm);
        let s: f64 = d.iter().zip(&b).map(|(x, y)| x * y).sum();
        d.iter_mut().zip(&b).for_each(|(x, y)| *x -= s * y);
        basis.push(b);
    }
    d.chunks_exact(3).map(|v| [v[0] as f32, v[1] as f32, v[2] as f32]).collect()
}

/// The render of `params` on `model` with `offsets` added to its shape, as the fit's target pixels.
fn render(model: &GpModel, params: &Params, offsets: &[[f32; 3]]) -> Vec<[u8; 3]> {
    let mut moved = model.clone();
    for (m, d) in moved.shape.mean.iter_mut().zip(offsets) {
        *m = [m[0] + d[0], m[1] + d[1], m[2] + d[2]];
    }
    let settings = FitOptions { size: SIZE, ..FitOptions::DEFAULT };
    render_params(&moved, params, &settings).unwrap().pixels().map(|p| [p.0[0], p.0[1], p.0[2]]).collect()
}

fn run(model: &GpModel, params: &Params, pixels: &[[u8; 3]], covered: CoveredPixels) -> Detail {
    let image = TargetImage::new(pixels, SIZE, SIZE).unwrap().with_covered(covered).unwrap();
    let settings = ShadingSettings::DEFAULT;
    let sm = ShadingModel::new(model, RANK, RANK, &settings).unwrap();
    let t0 = std::time::Instant::now();
    let detail = shape_from_shading(&sm, params, &image, &settings).unwrap();
    eprintln!(
        "{} seen of {} vertices, objective {:.1} -> {:.1}, {:.2} s",
        detail.seen_count(),
        detail.heights.len(),
        detail.objective[0],
        detail.objective[1],
        t0.elapsed().as_secs_f64()
    );
    detail
}

/// Unit normals of the model's mean shape.
fn mean_normals(model: &GpModel) -> Vec<[f32; 3]> {
    let mut n = vec![[0.0f32; 3]; model.shape.mean.len()];
    gpmm_core::render::vertex_normals(&model.shape.mean, &model.triangles, &mut n).unwrap();
    n
}

#[test]
fn a_bump_outside_the_span_is_recovered_and_nothing_else_moves() {
    let Some(model) = model() else { return };
    let params = params(model, 15.0);
    let centre = cheek(model);
    let offsets = bump(model, centre, &mean_normals(model));
    let truth = offsets[centre];
    let height = distance(truth, [0.0; 3]);
    assert!(height > 0.6 * BUMP_MM, "the bump lies mostly outside the span: {height:.2} mm of {BUMP_MM} left");
    let detail = run(model, &params, &render(model, &params, &offsets), CoveredPixels::whole(SIZE, SIZE));
    assert!(detail.seen[centre], "the bump's centre is seen");
    let found = detail.shape_offset(centre);
    let along = (found[0] * truth[0] + found[1] * truth[1] + found[2] * truth[2]) / height;
    eprintln!("bump {height:.2} mm at its centre, found {along:.2} mm along it");
    assert!(along >= 0.5 * height, "found {along:.2} mm of the bump's {height:.2} mm at its centre");
    assert!(along <= 1.5 * height, "found {along:.2} mm, overshooting the bump's {height:.2} mm");
    // Far from the bump (beyond 4 radii) the seen vertices stay near the instance.
    let c = model.shape.mean[centre];
    let far: Vec<f32> = (0..detail.heights.len())
        .filter(|&v| detail.seen[v] && distance(model.shape.mean[v], c) > 4.0 * BUMP_RADIUS_MM)
        .map(|v| detail.heights[v].abs())
        .collect();
    let mean_far = far.iter().sum::<f32>() / far.len() as f32;
    let mut sorted = far.clone();
    sorted.sort_by(f32::total_cmp);
    let p95 = sorted[sorted.len() * 95 / 100];
    eprintln!("far from the bump: {} vertices, mean |h| {mean_far:.3} mm, 95th percentile {p95:.3} mm", far.len());
    assert!(mean_far < 0.1 * height && p95 < 0.25 * height, "far from the bump: mean |h| {mean_far:.3} mm, 95th percentile {p95:.3} mm");
    assert!(detail.mean_albedo_change() < 2.0 / 255.0, "albedo change {:.4}: the bump is shape", detail.mean_albedo_change());
}

#[test]
fn where_the_image_says_nothing_the_result_stays_at_the_instance() {
    let Some(model) = model() else { return };
    // Turned 50° toward the image right: the bumped cheek (the subject's left, +x) turns away
    // from the camera; and the photo covers only the right 70 % of the crop.
    let params = params(model, 50.0);
    let centre = cheek(model);
    let offsets = bump(model, centre, &mean_normals(model));
    let covered = CoveredPixels { x0: SIZE * 3 / 10, y0: 0, x1: SIZE, y1: SIZE };
    let detail = run(model, &params, &render(model, &params, &offsets), covered);
    assert!(!detail.seen[centre], "the bump's centre is hidden at this yaw");
    assert!(detail.seen_count() > 300, "only {} vertices seen", detail.seen_count());
    // The hidden bump (within a radius of its centre) and the strip the photo does not cover
    // keep the instance, whatever the render shows there.
    let c = model.shape.mean[centre];
    let camera = params.camera(SIZE, SIZE);
    let in_strip =
        |v: usize| camera.project(params.pose.transform_point(model.shape.mean[v])).is_some_and(|s| s.x < covered.x0 as f32 - 6.0);
    let quiet: Vec<usize> = (0..detail.seen.len()).filter(|&v| distance(model.shape.mean[v], c) < BUMP_RADIUS_MM || in_strip(v)).collect();
    let largest_h = quiet.iter().map(|&v| detail.heights[v].abs()).fold(0.0f32, f32::max);
    let largest_a = quiet.iter().flat_map(|&v| detail.albedo[v]).map(f32::abs).fold(0.0f32, f32::max);
    eprintln!("{} vertices on the hidden bump or the uncovered strip: largest |h| {largest_h:.4} mm, albedo {largest_a:.5}", quiet.len());
    assert!(quiet.len() > 100, "only {} vertices on the hidden bump or the uncovered strip", quiet.len());
    assert!(largest_h < 0.01 && largest_a < 0.001, "they moved: |h| {largest_h:.4} mm, albedo {largest_a:.5}");
    // The seen side did move: shape from shading ran there.
    let moved = (0..detail.seen.len()).filter(|&v| detail.seen[v] && detail.heights[v].abs() > 0.05).count();
    assert!(moved > 100, "only {moved} seen vertices moved");
}
