//! The blob's header: the sizes it declares, the section table they lay out, the CRC, and the
//! reader that checks them all.

use crate::checksum::crc32_update;

use super::{
    BlobError, Layout, Section, SectionProblem, CRC_OFFSET, FIXED_HEADER_BYTES, HEADER_BYTES, MAGIC, MAX_METADATA_BYTES, MAX_VERTICES,
    SECTION_ALIGN, SECTION_COUNT, VERSION,
};

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
