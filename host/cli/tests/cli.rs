//! End-to-end tests of the `gpmm` program: build (all nine kernels), info, sample, bad input.

mod common;
use common::{fails, gpmm, ok};

use std::path::{Path, PathBuf};

fn data_dir() -> Option<PathBuf> {
    gpmm_host::data::data_dir_for_tests()
}

fn template_args(data: &Path) -> (String, String) {
    let t = data.join("template/lee-perry-smith");
    (t.join("lee-perry-smith.ply").display().to_string(), t.join("landmarks_ibug68.json").display().to_string())
}

#[test]
fn build_info_for_all_nine_kernels() {
    let Some(data) = data_dir() else { return };
    let (ply, lm) = template_args(&data);
    let dir = tempfile::tempdir().unwrap();
    let names = [
        "standard-full",
        "standard-rgb",
        "standard-xyz",
        "symmetric-full",
        "symmetric-rgb",
        "symmetric-xyz",
        "correlated-full",
        "correlated-rgb",
        "correlated-xyz",
    ];
    for (i, name) in names.iter().enumerate() {
        let out = dir.path().join(format!("{name}.gpmm"));
        let (rs, rc) = (format!("{}", 12 + i), format!("{}", 7 + i));
        let o = out.to_str().unwrap();
        ok(&gpmm(&[
            "build",
            "--template",
            &ply,
            "--landmarks",
            &lm,
            "--kernel",
            name,
            "--rank-shape",
            &rs,
            "--rank-color",
            &rc,
            "--vertices",
            "800",
            "--nystrom-points",
            "400",
            "-o",
            o,
        ]));
        let info: serde_json::Value = serde_json::from_str(&ok(&gpmm(&["info", o]))).unwrap();
        assert_eq!(info["kernel"], *name);
        assert_eq!(info["rank_shape"].as_u64().unwrap(), 12 + i as u64, "shape rank honoured");
        assert_eq!(info["rank_color"].as_u64().unwrap(), 7 + i as u64, "colour rank honoured");
        assert!(info["vertices"].as_u64().unwrap() <= 800 && info["vertices"].as_u64().unwrap() > 300);
        assert!(info["triangles"].as_u64().unwrap() > 500);
        assert_eq!(info["landmarks"].as_u64().unwrap(), 68);
        for key in ["captured_shape", "captured_color"] {
            let f = info[key].as_f64().unwrap();
            assert!(f > 0.0 && f <= 1.0, "{key} = {f}");
        }
        let model = gpmm_host::gp::model_io::load(&out).unwrap();
        for ev in [&model.shape.eigenvalues, &model.color.eigenvalues] {
            assert!(ev.iter().all(|v| *v > 0.0), "{name}: eigenvalues positive");
            assert!(ev.windows(2).all(|w| w[0] >= w[1]), "{name}: eigenvalues sorted");
        }
        assert!(info["attribution"].as_str().unwrap().contains("Lee Perry-Smith"));
    }
}

