//! The validated blob, borrowed in place: its arrays, its bases and the morphable model over them.

use crate::error::FitError;
use crate::geometry::Vec3;
use crate::model::MorphableModel;
use crate::model::{Basis, ModelError, QuantValues, QuantizedBasis};

use super::header::{parse_header, BlobHeader, SectionEntry};
use super::{BlobError, Layout, Section, SectionProblem, HEADER_BYTES, START_ALIGN, UNIT_TOLERANCE};

/// A validated model blob, borrowed in place (e.g. from a flash partition).
#[derive(Debug, Clone, Copy)]
pub struct ModelBlob<'a> {
    bytes: &'a [u8],
    header: BlobHeader,
    shape_mean: &'a [Vec3],
    color_mean: &'a [Vec3],
    triangles: &'a [[u16; 3]],
    landmarks: &'a [u32],
    shape: QuantizedBasis<'a>,
    color: QuantizedBasis<'a>,
    metadata: &'a str,
}

fn section_bytes<'a>(blob: &'a [u8], header: &BlobHeader, s: Section) -> Result<&'a [u8], BlobError> {
    blob.get(header.section(s).range()).ok_or(BlobError::Section { section: s, problem: SectionProblem::OutOfBounds })
}

fn cast<'a, T: bytemuck::Pod>(blob: &'a [u8], header: &BlobHeader, s: Section) -> Result<&'a [T], BlobError> {
    bytemuck::try_cast_slice(section_bytes(blob, header, s)?).map_err(|_| BlobError::Misaligned)
}

fn values<'a>(blob: &'a [u8], header: &BlobHeader, s: Section) -> Result<QuantValues<'a>, BlobError> {
    Ok(match header.dims.bits {
        8 => QuantValues::I8(cast(blob, header, s)?),
        _ => QuantValues::I16(cast(blob, header, s)?),
    })
}

fn part<'a>(blob: &'a [u8], header: &BlobHeader, layout: Layout, sections: [Section; 3]) -> Result<QuantizedBasis<'a>, BlobError> {
    let [s_scales, s_dirs, s_values] = sections;
    let scales: &[f32] = cast(blob, header, s_scales)?;
    if !scales.iter().all(|s| s.is_finite() && *s >= 0.0) {
        return Err(BlobError::NonFinite(s_scales));
    }
    let directions = match layout {
        Layout::Factored => {
            let d: &[Vec3] = cast(blob, header, s_dirs)?;
            if !d.iter().flatten().all(|v| v.is_finite()) {
                return Err(BlobError::NonFinite(s_dirs));
            }
            if !d.iter().all(|e| libm::fabsf(e[0] * e[0] + e[1] * e[1] + e[2] * e[2] - 1.0) <= 2.0 * UNIT_TOLERANCE) {
                return Err(BlobError::NotUnit(s_dirs));
            }
            Some(d)
        }
        Layout::Dense => None,
    };
    let values = values(blob, header, s_values)?;
    QuantizedBasis::new(values, scales, directions, header.dims.vertices as usize).map_err(|e| match e {
        ModelError::LengthMismatch | ModelError::TooManyCoefficients => BlobError::Section {
            section: s_values,
            problem: SectionProblem::Length { expected: values.len(), found: header.section(s_values).len },
        },
    })
}

