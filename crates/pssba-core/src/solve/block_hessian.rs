//! The Gauss-Newton matrix H of a factor block kept as 6 x 6 blocks, one per pair of free
//! frames that a residual couples (the frames' co-visibility) plus every diagonal block.
//!
//! A window of N free frames has a 6N x 6N matrix H, but a residual only couples the frame
//! of its surface with the frame of its point: over a long window most pairs of frames never
//! see the same kernel, and a dense H is mostly zeros (1000 frames: 288 MB of them). The
//! pattern is fixed for one block, so it is built once per LM run and filled at each
//! linearisation.

use crate::factor::FactorBlock;
use nalgebra::Matrix6;

/// The upper block triangle of a symmetric 6N x 6N matrix: blocks `(row, col)`, `row <= col`,
/// in block-column order (by `col`, then `row`). Diagonal blocks are stored whole; only their
/// upper triangles are read.
#[derive(Debug, Clone, PartialEq)]
pub struct BlockHessian {
    /// Free frames (block rows and columns).
    frames: usize,
    /// `(col, row)` of each stored block, sorted: a binary search finds a block.
    keys: Vec<(u32, u32)>,
    /// Column `c`'s blocks are `keys[column_start[c]..column_start[c + 1]]`, its diagonal
    /// block last. A search within one column (at most `frames` rows, contiguous) instead of
    /// over all keys: at 1000 frames the keys are 4 MB, and the full binary search's cache
    /// misses were 8 % of the run (`perf`), on the serial part of the accumulation.
    column_start: Vec<usize>,
    /// The blocks, in the order of `keys`.
    blocks: Vec<Matrix6<f64>>,
}

impl BlockHessian {
    /// All-zero blocks at the diagonal and at the given pairs of free-frame indices (either
    /// order, repeats allowed).
    pub fn with_pairs(frames: usize, pairs: impl IntoIterator<Item = (usize, usize)>) -> Self {
        let mut keys: Vec<(u32, u32)> = (0..frames as u32).map(|k| (k, k)).collect();
        // Repeats of the previous pair are skipped before the sort: a block ordered by frame
        // pair (as LM orders it) lists each pair once instead of once per residual.
        let mut previous = None;
        keys.extend(
            pairs
                .into_iter()
                .filter(|&(a, b)| a < frames && b < frames)
                .map(|(a, b)| (a.max(b) as u32, a.min(b) as u32))
                .filter(|&key| previous.replace(key) != Some(key)),
        );
        keys.sort_unstable();
        keys.dedup();
        let mut column_start = vec![0; frames + 1];
        for &(col, _) in &keys {
            column_start[col as usize + 1] += 1;
        }
        for c in 0..frames {
            column_start[c + 1] += column_start[c];
        }
        let blocks = vec![Matrix6::zeros(); keys.len()];
        Self {
            frames,
            keys,
            column_start,
            blocks,
        }
    }

    /// The pattern of `block`'s residuals: the pairs (surface frame, point frame) with both
    /// frames free. `variable_of[frame]` is the frame's first parameter index (6 per frame).
    pub fn for_block(block: &FactorBlock, variable_of: &[Option<usize>], dim: usize) -> Self {
        Self::for_block_and_pairs(block, variable_of, dim, &[])
    }

    /// [`Self::for_block`] plus the blocks of `extra` pairs of free-frame indices (the motion
    /// prior's consecutive frames).
    pub fn for_block_and_pairs(
        block: &FactorBlock,
        variable_of: &[Option<usize>],
        dim: usize,
        extra: &[(usize, usize)],
    ) -> Self {
        let free = |frame: usize| variable_of.get(frame).copied().flatten().map(|v| v / 6);
        let pairs = block.points.iter().filter_map(|p| {
            let a = free(block.surfaces.get(p.surface as usize)?.frame)?;
            let b = free(p.frame as usize)?;
            (a != b).then_some((a, b))
        });
        Self::with_pairs(dim / 6, pairs.chain(extra.iter().copied()))
    }

    /// Free frames.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Stored blocks, the diagonal included.
    pub fn stored_blocks(&self) -> usize {
        self.keys.len()
    }

    /// Sets every block to zero (the pattern stays).
    pub fn fill_zero(&mut self) {
        self.blocks.iter_mut().for_each(|b| *b = Matrix6::zeros());
    }

    /// Position of block `(row, col)`, `row <= col`, in `keys` and `blocks`.
    fn slot(&self, row: usize, col: usize) -> Option<usize> {
        slot_in(&self.keys, &self.column_start, row, col)
    }

    /// Adds `m` at block `(row, col)` (the transposed block when `row > col`). A block outside
    /// the pattern is a bug in the caller: it panics in debug builds and is dropped otherwise.
    pub fn add(&mut self, row: usize, col: usize, m: &Matrix6<f64>) {
        let (keys, column_start) = (&self.keys, &self.column_start);
        add_in(keys, column_start, &mut self.blocks, 0, row, col, m);
    }