#[test]
fn captured_fraction_selects_rank_and_sample_writes_meshes() {
    let Some(data) = data_dir() else { return };
    let (ply, lm) = template_args(&data);
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("m.gpmm");
    let m = model.to_str().unwrap();
    ok(&gpmm(&[
        "build",
        "--template",
        &ply,
        "--landmarks",
        &lm,
        "--captured-shape",
        "0.9",
        "--captured-color",
        "0.5",
        "--vertices",
        "600",
        "--nystrom-points",
        "300",
        "-o",
        m,
    ]));
    let info: serde_json::Value = serde_json::from_str(&ok(&gpmm(&["info", m]))).unwrap();
    assert!(info["captured_shape"].as_f64().unwrap() >= 0.9);
    assert!(info["captured_color"].as_f64().unwrap() >= 0.5);
    assert_eq!(info["kernel"], "symmetric-full", "default kernel");

    let out = dir.path().join("samples");
    ok(&gpmm(&["sample", m, "-n", "3", "--seed", "7", "--out-dir", out.to_str().unwrap()]));
    let mean = gpmm_host::mesh::io::read_mesh(&out.join("mean.ply"), None, None).unwrap();
    let s0 = gpmm_host::mesh::io::read_mesh(&out.join("sample_000.ply"), None, None).unwrap();
    assert!(out.join("sample_002.ply").is_file());
    assert_eq!(mean.positions.len(), info["vertices"].as_u64().unwrap() as usize);
    assert_eq!(s0.triangles, mean.triangles);
    let rms = (mean.positions.iter().zip(&s0.positions).map(|(a, b)| (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>()).sum::<f64>()
        / mean.positions.len() as f64)
        .sqrt();
    assert!(rms > 0.5 && rms < 30.0, "a sample differs from the mean by a plausible amount (mm): {rms}");
    // Same seed, same samples.
    let out2 = dir.path().join("samples2");
    ok(&gpmm(&["sample", m, "-n", "1", "--seed", "7", "--out-dir", out2.to_str().unwrap()]));
    assert_eq!(std::fs::read(out.join("sample_000.ply")).unwrap(), std::fs::read(out2.join("sample_000.ply")).unwrap());
}

#[test]
fn bad_input_gives_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    // A PLY without colours.
    let ply = dir.path().join("plain.ply");
    std::fs::write(&ply, "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n").unwrap();
    let lm = dir.path().join("lm.json");
    std::fs::write(&lm, r#"{"scheme": "points", "vertex_ids": [0, 1]}"#).unwrap();
    let out = dir.path().join("m.gpmm");
    let o = gpmm(&["build", "--template", ply.to_str().unwrap(), "--landmarks", lm.to_str().unwrap(), "-o", out.to_str().unwrap()]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("plain.ply") && err.contains("colour"), "{err}");
    // Unknown kernel.
    let o = gpmm(&["build", "--template", "x.ply", "--landmarks", "x.json", "--kernel", "fancy", "-o", "m"]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("symmetric-full"));
    // Not a model file.
    let o = gpmm(&["info", ply.to_str().unwrap()]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("plain.ply") && err.contains("not a gpmm model"), "{err}");
    // Missing file.
    let o = gpmm(&["info", "/nonexistent/model.gpmm"]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("/nonexistent/model.gpmm"));
    // Invalid config.
    let cfg = dir.path().join("hp.toml");
    std::fs::write(&cfg, "shape_alpha = 2.0\n").unwrap();
    let o = gpmm(&["build", "--template", "x.ply", "--landmarks", "x.json", "--config", cfg.to_str().unwrap(), "-o", "m"]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("shape_alpha"));
    // A malformed PLY: the file and the line in words, not the parser's internals.
    let bad = dir.path().join("bad.ply");
    std::fs::write(&bad, "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nend_header\n0 0\n1 zz\n").unwrap();
    let err =
        fails(&gpmm(&["build", "--template", bad.to_str().unwrap(), "--landmarks", lm.to_str().unwrap(), "-o", out.to_str().unwrap()]));
    assert!(err.contains("bad.ply") && err.contains("invalid PLY file") && err.contains("Line 8"), "{err}");
    assert!(!err.contains("String:") && !err.contains("expected one of") && err.lines().count() <= 2, "{err}");
    // Rank 0 is refused before anything is built.
    let err = fails(&gpmm(&["build", "--template", "x.ply", "--landmarks", "x.json", "--rank-shape", "0", "-o", "m"]));
    assert!(err.contains("--rank-shape 0") && err.contains("at least one"), "{err}");
}

#[test]
fn ranks_beyond_the_nystrom_points_are_clamped_with_a_warning() {
    let Some(data) = data_dir() else { return };
    let (ply, lm) = template_args(&data);
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("m.gpmm");
    let o = out.to_str().unwrap();
    let args = ["build", "--template", &ply, "--landmarks", &lm, "--rank-shape", "10", "--rank-color", "100000000"];
    let run = gpmm(&[&args[..], &["--vertices", "600", "--nystrom-points", "50", "-o", o]].concat());
    ok(&run);
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(err.contains("warning: --rank-color 100000000") && err.contains("50 Nyström points"), "{err}");
    let info: serde_json::Value = serde_json::from_str(&ok(&gpmm(&["info", o]))).unwrap();
    let kept = info["rank_color"].as_u64().unwrap();
    assert!(kept > 10 && kept <= 150, "colour rank clamped to what 50 points support: {kept}");
    assert_eq!(info["rank_shape"].as_u64().unwrap(), 10);
}

#[test]
fn every_command_has_help() {
    for cmd in [&["--help"][..], &["build", "--help"], &["info", "--help"], &["sample", "--help"]] {
        let out = ok(&gpmm(cmd));
        assert!(out.contains("Usage"), "{cmd:?}: {out}");
    }
}

#[test]
fn demo_quick_writes_model_pictures_and_synthetic_faces() {
    let Some(data) = data_dir() else { return };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo");
    ok(&gpmm(&["demo", "--quick", "--data", data.to_str().unwrap(), "--out-dir", out.to_str().unwrap()]));
    for f in ["model.gpmm", "info.json", "mean.png", "mean_yaw30.png", "samples.png", "kernels.png", "synth.png", "synth/truth.json"] {
        assert!(out.join(f).is_file(), "demo wrote {f}");
    }
    let info: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(out.join("info.json")).unwrap()).unwrap();
    assert_eq!(info["rank_shape"], 40);
    let truth: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(out.join("synth/truth.json")).unwrap()).unwrap();
    assert!(truth.to_string().contains("yaw"));
    // A wrong data directory is a clear error.
    let o = gpmm(&["demo", "--quick", "--data", "/nonexistent", "--out-dir", out.to_str().unwrap()]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("GPMM_DATA"));
}

