//! The BALM run: check the input, then outer iterations of "voxelise at the current poses,
//! LM on those voxels" until the poses stop moving (the schedule HBA uses BALM with).

use crate::lm::optimise;
use crate::normal_equations::total_cost;
use crate::result::{BalmResult, OuterReport};
use crate::voxel::voxelise;
use crate::{BalmConfig, BalmError};
use nalgebra::{Isometry3, Point3, Vector3};
use pssba_core::geometry::{Pose, pose_change_norm};
use pssba_core::parallel::Parallelism;
use std::time::Instant;

/// Adjusts `frames` (points in each lidar frame) from the initial `world_from_lidar`, frame 0
/// held fixed (gauge). Non-finite points are dropped; empty frames keep their pose.
pub fn adjust(
    frames: &[Vec<Point3<f64>>],
    world_from_lidar: &[Isometry3<f64>],
    config: &BalmConfig,
    parallelism: Parallelism,
) -> Result<BalmResult, BalmError> {
    config.validate()?;
    if frames.len() != world_from_lidar.len() {
        return Err(BalmError::CountMismatch {
            frames: frames.len(),
            poses: world_from_lidar.len(),
        });
    }
    if frames.len() < 2 {
        return Err(BalmError::TooFewFrames(frames.len()));
    }
    let initial: Vec<Pose> = world_from_lidar.iter().map(Pose::from_isometry).collect();
    let mut poses = initial.clone();
    if let Some(frame) = poses.iter().position(|p| !p.is_finite()) {
        return Err(BalmError::NonFinitePose { frame });
    }
    let finite: Vec<Vec<Vector3<f64>>> = frames
        .iter()
        .map(|f| {
            f.iter()
                .filter(|p| p.iter().all(|v| v.is_finite()))
                .map(|p| p.coords)
                .collect()
        })
        .collect();
    let dropped_nonfinite_points =
        frames.iter().map(Vec::len).sum::<usize>() - finite.iter().map(Vec::len).sum::<usize>();
    let empty_frames: Vec<usize> = (0..finite.len())
        .filter(|&k| finite[k].is_empty())
        .collect();
    let fixed: Vec<bool> = (0..poses.len()).map(|k| k == 0).collect();

    let mut outer = Vec::new();
    let mut converged = false;
    for round in 0..config.max_outer_iterations {
        let started = Instant::now();
        let voxels = voxelise(&finite, &poses, config, parallelism);
        let voxelise_time_s = started.elapsed().as_secs_f64();
        if voxels.planes.is_empty() {
            if round == 0 {
                return Err(BalmError::NoPlaneVoxels {
                    voxels_dropped: voxels.dropped,
                });
            }
            tracing::warn!("outer iteration {round}: no plane voxel left, stopping");
            break;
        }
        let cost_before = total_cost(&voxels.planes, &poses, parallelism);
        let (next, lm_iterations) = optimise(&voxels.planes, &poses, &fixed, config, parallelism);
        let pose_change = pose_change_norm(&poses, &next);
        poses = next;
        let report = OuterReport {
            plane_voxels: voxels.planes.len(),
            plane_voxels_per_layer: voxels.planes_per_layer(config.octree_layers),
            voxels_dropped: voxels.dropped,
            points_in_planes: voxels
                .planes
                .iter()
                .flat_map(|v| v.clusters.iter().map(|(_, c)| c.count))
                .sum(),
            cost_before,
            cost_after: lm_iterations.last().map_or(cost_before, |r| r.cost_after),
            lm_iterations,
            pose_change,
            voxelise_time_s,
            wall_time_s: started.elapsed().as_secs_f64(),
        };
        tracing::debug!(
            "balm outer {round}: {} planes, cost {:.5} -> {:.5}, {} LM its, dX {:.2e}",
            report.plane_voxels,
            report.cost_before,
            report.cost_after,
            report.lm_iterations.len(),
            report.pose_change
        );
        outer.push(report);
        if pose_change < config.outer_pose_change_threshold {
            converged = true;
            break;
        }
    }
    Ok(BalmResult {
        // Frames that never moved (frame 0, empty frames) return their input bit for bit.
        world_from_lidar: poses
            .iter()
            .zip(&initial)
            .zip(world_from_lidar)
            .map(|((pose, start), input)| {
                if pose == start {
                    *input
                } else {
                    pose.to_isometry()
                }
            })
            .collect(),
        outer,
        converged,
        dropped_nonfinite_points,
        empty_frames,
    })
}
