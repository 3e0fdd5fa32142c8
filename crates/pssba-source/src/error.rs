//! The crate's error type: each message names the file (and line, topic or message) it is
//! about, once.

use std::path::PathBuf;

/// Every error this crate returns.
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    /// The input does not exist.
    #[error("{}: no such file or folder", .path.display())]
    NotFound {
        /// The input given.
        path: PathBuf,
    },

    /// No source recognises the input.
    #[error("{}: not an input pssba reads. It looked for:\n{looked_for}", .path.display())]
    NotRecognised {
        /// The input given.
        path: PathBuf,
        /// One line per source: its name and what it looks for.
        looked_for: String,
    },

    /// A dataset folder's file (PCD, TUM).
    #[error(transparent)]
    Dataset(#[from] pssba_io::IoError),

    /// A robot recording.
    #[error(transparent)]
    Bag(#[from] pssba_bag::BagError),

    /// A file of the input is malformed or inconsistent.
    #[error("{}: {message}", .path.display())]
    Invalid {
        /// The file (with the line or message in `message` where it helps).
        path: PathBuf,
        /// What is wrong.
        message: String,
    },

    /// A setting of the source is out of range.
    #[error("{0}")]
    Settings(String),
}

impl SourceError {
    /// A malformed or inconsistent file.
    pub fn invalid(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        SourceError::Invalid {
            path: path.into(),
            message: message.into(),
        }
    }
}
