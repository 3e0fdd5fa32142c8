//! A pose graph over keyframes (DESIGN section 9): relative-pose edges between poses, some of
//! them held fixed, solved by Gauss-Newton with Levenberg damping on the core's sparse
//! Cholesky ([`SparseDampedSolver`], the one the long windows use).
//!
//! An edge `(i, j)` measures `Z = T_i^-1 T_j`. Its residual, in frame i:
//! `r = [Log(R_z^T R_i^T R_j); R_i^T (t_j - t_i) - t_z]`. With the core's left perturbations
//! (`R <- Exp(a) R`, `t <- t + dt`, parameters `[a; dt]`),
//! `dr/d[a_i; dt_i] = [[-J R_j^T, 0], [R_i^T [d]x, -R_i^T]]` and
//! `dr/d[a_j; dt_j] = [[J R_j^T, 0], [0, R_i^T]]`, `d = t_j - t_i`, `J = Jr^-1(r_rot)` the
//! inverse right Jacobian of SO(3) at the rotation residual.

use crate::geometry::{Pose, log_so3, skew};
use crate::solve::block_hessian::BlockHessian;
use crate::solve::sparse_solve::SparseDampedSolver;
use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};

/// One relative-pose edge between two poses of the graph.
#[derive(Debug, Clone, PartialEq)]
pub struct Edge {
    /// Index of the first pose.
    pub from: usize,
    /// Index of the second pose.
    pub to: usize,
    /// Measured `T_from^-1 T_to`.
    pub measured: Pose,
    /// Information (inverse covariance) of the residual `[rotation (rad); translation (m)]`.
    pub information: Matrix6<f64>,
}

/// What a solve did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GraphReport {
    /// Weighted squared residual before and after.
    pub initial_cost: f64,
    pub final_cost: f64,
    /// Gauss-Newton iterations run.
    pub iterations: usize,
}

/// Residual of `edge` at `poses`.
pub(crate) fn residual(edge: &Edge, poses: &[Pose]) -> Vector6<f64> {
    let (a, b, z) = (&poses[edge.from], &poses[edge.to], &edge.measured);
    let rotation = log_so3(&(z.rotation.transpose() * a.rotation.transpose() * b.rotation));
    let translation = a.rotation.transpose() * (b.translation - a.translation) - z.translation;
    Vector6::new(
        rotation.x,
        rotation.y,
        rotation.z,
        translation.x,
        translation.y,
        translation.z,
    )
}

/// `Jr^-1(phi) = I + [phi]x / 2 + (1 / theta^2 - (1 + cos theta) / (2 theta sin theta)) [phi]x^2`.
fn inverse_right_jacobian(phi: &Vector3<f64>) -> Matrix3<f64> {
    let theta = phi.norm();
    let w = skew(phi);
    let c = if theta < 1e-4 {
        1.0 / 12.0
    } else {
        1.0 / (theta * theta) - (1.0 + theta.cos()) / (2.0 * theta * theta.sin())
    };
    Matrix3::identity() + 0.5 * w + c * w * w
}

/// Jacobians of [`residual`] with respect to the `from` and `to` parameters.
pub(crate) fn jacobians(edge: &Edge, poses: &[Pose]) -> (Matrix6<f64>, Matrix6<f64>) {
    let (a, b) = (&poses[edge.from], &poses[edge.to]);
    let (ra_t, rb_t) = (a.rotation.transpose(), b.rotation.transpose());
    let r = residual(edge, poses);
    let jr_inv = inverse_right_jacobian(&Vector3::new(r[0], r[1], r[2]));
    let d: Vector3<f64> = b.translation - a.translation;
    let mut j_from = Matrix6::zeros();
    j_from
        .fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(-jr_inv * rb_t));
    j_from
        .fixed_view_mut::<3, 3>(3, 0)
        .copy_from(&(ra_t * skew(&d)));
    j_from.fixed_view_mut::<3, 3>(3, 3).copy_from(&(-ra_t));
    let mut j_to = Matrix6::zeros();
    j_to.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(jr_inv * rb_t));
    j_to.fixed_view_mut::<3, 3>(3, 3).copy_from(&ra_t);
    (j_from, j_to)
}

fn cost(edges: &[Edge], poses: &[Pose]) -> f64 {
    edges
        .iter()
        .map(|e| {
            let r = residual(e, poses);
            (r.transpose() * e.information * r)[0]
        })
        .sum()
}

