//! Statismo / scalismo-faces HDF5 model files (`.h5`, the Basel Face Model's format) in and out.
//!
//! Layout per model part (`shape`, `color`; an `expression` part is read past): `model/mean`
//! (`3N`, `x0 y0 z0 x1 …`), `model/pcaBasis` (`3N × K`, orthonormal columns; version 0.8 files
//! store them scaled by `sqrt(variance)`), `model/pcaVariance` (`K`), `model/noiseVariance`,
//! `version/{majorVersion,minorVersion}`, `representer/points` (`3 × N`) and `representer/cells`
//! (`3 × M`, integer). Landmarks are scalismo landmarks (`id`, `coordinates`) under
//! `metadata/landmarks/json`; gpmm also writes its own metadata as JSON under `metadata/gpmm`.
//!
//! Import gives a dense-layout [`GpModel`] in millimetres (units detected from the mean's width
//! or given), export writes the dense statismo basis (version 0.9, unscaled). The HDF5 file is
//! read and written by `hdf5-pure` (pure Rust, no system library). Every refusal names the file
//! and the dataset; nothing panics on a malformed file.

use crate::gp::model::{GpModel, ModelMetadata, ModelPart, PartBasis};
use crate::mesh::template::Provenance;
use hdf5_pure::{AttrValue, DType, File, FileBuilder, GroupBuilder};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Why a statismo file could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum StatismoError {
    /// The file could not be read, written or parsed as HDF5.
    #[error("{path}: {message}")]
    File {
        /// File name.
        path: String,
        /// What went wrong.
        message: String,
    },
    /// The model could not be written as a statismo file.
    #[error("{path}: {error}")]
    Export {
        /// File name.
        path: String,
        /// What the writer refused.
        error: ExportError,
    },
    /// A dataset is missing or malformed.
    #[error("{path}: dataset '{dataset}': {message}")]
    Dataset {
        /// File name.
        path: String,
        /// The dataset's path in the file.
        dataset: String,
        /// What is wrong.
        message: String,
    },
    /// The model as a whole is inconsistent or cannot be converted.
    #[error("{path}: {message}")]
    Invalid {
        /// File name.
        path: String,
        /// What is wrong.
        message: String,
    },
}

/// How to import a statismo file.
#[derive(Debug, Clone, Default)]
pub struct ImportOptions {
    /// Millimetres per file unit (default: detected from the mean shape's width).
    pub scale: Option<f64>,
    /// Landmarks to use instead of the file's: scheme and vertex ids.
    pub landmarks: Option<(String, Vec<u32>)>,
}

/// What an import found and did (printed by `gpmm import-h5`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ImportReport {
    /// Statismo version of the shape part (`major.minor`).
    pub version: String,
    /// Vertices, triangles, shape and colour ranks.
    pub vertices: usize,
    /// Triangles.
    pub triangles: usize,
    /// Shape components.
    pub rank_shape: usize,
    /// Colour components.
    pub rank_color: usize,
    /// Millimetres per file unit applied to the shape.
    pub scale_mm_per_unit: f64,
    /// How the scale was chosen.
    pub units: String,
    /// Factor applied to the colours (1, or 1/255 for a 0..255 colour model).
    pub color_scale: f64,
    /// Number of landmarks the model has (0: it cannot be fitted to photos).
    pub landmarks: usize,
    /// Where the landmarks came from.
    pub landmark_source: String,
    /// Anything else worth knowing (parts ignored, noise variance, …).
    pub notes: Vec<String>,
}

/// A scalismo landmark as stored in `metadata/landmarks/json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct ScalismoLandmark {
    id: String,
    coordinates: [f64; 3],
}

/// What gpmm stores under `metadata/gpmm`: its metadata and the exact landmark vertex ids.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct GpmmExtra {
    metadata: ModelMetadata,
    landmark_vertex_ids: Vec<u32>,
}

