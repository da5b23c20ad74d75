//! `gpmm train-init`, `gpmm detect`, `gpmm eval detect` and `gpmm fit --init` end to end on a
//! small model: training is deterministic for a seed, the outputs are well-formed, corrupted or
//! missing init files are refused with the file's name.

mod common;
use common::{fails, gpmm, ok, people_folder};

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

struct Fixture {
    dir: tempfile::TempDir,
    model: PathBuf,
    init: PathBuf,
    synth: PathBuf,
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A small model, a quick init file trained on it, and two synthetic faces.
fn fixture() -> Option<&'static Fixture> {
    static F: OnceLock<Option<Fixture>> = OnceLock::new();
    F.get_or_init(|| {
        let data = gpmm_host::data::data_dir_for_tests()?;
        let dir = tempfile::tempdir().unwrap();
        let t = data.join("template/lee-perry-smith");
        let model = dir.path().join("small.gpmm");
        let (ply, lm) = (t.join("lee-perry-smith.ply"), t.join("landmarks_ibug68.json"));
        ok(&gpmm(&[
            "build",
            "--template",
            s(&ply),
            "--landmarks",
            s(&lm),
            "--vertices",
            "1500",
            "--rank-shape",
            "20",
            "--rank-color",
            "20",
            "--nystrom-points",
            "500",
            "-o",
            s(&model),
        ]));
        let init = dir.path().join("quick.init");
        let report = ok(&gpmm(&["train-init", s(&model), "-o", s(&init), "--quick", "--seed", "7"]));
        let report: serde_json::Value = serde_json::from_str(&report).unwrap();
        assert!(report["steps"].as_u64().unwrap() > 0);
        assert_eq!(report["macs"].as_array().unwrap().len(), 2);
        let synth = dir.path().join("synth");
        let ict = data.join("ict");
        ok(&gpmm(&["synth", "--ict", s(&ict), "--template-dir", s(&t), "--count", "1", "--yaws", "30,0", "--seed", "3", "-o", s(&synth)]));
        Some(Fixture { dir, model, init, synth })
    })
    .as_ref()
}

#[test]
fn training_twice_with_one_seed_gives_the_same_file() {
    let Some(f) = fixture() else { return };
    let again = f.dir.path().join("again.init");
    ok(&gpmm(&["train-init", s(&f.model), "-o", s(&again), "--quick", "--seed", "7"]));
    assert_eq!(std::fs::read(&f.init).unwrap(), std::fs::read(&again).unwrap());
    let other = f.dir.path().join("other.init");
    ok(&gpmm(&["train-init", s(&f.model), "-o", s(&other), "--quick", "--seed", "8"]));
    assert_ne!(std::fs::read(&f.init).unwrap(), std::fs::read(&other).unwrap());
}

#[test]
fn detect_writes_68_landmarks_and_a_picture() {
    let Some(f) = fixture() else { return };
    let image = f.synth.join("0000_yaw30.png");
    let (pts, png) = (f.dir.path().join("d.pts"), f.dir.path().join("d.png"));
    let out = ok(&gpmm(&["detect", s(&image), "--init", s(&f.init), "-o", s(&pts), "--draw", s(&png)]));
    let json: serde_json::Value = serde_json::from_str(&out).unwrap();
    let faces = json["faces"].as_array().unwrap();
    assert!(!faces.is_empty() && faces.len() <= gpmm_host::detect::PHOTO_MAX_FACES);
    for face in faces {
        assert_eq!(face["landmarks"].as_array().unwrap().len(), 68);
        assert!(face["box"]["score"].as_f64().unwrap() >= 0.0);
    }
    // Listed best first; the .pts is the largest near-best face's.
    let score = |k: usize| faces[k]["box"]["score"].as_f64().unwrap();
    assert!((1..faces.len()).all(|k| score(k - 1) >= score(k)));
    let size = |k: usize| faces[k]["box"]["size"].as_f64().unwrap();
    let chosen = json["chosen"].as_u64().unwrap() as usize;
    let near_best = |k: usize| score(k) >= f64::from(gpmm_host::detect::LARGEST_AMONG_SCORE_SHARE) * score(0);
    assert!(near_best(chosen) && (0..faces.len()).filter(|&k| near_best(k)).all(|k| size(chosen) >= size(k)));
    let read = gpmm_host::photo::pts::read_pts(&pts, false).unwrap();
    assert_eq!(read.points.len(), 68);
    assert_eq!(image::image_dimensions(&png).unwrap(), image::image_dimensions(&image).unwrap());
    // A finder score no face reaches: a clear error, no output.
    let err = fails(&gpmm(&["detect", s(&image), "--init", s(&f.init), "--min-score", "1.5"]));
    assert!(err.contains("no face found"), "{err}");
    // A face the list does not have: an error naming the image and the count.
    let err = fails(&gpmm(&["detect", s(&image), "--init", s(&f.init), "--face", "99"]));
    assert!(err.contains("0000_yaw30.png") && err.contains("--face 99"), "{err}");
}