#[test]
fn synth_command_writes_images_landmarks_and_truth() {
    let Some(data) = data_dir() else { return };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s");
    let ict = data.join("ict");
    ok(&gpmm(&[
        "synth",
        "--ict",
        ict.to_str().unwrap(),
        "--count",
        "2",
        "--seed",
        "3",
        "--yaws",
        "0,-30",
        "--size",
        "64",
        "-o",
        out.to_str().unwrap(),
    ]));
    let pngs = std::fs::read_dir(&out).unwrap().filter(|e| e.as_ref().unwrap().path().extension().is_some_and(|x| x == "png")).count();
    let pts = std::fs::read_dir(&out).unwrap().filter(|e| e.as_ref().unwrap().path().extension().is_some_and(|x| x == "pts")).count();
    assert_eq!((pngs, pts), (4, 4));
    assert!(out.join("truth.json").is_file());
    assert!(!out.join("detector").exists() && !std::fs::read_to_string(out.join("truth.json")).unwrap().contains("detector_noise"));

    // Detector-like landmarks: the same images, plus DIR/detector/*.pts a few pixels off the truth.
    let noisy = dir.path().join("n");
    let args = ["synth", "--ict", ict.to_str().unwrap(), "--count", "2", "--seed", "3", "--yaws", "0,-30", "--size", "128"];
    ok(&gpmm(&[&args[..], &["--detector-noise", "-o", noisy.to_str().unwrap()]].concat()));
    let read_pts = |p: &std::path::Path| -> Vec<[f32; 2]> {
        let t = std::fs::read_to_string(p).unwrap();
        t.lines().filter_map(|l| l.split_once(' ').and_then(|(a, b)| Some([a.parse().ok()?, b.parse().ok()?]))).collect()
    };
    let mut sq = Vec::new();
    for name in ["0000_yaw00.pts", "0001_yaw-30.pts"] {
        let (truth, det) = (read_pts(&noisy.join(name)), read_pts(&noisy.join("detector").join(name)));
        assert_eq!((truth.len(), det.len()), (68, 68), "{name}");
        sq.extend(truth.iter().zip(&det).map(|(p, q)| (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)));
    }
    let rmse = (sq.iter().sum::<f32>() / sq.len() as f32).sqrt();
    assert!((0.8..4.0).contains(&rmse), "detector-like landmarks {rmse} px from the truth at 128 px");
    let o = gpmm(&["synth", "--ict", "/nonexistent/ict", "--count", "1", "-o", out.to_str().unwrap()]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("/nonexistent/ict"));
}
