//! Open eyes and mouths painted over the scan's shut ones in training scenes: only the eyes'
//! vertices (the mouth's pixels) change, some turn iris-dark (teeth or mouth), and the lid (inner
//! lip) landmarks move apart onto the painted rims while the corners stay where they are.

use gpmm_host::data::{data_dir_for_tests, template_dir};
use gpmm_host::gp::kernel::ModelKernel;
use gpmm_host::gp::lowrank::{NystromOptions, RankSpec};
use gpmm_host::gp::model::{build_model, BuildOptions, GpModel};
use gpmm_host::init::eyes::OpenEyes;
use gpmm_host::init::mouth::OpenMouth;
use gpmm_host::mesh::template::{load_template, TemplateOptions};
use gpmm_host::render::Instance;
use image::{Rgba, RgbaImage};
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;

fn model() -> Option<GpModel> {
    let dir = template_dir(&data_dir_for_tests()?);
    let (mesh, lm) = (dir.join("lee-perry-smith.ply"), dir.join("landmarks_ibug68.json"));
    let template = load_template(&mesh, &lm, &TemplateOptions { vertices: Some(4000), ..Default::default() }).unwrap();
    let build = BuildOptions {
        kernel: ModelKernel::SymmetricFull,
        hyperparameters: Default::default(),
        rank_shape: RankSpec::Count(4),
        rank_color: RankSpec::Count(4),
        nystrom: NystromOptions { points: 100, ..Default::default() },
    };
    Some(build_model(&template, &build, |_, _, _| {}))
}

#[test]
fn open_eyes_repaint_only_the_eyes_and_move_the_lid_landmarks_apart() {
    let Some(model) = model() else { return };
    let eyes = OpenEyes::of_model(&model).expect("a model with the 68 iBUG landmarks has eyes");
    let sizes = eyes.region_sizes();
    assert!(sizes.len() == 2 && sizes.iter().all(|&n| n >= 20), "eye regions of {sizes:?} vertices");
    let mean = Instance::of_model(&model, &[], &[]).unwrap();
    // A frontal orthographic view, 4 px per mm, y down.
    let projected = |v: u32| model.shape.mean.get(v as usize).map(|p| [4.0 * p[0], -4.0 * p[1]]);
    let shut: Vec<[f32; 2]> = model.landmarks.iter().map(|&i| projected(i).unwrap()).collect();
    let (mut opened, mut stayed_shut) = (0, 0);
    for seed in 0..20 {
        let mut albedos = mean.albedos.clone();
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        let Some(opening) = eyes.paint(&mut albedos, &mut rng) else {
            assert_eq!(albedos, mean.albedos, "shut eyes repainted");
            stayed_shut += 1;
            continue;
        };
        opened += 1;
        // Only vertices near the eyes change, and some of them become iris- or pupil-dark.
        let eye_lm: Vec<[f32; 3]> = (36..48).map(|k| model.shape.mean[model.landmarks[k] as usize]).collect();
        let near_eye = |p: [f32; 3]| eye_lm.iter().any(|q| (0..3).map(|k| (p[k] - q[k]).powi(2)).sum::<f32>() < 30.0f32.powi(2));
        let changed: Vec<usize> = (0..albedos.len()).filter(|&i| albedos[i] != mean.albedos[i]).collect();
        assert!(!changed.is_empty(), "seed {seed}: nothing painted");
        assert!(changed.iter().all(|&i| near_eye(model.shape.mean[i])), "seed {seed}: a vertex away from the eyes was repainted");
        assert!(changed.iter().any(|&i| albedos[i].iter().all(|&c| c < 0.2)), "seed {seed}: no dark iris or pupil");
        let mut lm = shut.clone();
        eyes.relabel_lids(opening, projected, &mut lm);
        for first in [36usize, 42] {
            // Corners unchanged; upper lid points above the lower ones (y down), between the corners.
            assert_eq!(lm[first], shut[first]);
            assert_eq!(lm[first + 3], shut[first + 3]);
            let width = (shut[first + 3][0] - shut[first][0]).abs();
            for (up, down) in [(first + 1, first + 5), (first + 2, first + 4)] {
                let gap = lm[down][1] - lm[up][1];
                assert!(gap > 0.1 * width && gap < 0.6 * width, "seed {seed}: lids {up}/{down} {gap} px apart, eye {width} px wide");
                for k in [up, down] {
                    assert!(lm[k][0] > shut[first][0].min(shut[first + 3][0]) && lm[k][0] < shut[first][0].max(shut[first + 3][0]));
                }
            }
        }
    }
    assert!(opened >= 12 && stayed_shut >= 1, "{opened} opened, {stayed_shut} shut of 20");
}

