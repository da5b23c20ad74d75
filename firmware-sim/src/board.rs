//! The board this image is built for: its device profile and memory map, the sizes of the static
//! buffers they give, and how the program ends on failure.

use gpmm_core::profile::{DeviceProfile, MemoryMap, M4F, M7, MPS2, NETDUINOPLUS2, NRF52840, STM32F405};
use gpmm_core::render::TileRasterizer;

/// The device profile this image is built and linked for (build.rs writes its memory map).
pub(crate) const PROFILE: DeviceProfile = if cfg!(feature = "m7") { M7 } else { M4F };
/// The memory map this image is linked for (build.rs picks it by the same features).
pub(crate) const MAP: MemoryMap = if cfg!(feature = "stm32f405") {
    STM32F405
} else if cfg!(feature = "netduinoplus2") {
    NETDUINOPLUS2
} else if cfg!(feature = "nrf52840") {
    NRF52840
} else {
    MPS2
};

/// The static per-vertex buffers: a `Vec3` pool of `vertex_pool` entries and a projected-vertex
/// array of `projected_pool` entries (12 and 24 bytes of RAM each). A fit takes three `Vec3`
/// (positions, albedos, normals) and one projected vertex per model vertex, a render one of each,
/// so both take meshes of up to `projected_pool` vertices: 1,024 on `m4f` (its blob has at most
/// 1,000), 3,072 on `m7` (at most 2,000). `m4f`: 36 + 24 KiB of buffers, the renderer's 46 KiB,
/// the fit's 14 KiB frame cache (6,144 pixels: a 128 px crop's face covers about 5,500) and its
/// 2 KiB of occlusion labels leave about 70 KiB of the 192 KiB for the stack (the fit's peak is
/// about 46 KiB: chain states and parameter copies). Nothing guards the stack's end, so
/// these margins are checked by the tests (static + peak <= RAM).
pub(crate) const MAX_VERTICES: usize = PROFILE.vertex_pool;
/// Entries of the projected-vertex array: the largest mesh a fit or a render takes.
pub(crate) const MAX_PROJECTED: usize = PROFILE.projected_pool;
/// Tile side of the renderer (32: 28 KiB of tile buffers). Each tile row scans the whole triangle
/// list once, so taller tiles scan less: at 16×16 a fit's image step took 2.95 M instructions, at
/// 32×32 2.59 M (same fit). The host's parity runs use the profile's tile too.
const TILE: usize = PROFILE.tile;
/// Triangles binned per frame (12 bytes each); a frame with more drawn triangles bins per tile
/// row, and a row with more scans the whole list (never lossy, but slow: with 1,024 per row the
/// template's frame overflowed 2 rows and took 80 M instead of 28 M instructions). A 1,000-vertex
/// blob has about 2,000 triangles, of which the front faces (about half) are drawn.
const BIN: usize = PROFILE.bin;

/// The renderer of this firmware (tile buffers + bin).
pub(crate) type Rasterizer = TileRasterizer<TILE, TILE, BIN>;
/// Covered pixels the fit's compact frame cache holds (2 bytes each).
pub(crate) const CACHE_PIXELS: usize = PROFILE.frame_cache_pixels;
/// Words of the frame cache's coverage mask (one bit per image pixel).
pub(crate) const CACHE_WORDS: usize = PROFILE.pixel_words();

/// Words of the occlusion-aware fit's labels (one bit per image pixel).
pub(crate) const MASK_WORDS: usize = CACHE_WORDS;

/// Ends the program with failure (QEMU exits with status 1).
pub(crate) fn fail() -> ! {
    defmt::error!("status=failed");
    semihosting::process::exit(1)
}
