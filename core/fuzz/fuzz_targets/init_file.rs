//! Fuzzes the init file (`GPMI`): the finder and initializer networks, run when they parse.
//! The body, `bodies::init_file`, is shared with the stable test core/tests/fuzz.rs. Any panic is a bug.
#![no_main]

// Each target uses one body of the shared file.
#[allow(dead_code)]
#[path = "../src/bodies.rs"]
mod bodies;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    bodies::init_file(data);
});