#[test]
fn detect_says_when_the_face_check_refused_every_box() {
    use gpmm_host::detect::{check::FaceCheck, check_fit::with_metadata, Detector};
    let Some(f) = fixture() else { return };
    let image = f.synth.join("0000_yaw00.png");
    // The quick file with a check no box passes.
    let bytes = std::fs::read(&f.init).unwrap();
    let plain = Detector::from_bytes(&bytes).unwrap();
    let refuse_all = FaceCheck { weights: [0.0; 4], bias: -10.0, threshold: 0.5, faces: 10, others: 10 };
    let metadata = refuse_all.into_metadata(plain.file().unwrap().metadata).unwrap();
    let checked = f.dir.path().join("refuse-all.init");
    std::fs::write(&checked, with_metadata(&bytes, &metadata).unwrap()).unwrap();
    // A file with a check counts faces from 0.9 by default; the quick file's scores are lower.
    let err = fails(&gpmm(&["detect", s(&image), "--init", s(&checked), "--min-score", "0.05"]));
    assert!(err.contains("no face passed the face check") && err.contains("refuse-all.init") && err.contains("--no-face-check"), "{err}");
    assert!(!err.contains("finder score below"), "{err}");
    // Without the check the same boxes are listed.
    let out = ok(&gpmm(&["detect", s(&image), "--init", s(&checked), "--no-face-check", "--min-score", "0.05"]));
    let json: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert!(!json["faces"].as_array().unwrap().is_empty());
    // Its default score is the one advised for files trained on real photos, and the message says so.
    let err = fails(&gpmm(&["detect", s(&image), "--init", s(&checked)]));
    assert!(err.contains("below --min-score 0.9"), "{err}");
}

