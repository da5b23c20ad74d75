//! The model file: safetensors with JSON metadata (documented in `docs/model-format.md`).
//!
//! Tensors (little-endian; `N` vertices, `K` components, `T` triangles, `L` landmarks):
//! `shape.mean` / `color.mean` F32 `[N,3]`; `shape.eigenvalues` / `color.eigenvalues`
//! F64 `[K]`; factored bases `*.directions` F32 `[K,3]` + `*.fields` F32 `[K,N]`, or dense
//! bases `*.basis` F32 `[K,N,3]` (already scaled by `sqrt(eigenvalue)`); `triangles` U32
//! `[T,3]`; `landmarks` U32 `[L]`. The `__metadata__` entry `gpmm` holds [`ModelMetadata`]
//! as JSON. Readable from Python with `safetensors.numpy.load_file`.

use crate::gp::model::{GpModel, ModelMetadata, ModelPart, PartBasis, MODEL_VERSION};
use safetensors::tensor::{Dtype, SafeTensors, TensorView};
use std::collections::HashMap;
use std::path::Path;

/// Why a model file could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum ModelIoError {
    /// The file could not be read or written.
    #[error("{path}: {error}")]
    Io {
        /// File name.
        path: String,
        /// IO error.
        error: std::io::Error,
    },
    /// The file is not a valid safetensors container.
    #[error("{path}: not a gpmm model file (safetensors: {message})")]
    Container {
        /// File name.
        path: String,
        /// What the parser said.
        message: String,
    },
    /// The file is a gpmm model of another format version.
    #[error("{path}: model file format version {found} is not supported by this gpmm (expects version {expected}); rebuild the model with `gpmm build`")]
    Version {
        /// File name.
        path: String,
        /// Version in the file.
        found: u32,
        /// Version this program reads.
        expected: u32,
    },
    /// The model could not be serialized.
    #[error("{path}: {error}")]
    Encode {
        /// File name.
        path: String,
        /// What the serializer refused.
        error: EncodeError,
    },
    /// A tensor or metadata entry is missing or inconsistent.
    #[error("{path}: {message}")]
    Invalid {
        /// File name.
        path: String,
        /// What is wrong.
        message: String,
    },
}

/// Why a model could not be serialized.
#[derive(Debug, thiserror::Error)]
pub enum EncodeError {
    /// safetensors refused a tensor or the container.
    #[error("{0}")]
    Tensors(safetensors::SafeTensorError),
    /// The metadata could not be written as JSON.
    #[error("{0}")]
    Metadata(serde_json::Error),
}

fn f32_bytes(v: impl IntoIterator<Item = f32>) -> Vec<u8> {
    v.into_iter().flat_map(f32::to_le_bytes).collect()
}

struct Owned {
    dtype: Dtype,
    shape: Vec<usize>,
    data: Vec<u8>,
}

fn part_tensors(prefix: &str, part: &ModelPart, out: &mut Vec<(String, Owned)>) {
    let n = part.mean.len();
    let k = part.rank();
    out.push((
        format!("{prefix}.mean"),
        Owned { dtype: Dtype::F32, shape: vec![n, 3], data: f32_bytes(part.mean.iter().flatten().copied()) },
    ));
    let ev = part.eigenvalues.iter().flat_map(|v| v.to_le_bytes()).collect();
    out.push((format!("{prefix}.eigenvalues"), Owned { dtype: Dtype::F64, shape: vec![k], data: ev }));
    match &part.basis {
        PartBasis::Factored { directions, fields } => {
            out.push((
                format!("{prefix}.directions"),
                Owned { dtype: Dtype::F32, shape: vec![k, 3], data: f32_bytes(directions.iter().flatten().copied()) },
            ));
            out.push((format!("{prefix}.fields"), Owned { dtype: Dtype::F32, shape: vec![k, n], data: f32_bytes(fields.iter().copied()) }));
        }
        PartBasis::Dense { values } => {
            out.push((
                format!("{prefix}.basis"),
                Owned { dtype: Dtype::F32, shape: vec![k, n, 3], data: f32_bytes(values.iter().copied()) },
            ));
        }
    }
}