impl<'a> ModelBlob<'a> {
    /// Validates the blob at the start of `bytes` (which may be longer, e.g. a whole flash
    /// partition) and borrows its arrays in place. `bytes` must start 4-byte aligned.
    ///
    /// # Examples
    ///
    /// A one-triangle model with one shape component laid out by [`super::BlobDims::layout`] and
    /// sealed by [`super::blob_crc`], parsed in place; the same bytes with one byte changed are refused:
    ///
    /// ```
    /// use gpmm_core::format::blob::{blob_crc, BlobDims, BlobError, Layout, ModelBlob, Section, CRC_OFFSET};
    /// # use gpmm_core::format::blob::{HEADER_BYTES, MAGIC, SECTION_COUNT, VERSION};
    ///
    /// let dims = BlobDims { vertices: 3, triangles: 1, landmarks: 1, rank_shape: 1, rank_color: 0, bits: 8,
    ///     shape_layout: Layout::Factored, color_layout: Layout::Factored, metadata_bytes: 2 };
    /// let f32s = |v: &[f32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
    /// let sections: [Vec<u8>; 11] = [
    ///     f32s(&[0.0, 0.0, 0.0, 10.0, 0.0, 0.0, 0.0, 10.0, 0.0]),      // shape mean (mm)
    ///     f32s(&[0.5; 9]),                                             // colour mean
    ///     [0u16, 1, 2].iter().flat_map(|i| i.to_le_bytes()).collect(), // the triangle
    ///     2u32.to_le_bytes().to_vec(),                                 // one landmark: vertex 2
    ///     f32s(&[0.5]), f32s(&[0.0, 0.0, 1.0]), vec![0, 0, 10],        // shape: scale, direction, i8 values
    ///     vec![], vec![], vec![],                                      // no colour component
    ///     b"{}".to_vec(),                                              // metadata
    /// ];
    /// // Read in place: the blob's first byte must be 4-byte aligned, as `u32` words are.
    /// let (table, total) = dims.layout()?;
    /// let mut words = vec![0u32; total / 4];
    /// let blob: &mut [u8] = bytemuck::cast_slice_mut(&mut words);
    /// # fn put(blob: &mut [u8], at: usize, bytes: &[u8]) { blob[at..at + bytes.len()].copy_from_slice(bytes) }
    /// # // The header (docs/blob-format.md): magic, version, header size, total size, sizes,
    /// # // bits, layouts, section count and the section table.
    /// # put(blob, 0, &MAGIC);
    /// # put(blob, 4, &VERSION.to_le_bytes());
    /// # put(blob, 6, &(HEADER_BYTES as u16).to_le_bytes());
    /// # put(blob, 8, &(total as u32).to_le_bytes());
    /// # for (at, v) in [(16, dims.vertices), (20, dims.triangles), (24, dims.landmarks)] { put(blob, at, &v.to_le_bytes()) }
    /// # put(blob, 28, &dims.rank_shape.to_le_bytes());
    /// # put(blob, 30, &dims.rank_color.to_le_bytes());
    /// # put(blob, 32, &[dims.bits, dims.shape_layout.code(), dims.color_layout.code()]);
    /// # put(blob, 36, &(SECTION_COUNT as u16).to_le_bytes());
    /// # for (i, e) in table.iter().enumerate() {
    /// #     put(blob, 48 + 8 * i, &e.offset.to_le_bytes());
    /// #     put(blob, 52 + 8 * i, &e.len.to_le_bytes());
    /// # }
    /// // The header (hidden here: magic, sizes, the table), each section at its offset, the CRC.
    /// for (entry, bytes) in table.iter().zip(&sections) {
    ///     blob[entry.offset as usize..][..bytes.len()].copy_from_slice(bytes);
    /// }
    /// let crc = blob_crc(blob);
    /// blob[CRC_OFFSET..CRC_OFFSET + 4].copy_from_slice(&crc.to_le_bytes());
    ///
    /// let model = ModelBlob::parse(blob)?;
    /// assert_eq!((model.vertices(), model.triangles(), model.landmarks()), (3, &[[0, 1, 2]][..], &[2][..]));
    /// assert_eq!((model.rank_shape(), model.rank_color(), model.metadata_str()), (1, 0, "{}"));
    /// // The first shape component lifts vertex 2 by 0.5 × 10 mm per unit coefficient.
    /// let mut positions = [[0.0; 3]; 3];
    /// model.morphable()?.shape_instance(&[1.0], &mut positions)?;
    /// assert_eq!(positions[2], [0.0, 10.0, 5.0]);
    ///
    /// // A changed byte of the shape mean: the CRC no longer matches, the blob is refused.
    /// let at = model.header().section(Section::ShapeMean).offset as usize;
    /// blob[at] ^= 0x40;
    /// assert!(matches!(ModelBlob::parse(blob), Err(BlobError::Crc { .. })));
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn parse(bytes: &'a [u8]) -> Result<Self, BlobError> {
        if cfg!(target_endian = "big") {
            return Err(BlobError::BigEndian);
        }
        if !(bytes.as_ptr() as usize).is_multiple_of(START_ALIGN) {
            return Err(BlobError::Misaligned);
        }
        let header = parse_header(bytes)?;
        let blob =
            bytes.get(..header.total_bytes as usize).ok_or(BlobError::Truncated { total: header.total_bytes, available: bytes.len() })?;
        let crc = header.check_crc(blob)?;
        if !crc.ok() {
            return Err(BlobError::Crc { stored: crc.stored, computed: crc.computed });
        }
        // Padding: the header's tail before the first section, between sections and at the end.
        let mut end = HEADER_BYTES;
        for e in header.sections.iter().chain(core::iter::once(&SectionEntry { offset: header.total_bytes, len: 0 })) {
            let gap = blob.get(end..e.offset as usize).ok_or(BlobError::Overflow)?;
            if gap.iter().any(|&b| b != 0) {
                return Err(BlobError::PaddingNotZero);
            }
            end = e.range().end;
        }

        let n = header.dims.vertices as usize;
        let shape_mean: &[Vec3] = cast(blob, &header, Section::ShapeMean)?;
        let color_mean: &[Vec3] = cast(blob, &header, Section::ColorMean)?;
        for (mean, s) in [(shape_mean, Section::ShapeMean), (color_mean, Section::ColorMean)] {
            if !mean.iter().flatten().all(|v| v.is_finite()) {
                return Err(BlobError::NonFinite(s));
            }
        }
        let triangles: &[[u16; 3]] = cast(blob, &header, Section::Triangles)?;
        if triangles.iter().flatten().any(|&i| usize::from(i) >= n) {
            return Err(BlobError::IndexOutOfRange(Section::Triangles));
        }
        let landmarks: &[u32] = cast(blob, &header, Section::Landmarks)?;
        if landmarks.iter().any(|&i| i as usize >= n) {
            return Err(BlobError::IndexOutOfRange(Section::Landmarks));
        }
        let d = header.dims;
        let shape = part(blob, &header, d.shape_layout, [Section::ShapeScales, Section::ShapeDirections, Section::ShapeValues])?;
        let color = part(blob, &header, d.color_layout, [Section::ColorScales, Section::ColorDirections, Section::ColorValues])?;
        let metadata = core::str::from_utf8(section_bytes(blob, &header, Section::Metadata)?).map_err(|_| BlobError::MetadataNotUtf8)?;
        Ok(Self { bytes: blob, header, shape_mean, color_mean, triangles, landmarks, shape, color, metadata })
    }