/// The landmark id of landmark `i` of `scheme` in exported files (`ibug68.0` …).
pub fn landmark_id(scheme: &str, i: usize) -> String {
    format!("{scheme}.{i}")
}

/// Dataset reader over one open file; errors name the file and the dataset.
struct Reader<'a> {
    file: File,
    path: &'a str,
}

/// A read numeric dataset: its shape and values as f64.
struct Numbers {
    shape: Vec<usize>,
    values: Vec<f64>,
}

impl Reader<'_> {
    fn err(&self, dataset: &str, message: impl Into<String>) -> StatismoError {
        StatismoError::Dataset { path: self.path.to_string(), dataset: format!("/{dataset}"), message: message.into() }
    }

    fn exists(&self, dataset: &str) -> bool {
        self.file.dataset(dataset).is_ok()
    }

    fn group_exists(&self, group: &str) -> bool {
        self.file.group(group).is_ok()
    }

    fn dataset(&self, name: &str) -> Result<hdf5_pure::Dataset, StatismoError> {
        self.file.dataset(name).map_err(|_| self.err(name, "missing"))
    }

    fn shape(&self, name: &str, d: &hdf5_pure::Dataset) -> Result<Vec<usize>, StatismoError> {
        let s = d.shape().map_err(|e| self.err(name, format!("unreadable shape: {e}")))?;
        s.iter().map(|&v| usize::try_from(v).map_err(|_| self.err(name, "dimension too large"))).collect()
    }

    /// A floating-point dataset (f32 or f64), every value finite.
    fn floats(&self, name: &str) -> Result<Numbers, StatismoError> {
        let d = self.dataset(name)?;
        let dt = d.dtype().map_err(|e| self.err(name, format!("unreadable type: {e}")))?;
        if !matches!(dt, DType::F32 | DType::F64) {
            return Err(self.err(name, format!("has type {dt}, expected floating point (f32 or f64)")));
        }
        let shape = self.shape(name, &d)?;
        let values = d.read_f64().map_err(|e| self.err(name, format!("unreadable: {e}")))?;
        if values.len() != shape.iter().product::<usize>() {
            return Err(self.err(name, format!("holds {} values for shape {shape:?}", values.len())));
        }
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(self.err(name, format!("has a non-finite value (NaN or infinite) at element {i}")));
        }
        Ok(Numbers { shape, values })
    }

    /// An integer dataset.
    fn integers(&self, name: &str) -> Result<(Vec<usize>, Vec<i64>), StatismoError> {
        let d = self.dataset(name)?;
        let dt = d.dtype().map_err(|e| self.err(name, format!("unreadable type: {e}")))?;
        if !matches!(dt, DType::I8 | DType::I16 | DType::I32 | DType::I64 | DType::U8 | DType::U16 | DType::U32 | DType::U64) {
            return Err(self.err(name, format!("has type {dt}, expected integers")));
        }
        let shape = self.shape(name, &d)?;
        let values = if dt == DType::U64 {
            let v = d.read_u64().map_err(|e| self.err(name, format!("unreadable: {e}")))?;
            v.into_iter().map(|x| i64::try_from(x).unwrap_or(i64::MAX)).collect()
        } else {
            d.read_i64().map_err(|e| self.err(name, format!("unreadable: {e}")))?
        };
        if values.len() != shape.iter().product::<usize>() {
            return Err(self.err(name, format!("holds {} values for shape {shape:?}", values.len())));
        }
        Ok((shape, values))
    }

    /// A scalar (shape `[]` or `[1]`) read as f64 from any numeric type.
    fn scalar(&self, name: &str) -> Result<f64, StatismoError> {
        let d = self.dataset(name)?;
        let shape = self.shape(name, &d)?;
        if shape.iter().product::<usize>() != 1 {
            return Err(self.err(name, format!("has shape {shape:?}, expected a scalar")));
        }
        let v = d.read_f64().map_err(|e| self.err(name, format!("unreadable: {e}")))?;
        v.first().copied().filter(|x| x.is_finite()).ok_or_else(|| self.err(name, "is not a finite number"))
    }

    /// A string dataset's first value.
    fn string(&self, name: &str) -> Result<String, StatismoError> {
        let d = self.dataset(name)?;
        let v = d.read_string().map_err(|e| self.err(name, format!("is not a string: {e}")))?;
        v.into_iter().next().ok_or_else(|| self.err(name, "is empty"))
    }
}

