//! The progressive loop (DESIGN step 9, paper "System Overview"): smooth at gamma, adjust all
//! poses, stop when the pose change is below T_conv, else gamma <- gamma / k.

use crate::cloud::deskew::FrameTimes;
use crate::config::PssBaConfig;
use crate::error::CoreError;
use crate::geometry::Pose;
use crate::parallel::Parallelism;
use crate::result::{AdjustResult, ScaleReport};
use crate::schedule::progressive::{ProgressiveRun, Window};
use crate::solve::lm::solve_block;
use nalgebra::{Isometry3, Point3};

/// Runs the configured PSS-BA variant on one window: every scale's smoothing and adjustment
/// in this process (see [`ProgressiveRun`] for the step-by-step form).
pub fn adjust_window(
    window: Window<'_>,
    config: &PssBaConfig,
    parallelism: Parallelism,
) -> Result<AdjustResult, CoreError> {
    adjust_window_observed(window, config, parallelism, |_, _| {})
}

/// [`adjust_window_observed`] on frames handed over instead of borrowed: the run filters them
/// in place rather than copying them, and frees them once the scales no longer need them (the
/// fixed frames: frame 0 only). `times`: the points' times, for frames taken while moving.
pub fn adjust_frames_observed(
    frames: Vec<Vec<Point3<f64>>>,
    world_from_lidar: &[Isometry3<f64>],
    times: Option<FrameTimes>,
    config: &PssBaConfig,
    parallelism: Parallelism,
    after_scale: impl FnMut(&ScaleReport, &[Pose]),
) -> Result<AdjustResult, CoreError> {
    let run = ProgressiveRun::new_owned(frames, world_from_lidar, None, times, config)?;
    run_to_end(run, parallelism, after_scale)
}

/// [`adjust_window`], calling `after_scale` with each scale's report and the poses it left
/// (e.g. to follow the error against a ground truth scale by scale).
pub fn adjust_window_observed(
    window: Window<'_>,
    config: &PssBaConfig,
    parallelism: Parallelism,
    after_scale: impl FnMut(&ScaleReport, &[Pose]),
) -> Result<AdjustResult, CoreError> {
    run_to_end(
        ProgressiveRun::new(window, config)?,
        parallelism,
        after_scale,
    )
}

/// Every scale of `run`, then its result.
fn run_to_end(
    mut run: ProgressiveRun,
    parallelism: Parallelism,
    mut after_scale: impl FnMut(&ScaleReport, &[Pose]),
) -> Result<AdjustResult, CoreError> {
    while let Some(step) = run.next_step(parallelism)? {
        let (adjusted, lm) = solve_block(
            &step.block,
            run.poses(),
            run.fixed(),
            &step.settings,
            parallelism,
        );
        let report = run.complete_step(step, adjusted, &lm)?.clone();
        after_scale(&report, run.poses());
    }
    Ok(run.finish(parallelism))
}