#[test]
fn eval_detect_scores_a_real_photo_set() {
    let Some(f) = fixture() else { return };
    // Two faces with reference points (the synthetic set's own) and a face-free gray image.
    let set = f.dir.path().join("photo-set");
    std::fs::create_dir_all(&set).unwrap();
    for stem in ["0000_yaw00", "0000_yaw30"] {
        std::fs::copy(f.synth.join(format!("{stem}.png")), set.join(format!("{stem}.png"))).unwrap();
        let points = gpmm_host::photo::pts::read_pts(&f.synth.join(format!("{stem}.pts")), false).unwrap().points;
        let xs = points.iter().map(|p| p[0]);
        let ys = points.iter().map(|p| p[1]);
        let bbox = [
            xs.clone().fold(f32::MAX, f32::min),
            ys.clone().fold(f32::MAX, f32::min),
            xs.fold(f32::MIN, f32::max),
            ys.fold(f32::MIN, f32::max),
        ];
        let face = serde_json::json!({ "box": bbox, "landmarks": points.iter().map(|p| [p[0], p[1]]).collect::<Vec<_>>() });
        let json = serde_json::json!({ "source": "gpmm synth", "reference": "exact", "faces": [face] });
        std::fs::write(set.join(format!("{stem}.faces.json")), json.to_string()).unwrap();
    }
    image::RgbImage::from_pixel(200, 150, image::Rgb([128, 128, 128])).save(set.join("gray.png")).unwrap();
    std::fs::write(set.join("gray.faces.json"), r#"{"source": "flat", "reference": "none", "faces": []}"#).unwrap();
    let draw = f.dir.path().join("photo-draw");
    let out = ok(&gpmm(&["eval", "detect", s(&set), "--init", s(&f.init), "--draw-dir", s(&draw), "--min-score", "0.5"]));
    let json: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!((json["images"].as_u64(), json["face_free_images"].as_u64(), json["faces"].as_u64()), (Some(3), Some(1), Some(2)));
    assert_eq!(json["by_size"].as_array().unwrap().len(), 3);
    let found = json["all"]["found"].as_u64().unwrap();
    assert!(found <= 2 && json["landmark_faces"].as_u64().unwrap() == found);
    assert!(json["false_positives_per_face_free_image"].as_f64().unwrap() >= 0.0);
    for name in ["0000_yaw00.png", "0000_yaw30.png", "gray.png"] {
        assert!(draw.join(name).exists(), "{name} not drawn");
    }
    let written: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(set.join("detect.json")).unwrap()).unwrap();
    assert_eq!(written["images"].as_array().unwrap().len(), 3);
    // With --mirror every photo is scored twice, the mirror image after it, drawn mirrored.
    let mirror_draw = f.dir.path().join("photo-draw-mirror");
    let args =
        ["eval", "detect", s(&set), "--init", s(&f.init), "--min-score", "0.5", "--no-write", "--mirror", "--draw-dir", s(&mirror_draw)];
    let mirrored: serde_json::Value = serde_json::from_str(&ok(&gpmm(&args))).unwrap();
    assert_eq!(
        (mirrored["images"].as_u64(), mirrored["face_free_images"].as_u64(), mirrored["faces"].as_u64()),
        (Some(6), Some(2), Some(4))
    );
    assert_eq!(mirrored["mirror_images"].as_bool(), Some(true));
    assert_eq!(json["mirror_images"].as_bool(), Some(false));
    let drawn = image::open(draw.join("0000_yaw30.png")).unwrap().to_rgb8();
    let drawn_mirror = image::open(mirror_draw.join("0000_yaw30.mirrored.png")).unwrap().to_rgb8();
    assert_eq!(drawn.dimensions(), drawn_mirror.dimensions());
    assert_ne!(drawn, drawn_mirror, "the mirror image is drawn mirrored");
    assert!(mirror_draw.join("gray.mirrored.png").exists());
    // A broken reference file is refused with its name.
    std::fs::write(set.join("gray.faces.json"), r#"{"faces": [{"box": [1, 2, 3], "landmarks": null}]}"#).unwrap();
    let err = fails(&gpmm(&["eval", "detect", s(&set), "--init", s(&f.init), "--no-write"]));
    assert!(err.contains("gray.faces.json"), "{err}");
}

#[test]
fn eval_detect_reports_every_image() {
    let Some(f) = fixture() else { return };
    let pts_dir = f.dir.path().join("detected-pts");
    let out = ok(&gpmm(&["eval", "detect", s(&f.synth), "--init", s(&f.init), "--pts-dir", s(&pts_dir)]));
    let json: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(json["images"].as_u64(), Some(2));
    // Every detection's landmarks as a 68-point .pts named after its image (bench-fit reads them).
    for name in ["0000_yaw00.pts", "0000_yaw30.pts"] {
        let pts = gpmm_host::photo::pts::read_pts(&pts_dir.join(name), false).unwrap();
        assert_eq!(pts.points.len(), 68, "{name}");
    }
    let found = json["found"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&found));
    assert_eq!(json["per_yaw"].as_array().unwrap().len(), 2);
    let written: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(f.synth.join("detect.json")).unwrap()).unwrap();
    assert_eq!(written["images"].as_array().unwrap().len(), 2);
}

