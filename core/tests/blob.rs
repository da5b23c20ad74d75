//! The model blob parser: valid round trips, and every corruption an error, never a panic.
//!
//! Blobs are written by a compact encoder in this file (independent of the host's writer), into
//! `u32`-backed buffers so that they start 4-byte aligned like a flash partition.
#![allow(clippy::indexing_slicing, clippy::unwrap_used, clippy::expect_used)]

use gpmm_core::checksum::crc32;
use gpmm_core::format::blob::{
    blob_crc, parse_header, BlobDims, BlobError, Layout, ModelBlob, Section, SectionProblem, CRC_OFFSET, HEADER_BYTES, SECTION_COUNT,
};
use gpmm_core::model::{Basis, DenseBasis, FactoredBasis};
use proptest::prelude::*;

// ------------------------------------------------------------------ encoder

#[derive(Debug, Clone)]
struct Part {
    dense: bool,
    scales: Vec<f32>,
    dirs: Vec<[f32; 3]>,
    values: Vec<i16>,
}

#[derive(Debug, Clone)]
struct Model {
    bits: u8,
    shape_mean: Vec<[f32; 3]>,
    color_mean: Vec<[f32; 3]>,
    tris: Vec<[u16; 3]>,
    lms: Vec<u32>,
    shape: Part,
    color: Part,
    meta: Vec<u8>,
}

/// Offsets of the header fields (docs/blob-format.md).
mod at {
    pub const TOTAL: usize = 8;
    pub const VERTICES: usize = 16;
    pub const TRIANGLES: usize = 20;
    pub const LANDMARKS: usize = 24;
    pub const RANK_SHAPE: usize = 28;
    pub const BITS: usize = 32;
    pub const SHAPE_LAYOUT: usize = 33;
    pub const TABLE: usize = 48;
}

fn f32s(v: impl IntoIterator<Item = f32>) -> Vec<u8> {
    v.into_iter().flat_map(f32::to_le_bytes).collect()
}

fn part_sections(p: &Part, bits: u8) -> [Vec<u8>; 3] {
    let values =
        if bits == 8 { p.values.iter().map(|&q| q as i8 as u8).collect() } else { p.values.iter().flat_map(|q| q.to_le_bytes()).collect() };
    let dirs = if p.dense { Vec::new() } else { f32s(p.dirs.iter().flatten().copied()) };
    [f32s(p.scales.iter().copied()), dirs, values]
}

fn encode(m: &Model) -> Vec<u8> {
    let [ss, sd, sv] = part_sections(&m.shape, m.bits);
    let [cs, cd, cv] = part_sections(&m.color, m.bits);
    let sections: [Vec<u8>; SECTION_COUNT] = [
        f32s(m.shape_mean.iter().flatten().copied()),
        f32s(m.color_mean.iter().flatten().copied()),
        m.tris.iter().flatten().flat_map(|i| i.to_le_bytes()).collect(),
        m.lms.iter().flat_map(|i| i.to_le_bytes()).collect(),
        ss,
        sd,
        sv,
        cs,
        cd,
        cv,
        m.meta.clone(),
    ];
    let mut out = vec![0u8; HEADER_BYTES];
    let mut table = Vec::new();
    for s in &sections {
        out.resize(out.len().next_multiple_of(16), 0);
        table.push((out.len() as u32, s.len() as u32));
        out.extend_from_slice(s);
    }
    out.resize(out.len().next_multiple_of(16), 0);
    let total = out.len() as u32;
    out[..4].copy_from_slice(b"GPMB");
    out[4..6].copy_from_slice(&1u16.to_le_bytes());
    out[6..8].copy_from_slice(&(HEADER_BYTES as u16).to_le_bytes());
    put_u32(&mut out, at::TOTAL, total);
    put_u32(&mut out, at::VERTICES, m.shape_mean.len() as u32);
    put_u32(&mut out, at::TRIANGLES, m.tris.len() as u32);
    put_u32(&mut out, at::LANDMARKS, m.lms.len() as u32);
    out[28..30].copy_from_slice(&(m.shape.scales.len() as u16).to_le_bytes());
    out[30..32].copy_from_slice(&(m.color.scales.len() as u16).to_le_bytes());
    out[at::BITS] = m.bits;
    out[33] = u8::from(m.shape.dense);
    out[34] = u8::from(m.color.dense);
    out[36..38].copy_from_slice(&(SECTION_COUNT as u16).to_le_bytes());
    for (i, (o, l)) in table.into_iter().enumerate() {
        put_u32(&mut out, at::TABLE + 8 * i, o);
        put_u32(&mut out, at::TABLE + 8 * i + 4, l);
    }
    fix_crc(&mut out);
    out
}

