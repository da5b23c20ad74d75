//! Statismo `.h5` import and export: round trips, units, landmarks, and malformed files refused
//! with an error naming the dataset (never a panic).

use gpmm_host::gp::kernel::Hyperparameters;
use gpmm_host::gp::model::{GpModel, ModelMetadata, ModelPart, PartBasis, MODEL_VERSION};
use gpmm_host::gp::statismo::{dense_values, export_bytes, import_bytes, ImportOptions, StatismoError};
use gpmm_host::mesh::template::Provenance;
use hdf5_pure::{AttrValue, FileBuilder};

/// A small face-sized model: a 6 x 6 grid 150 mm wide, factored shape and colour bases.
fn grid_model() -> GpModel {
    let side = 6;
    let n = side * side;
    let mean: Vec<[f32; 3]> =
        (0..n).map(|i| [(i % side) as f32 * 30.0 - 75.0, (i / side) as f32 * 30.0 - 75.0, ((i * 7) % 5) as f32]).collect();
    let mut triangles = Vec::new();
    for y in 0..side - 1 {
        for x in 0..side - 1 {
            let i = (y * side + x) as u32;
            let s = side as u32;
            triangles.push([i, i + 1, i + s + 1]);
            triangles.push([i, i + s + 1, i + s]);
        }
    }
    let field = |k: usize, i: usize| ((i as f32 * 0.37 + k as f32).sin()) * (3.0 - k as f32);
    let part = |mean: Vec<[f32; 3]>, dirs: Vec<[f32; 3]>, ev: Vec<f64>| ModelPart {
        mean,
        eigenvalues: ev,
        basis: PartBasis::Factored {
            directions: dirs.clone(),
            fields: (0..dirs.len()).flat_map(|k| (0..n).map(move |i| field(k, i))).collect(),
        },
    };
    let shape = part(mean, vec![[1.0, 0.0, 0.0], [0.0, 0.6, 0.8], [0.0, 0.0, 1.0]], vec![40.0, 12.5, 3.25]);
    let color =
        part((0..n).map(|i| [0.5, 0.4 + i as f32 * 0.001, 0.3]).collect(), vec![[0.577, 0.577, 0.577], [1.0, 0.0, 0.0]], vec![0.01, 0.002]);
    GpModel {
        shape,
        color,
        triangles,
        landmarks: vec![0, 5, 30, 35, 14],
        metadata: ModelMetadata {
            format: "gpmm-model".into(),
            version: MODEL_VERSION,
            kernel: "symmetric-full".into(),
            hyperparameters: Hyperparameters::default(),
            nystrom_points: 36,
            nystrom_seed: 7,
            shape_trace: 100.0,
            color_trace: 0.02,
            landmark_scheme: "test5".into(),
            template: Provenance { source: "grid".into(), scale_mm_per_unit: 1.0, ..Default::default() },
            units: "mm".into(),
            created_by: "test".into(),
            learning: None,
        },
    }
}

fn import(bytes: Vec<u8>) -> Result<GpModel, StatismoError> {
    import_bytes(bytes, "test.h5", &ImportOptions::default()).map(|(m, _)| m)
}

#[test]
fn export_then_import_is_exact_to_float32() {
    let m = grid_model();
    let (back, report) = import_bytes(export_bytes(&m).unwrap(), "rt.h5", &ImportOptions::default()).unwrap();
    assert_eq!(back.shape.mean, m.shape.mean, "means are written as float32 as they are");
    assert_eq!(back.color.mean, m.color.mean);
    assert_eq!(back.triangles, m.triangles);
    assert_eq!(back.landmarks, m.landmarks);
    assert_eq!(back.metadata, m.metadata, "gpmm metadata travels in /metadata/gpmm");
    assert_eq!(report.scale_mm_per_unit, 1.0);
    assert!(matches!(back.shape.basis, PartBasis::Dense { .. }), "import gives the dense layout");
    for (a, b) in [(&m.shape, &back.shape), (&m.color, &back.color)] {
        for (x, y) in a.eigenvalues.iter().zip(&b.eigenvalues) {
            assert_eq!(*y, f64::from(*x as f32), "variances are float32 in the file");
        }
        assert_eq!(dense_values(a), dense_values(b), "the scaled basis comes back bit for bit");
    }
    // A second round trip of the imported (dense) model changes nothing.
    let again = import(export_bytes(&back).unwrap()).unwrap();
    assert_eq!(again.shape.eigenvalues, back.shape.eigenvalues);
    assert_eq!(again.shape.mean, back.shape.mean);
    assert_eq!(dense_values(&again.shape), dense_values(&back.shape));
    assert_eq!(dense_values(&again.color), dense_values(&back.color));
}

