//! Device profiles: the one place where a board class's image size, coefficient capacities,
//! renderer sizes, buffers and memory budgets are defined. The firmware (its constants and its
//! generated memory map), `gpmm quantize` and `gpmm device-fit` all read them from here.

/// A board class and everything the fit on it is sized by.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DeviceProfile {
    /// Name on the command line (`m4f`, `m7`).
    pub name: &'static str,
    /// Side of the square RGB working image the device fits (px).
    pub image_side: u32,
    /// Shape-coefficient capacity of the device's fit (`KS`); every parameter copy holds `KS + KC` floats.
    pub shape_capacity: usize,
    /// Colour-coefficient capacity (`KC`).
    pub color_capacity: usize,
    /// Tile side of the device's renderer (px); the host's parity runs use the same tiles so the
    /// likelihood sums in the same order.
    pub tile: usize,
    /// Triangles binned per frame, or per tile row if a frame's do not fit (12 bytes each).
    pub bin: usize,
    /// `Vec3` entries of the device's vertex pool: a fit takes three per model vertex (positions,
    /// albedos, normals), a render one (normals).
    pub vertex_pool: usize,
    /// Projected-vertex entries (24 B each): one per model vertex, for a fit or a render.
    pub projected_pool: usize,
    /// Covered pixels the fit's compact frame cache holds (2 B each, plus a coverage bit per
    /// image pixel): a colour or light proposal re-shades a frame up to this size instead of
    /// rendering it (`gpmm_core::render::frame_cache`).
    pub frame_cache_pixels: usize,
    /// Bytes of each of the two activation buffers (`gpmm_core::net::NetScratch`) the device gives
    /// the landmark-free start's networks: the largest activation of the default finder and
    /// initializer is the finder's 96 × 96 × 3 input. They live on the detection's stack, not in
    /// the statics, so the fit's RAM is unchanged.
    pub net_scratch: usize,
    /// Largest working side (px) of the landmark-free fit on the device (`gpmm device-fit --init`):
    /// its crop of the camera frame (3 B a pixel) lives on the fit's stack next to everything the
    /// fit itself uses, so on the `m4f` it is smaller than [`Self::image_side`] (firmware-sim/README.md,
    /// "The landmark-free fit").
    pub frame_fit_side: u32,
    /// Program flash (bytes), from address 0.
    pub flash_code_bytes: usize,
    /// Data partition (bytes) right after the program flash: the blob and the fit input.
    pub partition_bytes: usize,
    /// RAM (bytes).
    pub ram_bytes: usize,
    /// Default vertex budget of `gpmm quantize`.
    pub model_vertices: usize,
    /// Default shape and colour rank of `gpmm quantize`.
    pub model_rank: usize,
    /// Largest blob `gpmm quantize` writes (leaves room in the partition for the fit input).
    pub blob_budget: usize,
}

/// Cortex-M4F class (STM32F405 / nRF52840): 1 MiB flash, 192 KiB RAM, 128×128 images.
pub const M4F: DeviceProfile = DeviceProfile {
    name: "m4f",
    image_side: 128,
    shape_capacity: 64,
    color_capacity: 64,
    tile: 32,
    bin: 1536,
    vertex_pool: 3072,
    projected_pool: 1024,
    frame_cache_pixels: 6144,
    net_scratch: 96 * 96 * 3,
    frame_fit_side: 72,
    flash_code_bytes: 512 * 1024,
    partition_bytes: 512 * 1024,
    ram_bytes: 192 * 1024,
    model_vertices: 1000,
    model_rank: 50,
    blob_budget: 400 * 1024,
};

/// Cortex-M7 class (STM32H743): 2 MiB flash, 512 KiB RAM, 256×256 images.
pub const M7: DeviceProfile = DeviceProfile {
    name: "m7",
    image_side: 256,
    shape_capacity: 100,
    color_capacity: 100,
    tile: 32,
    bin: 4096,
    vertex_pool: 9216,
    projected_pool: 3072,
    frame_cache_pixels: 28672,
    net_scratch: 96 * 96 * 3,
    frame_fit_side: 128,
    flash_code_bytes: 1024 * 1024,
    partition_bytes: 1024 * 1024,
    ram_bytes: 512 * 1024,
    model_vertices: 2000,
    model_rank: 80,
    blob_budget: 800 * 1024,
};

/// Every profile.
pub const ALL: [DeviceProfile; 2] = [M4F, M7];

