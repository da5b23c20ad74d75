//! `gpmm learn` end to end on a tiny model (`--quick`): an iteration writes a model every command
//! can read, with its record; an unreadable image is recorded, not fatal; a rerun keeps the
//! complete iteration; bad arguments give clear errors.

mod common;
use common::{fails, gpmm, ok, read_json};

use std::path::Path;

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn learn_quick_makes_a_model_records_every_image_and_resumes() {
    let Some(data) = gpmm_host::data::data_dir_for_tests() else { return };
    let dir = tempfile::tempdir().unwrap();
    let t = data.join("template/lee-perry-smith");
    let images = dir.path().join("images");
    ok(&gpmm(&[
        "synth",
        "--ict",
        s(&data.join("ict")),
        "--template-dir",
        s(&t),
        "--count",
        "2",
        "--yaws",
        "0,30",
        "--seed",
        "9",
        "-o",
        s(&images),
    ]));
    // A broken "image" among them: it is recorded as failed, the run goes on.
    std::fs::write(images.join("broken.png"), b"not a png").unwrap();
    let model = dir.path().join("tiny.gpmm");
    let (ply, lm) = (t.join("lee-perry-smith.ply"), t.join("landmarks_ibug68.json"));
    ok(&gpmm(&[
        "build",
        "--template",
        s(&ply),
        "--landmarks",
        s(&lm),
        "--vertices",
        "600",
        "--rank-shape",
        "10",
        "--rank-color",
        "10",
        "--nystrom-points",
        "300",
        "-o",
        s(&model),
    ]));
    let init = dir.path().join("quick.init");
    ok(&gpmm(&["train-init", s(&model), "--quick", "-o", s(&init)]));
    let out = dir.path().join("learned");
    let args = ["learn", s(&model), s(&images), "--init", s(&init), "--quick", "--mirror", "--shape-from-shading", "-o", s(&out)];
    let printed = ok(&gpmm(&args));
    let learned = out.join("model_1.gpmm");
    assert_eq!(printed.trim(), s(&learned));
    let records = read_json(&out.join("iteration_1/records.json"));
    // Four renders and the broken file, each also mirrored.
    assert_eq!(records["images"], 10, "{records}");
    let list = records["records"].as_array().unwrap();
    let broken: Vec<&serde_json::Value> = list.iter().filter(|r| r["image"].as_str().unwrap().ends_with("broken.png")).collect();
    assert_eq!(broken.len(), 2);
    assert!(broken.iter().all(|r| r["accepted"] == false && r["reason"].as_str().unwrap().contains("broken.png")), "{broken:?}");
    let accepted = records["accepted"].as_u64().unwrap();
    assert!(accepted >= 2, "{records}");
    let rejected = records["rejected_overlap"].as_u64().unwrap() + records["rejected_albedo"].as_u64().unwrap();
    assert_eq!(accepted + rejected + records["failed"].as_u64().unwrap(), 10);
    // Shape from shading ran on every accepted fit, within the first iteration's albedo limit (8/255).
    let limit = records["max_albedo_change"].as_f64().unwrap();
    assert!((limit - 8.0 / 255.0).abs() < 1e-6, "{records}");
    for r in list.iter().filter(|r| r["accepted"] == true) {
        assert!(r["iou"].as_f64().unwrap() >= gpmm_host::learn::MIN_IOU, "{r}");
        assert!(r["albedo_change"].as_f64().unwrap() <= limit, "{r}");
        assert!(r["detail_vertices"].as_u64().unwrap() > 50 && r["detail_mm"].as_f64().unwrap() > 0.0, "{r}");
    }
    for name in ["samples.png", "reconstructions.png"] {
        assert!(out.join("iteration_1").join(name).is_file(), "{name} missing");
    }
    // The model: the template's topology and landmarks, a rank below the accepted examples, its record.
    let m = gpmm_host::gp::model_io::load(&learned).unwrap();
    let base = gpmm_host::gp::model_io::load(&model).unwrap();
    assert_eq!((m.vertices(), &m.triangles, &m.landmarks), (base.vertices(), &base.triangles, &base.landmarks));
    assert!(m.shape.rank() >= 1 && m.shape.rank() < accepted as usize, "rank {}", m.shape.rank());
    let rec = m.metadata.learning.as_ref().expect("a learning record");
    assert_eq!((rec.iteration, rec.images, rec.accepted as u64), (1, 10, accepted));
    assert!(rec.max_albedo_change.is_some_and(|m| (f64::from(m) - limit).abs() < 1e-6), "{rec:?}");
    assert_eq!(m.metadata.template.attribution, base.metadata.template.attribution);
    // Another command reads it: a fit with landmarks.
    let fit_dir = dir.path().join("fit");
    let image = images.join("0000_yaw00.png");
    let pts = images.join("0000_yaw00.pts");
    ok(&gpmm(&[
        "fit",
        s(&learned),
        s(&image),
        "--landmarks",
        s(&pts),
        "--landmark-steps",
        "200",
        "--image-steps",
        "10",
        "-o",
        s(&fit_dir),
    ]));
    // A rerun keeps the complete iteration: nothing is fitted again, the model is unchanged.
    let before = std::fs::read(&learned).unwrap();
    let rerun = gpmm(&args);
    ok(&rerun);
    assert!(String::from_utf8_lossy(&rerun.stderr).contains("complete on disk"), "{}", String::from_utf8_lossy(&rerun.stderr));
    assert_eq!(std::fs::read(&learned).unwrap(), before);
    // Without shape from shading (the default): the fitted instances alone, no albedo change
    // recorded, another model.
    let plain = dir.path().join("plain");
    let args = ["learn", s(&model), s(&images), "--init", s(&init), "--quick", "--mirror", "-o", s(&plain)];
    ok(&gpmm(&args));
    let records = read_json(&plain.join("iteration_1/records.json"));
    assert!(records.get("max_albedo_change").is_none(), "{records}");
    assert!(records["records"].as_array().unwrap().iter().all(|r| r["albedo_change"].is_null()), "{records}");
    assert_ne!(std::fs::read(plain.join("model_1.gpmm")).unwrap(), before);
}

#[test]
fn learn_refuses_bad_arguments_clearly() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("nope");
    let e = fails(&gpmm(&["learn", "m.gpmm", s(&missing), "--init", "x.init", "-o", s(dir.path())]));
    assert!(e.contains("nope") && e.contains("no such image or directory"), "{e}");
    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    let e = fails(&gpmm(&["learn", "m.gpmm", s(&empty), "--init", "x.init", "-o", s(dir.path())]));
    assert!(e.contains("empty") && e.contains("no .png"), "{e}");
    let e = fails(&gpmm(&["learn", "m.gpmm", s(&empty), "--init", "x.init", "--min-iou", "1.5", "-o", s(dir.path())]));
    assert!(e.contains("--min-iou 1.5"), "{e}");
}