#[test]
fn exported_datasets_have_the_statismo_shapes() {
    let m = grid_model();
    let f = hdf5_pure::File::from_bytes(export_bytes(&m).unwrap()).unwrap();
    let n = m.vertices() as u64;
    let shape_of = |p: &str| f.dataset(p).unwrap_or_else(|e| panic!("{p}: {e}")).shape().unwrap();
    assert_eq!(shape_of("shape/model/mean"), vec![3 * n]);
    assert_eq!(shape_of("shape/model/pcaBasis"), vec![3 * n, 3]);
    assert_eq!(shape_of("shape/model/pcaVariance"), vec![3]);
    assert_eq!(shape_of("color/model/pcaBasis"), vec![3 * n, 2]);
    assert_eq!(shape_of("shape/representer/points"), vec![3, n]);
    assert_eq!(shape_of("shape/representer/cells"), vec![3, m.triangles.len() as u64]);
    assert_eq!(f.dataset("shape/version/minorVersion").unwrap().read_i64().unwrap(), vec![9]);
    // Version 0.9 columns are unscaled: column c times sqrt(variance c) is gpmm's scaled component c.
    let b = f.dataset("shape/model/pcaBasis").unwrap().read_f64().unwrap();
    let dense = dense_values(&m.shape);
    for c in 0..3 {
        let s = m.shape.eigenvalues[c].sqrt();
        for r in 0..3 * n as usize {
            let want = f64::from(dense[c * 3 * n as usize + r]);
            assert!((b[r * 3 + c] * s - want).abs() <= 1e-5 * want.abs().max(1.0), "column {c} row {r}");
        }
    }
    let json = f.dataset("metadata/landmarks/json").unwrap().read_string().unwrap();
    assert!(json[0].contains("\"test5.4\""), "{}", json[0]);
}

/// Writes a statismo file the way other tools do (as h5py would), with knobs to break it.
struct Statismo {
    n: usize,
    k: usize,
    unit: f64,
    version: (i32, i32),
    mean_nan: bool,
    float_cells: bool,
    bad_cell: bool,
    basis_cols: Option<usize>,
    skip: &'static str,
    landmarks: Option<String>,
}

impl Default for Statismo {
    fn default() -> Self {
        Self {
            n: 9,
            k: 2,
            unit: 1.0,
            version: (0, 9),
            mean_nan: false,
            float_cells: false,
            bad_cell: false,
            basis_cols: None,
            skip: "",
            landmarks: None,
        }
    }
}

impl Statismo {
    fn bytes(&self) -> Vec<u8> {
        let (n, k) = (self.n, self.k);
        let mut b = FileBuilder::new();
        for part in ["shape", "color"] {
            let mut g = b.create_group(part);
            let mut model = g.create_group("model");
            let mut mean: Vec<f64> =
                (0..3 * n).map(|i| if part == "shape" { ((i / 3) % 3) as f64 * 80.0 * self.unit + (i % 3) as f64 } else { 0.5 }).collect();
            if self.mean_nan && part == "shape" {
                mean[4] = f64::NAN;
            }
            let name = |d: &str| format!("{part}/model/{d}");
            if self.skip != name("mean") {
                model.create_dataset("mean").with_f64_data(&mean);
            }
            let cols = self.basis_cols.unwrap_or(k);
            let basis: Vec<f32> = (0..3 * n * cols).map(|i| if i % (cols + 1) == 0 { 1.0 } else { 0.0 }).collect();
            if self.skip != name("pcaBasis") {
                model.create_dataset("pcaBasis").with_f32_data(&basis).with_shape(&[(3 * n) as u64, cols as u64]);
            }
            let var: Vec<f32> = (0..k).map(|c| if part == "shape" { 25.0 / (c + 1) as f32 } else { 0.01 }).collect();
            if self.skip != name("pcaVariance") {
                model.create_dataset("pcaVariance").with_f32_data(&var);
            }
            model.create_dataset("noiseVariance").with_f32_data(&[0.0]).with_shape(&[]);
            g.add_group(model.finish());
            let mut version = g.create_group("version");
            version.create_dataset("majorVersion").with_i32_data(&[self.version.0]).with_shape(&[]);
            version.create_dataset("minorVersion").with_i32_data(&[self.version.1]).with_shape(&[]);
            g.add_group(version.finish());
            let mut rep = g.create_group("representer");
            rep.set_attr("datasetType", AttrValue::AsciiString("POLYGON_MESH".into()));
            let m = n - 2;
            let mut cells: Vec<i32> =
                (0..m).map(|t| t as i32).chain((0..m).map(|t| t as i32 + 1)).chain((0..m).map(|t| t as i32 + 2)).collect();
            if self.bad_cell {
                cells[3] = n as i32 + 5;
            }
            if self.float_cells {
                let f: Vec<f32> = cells.iter().map(|&c| c as f32).collect();
                rep.create_dataset("cells").with_f32_data(&f).with_shape(&[3, m as u64]);
            } else if self.skip != "shape/representer/cells" {
                rep.create_dataset("cells").with_i32_data(&cells).with_shape(&[3, m as u64]);
            }
            g.add_group(rep.finish());
            b.add_group(g.finish());
        }
        if let Some(json) = &self.landmarks {
            let mut meta = b.create_group("metadata");
            let mut lm = meta.create_group("landmarks");
            lm.create_dataset("json").with_vlen_strings(&[json.as_str()]);
            meta.add_group(lm.finish());
            b.add_group(meta.finish());
        }
        b.finish().unwrap()
    }
}

