//! Quantizing a model for a device and writing its flash image, the model blob
//! (`docs/blob-format.md`; read in place by [`gpmm_core::format::blob::ModelBlob`]).
//!
//! [`quantize`] does three things to a [`GpModel`]:
//! 1. **Simplify** to the vertex budget with meshoptimizer (as the template import does):
//!    landmark vertices locked, colours as attributes, vertices never moved; the kept vertices
//!    stay in their original order, the bases' rows of the kept vertices are taken, triangles and
//!    landmarks (same order) are remapped. A model within the budget keeps every vertex.
//! 2. **Truncate** each part to its leading components.
//! 3. **Quantize** each component symmetrically with its own scale: `scale = max |value| / 127`
//!    (8 bits) or `/ 32767` (16 bits), `q = round(value / scale)`; means stay `f32`, triangle
//!    indices become `u16`.
//!
//! [`crate::device::accuracy`] measures what step 3 costs (float model of steps 1–2 against the blob,
//! over random coefficient draws) and what step 1 costs (distance of the
//! original mean surface's vertices to the simplified mean surface).

use crate::gp::model::{GpModel, ModelPart, PartBasis};
use gpmm_core::format::blob::{
    blob_crc, parse_header, BlobDims, Layout, Section, CRC_OFFSET, HEADER_BYTES, MAGIC, MAX_METADATA_BYTES, MAX_VERTICES, VERSION,
};
use gpmm_core::format::blob::{BlobError, ModelBlob};
use gpmm_core::geometry::Vec3;
use std::path::Path;

/// A device profile on the command line; its numbers are `gpmm_core::profile`'s (the one place
/// the firmware and the host read them from).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Profile {
    /// Cortex-M4F class (STM32F405 / nRF52840): 512 KiB data partition, 128×128 images.
    M4f,
    /// Cortex-M7 class (STM32H743): 1 MiB data partition, 256×256 images.
    M7,
}

impl Profile {
    /// Both profiles.
    pub const ALL: [Profile; 2] = [Profile::M4f, Profile::M7];

    /// The core's description of this profile.
    pub fn device(self) -> gpmm_core::profile::DeviceProfile {
        match self {
            Profile::M4f => gpmm_core::profile::M4F,
            Profile::M7 => gpmm_core::profile::M7,
        }
    }

    /// `m4f` or `m7`.
    pub fn name(self) -> &'static str {
        self.device().name
    }

    /// Default vertex budget.
    pub fn vertices(self) -> usize {
        self.device().model_vertices
    }

    /// Default shape rank.
    pub fn rank_shape(self) -> usize {
        self.device().model_rank
    }

    /// Default colour rank.
    pub fn rank_color(self) -> usize {
        self.device().model_rank
    }

    /// Default bits per basis value.
    pub fn bits(self) -> Bits {
        Bits::Sixteen
    }

    /// Side of the square RGB target image the firmware fits.
    pub fn image_side(self) -> u32 {
        self.device().image_side
    }

    /// Bytes of the 8-bit RGB target image.
    pub fn image_bytes(self) -> usize {
        self.device().image_bytes()
    }

    /// Size of the flash data partition that holds the blob and the fit input.
    pub fn partition_bytes(self) -> usize {
        self.device().partition_bytes
    }

    /// Largest blob `gpmm quantize` writes for this profile (leaves room for the image and landmarks).
    pub fn blob_budget(self) -> usize {
        self.device().blob_budget
    }
}

impl std::fmt::Display for Profile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Profile {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Profile::ALL.into_iter().find(|p| p.name().eq_ignore_ascii_case(s)).ok_or_else(|| format!("unknown profile '{s}' (m4f or m7)"))
    }
}

/// Bits per quantized basis value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Bits {
    /// `i8`, values in -127..=127.
    Eight,
    /// `i16`, values in -32767..=32767.
    Sixteen,
}

impl Bits {
    /// 8 or 16.
    pub fn count(self) -> u8 {
        match self {
            Bits::Eight => 8,
            Bits::Sixteen => 16,
        }
    }