/// Serializes a model to bytes.
pub fn to_bytes(model: &GpModel) -> Result<Vec<u8>, EncodeError> {
    let mut tensors = Vec::new();
    part_tensors("shape", &model.shape, &mut tensors);
    part_tensors("color", &model.color, &mut tensors);
    let tri = model.triangles.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
    tensors.push(("triangles".into(), Owned { dtype: Dtype::U32, shape: vec![model.triangles.len(), 3], data: tri }));
    let lm = model.landmarks.iter().flat_map(|v| v.to_le_bytes()).collect();
    tensors.push(("landmarks".into(), Owned { dtype: Dtype::U32, shape: vec![model.landmarks.len()], data: lm }));
    let views = tensors
        .iter()
        .map(|(name, t)| TensorView::new(t.dtype, t.shape.clone(), &t.data).map(|v| (name.clone(), v)))
        .collect::<Result<Vec<_>, _>>()
        .map_err(EncodeError::Tensors)?;
    let meta = serde_json::to_string(&model.metadata).map_err(EncodeError::Metadata)?;
    let info = HashMap::from([("gpmm".to_string(), meta)]);
    safetensors::serialize(views, Some(info)).map_err(EncodeError::Tensors)
}

/// Writes a model file.
pub fn save(model: &GpModel, path: &Path) -> Result<(), ModelIoError> {
    let name = path.display().to_string();
    let bytes = to_bytes(model).map_err(|error| ModelIoError::Encode { path: name.clone(), error })?;
    std::fs::write(path, bytes).map_err(|error| ModelIoError::Io { path: name, error })
}

/// Reads and validates a model file.
pub fn load(path: &Path) -> Result<GpModel, ModelIoError> {
    let name = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|error| ModelIoError::Io { path: name.clone(), error })?;
    from_bytes(&bytes, &name)
}

struct Reader<'a> {
    st: SafeTensors<'a>,
    path: &'a str,
}

impl Reader<'_> {
    fn invalid(&self, message: String) -> ModelIoError {
        ModelIoError::Invalid { path: self.path.to_string(), message }
    }

    fn has(&self, name: &str) -> bool {
        self.st.tensor(name).is_ok()
    }

    fn tensor(&self, name: &str, dtype: Dtype, shape: &[Option<usize>]) -> Result<(Vec<usize>, &[u8]), ModelIoError> {
        let t = self.st.tensor(name).map_err(|_| self.invalid(format!("missing tensor '{name}'")))?;
        if t.dtype() != dtype {
            return Err(self.invalid(format!("tensor '{name}' has type {:?}, expected {dtype:?}", t.dtype())));
        }
        let got = t.shape();
        let ok = got.len() == shape.len() && got.iter().zip(shape).all(|(g, w)| w.is_none_or(|w| w == *g));
        if !ok {
            return Err(self.invalid(format!("tensor '{name}' has shape {got:?}, expected {shape:?} (None = any)")));
        }
        Ok((got.to_vec(), t.data()))
    }

    fn f32s(&self, name: &str, shape: &[Option<usize>]) -> Result<(Vec<usize>, Vec<f32>), ModelIoError> {
        let (s, d) = self.tensor(name, Dtype::F32, shape)?;
        let v: Vec<f32> = d.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect();
        if let Some(i) = v.iter().position(|x| !x.is_finite()) {
            return Err(self.invalid(format!("tensor '{name}' has a non-finite value at element {i}")));
        }
        Ok((s, v))
    }

    fn u32s(&self, name: &str, shape: &[Option<usize>]) -> Result<(Vec<usize>, Vec<u32>), ModelIoError> {
        let (s, d) = self.tensor(name, Dtype::U32, shape)?;
        Ok((s, d.chunks_exact(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect()))
    }

    fn part(&self, prefix: &str, n: Option<usize>) -> Result<ModelPart, ModelIoError> {
        let (s, mean) = self.f32s(&format!("{prefix}.mean"), &[n, Some(3)])?;
        let n = s[0];
        let (es, ed) = self.tensor(&format!("{prefix}.eigenvalues"), Dtype::F64, &[None])?;
        let k = es[0];
        let eigenvalues: Vec<f64> =
            ed.chunks_exact(8).map(|c| f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]])).collect();
        if eigenvalues.iter().any(|e| !(e.is_finite() && *e >= 0.0)) {
            return Err(self.invalid(format!("'{prefix}.eigenvalues' must be finite and non-negative")));
        }
        let basis = if self.has(&format!("{prefix}.fields")) {
            let (_, dirs) = self.f32s(&format!("{prefix}.directions"), &[Some(k), Some(3)])?;
            let (_, fields) = self.f32s(&format!("{prefix}.fields"), &[Some(k), Some(n)])?;
            PartBasis::Factored { directions: dirs.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(), fields }
        } else {
            let (_, values) = self.f32s(&format!("{prefix}.basis"), &[Some(k), Some(n), Some(3)])?;
            PartBasis::Dense { values }
        };
        Ok(ModelPart { mean: mean.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(), eigenvalues, basis })
    }
}

