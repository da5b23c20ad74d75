//! Puts the chosen profile's memory map on the linker's search path as `memory.x`
//! (cortex-m-rt's `link.x` includes `memory.x`): `memory-m4f.x` by default, `memory-m7.x`
//! with the `m7` feature.
//!
//! No file in this directory may be named `memory.x`: GNU ld looks for INCLUDEd scripts
//! in the current directory (the package root) before the -L paths, so such a file would
//! win over the copy made here, whatever the profile.
use std::{env, fs, path::PathBuf};

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("OUT_DIR"));
    let src = if env::var_os("CARGO_FEATURE_M7").is_some() { "memory-m7.x" } else { "memory-m4f.x" };
    fs::copy(src, out.join("memory.x")).expect("copy memory map");
    println!("cargo:rustc-link-search={}", out.display());
    // Link scripts here rather than in rustflags, so that a RUSTFLAGS from the
    // environment (which replaces config rustflags) cannot drop them.
    // link.x: cortex-m-rt's (includes memory.x); defmt.x: keeps the .defmt table.
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
    println!("cargo:rustc-link-arg-bins=--nmagic");
    println!("cargo:rerun-if-changed=memory-m4f.x");
    println!("cargo:rerun-if-changed=memory-m7.x");
    println!("cargo:rerun-if-changed=build.rs");
}