fn put_u32(b: &mut [u8], at: usize, v: u32) {
    b[at..at + 4].copy_from_slice(&v.to_le_bytes());
}

/// Rewrites the CRC field (zlib CRC-32 of the blob with the field zeroed), as a forger would.
fn fix_crc(b: &mut [u8]) {
    b[CRC_OFFSET..CRC_OFFSET + 4].fill(0);
    let c = crc32(b);
    put_u32(b, CRC_OFFSET, c);
}

/// A 4-byte aligned copy of `bytes` starting `shift` bytes into a `u32` buffer.
struct Aligned {
    words: Vec<u32>,
    shift: usize,
    len: usize,
}

impl Aligned {
    fn new(bytes: &[u8], shift: usize) -> Self {
        let mut words = vec![0u32; (bytes.len() + shift).div_ceil(4) + 1];
        bytemuck::cast_slice_mut::<u32, u8>(&mut words)[shift..shift + bytes.len()].copy_from_slice(bytes);
        Self { words, shift, len: bytes.len() }
    }

    fn bytes(&self) -> &[u8] {
        &bytemuck::cast_slice::<u32, u8>(&self.words)[self.shift..self.shift + self.len]
    }
}

fn parse_copy(bytes: &[u8]) -> Result<(), BlobError> {
    let a = Aligned::new(bytes, 0);
    let blob = ModelBlob::parse(a.bytes())?;
    exercise(&blob);
    Ok(())
}

/// Uses a parsed view the way the fitter does; must never panic.
fn exercise(blob: &ModelBlob<'_>) {
    assert!(blob.len() <= blob.bytes().len() && blob.len().is_multiple_of(16));
    let n = blob.vertices();
    assert_eq!(blob.shape_mean().len(), n);
    let mut out = vec![[0.0f32; 3]; n];
    let coeffs = [0.5f32, -1.0, 2.0];
    let k = blob.rank_shape().min(3);
    blob.shape_basis().add_instance(&coeffs[..k], &mut out).unwrap();
    if let Ok(mm) = blob.morphable() {
        let mut lm = vec![[0.0f32; 3]; mm.landmarks().len()];
        mm.landmark_positions(&coeffs[..k], &mut lm).unwrap();
        let kc = blob.rank_color().min(3);
        mm.color_instance(&coeffs[..kc], &mut out).unwrap();
    }
}

// ------------------------------------------------------------------ models

/// splitmix64: deterministic model contents from a seed.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
    fn unit(&mut self) -> f32 {
        (self.next() >> 40) as f32 / (1u64 << 24) as f32
    }
}

#[derive(Debug, Clone, Copy)]
struct Dims {
    n: usize,
    t: usize,
    l: usize,
    ks: usize,
    kc: usize,
    bits: u8,
    shape_dense: bool,
    color_dense: bool,
    meta: usize,
}

