//! Writes the chosen profile's memory map as `memory.x` on the linker's search path (cortex-m-rt's
//! `link.x` includes it), from `gpmm_core::profile`: `m4f` by default, `m7` with the `m7` feature.
//!
//! No file in this directory may be named `memory.x`: GNU ld looks for INCLUDEd scripts
//! in the current directory (the package root) before the -L paths, so such a file would
//! win over the one written here, whatever the profile.
use std::{env, fs, path::PathBuf};

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("OUT_DIR"));
    let profile = if env::var_os("CARGO_FEATURE_M7").is_some() { gpmm_core::profile::M7 } else { gpmm_core::profile::M4F };
    let mut map = String::new();
    profile.write_memory_x(&mut map).expect("format the memory map");
    fs::write(out.join("memory.x"), map).expect("write memory.x");
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
