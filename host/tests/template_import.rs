//! Template import: PLY/glTF reading, normalization, face crop, simplification
//! and error handling on bad input.
//!
//! Tests on the real template read it from `$GPMM_DATA` (default
//! `../shared/data` next to the workspace) and return early with a message
//! only when that directory is absent.

use std::io::Write;
use std::path::{Path, PathBuf};

use gpmm_host::mesh::io::{read_landmarks_json, read_mesh, write_ply, write_ply_with, MeshIoError, PlyEncoding};
use gpmm_host::mesh::template::{load_template, Mesh, Template, TemplateError, TemplateOptions, IBUG68_MIRROR_PAIRS};

fn data_dir() -> Option<PathBuf> {
    gpmm_host::data::data_dir_for_tests()
}

fn template_dir() -> Option<PathBuf> {
    data_dir().map(|d| d.join("template/lee-perry-smith"))
}

fn load(dir: &Path, opts: &TemplateOptions) -> Template {
    load_template(&dir.join("lee-perry-smith.ply"), &dir.join("landmarks_ibug68.json"), opts).expect("template loads")
}

fn lm_positions(t: &Template) -> Vec<[f64; 3]> {
    t.landmarks.iter().map(|&i| t.mesh.positions[i as usize]).collect()
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt()
}

fn assert_valid(mesh: &Mesh) {
    let n = mesh.positions.len();
    assert_eq!(mesh.colors.len(), n);
    assert!(mesh.triangles.iter().all(|t| t.iter().all(|&i| (i as usize) < n)));
    // Every vertex is used by a triangle.
    let mut used = vec![false; n];
    for t in &mesh.triangles {
        for &i in t {
            used[i as usize] = true;
        }
    }
    assert!(used.iter().all(|&u| u), "unused vertices after compaction");
}

#[test]
fn ply_template_loads_with_landmarks() {
    let Some(dir) = template_dir() else { return };
    let mesh = read_mesh(&dir.join("lee-perry-smith.ply"), None, None).unwrap();
    assert_eq!(mesh.positions.len(), 8844);
    assert_eq!(mesh.triangles.len(), 17684);
    assert!(mesh.colors.iter().all(|c| c.iter().all(|v| (0.0..=1.0).contains(v))));
    // First vertex of the file: -4.27632 -2.86604 -0.55742 196 149 133.
    assert!((mesh.positions[0][0] + 4.27632).abs() < 1e-5);
    assert!((mesh.colors[0][0] - 196.0 / 255.0).abs() < 1e-9);
    let (scheme, ids) = read_landmarks_json(&dir.join("landmarks_ibug68.json")).unwrap();
    assert_eq!(scheme, "ibug68");
    assert_eq!(ids.len(), 68);
    assert_eq!(ids[0], 1067);
}

#[test]
fn normalization_scales_centres_and_orients() {
    let Some(dir) = template_dir() else { return };
    let t = load(&dir, &TemplateOptions { no_crop: true, ..Default::default() });
    assert_eq!(t.scheme, "ibug68");
    assert_eq!(t.mesh.positions.len(), 8844);
    let p = lm_positions(&t);
    assert!((dist(p[36], p[45]) - 90.0).abs() < 1e-6);
    assert!((t.provenance.scale_mm_per_unit - 90.0 / 1.712).abs() < 0.1);
    // x to image right: the subject's left eye corner (45) has larger x.
    assert!(p[45][0] > p[36][0]);
    // Mirror pairs straddle x = 0 and sit at matching height and depth, within
    // the landmarks' accuracy (the jaw contour 0-16 is silhouette-dependent and
    // least exact). The mirror plane passes through the pairs' mean midpoint.
    let mut mean_mid_x = 0.0;
    for &(l, r) in &IBUG68_MIRROR_PAIRS {
        let d = [p[l][0] + p[r][0], p[l][1] - p[r][1], p[l][2] - p[r][2]];
        mean_mid_x += d[0] / 2.0 / IBUG68_MIRROR_PAIRS.len() as f64;
        let bound = if l < 17 { 20.0 } else { 8.0 };
        assert!(
            d[0].abs() < 7.0 && d[1].abs() < bound && d[2].abs() < bound,
            "pair {l}/{r} not mirrored about x = 0: {:?} {:?}",
            p[l],
            p[r]
        );
    }
    assert!(mean_mid_x.abs() < 1e-6, "mirror plane off x = 0 by {mean_mid_x}");
    // Nose tip in front of the eye corners, chin below the brows, nose bridge above the chin.
    assert!(p[30][2] > p[36][2] + 20.0 && p[30][2] > p[45][2] + 20.0);
    assert!(p[8][1] < p[19][1] && p[8][1] < p[24][1]);
    assert!(p[27][1] > p[8][1] + 80.0);
    // Symmetric-ish about x = 0 as a whole.
    let cx: f64 = p.iter().map(|q| q[0]).sum::<f64>() / p.len() as f64;
    assert!(cx.abs() < 3.0, "landmark centroid x = {cx}");
    assert!(!t.provenance.cropped);
    assert_eq!(t.provenance.source_vertices, 8844);
    assert_eq!(t.provenance.source_sha256.len(), 64);
    let attribution = t.provenance.attribution.as_deref().unwrap_or("");
    assert!(attribution.contains("Lee Perry-Smith") && attribution.contains("CC BY 3.0"), "attribution: {attribution}");
    assert!(attribution.contains("\"Infinite, 3D Head Scan\""));
}

