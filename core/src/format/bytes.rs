//! The one set of little-endian byte readers and writers behind every wire format.

use super::FormatError;
use crate::checksum::crc32;

/// A little-endian reader over a byte slice that remembers its position; every read is checked.
#[derive(Debug, Clone)]
pub struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    /// A reader at the start of `bytes`.
    pub fn new(bytes: &'a [u8]) -> Self {
        Self { bytes, at: 0 }
    }

    /// Bytes read so far.
    pub fn position(&self) -> usize {
        self.at
    }

    /// A reader after the `magic` and `u32` `version` that `bytes` must start with.
    pub fn after_header(bytes: &'a [u8], magic: [u8; 4], version: u32) -> Result<Self, FormatError> {
        check_magic(bytes, magic)?;
        let mut r = Self::new(bytes);
        r.take(4)?;
        let found = r.u32()?;
        if found != version {
            return Err(FormatError::BadVersion { found, supported: version });
        }
        Ok(r)
    }

    /// The next `n` bytes.
    pub fn take(&mut self, n: usize) -> Result<&'a [u8], FormatError> {
        let end = self.at.checked_add(n).ok_or(FormatError::Truncated { needed: usize::MAX, available: self.bytes.len() })?;
        let s = self.bytes.get(self.at..end).ok_or(FormatError::Truncated { needed: end, available: self.bytes.len() })?;
        self.at = end;
        Ok(s)
    }

    /// The next `K` bytes as an array.
    pub fn array<const K: usize>(&mut self) -> Result<[u8; K], FormatError> {
        let s = self.take(K)?;
        let mut a = [0u8; K];
        a.copy_from_slice(s);
        Ok(a)
    }

    /// A `u16`.
    pub fn u16(&mut self) -> Result<u16, FormatError> {
        self.array().map(u16::from_le_bytes)
    }

    /// A `u32`.
    pub fn u32(&mut self) -> Result<u32, FormatError> {
        self.array().map(u32::from_le_bytes)
    }

    /// A `u64`.
    pub fn u64(&mut self) -> Result<u64, FormatError> {
        self.array().map(u64::from_le_bytes)
    }

    /// An `f32`.
    pub fn f32(&mut self) -> Result<f32, FormatError> {
        self.u32().map(f32::from_bits)
    }

    /// `out.len()` `f32`s.
    pub fn f32s(&mut self, out: &mut [f32]) -> Result<(), FormatError> {
        for v in out {
            *v = self.f32()?;
        }
        Ok(())
    }

    /// The next `count` items of `T` borrowed in place (the bytes must be aligned for `T`).
    pub fn slice<T: bytemuck::Pod>(&mut self, count: usize) -> Result<&'a [T], FormatError> {
        let n = count
            .checked_mul(core::mem::size_of::<T>())
            .ok_or(FormatError::Truncated { needed: usize::MAX, available: self.bytes.len() })?;
        bytemuck::try_cast_slice(self.take(n)?).map_err(|_| FormatError::Misaligned)
    }

    /// Skips to the next multiple of 4 (padding bytes are covered by the CRC, not checked here).
    pub fn align4(&mut self) -> Result<(), FormatError> {
        let pad = self.at.next_multiple_of(4) - self.at;
        self.take(pad).map(|_| ())
    }
}

/// A little-endian writer into a caller's buffer; every write is checked.
#[derive(Debug)]
pub struct Writer<'a> {
    out: &'a mut [u8],
    at: usize,
}

impl<'a> Writer<'a> {
    /// A writer at the start of `out`.
    pub fn new(out: &'a mut [u8]) -> Self {
        Self { out, at: 0 }
    }

    /// Bytes written so far.
    pub fn position(&self) -> usize {
        self.at
    }

    /// The unwritten rest of the buffer (for encoders that write in place; see [`Self::advance`]).
    pub fn rest(&mut self) -> &mut [u8] {
        self.out.get_mut(self.at..).unwrap_or(&mut [])
    }

    /// Marks `n` bytes of [`Self::rest`] as written.
    pub fn advance(&mut self, n: usize) -> Result<(), FormatError> {
        let end = self
            .at
            .checked_add(n)
            .filter(|&e| e <= self.out.len())
            .ok_or(FormatError::BufferTooSmall { needed: self.at.saturating_add(n) })?;
        self.at = end;
        Ok(())
    }

    /// Writes `bytes`.
    pub fn bytes(&mut self, bytes: &[u8]) -> Result<(), FormatError> {
        let end = self.at.saturating_add(bytes.len());
        let dst = self.out.get_mut(self.at..end).ok_or(FormatError::BufferTooSmall { needed: end })?;
        dst.copy_from_slice(bytes);
        self.at = end;
        Ok(())
    }

    /// Writes a `u16`.
    pub fn u16(&mut self, v: u16) -> Result<(), FormatError> {
        self.bytes(&v.to_le_bytes())
    }

    /// Writes a `u32`.
    pub fn u32(&mut self, v: u32) -> Result<(), FormatError> {
        self.bytes(&v.to_le_bytes())
    }

    /// Writes a `u64`.
    pub fn u64(&mut self, v: u64) -> Result<(), FormatError> {
        self.bytes(&v.to_le_bytes())
    }

    /// Writes an `f32`.
    pub fn f32(&mut self, v: f32) -> Result<(), FormatError> {
        self.bytes(&v.to_le_bytes())
    }

    /// Writes every `f32` of `vs`.
    pub fn f32s(&mut self, vs: impl IntoIterator<Item = f32>) -> Result<(), FormatError> {
        vs.into_iter().try_for_each(|v| self.f32(v))
    }

    /// Zero padding to the next multiple of 4.
    pub fn align4(&mut self) -> Result<(), FormatError> {
        while !self.at.is_multiple_of(4) {
            self.bytes(&[0])?;
        }
        Ok(())
    }

    /// Appends the CRC-32 of everything written so far; returns the total length.
    pub fn finish_crc(mut self) -> Result<usize, FormatError> {
        let crc = crc32(self.out.get(..self.at).unwrap_or(&[]));
        self.u32(crc)?;
        Ok(self.at)
    }
}

/// Checks the CRC-32 stored in the 4 bytes after `body` bytes of `bytes`.
pub fn check_crc(bytes: &[u8], body: usize) -> Result<(), FormatError> {
    let mut r = Reader::new(bytes);
    let head = r.take(body)?;
    let stored = r.u32()?;
    let computed = crc32(head);
    if stored == computed {
        Ok(())
    } else {
        Err(FormatError::Crc { stored, computed })
    }
}

/// Checks that `bytes` starts with `magic`.
pub fn check_magic(bytes: &[u8], magic: [u8; 4]) -> Result<(), FormatError> {
    if bytes.get(..4) == Some(&magic[..]) {
        Ok(())
    } else {
        Err(FormatError::BadMagic { expected: magic })
    }
}
