//! `gpmm render`, `gpmm sample -o` and `gpmm figure kernels`: PNGs of the right size that show a
//! centred face, clear errors on bad input, and byte-identical output for the same seed.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn data_dir() -> Option<PathBuf> {
    gpmm_host::data::data_dir_for_tests()
}

fn gpmm(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_gpmm")).args(args).output().expect("gpmm runs")
}

fn ok(out: &Output) {
    assert!(out.status.success(), "gpmm failed: {}", String::from_utf8_lossy(&out.stderr));
}

fn fails(out: &Output, needle: &str) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "expected failure mentioning '{needle}'");
    assert!(stderr.to_lowercase().contains(&needle.to_lowercase()), "stderr lacks '{needle}': {stderr}");
    assert!(!stderr.contains("panicked"), "no panic: {stderr}");
}

fn template_args(data: &Path) -> (String, String) {
    let t = data.join("template/lee-perry-smith");
    (t.join("lee-perry-smith.ply").display().to_string(), t.join("landmarks_ibug68.json").display().to_string())
}

/// A small model (rank 6 shape, 5 colour) in `dir`.
fn small_model(data: &Path, dir: &Path) -> String {
    let (ply, lm) = template_args(data);
    let out = dir.join("m.gpmm").display().to_string();
    ok(&gpmm(&[
        "build",
        "--template",
        &ply,
        "--landmarks",
        &lm,
        "--rank-shape",
        "6",
        "--rank-color",
        "5",
        "--vertices",
        "700",
        "--nystrom-points",
        "300",
        "-o",
        &out,
    ]));
    out
}

fn load(path: &Path) -> image::RgbaImage {
    image::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())).to_rgba8()
}

/// Pixels differing from the top-left (background) pixel, and their centroid.
fn foreground(img: &image::RgbaImage) -> (usize, f64, f64) {
    let bg = *img.get_pixel(0, 0);
    let fg: Vec<(u32, u32)> = img.enumerate_pixels().filter(|(_, _, p)| **p != bg).map(|(x, y, _)| (x, y)).collect();
    let n = fg.len().max(1) as f64;
    (fg.len(), fg.iter().map(|c| f64::from(c.0)).sum::<f64>() / n, fg.iter().map(|c| f64::from(c.1)).sum::<f64>() / n)
}

#[test]
fn render_writes_a_centred_face() {
    let Some(data) = data_dir() else { return };
    let dir = tempfile::tempdir().unwrap();
    let m = small_model(&data, dir.path());
    let out = dir.path().join("r.png");
    let o = out.to_str().unwrap();
    ok(&gpmm(&["render", &m, "-o", o]));
    let img = load(&out);
    assert_eq!(img.dimensions(), (256, 256));
    let (n, cx, cy) = foreground(&img);
    assert!(n > 256 * 256 / 5 && n < 256 * 256 * 9 / 10, "face covers {n} pixels");
    assert!((cx - 128.0).abs() < 16.0 && (cy - 128.0).abs() < 24.0, "centroid ({cx}, {cy})");

    // Pose, light, size, coefficients, transparent background.
    ok(&gpmm(&[
        "render",
        &m,
        "--yaw",
        "-30",
        "--pitch",
        "10",
        "--roll",
        "5",
        "--light",
        "left",
        "--size",
        "200x120",
        "--shape",
        "1,-0.5,2",
        "--color",
        "-1,0.5",
        "--background",
        "transparent",
        "-o",
        o,
    ]));
    let img = load(&out);
    assert_eq!(img.dimensions(), (200, 120));
    let covered = img.pixels().filter(|p| p[3] == 255).count();
    assert!(covered > 2000 && img.pixels().any(|p| p[3] == 0), "covered {covered}");

    // A light given as 9x3 JSON (inline and as a file) equals the matching preset.
    let amb = 1.0 / (0.282_094_8f32 * std::f32::consts::PI);
    let json = format!("[[{amb},{amb},{amb}],[0,0,0],[0,0,0],[0,0,0],[0,0,0],[0,0,0],[0,0,0],[0,0,0],[0,0,0]]");
    let a = dir.path().join("a.png");
    let b = dir.path().join("b.png");
    let c = dir.path().join("c.png");
    ok(&gpmm(&["render", &m, "--light", "ambient", "-o", a.to_str().unwrap()]));
    ok(&gpmm(&["render", &m, "--light", &json, "-o", b.to_str().unwrap()]));
    let light_file = dir.path().join("light.json");
    std::fs::write(&light_file, &json).unwrap();
    ok(&gpmm(&["render", &m, "--light", light_file.to_str().unwrap(), "-o", c.to_str().unwrap()]));
    let (ia, ib, ic) = (load(&a), load(&b), load(&c));
    assert_eq!(ib, ic);
    let max = ia.pixels().zip(ib.pixels()).flat_map(|(p, q)| (0..3).map(move |k| p[k].abs_diff(q[k]))).max().unwrap();
    assert!(max <= 1, "ambient preset vs JSON: {max}");
}

