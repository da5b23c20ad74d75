//! Fuzzes the model blob parser: arbitrary bytes, and the same bytes with the CRC fixed up (so
//! mutations get past the checksum into the structural and value checks). A blob that parses is
//! used the way the fitter uses it. Any panic is a bug.
#![no_main]

use gpmm_core::format::blob::{blob_crc, ModelBlob, CRC_OFFSET};
use libfuzzer_sys::fuzz_target;

/// `bytes` copied into a 4-byte aligned buffer (like a flash partition).
fn aligned(bytes: &[u8]) -> Vec<u32> {
    let mut words = vec![0u32; bytes.len().div_ceil(4)];
    bytemuck::cast_slice_mut::<u32, u8>(&mut words)[..bytes.len()].copy_from_slice(bytes);
    words
}

fn exercise(bytes: &[u8]) {
    let Ok(blob) = ModelBlob::parse(bytes) else { return };
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
}

fuzz_target!(|data: &[u8]| {
    // As given (libFuzzer's buffer may or may not be 4-aligned: either an error or a view).
    exercise(data);
    // Aligned, and at an odd address.
    let words = aligned(data);
    let bytes = &bytemuck::cast_slice::<u32, u8>(&words)[..data.len()];
    exercise(bytes);
    if data.len() > 1 {
        let _ = ModelBlob::parse(&bytes[1..]);
    }
    // With the CRC of the blob the header claims fixed up.
    if data.len() >= CRC_OFFSET + 4 {
        let total = u32::from_le_bytes([data[8], data[9], data[10], data[11]]) as usize;
        let mut words = aligned(data);
        let fixed = &mut bytemuck::cast_slice_mut::<u32, u8>(&mut words)[..data.len()];
        let end = total.min(fixed.len());
        let crc = blob_crc(&fixed[..end]);
        fixed[CRC_OFFSET..CRC_OFFSET + 4].copy_from_slice(&crc.to_le_bytes());
        exercise(fixed);
    }
});