    /// The blocks cut into the column ranges `bounds[k]..bounds[k + 1]` (`bounds` ascending
    /// from 0 to [`Self::frames`]), each a view that adds into its own columns only, so the
    /// ranges can be filled in parallel.
    ///
    /// # Panics
    /// If `bounds` does not run from 0 to the frame count in ascending order.
    pub fn columns_mut(&mut self, bounds: &[usize]) -> Vec<ColumnsMut<'_>> {
        assert!(
            bounds.first() == Some(&0)
                && bounds.last() == Some(&self.frames)
                && bounds.windows(2).all(|w| w[0] <= w[1]),
            "column bounds from 0 to {}",
            self.frames
        );
        let (keys, column_start) = (&self.keys, &self.column_start);
        let mut rest: &mut [Matrix6<f64>] = &mut self.blocks;
        let mut views = Vec::with_capacity(bounds.len().saturating_sub(1));
        for range in bounds.windows(2) {
            let (first, end) = (column_start[range[0]], column_start[range[1]]);
            let (blocks, tail) = rest.split_at_mut(end - first);
            rest = tail;
            views.push(ColumnsMut {
                columns: range[0]..range[1],
                first_slot: first,
                keys,
                column_start,
                blocks,
            });
        }
        views
    }

    /// Stored blocks of columns `0..col` (where column `col`'s blocks begin).
    pub fn blocks_before_column(&self, col: usize) -> usize {
        self.column_start[col.min(self.frames)]
    }

    /// Adds `value` to the diagonal entry `i` of the block diagonal `frame`.
    pub fn add_diagonal(&mut self, frame: usize, i: usize, value: f64) {
        if let Some(slot) = self.slot(frame, frame) {
            self.blocks[slot][(i, i)] += value;
        }
    }

    /// Entry `index` of the diagonal of H (`index < 6 * frames`).
    pub fn diagonal(&self, index: usize) -> f64 {
        let frame = index / 6;
        self.slot(frame, frame)
            .map_or(0.0, |slot| self.blocks[slot][(index % 6, index % 6)])
    }

    /// Every stored block as `(row, col, block)`, `row <= col`, in block-column order.
    pub fn blocks(&self) -> impl Iterator<Item = (usize, usize, &Matrix6<f64>)> {
        self.keys
            .iter()
            .zip(&self.blocks)
            .map(|(&(col, row), b)| (row as usize, col as usize, b))
    }

    /// Entry `(r, c)` of the symmetric matrix, read from the upper triangle.
    pub fn entry(&self, r: usize, c: usize) -> f64 {
        let (r, c) = (r.min(c), r.max(c));
        self.slot(r / 6, c / 6)
            .map_or(0.0, |slot| self.blocks[slot][(r % 6, c % 6)])
    }

    /// The full symmetric matrix, row-major `6N x 6N` (for tests and small systems).
    pub fn to_dense(&self) -> Vec<f64> {
        let dim = 6 * self.frames;
        let mut dense = vec![0.0; dim * dim];
        for r in 0..dim {
            for c in 0..dim {
                dense[r * dim + c] = self.entry(r, c);
            }
        }
        dense
    }
}

/// The blocks of a column range of a [`BlockHessian`] (see [`BlockHessian::columns_mut`]).
#[derive(Debug)]
pub struct ColumnsMut<'a> {
    columns: std::ops::Range<usize>,
    /// Slot of the range's first block in the whole matrix.
    first_slot: usize,
    keys: &'a [(u32, u32)],
    column_start: &'a [usize],
    blocks: &'a mut [Matrix6<f64>],
}

impl ColumnsMut<'_> {
    /// The columns (block columns, free frames) this view holds.
    pub fn columns(&self) -> std::ops::Range<usize> {
        self.columns.clone()
    }

    /// True when block `(row, col)` (either order) lies in this view's columns.
    #[inline]
    pub fn holds(&self, row: usize, col: usize) -> bool {
        self.columns.contains(&row.max(col))
    }

    /// [`BlockHessian::add`] for a block this view [`holds`](Self::holds); one it does not
    /// hold panics in debug builds and is dropped otherwise (its slot lies outside
    /// `blocks`).
    pub fn add(&mut self, row: usize, col: usize, m: &Matrix6<f64>) {
        debug_assert!(
            self.holds(row, col),
            "block ({row}, {col}) is not in this view"
        );
        let (keys, column_start) = (self.keys, self.column_start);
        add_in(
            keys,
            column_start,
            self.blocks,
            self.first_slot,
            row,
            col,
            m,
        );
    }
}

