//! Re-shading a cached frame gives the rasterizer's own sums to the bit, and a chain with spare
//! instances, a shading cache and a frame cache is the chain without them.
#![allow(clippy::indexing_slicing, clippy::unwrap_used, clippy::expect_used)]

mod common;
mod fit_support;

use fit_support::*;
use gpmm_core::fit::{
    image_chain, image_log_likelihood, landmark_chain, BackgroundModel, GaussianPixel, ImageEval, ImageProblem, LightSolveConfig, Mixture,
    NoObserver, Prior, Problem, TargetImage, DEFAULT_PIXEL_SIGMA,
};
use gpmm_core::geometry::Vec3;
use gpmm_core::model::{FitParams, Instance, InstanceBuffers, SpareBuffers};
use gpmm_core::render::frame_cache::{CachedFragment, CompactBuffers, FrameBuffers, FrameCache};
use gpmm_core::render::light::SH_COEFFS;
use gpmm_core::render::shading::{ShadingBuffers, ShadingCache};
use gpmm_core::render::{ProjectedVertex, ShLight};
use rand_core::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;

/// Everything a cached instance borrows: two instances' per-vertex buffers and two frame slots.
struct CachedBuffers {
    main: [Vec<Vec3>; 3],
    projected: Vec<ProjectedVertex>,
    spare: [Vec<Vec3>; 3],
    fragments: [Vec<CachedFragment>; 2],
    tile_ends: [Vec<u32>; 2],
    basis: Vec<[f32; SH_COEFFS]>,
    irradiance: Vec<Vec3>,
    covered: Vec<u32>,
    ids: Vec<u16>,
}

impl CachedBuffers {
    fn new(n: usize) -> Self {
        let v = || vec![[0.0f32; 3]; n];
        let pixels = (W * H) as usize;
        let tiles = (W as usize).div_ceil(16) * (H as usize).div_ceil(16);
        Self {
            main: [v(), v(), v()],
            projected: vec![ProjectedVertex::INVALID; n],
            spare: [v(), v(), v()],
            fragments: [vec![CachedFragment::EMPTY; pixels], vec![CachedFragment::EMPTY; pixels]],
            tile_ends: [vec![0; tiles], vec![0; tiles]],
            basis: vec![[0.0; SH_COEFFS]; n],
            irradiance: v(),
            covered: vec![0; pixels.div_ceil(32)],
            ids: vec![0; pixels],
        }
    }

    /// The device's configuration: no spare instance, no shading cache, one compact frame slot.
    fn compact_instance(&mut self) -> Instance<'_, KS, KC> {
        let n = self.projected.len();
        let [pos, alb, nor] = &mut self.main;
        let cache = FrameCache::compact(CompactBuffers { covered: &mut self.covered, triangles: &mut self.ids });
        Instance::new(InstanceBuffers { positions: pos, albedos: alb, normals: nor, projected: &mut self.projected }, n)
            .unwrap()
            .with_frame_cache(cache)
    }

    fn instance(&mut self) -> Instance<'_, KS, KC> {
        let n = self.projected.len();
        let [pos, alb, nor] = &mut self.main;
        let [pos2, alb2, nor2] = &mut self.spare;
        let [fa, fb] = &mut self.fragments;
        let [ta, tb] = &mut self.tile_ends;
        let cache = FrameCache::new(FrameBuffers { fragments: fa, tile_ends: ta }, FrameBuffers { fragments: fb, tile_ends: tb });
        Instance::new(InstanceBuffers { positions: pos, albedos: alb, normals: nor, projected: &mut self.projected }, n)
            .unwrap()
            .with_spare(SpareBuffers { positions: pos2, normals: nor2, albedos: alb2 })
            .unwrap()
            .with_frame_cache(cache)
            .with_shading_cache(ShadingCache::new(ShadingBuffers { basis: &mut self.basis, irradiance: &mut self.irradiance }, n).unwrap())
    }
}

fn bits(e: &ImageEval) -> (u32, u32, u32) {
    (e.log_likelihood.to_bits(), e.rmse().to_bits(), e.covered)
}

#[test]
fn reshading_gives_the_rendered_sums_to_the_bit() {
    reshade_in_turn(false);
}

/// The same at half resolution: a target of block means, read pixel by pixel.
#[test]
fn reshading_a_half_resolution_target_gives_the_rendered_sums_to_the_bit() {
    reshade_in_turn(true);
}