    /// The blob's bytes (exactly [`ModelBlob::len`] of them).
    pub fn bytes(&self) -> &'a [u8] {
        self.bytes
    }

    /// Total size in bytes.
    pub fn len(&self) -> usize {
        self.bytes.len()
    }

    /// Always false: a valid blob has a header.
    pub fn is_empty(&self) -> bool {
        self.bytes.is_empty()
    }

    /// The validated header.
    pub fn header(&self) -> &BlobHeader {
        &self.header
    }

    /// Format version.
    pub fn version(&self) -> u16 {
        self.header.version
    }

    /// The stored (and verified) CRC-32.
    pub fn crc(&self) -> u32 {
        self.header.crc
    }

    /// Number of vertices.
    pub fn vertices(&self) -> usize {
        self.shape_mean.len()
    }

    /// Triangles (vertex indices, counter-clockwise seen from outside).
    pub fn triangles(&self) -> &'a [[u16; 3]] {
        self.triangles
    }

    /// Landmark vertex ids (iBUG-68 order for faces).
    pub fn landmarks(&self) -> &'a [u32] {
        self.landmarks
    }

    /// Shape components.
    pub fn rank_shape(&self) -> usize {
        self.shape.rank()
    }

    /// Colour components.
    pub fn rank_color(&self) -> usize {
        self.color.rank()
    }

    /// Bits per basis value (8 or 16).
    pub fn bits(&self) -> u8 {
        self.header.dims.bits
    }

    /// Shape mean (mm).
    pub fn shape_mean(&self) -> &'a [Vec3] {
        self.shape_mean
    }

    /// Colour mean (linear RGB).
    pub fn color_mean(&self) -> &'a [Vec3] {
        self.color_mean
    }

    /// The shape basis (quantized).
    pub fn shape_basis(&self) -> Basis<'a> {
        Basis::Quantized(self.shape)
    }

    /// The colour basis (quantized).
    pub fn color_basis(&self) -> Basis<'a> {
        Basis::Quantized(self.color)
    }

    /// Shape basis layout.
    pub fn shape_layout(&self) -> Layout {
        self.header.dims.shape_layout
    }

    /// Colour basis layout.
    pub fn color_layout(&self) -> Layout {
        self.header.dims.color_layout
    }

    /// The metadata section's bytes (UTF-8 JSON, possibly empty).
    pub fn metadata(&self) -> &'a [u8] {
        self.metadata.as_bytes()
    }

    /// The metadata as text.
    pub fn metadata_str(&self) -> &'a str {
        self.metadata
    }

    /// The fitter's view of the model (checks lengths and indices once more).
    pub fn morphable(&self) -> Result<MorphableModel<'a, u16>, FitError> {
        MorphableModel::new(self.shape_mean, self.color_mean, self.shape_basis(), self.color_basis(), self.triangles, self.landmarks)
    }
}