#[test]
fn fit_without_landmarks_detects_them_first() {
    let Some(f) = fixture() else { return };
    let image = f.synth.join("0000_yaw00.png");
    let out = f.dir.path().join("fit-init");
    ok(&gpmm(&["fit", s(&f.model), s(&image), "--init", s(&f.init), "-o", s(&out), "--landmark-steps", "500", "--image-steps", "20"]));
    for name in ["detected.pts", "detected.png", "fit.json", "overlay.png"] {
        assert!(out.join(name).exists(), "{name} missing");
    }
    // The initializer's landmarks enter with their own σ, which the user can set.
    let json = |dir: &std::path::Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(dir.join("fit.json")).unwrap()).unwrap()
    };
    let sigma = |dir: &std::path::Path| json(dir)["settings"]["landmarks"]["sigma"].as_f64().unwrap();
    assert!((sigma(&out) - f64::from(gpmm_host::detect::INIT_LANDMARK_SIGMA)).abs() < 1e-6, "{}", sigma(&out));
    // Short fits from the init file with σ 0.02 and `extra` arguments, written to `dir`.
    let fit_init = |dir: &std::path::Path, extra: &[&str]| {
        let args = ["fit", s(&f.model), s(&image), "--init", s(&f.init), "--init-landmark-sigma", "0.02", "-o", s(dir)];
        ok(&gpmm(&[&args[..], &["--landmark-steps", "100", "--image-steps", "5"], extra].concat()));
    };
    let out2 = f.dir.path().join("fit-init-sigma");
    fit_init(&out2, &[]);
    assert!((sigma(&out2) - 0.02).abs() < 1e-6, "{}", sigma(&out2));
    // Every contour point is kept (the initializer learned the contour vertices, hidden or not),
    // unless --set says otherwise.
    let hidden = |dir: &std::path::Path| json(dir)["settings"]["landmarks"]["hidden_contour_min_cos"].as_f64().unwrap();
    assert_eq!(hidden(&out2), -1.0);
    let out3 = f.dir.path().join("fit-init-hidden");
    fit_init(&out3, &["--set", "landmarks.hidden_contour_min_cos=0.1"]);
    assert!((hidden(&out3) - 0.1).abs() < 1e-6 && (sigma(&out3) - 0.02).abs() < 1e-6, "{}", hidden(&out3));
    // A calibration of the initializer's landmarks (here: every point 0.1 IOD along the eye line)
    // corrects them before the fit, and fit.json names it.
    let cal = f.dir.path().join("init.cal.json");
    let offsets: Vec<Vec<[f32; 2]>> = vec![vec![[0.1, 0.0]]; 68];
    let body = serde_json::json!({"format": "gpmm-landmark-calibration", "version": 1, "detector": "test", "degree": 0,
        "turn_range": [-1.0, 1.0], "offsets": offsets,
        "training": {"images": 0, "median_rms_px_before": 0.0, "median_rms_px_after": 0.0}});
    std::fs::write(&cal, body.to_string()).unwrap();
    let out3 = f.dir.path().join("fit-init-cal");
    fit_init(&out3, &["--landmark-calibration", s(&cal)]);
    assert_eq!(json(&out3)["landmark_calibration"], s(&cal));
    let mean_x = |j: &serde_json::Value| {
        let v = j["fitted_landmarks"].as_array().unwrap();
        v.iter().map(|p| p[0].as_f64().unwrap()).sum::<f64>() / v.len() as f64
    };
    let shift = mean_x(&json(&out3)) - mean_x(&json(&out2));
    let detected = gpmm_host::photo::pts::read_pts(&out3.join("detected.pts"), false).unwrap().points;
    let iod = f64::from((detected[45][0] - detected[36][0]).hypot(detected[45][1] - detected[36][1]));
    // The fit follows the moved points at least halfway (short chains, σ 0.02 of the side).
    assert!(shift > 0.05 * iod, "the calibrated landmarks must move the fit right: {shift} px, IOD {iod} px");
    // Neither landmarks nor an init file: the shipped start finds the face.
    let shipped = f.dir.path().join("fit-shipped");
    ok(&gpmm(&["fit", s(&f.model), s(&image), "-o", s(&shipped), "--landmark-steps", "100", "--image-steps", "5"]));
    assert!(shipped.join("detected.pts").is_file() && shipped.join("fit.json").is_file());
    // --faces all and --landmarks do not go together; clap says so.
    let pts = shipped.join("detected.pts");
    let err = fails(&gpmm(&["fit", s(&f.model), s(&image), "--landmarks", s(&pts), "--faces", "all", "-o", s(&out)]));
    assert!(err.contains("--faces"), "{err}");
}

