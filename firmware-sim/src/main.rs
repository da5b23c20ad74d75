//! gpmm firmware, simulated: Cortex-M4F under QEMU (mps2-an386), or on a board.
//!
//! What it does now (the infrastructure later work fills):
//! 1. calibrates SysTick against a loop of known instruction count (under QEMU with
//!    `-icount shift=0` one SysTick tick is 40 instructions: 1 instruction = 1 ns of
//!    virtual time, SysTick runs on the 25 MHz system clock);
//! 2. reads the header of the data partition (`GPMM_DATA` in memory.x), flashed
//!    separately from the program;
//! 3. runs a workload from gpmm-core (a model instance from a factored basis) and
//!    measures its instructions (`clock::measure`, within ±4);
//! 4. measures the stack's high-water mark (cortex-m-rt's `paint-stack`);
//! 5. logs `key=value` figures with defmt over semihosting and exits through
//!    semihosting: status 0 on success, 1 on any failure (panic, fault, bad calibration).
#![no_std]
#![no_main]

mod clock;
mod partition;
mod stack;

use core::hint::black_box;

use cortex_m_rt::{entry, exception, ExceptionFrame};
use defmt_semihosting as _; // the global defmt logger: frames go to the host's stdout
use gpmm_core::{FactoredBasis, Vec3};

/// The device profile this image was linked for (memory.x or memory-m7.x).
const PROFILE: &str = if cfg!(feature = "m7") { "m7" } else { "m4f" };

/// Vertices and rank of the stand-in workload.
const VERTICES: usize = 256;
const RANK: usize = 16;

/// Deterministic pseudo-random values in [-1, 1), computed at compile time (lives in flash).
const fn pattern<const N: usize>(seed: u32) -> [f32; N] {
    let mut out = [0.0f32; N];
    let mut state = seed;
    let mut i = 0;
    while i < N {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        out[i] = (state % 2000) as f32 / 1000.0 - 1.0;
        i += 1;
    }
    out
}

static FIELDS: [f32; VERTICES * RANK] = pattern(0x9e37_79b9);
static DIRECTIONS: [Vec3; RANK] = {
    let raw: [f32; RANK * 3] = pattern(0x85eb_ca6b);
    let mut d = [[0.0f32; 3]; RANK];
    let mut k = 0;
    while k < RANK {
        d[k] = [raw[3 * k], raw[3 * k + 1], raw[3 * k + 2]];
        k += 1;
    }
    d
};

/// The measured workload: one model instance (`VERTICES × RANK` multiply-adds per axis).
/// Returns an FNV-1a checksum over the bits of the result.
#[inline(never)]
fn workload() -> Result<u32, gpmm_core::ModelError> {
    let basis = FactoredBasis::new(black_box(&FIELDS[..]), black_box(&DIRECTIONS[..]), VERTICES)?;
    let coeffs: [f32; RANK] = black_box(pattern(0xc2b2_ae35));
    let mut instance = [[0.0f32; 3]; VERTICES];
    basis.add_instance(&coeffs, &mut instance)?;
    let mut hash = 0x811c_9dc5u32;
    for v in black_box(&instance) {
        for x in v {
            for b in x.to_bits().to_le_bytes() {
                hash = (hash ^ u32::from(b)).wrapping_mul(0x0100_0193);
            }
        }
    }
    Ok(hash)
}

#[entry]
fn main() -> ! {
    let mut core = cortex_m::Peripherals::take().unwrap_or_else(|| fail());
    clock::start(&mut core.SYST);

    defmt::info!("gpmm-firmware-sim {=str} profile={=str}", env!("CARGO_PKG_VERSION"), PROFILE);

    // 1. SysTick against a loop of known length.
    let cal = clock::calibrate();
    defmt::info!(
        "calib_instructions={=u32} calib_ticks={=u32} instructions_per_tick={=u32} calib_measured_2000={=u64}",
        cal.instructions,
        cal.ticks,
        clock::INSTRUCTIONS_PER_TICK,
        cal.measured_2000
    );
    if !cal.ok() {
        defmt::error!(
            "SysTick does not count instructions (expected {=u32} ticks): run QEMU with -icount shift=0",
            cal.expected_ticks()
        );
        fail();
    }

    // 2. The data partition.
    let part = partition::region();
    defmt::info!("data_partition_addr=0x{=u32:08x} data_partition_bytes={=u32}", part.as_ptr() as u32, part.len() as u32);
    match partition::header(part) {
        Some(h) => defmt::info!("data_magic=0x{=u32:08x} data_head_fnv=0x{=u32:08x}", h.magic, h.head_fnv),
        None => defmt::info!("no data partition (first word erased)"),
    }

    // 3. The workload, timed.
    let (result, instructions) = clock::measure(workload);
    let checksum = match result {
        Ok(c) => c,
        Err(e) => {
            defmt::error!("workload failed: {=str}", model_error_name(e));
            fail();
        }
    };
    defmt::info!("instructions={=u64} checksum={=u32}", instructions, checksum);

    // 4. Stack high-water mark (everything any code above has used, exception frames included).
    let peak = stack::peak_bytes();
    defmt::info!("stack_peak_bytes={=u32} stack_free_bytes={=u32}", peak, stack::size_bytes() - peak);

    defmt::info!("status=ok");
    semihosting::process::exit(0)
}

fn model_error_name(e: gpmm_core::ModelError) -> &'static str {
    match e {
        gpmm_core::ModelError::LengthMismatch => "LengthMismatch",
        gpmm_core::ModelError::TooManyCoefficients => "TooManyCoefficients",
    }
}

/// Ends the program with failure (QEMU exits with status 1).
fn fail() -> ! {
    defmt::error!("status=failed");
    semihosting::process::exit(1)
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    // Location only: formatting the message would pull core::fmt into the image.
    match info.location() {
        Some(l) => defmt::error!("panic at {=str}:{=u32}", l.file(), l.line()),
        None => defmt::error!("panic"),
    }
    fail()
}

#[exception]
unsafe fn HardFault(frame: &ExceptionFrame) -> ! {
    defmt::error!("hard fault: pc=0x{=u32:08x} lr=0x{=u32:08x}", frame.pc(), frame.lr());
    fail()
}

#[exception]
unsafe fn DefaultHandler(irqn: i16) {
    defmt::error!("unexpected exception {=i16}", irqn);
    fail()
}

#[exception]
fn SysTick() {
    clock::on_wrap();
}
