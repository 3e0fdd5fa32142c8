//! What a BALM run returns: poses and a report per outer iteration and per LM iteration.

use nalgebra::Isometry3;
use serde::Serialize;

/// One LM linearisation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LmIterationReport {
    /// Summed eigenvalue cost at the linearisation point (m^2).
    pub cost_before: f64,
    /// Cost after the accepted step (equal to `cost_before` if none was accepted).
    pub cost_after: f64,
    /// Damping of the accepted (or last tried) step.
    pub lambda: f64,
    /// Norm of the accepted step (rad and m stacked; 0 if none).
    pub step_norm: f64,
    /// Whether a step lowered the cost.
    pub accepted: bool,
}

/// One outer iteration: voxelise at the current poses, then LM.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OuterReport {
    /// Plane voxels used.
    pub plane_voxels: usize,
    /// Plane voxels on each octree layer (index 0 = root voxels).
    pub plane_voxels_per_layer: Vec<usize>,
    /// Voxels dropped (too few points or frames, or not planar on the deepest layer).
    pub voxels_dropped: usize,
    /// Points inside plane voxels.
    pub points_in_planes: usize,
    /// Summed `N lambda_min` over the plane voxels before LM (m^2).
    pub cost_before: f64,
    /// The same after LM (m^2).
    pub cost_after: f64,
    /// LM linearisations, in order.
    pub lm_iterations: Vec<LmIterationReport>,
    /// Norm of the stacked per-frame pose change of this outer iteration (rad and m).
    pub pose_change: f64,
    /// Wall time of the voxelisation (s).
    pub voxelise_time_s: f64,
    /// Wall time of the whole outer iteration (s).
    pub wall_time_s: f64,
}

impl OuterReport {
    /// RMS point-to-plane distance after LM (m): `sqrt(cost_after / points_in_planes)`.
    pub fn rms_distance_m(&self) -> f64 {
        (self.cost_after / self.points_in_planes.max(1) as f64).sqrt()
    }
}

/// Everything a BALM run produces.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BalmResult {
    /// Optimised world-from-lidar poses, one per input frame (frame 0 unchanged).
    pub world_from_lidar: Vec<Isometry3<f64>>,
    /// One report per outer iteration.
    pub outer: Vec<OuterReport>,
    /// True when an outer iteration's pose change fell below the threshold.
    pub converged: bool,
    /// Input points dropped because a coordinate was NaN or infinite.
    pub dropped_nonfinite_points: usize,
    /// Frames without any (finite) point: they take no part and keep their initial pose.
    pub empty_frames: Vec<usize>,
}