/// Colour, light, pose and shape changes in turn, evaluated without caches, with a frame and
/// shading cache, and with a compact frame cache (at half resolution if `half`).
fn reshade_in_turn(half: bool) {
    let synth = Synth::new(11);
    let truth = truth();
    let pixels = render_target(&synth, &truth);
    let points = project_landmarks(&synth.model(), &truth);
    let valid = all_valid(points.len());
    let model = synth.model();
    let prior = Prior::around(&truth);
    let mixture = Mixture::image_default(W as f32);
    let full = TargetImage::new(&pixels, W, H).unwrap();
    let image = if half { full.half().unwrap() } else { full };
    let (w, h) = (image.width(), image.height());
    let problem =
        Problem { model, landmarks: target(&points, &valid), prior: &prior, mixture: &mixture, width: w, height: h, silhouette: None };
    let bg = BackgroundModel::from_image(&image, 0.01).unwrap();
    let ip = ImageProblem {
        image,
        pixel: GaussianPixel::new(DEFAULT_PIXEL_SIGMA).unwrap(),
        background: &bg,
        light_solve: LightSolveConfig::default(),
    };

    let mut plain_bufs = Buffers::new(synth.vertices());
    let mut plain = plain_bufs.instance();
    let mut cached_bufs = CachedBuffers::new(synth.vertices());
    let mut cached = cached_bufs.instance();
    let mut compact_bufs = CachedBuffers::new(synth.vertices());
    let mut compact = compact_bufs.compact_instance();
    let mut raster = Raster::new();

    // A start away from the truth, then colour, light and pose changes in turn.
    let mut start = truth.clone();
    start.pose.yaw += 0.05;
    if half {
        start.focal *= 0.5;
    }
    start.shape_coeffs_mut()[0] = 0.2;
    let mut recoloured = start.clone();
    recoloured.color_coeffs_mut().copy_from_slice(&[-0.4, 0.9, 0.1, -0.2]);
    let mut relit = recoloured.clone();
    relit.light = ShLight::from_ambient_diffuse([0.5, 0.55, 0.6], [0.5, 0.4, 0.3], [-0.3, 0.4, 0.9]);
    let mut turned = relit.clone();
    turned.pose.pitch += 0.03;
    let mut reshaped = turned.clone();
    reshaped.shape_coeffs_mut()[1] = -1.2;
    let sequence: [&FitParams<KS, KC>; 7] = [&start, &recoloured, &relit, &turned, &relit, &reshaped, &start];
    for (i, p) in sequence.iter().enumerate() {
        let want = image_log_likelihood(&problem, &ip, p, &mut plain, &mut raster).unwrap();
        let got = image_log_likelihood(&problem, &ip, p, &mut cached, &mut raster).unwrap();
        assert_eq!(bits(&got), bits(&want), "state {i}: {got:?} vs {want:?}");
        let small = image_log_likelihood(&problem, &ip, p, &mut compact, &mut raster).unwrap();
        assert_eq!(bits(&small), bits(&want), "compact, state {i}: {small:?} vs {want:?}");
        assert!(want.covered > if half { 500 } else { 2000 }, "{}", want.covered);
    }
    // The colour and light changes were re-shaded (start -> recoloured -> relit; relit again
    // after the pose change comes back to a kept geometry); the rest were rendered.
    let frames = cached.frames().unwrap();
    assert_eq!((frames.reshaded, frames.recorded), (3, 4), "re-shaded / rendered frames");
    // One compact slot: relit after the pose change is rendered again.
    let frames = compact.frames().unwrap();
    assert_eq!((frames.reshaded, frames.recorded), (2, 5), "compact: re-shaded / rendered frames");
}

#[test]
fn a_recomputed_shape_gets_its_serial_and_geometry_back() {
    let synth = Synth::new(11);
    let model = synth.model();
    let mut bufs = Buffers::new(synth.vertices());
    let mut inst = bufs.instance();
    let a = truth();
    let mut b = a.clone();
    b.shape_coeffs_mut()[0] += 0.3;
    inst.update(&model, &a, W, H).unwrap();
    let ka = inst.geometry();
    let positions = inst.positions().to_vec();
    inst.update(&model, &b, W, H).unwrap();
    assert_ne!(inst.geometry(), ka);
    // No spare buffers: `a` is recomputed, to the same bits, under the same key.
    assert_eq!(inst.geometry_of(&a, W, H), ka);
    inst.update(&model, &a, W, H).unwrap();
    assert_eq!((inst.geometry(), inst.shape_updates), (ka, 3));
    assert!(inst.positions().iter().zip(&positions).all(|(p, q)| p.map(f32::to_bits) == q.map(f32::to_bits)));
}