/// One part as read from the file (file units), basis rows `3N`, columns `K`.
struct RawPart {
    mean: Vec<f64>,
    basis: Vec<f64>,
    variance: Vec<f64>,
    rank: usize,
    version: (i64, i64),
}

fn read_part(r: &Reader<'_>, part: &str, n: Option<usize>) -> Result<RawPart, StatismoError> {
    let mean_name = format!("{part}/model/mean");
    let mean = r.floats(&mean_name)?;
    if mean.shape.len() != 1 || mean.values.len() % 3 != 0 || mean.values.is_empty() {
        return Err(r.err(&mean_name, format!("has shape {:?}, expected [3N] (x0 y0 z0 x1 …)", mean.shape)));
    }
    let len = mean.values.len();
    if let Some(n) = n {
        if len != 3 * n {
            return Err(r.err(&mean_name, format!("has {} values, expected {} (3 per shape vertex)", len, 3 * n)));
        }
    }
    let var_name = format!("{part}/model/pcaVariance");
    let variance = r.floats(&var_name)?;
    if variance.shape.len() != 1 || variance.values.is_empty() {
        return Err(r.err(&var_name, format!("has shape {:?}, expected [K] with K ≥ 1", variance.shape)));
    }
    if let Some(i) = variance.values.iter().position(|v| *v < 0.0) {
        return Err(r.err(&var_name, format!("has a negative variance at element {i}")));
    }
    let k = variance.values.len();
    let basis_name = format!("{part}/model/pcaBasis");
    let basis = r.floats(&basis_name)?;
    if basis.shape != [len, k] {
        return Err(r.err(&basis_name, format!("has shape {:?}, expected [{len}, {k}] (3N x K, K from pcaVariance)", basis.shape)));
    }
    let noise_name = format!("{part}/model/noiseVariance");
    if r.exists(&noise_name) {
        let noise = r.scalar(&noise_name)?;
        if noise < 0.0 {
            return Err(r.err(&noise_name, "is negative"));
        }
    }
    let version = if r.group_exists(&format!("{part}/version")) {
        let major = r.scalar(&format!("{part}/version/majorVersion"))?;
        let minor = r.scalar(&format!("{part}/version/minorVersion"))?;
        (major as i64, minor as i64)
    } else {
        (0, 9)
    };
    Ok(RawPart { mean: mean.values, basis: basis.values, variance: variance.values, rank: k, version })
}

/// The dense gpmm part of a raw part: mean and basis scaled by `scale`, variance by `scale²`.
fn dense_part(raw: &RawPart, scale: f64) -> ModelPart {
    let n = raw.mean.len() / 3;
    let k = raw.rank;
    let scaled_basis = raw.version < (0, 9);
    let mut values = vec![0.0f32; k * n * 3];
    for (c, &var) in raw.variance.iter().enumerate() {
        let factor = if scaled_basis { scale } else { var.sqrt() * scale };
        for row in 0..3 * n {
            values[c * 3 * n + row] = (raw.basis[row * k + c] * factor) as f32;
        }
    }
    ModelPart {
        mean: raw.mean.chunks_exact(3).map(|c| [(c[0] * scale) as f32, (c[1] * scale) as f32, (c[2] * scale) as f32]).collect(),
        eigenvalues: raw.variance.iter().map(|v| v * scale * scale).collect(),
        basis: PartBasis::Dense { values },
    }
}

