//! Accumulation of the Gauss-Newton normal equations `H = sum w rho' J^T J`,
//! `b = sum w rho' J sigma` over a factor block (DESIGN step 8), with a Cauchy loss
//! `rho(s) = c^2 ln(1 + s / c^2)` on `s = sigma^2`. Per-residual Jacobians are never stored.

use crate::factor::FactorBlock;
use crate::geometry::Pose;
use crate::parallel::Parallelism;
use crate::residual::PlacedSurface;
#[cfg(test)]
use crate::residual::residual_and_jacobians;
use rayon::prelude::*;

/// Dense normal equations over the free pose parameters (6 per free frame).
#[derive(Debug, Clone, PartialEq)]
pub struct NormalEquations {
    /// Number of unknowns.
    pub dim: usize,
    /// Row-major `dim x dim` matrix H (only the upper triangle is accumulated, then mirrored).
    pub hessian: Vec<f64>,
    /// Gradient vector b.
    pub gradient: Vec<f64>,
    /// Robust cost `sum w rho(sigma^2)` at the linearisation point.
    pub cost: f64,
    /// Residuals that linked two frames.
    pub residuals: usize,
}

impl NormalEquations {
    fn zeros(dim: usize) -> Self {
        Self {
            dim,
            hessian: vec![0.0; dim * dim],
            gradient: vec![0.0; dim],
            cost: 0.0,
            residuals: 0,
        }
    }

    fn merge(mut self, other: Self) -> Self {
        self.hessian
            .iter_mut()
            .zip(&other.hessian)
            .for_each(|(a, b)| *a += b);
        self.gradient
            .iter_mut()
            .zip(&other.gradient)
            .for_each(|(a, b)| *a += b);
        self.cost += other.cost;
        self.residuals += other.residuals;
        self
    }

    fn mirror_upper(&mut self) {
        for r in 0..self.dim {
            for c in 0..r {
                self.hessian[r * self.dim + c] = self.hessian[c * self.dim + r];
            }
        }
    }
}

/// Cauchy loss `rho(s)` and its derivative `rho'(s)` for `s = sigma^2`, scale `c` (m).
#[inline]
pub fn cauchy(sigma_sq: f64, scale_m: f64) -> (f64, f64) {
    let c_sq = scale_m * scale_m;
    (
        c_sq * (sigma_sq / c_sq).ln_1p(),
        1.0 / (1.0 + sigma_sq / c_sq),
    )
}

/// Sums are split into this many fixed parts and added in order, whatever the thread count,
/// so serial and parallel runs give bit-identical results.
const PARTS: usize = 8;

/// `f` over the fixed parts of `points`, serially or in parallel, results in part order.
fn over_parts<T: Send>(
    points: &[crate::factor::FactorPoint],
    parallelism: Parallelism,
    f: impl Fn(&[crate::factor::FactorPoint]) -> T + Sync + Send,
) -> Vec<T> {
    let size = points.len().div_ceil(PARTS).max(1);
    match parallelism {
        Parallelism::Serial => points.chunks(size).map(f).collect(),
        Parallelism::Rayon => points.par_chunks(size).map(f).collect(),
    }
}

/// Every surface of the block placed at its frame's pose.
fn placed_surfaces<'a>(block: &'a FactorBlock, poses: &[Pose]) -> Vec<PlacedSurface<'a>> {
    block
        .surfaces
        .iter()
        .map(|s| PlacedSurface::new(s, &poses[s.frame]))
        .collect()
}

/// Robust cost of the block at `poses` (no derivatives).
pub fn block_cost(block: &FactorBlock, poses: &[Pose], parallelism: Parallelism) -> f64 {
    let placed = placed_surfaces(block, poses);
    let part_cost = |points: &[crate::factor::FactorPoint]| -> f64 {
        points
            .iter()
            .map(|p| {
                let world = poses[p.frame as usize].apply(&p.point_in_lidar);
                let sigma = placed[p.surface as usize].residual(&world);
                p.weight * cauchy(sigma * sigma, block.robust_scale_m).0
            })
            .sum()
    };
    over_parts(&block.points, parallelism, part_cost)
        .into_iter()
        .sum()
}

