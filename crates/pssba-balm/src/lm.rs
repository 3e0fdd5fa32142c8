//! Levenberg-Marquardt on a fixed set of plane voxels (BALM2 section "optimisation"): with the
//! second-order Hessian H and gradient g of the summed eigenvalue cost, solve
//! `(H + lambda D) dx = -g` (faer Cholesky, D = |diag H| with a small floor), apply
//! `R <- Exp(dtheta) R`, `t <- t + dt` to the free frames, accept if the cost drops.
//! H may be indefinite far from the optimum; a failed factorisation raises lambda. The damping
//! loop is PSS-BA's ([`pssba_core::lm::damped_step`]).

use crate::BalmConfig;
use crate::normal_equations::{accumulate, total_cost};
use crate::result::LmIterationReport;
use crate::voxel::PlaneVoxel;
use pssba_core::geometry::Pose;
use pssba_core::lm::{DampedSolver, Damping, damped_step, relative_decrease};
use pssba_core::parallel::Parallelism;

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
    let mut damping = Damping::new(config.lm_initial_lambda);
    let mut reports = Vec::new();
    if dim == 0 {
        return (current, reports);
    }
    let mut solver = DampedSolver::new(dim);
    for _ in 0..config.max_lm_iterations {
        let eq = accumulate(voxels, &current, &variable_of, dim, parallelism);
        // The floor from the largest |diagonal entry| (pssba_core's DIAGONAL_FLOOR): directions
        // no voxel observes (an empty frame, a slide along the only plane a frame sees) stay
        // put instead of going singular.
        damping.relinearised((0..dim).map(|i| eq.hessian[i * dim + i].abs()));
        let mut report = LmIterationReport {
            cost_before: eq.cost,
            cost_after: eq.cost,
            lambda: damping.lambda(),
            step_norm: 0.0,
            accepted: false,
        };
        // (H + lambda max(|diag H|, floor) + floor I) dx = -g
        let kept = damped_step(
            &mut damping,
            MAX_DAMPING_TRIES,
            &current,
            &variable_of,
            eq.cost,
            |damping| solver.solve(&eq.hessian, &eq.gradient, |h| damping.damped_magnitude(h)),
            |candidate| (total_cost(voxels, candidate, parallelism), ()),
        );
        if let Some(kept) = kept {
            current = kept.poses;
            report = LmIterationReport {
                cost_after: kept.cost,
                lambda: kept.lambda,
                step_norm: kept.step.iter().map(|v| v * v).sum::<f64>().sqrt(),
                accepted: true,
                ..report
            };
        }
        let decrease = relative_decrease(report.cost_before, report.cost_after);
        reports.push(report);
        if !report.accepted || decrease < config.lm_min_relative_decrease {
            break;
        }
    }
    (current, reports)
}
