//! The head put around training faces: it continues the face (same frame, face first, seams
//! closed near the face, untouched far from it) and refuses a model built from another scan. And
//! what is behind it: background photos change the background only.

mod common;

use common::template_files as files;
use gpmm_host::gp::model::GpModel;
use gpmm_host::render::{Instance, Renderer};
use gpmm_train::scene::backgrounds::Backgrounds;
use gpmm_train::scene::head::HeadContext;
use gpmm_train::scene::{face_free_frame, render_scene, FaceModel, Openings, Scene, SceneRanges, SceneSource};
use image::{Rgb, RgbImage};
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;

/// The template at 800 vertices, 8 + 8 components.
fn small_model() -> GpModel {
    common::template_model(800, 8, 200).expect("data directory")
}

fn dist(a: [f32; 3], b: [f32; 3]) -> f32 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// Whole training scenes of `model`'s faces on `head` (the default ranges' eye and mouth openings).
struct Scenes<'a> {
    model: &'a GpModel,
    head: &'a HeadContext,
    openings: Openings,
    renderer: Renderer,
}

impl<'a> Scenes<'a> {
    fn new(model: &'a GpModel, head: &'a HeadContext) -> Self {
        Self { model, head, openings: Openings::of_model(model, &SceneRanges::default()), renderer: Renderer::new() }
    }

    /// Scene `i` of the stream `seed` drawn with `ranges`.
    fn render(&mut self, ranges: &SceneRanges, seed: u64, i: u64) -> Option<Scene> {
        let faces = [FaceModel { model: self.model, openings: &self.openings }];
        let source = SceneSource { faces: &faces, head: Some(self.head), ranges, backgrounds: None };
        render_scene(source, seed, i, &mut self.renderer)
    }
}

#[test]
fn the_head_continues_the_face_and_leaves_the_far_head_alone() {
    let Some((mesh, lm)) = files() else { return };
    let model = small_model();
    let head = HeadContext::load(&model, &mesh, &lm).unwrap();
    assert!(head.vertices() > 2 * model.vertices(), "{} head vertices", head.vertices());
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
    let mean = Instance::of_model(&model, &[], &[]).unwrap();
    let face = Instance::of_model(&model, &[2.5, -2.0, 1.5], &[1.0]).unwrap();
    let rest = head.around(&model, &mean, &mut rng);
    let moved = head.around(&model, &face, &mut rng);
    let n = model.vertices();
    // Face first, unchanged: the model's landmark ids still index the face.
    assert_eq!(&moved.instance.positions[..n], &face.positions[..]);
    assert_eq!(moved.instance.positions.len(), n + head.vertices());
    assert_eq!(moved.triangles.len(), model.triangles.len() + (rest.triangles.len() - model.triangles.len()));
    assert!(moved.triangles.iter().flatten().all(|&v| (v as usize) < moved.instance.positions.len()));
    // Around the mean face the head lies just beneath it (inset 1.5 mm).
    let gaps: Vec<f32> = (n..rest.instance.positions.len())
        .map(|i| mean.positions.iter().map(|p| dist(*p, rest.instance.positions[i])).fold(f32::INFINITY, f32::min))
        .collect();
    let near = gaps.iter().filter(|&&g| g < 3.0).count();
    assert!(near > n / 2, "only {near} head vertices within 3 mm of the face");
    // The head vertex nearest each face vertex moves with it; the farthest head vertices do not move.
    let shift = |i: usize| dist(moved.instance.positions[i], rest.instance.positions[i]);
    let mut face_moves = Vec::new();
    for (f, p) in face.positions.iter().enumerate().step_by(7) {
        let (i, _) = (n..rest.instance.positions.len())
            .map(|i| (i, dist(rest.instance.positions[i], mean.positions[f])))
            .fold((0, f32::INFINITY), |a, b| if b.1 < a.1 { b } else { a });
        face_moves.push((shift(i) - dist(*p, mean.positions[f])).abs());
    }
    face_moves.sort_by(f32::total_cmp);
    assert!(face_moves[face_moves.len() / 2] < 1.0, "median seam gap {} mm", face_moves[face_moves.len() / 2]);
    let far = gaps.iter().zip(n..).filter(|(g, _)| **g > 200.0).map(|(_, i)| shift(i)).fold(0.0f32, f32::max);
    assert!(gaps.iter().any(|&g| g > 200.0), "the head has no part 20 cm from the face");
    assert!(far < 0.01, "a vertex 20 cm from the face moved by {far} mm");
}

#[test]
fn a_model_of_another_scan_is_refused_with_the_file_named() {
    let Some((mesh, lm)) = files() else { return };
    let mut model = small_model();
    for p in &mut model.shape.mean {
        p[1] += 25.0;
    }
    let e = HeadContext::load(&model, &mesh, &lm).unwrap_err().to_string();
    assert!(e.contains("lee-perry-smith.ply") && e.contains("not built from this template"), "{e}");
}