fn part(rng: &mut Rng, k: usize, n: usize, dense: bool, bits: u8) -> Part {
    let qmax: i32 = if bits == 8 { 127 } else { 32767 };
    // Power-of-two scales: dequantized values are exact, so f32 and quantized sums agree exactly.
    let scales = (0..k).map(|_| 2f32.powi(-(rng.below(16) as i32))).collect();
    let dirs = (0..k)
        .map(|_| {
            let v = [rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() + 0.1];
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            v.map(|x| x / l)
        })
        .collect();
    let per = if dense { 3 } else { 1 };
    let values = (0..k * n * per).map(|_| (rng.below(2 * qmax as usize + 1) as i32 - qmax) as i16).collect();
    Part { dense, scales, dirs, values }
}

fn model(d: Dims, seed: u64) -> Model {
    let mut rng = Rng(seed);
    let n = d.n;
    Model {
        bits: d.bits,
        shape_mean: (0..n).map(|_| [rng.unit() * 100.0 - 50.0, rng.unit() * 100.0 - 50.0, rng.unit() * 40.0]).collect(),
        color_mean: (0..n).map(|_| [rng.unit(), rng.unit(), rng.unit()]).collect(),
        tris: (0..d.t).map(|_| [rng.below(n) as u16, rng.below(n) as u16, rng.below(n) as u16]).collect(),
        lms: (0..d.l).map(|_| rng.below(n) as u32).collect(),
        shape: part(&mut rng, d.ks, n, d.shape_dense, d.bits),
        color: part(&mut rng, d.kc, n, d.color_dense, d.bits),
        meta: format!("{{\"kernel\":\"test\",\"pad\":\"{}\"}}", "x".repeat(d.meta)).into_bytes(),
    }
}

fn small() -> Model {
    model(Dims { n: 9, t: 7, l: 4, ks: 3, kc: 2, bits: 16, shape_dense: false, color_dense: true, meta: 3 }, 7)
}

fn dims_strategy() -> impl Strategy<Value = Dims> {
    (1usize..40, 1usize..30, 0usize..10, 0usize..5, 0usize..5, prop::bool::ANY, prop::bool::ANY, prop::bool::ANY, 0usize..20).prop_map(
        |(n, t, l, ks, kc, b8, sd, cd, meta)| Dims {
            n,
            t,
            l,
            ks,
            kc,
            bits: if b8 { 8 } else { 16 },
            shape_dense: sd,
            color_dense: cd,
            meta,
        },
    )
}

/// The part's basis with dequantized `f32` values (the reference the quantized basis must equal).
fn float_basis(p: &Part, n: usize) -> (Vec<f32>, bool) {
    let per = if p.dense { 3 } else { 1 };
    (p.values.iter().enumerate().map(|(i, &q)| p.scales[i / (n * per)] * f32::from(q)).collect(), p.dense)
}

fn check_round_trip(m: &Model) {
    let bytes = encode(m);
    let a = Aligned::new(&bytes, 0);
    let blob = ModelBlob::parse(a.bytes()).unwrap();
    let n = m.shape_mean.len();
    assert_eq!(blob.len(), bytes.len());
    assert_eq!(blob.version(), 1);
    assert_eq!(blob.vertices(), n);
    assert_eq!(blob.triangles(), &m.tris[..]);
    assert_eq!(blob.landmarks(), &m.lms[..]);
    assert_eq!((blob.rank_shape(), blob.rank_color(), blob.bits()), (m.shape.scales.len(), m.color.scales.len(), m.bits));
    assert_eq!(blob.shape_mean(), &m.shape_mean[..]);
    assert_eq!(blob.color_mean(), &m.color_mean[..]);
    assert_eq!(blob.metadata(), &m.meta[..]);
    assert_eq!(blob.shape_layout() == Layout::Dense, m.shape.dense);
    // The header's table is the canonical layout.
    let h = parse_header(&bytes).unwrap();
    assert_eq!(BlobDims::layout(&h.dims).unwrap(), (h.sections, bytes.len()));
    assert_eq!(blob_crc(&bytes), h.crc);
    for (p, basis) in [(&m.shape, blob.shape_basis()), (&m.color, blob.color_basis())] {
        let (vals, dense) = float_basis(p, n);
        let reference = if dense {
            Basis::Dense(DenseBasis::new(&vals, p.scales.len(), n).unwrap())
        } else {
            Basis::Factored(FactoredBasis::new(&vals, &p.dirs, n).unwrap())
        };
        let coeffs: Vec<f32> = (0..p.scales.len()).map(|k| 0.75 - 0.5 * k as f32).collect();
        let (mut x, mut y) = (m.shape_mean.clone(), m.shape_mean.clone());
        reference.add_instance(&coeffs, &mut x).unwrap();
        basis.add_instance(&coeffs, &mut y).unwrap();
        assert_eq!(x, y);
        for v in [0, n - 1] {
            let mut p = m.shape_mean[v];
            basis.add_vertex(&coeffs, v, &mut p).unwrap();
            assert!((0..3).all(|a| (p[a] - y[v][a]).abs() <= 1e-4 * (1.0 + y[v][a].abs())), "{p:?} vs {:?}", y[v]);
        }
    }
    let mm = blob.morphable().unwrap();
    assert_eq!((mm.vertices(), mm.shape_rank(), mm.color_rank()), (n, m.shape.scales.len(), m.color.scales.len()));
    // A longer region (a flash partition) holding the blob at its start parses the same.
    let mut longer = bytes.clone();
    longer.extend_from_slice(&[0xff; 100]);
    let b = Aligned::new(&longer, 0);
    assert_eq!(ModelBlob::parse(b.bytes()).unwrap().len(), bytes.len());
}

