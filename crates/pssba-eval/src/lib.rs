//! Evaluation metrics for PSS-BA (pure computations: no file I/O, no CLI).
//!
//! * [`ape`]: Absolute Pose Error, translation part, after SE(3) Umeyama
//!   alignment — numerically the same as `evo_ape tum GT EST -a` (evo 1.38.1):
//!   nearest-time association ([`associate`]), alignment ([`umeyama_se3`]),
//!   statistics ([`ape_translation`] → [`ApeResult`]).
//! * [`occupancy`]: map sharpness as the number of occupied voxels, averaged
//!   over seeded sub-voxel grid offsets ([`occupancy_averaged`],
//!   [`occupancy_of_frames`]).
//! * [`error`]: the typed [`EvalError`] returned by every fallible function.

pub mod ape;
pub mod error;
pub mod occupancy;

pub use ape::{
    ApeResult, DEFAULT_MAX_DIFF_S, ape_translation, ape_translation_paired, associate, umeyama_se3,
};
pub use error::EvalError;
pub use occupancy::{
    OccupancyResult, VoxelCount, count_voxels, occupancy_averaged, occupancy_of_frames,
    occupied_voxels, sub_voxel_offsets,
};