#[test]
fn dressed_heads_keep_the_face_and_its_labels() {
    let Some((mesh, lm)) = files() else { return };
    let model = small_model();
    let head = HeadContext::load(&model, &mesh, &lm).unwrap();
    let n = model.vertices();
    let face = Instance::of_model(&model, &[1.5, -1.0], &[0.5]).unwrap();
    let (mut changed, mut moved_out) = (0, 0);
    for seed in 0..6 {
        // The same draws for the bare head: dressing changes the head's colours and pushes hair out.
        let bare = head.around(&model, &face, &mut Xoshiro256PlusPlus::seed_from_u64(seed));
        let mut dress = Xoshiro256PlusPlus::seed_from_u64(100 + seed);
        let (dressed, _) = head.dressed_around(&model, &face, &mut Xoshiro256PlusPlus::seed_from_u64(seed), &mut dress);
        assert_eq!(&dressed.instance.positions[..n], &face.positions[..], "draw {seed}: the face moved");
        assert_eq!(&dressed.instance.albedos[..n], &face.albedos[..], "draw {seed}: the face was recoloured");
        assert_eq!(dressed.triangles, bare.triangles);
        changed += usize::from(dressed.instance.albedos != bare.instance.albedos);
        let lift = (n..dressed.instance.positions.len())
            .map(|i| dist(dressed.instance.positions[i], bare.instance.positions[i]))
            .fold(0.0f32, f32::max);
        assert!(lift <= 35.0 + 1e-3, "draw {seed}: hair stands {lift} mm off the head");
        moved_out += usize::from(lift > 1.0);
    }
    assert!(changed >= 5, "only {changed} of 6 heads were dressed");
    assert!(moved_out >= 2, "hair stood off the head in only {moved_out} of 6 draws");
    // Whole scenes: the same labels, other pixels.
    let dressed = SceneRanges::default();
    let base = SceneRanges { dressed: false, ..dressed.clone() };
    let mut scenes = Scenes::new(&model, &head);
    let mut scene = |ranges: &SceneRanges, i: u64| scenes.render(ranges, 9, i);
    let mut compared = 0;
    for i in 0..4 {
        let (Some(a), Some(d)) = (scene(&base, i), scene(&dressed, i)) else { continue };
        compared += 1;
        assert_eq!(d.landmarks, a.landmarks);
        assert_eq!((d.angles, &d.light), (a.angles, &a.light));
        assert_ne!(d.frame, a.frame, "scene {i}: dressing changed no pixel");
    }
    assert!(compared >= 3, "only {compared} of 4 scenes rendered");
}

/// Fraction of `frame`'s pixels (in rows `rows`) that are clearly green.
fn green_share(frame: &RgbImage, rows: std::ops::Range<u32>) -> f64 {
    let px: Vec<&Rgb<u8>> = frame.enumerate_pixels().filter(|(_, y, _)| rows.contains(y)).map(|(_, _, p)| p).collect();
    px.iter().filter(|p| p[1] > p[0].saturating_add(60) && p[1] > p[2].saturating_add(60)).count() as f64 / px.len().max(1) as f64
}

#[test]
fn a_background_photo_changes_the_background_and_nothing_else() {
    let Some(model) = common::template_model(800, 8, 200) else { return };
    // Photographic looks would turn some green frames grey: they are tested on their own below.
    let ranges = SceneRanges { dressed: false, look_share: 0.0, ..SceneRanges::default() };
    let openings = Openings::of_model(&model, &ranges);
    let green = Backgrounds::from_photos(vec![RgbImage::from_pixel(640, 480, Rgb([20, 200, 30]))], 1.0);
    let faces = [FaceModel { model: &model, openings: &openings }];
    let plain = SceneSource { faces: &faces, head: None, ranges: &ranges, backgrounds: None };
    let photo = SceneSource { backgrounds: Some(&green), ..plain };
    let mut renderer = Renderer::new();
    let mut greener = 0;
    for i in 0..6 {
        let (Some(a), Some(b)) = (render_scene(plain, 5, i, &mut renderer), render_scene(photo, 5, i, &mut renderer)) else { continue };
        assert_eq!(a.landmarks, b.landmarks, "scene {i}: the face moved");
        assert_eq!((a.angles, &a.light), (b.angles, &b.light));
        // The top rows are mostly background: green with the photo.
        let rows = 0..b.frame.height() / 8;
        greener += usize::from(green_share(&b.frame, rows.clone()) > 0.5 && green_share(&a.frame, rows) < 0.5);
    }
    assert!(greener >= 4, "only {greener} of 6 scenes show the photo");
    // Face-free frames are views of the photo through the camera effects, the same for a seed.
    let f = face_free_frame(photo, 9, 2);
    assert!(green_share(&f, 0..f.height()) > 0.9, "{}", green_share(&f, 0..f.height()));
    assert_eq!(f, face_free_frame(photo, 9, 2));
    assert_ne!(face_free_frame(plain, 9, 2), f);
}

#[test]
fn looks_and_occluders_change_pixels_never_labels() {
    let Some(model) = common::template_model(800, 8, 200) else { return };
    let plain = SceneRanges { dressed: false, look_share: 0.0, occluders: false, ..SceneRanges::default() };
    let looks = SceneRanges { look_share: 1.0, ..plain.clone() };
    let worn = SceneRanges { occluders: true, ..plain.clone() };
    let openings = Openings::of_model(&model, &plain);
    let faces = [FaceModel { model: &model, openings: &openings }];
    let source = |ranges| SceneSource { faces: &faces, head: None, ranges, backgrounds: None };
    let mut renderer = Renderer::new();
    let (mut compared, mut looked, mut occluded) = (0, 0, 0);
    for i in 0..40 {
        let Some(a) = render_scene(source(&plain), 4, i, &mut renderer) else { continue };
        for (ranges, changed) in [(&looks, &mut looked), (&worn, &mut occluded)] {
            let b = render_scene(source(ranges), 4, i, &mut renderer).expect("the same scene renders");
            assert_eq!((&a.landmarks, a.angles, &a.light), (&b.landmarks, b.angles, &b.light), "scene {i}: a label changed");
            *changed += usize::from(a.frame != b.frame);
        }
        compared += 1;
    }
    assert!(compared >= 30, "only {compared} of 40 scenes rendered");
    assert_eq!(looked, compared, "every scene gets a look at share 1");
    // A tenth wear dark glasses, one in twenty a mask: a few of 40, not most.
    assert!((1..=15).contains(&occluded), "{occluded} of {compared} scenes occluded");
}