    /// The largest magnitude stored (127 or 32767).
    pub fn qmax(self) -> i32 {
        match self {
            Bits::Eight => 127,
            Bits::Sixteen => 32767,
        }
    }

    /// From 8 or 16.
    pub fn from_count(bits: u8) -> Option<Self> {
        match bits {
            8 => Some(Bits::Eight),
            16 => Some(Bits::Sixteen),
            _ => None,
        }
    }
}

/// What [`quantize`] keeps.
#[derive(Debug, Clone, PartialEq)]
pub struct QuantizeOptions {
    /// Vertex budget (landmark vertices are always kept; at most 65535).
    pub vertices: usize,
    /// Shape components kept (the leading ones; at most the model's rank).
    pub rank_shape: usize,
    /// Colour components kept.
    pub rank_color: usize,
    /// Bits per basis value.
    pub bits: Bits,
    /// Refuse a blob larger than this many bytes.
    pub budget: Option<usize>,
    /// The profile, recorded in the metadata and named in errors.
    pub profile: Option<Profile>,
    /// Where the model came from (recorded in the metadata, e.g. the model file's name).
    pub source: Option<String>,
}

impl QuantizeOptions {
    /// A profile's defaults and budget.
    pub fn for_profile(p: Profile) -> Self {
        Self {
            vertices: p.vertices(),
            rank_shape: p.rank_shape(),
            rank_color: p.rank_color(),
            bits: p.bits(),
            budget: Some(p.blob_budget()),
            profile: Some(p),
            source: None,
        }
    }
}

/// Why a model could not be quantized or a blob not read.
#[derive(Debug, thiserror::Error)]
pub enum QuantizeError {
    /// More vertices than `u16` triangle indices address.
    #[error("{vertices} vertices requested; a blob holds at most {MAX_VERTICES} (triangle indices are 16-bit)")]
    TooManyVertices {
        /// Requested vertex count.
        vertices: usize,
    },
    /// The vertex budget cannot hold the landmark vertices.
    #[error("a vertex budget of {vertices} cannot keep the model's {landmarks} landmark vertices")]
    BudgetBelowLandmarks {
        /// Requested vertex count.
        vertices: usize,
        /// Landmarks of the model.
        landmarks: usize,
    },
    /// More components were asked for than the model has.
    #[error("{part} rank {requested} requested, but the model has only {available} {part} components")]
    RankTooHigh {
        /// `shape` or `colour`.
        part: &'static str,
        /// Requested rank.
        requested: usize,
        /// The model's rank.
        available: usize,
    },
    /// The model itself is inconsistent (lengths, indices, non-finite values).
    #[error("invalid model: {0}")]
    Model(String),
    /// meshoptimizer could not reach the vertex budget.
    #[error("simplification failed: {0}")]
    Simplify(crate::mesh::simplify::SimplifyError),
    /// The blob would exceed the budget.
    #[error("the blob would be {bytes} bytes ({:.1} KiB), over the {what} budget of {budget} bytes ({:.1} KiB); lower --vertices, --rank-shape, --rank-color or use --bits 8", *bytes as f64 / 1024.0, *budget as f64 / 1024.0)]
    OverBudget {
        /// Blob size.
        bytes: usize,
        /// The budget.
        budget: usize,
        /// e.g. `m4f profile`.
        what: String,
    },
    /// The metadata JSON is too long.
    #[error("blob metadata is {0} bytes, at most {MAX_METADATA_BYTES} are allowed")]
    MetadataTooLong(usize),
    /// The core refused a blob.
    #[error(transparent)]
    Blob(#[from] BlobError),
    /// Reading or writing a file failed.
    #[error("{path}: {error}")]
    Io {
        /// File name.
        path: String,
        /// IO error.
        error: std::io::Error,
    },
}

/// Quantized basis values of one part.
#[derive(Debug, Clone, PartialEq)]
pub enum QuantValuesBuf {
    /// 8-bit values.
    I8(Vec<i8>),
    /// 16-bit values.
    I16(Vec<i16>),
}

/// One quantized part (shape or colour).
#[derive(Debug, Clone, PartialEq)]
pub struct QuantizedPart {
    /// Mean per vertex (`f32`, unchanged).
    pub mean: Vec<Vec3>,
    /// Per-component scale: dequantized value = `scale · q`.
    pub scales: Vec<f32>,
    /// Unit direction per component (factored layout), or `None` (dense layout).
    pub directions: Option<Vec<Vec3>>,
    /// Values, `rank × vertices` (factored) or `rank × vertices × 3` (dense).
    pub values: QuantValuesBuf,
}

impl QuantizedPart {
    /// Number of components.
    pub fn rank(&self) -> usize {
        self.scales.len()
    }

