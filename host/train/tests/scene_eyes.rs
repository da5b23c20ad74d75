//! Open eyes painted over the scan's shut ones in training scenes: only the eyes' vertices
//! change, some turn iris-dark, and the lid landmarks move apart onto the painted rims while the
//! corners stay where they are.

mod common;

use gpmm_host::gp::model::GpModel;
use gpmm_host::render::Instance;
use gpmm_train::scene::eyes::OpenEyes;
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;

fn model() -> Option<GpModel> {
    common::template_model(4000, 4, 100)
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
fn a_model_without_the_ibug_landmarks_has_no_eyes_to_open() {
    let Some(mut model) = model() else { return };
    model.landmarks.truncate(40);
    assert!(OpenEyes::of_model(&model).is_none());
}
