//! What a run returns: poses, surfaces, smoothed cloud and a report per scale.

use crate::factor::KernelRejections;
use nalgebra::{Isometry3, Matrix3, Point3};
use serde::Serialize;

/// A fitted surface in the world at the final poses.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WorldSurface {
    /// Frame of the kernel point.
    pub frame: usize,
    /// Kernel point in the world (m).
    pub kernel_in_world: Point3<f64>,
    /// Rows `[n0; n1; n2]`: world offsets to tangent coordinates; `n2` is the normal.
    pub tangent_from_world: Matrix3<f64>,
    /// `[a0..a5]` of `z = a0 x^2 + a1 y^2 + a2 xy + a3 x + a4 y + a5` (m).
    pub coefficients: [f64; 6],
    /// Kernel width (m).
    pub gamma_m: f64,
}

/// Diagnostics of one scale (one smoothing + adjustment round).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ScaleReport {
    /// Kernel width gamma (m).
    pub gamma_m: f64,
    /// Downsampled points in the window at this scale.
    pub cloud_points: usize,
    /// Kernels whose surface produced residuals.
    pub kernels_used: usize,
    /// Kernels not used, by reason.
    pub kernels_rejected: KernelRejections,
    /// Residuals linking two frames.
    pub residuals: usize,
    /// Robust cost before the adjustment.
    pub cost_before: f64,
    /// Robust cost after it.
    pub cost_after: f64,
    /// LM linearisations.
    pub iterations: usize,
    /// Norm of the stacked 6N pose change (m, rad), compared with T_conv.
    pub pose_change: f64,
    /// Free frames without residuals at this scale.
    pub unconstrained_frames: usize,
    /// Wall time of the scale (s).
    pub wall_time_s: f64,
    /// Where that time went.
    pub times: PhaseTimes,
}

/// Wall time of each phase of one scale (s); they add up to about `wall_time_s`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct PhaseTimes {
    /// Steps 1-2: per-frame downsampling (when the edge changed), world points, voxel index.
    pub cloud_s: f64,
    /// Step 2: PCA normals of the merged cloud.
    pub normals_s: f64,
    /// Steps 3-7: kernels, L0 normals, polynomial fits, residual points.
    pub extract_s: f64,
    /// Steps 7-8: the LM solve (in the process system: with the factor block's transport).
    pub solve_s: f64,
}

/// Everything a bundle adjustment run produces.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AdjustResult {
    /// Optimised world-from-lidar poses, one per input frame.
    pub world_from_lidar: Vec<Isometry3<f64>>,
    /// The last scale's surfaces, at the optimised poses.
    pub surfaces: Vec<WorldSurface>,
    /// Downsampled points of the last scale projected onto their nearest surface (world, m).
    pub smoothed_cloud: Vec<Point3<f64>>,
    /// One report per scale, in order.
    pub scales: Vec<ScaleReport>,
    /// True when a scale's pose change fell below T_conv.
    pub converged: bool,
    /// How many of the last `scales` were plain rounds (`final_plain_rounds`: consensus
    /// surfaces without anchor offsets, after convergence).
    pub plain_rounds: usize,
    /// Input points dropped because a coordinate was NaN or infinite.
    pub dropped_nonfinite_points: usize,
    /// Frames held fixed, their points left out, because they had fewer than
    /// `min_points_per_frame` points.
    pub sparse_frames_held: Vec<usize>,
    /// Wall time of the outputs after the last scale: world surfaces and smoothed cloud (s).
    pub finish_s: f64,
}