#[test]
fn explicit_scale_multiplies() {
    let Some(dir) = template_dir() else { return };
    let t = load(&dir, &TemplateOptions { no_crop: true, scale: Some(10.0), ..Default::default() });
    let p = lm_positions(&t);
    assert!((dist(p[36], p[45]) - 17.12).abs() < 0.01);
    assert_eq!(t.provenance.scale_mm_per_unit, 10.0);
}

#[test]
fn crop_keeps_face_and_all_landmarks() {
    let Some(dir) = template_dir() else { return };
    let full = load(&dir, &TemplateOptions { no_crop: true, ..Default::default() });
    let t = load(&dir, &TemplateOptions::default());
    assert!(t.provenance.cropped);
    assert_eq!(t.provenance.source_vertices, 8844);
    assert_valid(&t.mesh);
    let n = t.mesh.positions.len();
    assert!((3000..=5500).contains(&n), "cropped to {n} vertices");
    assert_eq!(t.landmarks.len(), 68);
    for (a, b) in lm_positions(&t).iter().zip(lm_positions(&full)) {
        assert_eq!(*a, b, "a landmark moved in the crop");
    }
    // The back of the head, the neck and the shoulders are gone.
    let zmin = t.mesh.positions.iter().map(|p| p[2]).fold(f64::MAX, f64::min);
    let ymin = t.mesh.positions.iter().map(|p| p[1]).fold(f64::MAX, f64::min);
    let full_zmin = full.mesh.positions.iter().map(|p| p[2]).fold(f64::MAX, f64::min);
    assert!(full_zmin < -150.0);
    assert!(zmin > -100.0, "crop reaches z = {zmin}");
    assert!(ymin > -100.0, "crop reaches y = {ymin} (neck)");
    // Forehead kept: something well above the brows.
    let ymax = t.mesh.positions.iter().map(|p| p[1]).fold(f64::MIN, f64::max);
    assert!(ymax > lm_positions(&t)[19][1] + 30.0);
}

#[test]
fn simplify_to_budget_keeps_landmarks() {
    let Some(dir) = template_dir() else { return };
    let cropped = load(&dir, &TemplateOptions::default());
    let t = load(&dir, &TemplateOptions { vertices: Some(2000), ..Default::default() });
    assert_valid(&t.mesh);
    let n = t.mesh.positions.len();
    assert!(n <= 2000 && n > 1500, "simplified to {n} vertices");
    assert_eq!(t.landmarks.len(), 68);
    for (k, (a, b)) in lm_positions(&t).iter().zip(lm_positions(&cropped)).enumerate() {
        assert_eq!(*a, b, "landmark {k} moved in simplification");
        let i = t.landmarks[k];
        assert!(t.mesh.triangles.iter().any(|tri| tri.contains(&i)));
    }
    // A budget above the vertex count changes nothing.
    let same = load(&dir, &TemplateOptions { vertices: Some(100_000), ..Default::default() });
    assert_eq!(same.mesh, cropped.mesh);
}

