//! Levenberg-Marquardt on a fixed set of plane voxels (BALM2 section "optimisation"): with the
//! second-order Hessian H and gradient g of the summed eigenvalue cost, solve
//! `(H + lambda D) dx = -g` (faer Cholesky, D = |diag H| with a small floor), apply
//! `R <- Exp(dtheta) R`, `t <- t + dt` to the free frames, accept if the cost drops.
//! H may be indefinite far from the optimum; a failed factorisation raises lambda.

use crate::BalmConfig;
use crate::normal_equations::{accumulate, total_cost};
use crate::result::LmIterationReport;
use crate::voxel::PlaneVoxel;
use pssba_core::geometry::Pose;
use pssba_core::lm::DampedSolver;
use pssba_core::parallel::Parallelism;

/// Damping floor relative to the largest diagonal entry: directions no voxel observes (an
/// empty frame, a slide along the only plane a frame sees) stay put instead of going singular.
const DIAGONAL_FLOOR: f64 = 1e-9;
/// Damping increases tried on one linearisation before giving up.
const MAX_DAMPING_TRIES: usize = 12;

/// Maps each frame to its first parameter index (shared with the PSS-BA solver).
pub use pssba_core::lm::variable_layout;

/// Runs LM from `poses` on `voxels`, `fixed` frames held. Returns the new poses and one report
/// per linearisation.
pub fn optimise(
    voxels: &[PlaneVoxel],
    poses: &[Pose],
    fixed: &[bool],
    config: &BalmConfig,
    parallelism: Parallelism,
) -> (Vec<Pose>, Vec<LmIterationReport>) {
    let (variable_of, dim) = variable_layout(fixed);
    let mut current = poses.to_vec();
    let mut lambda = config.lm_initial_lambda;
    let mut reports = Vec::new();
    if dim == 0 {
        return (current, reports);
    }
    let mut solver = DampedSolver::new(dim);
    for _ in 0..config.max_lm_iterations {
        let eq = accumulate(voxels, &current, &variable_of, dim, parallelism);
        let max_diag = (0..dim)
            .map(|i| eq.hessian[i * dim + i].abs())
            .fold(0.0f64, f64::max);
        let floor = DIAGONAL_FLOOR * max_diag.max(1e-300);
        let mut report = LmIterationReport {
            cost_before: eq.cost,
            cost_after: eq.cost,
            lambda,
            step_norm: 0.0,
            accepted: false,
        };
        for _ in 0..MAX_DAMPING_TRIES {
            // (H + lambda max(|diag H|, floor) + floor I) dx = -g
            let damp = |h: f64| h + lambda * h.abs().max(floor) + floor;
            let Some(step) = solver.solve(&eq.hessian, &eq.gradient, damp) else {
                lambda *= 10.0;
                continue;
            };
            let candidate: Vec<Pose> = current
                .iter()
                .enumerate()
                .map(|(k, pose)| match variable_of[k] {
                    Some(v) => pose.perturbed(&step[v..v + 6]),
                    None => *pose,
                })
                .collect();
            let cost = total_cost(voxels, &candidate, parallelism);
            if cost.is_finite() && cost < eq.cost && candidate.iter().all(Pose::is_finite) {
                current = candidate;
                report = LmIterationReport {
                    cost_after: cost,
                    lambda,
                    step_norm: step.iter().map(|v| v * v).sum::<f64>().sqrt(),
                    accepted: true,
                    ..report
                };
                lambda = (lambda / 3.0).max(1e-12);
                break;
            }
            lambda *= 10.0;
        }
        let decrease = (report.cost_before - report.cost_after) / report.cost_before.max(1e-300);
        reports.push(report);
        if !report.accepted || decrease < config.lm_min_relative_decrease {
            break;
        }
    }
    (current, reports)
}
