//! Where the shared data lives (template scan, ICT model, photos).
//!
//! The data is never copied into the repository: it is read from `$GPMM_DATA`, or from
//! `../shared/data` next to the workspace.

use std::path::{Path, PathBuf};

/// The data directory: `$GPMM_DATA` if set, else `../shared/data` beside the workspace.
pub fn default_data_dir() -> PathBuf {
    if let Some(dir) = std::env::var_os("GPMM_DATA") {
        return PathBuf::from(dir);
    }
    let beside_cwd = PathBuf::from("../shared/data");
    if beside_cwd.is_dir() {
        return beside_cwd;
    }
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data")
}

/// The template scan directory inside a data directory.
pub fn template_dir(data: &Path) -> PathBuf {
    data.join("template/lee-perry-smith")
}

/// For tests: the data directory if present; `None` (with a printed `SKIPPED` message) if
/// absent, unless `GPMM_REQUIRE_DATA` is set (CI), in which case absence is a test failure.
pub fn data_dir_for_tests() -> Option<PathBuf> {
    let dir = default_data_dir();
    if dir.is_dir() {
        Some(dir)
    } else if std::env::var_os("GPMM_REQUIRE_DATA").is_some() {
        panic!("data directory {} is absent but GPMM_REQUIRE_DATA is set", dir.display());
    } else {
        eprintln!("SKIPPED: data directory {} is absent (set GPMM_DATA)", dir.display());
        None
    }
}
