//! `gpmm quantize` and `gpmm inspect`: blobs from a small built model, their accuracy, corrupted
//! blobs, profile budgets and bad arguments.

mod common;
use common::{fails, gpmm, ok};

use gpmm_host::device::accuracy::quantization_error;
use gpmm_host::device::quantize::{quantize, Bits, BlobBuf, Profile, QuantizeError, QuantizeOptions};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

fn json(s: &str) -> serde_json::Value {
    serde_json::from_str(s).unwrap_or_else(|e| panic!("not JSON ({e}): {s}"))
}

/// One model for every test: the template simplified to 1200 vertices, ranks 100/100 (large
/// enough that the m4f profile's budget refuses it unreduced).
fn model() -> Option<&'static (tempfile::TempDir, PathBuf)> {
    static MODEL: OnceLock<Option<(tempfile::TempDir, PathBuf)>> = OnceLock::new();
    MODEL
        .get_or_init(|| {
            let data = gpmm_host::data::data_dir_for_tests()?;
            let t = gpmm_host::data::template_dir(&data);
            let dir = tempfile::tempdir().unwrap();
            let out = dir.path().join("model.gpmm");
            ok(&gpmm(&[
                "build",
                "--template",
                t.join("lee-perry-smith.ply").to_str().unwrap(),
                "--landmarks",
                t.join("landmarks_ibug68.json").to_str().unwrap(),
                "--kernel",
                "symmetric-full",
                "--rank-shape",
                "100",
                "--rank-color",
                "100",
                "--vertices",
                "1200",
                "--nystrom-points",
                "600",
                "-o",
                out.to_str().unwrap(),
            ]));
            Some((dir, out))
        })
        .as_ref()
}

