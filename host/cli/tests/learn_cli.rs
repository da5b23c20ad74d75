//! `gpmm learn` end to end on a tiny model (`--quick`): an iteration writes a model every command
//! can read, with its record; an unreadable image is recorded, not fatal; a rerun keeps the
//! complete iteration; a development set decides which model is kept; bad arguments give clear
//! errors.

mod common;
use common::{fails, gpmm, ok, people_folder, read_json};

use std::path::Path;

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Two identities at yaw 0 and 30 rendered by `gpmm synth` with `seed` into `out`.
fn synth(data: &Path, seed: u64, out: &Path) {
    let t = data.join("template/lee-perry-smith");
    let seed = seed.to_string();
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
        &seed,
        "-o",
        s(out),
    ]));
}

#[test]
fn learn_quick_makes_a_model_records_every_image_and_resumes() {
    let Some(data) = gpmm_host::data::data_dir_for_tests() else { return };
    let dir = tempfile::tempdir().unwrap();
    let t = data.join("template/lee-perry-smith");
    let images = dir.path().join("images");
    synth(&data, 9, &images);
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
    // The model: the template's topology and landmarks, the predecessor's rank and at least the
    // kept share of its variance (by default half of its covariance stays beside the fits'), its record.
    let m = gpmm_host::gp::model_io::load(&learned).unwrap();
    let base = gpmm_host::gp::model_io::load(&model).unwrap();
    assert_eq!((m.vertices(), &m.triangles, &m.landmarks), (base.vertices(), &base.triangles, &base.landmarks));
    assert_eq!(m.shape.rank(), base.shape.rank());
    let trace = |e: &[f64]| e.iter().sum::<f64>();
    let kept = gpmm_host::learn::DEFAULT_KEEP_VARIANCE * trace(&base.shape.eigenvalues);
    assert!(trace(&m.shape.eigenvalues) >= kept * 0.99, "{} < {kept}", trace(&m.shape.eigenvalues));
    let rec = m.metadata.learning.as_ref().expect("a learning record");
    assert_eq!((rec.iteration, rec.images, rec.accepted as u64), (1, 10, accepted));
    assert!(rec.max_albedo_change.is_some_and(|m| (f64::from(m) - limit).abs() < 1e-6), "{rec:?}");
    // The loop's fits: --quick's 40 image steps, the image chain fitting the shape too.
    let shape_share = gpmm_host::learn::wake_fit_options().fit.proposals.image.shape;
    assert!(shape_share > 0.0);
    assert_eq!((rec.image_steps, rec.image_shape_share), (Some(40), Some(shape_share)), "{rec:?}");
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
    let args = ["learn", s(&model), s(&images), "--init", s(&init), "--quick", "--mirror", "--keep-variance", "0", "-o", s(&plain)];
    ok(&gpmm(&args));
    // Of the fits alone (no kept share): a PCA of the accepted examples, fewer components than examples.
    let alone = gpmm_host::gp::model_io::load(&plain.join("model_1.gpmm")).unwrap();
    assert!(alone.shape.rank() >= 1 && alone.shape.rank() < accepted as usize, "rank {}", alone.shape.rank());
    let records = read_json(&plain.join("iteration_1/records.json"));
    assert!(records.get("max_albedo_change").is_none(), "{records}");
    assert!(records["records"].as_array().unwrap().iter().all(|r| r["albedo_change"].is_null()), "{records}");
    assert_ne!(std::fs::read(plain.join("model_1.gpmm")).unwrap(), before);

    // From landmark files instead of the init file (here the renders' own exact points): no init
    // needed, mirror images mirrored with their points; an image without a file is recorded.
    let from_files = dir.path().join("from-files");
    let args = ["learn", s(&model), s(&images), "--landmarks-dir", s(&images), "--quick", "--mirror", "-o", s(&from_files)];
    ok(&gpmm(&args));
    let records = read_json(&from_files.join("iteration_1/records.json"));
    let list = records["records"].as_array().unwrap();
    let renders: Vec<&serde_json::Value> = list.iter().filter(|r| r["image"].as_str().unwrap().ends_with("yaw00.png")).collect();
    assert_eq!(renders.len(), 4, "{records}");
    assert!(renders.iter().all(|r| r["accepted"] == true && r["score"].is_null()), "{renders:?}");
    let broken: Vec<&serde_json::Value> = list.iter().filter(|r| r["image"].as_str().unwrap().ends_with("broken.png")).collect();
    assert!(broken.iter().all(|r| r["accepted"] == false), "{broken:?}");
    let m = gpmm_host::gp::model_io::load(&from_files.join("model_1.gpmm")).unwrap();
    assert!(m.metadata.learning.as_ref().unwrap().init.contains("landmark files"), "{:?}", m.metadata.learning);
    let start = gpmm_host::gp::model_io::load(&model).unwrap();
    assert_eq!(m.landmarks, start.landmarks, "landmarks moved without --learn-landmarks");

    // Learning the points' convention: a "detector" that marks the nose tip (point 30) 6 px lower
    // than the renders' truth in every image; the learned model's nose-tip vertex moves down.
    let shifted = dir.path().join("shifted");
    std::fs::create_dir(&shifted).unwrap();
    for entry in std::fs::read_dir(&images).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "pts") {
            let mut pts = gpmm_host::photo::pts::read_pts(&path, false).unwrap().points;
            pts[30][1] += 6.0;
            std::fs::write(shifted.join(path.file_name().unwrap()), gpmm_host::photo::pts::pts_string(&pts)).unwrap();
        }
    }
    let learned_lm = dir.path().join("learned-landmarks");
    let args =
        ["learn", s(&model), s(&images), "--landmarks-dir", s(&shifted), "--learn-landmarks", "--quick", "--mirror", "-o", s(&learned_lm)];
    ok(&gpmm(&args));
    let m = gpmm_host::gp::model_io::load(&learned_lm.join("model_1.gpmm")).unwrap();
    let (old, new) = (start.landmarks[30] as usize, m.landmarks[30] as usize);
    // Model y points up; 6 px is about 10 mm on these renders.
    assert!(start.shape.mean[new][1] < start.shape.mean[old][1] - 2.0, "nose tip {old} -> {new}");
    assert!(m.metadata.learning.as_ref().unwrap().landmarks_moved.is_some_and(|n| n >= 1), "{:?}", m.metadata.learning);
    let records = read_json(&learned_lm.join("iteration_1/records.json"));
    let hits: Vec<&serde_json::Value> =
        records["records"].as_array().unwrap().iter().filter(|r| r["accepted"] == true).map(|r| &r["landmark_hits"]).collect();
    assert!(!hits.is_empty() && hits.iter().all(|h| h.as_array().is_some_and(|a| a.len() == 68)), "{records}");
    let e = fails(&gpmm(&["learn", s(&model), s(&images), "--init", s(&init), "--learn-landmarks", "-o", s(&learned_lm)]));
    assert!(e.contains("--learn-landmarks") && e.contains("--landmarks-dir"), "{e}");

    // With a development set: each model is measured against its predecessor and the best so
    // far there, every iteration runs, and DIR/model.gpmm is the best.
    let dev = dir.path().join("dev");
    synth(&data, 10, &dev);
    let checked = dir.path().join("checked");
    let args = [
        "learn",
        s(&model),
        s(&images),
        "--init",
        s(&init),
        "--quick",
        "--iterations",
        "2",
        "--dev",
        s(&dev),
        "--data",
        s(&data),
        "-o",
        s(&checked),
    ];
    let run = gpmm(&args);
    let printed = ok(&run);
    let kept_path = checked.join("model.gpmm");
    assert_eq!(printed.trim(), s(&kept_path));
    let stderr = String::from_utf8_lossy(&run.stderr).to_string();
    assert!(stderr.contains("development median"), "{stderr}");
    let c1 = read_json(&checked.join("iteration_1/records.json"))["development"].clone();
    let c2 = read_json(&checked.join("iteration_2/records.json"))["development"].clone();
    let median = |c: &serde_json::Value, k: &str| c[k]["median_mm"].as_f64().unwrap();
    let (start, m1, m2) = (median(&c1, "previous"), median(&c1, "learned"), median(&c2, "learned"));
    assert!([start, m1, m2].iter().all(|m| *m > 0.0 && *m < 50.0), "{c1} {c2}");
    assert!(c1["learned"]["fits"].as_u64().unwrap() >= 3, "{c1}");
    // The check fits as `gpmm fit` does (no shape moves in the image chain), not as the loop does.
    let cache = read_json(&checked.join("development/fits/model_1.json"));
    let used: serde_json::Value = serde_json::from_str(cache["key"]["settings"].as_str().unwrap()).unwrap();
    assert_eq!(used["proposals"]["image"]["shape"].as_f64(), Some(0.0), "{used}");
    let loop_record = gpmm_host::gp::model_io::load(&checked.join("model_1.gpmm")).unwrap().metadata.learning.unwrap();
    assert!(loop_record.image_shape_share.is_some_and(|s| s > 0.0), "{loop_record:?}");
    // The second iteration starts from model_1 and reuses its measured figure.
    assert_eq!(c2["previous"], c1["learned"], "{c2}");
    // Closer (a lower median) and identifying at most five points worse (the default drop): better.
    let rank1 = |c: &serde_json::Value, k: &str| c[k]["rank1"].as_f64().unwrap();
    let (r_start, r1, r2) = (rank1(&c1, "previous"), rank1(&c1, "learned"), rank1(&c2, "learned"));
    assert!([r_start, r1, r2].iter().all(|r| (0.0..=1.0).contains(r)) && c1["learned"]["probes"].as_u64().unwrap() > 0, "{c1} {c2}");
    assert!(stderr.contains("rank-1"), "{stderr}");
    let better = |m: f64, r: f64, than: (f64, f64)| m < than.0 && r >= than.1 - 0.05;
    assert_eq!(c1["better"].as_bool().unwrap(), better(m1, r1, (start, r_start)), "{c1}");
    assert_eq!(c1["closer"].as_bool().unwrap(), m1 < start, "{c1}");
    assert_eq!(c2["better"].as_bool().unwrap(), better(m2, r2, (m1, r1)), "{c2}");
    let (best, _, best_file) = [(m1, r1, checked.join("model_1.gpmm")), (m2, r2, checked.join("model_2.gpmm"))]
        .into_iter()
        .fold((start, r_start, model.clone()), |acc, (m, r, f)| if better(m, r, (acc.0, acc.1)) { (m, r, f) } else { acc });
    assert_eq!(c2["best_median_mm"].as_f64().unwrap(), best, "{c2}");
    assert_eq!(std::fs::read(&kept_path).unwrap(), std::fs::read(&best_file).unwrap(), "DIR/model.gpmm is not the best");
    assert!(stderr.contains(&format!("kept {}", s(&best_file))), "{stderr}");
    // Retraining the initializer after each iteration: the next iteration starts from the new
    // init file, the development images are re-read with it, and a rerun reuses it. The
    // retraining is shown real photos as `train-init --backgrounds` is (one of people here).
    let people = dir.path().join("people");
    people_folder(&people);
    let retrained = dir.path().join("retrained");
    let refused = fails(&gpmm(&["learn", s(&model), s(&images), "--init", s(&init), "--backgrounds", s(&people), "-o", s(&retrained)]));
    assert!(refused.contains("--retrain-init"), "{refused}");
    let args_r = [
        "learn",
        s(&model),
        s(&images),
        "--init",
        s(&init),
        "--quick",
        "--iterations",
        "2",
        "--retrain-init",
        "1",
        "--backgrounds",
        s(&people),
        "--photo-faces",
        "0.5",
        "--dev",
        s(&dev),
        "--data",
        s(&data),
        "-o",
        s(&retrained),
    ];
    let run_r = gpmm(&args_r);
    ok(&run_r);
    let first_init = retrained.join("iteration_1/init.init");
    let bytes = std::fs::read(&first_init).expect("iteration_1/init.init");
    assert_ne!(bytes, std::fs::read(&init).unwrap(), "the retrained init file is the start's");
    let text = String::from_utf8_lossy(&bytes).into_owned();
    assert!(text.contains("\"people_photos\":1") && text.contains("\"photo_face_share\":0.5"), "the retraining saw no photos");
    let report = read_json(&retrained.join("iteration_1/init.json"));
    assert!(report["found"].as_f64().is_some() && report["median_landmark_error"].as_f64().is_some(), "{report}");
    let m2 = gpmm_host::gp::model_io::load(&retrained.join("model_2.gpmm")).unwrap();
    assert_eq!(m2.metadata.learning.as_ref().unwrap().init, s(&first_init));
    assert!(retrained.join("development/points-1").is_dir() && retrained.join("iteration_2/init.init").is_file());
    let stderr = String::from_utf8_lossy(&run_r.stderr).to_string();
    assert!(stderr.contains("initializer retrained"), "{stderr}");
    // The kept model is named with the init file retrained after its iteration (none for the start model).
    let best = read_json(&retrained.join("iteration_2/records.json"))["development"]["best_model"].as_str().unwrap().to_string();
    let paired = if best.ends_with("model_1.gpmm") {
        Some("iteration_1/init.init")
    } else if best.ends_with("model_2.gpmm") {
        Some("iteration_2/init.init")
    } else {
        None
    };
    match paired {
        Some(p) => assert!(stderr.contains(&format!("its init file: {}", s(&retrained.join(p)))), "{stderr}"),
        None => assert!(!stderr.contains("its init file"), "{stderr}"),
    }
    let rerun = gpmm(&args_r);
    ok(&rerun);
    assert!(!String::from_utf8_lossy(&rerun.stderr).contains("initializer retrained"), "a rerun retrained again");
    assert_eq!(std::fs::read(&first_init).unwrap(), bytes);

    // A rerun reads both iterations back and keeps the same best.
    let rerun = gpmm(&args);
    ok(&rerun);
    let stderr = String::from_utf8_lossy(&rerun.stderr).to_string();
    assert!(stderr.contains("complete on disk") && stderr.contains(&format!("kept {}", s(&best_file))), "{stderr}");
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
    let e = fails(&gpmm(&["learn", "m.gpmm", s(&empty), "--init", "x.init", "--dev-max-identity-drop", "5", "-o", s(dir.path())]));
    assert!(e.contains("--dev-max-identity-drop") && e.contains("--dev"), "{e}");
}
