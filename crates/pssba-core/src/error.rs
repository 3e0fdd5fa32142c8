//! Typed failures of the algorithm. Numerical trouble that only affects some kernels is not an
//! error: those kernels are skipped and counted in the per-scale report.

/// Why a bundle adjustment could not run or finish.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum CoreError {
    /// A configuration value is out of range.
    #[error("config field `{field}` = {value}: {reason}")]
    InvalidConfig {
        /// Field name as in `config/default.toml`.
        field: &'static str,
        /// The offending value.
        value: String,
        /// What is wrong with it.
        reason: &'static str,
    },
    /// The number of frames and of initial poses differ.
    #[error("{frames} frames but {poses} initial poses")]
    CountMismatch {
        /// Frames given.
        frames: usize,
        /// Poses given.
        poses: usize,
    },
    /// Bundle adjustment needs at least two frames.
    #[error("need at least 2 frames, got {0}")]
    TooFewFrames(usize),
    /// The mask of fixed frames does not have one entry per frame.
    #[error("fixed-frame mask has {mask} entries for {frames} frames")]
    FixedMaskLength {
        /// Frames given.
        frames: usize,
        /// Mask entries given.
        mask: usize,
    },
    /// An initial pose has a NaN or infinite entry.
    #[error("initial pose of frame {frame} is not finite")]
    NonFinitePose {
        /// Frame index.
        frame: usize,
    },
    /// Point times were given for a different number of frames (or stamps).
    #[error("{frames} frames but point times for {time_lists} frames and {stamps} frame stamps")]
    PointTimesFrames {
        /// Frames given.
        frames: usize,
        /// Frame stamps given.
        stamps: usize,
        /// Per-frame time lists given.
        time_lists: usize,
    },
    /// A frame's point times are not one per point.
    #[error("frame {frame} has {points} points but {times} point times")]
    PointTimesCount {
        /// Frame index.
        frame: usize,
        /// Points in the frame.
        points: usize,
        /// Times given for it.
        times: usize,
    },
    /// A frame's stamp or one of its point times is NaN or infinite.
    #[error("frame {frame} has a NaN or infinite stamp or point time")]
    NonFinitePointTime {
        /// Frame index.
        frame: usize,
    },
    /// No frame is free to move (all are held fixed).
    #[error("every frame is held fixed: nothing to adjust")]
    NothingToAdjust,
    /// A frame was pushed into a stream that had already ended.
    #[error("frame {sequence} arrived after the end of the stream")]
    FrameAfterEndOfStream {
        /// Stream index the frame would have had.
        sequence: usize,
    },
    /// The first scale produced no usable kernel linking two frames (e.g. the scene is a
    /// single line, empty, or the frames do not overlap).
    #[error(
        "no usable surface constraint between frames at gamma = {gamma_m} m \
         ({kernels_rejected} kernels rejected): the scene is degenerate or the frames do not overlap"
    )]
    NoConstraints {
        /// Kernel width of the failed scale.
        gamma_m: f64,
        /// Kernels tried and rejected.
        kernels_rejected: usize,
    },
}
