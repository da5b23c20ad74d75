//! Synthetic faces with known truth (`gpmm_host::synth`): files, plausibility, determinism, bad input.

use std::path::{Path, PathBuf};

use gpmm_host::synth::{read_truth, synthesize, write_synth_dir, SynthError, SynthOptions, SynthWorld};

fn data_dir() -> Option<PathBuf> {
    gpmm_host::data::data_dir_for_tests()
}

fn small(data: &Path, size: u32, count: usize, yaws: &[f32]) -> SynthOptions {
    SynthOptions { count, size, yaws_deg: yaws.to_vec(), seed: 7, ..SynthOptions::with_data_dir(data) }
}

fn mean_x(lm: &[[f32; 2]], ids: &[usize]) -> f32 {
    ids.iter().map(|&i| lm[i][0]).sum::<f32>() / ids.len() as f32
}

fn mean_y(lm: &[[f32; 2]], ids: std::ops::Range<usize>) -> f32 {
    let n = ids.len() as f32;
    ids.map(|i| lm[i][1]).sum::<f32>() / n
}

/// A small run writes every file; images show a face of plausible size; landmarks are plausible.
#[test]
fn synth_writes_files_with_plausible_faces_and_landmarks() {
    let Some(data) = data_dir() else { return };
    let dir = tempfile::tempdir().unwrap();
    let opts = small(&data, 128, 2, &[0.0, 30.0]);
    let mut calls = Vec::new();
    let summary = write_synth_dir(&opts, dir.path(), |d, t| calls.push((d, t))).unwrap();
    assert_eq!(summary.images, 4);
    assert_eq!(calls.last(), Some(&(4, 4)));
    let truth = read_truth(&summary.truth).unwrap();
    assert_eq!(truth.format, "gpmm-synth");
    assert_eq!(truth.seed, 7);
    assert_eq!(truth.images.len(), 4);
    assert_eq!(truth.identities.len(), 2);
    assert_eq!(truth.ict.holes.iter().filter(|h| matches!(h, gpmm_host::synth::HoleKind::Eye)).count(), 2, "both eye holes closed");
    let names: Vec<&str> = truth.images.iter().map(|t| t.image.as_str()).collect();
    assert_eq!(names, ["0000_yaw00.png", "0000_yaw30.png", "0001_yaw00.png", "0001_yaw30.png"]);

    for t in &truth.images {
        assert_eq!(t.shape_coefficients.len(), 100);
        assert_eq!(t.landmarks.len(), 68);
        // The image is the right size and not blank: the face covers a plausible part of it.
        let img = image::open(dir.path().join(&t.image)).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (128, 128));
        assert!((0.25..=0.75).contains(&t.face_fraction), "{}: face covers {}", t.image, t.face_fraction);
        let bg = t.background_rgb.map(|c| (c * 255.0).round());
        let differing = img.pixels().filter(|p| (0..3).any(|k| (f32::from(p[k]) - bg[k]).abs() > 25.0)).count() as f32 / (128.0 * 128.0);
        assert!(differing > 0.2, "{}: only {differing} of the pixels differ from the background", t.image);

        // The .pts file holds the same landmarks in the iBUG format.
        let pts = std::fs::read_to_string(dir.path().join(&t.landmarks_file)).unwrap();
        let lines: Vec<&str> = pts.lines().collect();
        assert_eq!(&lines[..3], ["version: 1", "n_points:  68", "{"]);
        assert_eq!(lines.len(), 72);
        assert_eq!(lines[71], "}");
        for (line, p) in lines[3..71].iter().zip(&t.landmarks) {
            let v: Vec<f32> = line.split_whitespace().map(|s| s.parse().unwrap()).collect();
            assert!((v[0] - p[0]).abs() < 1e-3 && (v[1] - p[1]).abs() < 1e-3);
        }

        // Landmarks: inside the image, eyes above the nose above the mouth above the chin.
        let lm = &t.landmarks;
        assert!(lm.iter().all(|p| p[0] > 0.0 && p[1] > 0.0 && p[0] < 128.0 && p[1] < 128.0), "{}: {lm:?}", t.image);
        let (eyes, nose, mouth) = (mean_y(lm, 36..48), lm[33][1], mean_y(lm, 48..68));
        assert!(eyes + 5.0 < nose && nose + 2.0 < mouth && mouth + 5.0 < lm[8][1], "{}: eyes {eyes} nose {nose} mouth {mouth}", t.image);
        // The canthal distance spans a plausible part of the image at yaw 0.
        if t.yaw_deg == 0.0 {
            let eye_span = lm[45][0] - lm[36][0];
            assert!((25.0..55.0).contains(&eye_span), "{}: eye span {eye_span}", t.image);
            // Left and right eye corners are symmetric about the face's midline (nose bridge).
            for (l, r) in [(36, 45), (39, 42)] {
                let mid = 0.5 * (lm[l][0] + lm[r][0]);
                assert!((mid - lm[27][0]).abs() < 2.5, "{}: eye corners {l}/{r} mid {mid} vs bridge {}", t.image, lm[27][0]);
            }
            assert!(t.landmarks_visible.iter().all(|&v| v), "{}: all landmarks visible at yaw 0", t.image);
        }
    }
    // Positive yaw turns the nose toward the image right (relative to the eye corners).
    for id in 0..2 {
        let nose_offset = |yaw: f32| {
            let t = truth.images.iter().find(|t| t.identity == id && t.yaw_deg == yaw).unwrap();
            t.landmarks[30][0] - mean_x(&t.landmarks, &[36, 45])
        };
        let (o0, o30) = (nose_offset(0.0), nose_offset(30.0));
        assert!(o0.abs() < 2.5, "identity {id}: nose offset {o0} at yaw 0");
        assert!(o30 > 4.0, "identity {id}: nose offset {o30} at yaw 30 (should be to the image right)");
    }
    // At 30° the far jaw side begins to hide behind the face; the near side stays visible.
    let t30 = truth.images.iter().find(|t| t.yaw_deg == 30.0).unwrap();
    assert!(t30.landmarks_visible[0..=4].iter().all(|&v| v), "near jaw (subject's right, image left) visible: {:?}", t30.landmarks_visible);
}

