//! Wire formats, each written and read by this one code on the host and on the device.
//!
//! - [`blob`]: the quantized model (`GPMB`, `docs/blob-format.md`);
//! - [`device_mesh`]: a mesh instance plus the scene to render it in (`GPDM`);
//! - `fit_input` (feature `serde`): the target image, its landmarks, the seed and the whole fit
//!   settings (`GPFI`);
//! - [`fit_record`]: the fit's result as the firmware reports it (`GPFR`);
//! - [`detection`]: a camera frame to detect the face in (`GPDF`) and the detection (`GPDR`);
//! - [`init_file`]: the landmark-free start's two networks and what they read (`GPMI`,
//!   `docs/init-format.md`);
//! - `frame_fit` (feature `serde`): the landmark-free fit's job (`GPFF`: working side, seed,
//!   settings) and the partition layout blob + job + init file + frame.
//!
//! All are little-endian, 4-byte aligned where read in place, and end in (or carry) a CRC-32.
//! Readers check everything before anything is used and return a [`FormatError`], never panic.
//! Writers write into a caller's buffer (no allocation) and say how long it must be.
//! The formats are documented in `docs/formats.md`.

pub mod blob;
pub mod bytes;
pub mod detection;
pub mod device_mesh;
#[cfg(feature = "serde")]
pub mod fit_input;
pub mod fit_record;
#[cfg(feature = "serde")]
pub mod frame_fit;
pub mod init_file;

use core::fmt;

/// Why bytes were refused by a reader or a writer of [`device_mesh`], `fit_input`, [`fit_record`],
/// [`detection`] or `frame_fit`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FormatError {
    /// The first four bytes are not the format's magic.
    BadMagic {
        /// The magic expected.
        expected: [u8; 4],
    },
    /// A version this code does not read.
    BadVersion {
        /// The version found.
        found: u32,
        /// The version this code reads.
        supported: u32,
    },
    /// A header field is out of its range (the name says which).
    BadField(&'static str),
    /// Fewer bytes than the header's sizes imply.
    Truncated {
        /// Bytes needed.
        needed: usize,
        /// Bytes present.
        available: usize,
    },
    /// The CRC-32 does not match the content.
    Crc {
        /// The stored CRC.
        stored: u32,
        /// The CRC of the content.
        computed: u32,
    },
    /// An array is not aligned for reading in place (copy the bytes into an aligned buffer).
    Misaligned,
    /// A writer's output buffer is too small.
    BufferTooSmall {
        /// Bytes needed.
        needed: usize,
    },
    /// More items than the reader's fixed capacity (the name says which).
    TooMany(&'static str),
    /// The settings payload could not be encoded or decoded.
    Payload,
}

impl fmt::Display for FormatError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            FormatError::BadMagic { expected } => {
                let m = core::str::from_utf8(&expected).unwrap_or("????");
                write!(f, "not a {m} section (the first four bytes are not {m})")
            }
            FormatError::BadVersion { found, supported } => {
                write!(f, "format version {found} is not supported (this gpmm reads version {supported})")
            }
            FormatError::BadField(name) => write!(f, "header field {name} is out of range"),
            FormatError::Truncated { needed, available } => {
                write!(f, "truncated: the header's sizes need {needed} bytes, only {available} are present")
            }
            FormatError::Crc { stored, computed } => {
                write!(f, "corrupted: CRC-32 mismatch (stored {stored:#010x}, computed {computed:#010x})")
            }
            FormatError::Misaligned => write!(f, "not 4-byte aligned in memory (copy it into an aligned buffer)"),
            FormatError::BufferTooSmall { needed } => write!(f, "the output buffer is too small ({needed} bytes needed)"),
            FormatError::TooMany(what) => write!(f, "more {what} than this build holds"),
            FormatError::Payload => write!(f, "the settings payload is malformed or does not fit"),
        }
    }
}

impl core::error::Error for FormatError {}