#[test]
fn training_over_background_photos_records_them_and_names_a_bad_photo() {
    let Some(f) = fixture() else { return };
    let photos = f.dir.path().join("backgrounds");
    std::fs::create_dir_all(&photos).unwrap();
    for (i, colour) in [[40u8, 160, 60], [150, 120, 90]].into_iter().enumerate() {
        let img =
            image::RgbImage::from_fn(300, 200, |x, y| image::Rgb(colour.map(|c| c.wrapping_add(((x * 7 + y * 13 + i as u32) % 50) as u8))));
        img.save(photos.join(format!("photo{i}.png"))).unwrap();
    }
    let init = f.dir.path().join("backgrounds.init");
    ok(&gpmm(&["train-init", s(&f.model), "-o", s(&init), "--quick", "--seed", "7", "--backgrounds", s(&photos)]));
    let bytes = std::fs::read(&init).unwrap();
    let text = String::from_utf8_lossy(&bytes);
    assert!(text.contains("\"background_photos\":2") && text.contains("\"face_free_frames\":0.125"), "metadata lacks the photos");
    assert_ne!(bytes, std::fs::read(&f.init).unwrap(), "the photos changed nothing");
    assert!(text.contains("\"look_share\":0.5") && text.contains("\"occluders\":true"), "metadata lacks the looks and occluders");
    // Without looks and occluders: recorded, and other frames make another file.
    let plain = f.dir.path().join("plain.init");
    let args = ["train-init", s(&f.model), "-o", s(&plain), "--quick", "--seed", "7", "--backgrounds", s(&photos)];
    ok(&gpmm(&[&args[..], &["--plain-looks", "--no-occluders"]].concat()));
    let plain_bytes = std::fs::read(&plain).unwrap();
    let plain_text = String::from_utf8_lossy(&plain_bytes);
    assert!(plain_text.contains("\"look_share\":0.0") && plain_text.contains("\"occluders\":false"), "{plain_text}");
    assert_ne!(plain_bytes, bytes, "looks and occluders changed nothing");
    std::fs::write(photos.join("broken.jpg"), b"not a jpeg").unwrap();
    let err = fails(&gpmm(&["train-init", s(&f.model), "-o", s(&init), "--quick", "--backgrounds", s(&photos)]));
    assert!(err.contains("broken.jpg"), "{err}");
}

#[test]
fn photos_of_people_give_the_finder_real_faces_and_their_surroundings() {
    let Some(f) = fixture() else { return };
    let people = f.dir.path().join("people");
    people_folder(&people);
    let (init, preview) = (f.dir.path().join("people.init"), f.dir.path().join("people.png"));
    let args = ["train-init", s(&f.model), "-o", s(&init), "--quick", "--seed", "7", "--backgrounds", s(&people)];
    let run = gpmm(&[&args[..], &["--preview", s(&preview)]].concat());
    ok(&run);
    // One photo of people gives too few boxes to fit a face check: said, and the file has none.
    let said = String::from_utf8_lossy(&run.stderr);
    assert!(said.contains("no face check: too few boxes"), "{said}");
    assert!(gpmm_host::detect::Detector::load(&init).unwrap().check().is_none());
    let text = String::from_utf8_lossy(&std::fs::read(&init).unwrap()).into_owned();
    assert!(text.contains("\"people_photos\":1") && text.contains("\"photo_faces\":1"), "metadata lacks the photos of people");
    assert!(text.contains("\"photo_face_share\":0.25"), "metadata lacks the share of real faces");
    assert!(text.contains("\"photo_points\":true"), "metadata lacks the initializer's real points");
    // The preview shows two rows of real faces below the four of rendered scenes, then two of
    // face-free frames.
    let (w, h) = image::image_dimensions(&preview).unwrap();
    assert_eq!((w, h), (6 * 160, 8 * 160));
    // Without real faces in the batches the networks differ.
    let other = f.dir.path().join("people-none.init");
    ok(&gpmm(&["train-init", s(&f.model), "-o", s(&other), "--quick", "--seed", "7", "--backgrounds", s(&people), "--photo-faces", "0"]));
    assert_ne!(std::fs::read(&init).unwrap(), std::fs::read(&other).unwrap(), "the real faces changed nothing");
    // Nor when the initializer leaves their points out.
    let renders_only = f.dir.path().join("people-renders-only.init");
    ok(&gpmm(&[
        "train-init",
        s(&f.model),
        "-o",
        s(&renders_only),
        "--quick",
        "--seed",
        "7",
        "--backgrounds",
        s(&people),
        "--no-photo-points",
    ]));
    let bytes = std::fs::read(&renders_only).unwrap();
    assert_ne!(std::fs::read(&init).unwrap(), bytes, "the real points changed nothing");
    assert!(String::from_utf8_lossy(&bytes).contains("\"photo_points\":false"));
    let err = fails(&gpmm(&[&args[..], &["--photo-faces", "2"]].concat()));
    assert!(err.contains("--photo-faces 2"), "{err}");
}

