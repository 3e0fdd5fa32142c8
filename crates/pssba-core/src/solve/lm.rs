//! Levenberg-Marquardt over all free poses for one factor block (DESIGN step 8, paper
//! section "Poses Adjustment"): re-linearise, solve `(H + lambda D) dx = -b` (dense Cholesky,
//! sparse Cholesky or conjugate gradients, see step_solver.rs), apply `R <- Exp(dtheta) R`,
//! `t <- t + dt`, accept if the robust cost drops (the damping loop of damping.rs, which the
//! BALM baseline shares).

use crate::factor::FactorBlock;
use crate::geometry::Pose;
use crate::geometry::log_so3;
use crate::parallel::Parallelism;
use crate::solve::damping::{Damping, damped_step, relative_decrease};
use crate::solve::motion_prior::MotionPriorEdges;
use crate::solve::normal_equations::{
    NormalEquations, accumulate_into, block_cost, is_ordered_by_frame_pair, order_by_frame_pair,
};
use crate::solve::step_solver::StepSolver;
use serde::Serialize;

/// Outcome of one LM run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LmReport {
    /// Robust cost before the first step.
    pub cost_before: f64,
    /// Robust cost at the returned poses.
    pub cost_after: f64,
    /// Linearisations performed.
    pub iterations: usize,
    /// Residuals linking two frames.
    pub residuals: usize,
    /// Free frames without any residual (their poses stay where they are).
    pub unconstrained_frames: usize,
}

/// Smallest relative cost decrease that continues the iterations. At 1e-7 nearly every scale
/// ran all `lm_max_iterations`; at 1e-3 half as many linearisations, and `pssba bench` (6
/// scenes, 100 x 20k) ends with the same APE or lower (crane 31.3 -> 28.8 mm, mbs 3.5 -> 3.3,
/// truss 1.6 -> 1.5, the rest equal): a scale's surfaces are re-fitted at the next scale
/// anyway, so polishing the poses against them further buys nothing.
const MIN_RELATIVE_DECREASE: f64 = 1e-3;
/// Damping increases tried on one linearisation before giving up.
const MAX_DAMPING_TRIES: usize = 10;

/// Maps each frame to its first parameter index (`None` when held fixed).
pub fn variable_layout(fixed: &[bool]) -> (Vec<Option<usize>>, usize) {
    let mut next = 0;
    let layout = fixed
        .iter()
        .map(|&f| {
            (!f).then(|| {
                next += 6;
                next - 6
            })
        })
        .collect();
    (layout, next)
}

/// LM settings of one scale.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LmSettings {
    /// Linearisations at most.
    pub max_iterations: usize,
    /// Initial damping (relative to the Hessian diagonal).
    pub initial_lambda: f64,
    /// Sigma (m) of the prior that ties each free pose's translation to its value at the start
    /// of the scale.
    pub prior_translation_m: f64,
    /// Sigma (rad) of the same prior on rotation.
    pub prior_rotation_rad: f64,
    /// Sigma (m) of the motion prior on each consecutive pair's relative translation
    /// (`motion_prior.rs`; infinite = none).
    pub motion_translation_m: f64,
    /// Sigma (rad) of the motion prior on relative rotation (infinite = none).
    pub motion_rotation_rad: f64,
}

/// Prior residuals `[log(R R0^T) / sigma_r; (t - t0) / sigma_t]` of one pose.
fn prior_residual(pose: &Pose, start: &Pose, settings: &LmSettings) -> [f64; 6] {
    let dtheta =
        log_so3(&(pose.rotation * start.rotation.transpose())) / settings.prior_rotation_rad;
    let dt = (pose.translation - start.translation) / settings.prior_translation_m;
    [dtheta.x, dtheta.y, dtheta.z, dt.x, dt.y, dt.z]
}

/// Cost of the scale prior over the free frames.
fn prior_cost(
    poses: &[Pose],
    start: &[Pose],
    variable_of: &[Option<usize>],
    settings: &LmSettings,
) -> f64 {
    (0..poses.len())
        .filter(|&k| variable_of[k].is_some())
        .map(|k| {
            prior_residual(&poses[k], &start[k], settings)
                .iter()
                .map(|r| r * r)
                .sum::<f64>()
        })
        .sum()
}

/// Adds the prior to the normal equations (its Jacobian is taken as the identity scaled by
/// 1/sigma, exact at the start of the scale).
fn add_prior(
    eq: &mut NormalEquations,
    poses: &[Pose],
    start: &[Pose],
    variable_of: &[Option<usize>],
    settings: &LmSettings,
) {
    let inv_sigma = [
        1.0 / settings.prior_rotation_rad,
        1.0 / settings.prior_rotation_rad,
        1.0 / settings.prior_rotation_rad,
        1.0 / settings.prior_translation_m,
        1.0 / settings.prior_translation_m,
        1.0 / settings.prior_translation_m,
    ];
    for (k, var) in variable_of.iter().enumerate() {
        let Some(v) = var else { continue };
        let r = prior_residual(&poses[k], &start[k], settings);
        for i in 0..6 {
            eq.hessian
                .add_diagonal(v / 6, i, inv_sigma[i] * inv_sigma[i]);
            eq.gradient[v + i] += inv_sigma[i] * r[i];
            eq.cost += r[i] * r[i];
        }
    }
}