    /// The basis layout.
    pub fn layout(&self) -> Layout {
        if self.directions.is_some() {
            Layout::Factored
        } else {
            Layout::Dense
        }
    }
}

/// A model reduced to a device profile and quantized, ready to be written as a blob.
#[derive(Debug, Clone)]
pub struct QuantizedModel {
    /// The float model after simplification and rank truncation (the reference of [`super::accuracy::quantization_error`]).
    pub reduced: GpModel,
    /// Vertex ids in the source model of the kept vertices, ascending.
    pub kept: Vec<u32>,
    /// Quantized shape part.
    pub shape: QuantizedPart,
    /// Quantized colour part.
    pub color: QuantizedPart,
    /// Triangles with `u16` indices.
    pub triangles: Vec<[u16; 3]>,
    /// Landmark vertex ids (same order as the source model's).
    pub landmarks: Vec<u32>,
    /// Bits per basis value.
    pub bits: Bits,
    /// The metadata JSON.
    pub metadata: String,
}

impl QuantizedModel {
    /// Number of vertices.
    pub fn vertices(&self) -> usize {
        self.shape.mean.len()
    }

    /// The sizes the blob header declares.
    pub fn dims(&self) -> BlobDims {
        BlobDims {
            vertices: self.vertices() as u32,
            triangles: self.triangles.len() as u32,
            landmarks: self.landmarks.len() as u32,
            rank_shape: self.shape.rank() as u16,
            rank_color: self.color.rank() as u16,
            bits: self.bits.count(),
            shape_layout: self.shape.layout(),
            color_layout: self.color.layout(),
            metadata_bytes: self.metadata.len() as u32,
        }
    }

    /// The blob's size in bytes.
    pub fn blob_bytes(&self) -> Result<usize, QuantizeError> {
        Ok(self.dims().total_bytes()?)
    }

