//! The one error type of the crate: every failure names the file, and for parse errors the line
//! and column, so a bad file can be fixed without reading our code.

use std::path::PathBuf;

/// What went wrong while reading or writing evaluation files.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// The file system refused (missing file, permissions, ...).
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or folder concerned.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// A KITTI-style txt line that does not have the official 17 columns and types.
    /// `line` and `column` are 1-based; `column` counts whitespace-separated fields.
    #[error("{}:{line}: column {column}: {message}", path.display())]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// 1-based column (field) number.
        column: usize,
        /// What was expected and what was found.
        message: String,
    },
    /// A JSON file that is not valid JSON or not of the documented schema.
    /// `line` and `column` are 1-based character positions as serde_json reports them.
    #[error("{}:{line}:{column}: {message}", path.display())]
    Json {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// 1-based character column.
        column: usize,
        /// What was wrong.
        message: String,
    },
    /// A ground-truth frame has no detection file (the official tool refuses this too).
    #[error("no detections for ground-truth frame {}: expected {} (pass --missing-as-empty to treat it as an empty frame)", gt.display(), expected.display())]
    MissingDetections {
        /// The ground-truth file or frame.
        gt: PathBuf,
        /// Where the detections were looked for.
        expected: PathBuf,
    },
    /// A JRDB file read by data-jrdb's readers (labels), with the file and the key at fault.
    #[error(transparent)]
    Data(#[from] data_jrdb::DataError),
    /// A folder that is not laid out as the chosen format requires.
    #[error("{}: {message}", path.display())]
    Layout {
        /// The folder or file.
        path: PathBuf,
        /// What was expected.
        message: String,
    },
}

impl EvalError {
    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        EvalError::Io {
            path: path.into(),
            source,
        }
    }

    pub(crate) fn json(path: impl Into<PathBuf>, e: &serde_json::Error) -> Self {
        // serde_json's Display appends " at line L column C"; keep only the message part.
        let full = e.to_string();
        let message = match full.rfind(" at line ") {
            Some(i) => full[..i].to_string(),
            None => full,
        };
        EvalError::Json {
            path: path.into(),
            line: e.line(),
            column: e.column(),
            message,
        }
    }
}

/// Result with [`EvalError`].
pub type Result<T> = std::result::Result<T, EvalError>;
