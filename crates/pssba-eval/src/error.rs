//! Typed errors of the evaluation metrics.

use thiserror::Error;

/// Everything that can go wrong while computing an evaluation metric.
///
/// Every variant carries the offending values so that the message alone is
/// enough to diagnose the input.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum EvalError {
    /// Two inputs that must be parallel arrays have different lengths
    /// (e.g. source/destination points of an alignment, frames/poses).
    #[error("length mismatch: {left_name} has {left} elements but {right_name} has {right}")]
    LengthMismatch {
        /// Name of the first input.
        left_name: &'static str,
        /// Length of the first input.
        left: usize,
        /// Name of the second input.
        right_name: &'static str,
        /// Length of the second input.
        right: usize,
    },

    /// An alignment was requested with fewer point pairs than needed to fix
    /// a rigid motion (3 non-collinear points).
    #[error("SE(3) alignment needs at least {required} point pairs, got {got}")]
    TooFewPoints {
        /// Number of point pairs supplied.
        got: usize,
        /// Minimum number of point pairs.
        required: usize,
    },

    /// The cross-covariance of the point sets has rank < 2 (all points
    /// coincide or are collinear), so the rotation is not unique.
    #[error(
        "degenerate point configuration for Umeyama alignment (coincident or collinear points): \
         cross-covariance singular values {singular_values:?}"
    )]
    DegenerateAlignment {
        /// Singular values of the 3x3 cross-covariance, descending.
        singular_values: [f64; 3],
    },

    /// The SVD of the cross-covariance did not converge.
    #[error("SVD of the 3x3 cross-covariance did not converge within {max_iterations} iterations")]
    SvdFailed {
        /// Iteration budget that was exhausted.
        max_iterations: usize,
    },

    /// A NaN or infinite value was found in the input.
    #[error("non-finite {what} at index {index}")]
    NonFinite {
        /// Which input holds the value (e.g. "estimate timestamp").
        what: &'static str,
        /// Index of the offending element in that input.
        index: usize,
    },

    /// The association time tolerance is negative or not finite.
    #[error("invalid max. timestamp difference {max_diff_s} s: must be finite and >= 0")]
    InvalidMaxDiff {
        /// The rejected tolerance in seconds.
        max_diff_s: f64,
    },

    /// No estimate timestamp lies within the tolerance of a reference one.
    #[error(
        "no matching timestamps between reference ({gt_len} poses) and estimate \
         ({est_len} poses) with max. difference {max_diff_s} s"
    )]
    NoMatches {
        /// Number of reference poses.
        gt_len: usize,
        /// Number of estimated poses.
        est_len: usize,
        /// Tolerance used for the association, seconds.
        max_diff_s: f64,
    },

    /// Some poses matched, but fewer than an SE(3) alignment needs.
    #[error("only {matched} poses matched in time, SE(3) alignment needs at least {required}")]
    TooFewMatches {
        /// Number of associated pose pairs.
        matched: usize,
        /// Minimum number of pose pairs.
        required: usize,
    },

    /// The voxel edge length is zero, negative or not finite.
    #[error("invalid voxel size {voxel_m} m: must be finite and > 0")]
    InvalidVoxelSize {
        /// The rejected voxel edge length in metres.
        voxel_m: f64,
    },

    /// Occupancy averaging was requested over zero grid offsets.
    #[error("number of grid offsets must be at least 1, got {n_offsets}")]
    InvalidOffsetCount {
        /// The rejected number of offsets.
        n_offsets: usize,
    },
}
