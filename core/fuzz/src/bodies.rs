//! The bodies of the fuzz targets: one plain function of the input bytes per wire format, shared by
//! the cargo-fuzz targets (`fuzz_targets/*.rs`, long runs on nightly) and the stable test
//! `core/tests/fuzz.rs` (the seeds plus a few seconds of mutations in the test suite).
//!
//! Each body reads the bytes as given, 4-byte aligned (as in a flash partition), at an odd address,
//! and with the CRC the header implies fixed up, so mutations get past the checksum into the
//! structural and value checks. What parses is used the way the firmware or the host uses it.
//! Any panic is a bug: the core never panics on data.

use gpmm_core::checksum::crc32;
use gpmm_core::fit::{FitSettings, TargetImage};
use gpmm_core::format::blob::{blob_crc, ModelBlob, CRC_OFFSET};
use gpmm_core::format::init_file::InitFile;
use gpmm_core::format::{detection, fit_input, fit_record, frame_fit};
use gpmm_core::net::face::{detect, Reading};
use gpmm_core::net::NetScratch;
use gpmm_core::profile::M4F;

/// A target's body: runs on the input bytes, returns how many of its readings of them parsed.
pub type Body = fn(&[u8]) -> usize;

/// Every target: its name (the cargo-fuzz target and seed folder) and its body.
pub const TARGETS: [(&str, Body); 6] = [
    ("blob_parse", blob),
    ("init_file", init_file),
    ("fit_input", fit_input),
    ("frame_fit_job", frame_fit_job),
    ("detection", detection),
    ("fit_record", fit_record),
];

/// Bytes of each activation buffer the init-file body runs networks with (small: the fuzzer's
/// networks are small, and a larger one is refused with an error, which is also exercised).
const SCRATCH: usize = 4096;

/// `bytes` copied into a 4-byte aligned buffer (like a flash partition).
fn aligned(bytes: &[u8]) -> Vec<u32> {
    let mut words = vec![0u32; bytes.len().div_ceil(4)];
    bytemuck::cast_slice_mut::<u32, u8>(&mut words)[..bytes.len()].copy_from_slice(bytes);
    words
}

/// The little-endian `u32` at `at`, if there.
fn u32_at(bytes: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(bytes.get(at..at + 4)?.try_into().ok()?))
}

/// Runs `exercise` on `data` as given, aligned, at an odd address, and (when `body` says where
/// the header puts the CRC) aligned with that CRC recomputed; returns how many of these parsed.
fn each_placement(data: &[u8], body: Option<usize>, exercise: impl Fn(&[u8]) -> bool) -> usize {
    let mut parsed = usize::from(exercise(data));
    let words = aligned(data);
    parsed += usize::from(exercise(&bytemuck::cast_slice::<u32, u8>(&words)[..data.len()]));
    if data.len() > 1 {
        let odd = aligned(&[&[0u8][..], data].concat());
        parsed += usize::from(exercise(&bytemuck::cast_slice::<u32, u8>(&odd)[1..=data.len()]));
    }
    if let Some(end) = body.filter(|&b| b.checked_add(4).is_some_and(|e| e <= data.len())) {
        let mut words = aligned(data);
        let fixed = &mut bytemuck::cast_slice_mut::<u32, u8>(&mut words)[..data.len()];
        let crc = crc32(&fixed[..end]);
        fixed[end..end + 4].copy_from_slice(&crc.to_le_bytes());
        parsed += usize::from(exercise(fixed));
    }
    parsed
}

