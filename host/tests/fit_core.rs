//! The core fitter on a real model (the template scan, simplified, as a GP model) and a target
//! rendered by the core at a known pose: the landmark chain recovers the pose from a frontal
//! start, the image chain lowers the pixel error, and per-step times are printed (run with
//! `--release -- --nocapture` for the figures).

use gpmm_core::fit::{
    image_chain, initial_guess, landmark_chain, BackgroundModel, GaussianPixel, ImageProblem, LandmarkTarget, LightSolveConfig, Mixture,
    NoObserver, Prior, Problem, TargetImage, DEFAULT_PIXEL_SIGMA,
};
use gpmm_core::model::{FitParams, Instance, InstanceBuffers, MorphableModel};
use gpmm_core::render::{Cull, Pose, ProjectedVertex, ShLight, Tile, TileRasterizer, NO_TRIANGLE};
use gpmm_host::data::{data_dir_for_tests, template_dir};
use gpmm_host::gp::kernel::ModelKernel;
use gpmm_host::gp::lowrank::{NystromOptions, RankSpec};
use gpmm_host::gp::model::{build_model, BuildOptions};
use gpmm_host::mesh::template::{load_template, TemplateOptions};
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;
use std::time::Instant;

const KS: usize = 30;
const KC: usize = 20;
const W: u32 = 128;
const H: u32 = 128;
type Raster = TileRasterizer<32, 32, 4096>;

