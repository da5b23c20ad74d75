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
    frame_cache_pixels: 7168,
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
    /// The profile called `name` (`m4f`, `m7`; any case).
    pub fn by_name(name: &str) -> Option<Self> {
        ALL.into_iter().find(|p| p.name.eq_ignore_ascii_case(name))
    }

    /// Bytes of the 8-bit RGB working image.
    pub fn image_bytes(&self) -> usize {
        self.image_side as usize * self.image_side as usize * 3
    }

    /// The linker memory map (`memory.x`) of this profile, at QEMU's mps2 addresses: program
    /// flash at 0, the data partition after it, RAM at `0x2000_0000`.
    pub fn write_memory_x(&self, out: &mut impl core::fmt::Write) -> core::fmt::Result {
        let (code, data, ram) = (self.flash_code_bytes / 1024, self.partition_bytes / 1024, self.ram_bytes / 1024);
        writeln!(out, "/* Device profile {}: generated from gpmm_core::profile by build.rs; do not edit. */", self.name)?;
        writeln!(out, "MEMORY\n{{")?;
        writeln!(out, "  FLASH     : ORIGIN = 0x00000000, LENGTH = {code}K")?;
        writeln!(out, "  GPMM_DATA : ORIGIN = {:#010x}, LENGTH = {data}K", self.flash_code_bytes)?;
        writeln!(out, "  RAM       : ORIGIN = 0x20000000, LENGTH = {ram}K\n}}")?;
        writeln!(out, "_gpmm_data_start = ORIGIN(GPMM_DATA);")?;
        writeln!(out, "_gpmm_data_end   = ORIGIN(GPMM_DATA) + LENGTH(GPMM_DATA);")?;
        writeln!(out, "_gpmm_flash_size = LENGTH(FLASH) + LENGTH(GPMM_DATA);")?;
        writeln!(out, "_gpmm_ram_start  = ORIGIN(RAM);")?;
        writeln!(out, "_gpmm_ram_size   = LENGTH(RAM);")?;
        writeln!(out, "ASSERT(ORIGIN(GPMM_DATA) >= ORIGIN(FLASH) + LENGTH(FLASH), \"GPMM_DATA overlaps the code region\");")
    }
}
