//! The data partition: a fixed region of flash (`GPMM_DATA` in memory.x) that holds the
//! model blob, flashed separately from the program (QEMU: `-device loader`; a board:
//! probe-rs). The firmware reads it in place and validates whatever it finds there
//! (the device mesh: `mesh.rs`).

/// Words that mean "nothing flashed": erased flash (0xFF) or QEMU's zeroed RAM.
const ERASED: [u32; 2] = [0xffff_ffff, 0x0000_0000];

extern "C" {
    static _gpmm_data_start: u8;
    static _gpmm_data_end: u8;
}

/// The whole partition, as bytes.
pub fn region() -> &'static [u8] {
    // SAFETY: the linker script defines both symbols as the bounds of GPMM_DATA, a
    // region of flash that nothing writes while the program runs; reading any byte of
    // it is defined (whatever was flashed there, or the erased value).
    unsafe {
        // Through integers: the region is not the 1-byte `static` the symbols are declared as.
        let start = core::ptr::addr_of!(_gpmm_data_start) as usize;
        let end = core::ptr::addr_of!(_gpmm_data_end) as usize;
        core::slice::from_raw_parts(start as *const u8, end - start)
    }
}

/// Whether nothing was flashed: the first word is erased flash (`0xFFFFFFFF`) or QEMU's
/// zeroed RAM (`0x00000000`), or the partition is shorter than a word.
pub fn is_erased(part: &[u8]) -> bool {
    match part.get(..4).and_then(|b| b.try_into().ok()) {
        Some(w) => ERASED.contains(&u32::from_le_bytes(w)),
        None => true,
    }
}
