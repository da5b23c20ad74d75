//! The init file (`GPMI`, `docs/init-format.md`): the finder and the initializer networks of a
//! landmark-free start, the crop margin, and what the initializer's outputs mean.

use super::bytes::{check_crc, Reader, Writer};
use super::FormatError;
use crate::net::{NetError, Network};

/// The init file's magic.
pub const INIT_MAGIC: [u8; 4] = *b"GPMI";
/// The init file's format version.
pub const INIT_VERSION: u32 = 1;
/// Bytes of the init file's header.
pub const INIT_HEADER_BYTES: usize = 32;
/// Values per finder cell: face logit, centre x and y within the cell (0..1), log of the face size
/// over the finder's side.
pub const FINDER_CHANNELS: usize = 4;
/// Most landmarks an initializer reads.
pub const MAX_INIT_LANDMARKS: usize = 68;
/// Most light coefficients an initializer reads (9 SH coefficients × RGB).
pub const MAX_INIT_LIGHT: usize = 27;
/// Largest network output a detection holds (`f32` values).
pub const MAX_NET_OUTPUT: usize = 1024;

/// The finder, the initializer and what their outputs mean.
#[derive(Debug, Clone, Copy)]
pub struct InitFile<'a> {
    /// Whole frame (letterboxed) → per-cell face score, centre and size.
    pub finder: Network<'a>,
    /// Face crop → landmarks, pose, light.
    pub initializer: Network<'a>,
    /// Side of the initializer's square crop, in face sizes (the face size being the larger side
    /// of the landmarks' bounding box).
    pub crop_margin: f32,
    /// Number of landmarks the initializer reads.
    pub landmarks: usize,
    /// Number of light coefficients the initializer reads.
    pub light: usize,
    /// UTF-8 JSON written by the trainer (what it was trained on); readers do not depend on it.
    pub metadata: &'a str,
}