/// Adjusts the poses whose `fixed` entry is false so the edges agree; returns the report, or
/// `None` when the normal equations cannot be solved (a free pose no edge reaches).
pub fn solve(
    poses: &mut [Pose],
    fixed: &[bool],
    edges: &[Edge],
    max_iterations: usize,
) -> Option<GraphReport> {
    let mut variable_of = vec![None; poses.len()];
    let mut free = 0;
    for (k, &is_fixed) in fixed.iter().enumerate() {
        if !is_fixed {
            variable_of[k] = Some(free);
            free += 1;
        }
    }
    let initial_cost = cost(edges, poses);
    let mut report = GraphReport {
        initial_cost,
        final_cost: initial_cost,
        iterations: 0,
    };
    if free == 0 {
        return Some(report);
    }
    let pairs: Vec<(usize, usize)> = edges
        .iter()
        .filter_map(|e| Some((variable_of[e.from]?, variable_of[e.to]?)))
        .collect();
    let mut hessian = BlockHessian::with_pairs(free, pairs);
    let mut solver = SparseDampedSolver::new(&hessian)?;
    let mut lambda = 1e-6;
    for _ in 0..max_iterations {
        hessian.fill_zero();
        let mut gradient = vec![0.0; 6 * free];
        for edge in edges {
            let r = residual(edge, poses);
            let (j_from, j_to) = jacobians(edge, poses);
            let ends = [
                (variable_of[edge.from], j_from),
                (variable_of[edge.to], j_to),
            ];
            for (row, j_row) in ends.iter().filter_map(|(v, j)| Some((v.as_ref()?, j))) {
                let g = j_row.transpose() * edge.information * r;
                for (k, value) in g.iter().enumerate() {
                    gradient[6 * row + k] += value;
                }
                for (col, j_col) in ends.iter().filter_map(|(v, j)| Some((v.as_ref()?, j))) {
                    if row <= col {
                        hessian.add(*row, *col, &(j_row.transpose() * edge.information * j_col));
                    }
                }
            }
        }
        let mut accepted = false;
        while lambda < 1e6 {
            let Some(step) = solver.solve(&hessian, &gradient, |h| h * (1.0 + lambda) + 1e-12)
            else {
                lambda *= 10.0;
                continue;
            };
            let trial: Vec<Pose> = poses
                .iter()
                .zip(&variable_of)
                .map(|(pose, v)| v.map_or(*pose, |v| pose.perturbed(&step[6 * v..6 * v + 6])))
                .collect();
            let trial_cost = cost(edges, &trial);
            if trial_cost.is_finite() && trial_cost <= report.final_cost {
                let relative = (report.final_cost - trial_cost) / report.final_cost.max(1e-300);
                poses.copy_from_slice(&trial);
                report.final_cost = trial_cost;
                lambda = (lambda * 0.1).max(1e-9);
                accepted = relative > 1e-9;
                break;
            }
            lambda *= 10.0;
        }
        report.iterations += 1;
        if !accepted {
            break;
        }
    }
    Some(report)
}

/// Information of a relative pose from the geometry a frame sees: `geometry` is the
/// point-to-plane information per point (`[rotation; translation]`, see
/// `keyframes::geometry_information`), `point_sigma_m` what one window's relative pose is
/// good to along a direction every point constrains, and the odometry sigmas a floor for the
/// directions the scene leaves open (open ground: x, y and yaw).
pub fn edge_information(
    geometry: &Matrix6<f64>,
    point_sigma_m: f64,
    odometry_sigma_rad: f64,
    odometry_sigma_m: f64,
) -> Matrix6<f64> {
    let mut information = geometry / (point_sigma_m * point_sigma_m);
    for k in 0..3 {
        information[(k, k)] += 1.0 / (odometry_sigma_rad * odometry_sigma_rad);
        information[(k + 3, k + 3)] += 1.0 / (odometry_sigma_m * odometry_sigma_m);
    }
    information
}

/// `T_a^-1 T_b`.
pub fn relative(a: &Pose, b: &Pose) -> Pose {
    let ra_t: Matrix3<f64> = a.rotation.transpose();
    Pose {
        rotation: ra_t * b.rotation,
        translation: ra_t * (b.translation - a.translation),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::exp_so3;

    fn pose(theta: [f64; 3], t: [f64; 3]) -> Pose {
        Pose {
            rotation: exp_so3(&Vector3::from(theta)),
            translation: Vector3::from(t),
        }
    }

    #[test]
    fn jacobians_match_finite_differences() {
        let poses = vec![
            pose([0.1, -0.2, 0.7], [1.0, 2.0, 0.5]),
            pose([-0.05, 0.1, 0.9], [2.0, 2.5, 0.4]),
        ];
        let edge = Edge {
            from: 0,
            to: 1,
            measured: pose([0.01, 0.0, 0.18], [0.9, 0.2, -0.1]),
            information: Matrix6::identity(),
        };
        let (j_from, j_to) = jacobians(&edge, &poses);
        let h = 1e-7;
        for (which, analytic) in [(0, j_from), (1, j_to)] {
            for k in 0..6 {
                let mut delta = [0.0; 6];
                delta[k] = h;
                let mut plus = poses.clone();
                plus[which] = poses[which].perturbed(&delta);
                delta[k] = -h;
                let mut minus = poses.clone();
                minus[which] = poses[which].perturbed(&delta);
                let numeric = (residual(&edge, &plus) - residual(&edge, &minus)) / (2.0 * h);
                let error = (numeric - analytic.column(k)).norm();
                assert!(error < 1e-6, "pose {which}, parameter {k}: {error}");
            }
        }
    }

    #[test]
    fn a_loop_spreads_its_error_over_the_chain_and_the_fixed_pose_stays() {
        // Ten poses 1 m apart along x; the chain says 1 m steps, a loop edge from pose 0 says
        // pose 9 is 0.1 m further in y than the chain puts it.
        let mut poses: Vec<Pose> = (0..10)
            .map(|k| pose([0.0; 3], [k as f64, 0.0, 0.0]))
            .collect();
        let information = Matrix6::identity() * 100.0;
        let mut edges: Vec<Edge> = (0..9)
            .map(|k| Edge {
                from: k,
                to: k + 1,
                measured: relative(&poses[k], &poses[k + 1]),
                information,
            })
            .collect();
        edges.push(Edge {
            from: 0,
            to: 9,
            measured: pose([0.0; 3], [9.0, 0.1, 0.0]),
            information: information * 1e4,
        });
        let mut fixed = vec![false; 10];
        fixed[0] = true;
        let report = solve(&mut poses, &fixed, &edges, 20).expect("solvable");
        assert!(report.final_cost < 1e-3 * report.initial_cost, "{report:?}");
        assert_eq!(poses[0].translation, Vector3::zeros());
        assert!((poses[9].translation.y - 0.1).abs() < 1e-3);
        // The chain takes the correction step by step: no jump.
        for k in 1..10 {
            let dy = poses[k].translation.y - poses[k - 1].translation.y;
            assert!(dy > 0.0 && dy < 0.03, "step {k}: {dy}");
        }
    }
}