#[test]
fn a_compact_cache_keeps_the_chains_frame() {
    use gpmm_core::render::frame_cache::GeometryKey;
    use gpmm_core::render::Pose;
    let (mut covered, mut ids) = (vec![0u32; 512], vec![0u16; 64]);
    let mut frames = FrameCache::compact(CompactBuffers { covered: &mut covered, triangles: &mut ids });
    let pose = Pose { yaw: 0.1, pitch: 0.0, roll: 0.0, translation: [0.0, 0.0, -500.0] };
    let chain = GeometryKey::new(1, &pose, 300.0, W, H);
    let proposal = GeometryKey::new(1, &Pose { yaw: 0.2, ..pose }, 300.0, W, H);
    frames.recorder(chain, None, &mut ()).finish();
    assert!(frames.contains(&chain));
    // A proposal's frame (another geometry than the chain's) is not recorded over it...
    frames.recorder(proposal, Some(chain), &mut ()).finish();
    assert!(frames.contains(&chain) && !frames.contains(&proposal));
    // ... the chain's own frame is, and so is any frame without a chain state.
    frames.recorder(proposal, Some(proposal), &mut ()).finish();
    assert!(frames.contains(&proposal) && !frames.contains(&chain));
    frames.recorder(chain, None, &mut ()).finish();
    assert!(frames.contains(&chain));
    assert_eq!(frames.recorded, 3);
}

#[test]
fn drawn_set_ups_and_stepped_edges_give_the_direct_weights() {
    use gpmm_core::render::raster::FragmentSetup;
    let synth = Synth::new(11);
    let model = synth.model();
    let mut bufs = Buffers::new(synth.vertices());
    let mut inst = bufs.instance();
    inst.update(&model, &truth(), W, H).unwrap();
    let v = inst.projected();
    let bits = |w: Option<[f32; 3]>| w.map(|w| w.map(f32::to_bits));
    let (mut covered, mut stepped) = (0, 0);
    for tri in model.triangles() {
        let Some(direct) = FragmentSetup::new(v, tri, W, H) else { continue };
        let drawn = FragmentSetup::of_drawn(v, tri, W, H).unwrap();
        assert_eq!(drawn.ids, direct.ids);
        let (xs, ys) = (tri.map(|i| v[i as usize].x), tri.map(|i| v[i as usize].y));
        let lo = |c: [f32; 3]| (c.iter().fold(f32::MAX, |a, &b| a.min(b)) as i64 - 2).clamp(0, W as i64) as u32;
        let hi = |c: [f32; 3]| (c.iter().fold(f32::MIN, |a, &b| a.max(b)) as i64 + 2).clamp(0, W as i64) as u32;
        for y in lo(ys)..hi(ys).min(H) {
            let mut prev: Option<[i32; 3]> = None;
            for x in lo(xs)..hi(xs) {
                let want = direct.weights_at(x, y);
                assert_eq!(bits(drawn.weights_at(x, y)), bits(want));
                let e = drawn.small_edges(x, y);
                if let Some(e) = e {
                    assert_eq!(bits(drawn.weights_from(e)), bits(want));
                    covered += usize::from(want.is_some());
                    if let Some(p) = prev.filter(|p| drawn.weights_from(*p).is_some()) {
                        assert_eq!(drawn.step_right(p), e, "triangle {tri:?} at ({x}, {y})");
                        stepped += 1;
                    }
                }
                prev = e;
            }
        }
    }
    assert!(covered > 2000 && stepped > 1000, "{covered} covered pixels, {stepped} steps");
}

#[derive(Clone, Copy, PartialEq)]
enum Caches {
    None,
    Host,
    Device,
}

fn chain(caches: Caches, seed: u64) -> (gpmm_core::fit::FitResult<KS, KC>, u32) {
    let synth = Synth::new(11);
    let truth = truth();
    let pixels = render_target(&synth, &truth);
    let points = project_landmarks(&synth.model(), &truth);
    let valid = all_valid(points.len());
    let model = synth.model();
    let lm = target(&points, &valid);
    let mut init = truth.clone();
    init.pose.yaw += 0.08;
    init.shape_coeffs_mut().fill(0.0);
    init.color_coeffs_mut().fill(0.0);
    init.light = ShLight::ambient([0.8; 3]);
    let prior = Prior::around(&init);
    let lm_mix = Mixture::landmark_default(W as f32);
    let problem = Problem { model, landmarks: lm, prior: &prior, mixture: &lm_mix, width: W, height: H, silhouette: None };
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let lm_fit = landmark_chain(&problem, &init, 500, &mut rng, NoObserver).unwrap();
    let img_mix = Mixture::image_default(W as f32);
    let problem = Problem { mixture: &img_mix, ..problem };
    let image = TargetImage::new(&pixels, W, H).unwrap();
    let bg = BackgroundModel::from_image(&image, 0.01).unwrap();
    let ip = ImageProblem {
        image,
        pixel: GaussianPixel::new(DEFAULT_PIXEL_SIGMA).unwrap(),
        background: &bg,
        light_solve: LightSolveConfig::default(),
    };
    let mut raster = Raster::new();
    if caches != Caches::None {
        let mut bufs = CachedBuffers::new(synth.vertices());
        let mut inst = if caches == Caches::Host { bufs.instance() } else { bufs.compact_instance() };
        let r = image_chain(&problem, &ip, &lm_fit.best, 300, &mut inst, &mut raster, &mut rng, NoObserver).unwrap();
        (r, inst.frames().unwrap().reshaded)
    } else {
        let mut bufs = Buffers::new(synth.vertices());
        let mut inst = bufs.instance();
        (image_chain(&problem, &ip, &lm_fit.best, 300, &mut inst, &mut raster, &mut rng, NoObserver).unwrap(), 0)
    }
}