    /// Writes the blob (docs/blob-format.md).
    pub fn to_bytes(&self) -> Result<Vec<u8>, QuantizeError> {
        let dims = self.dims();
        let (table, total) = dims.layout()?;
        let mut out = vec![0u8; total];
        let mut put = |at: usize, bytes: &[u8]| out[at..at + bytes.len()].copy_from_slice(bytes);
        put(0, &MAGIC);
        put(4, &VERSION.to_le_bytes());
        put(6, &(HEADER_BYTES as u16).to_le_bytes());
        put(8, &(total as u32).to_le_bytes());
        put(16, &dims.vertices.to_le_bytes());
        put(20, &dims.triangles.to_le_bytes());
        put(24, &dims.landmarks.to_le_bytes());
        put(28, &dims.rank_shape.to_le_bytes());
        put(30, &dims.rank_color.to_le_bytes());
        put(32, &[dims.bits, dims.shape_layout.code(), dims.color_layout.code()]);
        put(36, &(Section::ALL.len() as u16).to_le_bytes());
        for (i, e) in table.iter().enumerate() {
            put(48 + 8 * i, &e.offset.to_le_bytes());
            put(52 + 8 * i, &e.len.to_le_bytes());
        }
        let f32s = |v: &mut dyn Iterator<Item = f32>| v.flat_map(f32::to_le_bytes).collect::<Vec<u8>>();
        let values = |v: &QuantValuesBuf| match v {
            QuantValuesBuf::I8(v) => v.iter().map(|&q| q as u8).collect::<Vec<u8>>(),
            QuantValuesBuf::I16(v) => v.iter().flat_map(|q| q.to_le_bytes()).collect(),
        };
        let dirs = |p: &QuantizedPart| p.directions.as_ref().map(|d| f32s(&mut d.iter().flatten().copied())).unwrap_or_default();
        let sections: [Vec<u8>; 11] = [
            f32s(&mut self.shape.mean.iter().flatten().copied()),
            f32s(&mut self.color.mean.iter().flatten().copied()),
            self.triangles.iter().flatten().flat_map(|i| i.to_le_bytes()).collect(),
            self.landmarks.iter().flat_map(|i| i.to_le_bytes()).collect(),
            f32s(&mut self.shape.scales.iter().copied()),
            dirs(&self.shape),
            values(&self.shape.values),
            f32s(&mut self.color.scales.iter().copied()),
            dirs(&self.color),
            values(&self.color.values),
            self.metadata.as_bytes().to_vec(),
        ];
        for (e, bytes) in table.iter().zip(&sections) {
            debug_assert_eq!(e.len as usize, bytes.len());
            put(e.offset as usize, bytes);
        }
        let crc = blob_crc(&out);
        out[CRC_OFFSET..CRC_OFFSET + 4].copy_from_slice(&crc.to_le_bytes());
        Ok(out)
    }

    /// The blob in an aligned buffer.
    pub fn to_blob(&self) -> Result<BlobBuf, QuantizeError> {
        Ok(BlobBuf::from_bytes(&self.to_bytes()?))
    }
}

/// An owned blob in a 4-byte aligned buffer (a `Vec<u8>` is not guaranteed to be aligned).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BlobBuf {
    words: Vec<u32>,
    len: usize,
}

impl BlobBuf {
    /// Copies `bytes` into an aligned buffer.
    pub fn from_bytes(bytes: &[u8]) -> Self {
        let mut words = vec![0u32; bytes.len().div_ceil(4)];
        bytemuck::cast_slice_mut::<u32, u8>(&mut words)[..bytes.len()].copy_from_slice(bytes);
        Self { words, len: bytes.len() }
    }

    /// Reads a blob file.
    pub fn read(path: &Path) -> Result<Self, QuantizeError> {
        let bytes = std::fs::read(path).map_err(|error| QuantizeError::Io { path: path.display().to_string(), error })?;
        Ok(Self::from_bytes(&bytes))
    }

    /// Writes the bytes to a file.
    pub fn write(&self, path: &Path) -> Result<(), QuantizeError> {
        std::fs::write(path, self.bytes()).map_err(|error| QuantizeError::Io { path: path.display().to_string(), error })
    }

    /// The bytes (4-byte aligned).
    pub fn bytes(&self) -> &[u8] {
        &bytemuck::cast_slice::<u32, u8>(&self.words)[..self.len]
    }

    /// Number of bytes.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether there are no bytes.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The validated view (the core's parser, as on the device).
    pub fn view(&self) -> Result<ModelBlob<'_>, BlobError> {
        ModelBlob::parse(self.bytes())
    }
}

/// Parses `--bits`: 8 or 16.
pub fn parse_bits(s: &str) -> Result<Bits, String> {
    s.trim().parse::<u8>().ok().and_then(Bits::from_count).ok_or_else(|| format!("'{s}': bits per basis value must be 8 or 16"))
}