#[test]
fn glb_with_texture_matches_ply() {
    let Some(dir) = template_dir() else { return };
    let ply = read_mesh(&dir.join("lee-perry-smith.ply"), None, None).unwrap();
    let glb = read_mesh(&dir.join("LeePerrySmith.glb"), Some(&dir.join("Map-COL.jpg")), None).unwrap();
    assert_eq!(glb.positions.len(), 8844, "welded vertex count");
    assert_eq!(glb.triangles.len(), 17684);
    let mut max_d: f64 = 0.0;
    let mut col = 0.0;
    for i in 0..ply.positions.len() {
        max_d = max_d.max(dist(ply.positions[i], glb.positions[i]));
        col += (0..3).map(|k| (ply.colors[i][k] - glb.colors[i][k]).abs()).sum::<f64>() / 3.0;
    }
    let mean_col = col / ply.positions.len() as f64;
    assert!(max_d < 1e-4, "positions differ by {max_d}");
    assert!(mean_col < 3.0 / 255.0, "colours differ by {} /255", mean_col * 255.0);
    assert_eq!(glb.triangles, ply.triangles);
    // The whole pipeline gives the same template.
    let opts = TemplateOptions { texture: Some(dir.join("Map-COL.jpg")), ..Default::default() };
    let tg = load_template(&dir.join("LeePerrySmith.glb"), &dir.join("landmarks_ibug68.json"), &opts).unwrap();
    let tp = load(&dir, &TemplateOptions::default());
    assert_eq!(tg.mesh.positions.len(), tp.mesh.positions.len());
    assert!(tg.provenance.texture.is_some());
    for (a, b) in lm_positions(&tg).iter().zip(lm_positions(&tp)) {
        assert!(dist(*a, b) < 1e-2);
    }
}

#[test]
fn glb_without_texture_is_an_error() {
    let Some(dir) = template_dir() else { return };
    let err = read_mesh(&dir.join("LeePerrySmith.glb"), None, None).unwrap_err();
    let msg = err.to_string();
    assert!(msg.contains("LeePerrySmith.glb") && msg.contains("--texture"), "{msg}");
}

// ------------------------------------------------------------ synthetic data

/// A closed tetrahedron with colours.
fn tetra() -> Mesh {
    Mesh {
        positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        colors: vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.5, 0.5, 0.5]],
        triangles: vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]],
    }
}

fn write_file(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::File::create(&p).and_then(|mut f| f.write_all(bytes)).unwrap();
    p
}

fn ascii_ply(vertex_props: &str, verts: &[&str], faces: &[&str]) -> String {
    format!(
        "ply\nformat ascii 1.0\nelement vertex {}\n{vertex_props}element face {}\nproperty list uchar int vertex_indices\nend_header\n{}\n{}\n",
        verts.len(),
        faces.len(),
        verts.join("\n"),
        faces.join("\n")
    )
}

const XYZ: &str = "property float x\nproperty float y\nproperty float z\n";
const XYZ_RGB: &str =
    "property float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n";

fn expect_err_naming(result: Result<Mesh, MeshIoError>, name: &str, word: &str) -> String {
    let msg = result.expect_err("bad input must be an error").to_string();
    assert!(msg.contains(name), "message does not name {name}: {msg}");
    assert!(msg.contains(word), "message does not mention {word}: {msg}");
    msg
}

#[test]
fn binary_ply_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = tetra();
    let path = dir.path().join("tetra.ply");
    write_ply(&path, &mesh).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    assert!(bytes.starts_with(b"ply\nformat binary_little_endian 1.0\n"));
    let back = read_mesh(&path, None, None).unwrap();
    assert_eq!(back.triangles, mesh.triangles);
    for (a, b) in back.positions.iter().zip(&mesh.positions) {
        assert!(dist(*a, *b) < 1e-6);
    }
    for (a, b) in back.colors.iter().zip(&mesh.colors) {
        for k in 0..3 {
            assert!((a[k] - b[k]).abs() <= 0.5 / 255.0 + 1e-12);
        }
    }
    // ASCII with an attribution comment.
    let apath = dir.path().join("tetra_ascii.ply");
    write_ply_with(&apath, &mesh, PlyEncoding::Ascii, &["by someone, CC BY"]).unwrap();
    let text = std::fs::read_to_string(&apath).unwrap();
    assert!(text.contains("format ascii 1.0\ncomment by someone, CC BY\n"));
    let back = read_mesh(&apath, None, None).unwrap();
    assert_eq!(back.triangles, mesh.triangles);
    assert_eq!(back.positions, mesh.positions);
}

