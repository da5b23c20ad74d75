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

use core::fmt;

mod header;
mod view;

pub use header::{blob_crc, parse_header, BlobDims, BlobHeader, CrcCheck, SectionEntry};
pub use view::ModelBlob;

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