/// The same seed gives identical images and truth; another seed gives other faces.
#[test]
fn synth_is_deterministic_for_a_seed() {
    let Some(data) = data_dir() else { return };
    let opts = small(&data, 64, 1, &[15.0]);
    let a = synthesize(&opts, |_, _| {}).unwrap();
    let b = synthesize(&opts, |_, _| {}).unwrap();
    assert_eq!(a.len(), 1);
    assert_eq!(a[0].image.as_raw(), b[0].image.as_raw());
    assert_eq!(a[0].truth, b[0].truth);
    // The written files are byte-identical too.
    let (d1, d2) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    write_synth_dir(&opts, d1.path(), |_, _| {}).unwrap();
    write_synth_dir(&opts, d2.path(), |_, _| {}).unwrap();
    for name in ["0000_yaw15.png", "0000_yaw15.pts", "truth.json"] {
        assert_eq!(std::fs::read(d1.path().join(name)).unwrap(), std::fs::read(d2.path().join(name)).unwrap(), "{name}");
    }
    let written = image::open(d1.path().join("0000_yaw15.png")).unwrap().to_rgb8();
    assert_eq!(written.as_raw(), a[0].image.as_raw(), "the PNG holds the rendered image");
    let c = synthesize(&SynthOptions { seed: 8, ..opts.clone() }, |_, _| {}).unwrap();
    assert_ne!(a[0].image.as_raw(), c[0].image.as_raw());
    assert_ne!(a[0].truth.shape_coefficients, c[0].truth.shape_coefficients);
}

