//! The crate's single error type.

use std::path::PathBuf;

use crate::lzf::LzfError;

/// Every error this crate returns.
///
/// Each message starts with the path of the offending file (or dataset
/// folder) and, where it makes sense, names the 1-based line number, the
/// header key or field, and the offending value.
#[derive(Debug, thiserror::Error)]
pub enum IoError {
    /// An operating-system I/O error while reading or writing `path`.
    #[error("{}: {cause}", .path.display())]
    Io {
        /// File or directory being accessed.
        path: PathBuf,
        /// Underlying error (in the message, not repeated as a source: an error chain printed
        /// whole says it once).
        cause: std::io::Error,
    },

    /// A TUM line does not have exactly eight fields.
    #[error(
        "{}: line {line}: expected 8 numbers (stamp tx ty tz qx qy qz qw), found {found}",
        .path.display()
    )]
    TumFieldCount {
        /// TUM file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// Number of whitespace-separated fields found.
        found: usize,
    },

    /// A TUM field is not a number, or is NaN/infinite.
    #[error("{}: line {line}: {field} is '{value}', expected a finite number", .path.display())]
    TumNumber {
        /// TUM file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// Field name (`stamp`, `tx`, ..., `qw`).
        field: &'static str,
        /// The offending text.
        value: String,
    },

    /// A TUM quaternion is zero (norm below [`crate::MIN_QUATERNION_NORM`]) or not finite.
    #[error(
        "{}: line {line}: quaternion (qx qy qz qw) has norm {norm}, cannot normalise it",
        .path.display()
    )]
    TumQuaternion {
        /// TUM file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// Norm of the quaternion as written.
        norm: f64,
    },

    /// A pose passed to a writer contains NaN or infinite values.
    #[error("{}: pose {index} has a non-finite stamp, translation or rotation", .path.display())]
    NonFinitePose {
        /// File that was to be written.
        path: PathBuf,
        /// 0-based index of the pose in the slice.
        index: usize,
    },

    /// A malformed or missing PCD header entry.
    #[error("{}: PCD header: {message}", .path.display())]
    PcdHeader {
        /// PCD file.
        path: PathBuf,
        /// What is wrong, naming the key and value.
        message: String,
    },

    /// The x, y or z field has an unsupported TYPE, SIZE or COUNT.
    #[error("{}: PCD: field '{field}' {message}", .path.display())]
    PcdField {
        /// PCD file.
        path: PathBuf,
        /// Field name.
        field: String,
        /// What is wrong, e.g. `has TYPE I, expected F`.
        message: String,
    },

    /// POINTS does not equal WIDTH * HEIGHT.
    #[error("{}: PCD header: POINTS {points} != WIDTH*HEIGHT ({width}*{height})", .path.display())]
    PcdPointCount {
        /// PCD file.
        path: PathBuf,
        /// Value of POINTS.
        points: usize,
        /// Value of WIDTH.
        width: usize,
        /// Value of HEIGHT.
        height: usize,
    },

    /// The DATA kind is not ascii, binary or binary_compressed.
    #[error(
        "{}: PCD header: unsupported DATA kind '{kind}' (expected ascii, binary or binary_compressed)",
        .path.display()
    )]
    PcdUnsupportedData {
        /// PCD file.
        path: PathBuf,
        /// The DATA value found.
        kind: String,
    },

    /// The data section is shorter than the header promises.
    #[error("{}: PCD {encoding} data truncated: expected {expected} {unit}, found {found}", .path.display())]
    PcdTruncated {
        /// PCD file.
        path: PathBuf,
        /// `ascii`, `binary` or `binary_compressed`.
        encoding: &'static str,
        /// Amount required.
        expected: usize,
        /// Amount present.
        found: usize,
        /// `bytes` or `points`.
        unit: &'static str,
    },

    /// A bad line in an ASCII PCD data section.
    #[error("{}: line {line}: PCD ascii data: {message}", .path.display())]
    PcdAscii {
        /// PCD file.
        path: PathBuf,
        /// 1-based line number in the whole file.
        line: usize,
        /// What is wrong, naming the field and value.
        message: String,
    },

    /// Inconsistent sizes in a binary or binary_compressed data section.
    #[error("{}: PCD {encoding} data: {message}", .path.display())]
    PcdData {
        /// PCD file.
        path: PathBuf,
        /// `binary` or `binary_compressed`.
        encoding: &'static str,
        /// What is wrong.
        message: String,
    },

    /// The LZF payload of a binary_compressed PCD is corrupt.
    #[error("{}: PCD binary_compressed: LZF decompression failed: {cause}", .path.display())]
    PcdLzf {
        /// PCD file.
        path: PathBuf,
        /// Decoder error (in the message only).
        cause: LzfError,
    },

    /// A malformed PLY file.
    #[error("{}: PLY: {message}", .path.display())]
    Ply {
        /// PLY file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },

    /// A malformed STL mesh (empty, truncated, bad triangle count, non-finite vertex, bad
    /// ASCII line).
    #[error("{}: STL: {message}", .path.display())]
    Stl {
        /// STL file.
        path: PathBuf,
        /// What is wrong, with the line or triangle where it applies.
        message: String,
    },

    /// A dataset folder is missing parts or is inconsistent.
    #[error("{}: dataset: {message}", .path.display())]
    Dataset {
        /// Dataset folder (or the file inside it at fault).
        path: PathBuf,
        /// What is wrong.
        message: String,
    },

    /// A frame index past the end of the dataset.
    #[error("{}: dataset: frame index {index} out of range (dataset has {count} frames)", .path.display())]
    FrameIndex {
        /// Dataset folder.
        path: PathBuf,
        /// Requested index.
        index: usize,
        /// Number of frames.
        count: usize,
    },
}

impl IoError {
    /// Wraps a `std::io::Error` with the path it concerns.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        IoError::Io {
            path: path.into(),
            cause: source,
        }
    }
}
