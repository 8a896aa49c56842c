//! The one error type of dataset I/O. Every variant names the file, and the line where there is one.

use std::path::{Path, PathBuf};

/// What went wrong reading or writing a dataset.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// The file could not be opened, read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// A required file does not exist.
    #[error("{}: missing ({what})", path.display())]
    MissingFile {
        /// The file.
        path: PathBuf,
        /// What it should hold.
        what: String,
    },
    /// A required key is absent from a YAML file.
    #[error("{}: missing key `{key}`", path.display())]
    MissingKey {
        /// The YAML file.
        path: PathBuf,
        /// The key.
        key: String,
    },
    /// Malformed content at a line: a missing column, a non-numeric cell, a bad YAML value...
    #[error("{}:{line}: {message}", path.display())]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// Timestamps that do not strictly increase.
    #[error("{}:{line}: timestamp {t_ns} ns is not after the previous one ({prev_t_ns} ns)", path.display())]
    TimeBackwards {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// The offending timestamp.
        t_ns: i64,
        /// The previous timestamp.
        prev_t_ns: i64,
    },
    /// An image that cannot be used (missing, unreadable, or not JPEG/PNG).
    #[error("{}: unreadable image ({reason}), referenced at {}:{line}", path.display(), csv.display())]
    Image {
        /// The image file.
        path: PathBuf,
        /// The `data.csv` that references it.
        csv: PathBuf,
        /// 1-based line number in `csv`.
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// A malformed or inconsistent MCAP recording.
    #[error("{}: {message}", path.display())]
    Mcap {
        /// The recording.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A value that is not a valid sensor sample or configuration.
    #[error("{}: {context}: {source}", path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// Where in the file (a line, a topic and message index...).
        context: String,
        /// The validation error.
        #[source]
        source: uavnav_proto::ConvertError,
    },
    /// A flight log (`.BIN`, `.ulg`) that could not be imported; the reason names the byte offset
    /// where the log stopped making sense.
    // Not a `#[source]`: the text already carries the reason, and a source would repeat it in
    // error chains.
    #[error("{}: {error}", path.display())]
    Log {
        /// The log file.
        path: PathBuf,
        /// The importer's error.
        error: uavnav_logs::LogError,
    },
    /// A dataset path that is neither an ASL folder nor an `.mcap` file, or a wrong request.
    #[error("{}: {message}", path.display())]
    Unsupported {
        /// The path.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

impl DatasetError {
    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        DatasetError::Io {
            path: path.to_owned(),
            source,
        }
    }

    pub(crate) fn parse(path: &Path, line: usize, message: impl Into<String>) -> Self {
        DatasetError::Parse {
            path: path.to_owned(),
            line,
            message: message.into(),
        }
    }

    pub(crate) fn mcap(path: &Path, message: impl std::fmt::Display) -> Self {
        DatasetError::Mcap {
            path: path.to_owned(),
            message: message.to_string(),
        }
    }

    /// The 1-based line number, when the error has one.
    pub fn line(&self) -> Option<usize> {
        match self {
            DatasetError::Parse { line, .. }
            | DatasetError::TimeBackwards { line, .. }
            | DatasetError::Image { line, .. } => Some(*line),
            _ => None,
        }
    }
}

/// Shorthand for dataset results.
pub type Result<T, E = DatasetError> = std::result::Result<T, E>;