/// The model blob (`GPMB`): a blob that parses is used the way the fitter uses it.
pub fn blob(data: &[u8]) -> usize {
    let exercise = |bytes: &[u8]| {
        let Ok(blob) = ModelBlob::parse(bytes) else { return false };
        assert!(blob.len() <= bytes.len());
        assert_eq!(blob.shape_mean().len(), blob.vertices());
        let coeffs = [0.8f32, -1.3, 2.1, 0.4];
        let mut out = vec![[0.0f32; 3]; blob.vertices()];
        let ks = blob.rank_shape().min(coeffs.len());
        let kc = blob.rank_color().min(coeffs.len());
        blob.shape_basis().add_instance(&coeffs[..ks], &mut out).expect("lengths agree");
        blob.color_basis().add_instance(&coeffs[..kc], &mut out).expect("lengths agree");
        if let Ok(mm) = blob.morphable() {
            mm.shape_instance(&coeffs[..ks], &mut out).expect("shape instance");
            mm.color_instance(&coeffs[..kc], &mut out).expect("colour instance");
            let mut lm = vec![[0.0f32; 3]; mm.landmarks().len()];
            assert_eq!(mm.landmark_positions(&coeffs[..ks], &mut lm).expect("landmarks"), lm.len());
        }
        true
    };
    let mut parsed = each_placement(data, None, exercise);
    // The blob's CRC covers the blob the header claims, with the CRC field itself zeroed.
    if data.len() >= CRC_OFFSET + 4 {
        let total = u32_at(data, 8).unwrap_or(0) as usize;
        let mut words = aligned(data);
        let fixed = &mut bytemuck::cast_slice_mut::<u32, u8>(&mut words)[..data.len()];
        let end = total.min(fixed.len());
        let crc = blob_crc(&fixed[..end]);
        fixed[CRC_OFFSET..CRC_OFFSET + 4].copy_from_slice(&crc.to_le_bytes());
        parsed += usize::from(exercise(fixed));
    }
    parsed
}

/// The init file (`GPMI`): a file that parses runs its finder and initializer on a small frame
/// (the landmark-free start), when its activations fit the scratch.
pub fn init_file(data: &[u8]) -> usize {
    let exercise = |bytes: &[u8]| {
        let byte_len = InitFile::byte_len(bytes);
        let Ok(init) = InitFile::parse(bytes) else { return false };
        assert!(byte_len.is_ok_and(|n| n <= bytes.len()), "a parsed init file lies within its bytes");
        assert!(init.landmarks > 0 && init.initializer.output().len() == 2 * init.landmarks + 3 + init.light);
        let _ = (init.finder.macs(), init.initializer.macs(), init.finder.layer_count());
        if init.scratch_bytes() > SCRATCH {
            return true;
        }
        let mut scratch = Box::new(NetScratch::<SCRATCH>::new());
        let (w, h) = (11usize, 7usize);
        let rgb: Vec<u8> = (0..3 * w * h).map(|i| (i * 37 % 251) as u8).collect();
        for reading in [Reading::passes(1), Reading::DEFAULT] {
            if let Ok(Some(det)) = detect(&init, &rgb, w, h, 0.0, reading, &mut scratch) {
                assert_eq!(det.landmarks.len(), init.landmarks);
            }
        }
        true
    };
    each_placement(data, u32_at(data, 8).map(|b| b as usize), exercise)
}

/// Where the fit input's header puts its CRC (`None` when the sizes overflow).
fn fit_input_body(data: &[u8]) -> Option<usize> {
    let (w, h, count, s) = (u32_at(data, 8)?, u32_at(data, 12)?, u32_at(data, 16)?, u32_at(data, 20)?);
    let pixels = 3 * u128::from(w) * u128::from(h);
    let body = fit_input::HEADER_BYTES as u128 + u128::from(s).next_multiple_of(4) + 8 * u128::from(count) + pixels.next_multiple_of(4);
    usize::try_from(body).ok()
}

/// The fit input (`GPFI`) as the m4f firmware reads it: its settings are validated and its pixels
/// become the fit's target image.
pub fn fit_input(data: &[u8]) -> usize {
    let exercise = |bytes: &[u8]| {
        let Ok(input) = fit_input::parse::<FitSettings>(bytes, M4F.image_side, 68) else { return false };
        assert_eq!(input.pixels.len(), input.width as usize * input.height as usize);
        assert!(!input.landmarks.is_empty() && input.landmarks.len() <= 68);
        let _ = input.settings.validate();
        let image = TargetImage::new(input.pixels, input.width, input.height).expect("a parsed image is a target image");
        assert_eq!((image.width(), image.height()), (input.width, input.height));
        true
    };
    each_placement(data, fit_input_body(data), exercise)
}

