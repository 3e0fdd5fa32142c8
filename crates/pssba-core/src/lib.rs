//! PSS-BA: LiDAR bundle adjustment with progressive spatial smoothing (Li et al.), as a pure
//! library: no files, no IPC, no CLI, no global thread pool.
//!
//! A window of frames with rough world-from-lidar poses goes in; polynomial smoothing kernels
//! fitted at a width gamma that shrinks each scale give point-to-surface constraints;
//! Levenberg-Marquardt corrects all free poses. See `../shared/paper/pss-ba.tex` and
//! DESIGN.md section 2; module docs cite the steps and equations they implement.

pub mod anchors;
pub mod block_assembly;
pub mod block_hessian;
pub mod cg_solve;
pub mod cloud;
pub mod config;
pub mod dense_solve;
pub mod eigen3;
pub mod error;
pub mod factor;
pub mod fit;
pub mod frame_set;
pub mod geometry;
pub mod l0;
pub mod lm;
pub mod neighbour_grid;
pub mod normal_equations;
pub mod normals;
pub mod parallel;
pub mod pipeline;
pub mod progressive;
pub mod residual;
pub mod result;
pub mod sliding;
pub mod smoothed;
pub mod smoothing;
pub mod sparse_solve;
pub mod step_solver;
pub mod tangent;
pub mod voxel_index;
mod voxel_sort;

pub use config::{Method, PssBaConfig};
pub use error::CoreError;
pub use factor::{FactorBlock, FactorPoint, Surface};
pub use parallel::Parallelism;
pub use pipeline::{adjust_frames_observed, adjust_window, adjust_window_observed};
pub use progressive::{ProgressiveRun, ScaleStep, Window};
pub use result::{AdjustResult, PhaseTimes, ScaleReport, WorldSurface};
pub use sliding::{SlidingResult, SlidingWindows, WindowSpec, adjust_sliding};

/// Adjusts `frames` (lidar-frame points) from `world_from_lidar` with frame 0 held fixed.
pub fn adjust(
    frames: &[Vec<nalgebra::Point3<f64>>],
    world_from_lidar: &[nalgebra::Isometry3<f64>],
    config: &PssBaConfig,
) -> Result<AdjustResult, CoreError> {
    adjust_window(
        Window {
            frames,
            world_from_lidar,
            fixed: None,
        },
        config,
        Parallelism::Rayon,
    )
}