/// What `gpmm inspect` prints, and whether the blob is valid.
///
/// The JSON has the header fields (`bytes`, `version`, `vertices`, `triangles`, `landmarks`,
/// `rank_shape`, `rank_color`, `bits`, `layout`, `crc`, `crc_ok`, `sections`) whenever the
/// header is readable, even if the blob is then refused (e.g. `"crc_ok": false`); `valid`,
/// and `metadata` or `error`.
pub fn inspect(blob: &BlobBuf) -> (serde_json::Value, Result<(), BlobError>) {
    let bytes = blob.bytes();
    let header = match parse_header(bytes) {
        Ok(h) => h,
        Err(e) => return (serde_json::json!({ "file_bytes": bytes.len(), "valid": false, "error": e.to_string() }), Err(e)),
    };
    let crc = header.check_crc(bytes).map(|c| c.ok()).ok();
    let d = header.dims;
    let sections: serde_json::Map<String, serde_json::Value> = Section::ALL
        .iter()
        .map(|&s| {
            let e = header.section(s);
            (s.name().to_string(), serde_json::json!({ "offset": e.offset, "len": e.len }))
        })
        .collect();
    let mut json = serde_json::json!({
        "bytes": header.total_bytes,
        "file_bytes": bytes.len(),
        "version": header.version,
        "vertices": d.vertices,
        "triangles": d.triangles,
        "landmarks": d.landmarks,
        "rank_shape": d.rank_shape,
        "rank_color": d.rank_color,
        "bits": d.bits,
        "layout": { "shape": d.shape_layout.name(), "color": d.color_layout.name() },
        "crc": format!("{:#010x}", header.crc),
        "crc_ok": crc,
        "sections": sections,
    });
    match blob.view() {
        Ok(view) => {
            json["valid"] = true.into();
            json["metadata"] = serde_json::from_str(view.metadata_str()).unwrap_or_else(|_| view.metadata_str().into());
            (json, Ok(()))
        }
        Err(e) => {
            json["valid"] = false.into();
            json["error"] = e.to_string().into();
            (json, Err(e))
        }
    }
}

// ------------------------------------------------------------------ reduce

/// Picks the vertices to keep: all of them within the budget, else a meshoptimizer
/// simplification with landmark vertices locked ([`crate::mesh::simplify`]). Returns kept ids
/// (ascending) and the triangles in source ids.
fn simplify(model: &GpModel, target: usize) -> Result<(Vec<u32>, Vec<[u32; 3]>), QuantizeError> {
    let landmarks = &model.landmarks;
    if model.vertices() > target && target < landmarks.len() {
        return Err(QuantizeError::BudgetBelowLandmarks { vertices: target, landmarks: landmarks.len() });
    }
    let s = crate::mesh::simplify::simplify_to(&model.shape.mean, &model.color.mean, &model.triangles, landmarks, target)
        .map_err(QuantizeError::Simplify)?;
    Ok((s.kept, s.triangles))
}

fn check_rank(part: &'static str, requested: usize, available: usize) -> Result<(), QuantizeError> {
    if requested > available {
        return Err(QuantizeError::RankTooHigh { part, requested, available });
    }
    Ok(())
}

/// The part restricted to the `kept` vertices and the leading `rank` components.
fn reduce_part(p: &ModelPart, kept: &[u32], rank: usize) -> ModelPart {
    let n = p.mean.len();
    let mean = kept.iter().map(|&v| p.mean[v as usize]).collect();
    let basis = match &p.basis {
        PartBasis::Factored { directions, fields } => PartBasis::Factored {
            directions: directions[..rank].to_vec(),
            fields: (0..rank).flat_map(|k| kept.iter().map(move |&v| fields[k * n + v as usize])).collect(),
        },
        PartBasis::Dense { values } => PartBasis::Dense {
            values: (0..rank)
                .flat_map(|k| kept.iter().flat_map(move |&v| (0..3).map(move |a| values[(k * n + v as usize) * 3 + a])))
                .collect(),
        },
    };
    ModelPart { mean, eigenvalues: p.eigenvalues[..rank].to_vec(), basis }
}

