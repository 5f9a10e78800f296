//! The error type of the BOP reader and writer; every variant names its file.

use std::path::PathBuf;

/// Why a BOP dataset could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum BopError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: invalid JSON: {source}")]
    Json {
        path: PathBuf,
        #[source]
        source: serde_json::Error,
    },
    #[error("{path}: {source}")]
    Image {
        path: PathBuf,
        #[source]
        source: super::images::ImageFileError,
    },
    /// A file holds a value this reader cannot use (wrong image format, size,
    /// non-finite pose, ...).
    #[error("{path}: {message}")]
    Invalid { path: PathBuf, message: String },
    /// An annotation file has no entry for a frame.
    #[error("{path}: no entry for image {im_id}")]
    MissingEntry { path: PathBuf, im_id: u32 },
    /// The frame handed to the writer is inconsistent with itself.
    #[error("frame scene {scene_id} image {im_id}: {message}")]
    BadFrame { scene_id: u32, im_id: u32, message: String },
    /// The writer refuses to mix a new split into one that already holds scenes.
    #[error("{path}: split folder already holds files; choose another output or remove it")]
    SplitNotEmpty { path: PathBuf },
    /// The dataset root names a different object set than the one being written.
    #[error("{path}: dataset was written for objects {existing:?}, not {requested:?}")]
    ObjectSetMismatch { path: PathBuf, existing: String, requested: String },
    /// The folder holds no BOP scene folders.
    #[error("{path}: no BOP scene folders (NNNNNN/ with scene_gt.json) found")]
    NoScenes { path: PathBuf },
    #[error("frame index {index} out of range (dataset has {len} frames)")]
    FrameOutOfRange { index: usize, len: usize },
}

pub(crate) fn io_err(path: &std::path::Path) -> impl FnOnce(std::io::Error) -> BopError + '_ {
    move |source| BopError::Io { path: path.to_owned(), source }
}

pub(crate) fn json_err(path: &std::path::Path) -> impl FnOnce(serde_json::Error) -> BopError + '_ {
    move |source| BopError::Json { path: path.to_owned(), source }
}

pub(crate) fn invalid(path: &std::path::Path, message: impl Into<String>) -> BopError {
    BopError::Invalid { path: path.to_owned(), message: message.into() }
}

pub(crate) fn image_err(path: &std::path::Path) -> impl FnOnce(super::images::ImageFileError) -> BopError + '_ {
    move |source| BopError::Image { path: path.to_owned(), source }
}
