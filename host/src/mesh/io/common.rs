//! What the readers of every format share: the errors, each naming its file, and where a mesh's
//! colours came from.

use std::path::{Path, PathBuf};

/// Errors from reading or writing mesh, texture and landmark files; each names the file.
#[derive(Debug, thiserror::Error)]
pub enum MeshIoError {
    /// The file could not be opened, read or written.
    #[error("{}: {action}: {error}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// What was being done ("cannot read", "cannot write").
        action: &'static str,
        /// The underlying error.
        error: std::io::Error,
    },
    /// The file extension is not a supported mesh format.
    #[error("{}: unsupported mesh format (expected .ply, .glb or .gltf)", path.display())]
    UnsupportedFormat {
        /// The file.
        path: PathBuf,
    },
    /// The PLY file is malformed or lacks required elements or properties.
    #[error("{}: invalid PLY file: {message}", path.display())]
    Ply {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The glTF file is malformed or lacks required data.
    #[error("{}: invalid glTF file: {message}", path.display())]
    Gltf {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The texture image could not be read or decoded.
    #[error("{}: cannot read texture image: {message}", path.display())]
    Texture {
        /// The texture image file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The mesh has no per-vertex colours and no default colour was given.
    #[error(
        "{}: the mesh has no per-vertex colours (red/green/blue); pass --default-color R,G,B to use a constant colour",
        path.display()
    )]
    NoColors {
        /// The mesh file.
        path: PathBuf,
    },
    /// A glTF mesh has no texture image, no vertex colours and no default colour was given.
    #[error(
        "{}: the glTF file has no embedded texture image or vertex colours; pass --texture IMAGE (or --default-color R,G,B)",
        path.display()
    )]
    NoTexture {
        /// The mesh file.
        path: PathBuf,
    },
    /// The mesh data is invalid (non-finite coordinate, index out of range, non-manifold edge, empty mesh, ...).
    #[error("{}: {message}", path.display())]
    InvalidMesh {
        /// The mesh file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The landmark file is malformed.
    #[error("{}: invalid landmark file: {message}", path.display())]
    Landmarks {
        /// The landmark file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

impl MeshIoError {
    pub(super) fn invalid(path: &Path, message: impl Into<String>) -> Self {
        MeshIoError::InvalidMesh { path: path.to_path_buf(), message: message.into() }
    }
    pub(super) fn ply(path: &Path, message: impl Into<String>) -> Self {
        // The parser's first line says where and what; the rest repeats its internals.
        let message: String = message.into();
        let first = message.lines().next().unwrap_or("").trim().trim_end_matches('.').to_string();
        MeshIoError::Ply { path: path.to_path_buf(), message: first }
    }
    pub(super) fn gltf(path: &Path, message: impl Into<String>) -> Self {
        MeshIoError::Gltf { path: path.to_path_buf(), message: message.into() }
    }
    pub(super) fn texture(path: &Path, message: impl Into<String>) -> Self {
        MeshIoError::Texture { path: path.to_path_buf(), message: message.into() }
    }
    pub(super) fn read(path: &Path, error: std::io::Error) -> Self {
        MeshIoError::Io { path: path.to_path_buf(), action: "cannot read", error }
    }
    pub(super) fn write(path: &Path, error: std::io::Error) -> Self {
        MeshIoError::Io { path: path.to_path_buf(), action: "cannot write", error }
    }
}

/// Where the colours of a mesh read by [`read_mesh_with_info`](crate::mesh::io::read_mesh_with_info) came from.
#[derive(Debug, Clone, PartialEq)]
pub enum ColorSource {
    /// Per-vertex colours stored in the file.
    Vertex,
    /// Sampled from a texture image (its path, or `FILE#image` for an image embedded in a glTF file).
    Texture(String),
    /// The constant default colour.
    Default,
}
