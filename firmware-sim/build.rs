//! Writes the chosen profile's memory map as `memory.x` on the linker's search path (cortex-m-rt's
//! `link.x` includes it), from `gpmm_core::profile`: `m4f` by default, `m7` with the `m7` feature;
//! on QEMU's mps2 boards by default, else the memory map its feature names (`stm32f405`,
//! `netduinoplus2`, QEMU's STM32F405 machine, `nrf52840`).
//!
//! No file in this directory may be named `memory.x`: GNU ld looks for INCLUDEd scripts
//! in the current directory (the package root) before the -L paths, so such a file would
//! win over the one written here, whatever the profile.
use gpmm_core::profile;
use std::{env, fs, path::PathBuf};

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("OUT_DIR"));
    let profile = if env::var_os("CARGO_FEATURE_M7").is_some() { profile::M7 } else { profile::M4F };
    let feature = |name: &str| env::var_os(format!("CARGO_FEATURE_{}", name.to_uppercase())).is_some();
    let chosen: Vec<_> = profile::MEMORY_MAPS.into_iter().filter(|m| m.name != "mps2" && feature(m.name)).collect();
    let map = match chosen[..] {
        [] => profile::MPS2,
        [one] => one,
        _ => panic!("choose at most one memory map feature (stm32f405, netduinoplus2 or nrf52840)"),
    };
    assert!(map.fits(&profile), "the {} profile does not fit the {} memory map", profile.name, map.name);
    let mut text = String::new();
    profile.write_memory_x(&map, &mut text).expect("format the memory map");
    fs::write(out.join("memory.x"), text).expect("write memory.x");
    println!("cargo:rustc-link-search={}", out.display());
    // Link scripts here rather than in rustflags, so that a RUSTFLAGS from the
    // environment (which replaces config rustflags) cannot drop them.
    // link.x: cortex-m-rt's (includes memory.x); defmt.x: keeps the .defmt table.
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
    println!("cargo:rustc-link-arg-bins=--nmagic");
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed=../core/src/profile.rs");
}
