//! Stack high-water mark. With cortex-m-rt's `paint-stack` feature the reset handler
//! fills all RAM between the statics (`_stack_end`) and the initial stack pointer
//! (`_stack_start`) with `STACK_PAINT_VALUE`; the deepest word that no longer holds it
//! marks how far the stack has grown.

use cortex_m_rt::STACK_PAINT_VALUE;

extern "C" {
    static _stack_start: u32;
    static _stack_end: u32;
}

fn bounds() -> (usize, usize) {
    // Symbols of cortex-m-rt's link.x; only their addresses are taken.
    (core::ptr::addr_of!(_stack_end) as usize, core::ptr::addr_of!(_stack_start) as usize)
}

/// Bytes available to the stack (RAM less the statics).
pub fn size_bytes() -> u32 {
    let (low, high) = bounds();
    (high - low) as u32
}

/// Bytes of stack used so far: from the top down to the lowest overwritten word.
pub fn peak_bytes() -> u32 {
    let (low, high) = bounds();
    let mut addr = low;
    while addr < high {
        // SAFETY: [low, high) is RAM reserved for the stack, word-aligned (link.x asserts it).
        let word = unsafe { core::ptr::read_volatile(addr as *const u32) };
        if word != STACK_PAINT_VALUE {
            break;
        }
        addr += 4;
    }
    (high - addr) as u32
}

/// Paints the stack again below the current stack pointer (less a small margin for this call), so
/// that the next [`peak_bytes`] is the peak of what runs after it: the landmark-free fit measures
/// its detection and its crop + fit apart.
pub fn repaint() {
    let (low, _) = bounds();
    let sp = cortex_m::register::msp::read() as usize;
    let mut addr = low;
    while addr + 256 < sp {
        // SAFETY: [low, sp - 256) is stack RAM below every live frame (the stack grows down and
        // this function's frame is above sp - 256); nothing else uses it. Word-aligned.
        unsafe { core::ptr::write_volatile(addr as *mut u32, STACK_PAINT_VALUE) };
        addr += 4;
    }
}
