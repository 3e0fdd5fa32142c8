//! Sparse damped Gauss-Newton steps: `(H + D) dx = -b` with faer's sparse (supernodal)
//! Cholesky, for long windows whose frames mostly do not see each other.
//!
//! The pattern of H is one LM run's [`BlockHessian`]: it is ordered and analysed once (an
//! approximate minimum degree ordering of the frames, each frame's 6 parameters kept
//! together), and each step only refills the values and factors them again.

use crate::solve::block_hessian::BlockHessian;
use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::perm::PermRef;
use faer::sparse::linalg::amd;
use faer::sparse::linalg::cholesky::{
    LltRef, SymbolicCholesky, SymmetricOrdering, factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, Mat, Par, Side};

/// Solves damped normal equations with a sparse Cholesky factorisation whose symbolic
/// analysis is shared by every step of one LM run.
pub struct SparseDampedSolver {
    dim: usize,
    /// Upper triangle of H in compressed columns: column pointers and row indices.
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    /// Values in the order of `row_idx`, refilled at each solve.
    values: Vec<f64>,
    symbolic: SymbolicCholesky<usize>,
    /// The factor's values.
    factor: Vec<f64>,
    rhs: Mat<f64>,
    scratch: MemBuffer,
}

impl std::fmt::Debug for SparseDampedSolver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SparseDampedSolver")
            .field("dim", &self.dim)
            .field("stored", &self.values.len())
            .field("factor", &self.factor.len())
            .finish_non_exhaustive()
    }
}

/// Row indices of the upper triangle of column `6 j + k` for the blocks `(i, j)` of one
/// block column (rows ascending, the diagonal block last).
fn column_rows(rows_of_blocks: &[usize], j: usize, k: usize, out: &mut Vec<usize>) {
    for &i in rows_of_blocks {
        let last = if i == j { k } else { 5 };
        out.extend((0..=last).map(|r| 6 * i + r));
    }
}

impl SparseDampedSolver {
    /// Analyses the pattern of `hessian`. `None` if faer cannot (out of memory).
    pub fn new(hessian: &BlockHessian) -> Option<Self> {
        let frames = hessian.frames();
        let dim = 6 * frames;
        // Block rows of each block column.
        let mut rows_of: Vec<Vec<usize>> = vec![Vec::new(); frames];
        for (i, j, _) in hessian.blocks() {
            rows_of[j].push(i);
        }
        let perm_fwd = frame_ordering(&rows_of)?;
        let mut perm_inv = vec![0usize; dim];
        for (new, &old) in perm_fwd.iter().enumerate() {
            perm_inv[old] = new;
        }
        let mut col_ptr = Vec::with_capacity(dim + 1);
        let mut row_idx = Vec::new();
        col_ptr.push(0);
        for (j, rows) in rows_of.iter().enumerate() {
            for k in 0..6 {
                column_rows(rows, j, k, &mut row_idx);
                col_ptr.push(row_idx.len());
            }
        }
        let pattern = SymbolicSparseColMatRef::new_checked(dim, dim, &col_ptr, None, &row_idx);
        let perm = PermRef::new_checked(&perm_fwd, &perm_inv, dim);
        let symbolic = factorize_symbolic_cholesky(
            pattern,
            Side::Upper,
            SymmetricOrdering::Custom(perm),
            Default::default(),
        )
        .ok()?;
        let scratch = StackReq::any_of(&[
            symbolic.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()),
            symbolic.solve_in_place_scratch::<f64>(1, Par::Seq),
        ]);
        let factor = vec![0.0; symbolic.len_val()];
        Some(Self {
            dim,
            values: vec![0.0; row_idx.len()],
            col_ptr,
            row_idx,
            symbolic,
            factor,
            rhs: Mat::zeros(dim, 1),
            scratch: MemBuffer::try_new(scratch).ok()?,
        })
    }

    /// Values stored for the factor L over a dense lower triangle (`dim (dim + 1) / 2`); the
    /// supernodes are stored padded, so it can exceed 1.
    pub fn fill_ratio(&self) -> f64 {
        let dense = self.dim as f64 * (self.dim as f64 + 1.0) / 2.0;
        self.factor.len() as f64 / dense.max(1.0)
    }

    /// Solves `(H + D) dx = -gradient`, each diagonal entry `h` of H replaced by `damp(h)`.
    /// `hessian` must have the pattern this solver was made for. `None` if H + D is not
    /// positive definite or the step is not finite.
    pub fn solve(
        &mut self,
        hessian: &BlockHessian,
        gradient: &[f64],
        damp: impl Fn(f64) -> f64,
    ) -> Option<Vec<f64>> {
        let dim = self.dim;
        if 6 * hessian.frames() != dim {
            return None;
        }
        // The values column by column, in the order of `row_idx` (see `new`): the blocks
        // come in block-column order, rows ascending, so each block column is a run.
        let blocks: Vec<_> = hessian.blocks().collect();
        self.values.clear();
        let mut start = 0;
        while start < blocks.len() {
            let j = blocks[start].1;
            let end = start + blocks[start..].iter().take_while(|b| b.1 == j).count();
            for k in 0..6 {
                for &(i, _, block) in &blocks[start..end] {
                    let last = if i == j { k } else { 5 };
                    self.values.extend((0..=last).map(|r| block[(r, k)]));
                }
                // The diagonal entry closes the column.
                if let Some(d) = self.values.last_mut() {
                    *d = damp(*d);
                }
            }
            start = end;
        }
        if self.values.len() != self.row_idx.len() {
            return None;
        }
        let pattern =
            SymbolicSparseColMatRef::new_checked(dim, dim, &self.col_ptr, None, &self.row_idx);
        let matrix = SparseColMatRef::new(pattern, &self.values);
        self.symbolic
            .factorize_numeric_llt::<f64>(
                &mut self.factor,
                matrix,
                Side::Upper,
                LltRegularization::default(),
                Par::Seq,
                MemStack::new(&mut self.scratch),
                Default::default(),
            )
            .ok()?;
        for (c, g) in gradient.iter().enumerate().take(dim) {
            self.rhs[(c, 0)] = -g;
        }
        LltRef::new(&self.symbolic, &self.factor).solve_in_place_with_conj(
            Conj::No,
            self.rhs.as_mut(),
            Par::Seq,
            MemStack::new(&mut self.scratch),
        );
        let step: Vec<f64> = (0..dim).map(|r| self.rhs[(r, 0)]).collect();
        step.iter().all(|v| v.is_finite()).then_some(step)
    }
}

