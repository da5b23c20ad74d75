//! The model blob: a quantized morphable model as one little-endian byte image, read in place.
//!
//! The format is specified in `docs/blob-format.md`. In short: a 136-byte header (magic `GPMB`,
//! version, sizes, CRC-32, a table of 11 sections as offset + length), then the sections, each
//! starting at the next multiple of 16 bytes after the previous one, zero padding in between and
//! at the end. Means are `f32`, triangles `u16`, landmarks `u32`, bases integers (`i8` or `i16`)
//! with one `f32` scale per component (dequantized value = `scale_k · q`), plus one unit
//! direction per component in the factored layout.
//!
//! [`ModelBlob::parse`] checks everything before anything is used: magic, version, header size,
//! reserved bytes, every size with checked arithmetic, the section table (alignment, order,
//! lengths, bounds), the CRC-32, zero padding, finite means, scales and unit directions, triangle
//! and landmark indices, UTF-8 metadata. It never panics and never reads out of bounds; the arrays
//! are borrowed in place (`bytemuck` casts, which check alignment). The blob must start 4-byte
//! aligned in memory, otherwise [`BlobError::Misaligned`] (copy it into an aligned buffer).

use crate::checksum::crc32_update;
use crate::error::FitError;
use crate::geometry::Vec3;
use crate::model::MorphableModel;
use crate::model::{Basis, ModelError, QuantValues, QuantizedBasis};
use core::fmt;

/// The magic bytes at offset 0.
pub const MAGIC: [u8; 4] = *b"GPMB";
/// The format version this code reads and writes.
pub const VERSION: u16 = 1;
/// Number of sections in the table (version 1).
pub const SECTION_COUNT: usize = 11;
/// Bytes of the fixed header fields before the section table.
pub const FIXED_HEADER_BYTES: usize = 48;
/// Bytes of the header including the section table (version 1): 48 + 11 × 8.
pub const HEADER_BYTES: usize = FIXED_HEADER_BYTES + 8 * SECTION_COUNT;
/// Every section offset (and the total size) is a multiple of this.
pub const SECTION_ALIGN: usize = 16;
/// The alignment the blob's first byte needs in memory.
pub const START_ALIGN: usize = 4;
/// Byte offset of the CRC-32 field.
pub const CRC_OFFSET: usize = 12;
/// Most vertices a blob holds (triangle indices are `u16`).
pub const MAX_VERTICES: usize = 65535;
/// Longest metadata section in bytes.
pub const MAX_METADATA_BYTES: usize = 4096;
/// Largest tolerated deviation of a direction's length from 1.
pub const UNIT_TOLERANCE: f32 = 1e-3;

/// The sections, in table (and file) order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Section {
    /// Shape mean, `f32[N][3]` (mm).
    ShapeMean,
    /// Colour mean, `f32[N][3]` (linear RGB).
    ColorMean,
    /// Triangles, `u16[T][3]`.
    Triangles,
    /// Landmark vertex ids, `u32[L]`.
    Landmarks,
    /// Shape scales, `f32[Ks]`.
    ShapeScales,
    /// Shape directions, `f32[Ks][3]` (factored layout; empty when dense).
    ShapeDirections,
    /// Shape values, `i8`/`i16` `[Ks][N]` (factored) or `[Ks][N][3]` (dense).
    ShapeValues,
    /// Colour scales, `f32[Kc]`.
    ColorScales,
    /// Colour directions, `f32[Kc][3]` (factored layout; empty when dense).
    ColorDirections,
    /// Colour values, `i8`/`i16` `[Kc][N]` (factored) or `[Kc][N][3]` (dense).
    ColorValues,
    /// UTF-8 JSON metadata (may be empty).
    Metadata,
}