fn path(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn quantize_then_inspect() {
    let Some((dir, model_path)) = model() else { return };
    let blob_path = dir.path().join("small16.blob");
    let q = json(&ok(&gpmm(&[
        "quantize",
        path(model_path),
        "--profile",
        "m4f",
        "--vertices",
        "300",
        "--rank-shape",
        "30",
        "--rank-color",
        "20",
        "-o",
        path(&blob_path),
    ])));
    let file_bytes = std::fs::metadata(&blob_path).unwrap().len();
    assert_eq!(q["bytes"].as_u64().unwrap(), file_bytes);
    let n = q["vertices"].as_u64().unwrap();
    assert!((150..=300).contains(&n), "vertices {n}");
    assert_eq!(
        (q["landmarks"].as_u64(), q["rank_shape"].as_u64(), q["rank_color"].as_u64(), q["bits"].as_u64()),
        (Some(68), Some(30), Some(20), Some(16))
    );
    // 16-bit quantization error (measured: shape RMS 1.0e-4 mm, max 3e-4; colour RMS 4e-6).
    let shape_rms = q["quantization"]["shape_rms_mm"].as_f64().unwrap();
    let color_rms = q["quantization"]["color_rms"].as_f64().unwrap();
    assert!(shape_rms > 0.0 && shape_rms < 1e-3, "shape RMS {shape_rms} mm");
    assert!(color_rms > 0.0 && color_rms < 2e-5, "colour RMS {color_rms}");
    assert!(q["quantization"]["shape_max_mm"].as_f64().unwrap() < 5e-3);
    assert_eq!(q["quantization"]["draws"].as_u64(), Some(100));
    // 1178 -> about 300 vertices moves the surface by about a millimetre (measured RMS 1.1 mm).
    let simp = q["simplification"]["mean_shape_rms_mm"].as_f64().unwrap();
    assert!(simp > 0.01 && simp < 3.0, "simplification RMS {simp} mm");

    let i = json(&ok(&gpmm(&["inspect", path(&blob_path)])));
    assert_eq!(i["bytes"].as_u64().unwrap(), file_bytes);
    assert_eq!(i["crc_ok"], true);
    assert_eq!(i["valid"], true);
    assert_eq!(i["version"], 1);
    for key in ["vertices", "triangles", "landmarks", "rank_shape", "rank_color", "bits"] {
        assert_eq!(i[key], q[key], "{key}");
    }
    assert_eq!(i["layout"]["shape"], "factored");
    assert_eq!(i["metadata"]["kernel"], "symmetric-full");
    assert_eq!(i["metadata"]["profile"], "m4f");
    assert_eq!(i["metadata"]["source"], "model.gpmm");
    assert!(i["metadata"]["attribution"].as_str().unwrap().contains("Lee Perry-Smith"));

    // The landmarks are the model's landmark vertices, in the same order, not moved.
    let model = gpmm_host::gp::model_io::load(model_path).unwrap();
    let buf = BlobBuf::read(&blob_path).unwrap();
    let blob = buf.view().unwrap();
    for (k, (&b, &m)) in blob.landmarks().iter().zip(&model.landmarks).enumerate() {
        assert_eq!(blob.shape_mean()[b as usize], model.shape.mean[m as usize], "landmark {k}");
    }
    let mm = blob.morphable().unwrap();
    assert_eq!(mm.triangles().len() as u64, q["triangles"].as_u64().unwrap());

    // 8 bits: half the basis bytes, a larger but bounded error (measured shape RMS 0.026 mm).
    let blob8 = dir.path().join("small8.blob");
    let q8 = json(&ok(&gpmm(&[
        "quantize",
        path(model_path),
        "--profile",
        "m4f",
        "--vertices",
        "300",
        "--rank-shape",
        "30",
        "--rank-color",
        "20",
        "--bits",
        "8",
        "--draws",
        "20",
        "-o",
        path(&blob8),
    ])));
    assert_eq!(q8["bits"], 8);
    assert!(q8["bytes"].as_u64().unwrap() < file_bytes);
    let rms8 = q8["quantization"]["shape_rms_mm"].as_f64().unwrap();
    assert!(rms8 > 50.0 * shape_rms && rms8 < 0.1, "8-bit shape RMS {rms8} mm");
    assert_eq!(json(&ok(&gpmm(&["inspect", path(&blob8)])))["bits"], 8);
}

#[test]
fn corrupted_blobs_are_refused_by_inspect() {
    let Some((dir, model_path)) = model() else { return };
    let blob_path = dir.path().join("corrupt-src.blob");
    ok(&gpmm(&[
        "quantize",
        path(model_path),
        "--profile",
        "m4f",
        "--vertices",
        "200",
        "--rank-shape",
        "5",
        "--rank-color",
        "5",
        "-o",
        path(&blob_path),
    ]));
    let good = std::fs::read(&blob_path).unwrap();

    let mut bad = good.clone();
    let mid = bad.len() / 2;
    bad[mid] ^= 0x40;
    let p = dir.path().join("flipped.blob");
    std::fs::write(&p, &bad).unwrap();
    let out = gpmm(&["inspect", path(&p)]);
    let err = fails(&out);
    assert!(err.contains("CRC-32 mismatch"), "{err}");
    let j = json(&String::from_utf8_lossy(&out.stdout));
    assert_eq!(j["crc_ok"], false);
    assert_eq!(j["valid"], false);
    assert!(j["vertices"].as_u64().unwrap() <= 200 && j["bits"] == 16, "the header is still reported: {j}");

    let p = dir.path().join("truncated.blob");
    std::fs::write(&p, &good[..good.len() - 100]).unwrap();
    let err = fails(&gpmm(&["inspect", path(&p)]));
    assert!(err.contains("truncated"), "{err}");

    let mut bad = good.clone();
    bad[0] = b'X';
    let p = dir.path().join("magic.blob");
    std::fs::write(&p, &bad).unwrap();
    let err = fails(&gpmm(&["inspect", path(&p)]));
    assert!(err.contains("magic"), "{err}");

    // A model file is not a blob.
    let err = fails(&gpmm(&["inspect", path(model_path)]));
    assert!(err.contains("not a valid model blob"), "{err}");
    let err = fails(&gpmm(&["inspect", "/nonexistent/x.blob"]));
    assert!(err.contains("/nonexistent/x.blob"), "{err}");

    // Trailing bytes (a partition image) are fine.
    let mut longer = good.clone();
    longer.extend_from_slice(&[0xff; 64]);
    let p = dir.path().join("partition.bin");
    std::fs::write(&p, &longer).unwrap();
    let j = json(&ok(&gpmm(&["inspect", path(&p)])));
    assert_eq!(j["bytes"].as_u64().unwrap() as usize, good.len());
    assert_eq!(j["file_bytes"].as_u64().unwrap() as usize, longer.len());
}

#[test]
fn profile_budget_and_bad_arguments() {
    let Some((dir, model_path)) = model() else { return };
    let out = dir.path().join("refused.blob");
    // 1200 vertices at ranks 100/100 and 16 bits is about 500 KiB: over m4f's 400 KiB, within m7's 800 KiB.
    let err = fails(&gpmm(&[
        "quantize",
        path(model_path),
        "--profile",
        "m4f",
        "--vertices",
        "1200",
        "--rank-shape",
        "100",
        "--rank-color",
        "100",
        "-o",
        path(&out),
    ]));
    assert!(err.contains("over the m4f profile budget of 409600 bytes"), "{err}");
    assert!(!out.exists(), "nothing written on refusal");
    let q = json(&ok(&gpmm(&[
        "quantize",
        path(model_path),
        "--profile",
        "m7",
        "--vertices",
        "1200",
        "--rank-shape",
        "100",
        "--rank-color",
        "100",
        "--draws",
        "5",
        "-o",
        path(&out),
    ])));
    let bytes = q["bytes"].as_u64().unwrap();
    assert!(bytes > 400 * 1024 && bytes <= 800 * 1024, "{bytes}");
    assert_eq!(q["simplification"]["mean_shape_rms_mm"], 0.0, "nothing removed");

    let args = |extra: &[&str]| {
        let mut v = vec!["quantize", path(model_path), "-o", path(&out)];
        v.extend_from_slice(extra);
        gpmm(&v)
    };
    for (extra, msg) in [
        (&["--profile", "m5"][..], "m4f or m7"),
        (&["--profile", "m4f", "--bits", "12"][..], "must be 8 or 16"),
        (&["--profile", "m4f", "--rank-shape", "500"][..], "shape rank 500 requested, but the model has only 100"),
        (&["--profile", "m4f", "--vertices", "70000"][..], "at most 65535"),
        (&["--profile", "m4f", "--vertices", "10"][..], "cannot keep the model's 68 landmark vertices"),
        (&[][..], "--profile"),
        (&["--profile", "m4f", "--vertices", "many"][..], "invalid value 'many'"),
    ] {
        let err = fails(&args(extra));
        assert!(err.contains(msg), "{extra:?}: {err}");
    }
    let err = fails(&gpmm(&["quantize", "/nonexistent/model.gpmm", "--profile", "m4f", "-o", path(&out)]));
    assert!(err.contains("/nonexistent/model.gpmm"), "{err}");
    for cmd in ["quantize", "inspect"] {
        let help = ok(&gpmm(&[cmd, "--help"]));
        assert!(help.contains("blob"), "{cmd} --help: {help}");
    }
}

#[test]
fn library_quantize_matches_profile_defaults() {
    let Some((_dir, model_path)) = model() else { return };
    let model = gpmm_host::gp::model_io::load(model_path).unwrap();
    let mut opts = QuantizeOptions::for_profile(Profile::M4f);
    opts.vertices = 400;
    opts.rank_shape = 12;
    opts.rank_color = 8;
    let q = quantize(&model, &opts).unwrap();
    assert!(q.vertices() <= 400 && q.kept.len() == q.vertices());
    assert_eq!(q.landmarks.len(), 68);
    let bytes = q.to_bytes().unwrap();
    assert_eq!(bytes.len(), q.blob_bytes().unwrap());
    assert_eq!(q.to_bytes().unwrap(), bytes, "deterministic");
    let buf = BlobBuf::from_bytes(&bytes);
    let blob = buf.view().unwrap();
    assert_eq!((blob.rank_shape(), blob.rank_color(), blob.bits()), (12, 8, 16));
    let stats = quantization_error(&q.reduced, &blob, 10, 1).unwrap();
    assert!(stats.shape_rms_mm < 1e-3 && stats.color_rms < 2e-5, "{stats:?}");
    // The float reference and the blob disagree in size: an error, not a panic.
    assert!(quantization_error(&model, &blob, 1, 1).is_err());
    // A tight budget is refused with the size in the message.
    opts.budget = Some(1000);
    let e = quantize(&model, &opts).unwrap_err();
    assert!(matches!(e, QuantizeError::OverBudget { budget: 1000, .. }), "{e}");
    opts.budget = None;
    opts.bits = Bits::Eight;
    let q8 = quantize(&model, &opts).unwrap();
    assert!(q8.blob_bytes().unwrap() < bytes.len());
}