#[test]
fn open_mouths_paint_only_between_the_lips_and_move_the_inner_lip_landmarks_apart() {
    let Some(model) = model() else { return };
    let mouth = OpenMouth::of_model(&model).expect("a model with the 68 iBUG landmarks has a mouth");
    // A frontal orthographic view of the mean, 4 px per mm, y down, centred in a 512 px frame.
    let projected = |v: u32| model.shape.mean.get(v as usize).map(|p| [256.0 + 4.0 * p[0], 256.0 - 4.0 * p[1]]);
    let shut: Vec<[f32; 2]> = model.landmarks.iter().map(|&i| projected(i).unwrap()).collect();
    let grey = Rgba([120u8, 120, 120, 255]);
    let (lo, hi) = shut[48..60]
        .iter()
        .fold(([f32::MAX; 2], [f32::MIN; 2]), |(l, h), p| ([l[0].min(p[0]), l[1].min(p[1])], [h[0].max(p[0]), h[1].max(p[1])]));
    let (mut opened, mut stayed_shut, mut with_teeth) = (0, 0, 0);
    for seed in 0..30 {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        let Some(look) = mouth.draw(&mut rng) else {
            stayed_shut += 1;
            continue;
        };
        opened += 1;
        let mut frame = RgbaImage::from_pixel(512, 512, grey);
        let mut lm = shut.clone();
        mouth.paint(&look, [1.0; 3], projected, &mut frame, &mut lm);
        let changed: Vec<(u32, u32, Rgba<u8>)> =
            frame.enumerate_pixels().filter(|(_, _, p)| **p != grey).map(|(x, y, p)| (x, y, *p)).collect();
        assert!(changed.len() > 20, "seed {seed}: {} pixels painted", changed.len());
        // Inside the outer lips' box, and dark (the mouth) or bright (teeth).
        for &(x, y, p) in &changed {
            assert!(
                x as f32 >= lo[0] - 1.0 && x as f32 <= hi[0] + 1.0 && y as f32 >= lo[1] - 1.0 && y as f32 <= hi[1] + 1.0,
                "seed {seed}: ({x}, {y}) painted outside the lips"
            );
            // The mouth is darker than 0.1 (26), the teeth at least 0.6 × 0.45 (68) even at the corners.
            assert!(p[0] <= 26 || p[0] >= 68, "seed {seed}: a painted pixel {p:?} is neither mouth nor teeth");
        }
        with_teeth += usize::from(changed.iter().any(|(_, _, p)| p[0] >= 68));
        assert!(changed.iter().any(|(_, _, p)| p[0] <= 26), "seed {seed}: no dark mouth");
        // Inner corners unchanged; upper inner lip points above the lower ones.
        assert_eq!((lm[60], lm[64]), (shut[60], shut[64]));
        let width = shut[64][0] - shut[60][0];
        for (up, down) in [(61, 67), (62, 66), (63, 65)] {
            let gap = lm[down][1] - lm[up][1];
            assert!(gap > 0.1 * width && gap < 0.6 * width, "seed {seed}: inner lips {up}/{down} {gap} px apart, mouth {width} px wide");
        }
        // Outside the face (alpha 0) nothing is painted.
        let mut empty = RgbaImage::from_pixel(512, 512, Rgba([0, 0, 0, 0]));
        mouth.paint(&look, [1.0; 3], projected, &mut empty, &mut shut.clone());
        assert!(empty.pixels().all(|p| p[3] == 0 && p[0] == 0));
    }
    assert!(opened >= 4 && stayed_shut >= 10 && with_teeth >= 2, "{opened} opened ({with_teeth} with teeth), {stayed_shut} shut of 30");
}

#[test]
fn a_model_without_the_ibug_landmarks_has_no_eyes_or_mouth_to_open() {
    let Some(mut model) = model() else { return };
    model.landmarks.truncate(40);
    assert!(OpenEyes::of_model(&model).is_none());
    assert!(OpenMouth::of_model(&model).is_none());
}