impl Section {
    /// All sections in table order.
    pub const ALL: [Section; SECTION_COUNT] = [
        Section::ShapeMean,
        Section::ColorMean,
        Section::Triangles,
        Section::Landmarks,
        Section::ShapeScales,
        Section::ShapeDirections,
        Section::ShapeValues,
        Section::ColorScales,
        Section::ColorDirections,
        Section::ColorValues,
        Section::Metadata,
    ];

    /// The section's name in messages and in `docs/blob-format.md`.
    pub fn name(self) -> &'static str {
        match self {
            Section::ShapeMean => "shape_mean",
            Section::ColorMean => "color_mean",
            Section::Triangles => "triangles",
            Section::Landmarks => "landmarks",
            Section::ShapeScales => "shape_scales",
            Section::ShapeDirections => "shape_directions",
            Section::ShapeValues => "shape_values",
            Section::ColorScales => "color_scales",
            Section::ColorDirections => "color_directions",
            Section::ColorValues => "color_values",
            Section::Metadata => "metadata",
        }
    }
}

/// How a part's basis is stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Layout {
    /// One scalar per vertex per component, times a unit direction per component (code 0).
    Factored,
    /// One 3-vector per vertex per component (code 1).
    Dense,
}

impl Layout {
    /// The header code.
    pub fn code(self) -> u8 {
        match self {
            Layout::Factored => 0,
            Layout::Dense => 1,
        }
    }

    /// The layout of a header code.
    pub fn from_code(code: u8) -> Option<Self> {
        match code {
            0 => Some(Layout::Factored),
            1 => Some(Layout::Dense),
            _ => None,
        }
    }

    /// `"factored"` or `"dense"`.
    pub fn name(self) -> &'static str {
        match self {
            Layout::Factored => "factored",
            Layout::Dense => "dense",
        }
    }
}

/// What is wrong with one section-table entry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SectionProblem {
    /// The offset is not a multiple of [`SECTION_ALIGN`].
    Misaligned,
    /// The section starts before the previous one (or the header) ends.
    Overlap,
    /// The section does not start at the first multiple of 16 after the previous one.
    Gap,
    /// The length disagrees with the header's sizes.
    Length {
        /// Bytes the sizes imply.
        expected: usize,
        /// Bytes in the table.
        found: u32,
    },
    /// The section ends past the blob's total size.
    OutOfBounds,
}

/// Why a blob was refused. Small and `Copy`; every message names the field concerned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BlobError {
    /// The blob does not start at a 4-byte aligned address.
    Misaligned,
    /// This machine is big-endian; the blob is little-endian and read in place.
    BigEndian,
    /// Fewer bytes than the header needs.
    TooShort {
        /// Bytes available.
        len: usize,
    },
    /// The first four bytes are not `GPMB`.
    BadMagic,
    /// A format version this code does not read.
    UnsupportedVersion(u16),
    /// The header size field is not [`HEADER_BYTES`].
    BadHeaderSize(u16),
    /// The section count field is not [`SECTION_COUNT`].
    BadSectionCount(u16),
    /// A reserved header byte is not zero.
    ReservedNotZero,
    /// Bits per value is neither 8 nor 16.
    BadBits(u8),
    /// A basis layout code is neither 0 (factored) nor 1 (dense).
    BadLayout(u8),
    /// Zero vertices or zero triangles.
    Empty,
    /// More than [`MAX_VERTICES`] vertices.
    TooManyVertices(u32),
    /// The sizes imply more bytes than the address space holds.
    Overflow,
    /// A section-table entry is inconsistent.
    Section {
        /// Which section.
        section: Section,
        /// What is wrong.
        problem: SectionProblem,
    },
    /// The total size field does not equal the end of the last section rounded up to 16.
    BadTotalSize {
        /// The header's total size.
        found: u32,
        /// What the sections imply.
        expected: usize,
    },
    /// The blob is longer than the bytes given (truncated).
    Truncated {
        /// The header's total size.
        total: u32,
        /// Bytes available.
        available: usize,
    },
    /// The CRC-32 does not match the content.
    Crc {
        /// The CRC in the header.
        stored: u32,
        /// The CRC of the content.
        computed: u32,
    },
    /// A padding byte between or after the sections is not zero.
    PaddingNotZero,
    /// A mean, scale or direction is NaN or infinite (or a scale is negative).
    NonFinite(Section),
    /// A direction is not a unit vector.
    NotUnit(Section),
    /// A triangle or landmark refers to a vertex that does not exist.
    IndexOutOfRange(Section),
    /// The metadata is longer than [`MAX_METADATA_BYTES`].
    MetadataTooLong(u32),
    /// The metadata is not UTF-8.
    MetadataNotUtf8,
}