/// Position of block `(row, col)`, `row <= col`, in `keys` (see [`BlockHessian`]).
fn slot_in(keys: &[(u32, u32)], column_start: &[usize], row: usize, col: usize) -> Option<usize> {
    if row > col || col + 1 >= column_start.len() {
        return None;
    }
    let (start, end) = (column_start[col], column_start[col + 1]);
    if row == col {
        // Every column holds its diagonal block, the largest row.
        return Some(end - 1);
    }
    let rows = &keys[start..end];
    rows.binary_search_by(|&(_, r)| r.cmp(&(row as u32)))
        .ok()
        .map(|i| start + i)
}

/// Adds `m` at block `(row, col)` (transposed when `row > col`) of `blocks`, which hold the
/// matrix's blocks from slot `first_slot` on.
fn add_in(
    keys: &[(u32, u32)],
    column_start: &[usize],
    blocks: &mut [Matrix6<f64>],
    first_slot: usize,
    row: usize,
    col: usize,
    m: &Matrix6<f64>,
) {
    let (slot, transposed) = if row <= col {
        (slot_in(keys, column_start, row, col), false)
    } else {
        (slot_in(keys, column_start, col, row), true)
    };
    debug_assert!(slot.is_some(), "block ({row}, {col}) is not in the pattern");
    let Some(block) = slot.and_then(|slot| blocks.get_mut(slot.checked_sub(first_slot)?)) else {
        return;
    };
    if transposed {
        *block += m.transpose();
    } else {
        *block += m;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_added_in_either_order_land_in_the_upper_triangle() {
        let mut h = BlockHessian::with_pairs(3, [(2, 0), (0, 2), (1, 1), (5, 0)]);
        // The diagonal and (0, 2); the repeat, the self pair and the out-of-range pair add
        // nothing.
        assert_eq!(h.stored_blocks(), 4);
        let m = Matrix6::from_fn(|r, c| (r * 6 + c) as f64);
        h.add(0, 2, &m);
        h.add(2, 0, &m.transpose());
        h.add(1, 1, &Matrix6::identity());
        h.add_diagonal(1, 3, 2.0);
        let dense = h.to_dense();
        let dim = 18;
        for r in 0..6 {
            for c in 0..6 {
                assert_eq!(dense[r * dim + 12 + c], 2.0 * m[(r, c)]);
                assert_eq!(dense[(12 + c) * dim + r], 2.0 * m[(r, c)]);
            }
        }
        assert_eq!(h.diagonal(9), 3.0);
        assert_eq!(h.diagonal(6), 1.0);
        assert_eq!(h.entry(0, 6), 0.0);
        h.fill_zero();
        assert!(h.to_dense().iter().all(|v| *v == 0.0));
        assert_eq!(h.stored_blocks(), 4);
    }

    #[test]
    fn column_views_add_exactly_what_the_whole_matrix_adds() {
        let frames = 30;
        let pairs: Vec<(usize, usize)> = (0..200)
            .map(|i| ((i * 7 + 3) % frames, (i * 11 + i / 3) % frames))
            .collect();
        let whole = BlockHessian::with_pairs(frames, pairs.iter().copied());
        // Adds in a fixed order, of values whose sums depend on the order of addition.
        let adds: Vec<(usize, usize, Matrix6<f64>)> = (0..3000)
            .map(|k| {
                let (a, b) = pairs[k % pairs.len()];
                let (row, col) = if k % 3 == 0 { (a, a) } else { (a, b) };
                let scale = 1.0 + (k as f64 * 0.37).sin() * 1e-9;
                (
                    row,
                    col,
                    Matrix6::from_fn(|r, c| scale * (r + 7 * c + k) as f64 / 3.0),
                )
            })
            .collect();
        let mut expected = whole.clone();
        for (row, col, m) in &adds {
            expected.add(*row, *col, m);
        }
        for bounds in [
            vec![0, frames],
            vec![0, 7, 7, 19, frames],
            vec![0, 1, 2, 29, frames],
        ] {
            let mut split = whole.clone();
            for mut view in split.columns_mut(&bounds) {
                for (row, col, m) in &adds {
                    if view.holds(*row, *col) {
                        view.add(*row, *col, m);
                    }
                }
            }
            assert_eq!(split, expected, "bounds {bounds:?}");
        }
    }

    #[test]
    fn the_column_search_finds_exactly_the_stored_blocks() {
        let frames = 40;
        let pairs: Vec<(usize, usize)> = (0..300)
            .map(|i| ((i * 7 + 3) % frames, (i * 13 + i / 5) % frames))
            .collect();
        let h = BlockHessian::with_pairs(frames, pairs.iter().copied());
        for row in 0..=frames {
            for col in 0..=frames {
                let expected = h.keys.binary_search(&(col as u32, row as u32)).ok();
                assert_eq!(h.slot(row, col), expected, "block ({row}, {col})");
            }
        }
    }
}
