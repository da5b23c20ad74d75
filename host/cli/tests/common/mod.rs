//! Helpers shared by the tests that run the `gpmm` program.
#![allow(dead_code)]

use std::process::{Command, Output};

/// Runs `gpmm` with `args`.
pub fn gpmm(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_gpmm")).args(args).output().expect("gpmm runs")
}

/// Asserts success; returns stdout.
pub fn ok(out: &Output) -> String {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "gpmm failed: {stderr}");
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Asserts failure without a panic; returns stderr.
pub fn fails(out: &Output) -> String {
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "gpmm should have failed; stdout: {}", String::from_utf8_lossy(&out.stdout));
    assert!(!stderr.contains("panicked"), "gpmm panicked: {stderr}");
    stderr
}

/// Reads a JSON file (panics with the path if it cannot).
pub fn read_json(p: &std::path::Path) -> serde_json::Value {
    let text = std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// Writes `dir/group.jpg`, a textured 640 × 480 photo with one "face" at x 300..380, y 150..230,
/// and its `group.faces.json` (the face's box and 68 points spread over it): a folder of photos
/// of people, as `train-init --backgrounds` reads one.
pub fn people_folder(dir: &std::path::Path) {
    std::fs::create_dir_all(dir).expect("the people folder");
    let img = image::RgbImage::from_fn(640, 480, |x, y| {
        if (300..380).contains(&x) && (150..230).contains(&y) {
            image::Rgb([210, 160, 130])
        } else {
            image::Rgb([((x * 3 + y) % 90) as u8 + 40, 90, ((y * 5) % 120) as u8 + 60])
        }
    });
    img.save(dir.join("group.jpg")).expect("group.jpg");
    let points: Vec<[f32; 2]> = (0..68).map(|i| [300.0 + (i % 9) as f32 * 10.0, 150.0 + (i / 9) as f32 * 80.0 / 7.0]).collect();
    let faces = serde_json::json!({"faces": [{"box": [305, 160, 375, 230], "landmarks": points}]});
    std::fs::write(dir.join("group.faces.json"), faces.to_string()).expect("group.faces.json");
}