impl fmt::Display for BlobError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            BlobError::Misaligned => write!(f, "model blob does not start at a 4-byte aligned address (copy it into an aligned buffer)"),
            BlobError::BigEndian => write!(f, "model blobs are little-endian and read in place; this machine is big-endian"),
            BlobError::TooShort { len } => write!(f, "model blob is {len} bytes, shorter than its {HEADER_BYTES}-byte header"),
            BlobError::BadMagic => write!(f, "not a gpmm model blob (magic is not GPMB)"),
            BlobError::UnsupportedVersion(v) => {
                write!(f, "model blob format version {v} is not supported (this gpmm reads version {VERSION})")
            }
            BlobError::BadHeaderSize(h) => write!(f, "model blob header size is {h} bytes, expected {HEADER_BYTES}"),
            BlobError::BadSectionCount(c) => write!(f, "model blob has {c} sections, expected {SECTION_COUNT}"),
            BlobError::ReservedNotZero => write!(f, "model blob header: a reserved byte is not zero"),
            BlobError::BadBits(b) => write!(f, "model blob header: {b} bits per basis value (8 or 16 expected)"),
            BlobError::BadLayout(c) => write!(f, "model blob header: basis layout code {c} (0 = factored or 1 = dense expected)"),
            BlobError::Empty => write!(f, "model blob has no vertices or no triangles"),
            BlobError::TooManyVertices(n) => write!(f, "model blob has {n} vertices, at most {MAX_VERTICES} are allowed"),
            BlobError::Overflow => write!(f, "model blob sizes overflow the address space"),
            BlobError::Section { section, problem } => {
                let name = section.name();
                match problem {
                    SectionProblem::Misaligned => write!(f, "model blob section {name}: offset is not a multiple of {SECTION_ALIGN}"),
                    SectionProblem::Overlap => write!(f, "model blob section {name}: overlaps the previous section or the header"),
                    SectionProblem::Gap => write!(f, "model blob section {name}: does not follow the previous section"),
                    SectionProblem::Length { expected, found } => {
                        write!(f, "model blob section {name}: {found} bytes, the header's sizes imply {expected}")
                    }
                    SectionProblem::OutOfBounds => write!(f, "model blob section {name}: ends past the blob's total size"),
                }
            }
            BlobError::BadTotalSize { found, expected } => {
                write!(f, "model blob total size field is {found} bytes, the sections imply {expected}")
            }
            BlobError::Truncated { total, available } => {
                write!(f, "model blob is truncated: its header says {total} bytes, only {available} are present")
            }
            BlobError::Crc { stored, computed } => {
                write!(f, "model blob is corrupted: CRC-32 mismatch (stored {stored:#010x}, computed {computed:#010x})")
            }
            BlobError::PaddingNotZero => write!(f, "model blob: a padding byte between sections is not zero"),
            BlobError::NonFinite(s) => write!(f, "model blob section {}: a value is NaN, infinite or (scales) negative", s.name()),
            BlobError::NotUnit(s) => write!(f, "model blob section {}: a direction is not a unit vector", s.name()),
            BlobError::IndexOutOfRange(s) => write!(f, "model blob section {}: a vertex index is out of range", s.name()),
            BlobError::MetadataTooLong(n) => write!(f, "model blob metadata is {n} bytes, at most {MAX_METADATA_BYTES} are allowed"),
            BlobError::MetadataNotUtf8 => write!(f, "model blob metadata is not UTF-8"),
        }
    }
}

