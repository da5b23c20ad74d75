//! Binary records over defmt: lines of `TAG <hex>`, 96 record bytes a line, which the host
//! joins and decodes (`gpmm_host::device::fit::tagged_hex`).

/// Record bytes logged per line.
const CHUNK: usize = 96;

/// Logs `bytes` as lowercase hex in lines `TAG <hex>`.
pub fn lines(tag: &str, bytes: &[u8]) {
    let mut hex = [0u8; 2 * CHUNK];
    for chunk in bytes.chunks(CHUNK) {
        for (pair, b) in hex.chunks_exact_mut(2).zip(chunk) {
            let digit = |v: u8| if v < 10 { b'0' + v } else { b'a' + v - 10 };
            pair.copy_from_slice(&[digit(b >> 4), digit(b & 15)]);
        }
        let text = hex.get(..2 * chunk.len()).and_then(|h| core::str::from_utf8(h).ok()).unwrap_or("");
        defmt::info!("{=str} {=str}", tag, text);
    }
}
