//! The import error, and the bounds-checked little-endian cursor both readers decode with, so that
//! every failure names the byte offset where the input stopped making sense.

/// Why a log could not be imported. Every decoding error names the byte offset (from the start of
/// the file) of the message or field where the input stopped making sense.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LogError {
    /// The file could not be read (only from [`crate::open`]).
    #[error("cannot read {path}: {reason}")]
    Io {
        /// The path given.
        path: String,
        /// The operating system's reason.
        reason: String,
    },
    /// The bytes are neither a DataFlash log nor a ULog file.
    #[error(
        "not a flight log: the first bytes are neither a DataFlash message (A3 95), the ULog magic nor a MAVLink telemetry record"
    )]
    UnknownFormat,
    /// The input ends inside a header or a message.
    #[error("truncated at byte {offset}: {what} needs {need} bytes, {available} left")]
    Truncated {
        /// Offset of the incomplete element.
        offset: u64,
        /// What was being read.
        what: &'static str,
        /// Bytes that element needs.
        need: u64,
        /// Bytes left in the input from `offset`.
        available: u64,
    },
    /// The bytes at `offset` are not valid for the format.
    #[error("corrupt log at byte {offset}: {reason}")]
    Corrupt {
        /// Offset of the offending message or field.
        offset: u64,
        /// What is wrong.
        reason: String,
    },
    /// The log decodes but lacks what an import needs (e.g. no IMU messages).
    #[error("unusable log: {0}")]
    Unusable(String),
}

impl LogError {
    /// The byte offset the error refers to, when it is a decoding error.
    pub fn offset(&self) -> Option<u64> {
        match self {
            LogError::Truncated { offset, .. } | LogError::Corrupt { offset, .. } => Some(*offset),
            _ => None,
        }
    }

    /// Whether the input merely ends inside a message (a log cut short), as opposed to bytes
    /// that are wrong for the format.
    pub fn is_cut_tail(&self) -> bool {
        matches!(self, LogError::Truncated { .. })
    }

    pub(crate) fn corrupt(offset: usize, reason: impl Into<String>) -> Self {
        LogError::Corrupt {
            offset: offset as u64,
            reason: reason.into(),
        }
    }
}

/// A view of `len` bytes at absolute offset `base` of the file. Reads are bounds-checked and fail
/// with [`LogError::Truncated`] naming the absolute offset.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Bytes<'a> {
    data: &'a [u8],
    base: usize,
}

impl<'a> Bytes<'a> {
    pub(crate) fn new(data: &'a [u8], base: usize) -> Self {
        Self { data, base }
    }

    /// `n` bytes at `at` (relative to this view).
    pub(crate) fn slice(
        &self,
        at: usize,
        n: usize,
        what: &'static str,
    ) -> Result<&'a [u8], LogError> {
        at.checked_add(n)
            .and_then(|end| self.data.get(at..end))
            .ok_or(LogError::Truncated {
                offset: (self.base + at) as u64,
                what,
                need: n as u64,
                available: self.data.len().saturating_sub(at) as u64,
            })
    }

    /// A sub-view of `n` bytes at `at`.
    pub(crate) fn view(
        &self,
        at: usize,
        n: usize,
        what: &'static str,
    ) -> Result<Bytes<'a>, LogError> {
        Ok(Bytes::new(self.slice(at, n, what)?, self.base + at))
    }

    pub(crate) fn array<const N: usize>(
        &self,
        at: usize,
        what: &'static str,
    ) -> Result<[u8; N], LogError> {
        let s = self.slice(at, N, what)?;
        let mut a = [0u8; N];
        a.copy_from_slice(s);
        Ok(a)
    }

    pub(crate) fn u8(&self, at: usize, what: &'static str) -> Result<u8, LogError> {
        Ok(self.array::<1>(at, what)?[0])
    }

    pub(crate) fn u16(&self, at: usize, what: &'static str) -> Result<u16, LogError> {
        Ok(u16::from_le_bytes(self.array(at, what)?))
    }

    pub(crate) fn u64(&self, at: usize, what: &'static str) -> Result<u64, LogError> {
        Ok(u64::from_le_bytes(self.array(at, what)?))
    }
}

/// A fixed-size, NUL-padded text field as a string (lossy: logs are not always valid UTF-8).
pub(crate) fn text(bytes: &[u8]) -> String {
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
    String::from_utf8_lossy(&bytes[..end]).into_owned()
}