impl<'a> InitFile<'a> {
    /// Reads and checks an init file (magic, version, sizes, CRC, both networks, output sizes).
    ///
    /// # Examples
    ///
    /// Two one-layer networks over a 2 × 2 RGB image, written into an init file and read back in
    /// place; a changed byte is refused.
    ///
    /// ```
    /// use gpmm_core::format::init_file::{write_init_file, InitFile};
    /// use gpmm_core::format::FormatError;
    /// use gpmm_core::net::{network_header, LayerKind, LayerShape, NetError, Shape};
    ///
    /// /// A network of one layer with `f32` output: header, layer header, `i8` weights (padded to
    /// /// four bytes), then one multiplier and one bias per output channel.
    /// fn one_layer(input: Shape, shape: LayerShape) -> Vec<u8> {
    ///     let mut b = network_header(1, input).unwrap().to_vec();
    ///     b.extend(shape.header(0.0).unwrap());
    ///     b.resize(b.len() + shape.cout * shape.weights_per_output(), 1);
    ///     b.resize(b.len().next_multiple_of(4), 0);
    ///     (0..shape.cout).for_each(|_| b.extend(0.5f32.to_le_bytes()));
    ///     (0..shape.cout).for_each(|_| b.extend(0.0f32.to_le_bytes()));
    ///     b
    /// }
    /// let rgb = Shape { h: 2, w: 2, c: 3 };
    /// // The finder: four values per cell of a 2 × 2 grid.
    /// let finder = one_layer(rgb, LayerShape { kind: LayerKind::Conv, kernel: 1, stride: 1, relu: false, cin: 3, cout: 4 });
    /// // The initializer: one landmark (x, y), three angles and no light.
    /// let reader = one_layer(rgb, LayerShape { kind: LayerKind::Dense, kernel: 1, stride: 1, relu: false, cin: 12, cout: 5 });
    ///
    /// let mut bytes = vec![0u8; 512];
    /// let len = write_init_file(&mut bytes, &finder, &reader, 2.0, 1, 0, r#"{"trained_on":"example"}"#).unwrap();
    /// let file = InitFile::parse(&bytes[..len]).unwrap();
    /// assert_eq!((file.landmarks, file.light, file.crop_margin), (1, 0, 2.0));
    /// assert_eq!(file.finder.output(), Shape { h: 2, w: 2, c: 4 });
    /// assert_eq!(file.initializer.output().len(), 5);
    /// assert_eq!(file.metadata, r#"{"trained_on":"example"}"#);
    /// assert_eq!(InitFile::byte_len(&bytes).unwrap(), len);
    ///
    /// bytes[60] ^= 1;
    /// assert!(matches!(InitFile::parse(&bytes[..len]), Err(NetError::Format(FormatError::Crc { .. }))));
    /// ```
    pub fn parse(bytes: &'a [u8]) -> Result<Self, NetError> {
        let mut r = Reader::after_header(bytes, INIT_MAGIC, INIT_VERSION)?;
        let body = r.u32()? as usize;
        if body < INIT_HEADER_BYTES {
            return Err(FormatError::BadField("body_len").into());
        }
        check_crc(bytes, body)?;
        let landmarks = usize::from(r.u16()?);
        let light = usize::from(r.u16()?);
        let crop_margin = r.f32()?;
        let finder_len = r.u32()? as usize;
        let init_len = r.u32()? as usize;
        let meta_len = r.u32()? as usize;
        if landmarks == 0 || landmarks > MAX_INIT_LANDMARKS {
            return Err(FormatError::BadField("landmarks").into());
        }
        if light > MAX_INIT_LIGHT {
            return Err(FormatError::BadField("light").into());
        }
        if !(crop_margin.is_finite() && (1.0..=4.0).contains(&crop_margin)) {
            return Err(FormatError::BadField("crop_margin").into());
        }
        let section = |r: &mut Reader<'a>, len: usize| -> Result<Network<'a>, NetError> {
            let bytes = r.take(len)?;
            let (net, used) = Network::parse(bytes)?;
            if used != len {
                return Err(NetError::Layer("a network's length differs from the header's"));
            }
            r.align4()?;
            Ok(net)
        };
        let finder = section(&mut r, finder_len)?;
        let initializer = section(&mut r, init_len)?;
        let metadata = core::str::from_utf8(r.take(meta_len)?).map_err(|_| FormatError::BadField("metadata"))?;
        r.align4()?;
        if r.position() != body {
            return Err(FormatError::BadField("body_len").into());
        }
        let (fi, ii, fo, io) = (finder.input(), initializer.input(), finder.output(), initializer.output());
        if fi.c != 3 || ii.c != 3 || fi.h != fi.w || ii.h != ii.w {
            return Err(NetError::Layer("the networks' inputs must be square RGB images"));
        }
        if fo.c != FINDER_CHANNELS || fo.h != fo.w || fo.len() > MAX_NET_OUTPUT {
            return Err(NetError::Layer("the finder's output is not a square grid of 4 values per cell"));
        }
        if io.len() != 2 * landmarks + 3 + light {
            return Err(NetError::Layer("the initializer's output length is not 2 × landmarks + 3 + light"));
        }
        Ok(Self { finder, initializer, crop_margin, landmarks, light, metadata })
    }

    /// Bytes of the init file at the start of `bytes` by its header (`body_len` + 4 for the CRC);
    /// checks the magic and the version only ([`Self::parse`] checks the rest).
    pub fn byte_len(bytes: &[u8]) -> Result<usize, NetError> {
        let mut r = Reader::after_header(bytes, INIT_MAGIC, INIT_VERSION)?;
        Ok((r.u32()? as usize).saturating_add(4))
    }

    /// Bytes each scratch buffer needs for both networks.
    pub fn scratch_bytes(&self) -> usize {
        self.finder.scratch_bytes().max(self.initializer.scratch_bytes())
    }
}

/// Writes an init file around two encoded networks into `out`; returns its length.
pub fn write_init_file(
    out: &mut [u8],
    finder: &[u8],
    initializer: &[u8],
    crop_margin: f32,
    landmarks: u16,
    light: u16,
    metadata: &str,
) -> Result<usize, FormatError> {
    let pad = |n: usize| n.next_multiple_of(4);
    let body = INIT_HEADER_BYTES + pad(finder.len()) + pad(initializer.len()) + pad(metadata.len());
    let mut w = Writer::new(out);
    w.bytes(&INIT_MAGIC)?;
    w.u32(INIT_VERSION)?;
    w.u32(u32::try_from(body).map_err(|_| FormatError::BadField("body_len"))?)?;
    w.u16(landmarks)?;
    w.u16(light)?;
    w.f32(crop_margin)?;
    for len in [finder.len(), initializer.len(), metadata.len()] {
        w.u32(u32::try_from(len).map_err(|_| FormatError::BadField("section length"))?)?;
    }
    for part in [finder, initializer, metadata.as_bytes()] {
        w.bytes(part)?;
        w.align4()?;
    }
    w.finish_crc()
}
