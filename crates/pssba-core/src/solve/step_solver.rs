//! The linear solver of one LM run, chosen from the size of the window and the co-visibility
//! of its frames:
//! - up to [`LARGE_WINDOW_FRAMES`] free frames, faer's dense Cholesky, always: it is fast
//!   there (100 frames: a 600 x 600 system, 2-3 ms), and short windows give exactly the
//!   results they gave before the other solvers existed;
//! - past it, when at most [`SPARSE_MAX_DENSITY`] of the frame pairs are coupled (frames
//!   that each see a few others, as along a street), faer's sparse Cholesky, if its factor
//!   stays under [`SPARSE_MAX_FACTOR`] of a dense triangle;
//! - otherwise conjugate gradients on the blocks of H ([`crate::solve::cg_solve`]).
//!
//! Measured on 1000 frames of a flight circling a hangar (`pssba simulate --scene hangar
//! --frames 1000 --seed 3`), where 23-48 % of the frame pairs are coupled depending on the
//! scale: the dense factorisation took 88 s over the 8 scales, conjugate gradients 27 s
//! (23-50 iterations per step to a relative residual of 1e-8; 3-30 since steps stop at
//! [`cg_solve::LM_RELATIVE_TOLERANCE`]), and at the sparsest scale (23 %, factor 0.45 of a dense
//! triangle) the sparse Cholesky took 8.3 s where conjugate gradients took 1.6 s. A
//! factorisation is exact in one pass whatever the conditioning, which a chain of frames
//! (a long corridor, little overlap) needs: there conjugate gradients may need as many
//! iterations as there are frames.

use crate::solve::block_hessian::BlockHessian;
use crate::solve::cg_solve;
use crate::solve::dense_solve::DampedSolver;
use crate::solve::sparse_solve::SparseDampedSolver;

/// Free frames from which the dense factorisation is no longer used.
pub const LARGE_WINDOW_FRAMES: usize = 150;
/// Largest share of coupled frame pairs for which the sparse factorisation is tried.
pub const SPARSE_MAX_DENSITY: f64 = 0.05;
/// Largest size of the sparse factor (values stored over `n (n + 1) / 2`; supernodes are
/// stored padded, so it can exceed 1) for which the sparse factorisation is used.
pub const SPARSE_MAX_FACTOR: f64 = 0.1;

/// The linear solver of one LM run.
#[derive(Debug)]
pub enum StepSolver {
    /// faer's dense Cholesky.
    Dense(DampedSolver),
    /// faer's sparse Cholesky.
    Sparse(Box<SparseDampedSolver>),
    /// Block-Jacobi preconditioned conjugate gradients.
    Iterative,
}

impl StepSolver {
    /// The solver for H's pattern.
    pub fn for_pattern(hessian: &BlockHessian) -> Self {
        let frames = hessian.frames();
        if frames < LARGE_WINDOW_FRAMES {
            return Self::Dense(DampedSolver::new(6 * frames));
        }
        let pairs = (hessian.stored_blocks() - frames) as f64;
        let density = pairs / (frames * (frames - 1) / 2) as f64;
        let sparse = (density <= SPARSE_MAX_DENSITY)
            .then(|| SparseDampedSolver::new(hessian))
            .flatten();
        let factor = sparse.as_ref().map(SparseDampedSolver::fill_ratio);
        let solver = match sparse {
            Some(sparse) if sparse.fill_ratio() <= SPARSE_MAX_FACTOR => {
                Self::Sparse(Box::new(sparse))
            }
            _ => Self::Iterative,
        };
        tracing::debug!(
            frames,
            density,
            sparse_factor = factor,
            solver = solver.name(),
            "LM linear solver"
        );
        solver
    }

    /// Solves `(H + D) dx = -gradient`, each diagonal entry `h` replaced by `damp(h)`; `None`
    /// if H + D is not positive definite or the step is not finite.
    pub fn solve(
        &mut self,
        hessian: &BlockHessian,
        gradient: &[f64],
        damp: impl Fn(f64) -> f64,
    ) -> Option<Vec<f64>> {
        match self {
            Self::Dense(dense) => dense.solve_blocks(hessian, gradient, damp),
            Self::Sparse(sparse) => sparse.solve(hessian, gradient, damp),
            Self::Iterative => {
                let (step, report) =
                    cg_solve::solve(hessian, gradient, damp, cg_solve::LM_RELATIVE_TOLERANCE)?;
                tracing::debug!(
                    iterations = report.iterations,
                    relative_residual = report.relative_residual,
                    "conjugate gradients"
                );
                Some(step)
            }
        }
    }

    /// The solver's name, for logs.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Dense(_) => "dense Cholesky",
            Self::Sparse(_) => "sparse Cholesky",
            Self::Iterative => "conjugate gradients",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with_pairs(frames: usize, pairs: impl IntoIterator<Item = (usize, usize)>) -> BlockHessian {
        BlockHessian::with_pairs(frames, pairs)
    }

    #[test]
    fn short_windows_are_dense_chains_sparse_and_revisits_iterative() {
        let chain = |n: usize| with_pairs(n, (1..n).map(|k| (k - 1, k)));
        assert_eq!(
            StepSolver::for_pattern(&chain(100)).name(),
            "dense Cholesky"
        );
        assert_eq!(
            StepSolver::for_pattern(&chain(400)).name(),
            "sparse Cholesky"
        );
        // Every frame coupled with its 40 neighbours and 40 frames half a loop away.
        let n = 400;
        let revisits = (0..n)
            .flat_map(|a| (1..=40).flat_map(move |d| [(a, (a + d) % n), (a, (a + n / 2 + d) % n)]));
        assert_eq!(
            StepSolver::for_pattern(&with_pairs(n, revisits)).name(),
            "conjugate gradients"
        );
    }
}