/// The float model simplified to at most `vertices` vertices and truncated to the given ranks,
/// with the source ids of the kept vertices.
pub fn reduce(model: &GpModel, vertices: usize, rank_shape: usize, rank_color: usize) -> Result<(GpModel, Vec<u32>), QuantizeError> {
    check_rank("shape", rank_shape, model.shape.rank())?;
    check_rank("colour", rank_color, model.color.rank())?;
    crate::fit::morphable(model).map_err(|e| QuantizeError::Model(e.to_string()))?;
    let (kept, triangles) = simplify(model, vertices)?;
    if kept.len() > MAX_VERTICES {
        return Err(QuantizeError::TooManyVertices { vertices: kept.len() });
    }
    let mut map = vec![u32::MAX; model.vertices()];
    for (new, &old) in kept.iter().enumerate() {
        map[old as usize] = new as u32;
    }
    let reduced = GpModel {
        shape: reduce_part(&model.shape, &kept, rank_shape),
        color: reduce_part(&model.color, &kept, rank_color),
        triangles: triangles.iter().map(|t| t.map(|i| map[i as usize])).collect(),
        landmarks: model.landmarks.iter().map(|&i| map[i as usize]).collect(),
        metadata: model.metadata.clone(),
    };
    Ok((reduced, kept))
}

// ------------------------------------------------------------------ quantize

fn quantize_rows(rows: &[f32], rank: usize, bits: Bits) -> (Vec<f32>, QuantValuesBuf) {
    let len = rows.len().checked_div(rank).unwrap_or(0);
    let qmax = bits.qmax();
    let mut scales = Vec::with_capacity(rank);
    let mut q = Vec::with_capacity(rows.len());
    for row in rows.chunks_exact(len.max(1)).take(rank) {
        let max = row.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        let scale = max / qmax as f32;
        scales.push(scale);
        let s = f64::from(scale);
        q.extend(row.iter().map(|&v| if s > 0.0 { (f64::from(v) / s).round().clamp(-f64::from(qmax), f64::from(qmax)) as i32 } else { 0 }));
    }
    let values = match bits {
        Bits::Eight => QuantValuesBuf::I8(q.iter().map(|&v| v as i8).collect()),
        Bits::Sixteen => QuantValuesBuf::I16(q.iter().map(|&v| v as i16).collect()),
    };
    (scales, values)
}

/// Quantizes one (already reduced) part: symmetric, one scale per component.
pub fn quantize_part(p: &ModelPart, bits: Bits) -> Result<QuantizedPart, QuantizeError> {
    let rank = p.rank();
    let finite = |v: &[f32]| v.iter().all(|x| x.is_finite());
    if !p.mean.iter().all(|m| finite(m)) {
        return Err(QuantizeError::Model("a mean value is NaN or infinite".into()));
    }
    let (scales, directions, values) = match &p.basis {
        PartBasis::Factored { directions, fields } => {
            // Exactly unit directions (the blob requires it); the length goes into the field.
            let mut fields = fields.clone();
            let mut dirs = Vec::with_capacity(rank);
            for (k, d) in directions.iter().enumerate() {
                let len = d.iter().map(|x| f64::from(*x).powi(2)).sum::<f64>().sqrt();
                if !(len.is_finite() && len > 0.0) {
                    return Err(QuantizeError::Model(format!("direction of component {k} is zero or not finite")));
                }
                dirs.push(d.map(|x| (f64::from(x) / len) as f32));
                let n = p.mean.len();
                for f in &mut fields[k * n..(k + 1) * n] {
                    *f = (f64::from(*f) * len) as f32;
                }
            }
            if !finite(&fields) {
                return Err(QuantizeError::Model("a basis value is NaN or infinite".into()));
            }
            let (s, v) = quantize_rows(&fields, rank, bits);
            (s, Some(dirs), v)
        }
        PartBasis::Dense { values } => {
            if !finite(values) {
                return Err(QuantizeError::Model("a basis value is NaN or infinite".into()));
            }
            let (s, v) = quantize_rows(values, rank, bits);
            (s, None, v)
        }
    };
    Ok(QuantizedPart { mean: p.mean.clone(), scales, directions, values })
}

