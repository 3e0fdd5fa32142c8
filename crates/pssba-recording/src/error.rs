//! The crate's error type: every message names the file, topic or record it is about.

use std::path::PathBuf;

/// Every error this crate returns.
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    /// The MCAP writer failed (a full disk, a closed file).
    #[error("writing the MCAP file")]
    Write(#[source] mcap::McapError),

    /// A message could not be encoded.
    #[error("encoding a message on {topic}: {message}")]
    Encode {
        /// Its topic.
        topic: &'static str,
        /// What went wrong.
        message: String,
    },

    /// A recording could not be read: a bad record, a message that does not decode.
    #[error("{}: {message}", .path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// What is wrong, naming the topic and message where it can.
        message: String,
    },

    /// An operating-system error on a file.
    #[error("{what} {}", .path.display())]
    Io {
        /// What was being done ("opening", "ending").
        what: &'static str,
        /// The file.
        path: PathBuf,
        /// The cause.
        #[source]
        source: std::io::Error,
    },

    /// A setting that cannot be used (a map voxel size that is not positive).
    #[error("{0}")]
    Settings(String),

    /// A frame handed over with a time count that is not its point count.
    #[error("a frame of {points} points came with {times} point times")]
    PointTimes {
        /// Points of the frame.
        points: usize,
        /// Times given.
        times: usize,
    },

    /// A window result names a frame the recorder has not seen.
    #[error("window result for unknown frame {0}")]
    UnknownFrame(u64),
}

impl From<mcap::McapError> for RecordingError {
    fn from(error: mcap::McapError) -> Self {
        RecordingError::Write(error)
    }
}

impl RecordingError {
    /// A read error on `path`.
    pub fn read(path: &std::path::Path, message: impl Into<String>) -> Self {
        RecordingError::Read {
            path: path.to_path_buf(),
            message: message.into(),
        }
    }
}