#[test]
fn fits_a_rendered_face_with_known_pose() {
    let Some(data) = data_dir_for_tests() else { return };
    let dir = template_dir(&data);
    let opts = TemplateOptions { vertices: Some(4000), ..Default::default() };
    let template = load_template(&dir.join("lee-perry-smith.ply"), &dir.join("landmarks_ibug68.json"), &opts).unwrap();
    let build = BuildOptions {
        kernel: ModelKernel::SymmetricFull,
        hyperparameters: Default::default(),
        rank_shape: RankSpec::Count(KS),
        rank_color: RankSpec::Count(KC),
        nystrom: NystromOptions { points: 400, ..Default::default() },
    };
    let gp = build_model(&template, &build, |_, _, _| {});
    let model = MorphableModel::new(
        &gp.shape.mean,
        &gp.color.mean,
        gp.shape.core_basis().unwrap(),
        gp.color.core_basis().unwrap(),
        &gp.triangles,
        &gp.landmarks,
    )
    .unwrap();
    let n = model.vertices();

    // Truth: turned 20° to the image right, a random face, a directional light.
    let pose = Pose { yaw: 20f32.to_radians(), pitch: 5f32.to_radians(), roll: -3f32.to_radians(), translation: [4.0, -6.0, -650.0] };
    let light = ShLight::from_ambient_diffuse([0.6, 0.58, 0.55], [0.4, 0.38, 0.35], [-0.3, 0.4, 0.85]);
    let mut truth = FitParams::<KS, KC>::new(pose, 420.0, light, KS, KC);
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(2024);
    for c in truth.shape.iter_mut() {
        *c = 0.7 * gpmm_core::fit::chain::normal::standard_normal(&mut rng);
    }
    for c in truth.color.iter_mut() {
        *c = 0.7 * gpmm_core::fit::chain::normal::standard_normal(&mut rng);
    }

    let (mut pos, mut alb, mut nor, mut proj) =
        (vec![[0.0f32; 3]; n], vec![[0.0f32; 3]; n], vec![[0.0f32; 3]; n], vec![ProjectedVertex::INVALID; n]);
    let mut inst =
        Instance::<KS, KC>::new(InstanceBuffers { positions: &mut pos, albedos: &mut alb, normals: &mut nor, projected: &mut proj }, n)
            .unwrap();
    inst.update(&model, &truth, W, H).unwrap();
    let mut raster = Raster::new();
    let mut pixels = vec![[0u8; 3]; (W * H) as usize];
    for (i, p) in pixels.iter_mut().enumerate() {
        let (x, y) = ((i % W as usize) as f32, (i / W as usize) as f32);
        *p = [(60.0 + x) as u8, (90.0 + y * 0.5) as u8, (150.0 - x * 0.4) as u8];
    }
    let mut sink = |tile: &Tile<32, 32>| {
        let (x0, y0) = tile.origin();
        let (w, h) = tile.size();
        for ly in 0..h as usize {
            for lx in 0..w as usize {
                if tile.triangles()[ly][lx] != NO_TRIANGLE {
                    let c = tile.colors()[ly][lx];
                    pixels[(y0 as usize + ly) * W as usize + x0 as usize + lx] = c.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8);
                }
            }
        }
    };
    raster.render(inst.projected(), model.triangles(), W, H, Cull::Clockwise, &mut sink).unwrap();
    let mut lm3 = vec![[0.0f32; 3]; model.landmarks().len()];
    model.landmark_positions(truth.shape_coeffs(), &mut lm3).unwrap();
    let cam = truth.camera(W, H);
    let points: Vec<[f32; 2]> = lm3.iter().map(|p| cam.project(truth.pose.transform_point(*p)).map(|s| [s.x, s.y]).unwrap()).collect();
    let valid = vec![true; points.len()];
    let lm = LandmarkTarget::new(&points, &valid, LandmarkTarget::default_sigma(W, H)).unwrap();

    // Fit: frontal mean-face start with a 15 % wrong focal length.
    let init: FitParams<KS, KC> = initial_guess(&model, &lm, 360.0, W, H, ShLight::ambient([0.8; 3]), KS, KC).unwrap();
    let prior = Prior::around(&init);
    let lm_mix = Mixture::landmark_default(W as f32);
    let problem = Problem { model, landmarks: lm, prior: &prior, mixture: &lm_mix, width: W, height: H, silhouette: None };
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(5);
    let lm_steps = 5000;
    let t0 = Instant::now();
    let lm_fit = landmark_chain(&problem, &init, lm_steps, &mut rng, NoObserver).unwrap();
    let t_lm = t0.elapsed().as_secs_f64();

    let image = TargetImage::new(&pixels, W, H).unwrap();
    let bg = BackgroundModel::from_image(&image, 0.01).unwrap();
    let pixel = GaussianPixel::new(DEFAULT_PIXEL_SIGMA).unwrap();
    let ip = ImageProblem { image, pixel, background: &bg, light_solve: LightSolveConfig::default() };
    let img_mix = Mixture::image_default(W as f32);
    let problem = Problem { mixture: &img_mix, ..problem };
    let start = image_chain(&problem, &ip, &lm_fit.best, 0, &mut inst, &mut raster, &mut rng, NoObserver).unwrap();
    let img_steps = 1500;
    let t0 = Instant::now();
    let fit = image_chain(&problem, &ip, &lm_fit.best, img_steps, &mut inst, &mut raster, &mut rng, NoObserver).unwrap();
    let t_img = t0.elapsed().as_secs_f64();

    let deg = |p: &FitParams<KS, KC>| [p.pose.yaw, p.pose.pitch, p.pose.roll].map(f32::to_degrees);
    let (a, b) = (start.best_image.unwrap(), fit.best_image.unwrap());
    eprintln!("model: {n} vertices, {} triangles, ranks {KS}/{KC}, image {W}x{H}", model.triangles().len());
    eprintln!(
        "landmark chain: {lm_steps} steps, {:.2} us/step; pose {:?} (truth [20, 5, -3]), landmark RMSE {:.2} px",
        t_lm * 1e6 / f64::from(lm_steps),
        deg(&lm_fit.best),
        lm_fit.best_landmarks.rmse()
    );
    eprintln!(
        "image chain: {img_steps} steps, {:.0} us/step; pose {:?}, landmark RMSE {:.2} px, pixel RMSE {:.4} -> {:.4}, acceptance {:.2}",
        t_img * 1e6 / f64::from(img_steps),
        deg(&fit.best),
        fit.best_landmarks.rmse(),
        a.rmse(),
        b.rmse(),
        fit.acceptance.overall()
    );
    let [y, p, r] = deg(&lm_fit.best);
    assert!((y - 20.0).abs() < 3.0 && (p - 5.0).abs() < 5.0 && (r + 3.0).abs() < 3.0, "{y} {p} {r}");
    assert!(lm_fit.best_landmarks.rmse() < 1.5);
    assert!(b.rmse() < a.rmse());
    assert!((deg(&fit.best)[0] - 20.0).abs() < 3.0);
}
