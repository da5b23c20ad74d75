//! gpmm firmware, simulated: Cortex-M4F under QEMU (mps2-an386), or on a board.
//!
//! What it does (the data partition decides: a device mesh is rendered, a model blob is fitted, an
//! init file runs the landmark-free start on the camera frame after it, `detect.rs`):
//! 1. calibrates SysTick against a loop of known instruction count (under QEMU with
//!    `-icount shift=0` one SysTick tick on mps2 is 40 instructions: 1 instruction = 1 ns of
//!    virtual time, SysTick runs on the 25 MHz system clock);
//! 2. reads the data partition (`GPMM_DATA` in memory.x), flashed separately from the
//!    program: nothing there (first word erased) logs "no data partition" and exits ok;
//!    a device mesh (`gpmm_core::format::device_mesh`, magic `GPDM`) is rendered, an init file
//!    (magic `GPMI`) and a frame (`gpmm_core::format::detection`) are detected in, anything else
//!    must be a model blob followed by a fit input (`gpmm_core::format::fit_input`), which is
//!    fitted (`fit.rs`), or by a landmark-free fit job, an init file and a camera frame
//!    (`gpmm_core::format::frame_fit`): the face is found, cropped and fitted (`frame_fit.rs`);
//! 3. a device mesh: renders it with gpmm-core exactly as the host does: the vertex stage (normals,
//!    SH shading, projection) into static buffers, then `TileRasterizer<32, 32, BIN>` into a
//!    `FrameChecksum` sink; both stages are timed in instructions (`clock::measure`, ±4);
//!    a model blob: runs the core's standard fit (the same function as `gpmm fit`) and logs its
//!    result as a binary fit record (`gpmm_core::format::fit_record`, hex lines `GPFR ...`);
//! 4. measures the stack's high-water mark (cortex-m-rt's `paint-stack`);
//! 5. logs with defmt over semihosting and exits through
//!    semihosting: status 0 on success, 1 on any failure (bad data, panic, fault, bad calibration).
#![no_std]
#![no_main]

mod board;
mod clock;
mod detect;
mod fit;
mod frame_fit;
mod hexlog;
mod partition;
mod stack;

use board::{fail, Rasterizer, CACHE_PIXELS, CACHE_WORDS, MAP, MASK_WORDS, MAX_PROJECTED, MAX_VERTICES, PROFILE};
use cortex_m_rt::{entry, exception, ExceptionFrame};
use defmt_semihosting as _; // the global defmt logger: frames go to the host's stdout
use gpmm_core::checksum::FrameChecksum;
use gpmm_core::fit::OcclusionMask;
use gpmm_core::format::blob::ModelBlob;
use gpmm_core::format::device_mesh::{self, DeviceMeshView};
use gpmm_core::format::frame_fit as sections;
use gpmm_core::format::init_file::INIT_MAGIC;
use gpmm_core::geometry::Vec3;
use gpmm_core::render::frame_cache::CompactBuffers;
use gpmm_core::render::{vertex_stage, Cull, ProjectedVertex};

#[entry]
fn main() -> ! {
    // cortex-m-rt turns these into `&'static mut` (zero-initialised ones go to .bss).
    static mut NORMALS: [Vec3; MAX_VERTICES] = [[0.0; 3]; MAX_VERTICES];
    static mut PROJECTED: [ProjectedVertex; MAX_PROJECTED] = [ProjectedVertex::INVALID; MAX_PROJECTED];
    static mut RASTERIZER: Rasterizer = Rasterizer::new();
    static mut CACHE_COVERED: [u32; CACHE_WORDS] = [0; CACHE_WORDS];
    static mut CACHE_TRIANGLES: [u16; CACHE_PIXELS] = [0; CACHE_PIXELS];
    static mut OCCLUSION: OcclusionMask<MASK_WORDS> = OcclusionMask::new();

    let mut core = cortex_m::Peripherals::take().unwrap_or_else(|| fail());
    clock::start(&mut core.SYST);

    defmt::info!("gpmm-firmware-sim {=str} profile={=str} memory_map={=str}", env!("CARGO_PKG_VERSION"), PROFILE.name, MAP.name);

    // 1. SysTick against a loop of known length.
    let cal = clock::calibrate();
    defmt::info!(
        "calib_instructions={=u32} calib_ticks={=u32} core_clock_hz={=u32} calib_measured_2000={=u64}",
        cal.instructions,
        cal.ticks,
        MAP.core_clock_hz,
        cal.measured_2000
    );
    // On a board SysTick counts clock cycles, not instructions: nothing to check.
    if MAP.emulated && !cal.ok() {
        defmt::error!("SysTick does not count instructions (expected {=u32} ticks): run QEMU with -icount shift=0", cal.expected_ticks());
        fail();
    }

    // 2. The data partition.
    let part = partition::region();
    defmt::info!("data_partition_addr=0x{=u32:08x} data_partition_bytes={=u32}", part.as_ptr() as u32, part.len() as u32);
    if partition::is_erased(part) {
        defmt::info!("no data partition (first word erased)");
    } else if part.starts_with(&INIT_MAGIC) {
        detect::run(part);
    } else if !device_mesh::is_device_mesh(part) {
        let cache = CompactBuffers { covered: CACHE_COVERED, triangles: CACHE_TRIANGLES };
        fit_blob(part, fit::Buffers { pool: NORMALS, projected: PROJECTED, raster: RASTERIZER, cache, mask: OCCLUSION });
    } else {
        let m = match device_mesh::parse(part, MAX_PROJECTED.min(MAX_VERTICES)) {
            Ok(m) => m,
            Err(e) => {
                defmt::error!("data partition: not a valid device mesh: {}", defmt::Display2Format(&e));
                fail();
            }
        };
        render(&m, NORMALS, PROJECTED, RASTERIZER);
    }

    // 4. Stack high-water mark (everything any code above has used, exception frames included).
    let peak = stack::peak_bytes();
    defmt::info!("stack_peak_bytes={=u32} stack_free_bytes={=u32}", peak, stack::size_bytes() - peak);
    // Painted words left at the bottom of the stack's RAM, else it ran into what lies below (the
    // statics, or on the STM32F405 nothing: a fault) and the results cannot be trusted.
    if peak >= stack::size_bytes() {
        defmt::error!("the stack overflowed its {=u32} B of RAM ({=str} memory map)", stack::size_bytes(), MAP.name);
        fail();
    }

    defmt::info!("status=ok");
    semihosting::process::exit(0)
}

