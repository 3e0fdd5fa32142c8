//! Damped Gauss-Newton steps by preconditioned conjugate gradients, for long windows whose
//! frames see so many others that a Cholesky factor is dense (a 1000-frame flight circling
//! one hangar couples 23-48 % of all frame pairs; a dense factorisation of the 6000 x 6000
//! system costs 2-3 s, and LM needs one per iteration; 23-50 iterations solve it here).
//!
//! CG only multiplies by H: one pass over the stored 6 x 6 blocks per iteration. The
//! preconditioner is block Jacobi (each frame's damped 6 x 6 diagonal block, inverted), which
//! removes the scale difference between rotations and translations and between frames with
//! many and few residuals. LM's steps stop at a relative residual of [`LM_RELATIVE_TOLERANCE`]
//! (or after [`MAX_ITERATIONS`]): any truncated CG iterate is still a descent direction of the
//! local quadratic model, and LM accepts a step only if the cost drops (inexact
//! Levenberg-Marquardt, as in Ceres' iterative solvers, whose default forcing term is 0.1).
//!
//! Every sum runs in a fixed order on one thread, so the result does not depend on the
//! thread count.

use crate::solve::block_hessian::BlockHessian;
use nalgebra::{Cholesky, Matrix6, Vector6};

/// LM's steps stop when `|r| <= LM_RELATIVE_TOLERANCE |b|`. Measured on the 1000-frame
/// hangar flight (`pssba simulate --scene hangar --frames 1000`, seeds 3, 1, 2): at 1e-8 a
/// step took 27-42 iterations; at 1e-2 the LM phase ran about 12 % faster and the APE
/// ended at 4.40 / 4.43 / 4.23 mm instead of 4.56 / 4.45 / 4.40 mm (1e-4: 4.52 / 4.37 / 4.27):
/// within the spread a 1e-9 perturbation of the weights gives (BENCHMARK.md).
pub const LM_RELATIVE_TOLERANCE: f64 = 1e-2;
/// Iterations at most per solve.
pub const MAX_ITERATIONS: usize = 600;

/// What one solve did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CgReport {
    /// Iterations run.
    pub iterations: usize,
    /// `|r| / |b|` at the end.
    pub relative_residual: f64,
}

