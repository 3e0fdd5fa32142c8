//! PSS-BA: LiDAR bundle adjustment with progressive spatial smoothing (Li et al.), as a pure
//! library: no files, no IPC, no CLI, no global thread pool.
//!
//! A window of frames with rough world-from-lidar poses goes in; polynomial smoothing kernels
//! fitted at a width gamma that shrinks each scale give point-to-surface constraints;
//! Levenberg-Marquardt corrects all free poses. See `../shared/paper/pss-ba.tex` and
//! DESIGN.md section 2; module docs cite the steps and equations they implement.
//!
//! The modules follow those steps: `cloud` (steps 1-3: world cloud, normals, kernel points),
//! `kernels` (steps 4-7: L0 normals, tangent frames, polynomial fits, factor blocks), `solve`
//! (step 8: Levenberg-Marquardt and its linear solvers), `schedule` (step 9, and sliding
//! windows over a stream). They are private to the crate; the public API is the items below,
//! plus [`factor`] (the block that travels from the smoothing to the adjustment),
//! [`geometry`], [`parallel`], [`fit`], [`lm`], [`sliding`], [`flight`] and [`smoothing`].

mod cloud;
mod config;
mod error;
pub mod factor;
pub mod geometry;
mod kernels;
pub mod parallel;
mod result;
mod schedule;
mod solve;

pub use cloud::deskew::{FrameTimes, PointTimes, deskew_frame_along, deskew_frames, world_cloud};
pub use config::{Method, MotionPrior, PssBaConfig};
pub use error::CoreError;
pub use factor::{FactorBlock, FactorPoint, Surface};
pub use kernels::fit;
pub use parallel::Parallelism;
pub use result::{AdjustResult, PhaseTimes, ScaleReport, WorldSurface};
pub use schedule::flight::{
    self, FlightResult, FlightSettings, FlightStep, FlightWindows, GlobalPass, LoopClosure,
    adjust_flight,
};
pub use schedule::pipeline::{adjust_frames_observed, adjust_window, adjust_window_observed};
pub use schedule::progressive::{ProgressiveRun, ScaleStep, Window};
pub use schedule::sliding::{self, SlidingResult, SlidingWindows, WindowSpec, adjust_sliding};

pub mod lm {
    //! Levenberg-Marquardt over the free poses (DESIGN step 8): the solve of one factor block
    //! that a [`ScaleStep`](crate::ScaleStep) asks for ([`solve_block`]), the damping loop and
    //! dense solver the BALM baseline shares ([`damped_step`], [`DampedSolver`]), and the normal
    //! equations and linear solvers underneath, for the serial-twin tests and the benchmarks.

    pub use crate::solve::block_hessian::BlockHessian;
    pub use crate::solve::cg_solve;
    pub use crate::solve::damping::{
        DIAGONAL_FLOOR, Damping, KeptStep, damped_step, relative_decrease,
    };
    pub use crate::solve::dense_solve::DampedSolver;
    pub use crate::solve::lm::{LmReport, LmSettings, solve_block, variable_layout};
    pub use crate::solve::normal_equations::{
        NormalEquations, accumulate, block_cost, into_ordered_by_frame_pair,
    };
}

pub mod smoothing {
    //! The smoothing steps of one scale one call at a time (what
    //! [`ProgressiveRun::next_step`](crate::ProgressiveRun::next_step) runs): the world cloud
    //! with its normals (DESIGN steps 1-3), the factor block (steps 4-7) and the smoothed cloud
    //! at the final poses, for the serial-twin tests.

    pub use crate::cloud::scale_cloud::ScaleCloud;
    pub use crate::kernels::smoothed::smoothed_cloud;
    pub use crate::kernels::smoothing::extract_block;
}

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
            times: None,
        },
        config,
        Parallelism::Rayon,
    )
}
