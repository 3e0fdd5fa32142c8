//! The crate's error type: every message names the recording, and where it can the topic and
//! the message's 0-based index on that topic.

use std::path::{Path, PathBuf};

use crate::msg::DecodeError;

/// Every error this crate returns.
#[derive(Debug, thiserror::Error)]
pub enum BagError {
    /// An operating-system I/O error.
    #[error("{}: {cause}", .path.display())]
    Io {
        /// File being read.
        path: PathBuf,
        /// Underlying error (in the message, not repeated as a source: an error chain printed
        /// whole says it once).
        cause: std::io::Error,
    },

    /// The container is malformed or not supported (truncated, bad magic, unknown compression).
    #[error("{}: {message}", .path.display())]
    Format {
        /// File being read.
        path: PathBuf,
        /// What is wrong, with the byte offset or record where it helps.
        message: String,
    },

    /// One message cannot be decoded.
    #[error("{}: topic {topic} ({type_name}), message {index}: {cause}", .path.display())]
    Message {
        /// File being read.
        path: PathBuf,
        /// Topic of the message.
        topic: String,
        /// Its ROS type.
        type_name: String,
        /// 0-based index of the message on its topic.
        index: u64,
        /// What is wrong with it (in the message only).
        cause: DecodeError,
    },

    /// The recording cannot give frames: no fitting topic, no pose overlap, a bad option.
    #[error("{}: {message}", .path.display())]
    Recording {
        /// The recording.
        path: PathBuf,
        /// What is missing or inconsistent.
        message: String,
    },
}

impl BagError {
    /// An I/O error on `path`.
    pub fn io(path: &Path, cause: std::io::Error) -> Self {
        BagError::Io {
            path: path.to_path_buf(),
            cause,
        }
    }

    /// A container error on `path`.
    pub fn format(path: &Path, message: impl Into<String>) -> Self {
        BagError::Format {
            path: path.to_path_buf(),
            message: message.into(),
        }
    }

    /// A recording-level error on `path`.
    pub fn recording(path: &Path, message: impl Into<String>) -> Self {
        BagError::Recording {
            path: path.to_path_buf(),
            message: message.into(),
        }
    }
}
