//! Dense normal equations over the free poses, summed over plane voxels: `H` (6F x 6F blocks
//! of [`VoxelDerivatives::block`]), gradient and cost. Voxels are split into a fixed number
//! of parts summed in order, so serial and rayon runs give bit-identical results.

use crate::derivatives::{voxel_cost, voxel_derivatives};
use crate::voxel::PlaneVoxel;
use pssba_core::geometry::Pose;
use pssba_core::parallel::{Parallelism, map_indexed};

/// Voxel sums are split into this many parts, whatever the thread count.
const PARTS: usize = 8;

/// `H`, gradient and cost at one linearisation point.
#[derive(Debug, Clone, PartialEq)]
pub struct NormalEquations {
    /// Number of unknowns (6 per free frame).
    pub dim: usize,
    /// Row-major `dim x dim` Hessian.
    pub hessian: Vec<f64>,
    /// Gradient of the cost.
    pub gradient: Vec<f64>,
    /// Total cost (m^2).
    pub cost: f64,
}

impl NormalEquations {
    fn zeros(dim: usize) -> Self {
        Self {
            dim,
            hessian: vec![0.0; dim * dim],
            gradient: vec![0.0; dim],
            cost: 0.0,
        }
    }

    fn add(mut self, other: &Self) -> Self {
        self.hessian
            .iter_mut()
            .zip(&other.hessian)
            .for_each(|(a, b)| *a += b);
        self.gradient
            .iter_mut()
            .zip(&other.gradient)
            .for_each(|(a, b)| *a += b);
        self.cost += other.cost;
        self
    }
}

/// The voxel index range of part `k`.
fn part_range(voxels: usize, k: usize) -> std::ops::Range<usize> {
    let size = voxels.div_ceil(PARTS).max(1);
    (k * size).min(voxels)..((k + 1) * size).min(voxels)
}

/// Sum over voxels of `lambda_min(S)` at `poses` (m^2).
pub fn total_cost(voxels: &[PlaneVoxel], poses: &[Pose], parallelism: Parallelism) -> f64 {
    map_indexed(PARTS, parallelism, |k| {
        voxels[part_range(voxels.len(), k)]
            .iter()
            .map(|v| voxel_cost(&v.clusters, poses))
            .sum::<f64>()
    })
    .into_iter()
    .sum()
}

/// Accumulates the normal equations at `poses`; `variable_of[frame]` is the first parameter
/// index of a free frame, `None` for a fixed one.
pub fn accumulate(
    voxels: &[PlaneVoxel],
    poses: &[Pose],
    variable_of: &[Option<usize>],
    dim: usize,
    parallelism: Parallelism,
) -> NormalEquations {
    let parts = map_indexed(PARTS, parallelism, |k| {
        let mut eq = NormalEquations::zeros(dim);
        for voxel in &voxels[part_range(voxels.len(), k)] {
            add_voxel(&mut eq, voxel, poses, variable_of);
        }
        eq
    });
    let mut total = parts
        .iter()
        .fold(NormalEquations::zeros(dim), |acc, part| acc.add(part));
    // Only blocks with row <= column were added: mirror them.
    for r in 0..dim {
        for c in 0..r {
            total.hessian[r * dim + c] = total.hessian[c * dim + r];
        }
    }
    total
}

fn add_voxel(
    eq: &mut NormalEquations,
    voxel: &PlaneVoxel,
    poses: &[Pose],
    variable_of: &[Option<usize>],
) {
    let d = voxel_derivatives(&voxel.clusters, poses);
    eq.cost += d.cost;
    let dim = eq.dim;
    for (a, (frame_a, _)) in voxel.clusters.iter().enumerate() {
        let Some(va) = variable_of[*frame_a] else {
            continue;
        };
        for i in 0..6 {
            eq.gradient[va + i] += d.gradient[a][i];
        }
        for (b, (frame_b, _)) in voxel.clusters.iter().enumerate() {
            let Some(vb) = variable_of[*frame_b] else {
                continue;
            };
            if vb < va {
                continue;
            }
            let block = d.block(a, b);
            for i in 0..6 {
                let row = &mut eq.hessian[(va + i) * dim + vb..(va + i) * dim + vb + 6];
                for (j, h) in row.iter_mut().enumerate() {
                    *h += block[(i, j)];
                }
            }
        }
    }
}