impl core::error::Error for BlobError {}

/// The sizes a blob header declares; they determine every section's length.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BlobDims {
    /// Vertices `N` (1..=65535).
    pub vertices: u32,
    /// Triangles `T` (at least 1).
    pub triangles: u32,
    /// Landmarks `L`.
    pub landmarks: u32,
    /// Shape components `Ks`.
    pub rank_shape: u16,
    /// Colour components `Kc`.
    pub rank_color: u16,
    /// Bits per basis value (8 or 16).
    pub bits: u8,
    /// Shape basis layout.
    pub shape_layout: Layout,
    /// Colour basis layout.
    pub color_layout: Layout,
    /// Metadata bytes.
    pub metadata_bytes: u32,
}

/// One section-table entry: byte offset from the blob's start and byte length.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SectionEntry {
    /// Byte offset (a multiple of 16).
    pub offset: u32,
    /// Byte length.
    pub len: u32,
}

impl SectionEntry {
    /// The byte range (saturating; a parsed header's entries never saturate).
    pub fn range(&self) -> core::ops::Range<usize> {
        let start = self.offset as usize;
        start..start.saturating_add(self.len as usize)
    }
}

fn align_up(x: usize) -> Option<usize> {
    x.checked_next_multiple_of(SECTION_ALIGN)
}

impl BlobDims {
    /// The byte length section `s` must have (`None` if it overflows).
    pub fn section_len(&self, s: Section) -> Option<usize> {
        let n = self.vertices as usize;
        let width = usize::from(self.bits / 8);
        let part = |rank: u16, layout: Layout| -> (usize, usize, Option<usize>) {
            let k = usize::from(rank);
            let per_vertex = match layout {
                Layout::Factored => 1,
                Layout::Dense => 3,
            };
            let dirs = if layout == Layout::Factored { 12 * k } else { 0 };
            (4 * k, dirs, k.checked_mul(n).and_then(|v| v.checked_mul(per_vertex)).and_then(|v| v.checked_mul(width)))
        };
        let (ss, sd, sv) = part(self.rank_shape, self.shape_layout);
        let (cs, cd, cv) = part(self.rank_color, self.color_layout);
        match s {
            Section::ShapeMean | Section::ColorMean => n.checked_mul(12),
            Section::Triangles => (self.triangles as usize).checked_mul(6),
            Section::Landmarks => (self.landmarks as usize).checked_mul(4),
            Section::ShapeScales => Some(ss),
            Section::ShapeDirections => Some(sd),
            Section::ShapeValues => sv,
            Section::ColorScales => Some(cs),
            Section::ColorDirections => Some(cd),
            Section::ColorValues => cv,
            Section::Metadata => Some(self.metadata_bytes as usize),
        }
    }

    /// The canonical section table and total size: each section at the first multiple of 16
    /// after the previous one (the first after the header), the total rounded up to 16.
    pub fn layout(&self) -> Result<([SectionEntry; SECTION_COUNT], usize), BlobError> {
        let mut table = [SectionEntry::default(); SECTION_COUNT];
        let mut end = HEADER_BYTES;
        for (entry, s) in table.iter_mut().zip(Section::ALL) {
            let offset = align_up(end).ok_or(BlobError::Overflow)?;
            let len = self.section_len(s).ok_or(BlobError::Overflow)?;
            end = offset.checked_add(len).ok_or(BlobError::Overflow)?;
            *entry = SectionEntry {
                offset: u32::try_from(offset).map_err(|_| BlobError::Overflow)?,
                len: u32::try_from(len).map_err(|_| BlobError::Overflow)?,
            };
        }
        let total = align_up(end).ok_or(BlobError::Overflow)?;
        u32::try_from(total).map_err(|_| BlobError::Overflow)?;
        Ok((table, total))
    }