fn refused(s: Statismo, dataset: &str, words: &str) {
    let e = import(s.bytes()).err().unwrap_or_else(|| panic!("accepted a file with a bad {dataset}"));
    let text = e.to_string();
    assert!(text.contains(dataset) && text.contains(words), "message '{text}' should name {dataset} and say '{words}'");
}

#[test]
fn a_plain_statismo_file_imports_without_landmarks() {
    let (m, report) = import_bytes(Statismo::default().bytes(), "plain.h5", &ImportOptions::default()).unwrap();
    assert_eq!(m.vertices(), 9);
    assert_eq!(m.triangles.len(), 7);
    assert_eq!(m.shape.rank(), 2);
    assert!(m.landmarks.is_empty());
    assert_eq!(m.metadata.landmark_scheme, "none");
    assert!(report.notes.iter().any(|n| n.contains("no landmarks")), "{:?}", report.notes);
    assert_eq!(m.metadata.kernel, "pca");
    // Version 0.9: the basis is unscaled, so the gpmm basis is scaled by sqrt(variance) = 5.
    assert_eq!(dense_values(&m.shape)[0], 5.0);
    // Given landmarks are taken as they are.
    let opts = ImportOptions { landmarks: Some(("ibug68".into(), vec![1, 2, 3])), ..Default::default() };
    let (m, _) = import_bytes(Statismo::default().bytes(), "plain.h5", &opts).unwrap();
    assert_eq!(m.landmarks, vec![1, 2, 3]);
}

#[test]
fn units_are_detected_and_version_08_bases_are_scaled() {
    let (m, report) = import_bytes(Statismo { unit: 1000.0, ..Default::default() }.bytes(), "um.h5", &ImportOptions::default()).unwrap();
    assert_eq!(report.scale_mm_per_unit, 1e-3);
    assert!(report.units.contains("micrometres"), "{}", report.units);
    assert!((m.shape.mean[1][0] - 80.0).abs() < 1e-3, "{:?}", m.shape.mean[1]);
    assert!((m.shape.eigenvalues[0] - 25.0e-6).abs() < 1e-9);
    let m = import(Statismo { version: (0, 8), ..Default::default() }.bytes()).unwrap();
    assert_eq!(dense_values(&m.shape)[0], 1.0, "0.8 bases are stored scaled");
    let e = import(Statismo { unit: 1e-6, ..Default::default() }.bytes()).err().unwrap();
    assert!(e.to_string().contains("--scale"), "{e}");
    let opts = ImportOptions { scale: Some(2.0), ..Default::default() };
    let (m, _) = import_bytes(Statismo { unit: 1e-6, ..Default::default() }.bytes(), "s.h5", &opts).unwrap();
    assert_eq!(m.shape.mean[0][1], 2.0);
}

#[test]
fn scalismo_landmarks_map_to_vertices_or_are_reported_unusable() {
    let json = r#"[{"id":"ibug68.1","coordinates":[80.0,81.0,82.1]},{"id":"ibug68.0","coordinates":[0.1,1.0,2.0]}]"#;
    let m = import(Statismo { landmarks: Some(json.into()), ..Default::default() }.bytes()).unwrap();
    assert_eq!(m.landmarks, vec![0, 1]);
    assert_eq!(m.metadata.landmark_scheme, "ibug68");
    let json = r#"[{"id":"center.nose.tip","coordinates":[0,0,0]}]"#;
    let (m, report) =
        import_bytes(Statismo { landmarks: Some(json.into()), ..Default::default() }.bytes(), "x.h5", &ImportOptions::default()).unwrap();
    assert!(m.landmarks.is_empty());
    assert!(report.notes[0].contains("center.nose.tip"), "{:?}", report.notes);
    refused(Statismo { landmarks: Some("{not json".into()), ..Default::default() }, "/metadata/landmarks/json", "JSON");
}

#[test]
fn malformed_files_name_the_dataset() {
    refused(Statismo { skip: "shape/model/pcaBasis", ..Default::default() }, "/shape/model/pcaBasis", "missing");
    refused(Statismo { skip: "color/model/mean", ..Default::default() }, "/color/model/mean", "missing");
    refused(Statismo { skip: "shape/representer/cells", ..Default::default() }, "/shape/representer/cells", "missing");
    refused(Statismo { basis_cols: Some(3), ..Default::default() }, "/shape/model/pcaBasis", "expected [27, 2]");
    refused(Statismo { mean_nan: true, ..Default::default() }, "/shape/model/mean", "non-finite");
    refused(Statismo { float_cells: true, ..Default::default() }, "/shape/representer/cells", "expected integers");
    refused(Statismo { bad_cell: true, ..Default::default() }, "/shape/representer/cells", "out of range");
    let e = import(b"definitely not hdf5".to_vec()).err().unwrap();
    assert!(e.to_string().contains("not an HDF5 file"), "{e}");
    let mut truncated = Statismo::default().bytes();
    truncated.truncate(truncated.len() / 2);
    assert!(import(truncated).is_err(), "a truncated file is refused");
}
