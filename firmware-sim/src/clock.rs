//! Time as instructions: SysTick under QEMU `-icount shift=0`.
//!
//! QEMU implements no DWT cycle counter. With `-icount shift=0` every instruction
//! advances virtual time by exactly 1 ns, and SysTick on the processor clock (the memory
//! map's `core_clock_hz`: mps2 25 MHz, netduinoplus2 168 MHz) ticks every 10⁹ / Hz ns
//! (40 instructions on mps2, 125/21 on netduinoplus2), deterministically. The 24-bit counter
//! wraps every 2^24 ticks; the SysTick exception counts the wraps, so [`ticks`] is a 64-bit
//! count since [`start`]. On a board the same code counts nanoseconds of the core clock instead.

use core::sync::atomic::{AtomicU32, Ordering};

use cortex_m::peripheral::{syst::SystClkSource, SYST};

/// Nanoseconds per `TICK_DEN` SysTick ticks: instructions under QEMU `-icount shift=0`.
const TICK_NS: u64 = 1_000_000_000;
/// SysTick ticks per second (the core clock).
const TICK_DEN: u64 = crate::board::MAP.core_clock_hz as u64;

/// Instructions (ns) in `ticks` SysTick ticks, rounded to nearest.
fn ticks_to_instructions(ticks: u64) -> u64 {
    (ticks * TICK_NS + TICK_DEN / 2) / TICK_DEN
}

const RELOAD: u32 = 0x00ff_ffff;
static WRAPS: AtomicU32 = AtomicU32::new(0);

/// Starts SysTick: processor clock, full 24-bit range, wrap interrupt on.
pub fn start(syst: &mut SYST) {
    syst.disable_counter();
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(RELOAD);
    syst.clear_current();
    syst.enable_interrupt();
    syst.enable_counter();
}

/// Called by the SysTick exception handler.
pub fn on_wrap() {
    WRAPS.fetch_add(1, Ordering::Relaxed);
}

/// Ticks since [`start`].
pub fn ticks() -> u64 {
    loop {
        let before = WRAPS.load(Ordering::Relaxed);
        let current = SYST::get_current();
        let after = WRAPS.load(Ordering::Relaxed);
        if before == after {
            return u64::from(before) * u64::from(RELOAD + 1) + u64::from(RELOAD - current);
        }
    }
}

/// SysTick current value register.
const SYST_CVR: u32 = 0xe000_e018;
/// Instructions per iteration of the polling loop in [`wait_edge`].
const POLL_INSTRUCTIONS: u64 = 4;

/// Spins until SysTick's counter changes (a tick edge); returns the number of polls.
#[inline(always)]
fn wait_edge() -> u32 {
    let polls: u32;
    // SAFETY: reads the SysTick current-value register (always mapped on Cortex-M);
    // registers only otherwise.
    unsafe {
        core::arch::asm!(
            "ldr {c0}, [{cvr}]",
            "movs {n}, #0",
            "2:",
            "adds {n}, {n}, #1",
            "ldr {v}, [{cvr}]",
            "cmp {v}, {c0}",
            "beq 2b",
            cvr = in(reg) SYST_CVR,
            c0 = out(reg) _,
            v = out(reg) _,
            n = out(reg) polls,
            options(nostack, readonly),
        );
    }
    polls
}

/// Raw measurement: ticks between two tick edges, and the polls spent waiting for the
/// second edge after `f` returned.
#[inline(always)]
fn measure_raw<R>(f: impl FnOnce() -> R) -> (R, u64, u32) {
    wait_edge();
    let t0 = ticks();
    let r = f();
    let polls = wait_edge();
    let t1 = ticks();
    (r, t1.wrapping_sub(t0), polls)
}

fn raw_instructions(ticks: u64, polls: u32) -> u64 {
    ticks_to_instructions(ticks).saturating_sub(u64::from(polls) * POLL_INSTRUCTIONS)
}

/// Instructions `f` executes, to within a few (the polling loop's length), whatever ran
/// before: the measurement starts on a tick edge and ends by counting the polls to the
/// next edge, and the overhead of an empty measurement is subtracted.
#[inline(never)]
pub fn measure<R>(f: impl FnOnce() -> R) -> (R, u64) {
    let (_, t, p) = measure_raw(|| core::hint::black_box(()));
    let overhead = raw_instructions(t, p);
    let (r, t, p) = measure_raw(f);
    (r, raw_instructions(t, p).saturating_sub(overhead))
}

/// `subs; bne` over `iterations` (2 instructions each, plus 1 to load the count).
#[inline(always)]
fn countdown(iterations: u32) {
    // SAFETY: a register-only countdown loop; touches no memory and no stack.
    unsafe {
        core::arch::asm!(
            "2:",
            "subs {n}, {n}, #1",
            "bne 2b",
            n = inout(reg) iterations => _,
            options(nomem, nostack),
        );
    }
}

/// A timed loop of known instruction count.
pub struct Calibration {
    /// Instructions the loop executes (2 per iteration).
    pub instructions: u32,
    /// SysTick ticks it took.
    pub ticks: u32,
    /// What [`measure`] reports for a loop of 2,000 instructions (expected: 2,000 or 2,001).
    pub measured_2000: u64,
}

impl Calibration {
    /// Ticks expected under QEMU `-icount shift=0`.
    pub fn expected_ticks(&self) -> u32 {
        (u64::from(self.instructions) * TICK_DEN / TICK_NS) as u32
    }

    /// Whether the measurement matches the core clock (within 0.1 %, which
    /// leaves room for the few instructions of the timer reads around the loop).
    pub fn ok(&self) -> bool {
        let expected = self.expected_ticks();
        self.ticks.abs_diff(expected) <= expected / 1000 + 1
    }
}

/// Times `subs; bne` over 1,000,000 iterations (2,000,000 instructions), and checks
/// [`measure`] on 1,000 iterations.
pub fn calibrate() -> Calibration {
    const ITERATIONS: u32 = 1_000_000;
    let t0 = ticks();
    countdown(core::hint::black_box(ITERATIONS));
    let t1 = ticks();
    let ((), measured_2000) = measure(|| countdown(core::hint::black_box(1_000)));
    Calibration { instructions: 2 * ITERATIONS, ticks: t1.wrapping_sub(t0) as u32, measured_2000 }
}

/// Instructions since the clock started (from SysTick ticks and the core clock).
pub(crate) fn instructions_now() -> u64 {
    ticks_to_instructions(ticks())
}