/// Parses and validates model bytes; `path` names the source in errors.
pub fn from_bytes(bytes: &[u8], path: &str) -> Result<GpModel, ModelIoError> {
    let container = |e: safetensors::SafeTensorError| ModelIoError::Container { path: path.to_string(), message: e.to_string() };
    let (_, header) = SafeTensors::read_metadata(bytes).map_err(container)?;
    let meta_json = header
        .metadata()
        .as_ref()
        .and_then(|m| m.get("gpmm"))
        .ok_or_else(|| ModelIoError::Invalid { path: path.to_string(), message: "no 'gpmm' metadata: not a gpmm model file".into() })?;
    // Check the version before anything else so old files get the right message.
    let raw: serde_json::Value = serde_json::from_str(meta_json)
        .map_err(|e| ModelIoError::Invalid { path: path.to_string(), message: format!("metadata is not JSON: {e}") })?;
    if raw.get("format").and_then(|f| f.as_str()) != Some("gpmm-model") {
        return Err(ModelIoError::Invalid { path: path.to_string(), message: "metadata 'format' is not 'gpmm-model'".into() });
    }
    let found = raw.get("version").and_then(|v| v.as_u64()).unwrap_or(0);
    if found != u64::from(MODEL_VERSION) {
        return Err(ModelIoError::Version {
            path: path.to_string(),
            found: u32::try_from(found).unwrap_or(u32::MAX),
            expected: MODEL_VERSION,
        });
    }
    let metadata: ModelMetadata =
        serde_json::from_value(raw).map_err(|e| ModelIoError::Invalid { path: path.to_string(), message: format!("metadata: {e}") })?;
    let st = SafeTensors::deserialize(bytes).map_err(container)?;
    let r = Reader { st, path };
    let shape = r.part("shape", None)?;
    let n = shape.mean.len();
    let color = r.part("color", Some(n))?;
    let (_, tri) = r.u32s("triangles", &[None, Some(3)])?;
    if let Some(bad) = tri.iter().find(|&&i| i as usize >= n) {
        return Err(r.invalid(format!("triangle index {bad} out of range (the model has {n} vertices)")));
    }
    let (_, landmarks) = r.u32s("landmarks", &[None])?;
    if let Some(bad) = landmarks.iter().find(|&&i| i as usize >= n) {
        return Err(r.invalid(format!("landmark vertex id {bad} out of range (the model has {n} vertices)")));
    }
    Ok(GpModel { shape, color, triangles: tri.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(), landmarks, metadata })
}