    /// The total blob size in bytes for these sizes (see [`BlobDims::layout`]).
    pub fn total_bytes(&self) -> Result<usize, BlobError> {
        self.layout().map(|(_, total)| total)
    }
}

/// A validated blob header (structure only: the CRC and the values are not checked yet).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BlobHeader {
    /// Format version.
    pub version: u16,
    /// Total blob size in bytes (the blob may sit at the start of a longer region).
    pub total_bytes: u32,
    /// The stored CRC-32.
    pub crc: u32,
    /// The declared sizes.
    pub dims: BlobDims,
    /// The section table.
    pub sections: [SectionEntry; SECTION_COUNT],
}

/// The stored and the computed CRC-32 of a blob.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CrcCheck {
    /// The CRC in the header.
    pub stored: u32,
    /// The CRC of the content.
    pub computed: u32,
}

impl CrcCheck {
    /// Whether they agree.
    pub fn ok(&self) -> bool {
        self.stored == self.computed
    }
}

impl BlobHeader {
    /// The table entry of section `s`.
    pub fn section(&self, s: Section) -> SectionEntry {
        let i = Section::ALL.iter().position(|&x| x == s).unwrap_or(0);
        self.sections.get(i).copied().unwrap_or_default()
    }

    /// Compares the stored CRC with the CRC of `bytes[..total_bytes]`.
    pub fn check_crc(&self, bytes: &[u8]) -> Result<CrcCheck, BlobError> {
        let blob =
            bytes.get(..self.total_bytes as usize).ok_or(BlobError::Truncated { total: self.total_bytes, available: bytes.len() })?;
        Ok(CrcCheck { stored: self.crc, computed: blob_crc(blob) })
    }
}

/// The CRC-32 (zlib/IEEE, as [`crate::checksum::crc32`]) of a whole blob with its CRC field taken as zero.
pub fn blob_crc(blob: &[u8]) -> u32 {
    let head = blob.get(..CRC_OFFSET).unwrap_or(blob);
    let field = blob.len().saturating_sub(CRC_OFFSET).min(4);
    let crc = crc32_update(0, head);
    let crc = crc32_update(crc, [0u8; 4].get(..field).unwrap_or(&[]));
    crc32_update(crc, blob.get(CRC_OFFSET + 4..).unwrap_or(&[]))
}

fn bytes_at<const K: usize>(b: &[u8], o: usize) -> Result<[u8; K], BlobError> {
    b.get(o..o.saturating_add(K)).and_then(|s| s.try_into().ok()).ok_or(BlobError::TooShort { len: b.len() })
}

fn u16_at(b: &[u8], o: usize) -> Result<u16, BlobError> {
    bytes_at(b, o).map(u16::from_le_bytes)
}

fn u32_at(b: &[u8], o: usize) -> Result<u32, BlobError> {
    bytes_at(b, o).map(u32::from_le_bytes)
}

fn u8_at(b: &[u8], o: usize) -> Result<u8, BlobError> {
    bytes_at::<1>(b, o).map(|[v]| v)
}