#[test]
fn template_binary_round_trip() {
    let Some(dir) = template_dir() else { return };
    let t = load(&dir, &TemplateOptions::default());
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("face.ply");
    write_ply(&path, &t.mesh).unwrap();
    let back = read_mesh(&path, None, None).unwrap();
    assert_eq!(back.triangles, t.mesh.triangles);
    assert_eq!(back.positions.len(), t.mesh.positions.len());
    for (a, b) in back.positions.iter().zip(&t.mesh.positions) {
        assert!(dist(*a, *b) < 1e-4);
    }
}

#[test]
fn ply_polygons_float_colours_and_alternative_names() {
    let dir = tempfile::tempdir().unwrap();
    // A double-precision square as one quad, float colours named r g b, a uint index list.
    let text = "ply\nformat ascii 1.0\nelement vertex 4\nproperty double x\nproperty double y\nproperty double z\nproperty float r\nproperty float g\nproperty float b\nelement face 1\nproperty list int uint vertex_index\nend_header\n0 0 0 0.25 0.5 1\n1 0 0 0 0 0\n1 1 0 1 1 1\n0 1 0 0.5 0.5 0.5\n4 0 1 2 3\n";
    let p = write_file(dir.path(), "quad.ply", text.as_bytes());
    let m = read_mesh(&p, None, None).unwrap();
    assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
    assert_eq!(m.colors[0], [0.25, 0.5, 1.0]);
    // Degenerate triangles are dropped, not fatal.
    let text = ascii_ply(XYZ_RGB, &["0 0 0 1 2 3", "1 0 0 1 2 3", "0 1 0 1 2 3"], &["3 0 1 2", "3 0 0 1"]);
    let p = write_file(dir.path(), "degenerate.ply", text.as_bytes());
    assert_eq!(read_mesh(&p, None, None).unwrap().triangles.len(), 1);
}

#[test]
fn missing_colours_error_or_default() {
    let dir = tempfile::tempdir().unwrap();
    let text = ascii_ply(XYZ, &["0 0 0", "1 0 0", "0 1 0"], &["3 0 1 2"]);
    let p = write_file(dir.path(), "nocolour.ply", text.as_bytes());
    let msg = expect_err_naming(read_mesh(&p, None, None), "nocolour.ply", "colour");
    assert!(msg.contains("--default-color"), "{msg}");
    let m = read_mesh(&p, None, Some([0.5, 0.4, 0.3])).unwrap();
    assert_eq!(m.colors, vec![[0.5, 0.4, 0.3]; 3]);
}

#[test]
fn nan_vertex_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let text = ascii_ply(XYZ_RGB, &["0 0 0 1 2 3", "1 nan 0 1 2 3", "0 1 0 1 2 3"], &["3 0 1 2"]);
    let p = write_file(dir.path(), "nan.ply", text.as_bytes());
    let result = read_mesh(&p, None, None);
    // Either the PLY parser rejects "nan" or the validation does; both must name the file.
    let msg = result.expect_err("NaN must be rejected").to_string();
    assert!(msg.contains("nan.ply"), "{msg}");
    // A binary NaN always reaches validation.
    let mut mesh = tetra();
    mesh.positions[2][1] = f64::NAN;
    let bp = dir.path().join("nan_binary.ply");
    write_ply(&bp, &mesh).unwrap();
    expect_err_naming(read_mesh(&bp, None, None), "nan_binary.ply", "vertex 2 has a non-finite coordinate");
}

