//! Helpers shared by the tests that run the `gpmm` program.
#![allow(dead_code)]

use std::process::{Command, Output};

/// Runs `gpmm` with `args`.
pub fn gpmm(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_gpmm")).args(args).output().expect("gpmm runs")
}

/// Asserts success; returns stdout.
pub fn ok(out: &Output) -> String {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "gpmm failed: {stderr}");
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Asserts failure without a panic; returns stderr.
pub fn fails(out: &Output) -> String {
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "gpmm should have failed; stdout: {}", String::from_utf8_lossy(&out.stdout));
    assert!(!stderr.contains("panicked"), "gpmm panicked: {stderr}");
    stderr
}

/// Reads a JSON file (panics with the path if it cannot).
pub fn read_json(p: &std::path::Path) -> serde_json::Value {
    let text = std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}
