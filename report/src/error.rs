//! The report's error type.

use std::path::PathBuf;

/// Why a report could not be written.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// Nothing to compare: no run with outputs, or no truth.
    #[error("nothing to report: {0}")]
    Empty(&'static str),
    /// Creating the directory or writing a file failed.
    #[error("writing {path}: {source}")]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// An accuracy figure is not valid JSON (e.g. a NaN from non-finite outputs).
    #[error("accuracy JSON: {0}")]
    Json(#[from] serde_json::Error),
    /// The embedded font could not be registered with the plotting library.
    #[error("plot font: {0}")]
    Font(String),
    /// Drawing or encoding a plot failed.
    #[error("plotting {path}: {message}")]
    Plot {
        /// The PNG being drawn.
        path: PathBuf,
        /// The plotting library's message.
        message: String,
    },
}