// ------------------------------------------------------------------ properties

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    #[test]
    fn valid_blobs_round_trip(d in dims_strategy(), seed in any::<u64>()) {
        check_round_trip(&model(d, seed));
    }

    /// Arbitrary bytes never panic.
    #[test]
    fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..600)) {
        prop_assert!(parse_copy(&bytes).is_err());
    }

    /// Random overwrites anywhere in a valid blob, with the CRC fixed up: an error or a view
    /// that is safe to use, never a panic.
    #[test]
    fn forged_blobs_never_panic(d in dims_strategy(), seed in any::<u64>(), edits in prop::collection::vec((any::<prop::sample::Index>(), any::<u32>()), 1..4)) {
        let mut b = encode(&model(d, seed));
        for (i, v) in edits {
            let at = i.index(b.len().saturating_sub(3));
            let w = b.len().min(at + 4);
            b[at..w].copy_from_slice(&v.to_le_bytes()[..w - at]);
        }
        fix_crc(&mut b);
        let _ = parse_copy(&b);
    }

    /// Random header words (sizes, offsets, lengths), CRC fixed: never a panic.
    #[test]
    fn forged_headers_never_panic(seed in any::<u64>(), words in prop::collection::vec((4usize..34, any::<u32>()), 1..6)) {
        let mut b = encode(&model(Dims { n: 12, t: 5, l: 3, ks: 2, kc: 2, bits: 8, shape_dense: false, color_dense: false, meta: 0 }, seed));
        for (w, v) in words {
            put_u32(&mut b, 4 * w, v);
        }
        fix_crc(&mut b);
        let _ = parse_copy(&b);
    }
}

#[test]
fn every_bit_flip_is_an_error() {
    for m in [small(), model(Dims { n: 5, t: 3, l: 2, ks: 1, kc: 4, bits: 8, shape_dense: true, color_dense: false, meta: 0 }, 3)] {
        let bytes = encode(&m);
        parse_copy(&bytes).unwrap();
        for i in 0..bytes.len() {
            for bit in 0..8 {
                let mut b = bytes.clone();
                b[i] ^= 1 << bit;
                let e = parse_copy(&b).unwrap_err();
                // Past the header's sizes, the CRC is what catches it.
                if i >= CRC_OFFSET {
                    if i >= HEADER_BYTES {
                        assert!(matches!(e, BlobError::Crc { .. }), "flip at byte {i} bit {bit}: {e}");
                    }
                } else {
                    assert!(!matches!(e, BlobError::Misaligned), "flip at byte {i}: {e}");
                }
            }
        }
    }
}

