//! A synthetic morphable model for the fitter tests: an ellipsoidal "head" (the shared test mesh)
//! with smooth random low-rank shape and colour bases and 68 landmark vertices on its front.
#![allow(dead_code, clippy::indexing_slicing, clippy::unwrap_used, clippy::expect_used)]

use crate::common::{head_mesh, FrameSink, Rng};
use gpmm_core::fit::LandmarkTarget;
use gpmm_core::geometry::Vec3;
use gpmm_core::model::{Basis, FactoredBasis};
use gpmm_core::model::{FitParams, Instance, InstanceBuffers, MorphableModel};
use gpmm_core::render::{Cull, Pose, ProjectedVertex, ShLight, TileRasterizer};

pub const KS: usize = 8;
pub const KC: usize = 4;
pub const W: u32 = 128;
pub const H: u32 = 128;
pub type Raster = TileRasterizer<16, 16, 2048>;

pub struct Synth {
    pub shape_mean: Vec<Vec3>,
    pub color_mean: Vec<Vec3>,
    pub shape_fields: Vec<f32>,
    pub shape_dirs: Vec<Vec3>,
    pub color_fields: Vec<f32>,
    pub color_dirs: Vec<Vec3>,
    pub triangles: Vec<[u32; 3]>,
    pub landmarks: Vec<u32>,
}

fn smooth_fields(pos: &[Vec3], rank: usize, amplitude: f32, rng: &mut Rng) -> Vec<f32> {
    let mut f = Vec::with_capacity(rank * pos.len());
    for k in 0..rank {
        let w = [rng.range(-1.0, 1.0) / 40.0, rng.range(-1.0, 1.0) / 40.0, rng.range(-1.0, 1.0) / 40.0];
        let phase = rng.range(0.0, std::f32::consts::TAU);
        let a = amplitude / (1.0 + k as f32 * 0.3);
        for p in pos {
            f.push(a * (w[0] * p[0] + w[1] * p[1] + w[2] * p[2] + phase).sin());
        }
    }
    f
}

impl Synth {
    pub fn new(seed: u64) -> Self {
        let (pos, albedo, tris) = head_mesh(24, 32, 0.05, None);
        let mut rng = Rng::new(seed);
        let shape_fields = smooth_fields(&pos, KS, 6.0, &mut rng);
        let color_fields = smooth_fields(&pos, KC, 0.06, &mut rng);
        let axes = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let shape_dirs = (0..KS).map(|k| axes[k % 3]).collect();
        let s = 1.0 / 3f32.sqrt();
        let color_dirs = (0..KC)
            .map(|k| if k % 2 == 0 { [s, s, s] } else { [std::f32::consts::FRAC_1_SQRT_2, -std::f32::consts::FRAC_1_SQRT_2, 0.0] })
            .collect();
        // 68 landmarks spread over the front (z > 35 mm), deterministic.
        let front: Vec<u32> = (0..pos.len() as u32).filter(|&i| pos[i as usize][2] > 35.0).collect();
        assert!(front.len() >= 68, "{}", front.len());
        let landmarks = (0..68).map(|i| front[i * front.len() / 68]).collect();
        let color_mean = albedo.iter().map(|a| [0.3 + 0.5 * a[0], 0.25 + 0.5 * a[1], 0.2 + 0.5 * a[2]]).collect();
        Self { shape_mean: pos, color_mean, shape_fields, shape_dirs, color_fields, color_dirs, triangles: tris, landmarks }
    }

    pub fn model(&self) -> MorphableModel<'_> {
        let n = self.shape_mean.len();
        let shape = Basis::Factored(FactoredBasis::new(&self.shape_fields, &self.shape_dirs, n).unwrap());
        let color = Basis::Factored(FactoredBasis::new(&self.color_fields, &self.color_dirs, n).unwrap());
        MorphableModel::new(&self.shape_mean, &self.color_mean, shape, color, &self.triangles, &self.landmarks).unwrap()
    }

    pub fn vertices(&self) -> usize {
        self.shape_mean.len()
    }
}

/// Per-vertex buffers for an [`Instance`].
pub struct Buffers {
    pub positions: Vec<Vec3>,
    pub albedos: Vec<Vec3>,
    pub normals: Vec<Vec3>,
    pub projected: Vec<ProjectedVertex>,
}

