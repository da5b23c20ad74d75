//! The memory maps the firmware links for: the m4f profile fits the STM32F405's flash, 128 KiB
//! SRAM and 64 KiB CCM exactly; the linker script puts each part where the chip has it.
#![allow(clippy::unwrap_used)]

use gpmm_core::profile::{MemoryMap, M4F, M7, MPS2, NETDUINOPLUS2, NRF52840, STM32F405};

fn memory_x(map: &MemoryMap) -> String {
    let mut s = String::new();
    M4F.write_memory_x(map, &mut s).unwrap();
    s
}

#[test]
fn the_m4f_profile_fits_the_stm32f405_split_ram_and_the_m7_does_not() {
    for map in [MPS2, STM32F405, NETDUINOPLUS2, NRF52840] {
        assert!(map.fits(&M4F), "{}", map.name);
    }
    assert!(MPS2.fits(&M7));
    assert!(!STM32F405.fits(&M7) && !NETDUINOPLUS2.fits(&M7) && !NRF52840.fits(&M7), "the m7 needs 2 MiB of flash");
    let [statics, stack] = [STM32F405.statics_bytes.unwrap(), STM32F405.stack.unwrap().bytes];
    assert_eq!((statics, stack), (128 * 1024, 64 * 1024));
    assert_eq!(statics + stack, M4F.ram_bytes);
    assert_eq!(MemoryMap::by_name("NetduinoPlus2"), Some(NETDUINOPLUS2));
}

#[test]
fn the_linker_script_places_flash_partition_statics_and_stack() {
    let f405 = memory_x(&STM32F405);
    for line in [
        "FLASH     : ORIGIN = 0x08000000, LENGTH = 512K",
        "GPMM_DATA : ORIGIN = 0x08080000, LENGTH = 512K",
        "RAM       : ORIGIN = 0x20000000, LENGTH = 128K",
        "STACK     : ORIGIN = 0x10000000, LENGTH = 64K",
        "_stack_start = ORIGIN(STACK) + LENGTH(STACK);",
        "_gpmm_memory_map = 2;",
    ] {
        assert!(f405.contains(line), "missing {line:?} in\n{f405}");
    }
    // QEMU's machine: the same but for the stack block's address.
    let qemu = memory_x(&NETDUINOPLUS2);
    assert!(qemu.contains("STACK     : ORIGIN = 0x20020000, LENGTH = 64K") && qemu.contains("_gpmm_memory_map = 3;"));
    assert_eq!(f405.lines().filter(|l| !qemu.contains(l)).count(), 3, "header, stack block, map number");
    // mps2: one RAM block, the stack after the statics (cortex-m-rt's default).
    let mps2 = memory_x(&MPS2);
    assert!(mps2.contains("FLASH     : ORIGIN = 0x00000000") && mps2.contains("RAM       : ORIGIN = 0x20000000, LENGTH = 192K"));
    assert!(!mps2.contains("STACK") && !mps2.contains("_stack_start"));
}
