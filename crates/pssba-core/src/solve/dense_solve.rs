//! Dense damped Gauss-Newton steps for the LM loops (PSS-BA and the BALM baseline): solve
//! `(H + D) dx = -b` with faer's Cholesky, where the caller says how each diagonal entry is
//! damped.

use crate::solve::block_hessian::BlockHessian;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt;
use faer::{Mat, Par};

/// Solves damped normal equations with faer's dense Cholesky, in buffers kept across the
/// iterations of one LM run.
///
/// The matrix is stored with explicit padding rows (up to faer's column stride) that are
/// zeroed before every factorisation: faer's SIMD kernels read and write those rows, and the
/// values a factorisation leaves in them made the next one on the same buffer 3 to 5 times
/// slower (measured: 9.5 ms against 2-3 ms for n = 594). A fresh matrix per solve avoids that
/// too, but pays for the allocation and its page faults.
pub struct DampedSolver {
    dim: usize,
    /// `stride x dim`; the system is its top `dim` rows.
    matrix: Mat<f64>,
    rhs: Mat<f64>,
    scratch: MemBuffer,
}

impl std::fmt::Debug for DampedSolver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DampedSolver")
            .field("dim", &self.dim)
            .finish_non_exhaustive()
    }
}

impl DampedSolver {
    /// A solver for `dim` unknowns.
    pub fn new(dim: usize) -> Self {
        // faer's column stride for `dim` rows (rounded up to its SIMD width).
        let stride = Mat::<f64>::zeros(dim, dim.min(1))
            .col_stride()
            .unsigned_abs();
        let scratch =
            llt::factor::cholesky_in_place_scratch::<f64>(dim, Par::Seq, Default::default())
                .or(llt::solve::solve_in_place_scratch::<f64>(dim, 1, Par::Seq));
        Self {
            dim,
            matrix: Mat::zeros(stride.max(dim), dim),
            rhs: Mat::zeros(dim, 1),
            scratch: MemBuffer::new(scratch),
        }
    }

    /// Solves `(H + D) dx = -gradient`, `H` row-major symmetric `dim x dim`, each diagonal
    /// entry `h` replaced by `damp(h)`. `None` if the Cholesky factorisation fails (not
    /// positive definite) or the step is not finite.
    pub fn solve(
        &mut self,
        hessian: &[f64],
        gradient: &[f64],
        damp: impl Fn(f64) -> f64,
    ) -> Option<Vec<f64>> {
        let dim = self.dim;
        let rows = self.matrix.nrows();
        // Only the lower triangle is factored and read. H is symmetric: reading it column by
        // column is reading its rows.
        for c in 0..dim {
            for r in c..dim {
                let h = hessian[c * dim + r];
                self.matrix[(r, c)] = if r == c { damp(h) } else { h };
            }
            for r in dim..rows {
                self.matrix[(r, c)] = 0.0;
            }
        }
        self.factor_and_solve(gradient)
    }

    /// [`DampedSolver::solve`] with H given as blocks.
    pub fn solve_blocks(
        &mut self,
        hessian: &BlockHessian,
        gradient: &[f64],
        damp: impl Fn(f64) -> f64,
    ) -> Option<Vec<f64>> {
        let dim = self.dim;
        debug_assert_eq!(6 * hessian.frames(), dim);
        self.matrix.fill(0.0);
        // Block (i, j), i <= j, of the upper triangle is block (j, i) of the lower one,
        // transposed; a diagonal block gives its upper triangle.
        for (i, j, block) in hessian.blocks() {
            for r in 0..6 {
                let first_c = if i == j { r } else { 0 };
                for c in first_c..6 {
                    self.matrix[(6 * j + c, 6 * i + r)] = block[(r, c)];
                }
            }
        }
        for d in 0..dim {
            self.matrix[(d, d)] = damp(self.matrix[(d, d)]);
        }
        self.factor_and_solve(gradient)
    }

    /// Factors the lower triangle of the matrix in place and solves for `-gradient`.
    fn factor_and_solve(&mut self, gradient: &[f64]) -> Option<Vec<f64>> {
        let dim = self.dim;
        for (c, g) in gradient.iter().enumerate().take(dim) {
            self.rhs[(c, 0)] = -g;
        }
        let mut system = self.matrix.as_mut().subrows_mut(0, dim);
        llt::factor::cholesky_in_place(
            system.as_mut(),
            Default::default(),
            Par::Seq,
            MemStack::new(&mut self.scratch),
            Default::default(),
        )
        .ok()?;
        llt::solve::solve_in_place(
            system.as_ref(),
            self.rhs.as_mut(),
            Par::Seq,
            MemStack::new(&mut self.scratch),
        );
        let step: Vec<f64> = (0..dim).map(|r| self.rhs[(r, 0)]).collect();
        step.iter().all(|v| v.is_finite()).then_some(step)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector};

    #[test]
    fn a_reused_solver_solves_each_system() {
        // Sizes with and without padding rows, each solver used for several systems.
        for dim in [1, 6, 13, 48, 61] {
            let mut solver = DampedSolver::new(dim);
            for round in 0..3 {
                let a =
                    DMatrix::from_fn(dim, dim, |r, c| ((r * 7 + c * 3 + round) % 11) as f64 - 5.0);
                let h = &a * a.transpose() + DMatrix::identity(dim, dim);
                let g = DVector::from_fn(dim, |r, _| (r as f64 - round as f64).sin());
                let lambda = 0.1 * round as f64;
                let damp = |h: f64| h + lambda * h;
                let step = solver
                    .solve(h.as_slice(), g.as_slice(), damp)
                    .expect("positive definite");
                let mut damped = h.clone();
                for i in 0..dim {
                    damped[(i, i)] = damp(h[(i, i)]);
                }
                let residual = damped * DVector::from_column_slice(&step) + &g;
                assert!(
                    residual.amax() < 1e-9 * (1.0 + g.amax()),
                    "dim {dim}: {residual}"
                );
            }
        }
    }

    #[test]
    fn blocks_and_a_row_major_matrix_give_the_same_step_bit_for_bit() {
        use nalgebra::Matrix6;
        let mut h = BlockHessian::with_pairs(3, [(0, 2), (1, 2)]);
        for (n, (a, b)) in [(0, 2), (1, 2), (0, 0), (1, 1), (2, 2)]
            .into_iter()
            .enumerate()
        {
            let m = Matrix6::from_fn(|r, c| ((r * 3 + c * 5 + n) % 7) as f64 * 0.2);
            let m = if a == b {
                m * m.transpose() + Matrix6::identity()
            } else {
                m
            };
            h.add(a, b, &m);
        }
        let dense = h.to_dense();
        let g: Vec<f64> = (0..18).map(|i| (i as f64).cos()).collect();
        let damp = |d: f64| 2.0 * d + 0.5;
        let mut solver = DampedSolver::new(18);
        let from_blocks = solver
            .solve_blocks(&h, &g, damp)
            .expect("positive definite");
        let from_dense = solver.solve(&dense, &g, damp).expect("positive definite");
        assert_eq!(from_blocks, from_dense);
    }

    #[test]
    fn an_indefinite_system_has_no_step() {
        let mut solver = DampedSolver::new(2);
        let h = [1.0, 0.0, 0.0, -1.0];
        assert!(solver.solve(&h, &[1.0, 1.0], |h| h).is_none());
    }
}