impl DeviceProfile {
    /// Words of a mask with one bit per working-image pixel (the frame cache's coverage, the
    /// occlusion labels).
    pub const fn pixel_words(&self) -> usize {
        (self.image_side as usize * self.image_side as usize).div_ceil(32)
    }

    /// The profile called `name` (`m4f`, `m7`; any case).
    pub fn by_name(name: &str) -> Option<Self> {
        ALL.into_iter().find(|p| p.name.eq_ignore_ascii_case(name))
    }

    /// Bytes of the 8-bit RGB working image.
    pub fn image_bytes(&self) -> usize {
        self.image_side as usize * self.image_side as usize * 3
    }

    /// The linker memory map (`memory.x`) of this profile on `map`: program flash, the data
    /// partition right after it, the statics in `RAM` and the stack in `STACK` (the same block
    /// unless the map has a separate one). `_gpmm_*` symbols tell `run.sh` the sizes and the map.
    pub fn write_memory_x(&self, map: &MemoryMap, out: &mut impl core::fmt::Write) -> core::fmt::Result {
        let (code, data) = (self.flash_code_bytes / 1024, self.partition_bytes / 1024);
        let statics = map.statics_bytes.unwrap_or(self.ram_bytes) / 1024;
        writeln!(out, "/* Device profile {} on {}: generated from gpmm_core::profile by build.rs; do not edit. */", self.name, map.name)?;
        writeln!(out, "MEMORY\n{{")?;
        writeln!(out, "  FLASH     : ORIGIN = {:#010x}, LENGTH = {code}K", map.flash_origin)?;
        writeln!(out, "  GPMM_DATA : ORIGIN = {:#010x}, LENGTH = {data}K", map.flash_origin as usize + self.flash_code_bytes)?;
        writeln!(out, "  RAM       : ORIGIN = {:#010x}, LENGTH = {statics}K", map.ram_origin)?;
        if let Some(stack) = map.stack {
            writeln!(out, "  STACK     : ORIGIN = {:#010x}, LENGTH = {}K", stack.origin, stack.bytes / 1024)?;
        }
        writeln!(out, "}}")?;
        if map.stack.is_some() {
            // cortex-m-rt PROVIDEs both at the end of the statics; its reset handler paints
            // [_stack_end, _stack_start) for the high-water mark.
            writeln!(out, "_stack_start = ORIGIN(STACK) + LENGTH(STACK);")?;
            writeln!(out, "_stack_end   = ORIGIN(STACK);")?;
        }
        writeln!(out, "_gpmm_data_start = ORIGIN(GPMM_DATA);")?;
        writeln!(out, "_gpmm_data_end   = ORIGIN(GPMM_DATA) + LENGTH(GPMM_DATA);")?;
        writeln!(out, "_gpmm_flash_size = LENGTH(FLASH) + LENGTH(GPMM_DATA);")?;
        writeln!(out, "_gpmm_ram_start  = ORIGIN(RAM);")?;
        writeln!(out, "_gpmm_ram_size   = {:#x};", self.ram_bytes)?;
        writeln!(out, "_gpmm_statics_size = LENGTH(RAM);")?;
        writeln!(out, "_gpmm_stack_size = {:#x};", map.stack.map_or(0, |s| s.bytes))?;
        writeln!(out, "_gpmm_memory_map = {};", map.code)?;
        writeln!(out, "ASSERT(ORIGIN(GPMM_DATA) >= ORIGIN(FLASH) + LENGTH(FLASH), \"GPMM_DATA overlaps the code region\");")?;
        writeln!(
            out,
            "ASSERT(LENGTH(FLASH) + LENGTH(GPMM_DATA) <= {:#x}, \"the program and the data partition exceed the chip's flash\");",
            map.flash_bytes
        )
    }
}

/// A separate stack RAM block (the STM32F405's core-coupled RAM).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StackBlock {
    /// Start address.
    pub origin: u32,
    /// Bytes.
    pub bytes: usize,
}