/// Reads and validates the header and section table of the blob at the start of `bytes`.
///
/// Checks magic, version, header size, section count, reserved bytes, bits, layouts, sizes
/// (checked arithmetic), every table entry (alignment, order, length, bounds) and the total
/// size against `bytes.len()`. Does not check the CRC, the padding or the values; alignment in
/// memory does not matter here.
pub fn parse_header(bytes: &[u8]) -> Result<BlobHeader, BlobError> {
    if bytes.len() < MAGIC.len() {
        return Err(BlobError::TooShort { len: bytes.len() });
    }
    if bytes.get(..4) != Some(&MAGIC[..]) {
        return Err(BlobError::BadMagic);
    }
    let version = u16_at(bytes, 4)?;
    if version != VERSION {
        return Err(BlobError::UnsupportedVersion(version));
    }
    let header_bytes = u16_at(bytes, 6)?;
    if usize::from(header_bytes) != HEADER_BYTES {
        return Err(BlobError::BadHeaderSize(header_bytes));
    }
    if bytes.len() < HEADER_BYTES {
        return Err(BlobError::TooShort { len: bytes.len() });
    }
    let total_bytes = u32_at(bytes, 8)?;
    let crc = u32_at(bytes, CRC_OFFSET)?;
    let section_count = u16_at(bytes, 36)?;
    if usize::from(section_count) != SECTION_COUNT {
        return Err(BlobError::BadSectionCount(section_count));
    }
    let reserved_zero = u8_at(bytes, 35)? == 0 && bytes.get(38..FIXED_HEADER_BYTES).is_some_and(|r| r.iter().all(|&b| b == 0));
    if !reserved_zero {
        return Err(BlobError::ReservedNotZero);
    }
    let bits = u8_at(bytes, 32)?;
    if bits != 8 && bits != 16 {
        return Err(BlobError::BadBits(bits));
    }
    let layout = |o| u8_at(bytes, o).and_then(|c| Layout::from_code(c).ok_or(BlobError::BadLayout(c)));
    let (shape_layout, color_layout) = (layout(33)?, layout(34)?);
    let mut sections = [SectionEntry::default(); SECTION_COUNT];
    for (i, e) in sections.iter_mut().enumerate() {
        let at = FIXED_HEADER_BYTES + 8 * i;
        *e = SectionEntry { offset: u32_at(bytes, at)?, len: u32_at(bytes, at + 4)? };
    }
    let metadata_bytes = sections.last().map_or(0, |e| e.len);
    let dims = BlobDims {
        vertices: u32_at(bytes, 16)?,
        triangles: u32_at(bytes, 20)?,
        landmarks: u32_at(bytes, 24)?,
        rank_shape: u16_at(bytes, 28)?,
        rank_color: u16_at(bytes, 30)?,
        bits,
        shape_layout,
        color_layout,
        metadata_bytes,
    };
    if dims.vertices == 0 || dims.triangles == 0 {
        return Err(BlobError::Empty);
    }
    if dims.vertices as usize > MAX_VERTICES {
        return Err(BlobError::TooManyVertices(dims.vertices));
    }
    if metadata_bytes as usize > MAX_METADATA_BYTES {
        return Err(BlobError::MetadataTooLong(metadata_bytes));
    }
    let total = total_bytes as usize;
    let mut end = HEADER_BYTES;
    for (e, section) in sections.iter().zip(Section::ALL) {
        let err = |problem| BlobError::Section { section, problem };
        let offset = e.offset as usize;
        if !offset.is_multiple_of(SECTION_ALIGN) {
            return Err(err(SectionProblem::Misaligned));
        }
        if offset < end {
            return Err(err(SectionProblem::Overlap));
        }
        if Some(offset) != align_up(end) {
            return Err(err(SectionProblem::Gap));
        }
        let expected = dims.section_len(section).ok_or(BlobError::Overflow)?;
        if expected != e.len as usize {
            return Err(err(SectionProblem::Length { expected, found: e.len }));
        }
        end = offset.checked_add(expected).ok_or(BlobError::Overflow)?;
        if end > total {
            return Err(err(SectionProblem::OutOfBounds));
        }
    }
    let expected_total = align_up(end).ok_or(BlobError::Overflow)?;
    if expected_total != total {
        return Err(BlobError::BadTotalSize { found: total_bytes, expected: expected_total });
    }
    if total > bytes.len() {
        return Err(BlobError::Truncated { total: total_bytes, available: bytes.len() });
    }
    Ok(BlobHeader { version, total_bytes, crc, dims, sections })
}

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
    /// A one-triangle model with one shape component laid out by [`BlobDims::layout`] and
    /// sealed by [`blob_crc`], parsed in place; the same bytes with one byte changed are refused:
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
