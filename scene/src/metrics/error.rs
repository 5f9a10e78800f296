//! The error type of the metrics module.

use std::path::PathBuf;

/// Why a metric could not be computed or written.
#[derive(Debug, thiserror::Error)]
pub enum MetricsError {
    /// ADD/ADD-S need at least one model point.
    #[error("the object has no model sample points: ADD/ADD-S are undefined")]
    NoPoints,
    /// A model point has a NaN or infinite coordinate.
    #[error("model sample point {index} is not finite")]
    NonFinitePoint { index: usize },
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The accuracy plot could not be drawn or written.
    #[error("plotting {path}: {message}")]
    Plot { path: PathBuf, message: String },
}