/// Fits the blob at the start of `part` to the section after it: a fit input (`GPFI`: image and
/// landmarks, `fit.rs`) or a landmark-free fit job (`GPFF`: init file and camera frame follow,
/// `frame_fit.rs`); logs everything, fails on bad data.
fn fit_blob(part: &'static [u8], bufs: fit::Buffers<'_>) {
    let t_start = clock::instructions_now();
    // The blob may be followed by more data: its header says how long it is.
    let blob = match ModelBlob::parse(part) {
        Ok(b) => b,
        Err(e) => {
            defmt::error!("data partition: not a valid model blob: {}", defmt::Display2Format(&e));
            fail();
        }
    };
    let model = match blob.morphable() {
        Ok(m) => m,
        Err(e) => fit::fit_failed("model blob", e),
    };
    let input_at = sections::next_section(blob.len());
    let Some(rest) = part.get(input_at..) else {
        defmt::error!("data partition: the blob fills it, no room for a fit input");
        fail();
    };
    if rest.starts_with(&sections::MAGIC) {
        frame_fit::run(part, &blob, &model, input_at, bufs, t_start);
    } else {
        fit::landmark_fit(part, &blob, &model, rest, bufs, t_start);
    }
}

/// 3. Renders the device mesh into a checksum and logs the frame's figures (fails on bad data).
fn render(m: &DeviceMeshView<'_>, normals: &mut [Vec3], projected: &mut [ProjectedVertex], rasterizer: &mut Rasterizer) {
    let n = m.positions.len();
    let (Some(normals), Some(projected)) = (normals.get_mut(..n), projected.get_mut(..n)) else {
        defmt::error!("mesh larger than the buffers");
        fail();
    };
    defmt::info!(
        "mesh_vertices={=u32} mesh_triangles={=u32} width={=u32} height={=u32} renderer_ram_bytes={=u32} vertex_buffers_bytes={=u32}",
        n as u32,
        m.triangles.len() as u32,
        m.scene.width,
        m.scene.height,
        core::mem::size_of::<Rasterizer>() as u32,
        (MAX_VERTICES * core::mem::size_of::<Vec3>() + MAX_PROJECTED * core::mem::size_of::<ProjectedVertex>()) as u32
    );
    let (r, vertex_instructions) = clock::measure(|| {
        vertex_stage(m.positions, m.albedo, m.triangles, &m.scene.pose, &m.scene.camera, &m.scene.light, normals, projected)
    });
    if let Err(e) = r {
        defmt::error!("vertex stage refused the mesh: {}", e);
        fail();
    }
    let mut sum = FrameChecksum::new();
    let (r, raster_instructions) =
        clock::measure(|| rasterizer.render(projected, m.triangles, m.scene.width, m.scene.height, Cull::Clockwise, &mut sum));
    let stats = match r {
        Ok(s) => s,
        Err(e) => {
            defmt::error!("rasterizer refused the frame: {}", e);
            fail();
        }
    };
    defmt::info!(
        "vertex_instructions={=u64} raster_instructions={=u64} frame_instructions={=u64}",
        vertex_instructions,
        raster_instructions,
        vertex_instructions + raster_instructions
    );
    defmt::info!(
        "frame_checksum={=u32} covered_pixels={=u32} color_sum_r={=u64} color_sum_g={=u64} color_sum_b={=u64} drawn_triangles={=u32} overflow_rows={=u32}",
        sum.value(),
        sum.covered,
        sum.color_sum[0],
        sum.color_sum[1],
        sum.color_sum[2],
        stats.drawn,
        stats.overflow_rows
    );
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