/// `J^T W J` and `J^T W sigma` of consecutive residuals between the same two frames, kept
/// small (12 x 12, upper triangle) and added to the full system once per run. With the
/// points ordered by frame pair ([`order_by_frame_pair`]) runs are hundreds long, and the
/// sums stay in cache instead of scattering over the `6N x 6N` matrix.
struct PairRun {
    /// First parameter of the surface frame (rows 0..6) and of the point frame (rows 6..12).
    vars: [Option<usize>; 2],
    frames: (usize, usize),
    hessian: [[f64; 12]; 12],
    gradient: [f64; 12],
}

impl PairRun {
    fn new() -> Self {
        Self {
            vars: [None, None],
            frames: (usize::MAX, usize::MAX),
            hessian: [[0.0; 12]; 12],
            gradient: [0.0; 12],
        }
    }

    /// Adds the run to `eq` (upper triangle) and starts an empty one for `frames`.
    fn flush(
        &mut self,
        eq: &mut NormalEquations,
        frames: (usize, usize),
        variable_of: &[Option<usize>],
    ) {
        let dim = eq.dim;
        let var_of_row = |row: usize| self.vars[row / 6].map(|v| v + row % 6);
        for i in 0..12 {
            let Some(r) = var_of_row(i) else { continue };
            eq.gradient[r] += self.gradient[i];
            for k in i..12 {
                let Some(c) = var_of_row(k) else { continue };
                let (r, c) = if r <= c { (r, c) } else { (c, r) };
                eq.hessian[r * dim + c] += self.hessian[i][k];
            }
        }
        let (a, b) = frames;
        // A residual within one frame (not produced by the smoothing, but a block may hold
        // one) has the single Jacobian J_a + J_b, kept in rows 0..6.
        self.vars = if a == b {
            [variable_of.get(a).copied().flatten(), None]
        } else {
            [
                variable_of.get(a).copied().flatten(),
                variable_of.get(b).copied().flatten(),
            ]
        };
        self.frames = frames;
        self.hessian = [[0.0; 12]; 12];
        self.gradient = [0.0; 12];
    }

    fn add(&mut self, w: f64, sigma: f64, jac_a: &[f64; 6], jac_b: &[f64; 6]) {
        let mut jac = [0.0; 12];
        if self.frames.0 == self.frames.1 {
            (0..6).for_each(|i| jac[i] = jac_a[i] + jac_b[i]);
        } else {
            jac[..6].copy_from_slice(jac_a);
            jac[6..].copy_from_slice(jac_b);
        }
        for (i, row) in self.hessian.iter_mut().enumerate() {
            let wj = w * jac[i];
            self.gradient[i] += wj * sigma;
            for (h, &jk) in row.iter_mut().zip(&jac).skip(i) {
                *h += wj * jk;
            }
        }
    }
}

/// The block with its points ordered by (surface frame, point frame), otherwise in their
/// order: the same residuals, summed faster by [`accumulate`].
pub fn order_by_frame_pair(block: &FactorBlock) -> FactorBlock {
    let mut points = block.points.clone();
    points.sort_by_key(|p| {
        let surface_frame = block
            .surfaces
            .get(p.surface as usize)
            .map_or(usize::MAX, |s| s.frame);
        (surface_frame, p.frame)
    });
    FactorBlock {
        points,
        ..block.clone()
    }
}

