//! Typed errors of the library. Each names the file and the glTF item it concerns.

use std::path::PathBuf;

/// Result with the library's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Everything that can go wrong in a bake.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("cannot read {path}")]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path} is not a valid glTF file: {reason}")]
    NotGltf { path: PathBuf, reason: String },
    #[error("{path}: {item}: {reason}")]
    BadItem {
        path: PathBuf,
        item: String,
        reason: String,
    },
    #[error("{path}: the scene has no static triangles to bake")]
    EmptyScene { path: PathBuf },
    #[error("cannot write {path}")]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("atlas: {0}")]
    Atlas(#[from] crate::atlas::AtlasError),
    #[error("invalid option {option}: {reason}")]
    Option {
        option: &'static str,
        reason: String,
    },
    #[error("{0}")]
    Image(String),
    #[error("compare: {0}")]
    Compare(String),
}