#[test]
fn corrupted_or_missing_init_files_are_refused_by_name() {
    let Some(f) = fixture() else { return };
    let image = f.synth.join("0000_yaw00.png");
    let mut bytes = std::fs::read(&f.init).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0xFF;
    let bad = f.dir.path().join("bad.init");
    std::fs::write(&bad, &bytes).unwrap();
    let err = fails(&gpmm(&["detect", s(&image), "--init", s(&bad)]));
    assert!(err.contains("bad.init") && err.contains("CRC"), "{err}");
    let short = f.dir.path().join("short.init");
    std::fs::write(&short, &bytes[..100]).unwrap();
    let err = fails(&gpmm(&["detect", s(&image), "--init", s(&short)]));
    assert!(err.contains("short.init"), "{err}");
    let err = fails(&gpmm(&["detect", s(&image), "--init", "/nonexistent.init"]));
    assert!(err.contains("/nonexistent.init"), "{err}");
    // A model file is not an init file.
    let err = fails(&gpmm(&["detect", s(&image), "--init", s(&f.model)]));
    assert!(err.contains("GPMI"), "{err}");
}

/// `gpmm device-detect` on a trained (quick) init file: the firmware under QEMU reads the same
/// face as the host to the bit, and a bad init file or image is refused before QEMU runs.
/// Needs QEMU and the thumbv7em toolchain (firmware-sim/install-deps.sh).
#[test]
fn device_detect_matches_the_host_bit_for_bit() {
    let Some(f) = fixture() else { return };
    let image = f.synth.join("0000_yaw30.png");
    let part = f.dir.path().join("detect.partition");
    let out = ok(&gpmm(&["device-detect", s(&image), "--init", s(&f.init), "--compare-host", "--keep-partition", s(&part)]));
    let json: serde_json::Value = serde_json::from_str(&out).unwrap();
    eprintln!("{}", serde_json::to_string(&json["counts"]).unwrap());
    assert_eq!(json["parity"]["bit_identical"], true, "{out}");
    let c = &json["counts"];
    assert_eq!((c["frame_width"].as_u64(), c["frame_height"].as_u64()), (Some(160), Some(120)));
    let (finder, init) = (c["instructions_finder"].as_u64().unwrap(), c["instructions_initializer"].as_u64().unwrap());
    assert!(finder > 1_000_000 && finder < c["instructions_total"].as_u64().unwrap(), "{c}");
    if json["detection"]["found"] == true {
        assert_eq!(json["landmarks_px"].as_array().unwrap().len(), 68);
        assert_eq!(json["landmarks_photo_px"].as_array().unwrap().len(), 68);
        assert!(init > 1_000_000, "{c}");
    }
    assert!(json["ram_total_bytes"].as_u64().unwrap() <= json["ram_budget_bytes"].as_u64().unwrap(), "{out}");
    let kept = std::fs::read(&part).unwrap();
    assert_eq!(&kept[..4], b"GPMI");
    // A corrupted init file and a file that is no image: refused by name, before QEMU.
    let mut bytes = std::fs::read(&f.init).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x01;
    let bad = f.dir.path().join("device-bad.init");
    std::fs::write(&bad, &bytes).unwrap();
    let err = fails(&gpmm(&["device-detect", s(&image), "--init", s(&bad)]));
    assert!(err.contains("device-bad.init") && err.contains("CRC"), "{err}");
    let err = fails(&gpmm(&["device-detect", s(&f.init), "--init", s(&f.init)]));
    assert!(err.contains("quick.init") && err.contains("image"), "{err}");
}