#[test]
fn triangle_index_out_of_range_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let text = ascii_ply(XYZ_RGB, &["0 0 0 1 2 3", "1 0 0 1 2 3", "0 1 0 1 2 3"], &["3 0 1 7"]);
    let p = write_file(dir.path(), "range.ply", text.as_bytes());
    expect_err_naming(read_mesh(&p, None, None), "range.ply", "vertex 7");
    let text = ascii_ply(
        "property float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n",
        &["0 0 0 1 2 3", "1 0 0 1 2 3", "0 1 0 1 2 3"],
        &[],
    );
    let p = write_file(dir.path(), "empty.ply", text.as_bytes());
    expect_err_naming(read_mesh(&p, None, None), "empty.ply", "no triangles");
}

#[test]
fn landmark_out_of_range_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let mesh_path = dir.path().join("tetra.ply");
    write_ply(&mesh_path, &tetra()).unwrap();
    let lm = write_file(dir.path(), "marks.json", br#"{"scheme": "custom", "vertex_ids": [0, 3, 99999]}"#);
    let err = load_template(&mesh_path, &lm, &TemplateOptions::default()).unwrap_err();
    let msg = err.to_string();
    assert!(msg.contains("marks.json") && msg.contains("landmark 2 refers to vertex 99999 but the mesh has 4 vertices"), "{msg}");
    assert!(matches!(err, TemplateError::Landmarks { .. }));
    // A malformed landmark file names itself too.
    let bad = write_file(dir.path(), "bad.json", br#"{"scheme": "x", "vertex_ids": [-1]}"#);
    let msg = read_landmarks_json(&bad).unwrap_err().to_string();
    assert!(msg.contains("bad.json"), "{msg}");
    // ibug68 needs 68 ids.
    let short = write_file(dir.path(), "short.json", br#"{"scheme": "ibug68", "vertex_ids": [0, 1]}"#);
    let msg = load_template(&mesh_path, &short, &TemplateOptions::default()).unwrap_err().to_string();
    assert!(msg.contains("short.json") && msg.contains("68"), "{msg}");
}

#[test]
fn non_face_scheme_is_centred_not_rotated() {
    let dir = tempfile::tempdir().unwrap();
    let mesh_path = dir.path().join("tetra.ply");
    write_ply(&mesh_path, &tetra()).unwrap();
    let lm = write_file(dir.path(), "marks.json", br#"{"scheme": "fish", "vertex_ids": [1, 2]}"#);
    let t = load_template(&mesh_path, &lm, &TemplateOptions { scale: Some(2.0), ..Default::default() }).unwrap();
    assert!(!t.provenance.cropped);
    assert_eq!(t.provenance.scale_mm_per_unit, 2.0);
    // Centroid (0.25, 0.25, 0.25) moved to the origin, scaled by 2, axes unchanged.
    assert!(dist(t.mesh.positions[1], [1.5, -0.5, -0.5]) < 1e-6);
    assert_eq!(t.landmarks, vec![1, 2]);
    assert!(t.provenance.attribution.is_none());
}

#[test]
fn non_manifold_edge_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    // Three triangles share the edge 0-1.
    let text = ascii_ply(
        XYZ_RGB,
        &["0 0 0 1 2 3", "1 0 0 1 2 3", "0 1 0 1 2 3", "0 -1 0 1 2 3", "0 0 1 1 2 3"],
        &["3 0 1 2", "3 1 0 3", "3 0 1 4"],
    );
    let p = write_file(dir.path(), "fin.ply", text.as_bytes());
    let msg = expect_err_naming(read_mesh(&p, None, None), "fin.ply", "non-manifold");
    assert!(msg.contains("vertices 0 and 1"), "{msg}");
}

#[test]
fn truncated_binary_ply_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cut.ply");
    write_ply(&path, &tetra()).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    for keep in [bytes.len() - 5, bytes.len() - 40, 30] {
        std::fs::write(&path, &bytes[..keep]).unwrap();
        let msg = read_mesh(&path, None, None).expect_err("truncated file must be an error").to_string();
        assert!(msg.contains("cut.ply"), "{msg}");
    }
    // Garbage and missing files, too.
    let g = write_file(dir.path(), "garbage.ply", b"\x00\x01not a ply at all");
    expect_err_naming(read_mesh(&g, None, None), "garbage.ply", "PLY");
    let missing = dir.path().join("missing.ply");
    expect_err_naming(read_mesh(&missing, None, None), "missing.ply", "cannot read");
    let obj = write_file(dir.path(), "mesh.stl", b"solid");
    expect_err_naming(read_mesh(&obj, None, None), "mesh.stl", "unsupported");
}

// --- a tiny glTF written by the test (no data directory needed)

fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for chunk in bytes.chunks(3) {
        let b = [chunk[0], chunk.get(1).copied().unwrap_or(0), chunk.get(2).copied().unwrap_or(0)];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(A[((n >> (18 - 6 * k)) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// Two triangles forming a square, split at a UV seam along the diagonal
/// (6 vertices, 4 distinct positions), with a node translation of +10 in x.
fn write_seamed_gltf(dir: &Path) -> PathBuf {
    let pos: [[f32; 3]; 6] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
    // The texture is 2x1: left pixel red, right pixel blue. u < 0.5 samples red.
    let uv: [[f32; 2]; 6] = [[0.25, 0.5], [0.25, 0.5], [0.25, 0.5], [0.75, 0.5], [0.75, 0.5], [0.75, 0.5]];
    let mut buf = Vec::new();
    for p in &pos {
        for v in p {
            buf.extend_from_slice(&v.to_le_bytes());
        }
    }
    for t in &uv {
        for v in t {
            buf.extend_from_slice(&v.to_le_bytes());
        }
    }
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],
"nodes":[{{"mesh":0,"translation":[10,0,0]}}],
"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0,"TEXCOORD_0":1}},"mode":4}}]}}],
"buffers":[{{"byteLength":{len},"uri":"data:application/octet-stream;base64,{b64}"}}],
"bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":72}},{{"buffer":0,"byteOffset":72,"byteLength":48}}],
"accessors":[{{"bufferView":0,"componentType":5126,"count":6,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}},
{{"bufferView":1,"componentType":5126,"count":6,"type":"VEC2"}}]}}"#,
        len = buf.len(),
        b64 = base64(&buf)
    );
    write_file(dir, "square.gltf", json.as_bytes())
}

