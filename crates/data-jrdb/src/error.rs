//! `DataError`: every failure names the file it came from and what is wrong with it.

use std::path::{Path, PathBuf};

/// An error reading or writing a JRDB-format file; `Display` is `<path>: <what is wrong>`.
#[derive(Debug, thiserror::Error)]
#[error("{}: {kind}", path.display())]
pub struct DataError {
    /// The file (or folder) at fault.
    pub path: PathBuf,
    /// What is wrong with it.
    pub kind: ErrorKind,
}

/// What went wrong, by kind, so callers and tests can tell cases apart.
#[derive(Debug, thiserror::Error)]
pub enum ErrorKind {
    /// The file or folder could not be read or written.
    #[error("{0}")]
    Io(#[from] std::io::Error),
    /// A PCD header line is missing, malformed or inconsistent.
    #[error("bad PCD header: {0}")]
    PcdHeader(String),
    /// The PCD `DATA` line names an encoding we do not know.
    #[error("unknown PCD DATA `{0}` (expected ascii, binary or binary_compressed)")]
    UnknownData(String),
    /// The data ends before the size its header states is reached.
    #[error("truncated data: {0}")]
    Truncated(String),
    /// The data disagrees with its header (extra bytes, wrong column count, bad value).
    #[error("data does not match its header: {0}")]
    Mismatch(String),
    /// A well-formed input larger than the reader was told to accept (a service's bound).
    #[error("too large: {0}")]
    OverLimit(String),
    /// A point with a NaN or infinite coordinate, under the strict policy.
    #[error("non-finite point: {0}")]
    NonFinite(String),
    /// Not valid JSON or YAML at all.
    #[error("cannot parse: {0}")]
    Parse(String),
    /// A required key is absent or has the wrong type.
    #[error("key `{key}`: {what}")]
    Key {
        /// Path of the key inside the document, e.g. `labels["000001.pcd"][0].box.cx`.
        key: String,
        /// What is wrong with it.
        what: String,
    },
    /// The folder tree is not a JRDB layout (missing folders, missing twins).
    #[error("{0}")]
    Layout(String),
}

impl DataError {
    /// Builds an error for `path`.
    pub fn new(path: impl AsRef<Path>, kind: ErrorKind) -> Self {
        Self { path: path.as_ref().to_path_buf(), kind }
    }

    /// A missing or malformed key.
    pub fn key(path: impl AsRef<Path>, key: impl Into<String>, what: impl Into<String>) -> Self {
        Self::new(path, ErrorKind::Key { key: key.into(), what: what.into() })
    }

    /// An I/O failure.
    pub fn io(path: impl AsRef<Path>, e: std::io::Error) -> Self {
        Self::new(path, ErrorKind::Io(e))
    }
}

/// Result alias of this crate.
pub type Result<T> = std::result::Result<T, DataError>;
