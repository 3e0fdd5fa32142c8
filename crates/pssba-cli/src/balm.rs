//! Running the BALM baseline from the CLI: its outer-iteration table on stderr and its JSON
//! summary.

use crate::report::ApeSummary;
use pssba_balm::{BalmResult, OuterReport};
use serde::Serialize;

/// Prints one line per outer iteration (voxelise + LM) to stderr.
pub fn print_outer(result: &BalmResult) {
    eprintln!(
        "{:>5} {:>7} {:>16} {:>8} {:>11} {:>11} {:>5} {:>8} {:>9} {:>7}",
        "outer",
        "planes",
        "per_layer",
        "dropped",
        "cost_before",
        "cost_after",
        "iters",
        "rms_m",
        "dX",
        "time_s"
    );
    for (k, o) in result.outer.iter().enumerate() {
        eprintln!(
            "{:>5} {:>7} {:>16} {:>8} {:>11.4} {:>11.4} {:>5} {:>8.4} {:>9.2e} {:>7.2}",
            k,
            o.plane_voxels,
            format!("{:?}", o.plane_voxels_per_layer),
            o.voxels_dropped,
            o.cost_before,
            o.cost_after,
            o.lm_iterations.len(),
            o.rms_distance_m(),
            o.pose_change,
            o.wall_time_s
        );
    }
    eprintln!(
        "balm {} after {} outer iterations{}{}",
        if result.converged {
            "converged"
        } else {
            "stopped (not converged)"
        },
        result.outer.len(),
        if result.dropped_nonfinite_points > 0 {
            format!(
                "; dropped {} non-finite points",
                result.dropped_nonfinite_points
            )
        } else {
            String::new()
        },
        if result.empty_frames.is_empty() {
            String::new()
        } else {
            format!("; {} empty frames kept in place", result.empty_frames.len())
        }
    );
}

/// The `--json` document of `adjust --method balm` and `demo --method balm`.
#[derive(Debug, Serialize)]
pub struct BalmSummary<'a> {
    /// Always "balm".
    pub method: &'static str,
    /// Frames in the window.
    pub frames: usize,
    /// Whether the outer loop converged.
    pub converged: bool,
    /// Per-outer-iteration reports.
    pub outer: &'a [OuterReport],
    /// Points dropped as non-finite.
    pub dropped_nonfinite_points: usize,
    /// Frames without points (kept at their initial pose).
    pub empty_frames: &'a [usize],
    /// APE, when ground truth is known.
    pub ape: Option<ApeSummary>,
    /// Wall time of the adjustment (s).
    pub wall_time_s: f64,
    /// Output files written.
    pub outputs: Vec<String>,
}

impl<'a> BalmSummary<'a> {
    /// Summary of `result`.
    pub fn new(
        result: &'a BalmResult,
        ape: Option<ApeSummary>,
        wall_time_s: f64,
        outputs: Vec<String>,
    ) -> Self {
        Self {
            method: "balm",
            frames: result.world_from_lidar.len(),
            converged: result.converged,
            outer: &result.outer,
            dropped_nonfinite_points: result.dropped_nonfinite_points,
            empty_frames: &result.empty_frames,
            ape,
            wall_time_s,
            outputs,
        }
    }
}

/// Every frame's points moved into the world by `world_from_lidar` (the merged map).
pub fn merged_cloud(
    frames: &[Vec<nalgebra::Point3<f64>>],
    world_from_lidar: &[nalgebra::Isometry3<f64>],
) -> Vec<nalgebra::Point3<f64>> {
    frames
        .iter()
        .zip(world_from_lidar)
        .flat_map(|(frame, pose)| frame.iter().map(move |p| pose * p))
        .filter(|p| p.iter().all(|v| v.is_finite()))
        .collect()
}