impl Buffers {
    pub fn new(n: usize) -> Self {
        Self {
            positions: vec![[0.0; 3]; n],
            albedos: vec![[0.0; 3]; n],
            normals: vec![[0.0; 3]; n],
            projected: vec![ProjectedVertex::INVALID; n],
        }
    }

    pub fn instance(&mut self) -> Instance<'_, KS, KC> {
        let n = self.positions.len();
        let bufs = InstanceBuffers {
            positions: &mut self.positions,
            albedos: &mut self.albedos,
            normals: &mut self.normals,
            projected: &mut self.projected,
        };
        Instance::new(bufs, n).unwrap()
    }
}

pub fn truth() -> FitParams<KS, KC> {
    let pose = Pose { yaw: 25f32.to_radians(), pitch: -6f32.to_radians(), roll: 4f32.to_radians(), translation: [6.0, -8.0, -600.0] };
    let light = ShLight::from_ambient_diffuse([0.65, 0.6, 0.55], [0.35, 0.35, 0.3], [0.4, 0.5, 0.8]);
    let mut p = FitParams::new(pose, 300.0, light, KS, KC);
    p.shape_coeffs_mut().copy_from_slice(&[0.8, -0.6, 0.5, 1.0, -0.3, 0.2, -0.7, 0.4]);
    p.color_coeffs_mut().copy_from_slice(&[0.6, -0.8, 0.4, 0.3]);
    p
}

/// Projected landmarks of `params` (all valid) as the target.
pub fn project_landmarks(model: &MorphableModel<'_>, params: &FitParams<KS, KC>) -> Vec<[f32; 2]> {
    let mut lm = vec![[0.0f32; 3]; model.landmarks().len()];
    model.landmark_positions(params.shape_coeffs(), &mut lm).unwrap();
    let cam = params.camera(W, H);
    lm.iter().map(|p| cam.project(params.pose.transform_point(*p)).map(|s| [s.x, s.y]).unwrap()).collect()
}

/// Renders `params` over a background gradient into 8-bit RGB.
pub fn render_target(synth: &Synth, params: &FitParams<KS, KC>) -> Vec<[u8; 3]> {
    let model = synth.model();
    let mut bufs = Buffers::new(synth.vertices());
    let mut inst = bufs.instance();
    inst.update(&model, params, W, H).unwrap();
    let mut sink = FrameSink::new(W, H);
    let mut raster = Raster::new();
    raster.render(inst.projected(), model.triangles(), W, H, Cull::Clockwise, &mut sink).unwrap();
    let to8 = |c: f32| (c.clamp(0.0, 1.0) * 255.0).round() as u8;
    (0..(W * H) as usize)
        .map(|i| {
            if sink.tri[i] == gpmm_core::render::NO_TRIANGLE {
                let (x, y) = ((i % W as usize) as f32, (i / W as usize) as f32);
                [to8(0.2 + x / 400.0), to8(0.35 + y / 500.0), to8(0.6 - x / 600.0)]
            } else {
                let c = sink.color[i];
                [to8(c[0]), to8(c[1]), to8(c[2])]
            }
        })
        .collect()
}

pub fn all_valid(n: usize) -> Vec<bool> {
    vec![true; n]
}

pub fn target<'a>(points: &'a [[f32; 2]], valid: &'a [bool]) -> LandmarkTarget<'a> {
    LandmarkTarget::new(points, valid, LandmarkTarget::default_sigma(W, H)).unwrap()
}

/// The synthetic model's face rendered at [`truth`], with its exact landmarks.
pub struct Scene {
    pub synth: Synth,
    pub truth: FitParams<KS, KC>,
    pub pixels: Vec<[u8; 3]>,
    pub points: Vec<[f32; 2]>,
    pub valid: Vec<bool>,
}

impl Scene {
    pub fn new() -> Self {
        let synth = Synth::new(11);
        let truth = truth();
        let pixels = render_target(&synth, &truth);
        let points = project_landmarks(&synth.model(), &truth);
        let valid = all_valid(points.len());
        Self { synth, truth, pixels, points, valid }
    }

    pub fn image(&self) -> gpmm_core::fit::TargetImage<'_> {
        gpmm_core::fit::TargetImage::new(&self.pixels, W, H).unwrap()
    }

    pub fn landmarks(&self) -> LandmarkTarget<'_> {
        target(&self.points, &self.valid)
    }
}