#[test]
fn every_truncation_is_an_error() {
    let bytes = encode(&small());
    for len in 0..bytes.len() {
        let e = parse_copy(&bytes[..len]).unwrap_err();
        if len >= HEADER_BYTES {
            assert_eq!(e, BlobError::Truncated { total: bytes.len() as u32, available: len });
        } else {
            assert!(matches!(e, BlobError::TooShort { .. }), "{len}: {e}");
        }
    }
}

#[test]
fn unaligned_start_is_an_error_not_a_panic() {
    let bytes = encode(&small());
    for shift in 1..4 {
        let a = Aligned::new(&bytes, shift);
        assert_eq!(ModelBlob::parse(a.bytes()).unwrap_err(), BlobError::Misaligned);
        // The header alone does not need alignment (inspect reads it from any buffer).
        assert!(parse_header(a.bytes()).is_ok());
    }
    assert!(ModelBlob::parse(Aligned::new(&bytes, 4).bytes()).is_ok());
}

/// Edits `b` (a valid blob) with `f`, fixes the CRC and returns the parse error.
fn forged(f: impl FnOnce(&mut Vec<u8>)) -> BlobError {
    let mut b = encode(&small());
    f(&mut b);
    fix_crc(&mut b);
    parse_copy(&b).unwrap_err()
}

fn table(s: Section) -> usize {
    at::TABLE + 8 * Section::ALL.iter().position(|&x| x == s).unwrap()
}

fn get_u32(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
}

fn add_u32(b: &mut [u8], at: usize, delta: i64) {
    let v = i64::from(get_u32(b, at)) + delta;
    put_u32(b, at, v as u32);
}