fn metadata_json(model: &GpModel, opts: &QuantizeOptions) -> String {
    let json = serde_json::json!({
        "format": "gpmm-blob",
        "kernel": model.metadata.kernel,
        "source": opts.source,
        "source_vertices": model.vertices(),
        "source_rank_shape": model.shape.rank(),
        "source_rank_color": model.color.rank(),
        "profile": opts.profile.map(Profile::name),
        "landmark_scheme": model.metadata.landmark_scheme,
        "units": model.metadata.units,
        "attribution": model.metadata.template.attribution,
        "created_by": concat!("gpmm ", env!("CARGO_PKG_VERSION")),
    });
    json.to_string()
}

/// Simplifies, truncates and quantizes `model` (see the module documentation); refuses a blob
/// over `opts.budget`.
pub fn quantize(model: &GpModel, opts: &QuantizeOptions) -> Result<QuantizedModel, QuantizeError> {
    if opts.vertices > MAX_VERTICES {
        return Err(QuantizeError::TooManyVertices { vertices: opts.vertices });
    }
    let (reduced, kept) = reduce(model, opts.vertices, opts.rank_shape, opts.rank_color)?;
    let metadata = metadata_json(model, opts);
    if metadata.len() > MAX_METADATA_BYTES {
        return Err(QuantizeError::MetadataTooLong(metadata.len()));
    }
    let q = QuantizedModel {
        shape: quantize_part(&reduced.shape, opts.bits)?,
        color: quantize_part(&reduced.color, opts.bits)?,
        triangles: reduced.triangles.iter().map(|t| t.map(|i| i as u16)).collect(),
        landmarks: reduced.landmarks.clone(),
        bits: opts.bits,
        metadata,
        kept,
        reduced,
    };
    let bytes = q.blob_bytes()?;
    if let Some(budget) = opts.budget {
        if bytes > budget {
            let what = opts.profile.map(|p| format!("{p} profile")).unwrap_or_else(|| "given".into());
            return Err(QuantizeError::OverBudget { bytes, budget, what });
        }
    }
    Ok(q)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_quantize_symmetrically_per_component() {
        let rows = [1.0f32, -0.5, 0.25, 0.0, 0.0, 0.0, 10.0, 2.0, -3.0];
        let (s, v) = quantize_rows(&rows, 3, Bits::Eight);
        assert_eq!(s, vec![1.0 / 127.0, 0.0, 10.0 / 127.0]);
        assert_eq!(v, QuantValuesBuf::I8(vec![127, -64, 32, 0, 0, 0, 127, 25, -38]));
        let (s, v) = quantize_rows(&rows, 3, Bits::Sixteen);
        let QuantValuesBuf::I16(q) = v else { panic!("16 bits") };
        for (i, (&x, &q)) in rows.iter().zip(&q).enumerate() {
            assert!((f64::from(s[i / 3]) * f64::from(q) - f64::from(x)).abs() <= f64::from(s[i / 3]) * 0.5 + 1e-9);
        }
        assert_eq!(q[0], 32767);
    }

    #[test]
    fn profiles_and_bits() {
        assert_eq!("M7".parse::<Profile>().unwrap(), Profile::M7);
        assert!("m5".parse::<Profile>().unwrap_err().contains("m4f or m7"));
        for p in Profile::ALL {
            assert!(p.blob_budget() + p.image_bytes() + 68 * 8 < p.partition_bytes());
        }
        assert_eq!(Bits::from_count(8), Some(Bits::Eight));
        assert_eq!(Bits::from_count(7), None);
        let b = BlobBuf::from_bytes(&[1, 2, 3, 4, 5]);
        assert_eq!(b.bytes(), &[1, 2, 3, 4, 5]);
        assert_eq!(b.bytes().as_ptr() as usize % 4, 0);
        assert!(matches!(b.view(), Err(BlobError::BadMagic)));
    }
}