/// Millimetres per unit from a mean shape's width (x extent): a face is 100–300 mm wide.
fn detect_scale(mean: &[f64]) -> Option<(f64, &'static str)> {
    let (lo, hi) = mean.chunks_exact(3).fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), p| (l.min(p[0]), h.max(p[0])));
    let width = hi - lo;
    [(1.0, "millimetres"), (1e-3, "micrometres"), (10.0, "centimetres"), (1000.0, "metres")]
        .into_iter()
        .find(|(s, _)| (50.0..=500.0).contains(&(width * s)))
}

/// Reads the shape part's triangles (`representer/cells`, `3 × M`).
fn read_cells(r: &Reader<'_>, n: usize) -> Result<Vec<[u32; 3]>, StatismoError> {
    let name = "shape/representer/cells";
    let (shape, values) = r.integers(name)?;
    if shape.len() != 2 || shape[0] != 3 {
        return Err(r.err(name, format!("has shape {shape:?}, expected [3, M]")));
    }
    let m = shape[1];
    if let Some(bad) = values.iter().find(|&&v| v < 0 || v as u64 >= n as u64) {
        return Err(r.err(name, format!("vertex index {bad} out of range (the mean has {n} vertices)")));
    }
    Ok((0..m).map(|t| [values[t] as u32, values[m + t] as u32, values[2 * m + t] as u32]).collect())
}

/// Checks `representer/points` (`3 × N`) when present.
fn check_points(r: &Reader<'_>, part: &str, n: usize) -> Result<(), StatismoError> {
    let name = format!("{part}/representer/points");
    if r.exists(&name) {
        let p = r.floats(&name)?;
        if p.shape != [3, n] {
            return Err(r.err(&name, format!("has shape {:?}, expected [3, {n}]", p.shape)));
        }
    }
    Ok(())
}

/// Why a statismo file's landmarks cannot be used (the import goes on without landmarks).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
enum UnusableLandmarks {
    /// `metadata/landmarks/json` is absent.
    #[error("the file has no landmarks")]
    Missing,
    /// The ids are not `<scheme>.<i>`.
    #[error("the file's {count} landmarks (e.g. '{example}') are not numbered vertex landmarks of a scheme such as ibug68")]
    NotNumbered {
        /// Landmarks in the file.
        count: usize,
        /// The first id.
        example: String,
    },
    /// The ids are not `<scheme>.0` to `<scheme>.<L-1>`, each once.
    #[error("the file's landmark ids are not {scheme}.0 to {scheme}.{last} once each")]
    NotOnceEach {
        /// The first id's scheme.
        scheme: String,
        /// `L - 1`.
        last: usize,
    },
}

/// Landmarks from `metadata/landmarks/json` when they are `<scheme>.<i>` for `i = 0..L`: each
/// mapped to the nearest mean vertex. `Ok(Err(why))` when there are none usable.
fn read_landmarks(
    r: &Reader<'_>,
    mean_mm: &[[f32; 3]],
    scale: f64,
) -> Result<Result<(String, Vec<u32>), UnusableLandmarks>, StatismoError> {
    let name = "metadata/landmarks/json";
    if !r.exists(name) {
        return Ok(Err(UnusableLandmarks::Missing));
    }
    let text = r.string(name)?;
    let list: Vec<ScalismoLandmark> =
        serde_json::from_str(&text).map_err(|e| r.err(name, format!("is not a JSON list of scalismo landmarks: {e}")))?;
    let parsed: Option<Vec<(String, usize)>> =
        list.iter().map(|l| l.id.rsplit_once('.').and_then(|(s, i)| i.parse::<usize>().ok().map(|i| (s.to_string(), i)))).collect();
    let scheme = parsed.as_ref().and_then(|p| p.first()).map(|(s, _)| s.clone());
    let (Some(parsed), Some(scheme)) = (parsed, scheme) else {
        let example = list.first().map(|l| l.id.clone()).unwrap_or_default();
        return Ok(Err(UnusableLandmarks::NotNumbered { count: list.len(), example }));
    };
    let mut ids = vec![u32::MAX; list.len()];
    for ((s, i), l) in parsed.iter().zip(&list) {
        if *s != scheme || *i >= ids.len() || ids[*i] != u32::MAX {
            return Ok(Err(UnusableLandmarks::NotOnceEach { scheme, last: list.len() - 1 }));
        }
        let q = l.coordinates.map(|c| c * scale);
        let nearest = mean_mm
            .iter()
            .enumerate()
            .map(|(v, p)| (v, (0..3).map(|d| (f64::from(p[d]) - q[d]).powi(2)).sum::<f64>()))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map_or(0, |(v, _)| v);
        ids[*i] = nearest as u32;
    }
    Ok(Ok((scheme, ids)))
}