#[test]
fn hostile_headers_are_errors() {
    use SectionProblem as P;
    let sec = |section, problem| BlobError::Section { section, problem };
    assert_eq!(forged(|b| b[0] = b'X'), BlobError::BadMagic);
    assert_eq!(forged(|b| b[4] = 2), BlobError::UnsupportedVersion(2));
    assert_eq!(forged(|b| b[6] = 128), BlobError::BadHeaderSize(128));
    assert_eq!(forged(|b| b[36] = 12), BlobError::BadSectionCount(12));
    assert_eq!(forged(|b| b[35] = 1), BlobError::ReservedNotZero);
    assert_eq!(forged(|b| b[47] = 1), BlobError::ReservedNotZero);
    assert_eq!(forged(|b| b[at::BITS] = 7), BlobError::BadBits(7));
    assert_eq!(forged(|b| b[at::SHAPE_LAYOUT] = 2), BlobError::BadLayout(2));
    assert_eq!(forged(|b| put_u32(b, at::VERTICES, 0)), BlobError::Empty);
    assert_eq!(forged(|b| put_u32(b, at::TRIANGLES, 0)), BlobError::Empty);
    assert_eq!(forged(|b| put_u32(b, at::VERTICES, u32::MAX)), BlobError::TooManyVertices(u32::MAX));
    assert_eq!(forged(|b| put_u32(b, at::VERTICES, 65536)), BlobError::TooManyVertices(65536));
    // Sizes that disagree with the table, including products that overflow 32 bits.
    assert_eq!(forged(|b| put_u32(b, at::VERTICES, 10)), sec(Section::ShapeMean, P::Length { expected: 120, found: 108 }));
    assert_eq!(
        forged(|b| put_u32(b, at::LANDMARKS, u32::MAX)),
        sec(Section::Landmarks, P::Length { expected: 4 * u32::MAX as usize, found: 16 })
    );
    let e = forged(|b| {
        put_u32(b, at::VERTICES, 65535);
        b[at::RANK_SHAPE..at::RANK_SHAPE + 2].copy_from_slice(&u16::MAX.to_le_bytes());
        b[at::SHAPE_LAYOUT] = 1;
    });
    assert!(matches!(e, BlobError::Section { section: Section::ShapeMean, problem: P::Length { .. } } | BlobError::Overflow), "{e}");
    assert!(matches!(
        forged(|b| put_u32(b, table(Section::ShapeValues) + 4, u32::MAX)),
        BlobError::Section { section: Section::ShapeValues, problem: P::Length { .. } }
    ));
    // Offsets: misaligned, overlapping, past the end, gaps.
    assert_eq!(forged(|b| add_u32(b, table(Section::ColorMean), 4)), sec(Section::ColorMean, P::Misaligned));
    assert_eq!(forged(|b| add_u32(b, table(Section::ColorMean), -16)), sec(Section::ColorMean, P::Overlap));
    assert_eq!(forged(|b| put_u32(b, table(Section::ShapeMean), 128)), sec(Section::ShapeMean, P::Overlap));
    assert_eq!(forged(|b| add_u32(b, table(Section::Triangles), 16)), sec(Section::Triangles, P::Gap));
    assert_eq!(forged(|b| put_u32(b, table(Section::Metadata), 0xffff_fff0)), sec(Section::Metadata, P::Gap));
    assert_eq!(forged(|b| put_u32(b, at::TOTAL, 160)), sec(Section::ShapeMean, P::OutOfBounds));
    let e = forged(|b| add_u32(b, at::TOTAL, 16));
    assert!(matches!(e, BlobError::BadTotalSize { .. }), "{e}");
    let e = forged(|b| put_u32(b, at::TOTAL, u32::MAX));
    assert!(matches!(e, BlobError::BadTotalSize { .. }), "{e}");
    // Values.
    let field = |b: &[u8], s: Section| get_u32(b, table(s)) as usize;
    assert_eq!(
        forged(|b| {
            let o = field(b, Section::ShapeScales);
            b[o..o + 4].copy_from_slice(&f32::NAN.to_le_bytes())
        }),
        BlobError::NonFinite(Section::ShapeScales)
    );
    assert_eq!(
        forged(|b| {
            let o = field(b, Section::ColorScales) + 4;
            b[o..o + 4].copy_from_slice(&(-1.0f32).to_le_bytes())
        }),
        BlobError::NonFinite(Section::ColorScales)
    );
    assert_eq!(
        forged(|b| {
            let o = field(b, Section::ShapeMean) + 8;
            b[o..o + 4].copy_from_slice(&f32::INFINITY.to_le_bytes())
        }),
        BlobError::NonFinite(Section::ShapeMean)
    );
    assert_eq!(
        forged(|b| {
            let o = field(b, Section::ColorMean);
            b[o..o + 4].copy_from_slice(&f32::NAN.to_le_bytes())
        }),
        BlobError::NonFinite(Section::ColorMean)
    );
    assert_eq!(
        forged(|b| {
            let o = field(b, Section::ShapeDirections);
            b[o..o + 4].copy_from_slice(&f32::NAN.to_le_bytes())
        }),
        BlobError::NonFinite(Section::ShapeDirections)
    );
    assert_eq!(
        forged(|b| {
            let o = field(b, Section::ShapeDirections) + 12;
            b[o..o + 12].copy_from_slice(&[0; 12])
        }),
        BlobError::NotUnit(Section::ShapeDirections)
    );
    assert_eq!(
        forged(|b| {
            let o = field(b, Section::Triangles) + 4;
            b[o..o + 2].copy_from_slice(&9u16.to_le_bytes())
        }),
        BlobError::IndexOutOfRange(Section::Triangles)
    );
    assert_eq!(
        forged(|b| {
            let o = field(b, Section::Landmarks) + 4;
            put_u32(b, o, u32::MAX)
        }),
        BlobError::IndexOutOfRange(Section::Landmarks)
    );
    assert_eq!(
        forged(|b| {
            let o = field(b, Section::Metadata);
            b[o] = 0xff
        }),
        BlobError::MetadataNotUtf8
    );
    assert_eq!(forged(|b| put_u32(b, table(Section::Metadata) + 4, 5000)), BlobError::MetadataTooLong(5000));
    // Padding after the header, between sections, at the end.
    assert_eq!(forged(|b| b[HEADER_BYTES] = 1), BlobError::PaddingNotZero);
    assert_eq!(
        forged(|b| {
            let o = field(b, Section::ColorMean);
            b[o - 1] = 1
        }),
        BlobError::PaddingNotZero
    );
    assert_eq!(
        forged(|b| {
            let l = b.len();
            b[l - 1] = 1
        }),
        BlobError::PaddingNotZero
    );
    // The same edits without a CRC fix-up are caught by the CRC first.
    let mut b = encode(&small());
    b[HEADER_BYTES] = 1;
    assert!(matches!(parse_copy(&b), Err(BlobError::Crc { .. })));
}

