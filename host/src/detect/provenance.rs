//! What an init file was trained for and on, kept in its metadata: each model file's SHA-256 and
//! landmark count (`trained_for`), and each photo folder's sources and licences as the folder's
//! `sources.json` lists them (`photo_sets`, written by `tests/realphotos/*.py`).

use serde_json::Value;
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};

/// Metadata key of the models an init file was trained for.
pub const TRAINED_FOR: &str = "trained_for";
/// Metadata key of the photo folders an init file was trained on.
pub const PHOTO_SETS: &str = "photo_sets";

/// Why the provenance could not be gathered or written.
#[derive(Debug, thiserror::Error)]
pub enum ProvenanceError {
    /// A file could not be read.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The IO error.
        error: std::io::Error,
    },
    /// A folder's `sources.json` or the file's metadata is not JSON (an object).
    #[error("{what}: not a JSON object ({error})")]
    Json {
        /// The file or part.
        what: String,
        /// What the parser said.
        error: String,
    },
}

/// The SHA-256 of `bytes` as 64 lower-case hex digits (how a model file is named in `trained_for`).
pub fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::digest(bytes).iter().map(|b| format!("{b:02x}")).collect()
}

/// The SHA-256 of the file at `path` ([`sha256_hex`]).
pub fn file_sha256(path: &Path) -> Result<String, ProvenanceError> {
    let bytes = std::fs::read(path).map_err(|error| ProvenanceError::Io { path: path.to_path_buf(), error })?;
    Ok(sha256_hex(&bytes))
}

/// One model an init file was trained for: the file's name, its SHA-256, its kernel and landmark count.
pub fn model_entry(path: &Path, kernel: &str, landmarks: usize) -> Result<Value, ProvenanceError> {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    Ok(serde_json::json!({ "file": name, "sha256": file_sha256(path)?, "kernel": kernel, "landmarks": landmarks }))
}

/// One photo folder an init file was trained on: its name, its photo count and, when the folder
/// has a `sources.json`, what that file says of where the photos come from (its `sources` or
/// `packages` and `summary`).
pub fn photo_set_entry(dir: &Path, photos: usize) -> Result<Value, ProvenanceError> {
    let name = dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let mut entry = serde_json::json!({ "folder": name, "photos": photos });
    let path = dir.join("sources.json");
    if path.is_file() {
        let text = std::fs::read_to_string(&path).map_err(|error| ProvenanceError::Io { path: path.clone(), error })?;
        let sources: Value =
            serde_json::from_str(&text).map_err(|e| ProvenanceError::Json { what: path.display().to_string(), error: e.to_string() })?;
        for key in ["sources", "packages", "summary"] {
            if let Some(v) = sources.get(key) {
                entry[key] = v.clone();
            }
        }
    }
    Ok(entry)
}

/// `metadata` (an init file's JSON object) with `trained_for` and `photo_sets` set.
pub fn with_provenance(metadata: &str, models: Vec<Value>, photo_sets: Vec<Value>) -> Result<String, ProvenanceError> {
    let mut meta: Value = serde_json::from_str(metadata)
        .map_err(|e| ProvenanceError::Json { what: "the init file's metadata".into(), error: e.to_string() })?;
    let Some(object) = meta.as_object_mut() else {
        return Err(ProvenanceError::Json { what: "the init file's metadata".into(), error: "not an object".into() });
    };
    object.insert(TRAINED_FOR.into(), Value::Array(models));
    if !photo_sets.is_empty() {
        object.insert(PHOTO_SETS.into(), Value::Array(photo_sets));
    }
    Ok(meta.to_string())
}

/// The SHA-256s of the models an init file's metadata says it was trained for (none for a file
/// written before they were recorded, or with metadata that is not JSON).
pub fn trained_for(metadata: &str) -> Vec<String> {
    let meta: Value = serde_json::from_str(metadata).unwrap_or(Value::Null);
    meta.get(TRAINED_FOR)
        .and_then(Value::as_array)
        .map(|models| models.iter().filter_map(|m| m.get("sha256").and_then(Value::as_str).map(str::to_owned)).collect())
        .unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn provenance_is_written_and_read_back() {
        let dir = tempfile::tempdir().unwrap();
        let model = dir.path().join("face.gpmm");
        std::fs::write(&model, b"model bytes").unwrap();
        std::fs::write(dir.path().join("sources.json"), r#"{"packages": {"a": "a.deb"}, "kept": []}"#).unwrap();
        let models = vec![model_entry(&model, "symmetric-full", 68).unwrap()];
        let sets = vec![photo_set_entry(dir.path(), 3).unwrap()];
        let meta = with_provenance(r#"{"format": "gpmm-init"}"#, models, sets).unwrap();
        assert_eq!(trained_for(&meta), vec![sha256_hex(b"model bytes")]);
        let v: Value = serde_json::from_str(&meta).unwrap();
        assert_eq!(v["photo_sets"][0]["packages"]["a"], "a.deb");
        assert!(v["photo_sets"][0].get("kept").is_none(), "only where the photos come from is kept");
        assert_eq!(v["format"], "gpmm-init");
    }

    #[test]
    fn bad_metadata_and_sources_are_named() {
        assert!(matches!(with_provenance("[1]", vec![], vec![]), Err(ProvenanceError::Json { .. })));
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("sources.json"), "not json").unwrap();
        let e = photo_set_entry(dir.path(), 1).unwrap_err().to_string();
        assert!(e.contains("sources.json"), "{e}");
        assert!(trained_for("not json").is_empty());
    }
}
