//! Typed failures of a BALM run. Voxels that are not planes are not errors: they are dropped
//! and counted in the outer report.

/// Why a BALM adjustment could not run.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum BalmError {
    /// A configuration value is out of range.
    #[error("balm config field `{field}` = {value}: {reason}")]
    InvalidConfig {
        /// Field name as in [`crate::BalmConfig`] (and the `[balm]` TOML table).
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
    /// An initial pose has a NaN or infinite entry.
    #[error("initial pose of frame {frame} is not finite")]
    NonFinitePose {
        /// Frame index.
        frame: usize,
    },
    /// The first voxelisation found no plane voxel seen by two frames: nothing links the
    /// frames (empty frames, no overlap, or a scene without planar patches).
    #[error(
        "no plane voxel at the initial poses ({voxels_dropped} voxels dropped): \
         the frames do not overlap or the scene has no planar patches"
    )]
    NoPlaneVoxels {
        /// Voxels (of any layer) examined and dropped.
        voxels_dropped: usize,
    },
}
