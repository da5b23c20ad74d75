//! Fuzzes the model blob parser (`GPMB`).
//! The body, `bodies::blob`, is shared with the stable test core/tests/fuzz.rs. Any panic is a bug.
#![no_main]

// Each target uses one body of the shared file.
#[allow(dead_code)]
#[path = "../src/bodies.rs"]
mod bodies;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    bodies::blob(data);
});