/// Reads a statismo file and converts it to a dense-layout gpmm model.
pub fn import(path: &Path, opts: &ImportOptions) -> Result<(GpModel, ImportReport), StatismoError> {
    let name = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|e| StatismoError::File { path: name.clone(), message: e.to_string() })?;
    import_bytes(bytes, &name, opts)
}

/// [`import`] from the file's bytes; `name` names the source in errors.
pub fn import_bytes(bytes: Vec<u8>, name: &str, opts: &ImportOptions) -> Result<(GpModel, ImportReport), StatismoError> {
    use sha2::{Digest, Sha256};
    let sha = Sha256::digest(&bytes).iter().map(|b| format!("{b:02x}")).collect::<String>();
    if !hdf5_pure::is_hdf5_bytes(&bytes) {
        return Err(StatismoError::File { path: name.into(), message: "not an HDF5 file".into() });
    }
    let file = File::from_bytes(bytes).map_err(|e| StatismoError::File { path: name.into(), message: format!("unreadable HDF5: {e}") })?;
    let r = Reader { file, path: name };
    let invalid = |message: String| StatismoError::Invalid { path: name.to_string(), message };
    let shape = read_part(&r, "shape", None)?;
    let n = shape.mean.len() / 3;
    let color = read_part(&r, "color", Some(n))?;
    check_points(&r, "shape", n)?;
    check_points(&r, "color", n)?;
    let triangles = read_cells(&r, n)?;
    if triangles.is_empty() {
        return Err(r.err("shape/representer/cells", "has no triangles"));
    }
    let mut notes = Vec::new();
    if r.group_exists("expression") {
        notes.push("the expression part was not imported (gpmm models have shape and colour only)".into());
    }
    let (scale, units) = match opts.scale {
        Some(s) if s.is_finite() && s > 0.0 => (s, "given".to_string()),
        Some(s) => return Err(invalid(format!("scale {s} must be a positive number of millimetres per unit"))),
        None => match detect_scale(&shape.mean) {
            Some((s, u)) => (s, format!("detected: {u} (the mean shape's width)")),
            None => {
                return Err(invalid(
                    "cannot tell the units from the mean shape's width (not 50-500 mm in mm, um, cm or m): give the scale (--scale MM_PER_UNIT)"
                        .into(),
                ))
            }
        },
    };
    let max_color = color.mean.iter().fold(0.0f64, |m, v| m.max(*v));
    let color_scale = if max_color > 1.5 {
        notes.push(format!("colours read as 0..255 (largest mean value {max_color:.1}) and divided by 255"));
        1.0 / 255.0
    } else {
        1.0
    };
    let shape_part = dense_part(&shape, scale);
    let color_part = dense_part(&color, color_scale);
    let extra: Option<GpmmExtra> = if r.exists("metadata/gpmm") {
        let text = r.string("metadata/gpmm")?;
        Some(serde_json::from_str(&text).map_err(|e| r.err("metadata/gpmm", format!("is not gpmm metadata: {e}")))?)
    } else {
        None
    };
    let (scheme, landmarks, landmark_source) = match (&opts.landmarks, &extra) {
        (Some((scheme, ids)), _) => (scheme.clone(), ids.clone(), "given landmark file".to_string()),
        (None, Some(x)) => (x.metadata.landmark_scheme.clone(), x.landmark_vertex_ids.clone(), "metadata/gpmm".to_string()),
        (None, None) => match read_landmarks(&r, &shape_part.mean, scale)? {
            Ok((scheme, ids)) => (scheme, ids, "metadata/landmarks/json (nearest mean vertex)".to_string()),
            Err(why) => {
                notes.push(format!(
                    "{why}: the model has no landmarks and cannot be fitted to photos until given some (--landmarks FILE.json)"
                ));
                ("none".to_string(), Vec::new(), "none".to_string())
            }
        },
    };
    if let Some(bad) = landmarks.iter().find(|&&i| i as usize >= n) {
        return Err(invalid(format!("landmark vertex id {bad} out of range (the model has {n} vertices)")));
    }
    let metadata = match extra {
        Some(x) => ModelMetadata { landmark_scheme: scheme.clone(), ..x.metadata },
        None => ModelMetadata::pca(
            &shape_part,
            &color_part,
            scheme.clone(),
            Provenance {
                source: name.to_string(),
                source_sha256: sha,
                texture: None,
                attribution: None,
                scale_mm_per_unit: scale,
                cropped: false,
                source_vertices: n,
            },
            concat!("gpmm ", env!("CARGO_PKG_VERSION"), " import-h5").into(),
        ),
    };
    let report = ImportReport {
        version: format!("{}.{}", shape.version.0, shape.version.1),
        vertices: n,
        triangles: triangles.len(),
        rank_shape: shape.rank,
        rank_color: color.rank,
        scale_mm_per_unit: scale,
        units,
        color_scale,
        landmarks: landmarks.len(),
        landmark_source,
        notes,
    };
    let model = GpModel { shape: shape_part, color: color_part, triangles, landmarks, metadata };
    Ok((model, report))
}

