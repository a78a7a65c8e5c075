//! The readers' one error type: every failure names the file, and a malformed line its
//! 1-based line number, so a user can open the file at the right place.

/// Why a receiver file could not be turned into epochs.
#[derive(Debug, thiserror::Error)]
pub enum FormatError {
    /// The file could not be read.
    #[error("{file}: {source}")]
    Io {
        /// The file's name as given.
        file: String,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// A line does not hold what its format says it must.
    #[error("{file}:{line}: {msg}")]
    Malformed {
        /// The file's name as given.
        file: String,
        /// 1-based line number.
        line: usize,
        /// What was wrong.
        msg: String,
    },
    /// A binary file's bytes at `offset` do not hold what its format says.
    #[error("{file}: byte {offset}: {msg}")]
    Corrupt {
        /// The file's name as given.
        file: String,
        /// Byte offset from the file's start.
        offset: usize,
        /// What was wrong.
        msg: String,
    },
    /// The file as a whole lacks something (a header line, a column, any data).
    #[error("{file}: {msg}")]
    Missing {
        /// The file's name as given.
        file: String,
        /// What is missing.
        msg: String,
    },
}

/// Where a line came from: builds [`FormatError::Malformed`] values for it.
#[derive(Debug, Clone, Copy)]
pub(crate) struct At<'a> {
    /// The file's name as given.
    pub file: &'a str,
    /// 1-based line number.
    pub line: usize,
}

impl At<'_> {
    /// A malformed-line error at this place.
    pub(crate) fn err(&self, msg: impl Into<String>) -> FormatError {
        FormatError::Malformed {
            file: self.file.to_string(),
            line: self.line,
            msg: msg.into(),
        }
    }
}

/// Reads a whole file, the error naming it.
pub(crate) fn read_to_string(path: &std::path::Path) -> Result<String, FormatError> {
    std::fs::read_to_string(path).map_err(|source| FormatError::Io {
        file: path.display().to_string(),
        source,
    })
}

/// Reads a whole binary file, the error naming it.
pub(crate) fn read_bytes(path: &std::path::Path) -> Result<Vec<u8>, FormatError> {
    std::fs::read(path).map_err(|source| FormatError::Io {
        file: path.display().to_string(),
        source,
    })
}

/// A whole-file error naming `file`.
pub(crate) fn missing(file: &str, msg: impl Into<String>) -> FormatError {
    FormatError::Missing {
        file: file.to_string(),
        msg: msg.into(),
    }
}