/// Identities differ in shape (3-D landmark distances) and albedo; views of one identity share both.
#[test]
fn synth_identities_differ_in_shape_and_albedo() {
    let Some(data) = data_dir() else { return };
    let opts = small(&data, 64, 2, &[0.0]);
    let world = SynthWorld::load(&opts).unwrap();
    let (a, b) = (world.identity(0).unwrap(), world.identity(1).unwrap());
    assert_eq!(world.identity(0).unwrap(), a, "identity is deterministic");
    let lm = world.landmarks();
    let dist = |p: &[[f32; 3]], i: usize, j: usize| {
        let (u, v) = (p[lm[i] as usize], p[lm[j] as usize]);
        ((u[0] - v[0]).powi(2) + (u[1] - v[1]).powi(2) + (u[2] - v[2]).powi(2)).sqrt()
    };
    let pairs = [(36, 45), (27, 8), (31, 35), (48, 54), (0, 16), (30, 8)];
    let diffs: Vec<f32> = pairs.iter().map(|&(i, j)| (dist(&a.positions, i, j) - dist(&b.positions, i, j)).abs()).collect();
    assert!(diffs.iter().cloned().fold(0.0, f32::max) > 2.0, "landmark distances differ by {diffs:?} mm");
    // Realistic sizes: outer canthal distance 75-110 mm.
    for p in [&a.positions, &b.positions] {
        let d = dist(p, 36, 45);
        assert!((75.0..110.0).contains(&d), "canthal distance {d}");
    }
    let mean_abs: f32 = a.albedo.iter().zip(&b.albedo).map(|(x, y)| (0..3).map(|k| (x[k] - y[k]).abs()).sum::<f32>() / 3.0).sum::<f32>()
        / a.albedo.len() as f32;
    assert!(mean_abs > 0.01, "albedo differs by {mean_abs} on average");
    // The albedo is plausible skin: mean brighter than dark, reddish (R >= B).
    let base = world.base_albedo();
    let mean: Vec<f32> = (0..3).map(|k| base.iter().map(|c| c[k]).sum::<f32>() / base.len() as f32).collect();
    assert!(mean[0] > 0.2 && mean[0] >= mean[2], "mean template albedo {mean:?}");
}

