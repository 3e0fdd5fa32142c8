//! What can go wrong on the wire: a message read from shared memory that fails validation
//! ([`MsgError`]), a node, service or port that cannot be created ([`ServiceError`]).

/// A message that failed validation. Any process of the same user can open a service, so
/// every header field is checked before use; the message is then dropped, never trusted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MsgError {
    /// A count in the header does not match the payload length.
    #[error("{message}: header says {expected} payload words, payload has {actual}")]
    LengthMismatch {
        /// Message kind.
        message: &'static str,
        /// Words implied by the header counts.
        expected: u64,
        /// Words in the payload.
        actual: u64,
    },
    /// A count above the configured maximum (or one whose size overflows).
    #[error("{message}: {field} = {value} exceeds the limit {limit}")]
    TooLarge {
        /// Message kind.
        message: &'static str,
        /// Header field.
        field: &'static str,
        /// Value read.
        value: u64,
        /// Largest accepted value.
        limit: u64,
    },
    /// A NaN or infinite number where a finite one is required.
    #[error("{message}: field {field} (item {index}) is not finite")]
    NotFinite {
        /// Message kind.
        message: &'static str,
        /// Field name.
        field: &'static str,
        /// Item index within the payload (0 for header fields).
        index: u64,
    },
    /// An index or enumeration value out of range.
    #[error("{message}: {field} = {value} is out of range (item {index})")]
    OutOfRange {
        /// Message kind.
        message: &'static str,
        /// Field name.
        field: &'static str,
        /// The value read (as f64, since payload words are f64).
        value: f64,
        /// Item index within the payload.
        index: u64,
    },
    /// A rotation that is not orthonormal.
    #[error("{message}: rotation of item {index} is not a rotation (|R^T R - I| = {error:e})")]
    NotARotation {
        /// Message kind.
        message: &'static str,
        /// Item index.
        index: u64,
        /// Frobenius norm of `R^T R - I`.
        error: f64,
    },
}

/// Why a node, service or port could not be created.
#[derive(Debug, thiserror::Error)]
#[error("{what}: {reason}")]
pub struct ServiceError {
    /// Which node, service or port.
    pub what: String,
    /// The iceoryx2 error, as text.
    pub reason: String,
}

impl ServiceError {
    /// From an iceoryx2 error.
    pub fn ipc(what: impl Into<String>, error: impl std::fmt::Debug) -> Self {
        Self {
            what: what.into(),
            reason: format!("{error:?}"),
        }
    }
}