/// The dense scaled basis of a part as `K × N × 3` values.
pub fn dense_values(part: &ModelPart) -> Vec<f32> {
    match &part.basis {
        PartBasis::Dense { values } => values.clone(),
        PartBasis::Factored { directions, fields } => {
            let n = part.mean.len();
            let mut out = Vec::with_capacity(directions.len() * n * 3);
            for (k, d) in directions.iter().enumerate() {
                for f in &fields[k * n..(k + 1) * n] {
                    out.extend(d.iter().map(|c| f * c));
                }
            }
            out
        }
    }
}

fn write_part(b: &mut FileBuilder, name: &str, part: &ModelPart, points: &[f32], cells: &[i32], m: usize, dataset_type: &str) {
    let n = part.mean.len();
    let k = part.rank();
    let values = dense_values(part);
    // Float64 columns divided by the very factor an importer computes from the stored (float32)
    // variance: multiplied back and rounded to float32, every value is the model's own (the
    // error of the two float64 operations is far below half a float32 ulp). HDF5 readers that
    // ask for float32 (statismo, scalismo) get the values converted by the library.
    let mut basis = vec![0.0f64; 3 * n * k];
    for (c, &ev) in part.eigenvalues.iter().enumerate() {
        let s = f64::from(ev as f32).sqrt();
        for row in 0..3 * n {
            let v = f64::from(values[c * 3 * n + row]);
            basis[row * k + c] = if s > 0.0 { v / s } else { 0.0 };
        }
    }
    let mut g: GroupBuilder = b.create_group(name);
    let mut model = g.create_group("model");
    let mean: Vec<f32> = part.mean.iter().flatten().copied().collect();
    model.create_dataset("mean").with_f32_data(&mean);
    model.create_dataset("pcaBasis").with_f64_data(&basis).with_shape(&[3 * n as u64, k as u64]);
    let var: Vec<f32> = part.eigenvalues.iter().map(|&v| v as f32).collect();
    model.create_dataset("pcaVariance").with_f32_data(&var);
    model.create_dataset("noiseVariance").with_f32_data(&[0.0]).with_shape(&[]);
    g.add_group(model.finish());
    let mut version = g.create_group("version");
    version.create_dataset("majorVersion").with_i32_data(&[0]).with_shape(&[]);
    version.create_dataset("minorVersion").with_i32_data(&[9]).with_shape(&[]);
    g.add_group(version.finish());
    let mut rep = g.create_group("representer");
    rep.set_attr("name", AttrValue::AsciiString("gpmm".into()));
    rep.set_attr("datasetType", AttrValue::AsciiString(dataset_type.into()));
    rep.set_attr("version", AttrValue::AsciiString("1.0".into()));
    rep.create_dataset("points").with_f32_data(points).with_shape(&[3, n as u64]);
    rep.create_dataset("cells").with_i32_data(cells).with_shape(&[3, m as u64]);
    g.add_group(rep.finish());
    b.add_group(g.finish());
}