/// `gpmm device-fit BLOB IMAGE --init INIT` (no landmark file): detection, crop and fit on the
/// device, both records bit-identical to the host's run; the working side is the profile's; a bad
/// init file is refused by name before QEMU runs, and so is a side the m4f's RAM does not hold.
/// Needs QEMU and the thumbv7em toolchain (firmware-sim/install-deps.sh).
#[test]
fn device_fit_without_landmarks_matches_the_host_bit_for_bit() {
    let Some(f) = fixture() else { return };
    let blob = f.dir.path().join("small8.blob");
    ok(&gpmm(&["quantize", s(&f.model), "--profile", "m4f", "--bits", "8", "-o", s(&blob)]));
    let image = f.synth.join("0000_yaw00.png");
    let args = |extra: &[&str]| {
        let mut v = vec![
            "device-fit",
            s(&blob),
            s(&image),
            "--init",
            s(&f.init),
            "--landmark-steps",
            "300",
            "--image-steps",
            "20",
            "--min-score",
            "0",
        ];
        v.extend_from_slice(extra);
        v.into_iter().map(String::from).collect::<Vec<_>>()
    };
    let run = |extra: &[&str]| gpmm(&args(extra).iter().map(String::as_str).collect::<Vec<_>>());
    let out = ok(&run(&["--compare-host"]));
    let json: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(json["parity"]["detection_bit_identical"], true, "{out}");
    assert_eq!(json["parity"]["fit_bit_identical"], true, "{out}");
    assert_eq!(json["crop"]["side"].as_u64(), Some(72), "{out}");
    assert_eq!(json["fitted_landmarks_photo_px"].as_array().unwrap().len(), 68);
    // The device's record carries the pose's spread (bit-identical above), reported calibrated.
    let sd: Vec<f64> = json["fit"]["angles_sd_deg"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    assert!(sd.len() == 3 && sd.iter().all(|s| *s > 0.0), "{out}");
    // The host's run of the same fit from landmarks reports the same kind of interval.
    let pts = f.synth.join("0000_yaw00.pts");
    let host = ok(&gpmm(&[
        "device-fit",
        s(&blob),
        s(&image),
        "--landmarks",
        s(&pts),
        "--host-only",
        "--landmark-steps",
        "300",
        "--image-steps",
        "20",
    ]));
    let host: serde_json::Value = serde_json::from_str(&host).unwrap();
    let (yaw, [lo, hi]) = (host["yaw_deg"].as_f64().unwrap(), [0, 1].map(|i| host["angles_interval_90_deg"][0][i].as_f64().unwrap()));
    assert!(lo < yaw && yaw < hi, "{host}");
    let st = &json["stage_instructions"];
    for stage in ["detection", "crop", "fit"] {
        assert!(st[stage].as_u64().unwrap() > 0, "{stage}: {st}");
    }
    assert!(json["ram"]["total_bytes"].as_u64().unwrap() <= json["ram"]["budget_bytes"].as_u64().unwrap(), "{out}");
    // Refused before QEMU: a corrupted init file (by name), a working side beyond the m4f's.
    let mut bytes = std::fs::read(&f.init).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x01;
    let bad = f.dir.path().join("fit-bad.init");
    std::fs::write(&bad, &bytes).unwrap();
    let err = fails(&gpmm(&["device-fit", s(&blob), s(&image), "--init", s(&bad)]));
    assert!(err.contains("fit-bad.init") && err.contains("CRC"), "{err}");
    let err = fails(&run(&["--side", "96"]));
    assert!(err.contains("working side 96") && err.contains("16..=72"), "{err}");
    // No face at a minimum score no finder reaches: the report, then "no face found".
    let out = gpmm(&["device-fit", s(&blob), s(&image), "--init", s(&f.init), "--min-score", "1"]);
    let err = String::from_utf8_lossy(&out.stderr);
    if !out.status.success() {
        assert!(err.contains("no face found"), "{err}");
    }
}

#[test]
fn fine_tuning_on_a_mixture_writes_a_file_detect_reads_and_refuses_what_does_not_fit() {
    let Some(f) = fixture() else { return };
    // A second model in the first one's topology: other mean faces.
    let mut other = gpmm_host::gp::model_io::load(&f.model).unwrap();
    other.color.mean.iter_mut().for_each(|c| c[1] = (c[1] * 1.3).min(1.0));
    let second = f.dir.path().join("second.gpmm");
    gpmm_host::gp::model_io::save(&other, &second).unwrap();
    let tuned = f.dir.path().join("tuned.init");
    let out = ok(&gpmm(&["train-init", s(&f.model), s(&second), "--from", s(&f.init), "--quick", "--seed", "9", "-o", s(&tuned)]));
    let report: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert!(report["steps"].as_u64().unwrap() > 0);
    let bytes = std::fs::read(&tuned).unwrap();
    assert_ne!(bytes, std::fs::read(&f.init).unwrap());
    let file = gpmm_core::format::init_file::InitFile::parse(&bytes).unwrap();
    let metadata: serde_json::Value = serde_json::from_str(file.metadata).unwrap();
    assert_eq!((metadata["models"].as_array().map(Vec::len), &metadata["fine_tuned_from"]["seed"]), (Some(2), &serde_json::json!(7)));
    let detected = ok(&gpmm(&["detect", s(&f.synth.join("0000_yaw30.png")), "--init", s(&tuned)]));
    let json: serde_json::Value = serde_json::from_str(&detected).unwrap();
    assert_eq!(json["faces"][0]["landmarks"].as_array().map(Vec::len), Some(68), "{json}");

    // An init file whose initializer reads 5 landmarks: refused, naming it.
    let geo = gpmm_train::train::geometry(5);
    let net = |side: usize, specs: Vec<gpmm_core::net::LayerShape>| gpmm_train::encode::FloatNet {
        input: gpmm_core::net::Shape { h: side, w: side, c: 3 },
        layers: specs
            .iter()
            .map(|&shape| gpmm_train::encode::FloatLayer {
                shape,
                weights: vec![0.01; shape.cout * shape.weights_per_output()],
                bias: vec![0.0; shape.cout],
                out_max: 1.0,
            })
            .collect(),
    };
    let (f5, i5) = (net(96, gpmm_train::nets::finder_specs()), net(64, gpmm_train::nets::initializer_specs(geo.initializer_outputs())));
    let five = f.dir.path().join("five-landmarks.init");
    std::fs::write(&five, gpmm_train::encode::init_file_bytes(&f5, &i5, geo.crop_margin, 5, 12, "{}").unwrap()).unwrap();
    let err = fails(&gpmm(&["train-init", s(&f.model), "--from", s(&five), "--quick", "-o", s(&f.dir.path().join("x.init"))]));
    assert!(err.contains("five-landmarks.init") && err.contains("reads 5 landmarks"), "{err}");
    // A model of another vertex count in the mixture: refused, naming it.
    let data = gpmm_host::data::data_dir_for_tests().unwrap();
    let t = data.join("template/lee-perry-smith");
    let coarse = f.dir.path().join("coarse.gpmm");
    let (ply, lm) = (t.join("lee-perry-smith.ply"), t.join("landmarks_ibug68.json"));
    let build = ["build", "--template", s(&ply), "--landmarks", s(&lm), "--vertices", "900", "--rank-shape", "5", "--rank-color", "5"];
    ok(&gpmm(&[&build[..], &["--nystrom-points", "300", "-o", s(&coarse)]].concat()));
    let err = fails(&gpmm(&["train-init", s(&f.model), s(&coarse), "--quick", "-o", s(&f.dir.path().join("x.init"))]));
    assert!(err.contains("coarse.gpmm") && err.contains("vertices"), "{err}");
    // Zero chunks re-quantize --from's networks, and mean nothing without it.
    let err = fails(&gpmm(&["train-init", s(&f.model), "--chunks", "0", "--quick", "-o", s(&f.dir.path().join("x.init"))]));
    assert!(err.contains("--chunks 0"), "{err}");
}

#[test]
fn check_init_refuses_too_few_boxes_and_an_empty_folder_by_name() {
    let Some(f) = fixture() else { return };
    let set = f.dir.path().join("check-set");
    std::fs::create_dir_all(&set).unwrap();
    image::RgbImage::from_pixel(200, 150, image::Rgb([128, 128, 128])).save(set.join("gray.png")).unwrap();
    std::fs::write(set.join("gray.faces.json"), r#"{"faces": []}"#).unwrap();
    let out = f.dir.path().join("checked.init");
    let err = fails(&gpmm(&["check-init", s(&f.init), "--photos", s(&set), "-o", s(&out)]));
    assert!(err.contains("too few boxes") && err.contains("0 true faces"), "{err}");
    assert!(!out.exists());
    let empty = f.dir.path().join("check-empty");
    std::fs::create_dir_all(&empty).unwrap();
    let err = fails(&gpmm(&["check-init", s(&f.init), "--photos", s(&empty), "-o", s(&out)]));
    assert!(err.contains("no photo") && err.contains("check-empty"), "{err}");
    let err = fails(&gpmm(&["check-init", s(&f.init), "--photos", s(&set), "-o", s(&out), "--kept-share", "1.5"]));
    assert!(err.contains("--kept-share"), "{err}");
}