/// Where a firmware image lies on a chip or an emulated machine: flash, the statics' RAM and the
/// stack's. A profile's sizes go into it ([`DeviceProfile::write_memory_x`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MemoryMap {
    /// Name (`mps2`, `stm32f405`, `netduinoplus2`, `nrf52840`): the firmware's cargo feature.
    pub name: &'static str,
    /// Number `run.sh` reads from the ELF (`_gpmm_memory_map`) to pick the QEMU machine.
    pub code: u32,
    /// Flash start address (the vector table).
    pub flash_origin: u32,
    /// Flash bytes of the chip (program + data partition must fit).
    pub flash_bytes: usize,
    /// Start address of the statics' RAM.
    pub ram_origin: u32,
    /// Bytes of the statics' RAM block (`None`: the profile's whole RAM, the stack after the statics).
    pub statics_bytes: Option<usize>,
    /// The stack's own block, if it has one.
    pub stack: Option<StackBlock>,
    /// Core clock (Hz) SysTick counts (under QEMU with `-icount shift=0` one instruction is 1 ns,
    /// so a tick is `10⁹ / core_clock_hz` instructions).
    pub core_clock_hz: u32,
    /// Whether this is a QEMU machine (SysTick then counts instructions, checked at start-up; on
    /// a board it counts clock cycles).
    pub emulated: bool,
}

/// QEMU's mps2 boards (`mps2-an386` for `m4f`, `mps2-an500` for `m7`): flash at 0, one RAM block
/// at `0x2000_0000` for statics and stack, 25 MHz.
pub const MPS2: MemoryMap = MemoryMap {
    name: "mps2",
    code: 1,
    flash_origin: 0,
    flash_bytes: 2 * 1024 * 1024,
    ram_origin: 0x2000_0000,
    statics_bytes: None,
    stack: None,
    core_clock_hz: 25_000_000,
    emulated: true,
};

/// The STM32F405 (and F407): 1 MiB flash at `0x0800_0000`, the statics in the 128 KiB SRAM at
/// `0x2000_0000`, the stack in the 64 KiB core-coupled RAM at `0x1000_0000`; the firmware sets up
/// no PLL, so the core runs on the 16 MHz internal oscillator.
pub const STM32F405: MemoryMap = MemoryMap {
    name: "stm32f405",
    code: 2,
    flash_origin: 0x0800_0000,
    flash_bytes: 1024 * 1024,
    ram_origin: 0x2000_0000,
    statics_bytes: Some(128 * 1024),
    stack: Some(StackBlock { origin: 0x1000_0000, bytes: 64 * 1024 }),
    core_clock_hz: 16_000_000,
    emulated: false,
};

/// QEMU's STM32F405 machine (`netduinoplus2`). QEMU 7.2 maps 192 KiB of SRAM at `0x2000_0000`
/// and no core-coupled RAM, so the stack's 64 KiB block sits at `0x2002_0000`, right after the
/// chip's 128 KiB of statics, instead of at `0x1000_0000`: same sizes, same flash, one address
/// apart. QEMU's core clock is a fixed 168 MHz.
pub const NETDUINOPLUS2: MemoryMap = MemoryMap {
    name: "netduinoplus2",
    code: 3,
    stack: Some(StackBlock { origin: 0x2002_0000, bytes: 64 * 1024 }),
    core_clock_hz: 168_000_000,
    emulated: true,
    ..STM32F405
};

/// The nRF52840 (nRF52840-DK): 1 MiB flash at 0, the statics and the stack in 192 KiB of its
/// 256 KiB RAM at `0x2000_0000` (the mps2 layout), 64 MHz.
pub const NRF52840: MemoryMap =
    MemoryMap { name: "nrf52840", code: 4, flash_bytes: 1024 * 1024, core_clock_hz: 64_000_000, emulated: false, ..MPS2 };

/// Every memory map.
pub const MEMORY_MAPS: [MemoryMap; 4] = [MPS2, STM32F405, NETDUINOPLUS2, NRF52840];

impl MemoryMap {
    /// The map called `name` (any case).
    pub fn by_name(name: &str) -> Option<Self> {
        MEMORY_MAPS.into_iter().find(|m| m.name.eq_ignore_ascii_case(name))
    }

    /// Whether the m4f-class `profile` fits: program + partition in the flash, statics + stack in
    /// the RAM blocks (`ram_bytes` is their sum when the stack has its own block).
    pub fn fits(&self, profile: &DeviceProfile) -> bool {
        let flash = profile.flash_code_bytes + profile.partition_bytes <= self.flash_bytes;
        let ram = match (self.statics_bytes, self.stack) {
            (Some(s), Some(k)) => s + k.bytes == profile.ram_bytes,
            _ => true,
        };
        flash && ram
    }
}
