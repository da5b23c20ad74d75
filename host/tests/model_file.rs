//! Model file: save/load round trip, Python-readable layout, corrupted and foreign files.

use gpmm_host::gp::kernel::ModelKernel;
use gpmm_host::gp::lowrank::{NystromOptions, RankSpec};
use gpmm_host::gp::model::{build_model, BuildOptions, GpModel, MODEL_VERSION};
use gpmm_host::gp::model_io::{from_bytes, to_bytes, ModelIoError};
use gpmm_host::mesh::template::{Mesh, Provenance, Template};

/// A small closed mesh (octahedron subdivided) with colours: no data files needed.
fn small_template() -> Template {
    let mut positions = vec![[60.0, 0.0, 0.0], [-60.0, 0.0, 0.0], [0.0, 80.0, 0.0], [0.0, -80.0, 0.0], [0.0, 0.0, 50.0], [0.0, 0.0, -50.0]];
    let mut triangles: Vec<[u32; 3]> = vec![[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]];
    for _ in 0..3 {
        let mut next = Vec::new();
        let mut mid = std::collections::HashMap::new();
        let mut midpoint = |a: u32, b: u32, pos: &mut Vec<[f64; 3]>| -> u32 {
            *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                let (p, q) = (pos[a as usize], pos[b as usize]);
                pos.push([(p[0] + q[0]) / 2.0, (p[1] + q[1]) / 2.0, (p[2] + q[2]) / 2.0]);
                (pos.len() - 1) as u32
            })
        };
        for t in &triangles {
            let ab = midpoint(t[0], t[1], &mut positions);
            let bc = midpoint(t[1], t[2], &mut positions);
            let ca = midpoint(t[2], t[0], &mut positions);
            next.extend([[t[0], ab, ca], [ab, t[1], bc], [ca, bc, t[2]], [ab, bc, ca]]);
        }
        triangles = next;
    }
    let colors = positions.iter().map(|p| [0.5 + p[0] / 200.0, 0.4 + p[1] / 300.0, 0.3]).collect();
    Template {
        mesh: Mesh { positions, colors, triangles },
        landmarks: vec![0, 1, 2, 3],
        scheme: "points".into(),
        provenance: Provenance { source: "octahedron".into(), scale_mm_per_unit: 1.0, ..Default::default() },
    }
}

fn small_model() -> GpModel {
    let opts = BuildOptions {
        kernel: ModelKernel::SymmetricFull,
        hyperparameters: Default::default(),
        rank_shape: RankSpec::Count(10),
        rank_color: RankSpec::Count(6),
        nystrom: NystromOptions { points: 100, ..Default::default() },
    };
    build_model(&small_template(), &opts, |_, _, _| {})
}

#[test]
fn save_load_round_trip_is_exact() {
    let model = small_model();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.gpmm");
    gpmm_host::gp::model_io::save(&model, &path).unwrap();
    let back = gpmm_host::gp::model_io::load(&path).unwrap();
    assert_eq!(back, model);
    assert_eq!(back.shape.rank(), 10);
    assert_eq!(back.color.rank(), 6);
}

#[test]
fn the_file_is_plain_safetensors_with_documented_tensors() {
    let bytes = to_bytes(&small_model()).unwrap();
    let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    let mut names: Vec<String> = st.names().into_iter().map(String::from).collect();
    names.sort();
    let want = [
        "color.directions",
        "color.eigenvalues",
        "color.fields",
        "color.mean",
        "landmarks",
        "shape.directions",
        "shape.eigenvalues",
        "shape.fields",
        "shape.mean",
        "triangles",
    ];
    assert_eq!(names, want);
    let n = small_template().mesh.positions.len();
    assert_eq!(st.tensor("shape.fields").unwrap().shape(), &[10, n]);
    assert_eq!(st.tensor("triangles").unwrap().shape()[1], 3);
}

#[test]
fn instance_is_mean_plus_scaled_components() {
    let model = small_model();
    let mut coeffs = vec![0.0f32; 10];
    coeffs[3] = 1.5;
    let inst = model.shape.instance(&coeffs).unwrap();
    let n = model.vertices();
    if let gpmm_host::gp::model::PartBasis::Factored { directions, fields } = &model.shape.basis {
        for i in [0, n / 2, n - 1] {
            for a in 0..3 {
                let want = model.shape.mean[i][a] + 1.5 * fields[3 * n + i] * directions[3][a];
                assert!((inst[i][a] - want).abs() < 1e-4);
            }
        }
        // Scaled fields have squared norm = eigenvalue.
        let norm2: f64 = fields[..n].iter().map(|f| f64::from(*f).powi(2)).sum();
        assert!((norm2 - model.shape.eigenvalues[0]).abs() < 1e-3 * model.shape.eigenvalues[0]);
    } else {
        panic!("kernel models are factored");
    }
}

#[test]
fn corrupted_truncated_and_foreign_files_are_errors() {
    let model = small_model();
    let bytes = to_bytes(&model).unwrap();
    for cut in [0, 7, 100, bytes.len() / 2, bytes.len() - 1] {
        assert!(from_bytes(&bytes[..cut], "cut.gpmm").is_err(), "truncated at {cut}");
    }
    // Another version.
    let mut other = model.clone();
    other.metadata.version = MODEL_VERSION + 1;
    let err = from_bytes(&to_bytes(&other).unwrap(), "new.gpmm").unwrap_err();
    assert!(matches!(err, ModelIoError::Version { .. }), "{err}");
    assert!(err.to_string().contains("new.gpmm") && err.to_string().contains("version"));
    // Out-of-range triangle index and NaN values.
    let mut bad = model.clone();
    bad.triangles[0][1] = 1_000_000;
    assert!(from_bytes(&to_bytes(&bad).unwrap(), "bad.gpmm").unwrap_err().to_string().contains("triangle index"));
    let mut bad = model.clone();
    bad.shape.mean[3][1] = f32::NAN;
    assert!(from_bytes(&to_bytes(&bad).unwrap(), "nan.gpmm").unwrap_err().to_string().contains("non-finite"));
    // Random byte flips never panic.
    let mut state = 0x12345678u64;
    for _ in 0..300 {
        let mut b = bytes.clone();
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        let i = (state % b.len() as u64) as usize;
        b[i] ^= 1 << (state % 8);
        let _ = from_bytes(&b, "flip.gpmm");
    }
}