/// Missing or malformed files and invalid options give clear errors naming the problem.
#[test]
fn synth_bad_input_errors() {
    let Some(data) = data_dir() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let ict = tmp.path().join("ict");
    std::fs::create_dir(&ict).unwrap();
    let base = SynthOptions { count: 1, size: 64, ict_dir: ict.clone(), ..SynthOptions::with_data_dir(&data) };
    let err = |o: &SynthOptions| SynthWorld::load(o).map(|_| ()).unwrap_err();
    let msg = |o: &SynthOptions| err(o).to_string();

    // Missing file.
    let m = msg(&base);
    assert!(m.contains("neutral.npy") && m.contains("cannot read"), "{m}");
    // Malformed npy.
    std::fs::write(ict.join("neutral.npy"), b"not an npy file").unwrap();
    let m = msg(&base);
    assert!(m.contains("neutral.npy") && m.contains("magic"), "{m}");
    // Wrong shape.
    write_npy_f32(&ict.join("neutral.npy"), &[100, 2], &vec![0.0; 200]);
    let m = msg(&base);
    assert!(m.contains("neutral.npy") && m.contains("(N, 3)"), "{m}");
    // Triangle index out of range; modes of the wrong shape; landmarks missing.
    let n = 100usize;
    let verts: Vec<f32> = (0..n * 3).map(|i| (i as f32 * 0.37).sin()).collect();
    write_npy_f32(&ict.join("neutral.npy"), &[n, 3], &verts);
    write_npy_u32(&ict.join("triangles.npy"), &[1, 3], &[0, 1, 100]);
    let m = msg(&base);
    assert!(m.contains("triangles.npy") && m.contains("out of range"), "{m}");
    write_npy_u32(&ict.join("triangles.npy"), &[1, 3], &[0, 1, 2]);
    write_npy_f32(&ict.join("identity_modes.npy"), &[2, n + 1, 3], &vec![0.0; 2 * (n + 1) * 3]);
    let m = msg(&base);
    assert!(m.contains("identity_modes.npy") && m.contains("expected shape"), "{m}");
    write_npy_f32(&ict.join("identity_modes.npy"), &[2, n, 3], &vec![0.0; 2 * n * 3]);
    let m = msg(&base);
    assert!(m.contains("landmarks_ibug68.json"), "{m}");
    std::fs::write(ict.join("landmarks_ibug68.json"), r#"{"scheme": "ibug68", "vertex_ids": [1, 2, 3]}"#).unwrap();
    let m = msg(&base);
    assert!(m.contains("landmarks_ibug68.json") && m.contains("68"), "{m}");
    // Truncated data.
    let bytes = std::fs::read(data.join("ict/triangles.npy")).unwrap();
    std::fs::write(ict.join("triangles.npy"), &bytes[..bytes.len() / 2]).unwrap();
    let m = msg(&base);
    assert!(m.contains("triangles.npy") && m.contains("truncated"), "{m}");
    assert!(matches!(err(&base), SynthError::Npy(_)));

    // Invalid options.
    let real = SynthOptions { count: 1, size: 64, ..SynthOptions::with_data_dir(&data) };
    for (o, what) in [
        (SynthOptions { size: 0, ..real.clone() }, "image size"),
        (SynthOptions { yaws_deg: vec![], ..real.clone() }, "yaw"),
        (SynthOptions { yaws_deg: vec![0.0, 120.0], ..real.clone() }, "yaw 120"),
        (SynthOptions { yaws_deg: vec![15.0, 15.0], ..real.clone() }, "repeat"),
        (SynthOptions { identity_scale: f32::NAN, ..real.clone() }, "identity scale"),
        (SynthOptions { fov_deg: [40.0, 30.0], ..real.clone() }, "field of view"),
    ] {
        let e = err(&o);
        assert!(matches!(e, SynthError::Options { .. }) && e.to_string().contains(what), "{e}");
    }
    // A missing template directory names the template file.
    let o = SynthOptions { template_dir: tmp.path().join("nowhere"), ..real };
    let m = msg(&o);
    assert!(m.contains("albedo template") && m.contains("nowhere"), "{m}");
}

/// Writes the contact sheet `docs/images/synth.png` (run explicitly: `cargo test -p gpmm-host --test synth -- --ignored`).
#[test]
#[ignore]
fn synth_contact_sheet() {
    let Some(data) = data_dir() else { return };
    let opts = SynthOptions { count: 4, seed: 1, yaws_deg: vec![0.0, 45.0], ..SynthOptions::with_data_dir(&data) };
    let faces = synthesize(&opts, |_, _| {}).unwrap();
    let sheet = gpmm_host::synth::contact_sheet(&faces, 4);
    let out = std::env::var_os("GPMM_SYNTH_SHEET")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/images/synth.png"));
    std::fs::create_dir_all(out.parent().unwrap()).unwrap();
    let file = std::io::BufWriter::new(std::fs::File::create(&out).unwrap());
    let encoder = image::codecs::png::PngEncoder::new_with_quality(
        file,
        image::codecs::png::CompressionType::Best,
        image::codecs::png::FilterType::Adaptive,
    );
    sheet.write_with_encoder(encoder).unwrap();
}

fn npy_bytes(descr: &str, shape: &[usize], data: &[u8]) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let shape = if dims.len() == 1 { format!("({},)", dims[0]) } else { format!("({})", dims.join(", ")) };
    let mut header = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}");
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    out.extend_from_slice(data);
    out
}

fn write_npy_f32(path: &Path, shape: &[usize], values: &[f32]) {
    let data: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    std::fs::write(path, npy_bytes("<f4", shape, &data)).unwrap();
}

fn write_npy_u32(path: &Path, shape: &[usize], values: &[u32]) {
    let data: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    std::fs::write(path, npy_bytes("<u4", shape, &data)).unwrap();
}