/// Why a model could not be written as a statismo file.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// More vertices than statismo's int32 cells can index.
    #[error("too many vertices for int32 cells")]
    TooManyVertices,
    /// The landmarks or gpmm's metadata could not be written as JSON.
    #[error("{0}")]
    Json(serde_json::Error),
    /// The HDF5 writer refused the file.
    #[error("{0}")]
    Hdf5(hdf5_pure::Error),
}

/// The statismo file of a model as bytes (version 0.9: unscaled orthonormal bases).
pub fn export_bytes(model: &GpModel) -> Result<Vec<u8>, ExportError> {
    let n = model.vertices();
    let m = model.triangles.len();
    let points: Vec<f32> = (0..3).flat_map(|d| model.shape.mean.iter().map(move |p| p[d])).collect();
    let cells: Vec<i32> = (0..3).flat_map(|d| model.triangles.iter().map(move |t| t[d] as i32)).collect();
    if n > i32::MAX as usize {
        return Err(ExportError::TooManyVertices);
    }
    let mut b = FileBuilder::new();
    write_part(&mut b, "shape", &model.shape, &points, &cells, m, "POLYGON_MESH");
    write_part(&mut b, "color", &model.color, &points, &cells, m, "POLYGON_MESH_DATA");
    let landmarks: Vec<ScalismoLandmark> = model
        .landmarks
        .iter()
        .enumerate()
        .map(|(i, &v)| ScalismoLandmark {
            id: landmark_id(&model.metadata.landmark_scheme, i),
            coordinates: model.shape.mean[v as usize].map(f64::from),
        })
        .collect();
    let extra = GpmmExtra { metadata: model.metadata.clone(), landmark_vertex_ids: model.landmarks.clone() };
    let mut meta = b.create_group("metadata");
    let mut lm = meta.create_group("landmarks");
    let lm_json = serde_json::to_string(&landmarks).map_err(ExportError::Json)?;
    lm.create_dataset("json").with_vlen_strings(&[lm_json.as_str()]).with_shape(&[]);
    meta.add_group(lm.finish());
    let extra_json = serde_json::to_string(&extra).map_err(ExportError::Json)?;
    meta.create_dataset("gpmm").with_vlen_strings(&[extra_json.as_str()]).with_shape(&[]);
    b.add_group(meta.finish());
    b.finish().map_err(ExportError::Hdf5)
}

/// Writes a model as a statismo file.
pub fn export(model: &GpModel, path: &Path) -> Result<(), StatismoError> {
    let name = path.display().to_string();
    let bytes = export_bytes(model).map_err(|error| StatismoError::Export { path: name.clone(), error })?;
    std::fs::write(path, bytes).map_err(|e| StatismoError::File { path: name, message: e.to_string() })
}
