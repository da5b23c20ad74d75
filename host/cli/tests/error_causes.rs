//! Each error message says its cause once: a refused init file or a missing file is reported
//! with the file and the reason, and the reason is not repeated by the error's chain.

mod common;
use common::{fails, gpmm};

use std::path::Path;

/// The number of times `needle` occurs in `text`.
fn count(text: &str, needle: &str) -> usize {
    text.matches(needle).count()
}

/// A small photo (grey, 64 × 64) in `dir`.
fn photo(dir: &Path) -> String {
    let path = dir.join("grey.png");
    image::RgbImage::from_pixel(64, 64, image::Rgb([128, 128, 128])).save(&path).expect("write the photo");
    path.display().to_string()
}

#[test]
fn a_truncated_init_file_is_reported_once() {
    let dir = tempfile::tempdir().unwrap();
    let init = dir.path().join("short.init");
    std::fs::write(&init, b"GPMI").unwrap();
    let image = photo(dir.path());
    let stderr = fails(&gpmm(&["detect", &image, "--init", init.to_str().unwrap()]));
    assert!(stderr.contains("not a valid init file"), "{stderr}");
    assert_eq!(count(&stderr, "truncated"), 1, "the cause is said more than once: {stderr}");
    assert_eq!(count(&stderr, init.to_str().unwrap()), 1, "{stderr}");
}

#[test]
fn a_missing_file_is_reported_once() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("absent.gpmm");
    let missing = missing.to_str().unwrap();
    let image = photo(dir.path());
    let init = dir.path().join("absent.init");
    let ict = dir.path().join("absent-ict");
    let synth_out = dir.path().join("synth");
    for args in [
        vec!["info", missing],
        vec!["fit", missing, &image, "--landmarks", "absent.pts", "-o", dir.path().to_str().unwrap()],
        vec!["detect", &image, "--init", init.to_str().unwrap()],
        vec!["synth", "--count", "1", "--ict", ict.to_str().unwrap(), "-o", synth_out.to_str().unwrap()],
    ] {
        let stderr = fails(&gpmm(&args));
        let cause = std::io::Error::from(std::io::ErrorKind::NotFound).to_string();
        let os_cause = "(os error 2)";
        assert!(stderr.contains(os_cause) || stderr.contains(&cause), "gpmm {args:?}: {stderr}");
        assert!(count(&stderr, os_cause) <= 1 && count(&stderr, &cause) <= 1, "gpmm {args:?} says its cause more than once: {stderr}");
    }
}