#[test]
fn crc_is_over_the_blob_with_the_field_zeroed() {
    let bytes = encode(&small());
    let h = parse_header(&bytes).unwrap();
    let mut zeroed = bytes.clone();
    zeroed[CRC_OFFSET..CRC_OFFSET + 4].fill(0);
    assert_eq!(h.crc, crc32(&zeroed));
    assert_eq!(blob_crc(&bytes), h.crc);
    let mut b = bytes.clone();
    b[200] ^= 4;
    let c = parse_header(&b).unwrap().check_crc(&b).unwrap();
    assert!(!c.ok());
    assert_eq!(ModelBlob::parse(Aligned::new(&b, 0).bytes()).unwrap_err(), BlobError::Crc { stored: c.stored, computed: c.computed });
    // Messages name what is wrong.
    let msg = BlobError::Crc { stored: 1, computed: 2 }.to_string();
    assert!(msg.contains("CRC-32 mismatch") && msg.contains("0x00000001"), "{msg}");
    let msg = BlobError::Section { section: Section::ShapeValues, problem: SectionProblem::Misaligned }.to_string();
    assert!(msg.contains("shape_values") && msg.contains("multiple of 16"), "{msg}");
}

#[test]
fn size_formula_matches_the_docs() {
    // docs/blob-format.md, worked example: N = 1000, T = 1900, L = 68, rank 50/50 factored, 16 bits, 300 bytes of metadata.
    let d = BlobDims {
        vertices: 1000,
        triangles: 1900,
        landmarks: 68,
        rank_shape: 50,
        rank_color: 50,
        bits: 16,
        shape_layout: Layout::Factored,
        color_layout: Layout::Factored,
        metadata_bytes: 300,
    };
    assert_eq!(d.total_bytes().unwrap(), 237_760);
    check_round_trip(&small());
}

/// The fuzz corpus seeds (core/fuzz/seeds/) are the blobs this encoder writes for two small
/// models; regenerate them with `GPMM_WRITE_FUZZ_SEEDS=1 cargo test -p gpmm-core --test blob`.
#[test]
fn fuzz_seeds_are_current() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/seeds/blob_parse");
    let seeds = [
        ("factored-i16.blob", encode(&small())),
        (
            "dense-i8.blob",
            encode(&model(Dims { n: 6, t: 4, l: 3, ks: 2, kc: 1, bits: 8, shape_dense: true, color_dense: false, meta: 0 }, 11)),
        ),
    ];
    for (name, bytes) in seeds {
        parse_copy(&bytes).unwrap();
        assert!(bytes.len() < 10_000);
        let path = dir.join(name);
        if std::env::var_os("GPMM_WRITE_FUZZ_SEEDS").is_some() {
            std::fs::create_dir_all(&dir).unwrap();
            std::fs::write(&path, &bytes).unwrap();
        }
        let on_disk = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e} (regenerate with GPMM_WRITE_FUZZ_SEEDS=1)", path.display()));
        assert_eq!(on_disk, bytes, "{} is stale (regenerate with GPMM_WRITE_FUZZ_SEEDS=1)", path.display());
    }
}