#[test]
fn a_chain_with_caches_is_the_chain_without() {
    let (plain, _) = chain(Caches::None, 5);
    for caches in [Caches::Host, Caches::Device] {
        let (cached, reshaded) = chain(caches, 5);
        // Debug prints every float in its shortest exact form: equal strings, equal bits.
        assert_eq!(format!("{cached:?}"), format!("{plain:?}"));
        assert!(reshaded > 30, "colour and light proposals are re-shaded ({reshaded})");
    }
}

#[test]
fn the_shading_cache_gives_shade_vertices_colours_and_errors() {
    use gpmm_core::render::{shade_vertices, Pose, VertexError};
    let n = 50;
    let normals: Vec<Vec3> = (0..n).map(|i| [(i as f32 * 0.37).sin(), (i as f32 * 0.11).cos(), 0.5 + (i % 7) as f32 * 0.1]).collect();
    let albedo_a: Vec<Vec3> = (0..n).map(|i| [0.2 + (i % 5) as f32 * 0.1, 0.3, 0.7 - (i % 3) as f32 * 0.1]).collect();
    let albedo_b: Vec<Vec3> = albedo_a.iter().map(|a| [a[2], a[0], a[1]]).collect();
    let pose_a = Pose { yaw: 0.3, pitch: -0.1, roll: 0.05, translation: [0.0, 0.0, -500.0] };
    let pose_b = Pose { yaw: 0.31, ..pose_a };
    let light_a = ShLight::from_ambient_diffuse([0.6; 3], [0.4, 0.3, 0.2], [0.2, 0.5, 0.8]);
    let light_b = ShLight::from_ambient_diffuse([0.5; 3], [0.5, 0.3, 0.2], [-0.2, 0.5, 0.8]);
    let (mut basis, mut irradiance) = (vec![[0.0; SH_COEFFS]; n], vec![[0.0; 3]; n]);
    let mut cache = ShadingCache::new(ShadingBuffers { basis: &mut basis, irradiance: &mut irradiance }, n).unwrap();
    let steps = [
        (&albedo_a, 1, &pose_a, &light_a),
        (&albedo_b, 2, &pose_a, &light_a),
        (&albedo_b, 2, &pose_a, &light_b),
        (&albedo_a, 1, &pose_b, &light_b),
    ];
    for (i, (albedos, albedos_id, pose, light)) in steps.into_iter().enumerate() {
        let mut want = vec![ProjectedVertex::INVALID; n];
        let mut got = vec![ProjectedVertex::INVALID; n];
        shade_vertices(albedos, &normals, pose, light, &mut want).unwrap();
        cache.shade(albedos, albedos_id, &normals, 1, pose, light, &mut got).unwrap();
        let bits = |v: &[ProjectedVertex]| v.iter().map(|p| p.color.map(f32::to_bits)).collect::<Vec<_>>();
        assert_eq!(bits(&got), bits(&want), "step {i}");
    }
    // A non-finite albedo is refused as shade_vertices refuses it, from a cached state too.
    let mut bad = albedo_a.clone();
    bad[3][1] = f32::NAN;
    let mut out = vec![ProjectedVertex::INVALID; n];
    assert_eq!(shade_vertices(&bad, &normals, &pose_b, &light_b, &mut out), Err(VertexError::NonFinite));
    assert_eq!(cache.shade(&bad, 3, &normals, 1, &pose_b, &light_b, &mut out), Err(VertexError::NonFinite));
    assert_eq!(cache.shade(&albedo_a, 1, &normals[1..], 1, &pose_b, &light_b, &mut out), Err(VertexError::LengthMismatch));
}
