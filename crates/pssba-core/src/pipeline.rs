//! The progressive loop (DESIGN step 9, paper "System Overview"): smooth at gamma, adjust all
//! poses, stop when the pose change is below T_conv, else gamma <- gamma / k.

use crate::cloud::ScaleCloud;
use crate::config::{Method, PssBaConfig};
use crate::error::CoreError;
use crate::fit::SurfaceModel;
use crate::geometry::{Pose, pose_change_norm};
use crate::lm::{LmSettings, solve_block};
use crate::parallel::Parallelism;
use crate::result::{AdjustResult, ScaleReport};
use crate::smoothed::{smoothed_cloud, world_surfaces};
use crate::smoothing::extract_block;
use nalgebra::{Isometry3, Point3, Vector3};
use std::time::Instant;

/// Input of one window.
#[derive(Debug, Clone, Copy)]
pub struct Window<'a> {
    /// Points of each frame in its lidar frame (m).
    pub frames: &'a [Vec<Point3<f64>>],
    /// Initial world-from-lidar pose of each frame.
    pub world_from_lidar: &'a [Isometry3<f64>],
    /// Frames held fixed (the gauge). `None`: frame 0 only.
    pub fixed: Option<&'a [bool]>,
}

/// Gamma of scale `index` for the configured method.
fn gamma_of_scale(config: &PssBaConfig, index: usize) -> f64 {
    match config.method {
        Method::PssBaFs => config.fixed_gamma_m,
        Method::PssBa | Method::Point2plane => {
            (config.gamma0_m / config.gamma_shrink.powi(index as i32)).max(config.gamma_min_m)
        }
    }
}

/// Runs the configured PSS-BA variant on one window.
pub fn adjust_window(
    window: Window<'_>,
    config: &PssBaConfig,
    parallelism: Parallelism,
) -> Result<AdjustResult, CoreError> {
    config.validate()?;
    let n = window.frames.len();
    if n != window.world_from_lidar.len() {
        return Err(CoreError::CountMismatch {
            frames: n,
            poses: window.world_from_lidar.len(),
        });
    }
    if n < 2 {
        return Err(CoreError::TooFewFrames(n));
    }
    let mut poses: Vec<Pose> = window
        .world_from_lidar
        .iter()
        .map(Pose::from_isometry)
        .collect();
    if let Some(frame) = poses.iter().position(|p| !p.is_finite()) {
        return Err(CoreError::NonFinitePose { frame });
    }
    let mut dropped_nonfinite_points = 0;
    let mut frames: Vec<Vec<Vector3<f64>>> = window
        .frames
        .iter()
        .map(|f| {
            let kept: Vec<Vector3<f64>> = f
                .iter()
                .filter(|p| p.coords.iter().all(|v| v.is_finite()))
                .map(|p| p.coords)
                .collect();
            dropped_nonfinite_points += f.len() - kept.len();
            kept
        })
        .collect();
    if dropped_nonfinite_points > 0 {
        tracing::warn!(
            dropped_nonfinite_points,
            "dropped points with NaN or infinite coordinates"
        );
    }
    let mut fixed: Vec<bool> = match window.fixed {
        Some(mask) if mask.len() == n => mask.to_vec(),
        Some(mask) => {
            return Err(CoreError::FixedMaskLength {
                frames: n,
                mask: mask.len(),
            });
        }
        None => (0..n).map(|k| k == 0).collect(),
    };
    let sparse_frames_held: Vec<usize> = (0..n)
        .filter(|&k| !fixed[k] && frames[k].len() < config.min_points_per_frame)
        .collect();
    for &k in &sparse_frames_held {
        tracing::warn!(
            frame = k,
            points = frames[k].len(),
            "frame has too few points; holding it fixed and leaving its points out"
        );
        fixed[k] = true;
        // Held at a pose nobody checked, its points would anchor the others to it.
        frames[k].clear();
    }
    if fixed.iter().all(|&f| f) {
        return Err(CoreError::NothingToAdjust);
    }
    let model = match config.method {
        Method::Point2plane => SurfaceModel::Planar,
        Method::PssBa | Method::PssBaFs => SurfaceModel::Quadratic,
    };

    let mut scales = Vec::new();
    let mut converged = false;
    let mut last = None;
    for index in 0..config.max_scales {
        let started = Instant::now();
        let gamma_m = gamma_of_scale(config, index);
        let _span = tracing::info_span!("scale", index, gamma_m).entered();
        let cloud = ScaleCloud::build(
            &frames,
            &poses,
            config.downsample_m(gamma_m),
            config.normal_neighbours,
            parallelism,
        );
        let cloud_s = started.elapsed().as_secs_f64();
        let block = extract_block(&cloud, &poses, gamma_m, model, config, parallelism);
        let extract_s = started.elapsed().as_secs_f64() - cloud_s;
        if block.points.is_empty() {
            if index == 0 {
                return Err(CoreError::NoConstraints {
                    gamma_m,
                    kernels_rejected: block.rejected.total(),
                });
            }
            tracing::warn!(gamma_m, "no usable constraint at this scale; stopping");
            break;
        }
        let coarse = gamma_m >= config.prior_min_gamma_m;
        let settings = LmSettings {
            max_iterations: config.lm_max_iterations,
            initial_lambda: config.lm_initial_lambda,
            // Coarse scales only: their surfaces are crude and extrapolate; a frame that slid
            // along them went 2 m astray (40 frames, seed 2), while a prior on every scale slowed
            // the fine ones (20 frames: APE 0.0023 m without, up to 0.037 m with).
            prior_translation_m: if coarse {
                config.prior_translation_m
            } else {
                f64::INFINITY
            },
            prior_rotation_rad: if coarse {
                config.prior_rotation_rad
            } else {
                f64::INFINITY
            },
        };
        let (adjusted, lm) = solve_block(&block, &poses, &fixed, &settings, parallelism);
        let pose_change = pose_change_norm(&poses, &adjusted);
        tracing::debug!(
            cloud_s,
            extract_s,
            solve_s = started.elapsed().as_secs_f64() - cloud_s - extract_s,
            "stage times"
        );
        poses = adjusted;
        let report = ScaleReport {
            gamma_m,
            cloud_points: cloud.len(),
            kernels_used: block.surfaces.len(),
            kernels_rejected: block.rejected,
            residuals: lm.residuals,
            cost_before: lm.cost_before,
            cost_after: lm.cost_after,
            iterations: lm.iterations,
            pose_change,
            unconstrained_frames: lm.unconstrained_frames,
            wall_time_s: started.elapsed().as_secs_f64(),
        };
        tracing::info!(?report, "scale done");
        scales.push(report);
        last = Some((cloud, block));
        if pose_change < config.convergence_threshold {
            converged = true;
            break;
        }
    }
    let (surfaces, smoothed) = match &last {
        Some((cloud, block)) => (
            world_surfaces(block, &poses),
            smoothed_cloud(cloud, block, &poses, parallelism),
        ),
        None => (Vec::new(), Vec::new()),
    };
    Ok(AdjustResult {
        world_from_lidar: poses.iter().map(Pose::to_isometry).collect(),
        surfaces,
        smoothed_cloud: smoothed,
        scales,
        converged,
        dropped_nonfinite_points,
        sparse_frames_held,
    })
}
