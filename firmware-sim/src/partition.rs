//! The data partition: a fixed region of flash (`GPMM_DATA` in memory.x) that holds the
//! model blob, flashed separately from the program (QEMU: `-device loader`; a board:
//! probe-rs). The firmware reads it in place and validates whatever it finds there.

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

/// What the firmware checks of the partition so far.
pub struct Header {
    /// First 4 bytes, little-endian.
    pub magic: u32,
    /// FNV-1a of the first 256 bytes.
    pub head_fnv: u32,
}

/// `None` if the partition looks erased (nothing was flashed).
pub fn header(part: &[u8]) -> Option<Header> {
    let magic = u32::from_le_bytes(part.get(..4)?.try_into().ok()?);
    if ERASED.contains(&magic) {
        return None;
    }
    let mut head_fnv = 0x811c_9dc5u32;
    for b in part.iter().take(256) {
        head_fnv = (head_fnv ^ u32::from(*b)).wrapping_mul(0x0100_0193);
    }
    Some(Header { magic, head_fnv })
}