#[test]
fn gltf_seams_are_welded_and_texture_sampled() {
    let dir = tempfile::tempdir().unwrap();
    let gltf = write_seamed_gltf(dir.path());
    let tex = write_file(dir.path(), "tex.ppm", b"P6\n2 1\n255\n\xff\x00\x00\x00\x00\xff");
    let m = read_mesh(&gltf, Some(&tex), None).unwrap();
    assert_eq!(m.positions.len(), 4, "seam vertices welded");
    assert_eq!(m.triangles.len(), 2);
    // Ordered by position, translated by the node.
    assert_eq!(m.positions, vec![[10.0, 0.0, 0.0], [10.0, 1.0, 0.0], [11.0, 0.0, 0.0], [11.0, 1.0, 0.0]]);
    // (11,0,0) is only in the red half, (10,1,0) only in the blue half, the diagonal is averaged.
    assert_eq!(m.colors[2], [1.0, 0.0, 0.0]);
    assert_eq!(m.colors[1], [0.0, 0.0, 1.0]);
    assert_eq!(m.colors[0], [0.5, 0.0, 0.5]);
    // Without a texture (none embedded) it is an error naming the file, unless a default colour is given.
    expect_err_naming(read_mesh(&gltf, None, None), "square.gltf", "--texture");
    assert!(read_mesh(&gltf, None, Some([0.2, 0.2, 0.2])).is_ok());
}

#[test]
fn unreadable_texture_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let gltf = write_seamed_gltf(dir.path());
    let bad = write_file(dir.path(), "broken.png", b"\x89PNG\r\n\x1a\n garbage");
    expect_err_naming(read_mesh(&gltf, Some(&bad), None), "broken.png", "texture");
    let missing = dir.path().join("nowhere.jpg");
    expect_err_naming(read_mesh(&gltf, Some(&missing), None), "nowhere.jpg", "texture");
    // Malformed glTF JSON names the glTF file.
    let junk = write_file(dir.path(), "junk.glb", b"glTF\x02\x00\x00\x00garbage");
    expect_err_naming(read_mesh(&junk, None, None), "junk.glb", "glTF");
}
