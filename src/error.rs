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
    #[error("{path}: the scene has no static triangles to bake (none, or all of zero area)")]
    EmptyScene { path: PathBuf },
    #[error("cannot write {path}")]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: atlas: {error}")]
    Atlas {
        path: PathBuf,
        error: crate::atlas::AtlasError,
    },
    #[error("{what}: {reason}")]
    Output { what: &'static str, reason: String },
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

impl Error {
    /// Places an item error inside an enclosing item (`mesh 0 primitive 1: POSITION`), so a
    /// message names the file once and the item from the outside in. Other errors pass through.
    pub(crate) fn within(self, outer: &str) -> Error {
        match self {
            Error::BadItem { path, item, reason } => Error::BadItem {
                path,
                item: format!("{outer}, {item}"),
                reason,
            },
            other => other,
        }
    }
}
