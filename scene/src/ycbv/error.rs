//! The error type of the YCB-Video reader; every variant names its file.

use std::path::PathBuf;

/// Why a YCB-Video file could not be read.
#[derive(Debug, thiserror::Error)]
pub enum YcbError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: {source}")]
    Image {
        path: PathBuf,
        #[source]
        source: crate::bop::images::ImageFileError,
    },
    /// The `.mat` file could not be parsed.
    #[error("{path}: cannot parse MATLAB file: {message}")]
    Mat { path: PathBuf, message: String },
    /// A file parsed but holds unusable values.
    #[error("{path}: {message}")]
    Invalid { path: PathBuf, message: String },
    #[error("no class list found (tried {tried:?})")]
    NoClasses { tried: Vec<PathBuf> },
    #[error("{path}:{line}: frame entry {entry:?} must be a relative path like 0048/000001")]
    BadListEntry { path: PathBuf, line: usize, entry: String },
    #[error("frame index {index} out of range (list has {len} frames)")]
    FrameOutOfRange { index: usize, len: usize },
}