/// A fill-reducing order of the parameters: an approximate minimum degree order of the
/// frames' co-visibility graph (`rows_of[j]`: the frames `i <= j` coupled with frame `j`),
/// each frame's 6 parameters kept in a row. Ordering the frames rather than the 6N scalars
/// is 36 times less work and keeps the supernodes whole.
fn frame_ordering(rows_of: &[Vec<usize>]) -> Option<Vec<usize>> {
    let frames = rows_of.len();
    let mut col_ptr = Vec::with_capacity(frames + 1);
    let mut row_idx = Vec::new();
    col_ptr.push(0);
    for rows in rows_of {
        row_idx.extend_from_slice(rows);
        col_ptr.push(row_idx.len());
    }
    let graph = SymbolicSparseColMatRef::new_checked(frames, frames, &col_ptr, None, &row_idx);
    let mut order = vec![0usize; frames];
    let mut order_inv = vec![0usize; frames];
    let mut scratch =
        MemBuffer::try_new(amd::order_scratch::<usize>(frames, row_idx.len())).ok()?;
    amd::order(
        &mut order,
        &mut order_inv,
        graph,
        amd::Control::default(),
        MemStack::new(&mut scratch),
    )
    .ok()?;
    Some(
        order
            .iter()
            .flat_map(|&frame| (0..6).map(move |k| 6 * frame + k))
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solve::dense_solve::DampedSolver;
    use nalgebra::Matrix6;

    /// A chain of frames plus a few long-range pairs, positive definite once damped.
    fn chain(frames: usize) -> BlockHessian {
        let pairs: Vec<(usize, usize)> = (1..frames)
            .map(|k| (k - 1, k))
            .chain([(0, frames - 1), (2, frames / 2)])
            .collect();
        let mut h = BlockHessian::with_pairs(frames, pairs.iter().copied());
        for (n, &(a, b)) in pairs.iter().enumerate() {
            let m = Matrix6::from_fn(|r, c| (((r * 5 + c * 3 + n) % 7) as f64 - 3.0) * 0.1);
            h.add(a, b, &m);
            h.add(a, a, &(m * m.transpose()));
            h.add(b, b, &(m.transpose() * m));
        }
        for f in 0..frames {
            (0..6).for_each(|i| h.add_diagonal(f, i, 1.0));
        }
        h
    }

    #[test]
    fn sparse_and_dense_steps_agree() {
        for frames in [2, 3, 9, 40] {
            let h = chain(frames);
            let dim = 6 * frames;
            let gradient: Vec<f64> = (0..dim).map(|i| (i as f64 * 0.37).sin()).collect();
            let damp = |d: f64| 1.5 * d + 1e-6;
            let mut sparse = SparseDampedSolver::new(&h).expect("analysed");
            assert!(sparse.fill_ratio() > 0.0 && sparse.fill_ratio() <= 1.0);
            let mut dense = DampedSolver::new(dim);
            // Twice, as an LM run does: the analysis is reused.
            for _ in 0..2 {
                let a = sparse
                    .solve(&h, &gradient, damp)
                    .expect("positive definite");
                let b = dense
                    .solve_blocks(&h, &gradient, damp)
                    .expect("positive definite");
                let scale = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                for (x, y) in a.iter().zip(&b) {
                    assert!((x - y).abs() <= 1e-9 * scale, "{frames} frames: {x} vs {y}");
                }
            }
        }
    }

    #[test]
    fn a_chain_factor_stays_sparse_and_an_indefinite_system_has_no_step() {
        let h = chain(200);
        let sparse = SparseDampedSolver::new(&h).expect("analysed");
        assert!(sparse.fill_ratio() < 0.1, "{}", sparse.fill_ratio());
        let mut h = BlockHessian::with_pairs(2, [(0, 1)]);
        h.add(0, 0, &Matrix6::identity());
        h.add(1, 1, &(-Matrix6::identity()));
        let mut sparse = SparseDampedSolver::new(&h).expect("analysed");
        assert!(sparse.solve(&h, &[1.0; 12], |d| d).is_none());
    }
}