/// Accumulates H and b at `poses`. `variable_of[frame]` is the first parameter index of a
/// free frame, `None` for a fixed one.
pub fn accumulate(
    block: &FactorBlock,
    poses: &[Pose],
    variable_of: &[Option<usize>],
    dim: usize,
    parallelism: Parallelism,
) -> NormalEquations {
    let placed = placed_surfaces(block, poses);
    let chunk = |points: &[crate::factor::FactorPoint]| {
        let mut eq = NormalEquations::zeros(dim);
        let mut run = PairRun::new();
        for p in points {
            let (a, b) = (block.surfaces[p.surface as usize].frame, p.frame as usize);
            let world = poses[b].apply(&p.point_in_lidar);
            let (sigma, jac_a, jac_b) =
                placed[p.surface as usize].residual_and_jacobians(&world, &poses[b].translation);
            let (rho, rho_prime) = cauchy(sigma * sigma, block.robust_scale_m);
            eq.cost += p.weight * rho;
            eq.residuals += 1;
            if run.frames != (a, b) {
                run.flush(&mut eq, (a, b), variable_of);
            }
            run.add(p.weight * rho_prime, sigma, &jac_a, &jac_b);
        }
        run.flush(&mut eq, (usize::MAX, usize::MAX), variable_of);
        eq
    };
    let mut eq = over_parts(&block.points, parallelism, chunk)
        .into_iter()
        .fold(NormalEquations::zeros(dim), NormalEquations::merge);
    eq.mirror_upper();
    eq
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::factor::{FactorPoint, Surface};
    use crate::fit::Polynomial;
    use crate::lm::variable_layout;
    use nalgebra::{DMatrix, DVector, Isometry3, Vector3};

    /// H and b built the plain way: each residual's full-length Jacobian row, stacked.
    fn dense_reference(
        block: &FactorBlock,
        poses: &[Pose],
        variable_of: &[Option<usize>],
        dim: usize,
    ) -> (DMatrix<f64>, DVector<f64>) {
        let (mut h, mut g) = (DMatrix::zeros(dim, dim), DVector::zeros(dim));
        for p in &block.points {
            let surface = &block.surfaces[p.surface as usize];
            let (a, b) = (surface.frame, p.frame as usize);
            let (sigma, jac_a, jac_b) = residual_and_jacobians(surface, p, &poses[a], &poses[b]);
            let mut row = DVector::zeros(dim);
            for (frame, jac) in [(a, jac_a), (b, jac_b)] {
                if let Some(v) = variable_of[frame] {
                    (0..6).for_each(|i| row[v + i] += jac[i]);
                }
            }
            let w = p.weight * cauchy(sigma * sigma, block.robust_scale_m).1;
            h += w * &row * row.transpose();
            g += w * sigma * &row;
        }
        (h, g)
    }

    #[test]
    fn accumulation_equals_stacked_jacobians() {
        let poses: Vec<Pose> = (0..4)
            .map(|k| {
                let k = k as f64;
                Pose::from_isometry(&Isometry3::new(
                    Vector3::new(0.3 * k, -0.2 * k, 0.1),
                    Vector3::new(0.02 * k, -0.01, 0.03 * k),
                ))
            })
            .collect();
        let surface = |frame: usize, tilt: f64| Surface {
            frame,
            kernel_in_lidar: Vector3::new(1.0, tilt, 0.5),
            tangent_from_lidar: crate::tangent::tangent_from_world(
                &Vector3::new(tilt, 0.2, 1.0).normalize(),
            ) * poses[frame].rotation,
            polynomial: Polynomial {
                coefficients: [0.2, -0.1, 0.05, 0.1, 0.02, 0.01],
            },
            gamma_m: 1.0,
        };
        let point = |surface: u32, frame: u32, x: f64| FactorPoint {
            surface,
            frame,
            point_in_lidar: Vector3::new(1.0 + x, 0.3 - x, 0.4 + 0.5 * x),
            weight: 0.5 + x,
        };
        let block = FactorBlock {
            gamma_m: 1.0,
            robust_scale_m: 0.1,
            surfaces: vec![surface(0, 0.1), surface(2, -0.3), surface(3, 0.2)],
            // Runs of one frame pair, pairs with the fixed frame 0, both orders of the
            // variables, and one residual within a frame.
            points: vec![
                point(0, 1, 0.1),
                point(0, 1, 0.2),
                point(0, 2, 0.3),
                point(1, 1, 0.05),
                point(1, 1, 0.15),
                point(1, 3, 0.25),
                point(1, 2, 0.35),
                point(2, 0, 0.12),
                point(2, 1, 0.22),
            ],
            ..FactorBlock::default()
        };
        let (variable_of, dim) = variable_layout(&[true, false, false, false]);
        let eq = accumulate(&block, &poses, &variable_of, dim, Parallelism::Serial);
        let (h, g) = dense_reference(&block, &poses, &variable_of, dim);
        let h_got = DMatrix::from_row_slice(dim, dim, &eq.hessian);
        assert!((h_got - &h).abs().max() < 1e-12 * h.abs().max());
        assert!(
            (DVector::from_column_slice(&eq.gradient) - &g).abs().max() < 1e-12 * g.abs().max()
        );
        assert_eq!(eq.residuals, block.points.len());
    }
}