/// Runs LM from `poses` on `block`, holding `fixed` frames. Besides the block's residuals the
/// cost holds a weak prior on each free pose's change within this scale: a frame that only
/// sees a plane or few kernels at a coarse scale would otherwise slide far along directions
/// its residuals barely observe (seen: one frame of 40 jumping 0.45 m). Returns the new poses.
pub fn solve_block(
    block: &FactorBlock,
    poses: &[Pose],
    fixed: &[bool],
    settings: &LmSettings,
    parallelism: Parallelism,
) -> (Vec<Pose>, LmReport) {
    let (variable_of, dim) = variable_layout(fixed);
    // Blocks from `extract_block` come ordered; others are ordered in a copy.
    let ordered;
    let block = if is_ordered_by_frame_pair(block, poses.len()) {
        block
    } else {
        ordered = order_by_frame_pair(block, poses.len());
        &ordered
    };
    if tracing::enabled!(tracing::Level::DEBUG) {
        let pairs = coupled_pairs(block, &variable_of);
        let free = dim / 6;
        tracing::debug!(
            free_frames = free,
            coupled_pairs = pairs,
            density = pairs as f64 / (free * free.saturating_sub(1) / 2).max(1) as f64,
            "co-visibility of the free frames"
        );
    }
    let mut current = poses.to_vec();
    let mut damping = Damping::new(settings.initial_lambda);
    let mut report = LmReport {
        cost_before: f64::NAN,
        cost_after: f64::NAN,
        iterations: 0,
        residuals: 0,
        unconstrained_frames: 0,
    };
    // Robust cost of the block's residuals at `current`, once a step has computed it.
    let mut data_cost = None;
    let motion = MotionPriorEdges::new(
        poses,
        &variable_of,
        settings.motion_translation_m,
        settings.motion_rotation_rad,
    );
    let motion_pairs = motion
        .as_ref()
        .map_or_else(Vec::new, |m| m.free_pairs(&variable_of));
    let mut eq = NormalEquations::zeros_with_pairs(block, &variable_of, dim, &motion_pairs);
    let mut solver = StepSolver::for_pattern(&eq.hessian);
    for iteration in 0..settings.max_iterations {
        accumulate_into(
            &mut eq,
            block,
            &current,
            &variable_of,
            data_cost,
            parallelism,
        );
        let data_residuals = eq.residuals;
        if iteration == 0 {
            // Before the prior: it would give every free frame a non-zero diagonal.
            report.cost_before = eq.cost;
            report.cost_after = eq.cost;
            report.residuals = eq.residuals;
            report.unconstrained_frames = (0..dim / 6)
                .filter(|v| eq.hessian.diagonal(6 * v) == 0.0)
                .count();
        }
        add_prior(&mut eq, &current, poses, &variable_of, settings);
        if let Some(motion) = &motion {
            motion.add_to(&mut eq, &current, &variable_of);
        }
        report.iterations = iteration + 1;
        if dim == 0 || data_residuals == 0 {
            break;
        }
        damping.relinearised((0..dim).map(|i| eq.hessian.diagonal(i)));
        // Raise lambda until a step lowers the cost (or give up for this linearisation):
        // (H + lambda max(diag H, floor) + floor I) dx = -b.
        let kept = damped_step(
            &mut damping,
            MAX_DAMPING_TRIES,
            &current,
            &variable_of,
            eq.cost,
            |damping| solver.solve(&eq.hessian, &eq.gradient, |h| damping.damped(h)),
            |candidate| {
                let candidate_data_cost = block_cost(block, candidate, parallelism);
                let cost = candidate_data_cost
                    + prior_cost(candidate, poses, &variable_of, settings)
                    + motion.as_ref().map_or(0.0, |m| m.cost(candidate));
                (cost, candidate_data_cost)
            },
        );
        let Some(kept) = kept else { break };
        let decrease = relative_decrease(eq.cost, kept.cost);
        current = kept.poses;
        data_cost = Some(kept.extra);
        report.cost_after = kept.cost;
        let worth_another = decrease > MIN_RELATIVE_DECREASE;
        if !worth_another {
            break;
        }
    }
    (current, report)
}

/// Distinct pairs of free frames that a residual couples (the off-diagonal 6 x 6 blocks of H),
/// in a block ordered by frame pair.
pub fn coupled_pairs(block: &FactorBlock, variable_of: &[Option<usize>]) -> usize {
    let mut pairs: Vec<(usize, usize)> = block
        .points
        .iter()
        .filter_map(|p| {
            let a = block.surfaces.get(p.surface as usize)?.frame;
            let b = p.frame as usize;
            let (va, vb) = (*variable_of.get(a)?, *variable_of.get(b)?);
            let (va, vb) = (va?, vb?);
            (va != vb).then_some((va.min(vb), va.max(vb)))
        })
        .collect();
    pairs.sort_unstable();
    pairs.dedup();
    pairs.len()
}