/// The landmark-free fit job (`GPFF`) as the m4f firmware reads it, settings validated.
pub fn frame_fit_job(data: &[u8]) -> usize {
    let exercise = |bytes: &[u8]| {
        let Ok(job) = frame_fit::parse::<FitSettings>(bytes, M4F.frame_fit_side) else { return false };
        assert!(job.len <= bytes.len() && (frame_fit::MIN_SIDE..=M4F.frame_fit_side).contains(&job.side));
        let _ = job.settings.validate();
        assert!(frame_fit::next_section(job.len) >= job.len);
        true
    };
    let body = u32_at(data, 12).map(|s| frame_fit::HEADER_BYTES + (s as usize).next_multiple_of(4));
    each_placement(data, body, exercise)
}

/// The detection frame (`GPDF`) the firmware reads and the detection record (`GPDR`) the host
/// reads back; one target, the magic tells them apart.
pub fn detection(data: &[u8]) -> usize {
    let frame = |bytes: &[u8]| {
        let Ok(f) = detection::parse_frame(bytes) else { return false };
        assert_eq!(f.rgb.len(), 3 * f.width as usize * f.height as usize);
        assert!(detection::frame_len(f.width, f.height) <= bytes.len());
        assert!((0.0..=1.0).contains(&f.min_score) && f.refine <= detection::MAX_REFINE);
        true
    };
    let frame_body = match (u32_at(data, 8), u32_at(data, 12)) {
        (Some(w), Some(h)) => usize::try_from(3 * u128::from(w) * u128::from(h))
            .ok()
            .and_then(|p| p.checked_next_multiple_of(4))
            .and_then(|p| p.checked_add(detection::FRAME_HEADER_BYTES)),
        _ => None,
    };
    let frames = each_placement(data, frame_body, frame);
    let record = |bytes: &[u8]| {
        let Ok(r) = detection::parse_record(bytes) else { return false };
        assert!(r.landmarks.len() <= 2 * detection::MAX_RECORD_LANDMARKS && r.light.len() <= detection::MAX_RECORD_LIGHT);
        assert_eq!(r.landmarks.iter().count(), r.landmarks.len());
        let _ = r.light.iter().sum::<f32>();
        true
    };
    let record_body = match (u32_at(data, 12), u32_at(data, 16)) {
        (Some(l), Some(k)) => Some(detection::RECORD_HEADER_BYTES as u64 + 8 * u64::from(l) + 4 * u64::from(k)),
        _ => None,
    };
    frames + each_placement(data, record_body.and_then(|b| usize::try_from(b).ok()), record)
}

/// The fit record (`GPFR`) the host reads back from the firmware's log.
pub fn fit_record(data: &[u8]) -> usize {
    let exercise = |bytes: &[u8]| {
        let Ok(r) = fit_record::parse(bytes) else { return false };
        let (ks, kc, l) = (r.shape.len(), r.color.len(), r.landmarks.len());
        assert_eq!(l % 2, 0, "landmarks are x, y pairs");
        assert!(fit_record::encoded_len(ks, kc, l / 2) <= bytes.len());
        assert_eq!(r.shape.iter().count() + r.color.iter().count() + r.landmarks.iter().count(), ks + kc + l);
        true
    };
    let body = match (u32_at(data, 8), u32_at(data, 12), u32_at(data, 16)) {
        (Some(ks), Some(kc), Some(l)) => {
            let b = fit_record::HEADER_BYTES as u64 + 4 * (u64::from(ks) + u64::from(kc) + 2 * u64::from(l));
            usize::try_from(b).ok()
        }
        _ => None,
    };
    each_placement(data, body, exercise)
}
