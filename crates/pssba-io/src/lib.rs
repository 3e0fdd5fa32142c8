//! File formats of PSS-BA (LiDAR bundle adjustment): PCD frames, TUM
//! trajectories, PLY clouds, STL meshes (simulator scenes), and the dataset
//! folder that ties them together.
//!
//! # Dataset folder
//!
//! ```text
//! DIR/frames/000000.pcd ...  one PCD v0.7 per frame, points in the sensor frame;
//!                            DATA ascii, binary or binary_compressed; x y z as
//!                            F4 or F8; other fields ignored
//! DIR/poses.txt              TUM lines `stamp tx ty tz qx qy qz qw`, world from
//!                            lidar, one per frame in file-name order (initial poses)
//! DIR/gt.txt                 same format, ground truth (optional)
//! DIR/meta.json              optional free-form description (not read)
//! ```
//!
//! Open one with [`Dataset::open`], create one with [`Dataset::write`].
//! Every error is an [`IoError`] whose message names the file and, where
//! relevant, the line, header key or field, and the offending value.
//!
//! Point coordinates are returned exactly as stored, including NaN or
//! infinite values; callers filter them.

mod dataset;
mod error;
pub mod lzf;
mod pcd;
mod ply;
mod stl;
mod tum;

pub use dataset::{Dataset, FRAMES_DIR, GT_FILE, POSES_FILE};
pub use error::IoError;
pub use pcd::{
    PcdEncoding, PcdPrecision, TIME_FIELD, TimedPoints, pcd_point_count, pcd_to_bytes,
    pcd_to_bytes_with_times, read_pcd, read_pcd_from_bytes, read_pcd_with_times,
    read_pcd_with_times_from_bytes, write_pcd, write_pcd_with_precision,
};
pub use ply::{read_ply, read_ply_from_bytes, write_ply, write_ply_ascii};
pub use stl::{StlTriangle, read_stl, read_stl_from_bytes};
pub use tum::{MIN_QUATERNION_NORM, StampedPose, format_tum, parse_tum, read_tum, write_tum};