#[test]
fn render_rejects_bad_input() {
    let Some(data) = data_dir() else { return };
    let dir = tempfile::tempdir().unwrap();
    let m = small_model(&data, dir.path());
    let o = dir.path().join("x.png");
    let o = o.to_str().unwrap();
    fails(&gpmm(&["render", &m, "--size", "0x100", "-o", o]), "1 to 8192");
    fails(&gpmm(&["render", &m, "--size", "100000x100", "-o", o]), "1 to 8192");
    fails(&gpmm(&["render", &m, "--size", "big", "-o", o]), "WIDTHxHEIGHT");
    fails(&gpmm(&["render", &m, "--light", "disco", "-o", o]), "unknown light");
    fails(&gpmm(&["render", &m, "--light", "[[1,2,3]", "-o", o]), "malformed light JSON");
    fails(&gpmm(&["render", &m, "--light", "[[1,2,3],[4,5,6]]", "-o", o]), "9 rows");
    fails(&gpmm(&["render", &m, "--shape", "1,2,3,4,5,6,7", "-o", o]), "7 shape coefficients given, but the model has only 6");
    fails(&gpmm(&["render", &m, "--color", "0,0,0,0,0,1", "-o", o]), "6 colour coefficients given, but the model has only 5");
    fails(&gpmm(&["render", &m, "--shape", "1,x", "-o", o]), "'x'");
    fails(&gpmm(&["render", &m, "--shape", "nan", "-o", o]), "finite");
    fails(&gpmm(&["render", &m, "--background", "red", "-o", o]), "transparent");
    fails(&gpmm(&["render", &m, "--fov", "0", "-o", o]), "field of view");
    fails(&gpmm(&["render", dir.path().join("missing.gpmm").to_str().unwrap(), "-o", o]), "missing.gpmm");
    assert!(!Path::new(o).exists(), "no output on error");
}

#[test]
fn sample_grid_is_deterministic_and_matches_the_meshes() {
    let Some(data) = data_dir() else { return };
    let dir = tempfile::tempdir().unwrap();
    let m = small_model(&data, dir.path());
    let (a, b, c) = (dir.path().join("a.png"), dir.path().join("b.png"), dir.path().join("c.png"));
    let ply_dir = dir.path().join("ply");
    ok(&gpmm(&[
        "sample",
        &m,
        "-n",
        "3",
        "--seed",
        "5",
        "--size",
        "64x80",
        "-o",
        a.to_str().unwrap(),
        "--out-dir",
        ply_dir.to_str().unwrap(),
    ]));
    assert!(ply_dir.join("sample_002.ply").is_file());
    ok(&gpmm(&["sample", &m, "-n", "3", "--seed", "5", "--size", "64x80", "-o", b.to_str().unwrap()]));
    ok(&gpmm(&["sample", &m, "-n", "3", "--seed", "6", "--size", "64x80", "-o", c.to_str().unwrap()]));
    let (ba, bb, bc) = (std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap(), std::fs::read(&c).unwrap());
    assert_eq!(ba, bb, "same seed, same PNG bytes");
    assert_ne!(ba, bc, "another seed, another grid");
    let img = load(&a);
    // 4 columns (mean + 3) and 2 rows of 64x80 cells, plus labels and gaps.
    assert!(img.width() > 4 * 64 && img.width() < 4 * 64 + 200, "{}", img.width());
    assert!(img.height() > 2 * 80 && img.height() < 2 * 80 + 80, "{}", img.height());
    let (n, _, _) = foreground(&img);
    assert!(n > 8 * 64 * 80 / 5, "faces cover {n} pixels");

    fails(&gpmm(&["sample", &m, "-n", "2"]), "--out-dir");
    fails(&gpmm(&["sample", &m, "-n", "2", "--size", "0x3", "-o", a.to_str().unwrap()]), "1 to 8192");
    fails(&gpmm(&["sample", &m, "-n", "2", "--light", "nope", "-o", a.to_str().unwrap()]), "unknown light");
    fails(&gpmm(&["sample", &m, "-n", "1000000", "-o", a.to_str().unwrap()]), "pixels wide");
}

#[test]
fn kernel_figure_has_nine_blocks_and_is_deterministic() {
    let Some(data) = data_dir() else { return };
    let (ply, lm) = template_args(&data);
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a.png"), dir.path().join("b.png"));
    let args = |o: &Path| {
        let v: Vec<String> = [
            "figure",
            "kernels",
            "--template",
            &ply,
            "--landmarks",
            &lm,
            "--vertices",
            "500",
            "--nystrom-points",
            "200",
            "--ranks",
            "8,6",
            "--cell",
            "48",
            "-o",
            o.to_str().unwrap(),
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        v
    };
    let run = |o: &Path| {
        let v = args(o);
        gpmm(&v.iter().map(String::as_str).collect::<Vec<_>>())
    };
    ok(&run(&a));
    ok(&run(&b));
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap(), "same seed, same figure");
    let img = load(&a);
    // 3 x 3 blocks of 3 x 2 cells of 48 px, plus titles, labels and gaps.
    assert!(img.width() > 9 * 48 && img.width() < 9 * 48 + 300, "{}", img.width());
    assert!(img.height() > 6 * 48 && img.height() < 6 * 48 + 200, "{}", img.height());
    let (n, cx, _) = foreground(&img);
    assert!(n > 54 * 48 * 48 / 5, "faces cover {n} pixels");
    assert!(cx > img.width() as f64 * 0.35 && cx < img.width() as f64 * 0.65, "centroid x {cx}");

    let o = dir.path().join("c.png");
    let o = o.to_str().unwrap();
    fails(&gpmm(&["figure", "kernels", "--template", &ply, "--landmarks", &lm, "--ranks", "0,5", "-o", o]), "ranks");
    fails(&gpmm(&["figure", "kernels", "--template", &ply, "--landmarks", &lm, "--cell", "5", "-o", o]), "cell");
    fails(&gpmm(&["figure", "kernels", "--template", "nope.ply", "--landmarks", &lm, "-o", o]), "nope.ply");
}
