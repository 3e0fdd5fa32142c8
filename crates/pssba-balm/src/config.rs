//! Every tunable of the BALM baseline, with its unit. Defaults follow the BALM2 paper's
//! settings as described in DESIGN.md section 3; the schedule (re-voxelise each outer loop) is
//! the one HBA uses BALM with.

use crate::BalmError;
use serde::{Deserialize, Serialize};

/// Configuration of one BALM run. Units are in the field names; the `[balm]` table of a
/// `pssba` TOML config uses the same keys.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BalmConfig {
    /// Edge of the root voxels of the world grid (paper: 2 m).
    pub voxel_size_m: f64,
    /// Octree layers in total, the root included: 3 means root voxels of `voxel_size_m`, cut at
    /// most twice (edges 2 m, 1 m, 0.5 m with the defaults).
    pub octree_layers: usize,
    /// A voxel is a plane when lambda_min / lambda_mid of its point covariance is below this
    /// (paper: 1/16), on every layer except the deepest.
    pub plane_eigen_ratio: f64,
    /// The same threshold on the deepest layer (paper: 1/9), where a voxel that fails is
    /// dropped instead of cut.
    pub plane_eigen_ratio_deepest: f64,
    /// Fewest points (all frames together) a plane voxel holds (paper: 15).
    pub min_points_per_voxel: usize,
    /// Fewest distinct frames a plane voxel is seen by (paper: 2).
    pub min_frames_per_voxel: usize,
    /// Outer iterations at most; each re-voxelises at the current poses, then runs LM.
    pub max_outer_iterations: usize,
    /// Stop the outer loop when one outer iteration moves the poses less than this (norm of
    /// the stacked per-frame `[log(R' R^T) (rad); t' - t (m)]`).
    pub outer_pose_change_threshold: f64,
    /// LM iterations (re-linearisations) per outer iteration at most.
    pub max_lm_iterations: usize,
    /// Initial LM damping, relative to the Hessian diagonal.
    pub lm_initial_lambda: f64,
    /// LM stops when an accepted step lowers the cost by less than this fraction.
    pub lm_min_relative_decrease: f64,
}

impl Default for BalmConfig {
    fn default() -> Self {
        Self {
            voxel_size_m: 2.0,
            octree_layers: 3,
            plane_eigen_ratio: 1.0 / 16.0,
            plane_eigen_ratio_deepest: 1.0 / 9.0,
            min_points_per_voxel: 15,
            min_frames_per_voxel: 2,
            max_outer_iterations: 5,
            outer_pose_change_threshold: 1e-3,
            max_lm_iterations: 15,
            lm_initial_lambda: 1e-3,
            lm_min_relative_decrease: 1e-7,
        }
    }
}

fn invalid(field: &'static str, value: impl ToString, reason: &'static str) -> BalmError {
    BalmError::InvalidConfig {
        field,
        value: value.to_string(),
        reason,
    }
}

impl BalmConfig {
    /// Checks every field's range; the error names the first bad field.
    pub fn validate(&self) -> Result<(), BalmError> {
        if !(self.voxel_size_m.is_finite() && self.voxel_size_m > 0.0) {
            return Err(invalid("voxel_size_m", self.voxel_size_m, "must be > 0"));
        }
        if !(1..=8).contains(&self.octree_layers) {
            return Err(invalid(
                "octree_layers",
                self.octree_layers,
                "must be 1..=8",
            ));
        }
        for (field, value) in [
            ("plane_eigen_ratio", self.plane_eigen_ratio),
            ("plane_eigen_ratio_deepest", self.plane_eigen_ratio_deepest),
        ] {
            if !(value > 0.0 && value <= 1.0) {
                return Err(invalid(field, value, "must be in (0, 1]"));
            }
        }
        if self.min_points_per_voxel < 3 {
            return Err(invalid(
                "min_points_per_voxel",
                self.min_points_per_voxel,
                "a plane needs at least 3 points",
            ));
        }
        if self.min_frames_per_voxel < 2 {
            return Err(invalid(
                "min_frames_per_voxel",
                self.min_frames_per_voxel,
                "a voxel seen by one frame does not constrain any pose",
            ));
        }
        for (field, value) in [
            ("max_outer_iterations", self.max_outer_iterations),
            ("max_lm_iterations", self.max_lm_iterations),
        ] {
            if value == 0 {
                return Err(invalid(field, value, "must be at least 1"));
            }
        }
        for (field, value) in [
            (
                "outer_pose_change_threshold",
                self.outer_pose_change_threshold,
            ),
            ("lm_min_relative_decrease", self.lm_min_relative_decrease),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(invalid(field, value, "must be a finite number >= 0"));
            }
        }
        if !(self.lm_initial_lambda.is_finite() && self.lm_initial_lambda > 0.0) {
            return Err(invalid(
                "lm_initial_lambda",
                self.lm_initial_lambda,
                "must be a finite number > 0",
            ));
        }
        Ok(())
    }
}
