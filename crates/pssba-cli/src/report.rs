//! Human-readable per-scale table (stderr) and the JSON summary shared by subcommands.

use pssba_core::{AdjustResult, Method};
use serde::Serialize;

/// Prints one line per scale to stderr.
pub fn print_scales(result: &AdjustResult) {
    eprintln!(
        "{:>5} {:>8} {:>8} {:>8} {:>9} {:>11} {:>11} {:>5} {:>9} {:>7} {:>7} {:>7} {:>7} {:>7}",
        "scale",
        "gamma_m",
        "kernels",
        "rejected",
        "residuals",
        "cost_before",
        "cost_after",
        "iters",
        "dX",
        "time_s",
        "cloud",
        "normals",
        "extract",
        "solve"
    );
    for (k, s) in result.scales.iter().enumerate() {
        eprintln!(
            "{:>5} {:>8.3} {:>8} {:>8} {:>9} {:>11.4} {:>11.4} {:>5} {:>9.5} {:>7.2} {:>7.2} {:>7.2} {:>7.2} {:>7.2}",
            k,
            s.gamma_m,
            s.kernels_used,
            s.kernels_rejected.total(),
            s.residuals,
            s.cost_before,
            s.cost_after,
            s.iterations,
            s.pose_change,
            s.wall_time_s,
            s.times.cloud_s,
            s.times.normals_s,
            s.times.extract_s,
            s.times.solve_s
        );
    }
    let total = |phase: fn(&pssba_core::PhaseTimes) -> f64| -> f64 {
        result.scales.iter().map(|s| phase(&s.times)).sum()
    };
    eprintln!(
        "time by phase: cloud {:.2} s, normals {:.2} s, extract {:.2} s, solve {:.2} s; \
         outputs (surfaces, smoothed cloud) {:.2} s",
        total(|t| t.cloud_s),
        total(|t| t.normals_s),
        total(|t| t.extract_s),
        total(|t| t.solve_s),
        result.finish_s
    );
    eprintln!(
        "{} after {} scales{}{}",
        if result.converged {
            "converged"
        } else {
            "stopped (not converged)"
        },
        result.scales.len(),
        match result.plain_rounds {
            0 => String::new(),
            1 => " (the last with plain surfaces: final_plain_rounds)".to_string(),
            n => format!(" (the last {n} with plain surfaces: final_plain_rounds)"),
        },
        if result.dropped_nonfinite_points > 0 {
            format!(
                "; dropped {} non-finite points",
                result.dropped_nonfinite_points
            )
        } else {
            String::new()
        }
    );
}

/// APE before and after, when ground truth is known.
#[derive(Debug, Serialize)]
pub struct ApeSummary {
    /// Initial poses' APE (m).
    pub initial_m: f64,
    /// Optimised poses' APE (m).
    pub optimized_m: f64,
}

/// The `--json` document of `adjust` and `demo`.
#[derive(Debug, Serialize)]
pub struct RunSummary<'a> {
    /// Method name.
    pub method: &'static str,
    /// Frames in the window.
    pub frames: usize,
    /// Whether T_conv was reached.
    pub converged: bool,
    /// Per-scale reports.
    pub scales: &'a [pssba_core::ScaleReport],
    /// Points dropped as non-finite.
    pub dropped_nonfinite_points: usize,
    /// Frames held fixed for having too few points.
    pub sparse_frames_held: &'a [usize],
    /// Surfaces of the last scale.
    pub surfaces: usize,
    /// Points of the smoothed cloud.
    pub smoothed_points: usize,
    /// APE, when ground truth is known.
    pub ape: Option<ApeSummary>,
    /// Wall time of the adjustment (s).
    pub wall_time_s: f64,
    /// Output files written.
    pub outputs: Vec<String>,
}

impl<'a> RunSummary<'a> {
    /// Summary of `result`.
    pub fn new(
        method: Method,
        result: &'a AdjustResult,
        ape: Option<ApeSummary>,
        wall_time_s: f64,
        outputs: Vec<String>,
    ) -> Self {
        Self {
            method: method.name(),
            frames: result.world_from_lidar.len(),
            converged: result.converged,
            scales: &result.scales,
            dropped_nonfinite_points: result.dropped_nonfinite_points,
            sparse_frames_held: &result.sparse_frames_held,
            surfaces: result.surfaces.len(),
            smoothed_points: result.smoothed_cloud.len(),
            ape,
            wall_time_s,
            outputs,
        }
    }
}

/// APE (m) of `est` against `gt`, both as (stamp, pose).
pub fn ape_m(
    gt: &[(f64, nalgebra::Isometry3<f64>)],
    est: &[(f64, nalgebra::Isometry3<f64>)],
) -> anyhow::Result<f64> {
    Ok(pssba_eval::ape_translation(gt, est, pssba_eval::DEFAULT_MAX_DIFF_S)?.rmse_m)
}