/// Solves `(H + D) dx = -gradient` with each diagonal entry `h` of H replaced by `damp(h)`,
/// until `|r| <= relative_tolerance |b|`. `None` if a damped diagonal block or the system is
/// not positive definite, or the step is not finite.
pub fn solve(
    hessian: &BlockHessian,
    gradient: &[f64],
    damp: impl Fn(f64) -> f64,
    relative_tolerance: f64,
) -> Option<(Vec<f64>, CgReport)> {
    let frames = hessian.frames();
    if gradient.len() != 6 * frames {
        return None;
    }
    // The damped diagonal blocks, whole and symmetric, and their inverses.
    let mut diagonal = vec![Matrix6::<f64>::zeros(); frames];
    let mut off_diagonal = Vec::new();
    for (i, j, block) in hessian.blocks() {
        if i == j {
            diagonal[i] = Matrix6::from_fn(|r, c| {
                let (r, c) = (r.min(c), r.max(c));
                if r == c {
                    damp(block[(r, c)])
                } else {
                    block[(r, c)]
                }
            });
        } else {
            off_diagonal.push((i, j, block));
        }
    }
    let inverses: Vec<Cholesky<f64, nalgebra::U6>> = diagonal
        .iter()
        .map(|d| Cholesky::new(*d))
        .collect::<Option<_>>()?;
    let multiply = |x: &[Vector6<f64>], y: &mut [Vector6<f64>]| {
        for (k, yk) in y.iter_mut().enumerate() {
            *yk = diagonal[k] * x[k];
        }
        for &(i, j, block) in &off_diagonal {
            y[i] += block * x[j];
            y[j] += block.tr_mul(&x[i]);
        }
    };
    let precondition = |r: &[Vector6<f64>]| -> Vec<Vector6<f64>> {
        r.iter().zip(&inverses).map(|(r, c)| c.solve(r)).collect()
    };
    let dot = |a: &[Vector6<f64>], b: &[Vector6<f64>]| -> f64 {
        a.iter().zip(b).map(|(a, b)| a.dot(b)).sum()
    };

    let b: Vec<Vector6<f64>> = (0..frames)
        .map(|k| -Vector6::from_column_slice(&gradient[6 * k..6 * k + 6]))
        .collect();
    let b_norm = dot(&b, &b).sqrt();
    let mut x = vec![Vector6::zeros(); frames];
    let mut report = CgReport {
        iterations: 0,
        relative_residual: 0.0,
    };
    if b_norm == 0.0 {
        return Some((vec![0.0; 6 * frames], report));
    }
    let mut r = b;
    let mut z = precondition(&r);
    let mut p = z.clone();
    let mut rz = dot(&r, &z);
    let mut ap = vec![Vector6::zeros(); frames];
    report.relative_residual = 1.0;
    while report.iterations < MAX_ITERATIONS && report.relative_residual > relative_tolerance {
        multiply(&p, &mut ap);
        let curvature = dot(&p, &ap);
        if !curvature.is_finite() || curvature <= 0.0 {
            // Not positive definite along p (or not finite).
            return None;
        }
        let alpha = rz / curvature;
        for k in 0..frames {
            x[k] += alpha * p[k];
            r[k] -= alpha * ap[k];
        }
        report.iterations += 1;
        report.relative_residual = dot(&r, &r).sqrt() / b_norm;
        z = precondition(&r);
        let rz_next = dot(&r, &z);
        let beta = rz_next / rz;
        rz = rz_next;
        for k in 0..frames {
            p[k] = z[k] + beta * p[k];
        }
    }
    let step: Vec<f64> = x.iter().flat_map(|v| v.iter().copied()).collect();
    step.iter().all(|v| v.is_finite()).then_some((step, report))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solve::dense_solve::DampedSolver;

    #[test]
    fn cg_steps_equal_the_cholesky_steps() {
        let frames = 30;
        let pairs: Vec<(usize, usize)> = (1..frames)
            .map(|k| (k - 1, k))
            .chain([(0, 29), (3, 17), (5, 6)])
            .collect();
        let mut h = BlockHessian::with_pairs(frames, pairs.iter().copied());
        // Each pair adds J^T J for J = [M, -N]: positive semi-definite, as in LM.
        for (n, &(a, b)) in pairs.iter().enumerate() {
            let m = Matrix6::from_fn(|r, c| (((r * 5 + c * 3 + n) % 7) as f64 - 3.0) * 0.1);
            let q = Matrix6::from_fn(|r, c| (((r * 2 + c * 7 + n) % 5) as f64 - 2.0) * 0.1);
            h.add(a, b, &(-m.transpose() * q));
            h.add(a, a, &(m.transpose() * m));
            h.add(b, b, &(q.transpose() * q));
        }
        for f in 0..frames {
            (0..6).for_each(|i| h.add_diagonal(f, i, 0.01 * (1 + i) as f64));
        }
        let gradient: Vec<f64> = (0..6 * frames).map(|i| (i as f64 * 0.7).sin()).collect();
        let damp = |d: f64| 1.2 * d;
        let (cg, report) = solve(&h, &gradient, damp, 1e-8).expect("positive definite");
        assert!(report.relative_residual <= 1e-8, "{report:?}");
        let exact = DampedSolver::new(6 * frames)
            .solve_blocks(&h, &gradient, damp)
            .expect("positive definite");
        let scale = exact.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for (a, b) in cg.iter().zip(&exact) {
            assert!((a - b).abs() <= 1e-6 * scale, "{a} vs {b}");
        }
    }

    #[test]
    fn an_indefinite_system_has_no_step() {
        let mut h = BlockHessian::with_pairs(2, [(0, 1)]);
        h.add(0, 0, &Matrix6::identity());
        h.add(1, 1, &Matrix6::identity());
        h.add(0, 1, &(Matrix6::identity() * 2.0));
        let gradient = [[1.0; 6], [-1.0; 6]].concat();
        assert!(solve(&h, &gradient, |d| d, 1e-8).is_none());
        let mut h = BlockHessian::with_pairs(1, []);
        h.add(0, 0, &(-Matrix6::identity()));
        assert!(solve(&h, &[1.0; 6], |d| d, 1e-8).is_none());
    }
}
