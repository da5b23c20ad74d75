//! The jaw contour as a silhouette on the real template model: at a 40° yaw the outline vertices
//! the core selects for the contour landmarks of the side turned away are where the surface turns
//! away from the camera (normal ⟂ viewing ray), unlike the fixed contour vertices on that cheek.

use gpmm_core::fit::{LandmarkTarget, Silhouette, MAX_CONTOUR, NO_VERTEX};
use gpmm_core::geometry::mat_vec;
use gpmm_core::model::{FitParams, Instance, InstanceBuffers, MorphableModel};
use gpmm_core::render::{Pose, ProjectedVertex, ShLight};
use gpmm_host::data::{data_dir_for_tests, template_dir};
use gpmm_host::gp::kernel::ModelKernel;
use gpmm_host::gp::lowrank::{NystromOptions, RankSpec};
use gpmm_host::gp::model::{build_model, BuildOptions};
use gpmm_host::mesh::template::{load_template, TemplateOptions};

const W: u32 = 128;

/// |cos| between the camera-space normal of `v` and its viewing ray.
fn grazing(inst: &Instance<'_, 4, 4>, pose: &Pose, v: usize) -> f32 {
    let r = pose.rotation();
    let q = mat_vec(&r, inst.positions()[v]);
    let q = [q[0] + pose.translation[0], q[1] + pose.translation[1], q[2] + pose.translation[2]];
    let n = mat_vec(&r, inst.normals()[v]);
    let len = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]).sqrt();
    ((n[0] * q[0] + n[1] * q[1] + n[2] * q[2]) / len).abs()
}

#[test]
fn contour_landmarks_land_on_the_outline() {
    let Some(data) = data_dir_for_tests() else { return };
    let dir = template_dir(&data);
    let opts = TemplateOptions { vertices: Some(4000), ..Default::default() };
    let template = load_template(&dir.join("lee-perry-smith.ply"), &dir.join("landmarks_ibug68.json"), &opts).unwrap();
    let build = BuildOptions {
        kernel: ModelKernel::SymmetricFull,
        hyperparameters: Default::default(),
        rank_shape: RankSpec::Count(4),
        rank_color: RankSpec::Count(4),
        nystrom: NystromOptions { points: 200, ..Default::default() },
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
    for yaw in [-40.0f32, 40.0] {
        let pose = Pose { yaw: yaw.to_radians(), pitch: 0.0, roll: 0.0, translation: [0.0, 0.0, -600.0] };
        let params = FitParams::<4, 4>::new(pose, 400.0, ShLight::ambient([1.0; 3]), 0, 0);
        let (mut pos, mut alb, mut nor, mut proj) =
            (vec![[0.0f32; 3]; n], vec![[0.0f32; 3]; n], vec![[0.0f32; 3]; n], vec![ProjectedVertex::INVALID; n]);
        let mut inst =
            Instance::<4, 4>::new(InstanceBuffers { positions: &mut pos, albedos: &mut alb, normals: &mut nor, projected: &mut proj }, n)
                .unwrap();
        inst.update(&model, &params, W, W).unwrap();
        // Targets: the fixed landmark vertices' projections (the outward directions come from them).
        let cam = params.camera(W, W);
        let points: Vec<[f32; 2]> = model
            .landmarks()
            .iter()
            .map(|&v| cam.project(pose.transform_point(gp.shape.mean[v as usize])).map(|s| [s.x, s.y]).unwrap())
            .collect();
        let valid = vec![true; points.len()];
        let target = LandmarkTarget::new(&points, &valid, 1.0).unwrap();
        let sil = Silhouette::new(&model, &target, 17).unwrap();
        eprintln!("pool of {} vertices", sil.pool_len());
        assert!(sil.pool_len() > 50, "pool of {} vertices", sil.pool_len());
        let mut ids = [NO_VERTEX; MAX_CONTOUR];
        sil.select(&pose, &cam, &target, &mut ids);
        let selected: Vec<usize> = (0..17).filter(|&i| ids[i] != NO_VERTEX).collect();
        // Only the side turned away has an occluding outline: 6 of the 17 points (not the chin's 5).
        assert!(selected.len() >= 5, "yaw {yaw}: only {} contour landmarks found an outline vertex", selected.len());
        assert!(selected.iter().all(|&i| i <= 8) || selected.iter().all(|&i| i >= 8), "yaw {yaw}: both sides selected: {selected:?}");
        // The side points (not the chin): the outline is where the surface grazes the ray.
        let side: Vec<usize> = selected.iter().copied().filter(|&i| !(6..=10).contains(&i)).collect();
        let mean = |f: &dyn Fn(usize) -> f32| side.iter().map(|&i| f(i)).sum::<f32>() / side.len() as f32;
        for &i in &selected {
            let (a, b) = (grazing(&inst, &pose, ids[i] as usize), grazing(&inst, &pose, model.landmarks()[i] as usize));
            eprintln!("  {i:>2}: outline {a:.2} fixed {b:.2}");
        }
        let on_outline = mean(&|i| grazing(&inst, &pose, ids[i] as usize));
        let grazing_points = side.iter().filter(|&&i| grazing(&inst, &pose, ids[i] as usize) < 0.1).count();
        let fixed = mean(&|i| grazing(&inst, &pose, model.landmarks()[i] as usize));
        eprintln!("yaw {yaw}: mean |cos(normal, ray)| of the side contour points: outline {on_outline:.2}, fixed vertices {fixed:.2}");
        // Most points graze (the ends of the jaw side, next to the ear and the chin, less so).
        assert!(2 * grazing_points >= side.len(), "yaw {yaw}: only {grazing_points} of {} selected vertices graze the ray", side.len());
        assert!(on_outline < fixed, "yaw {yaw}: outline {on_outline:.2} vs fixed {fixed:.2}");
    }
}
