//! Accumulation of the Gauss-Newton normal equations `H = sum w rho' J^T J`,
//! `b = sum w rho' J sigma` over a factor block (DESIGN step 8), with a Cauchy loss
//! `rho(s) = c^2 ln(1 + s / c^2)` on `s = sigma^2`. Per-residual Jacobians are never stored.

use crate::factor::{FactorBlock, FactorPoint, Surface};
use crate::geometry::Pose;
use crate::parallel::{Parallelism, map_indexed};
use crate::solve::block_hessian::{BlockHessian, ColumnsMut};
use crate::solve::residual::PlacedSurface;
#[cfg(test)]
use crate::solve::residual::residual_and_jacobians;
use nalgebra::{Matrix6, Vector6};
use rayon::prelude::*;

/// Normal equations over the free pose parameters (6 per free frame).
#[derive(Debug, Clone)]
pub struct NormalEquations {
    /// Number of unknowns.
    pub dim: usize,
    /// H, as the 6 x 6 blocks of the frame pairs that residuals couple.
    pub hessian: BlockHessian,
    /// Gradient vector b.
    pub gradient: Vec<f64>,
    /// Robust cost `sum w rho(sigma^2)` at the linearisation point.
    pub cost: f64,
    /// Residuals that linked two frames.
    pub residuals: usize,
    /// Each part's runs of [`accumulate_into`], kept between linearisations: grown afresh at
    /// every LM step they were 30 % of a 1000-frame run's page faults (250k runs of 352 bytes
    /// at the finest scale, doubled and copied as they grew).
    run_scratch: Vec<Vec<PairRun>>,
}

/// Equal equations: their buffers are not compared.
impl PartialEq for NormalEquations {
    fn eq(&self, other: &Self) -> bool {
        (
            self.dim,
            &self.hessian,
            &self.gradient,
            self.cost,
            self.residuals,
        ) == (
            other.dim,
            &other.hessian,
            &other.gradient,
            other.cost,
            other.residuals,
        )
    }
}

impl NormalEquations {
    /// All zero, with room for the blocks that `block`'s residuals fill.
    pub fn zeros_for(block: &FactorBlock, variable_of: &[Option<usize>], dim: usize) -> Self {
        Self::zeros_with_pairs(block, variable_of, dim, &[])
    }

    /// [`Self::zeros_for`] with room for the blocks of `extra` pairs of free-frame indices.
    pub fn zeros_with_pairs(
        block: &FactorBlock,
        variable_of: &[Option<usize>],
        dim: usize,
        extra: &[(usize, usize)],
    ) -> Self {
        Self {
            dim,
            hessian: BlockHessian::for_block_and_pairs(block, variable_of, dim, extra),
            gradient: vec![0.0; dim],
            cost: 0.0,
            residuals: 0,
            run_scratch: Vec::new(),
        }
    }
}

/// Cauchy loss `rho(s)` and its derivative `rho'(s)` for `s = sigma^2`, scale `c` (m).
#[inline]
pub fn cauchy(sigma_sq: f64, scale_m: f64) -> (f64, f64) {
    let c_sq = scale_m * scale_m;
    (
        c_sq * (sigma_sq / c_sq).ln_1p(),
        cauchy_weight(sigma_sq, scale_m),
    )
}

/// `rho'(s)` of [`cauchy`] alone.
#[inline]
fn cauchy_weight(sigma_sq: f64, scale_m: f64) -> f64 {
    1.0 / (1.0 + sigma_sq / (scale_m * scale_m))
}

/// Sums are split into this many fixed parts and added in order, whatever the thread count,
/// so serial and parallel runs give bit-identical results.
const PARTS: usize = 8;

/// `f` over the fixed parts of `points`, serially or in parallel, results in part order.
fn over_parts<T: Send>(
    points: &[FactorPoint],
    parallelism: Parallelism,
    f: impl Fn(&[FactorPoint]) -> T + Sync + Send,
) -> Vec<T> {
    over_parts_with(points, &mut Vec::<()>::new(), parallelism, |part, _| {
        f(part)
    })
}

/// [`over_parts`], each part also handed its own entry of `buffers` (resized to the parts).
fn over_parts_with<B: Send + Default, T: Send>(
    points: &[FactorPoint],
    buffers: &mut Vec<B>,
    parallelism: Parallelism,
    f: impl Fn(&[FactorPoint], &mut B) -> T + Sync + Send,
) -> Vec<T> {
    let size = points.len().div_ceil(PARTS).max(1);
    buffers.resize_with(points.len().div_ceil(size), B::default);
    match parallelism {
        Parallelism::Serial => (points.chunks(size).zip(buffers.iter_mut()))
            .map(|(part, buffer)| f(part, buffer))
            .collect(),
        Parallelism::Rayon => (points.par_chunks(size).zip(buffers.par_iter_mut()))
            .map(|(part, buffer)| f(part, buffer))
            .collect(),
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
    let part_cost = |points: &[FactorPoint]| -> f64 {
        points
            .iter()
            .map(|p| {
                let world = poses[p.frame as usize].apply(&p.point_in_lidar_m());
                let sigma = placed[p.surface as usize].residual(&world);
                p.weight_f64() * cauchy(sigma * sigma, block.robust_scale_m).0
            })
            .sum()
    };
    over_parts(&block.points, parallelism, part_cost)
        .into_iter()
        .sum()
}

/// Sums over consecutive residuals between the same two frames (a "run"), kept in terms of
/// the point frame's Jacobian alone. With the left perturbations of residual.rs,
/// `J_b = [(w - t_b) x g, g]` and `J_a = [g x (w - t_a), -g] = -B J_b` with
/// `B = [[I, [t_b - t_a]x], [0, I]]`. So with `S = sum w J_b J_b^T` and
/// `s = sum w sigma J_b`: `H_bb = S`, `H_ab = -B S`, `H_aa = B S B^T`, `b_b = s`,
/// `b_a = -B s`. A residual costs 36 products instead of the 144 of the stacked 12-vector,
/// and the 6 x 6 sums stay in cache. Within one frame (`a = b`, `B = I`) the residual is
/// invariant to the frame's motion and adds nothing to H or b.
#[derive(Debug, Clone)]
struct PairRun {
    /// (surface frame a, point frame b).
    frames: (usize, usize),
    /// `S`, full and symmetric.
    jtj: [[f64; 6]; 6],
    /// `s`.
    jts: [f64; 6],
}

impl PairRun {
    fn new(frames: (usize, usize)) -> Self {
        Self {
            frames,
            jtj: [[0.0; 6]; 6],
            jts: [0.0; 6],
        }
    }

    #[inline]
    fn add(&mut self, w: f64, sigma: f64, jac_b: &[f64; 6]) {
        for (row, &j) in self.jtj.iter_mut().zip(jac_b) {
            let wj = w * j;
            for (h, &jk) in row.iter_mut().zip(jac_b) {
                *h += wj * jk;
            }
        }
        for (g, &j) in self.jts.iter_mut().zip(jac_b) {
            *g += w * sigma * j;
        }
    }

    /// The run's blocks of H and b at `poses` (computed in parallel; only adding them to H is
    /// left to the serial pass, which was 40 % of the demo's accumulation otherwise).
    fn blocks(&self, poses: &[Pose]) -> RunBlocks {
        let (a, b) = self.frames;
        let s = Matrix6::from_fn(|r, c| self.jtj[r][c]);
        let g = Vector6::from_column_slice(&self.jts);
        let mut coupling = Matrix6::<f64>::identity();
        let d = poses[b].translation - poses[a].translation;
        coupling
            .fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&d.cross_matrix());
        let h_ab = -(coupling * s);
        let h_aa = h_ab * -coupling.transpose();
        let g_a = -(coupling * g);
        RunBlocks {
            frames: self.frames,
            h_aa,
            h_ab,
            h_bb: s,
            g_a,
            g_b: g,
        }
    }
}

/// What a [`PairRun`] adds to H and b: `H_aa`, `H_ab`, `H_bb`, `b_a`, `b_b`.
struct RunBlocks {
    /// (surface frame a, point frame b), `a != b`.
    frames: (usize, usize),
    h_aa: Matrix6<f64>,
    h_ab: Matrix6<f64>,
    h_bb: Matrix6<f64>,
    g_a: Vector6<f64>,
    g_b: Vector6<f64>,
}

impl RunBlocks {
    /// Adds the blocks of the free frames that fall in `columns` to it, and their gradient
    /// entries to `gradient` (the entries of those columns' frames).
    fn add_to(
        &self,
        columns: &mut ColumnsMut,
        gradient: &mut [f64],
        variable_of: &[Option<usize>],
    ) {
        let (a, b) = self.frames;
        let free = |frame: usize| variable_of[frame].map(|v| v / 6);
        let (fa, fb) = (free(a), free(b));
        let first = columns.columns().start;
        // Each destination (block or gradient entry) gets one term per run, so the order of
        // these adds among themselves does not matter.
        for (frame, h, g) in [(fa, &self.h_aa, &self.g_a), (fb, &self.h_bb, &self.g_b)] {
            if let Some(f) = frame.filter(|&f| columns.holds(f, f)) {
                columns.add(f, f, h);
                let at = 6 * (f - first);
                let entries = gradient[at..at + 6].iter_mut();
                entries.zip(g.iter()).for_each(|(e, g)| *e += g);
            }
        }
        if let (Some(fa), Some(fb)) = (fa, fb)
            && columns.holds(fa, fb)
        {
            columns.add(fa, fb, &self.h_ab);
        }
    }
}

/// Column ranges H is filled in, in parallel (a fixed number, whatever the thread count).
const ADD_PARTS: usize = 8;

/// About `parts` column ranges of H holding equal shares of its stored blocks, as bounds
/// from 0 to the frame count (see [`BlockHessian::columns_mut`]).
fn column_bounds(hessian: &BlockHessian, parts: usize) -> Vec<usize> {
    let (frames, blocks) = (hessian.frames(), hessian.stored_blocks());
    let mut bounds = vec![0];
    for k in 1..parts {
        let share = blocks * k / parts;
        // The first column whose blocks begin at or after this share.
        let col = (0..=frames).find(|&c| hessian.blocks_before_column(c) >= share);
        let col = col
            .unwrap_or(frames)
            .max(*bounds.last().expect("starts at 0"));
        bounds.push(col);
    }
    bounds.push(frames);
    bounds
}

/// Adds `runs`' blocks to H and b, each column range of `bounds` by one task that reads every
/// run in order and adds what falls in its columns: each block and gradient entry receives its
/// terms in run order, as a serial pass would add them (bit-identical, whatever the thread
/// count), but the two threads share the work (at 1000 frames the serial pass was 6 % of the
/// run, `perf`).
fn add_runs(
    eq: &mut NormalEquations,
    runs: &[RunBlocks],
    bounds: &[usize],
    variable_of: &[Option<usize>],
    parallelism: Parallelism,
) {
    let columns = eq.hessian.columns_mut(bounds);
    let mut gradients = Vec::with_capacity(columns.len());
    let mut rest = eq.gradient.as_mut_slice();
    for range in bounds.windows(2) {
        let (part, tail) = rest.split_at_mut(6 * (range[1] - range[0]));
        gradients.push(part);
        rest = tail;
    }
    let fill = |(mut columns, gradient): (ColumnsMut, &mut [f64])| {
        for run in runs {
            run.add_to(&mut columns, gradient, variable_of);
        }
    };
    match parallelism {
        Parallelism::Serial => columns.into_iter().zip(gradients).for_each(fill),
        Parallelism::Rayon => columns.into_par_iter().zip(gradients).for_each(fill),
    }
}

/// Runs whose blocks are computed together before they are added to H.
const RUNS_PER_CHUNK: usize = 4096;

/// What one fixed part of the block contributes: its runs in order (runs within one frame
/// left out), its cost and count.
struct PartSums {
    cost: f64,
    residuals: usize,
}

/// The block with its points ordered by (surface frame, point frame), otherwise in their
/// order: the same residuals, summed faster by [`accumulate`]. `frames` bounds the frame
/// indices; a point whose frame or surface is out of range goes last.
pub fn order_by_frame_pair(block: &FactorBlock, frames: usize) -> FactorBlock {
    into_ordered_by_frame_pair(block.clone(), frames)
}

/// `order_by_frame_pair` in place of `block` (its unordered points freed on the way, so
/// at most two copies of the points exist at once).
pub fn into_ordered_by_frame_pair(mut block: FactorBlock, frames: usize) -> FactorBlock {
    let points = std::mem::take(&mut block.points);
    let ordered = {
        let key = frame_pair_key(&block.surfaces, frames);
        // Stably by surface frame, then each surface frame's run stably by point frame: the
        // (surface frame, point frame) order, ties in input order, with one copy of the points
        // (two stable passes over all of them made two; 17.6 M points at the finest scale of a
        // 1000-frame window are 700 MB each).
        let mut ordered = points.clone();
        let mut counts = Vec::new();
        counting_sort_into(&points, &mut ordered, frames + 1, |p| key(p).0, &mut counts);
        drop(points);
        let surface_frame_ends = counts[..=frames].to_vec();
        let mut run = Vec::new();
        let mut start = 0;
        for &end in &surface_frame_ends {
            let range = start..end;
            start = end;
            if range.len() < 2 {
                continue;
            }
            run.clear();
            run.extend_from_slice(&ordered[range.clone()]);
            counting_sort_into(
                &run,
                &mut ordered[range],
                frames + 1,
                |p| key(p).1,
                &mut counts,
            );
        }
        ordered
    };
    block.points = ordered;
    block
}

/// True when `block`'s points are in (surface frame, point frame) order (as
/// [`order_by_frame_pair`] leaves them, and as the smoothing step makes them).
pub fn is_ordered_by_frame_pair(block: &FactorBlock, frames: usize) -> bool {
    let key = frame_pair_key(&block.surfaces, frames);
    block.points.windows(2).all(|w| key(&w[0]) <= key(&w[1]))
}

/// (surface frame, point frame) of a point, frames clamped to `frames`. The surfaces' frames
/// are read once into a compact table (the sorts look one up per point and pass).
fn frame_pair_key(surfaces: &[Surface], frames: usize) -> impl Fn(&FactorPoint) -> (usize, usize) {
    let surface_frames: Vec<u32> = surfaces
        .iter()
        .map(|s| s.frame.min(frames) as u32)
        .collect();
    move |p: &FactorPoint| {
        let surface_frame = surface_frames
            .get(p.surface as usize)
            .map_or(frames, |&f| f as usize);
        (surface_frame, (p.frame as usize).min(frames))
    }
}

/// `points` stably sorted by `key` (below `buckets`) into `sorted` (as long as `points`).
/// `counts` is a buffer; on return `counts[k]` is where bucket `k` ends in `sorted`.
fn counting_sort_into(
    points: &[FactorPoint],
    sorted: &mut [FactorPoint],
    buckets: usize,
    key: impl Fn(&FactorPoint) -> usize,
    counts: &mut Vec<usize>,
) {
    assert_eq!(points.len(), sorted.len(), "one slot per point");
    counts.clear();
    counts.resize(buckets + 1, 0);
    for p in points {
        counts[key(p) + 1] += 1;
    }
    for k in 0..buckets {
        counts[k + 1] += counts[k];
    }
    for p in points {
        let slot = &mut counts[key(p)];
        sorted[*slot] = *p;
        *slot += 1;
    }
}

/// Accumulates H and b at `poses`. `variable_of[frame]` is the first parameter index of a
/// free frame, `None` for a fixed one. `known_cost` is the [`block_cost`] at `poses` when the
/// caller already has it (LM has it from the accepted step): it is taken as the cost, and
/// the logarithm of the loss is not evaluated again.
pub fn accumulate(
    block: &FactorBlock,
    poses: &[Pose],
    variable_of: &[Option<usize>],
    dim: usize,
    known_cost: Option<f64>,
    parallelism: Parallelism,
) -> NormalEquations {
    let mut eq = NormalEquations::zeros_for(block, variable_of, dim);
    accumulate_into(&mut eq, block, poses, variable_of, known_cost, parallelism);
    eq
}

/// [`accumulate`] into `eq` (made by [`NormalEquations::zeros_for`] for this block and
/// layout; its pattern kept, its contents replaced), which saves building the pattern and
/// allocating per linearisation.
pub fn accumulate_into(
    eq: &mut NormalEquations,
    block: &FactorBlock,
    poses: &[Pose],
    variable_of: &[Option<usize>],
    known_cost: Option<f64>,
    parallelism: Parallelism,
) {
    eq.hessian.fill_zero();
    eq.gradient.fill(0.0);
    eq.cost = 0.0;
    eq.residuals = 0;
    let placed = placed_surfaces(block, poses);
    // Each part's runs go into its buffer of `run_scratch`.
    let part = |points: &[FactorPoint], runs: &mut Vec<PairRun>| {
        runs.clear();
        let mut sums = PartSums {
            cost: 0.0,
            residuals: 0,
        };
        // Within one frame (a = b) a residual adds nothing to H or b (see `PairRun`).
        let close = |run: PairRun, runs: &mut Vec<PairRun>| {
            if run.frames.0 != run.frames.1 {
                runs.push(run);
            }
        };
        let mut current: Option<PairRun> = None;
        for p in points {
            let (a, b) = (block.surfaces[p.surface as usize].frame, p.frame as usize);
            let world = poses[b].apply(&p.point_in_lidar_m());
            let (sigma, jac_b) = placed[p.surface as usize]
                .residual_and_point_jacobian(&world, &poses[b].translation);
            let rho_prime = if known_cost.is_some() {
                cauchy_weight(sigma * sigma, block.robust_scale_m)
            } else {
                let (rho, rho_prime) = cauchy(sigma * sigma, block.robust_scale_m);
                sums.cost += p.weight_f64() * rho;
                rho_prime
            };
            sums.residuals += 1;
            if current.as_ref().is_some_and(|run| run.frames != (a, b)) {
                close(current.take().expect("checked"), runs);
            }
            current.get_or_insert_with(|| PairRun::new((a, b))).add(
                p.weight_f64() * rho_prime,
                sigma,
                &jac_b,
            );
        }
        if let Some(run) = current {
            close(run, runs);
        }
        sums
    };
    // Parts are added in order, so serial and parallel runs agree bit for bit.
    let mut run_scratch = std::mem::take(&mut eq.run_scratch);
    let parts = over_parts_with(&block.points, &mut run_scratch, parallelism, part);
    for sums in &parts {
        eq.cost += sums.cost;
        eq.residuals += sums.residuals;
    }
    // The runs' blocks are computed in parallel a chunk at a time (a run's blocks take 1.3 kB:
    // all at once would be 0.5 GB at 1000 frames) and added to H in order.
    let runs: Vec<&PairRun> = run_scratch.iter().flatten().collect();
    let bounds = column_bounds(&eq.hessian, ADD_PARTS);
    for chunk in runs.chunks(RUNS_PER_CHUNK) {
        let blocks = map_indexed(chunk.len(), parallelism, |k| chunk[k].blocks(poses));
        add_runs(eq, &blocks, &bounds, variable_of, parallelism);
    }
    drop(runs);
    eq.run_scratch = run_scratch;
    if let Some(cost) = known_cost {
        eq.cost = cost;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::factor::{FactorPoint, Surface};
    use crate::kernels::fit::Polynomial;
    use crate::solve::lm::variable_layout;
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
            let w = p.weight_f64() * cauchy(sigma * sigma, block.robust_scale_m).1;
            h += w * &row * row.transpose();
            g += w * sigma * &row;
        }
        (h, g)
    }

    #[test]
    fn frame_pair_order_is_a_stable_sort() {
        let surface = |frame: usize| Surface {
            frame,
            kernel_in_lidar: Vector3::zeros(),
            tangent_from_lidar: nalgebra::Matrix3::identity(),
            polynomial: Polynomial {
                coefficients: [0.0; 6],
            },
            gamma_m: 1.0,
        };
        let point = |surface: u32, frame: u32, k: usize| {
            FactorPoint::new(surface, frame, Vector3::new(k as f64, 0.0, 0.0), 1.0)
        };
        let pairs = [
            (2, 1),
            (0, 3),
            (1, 0),
            (2, 1),
            (0, 0),
            (9, 1),
            (1, 7),
            (0, 3),
            (1, 0),
        ];
        let block = FactorBlock {
            surfaces: vec![surface(3), surface(1), surface(3)],
            points: (pairs.iter().enumerate())
                .map(|(k, &(s, f))| point(s, f, k))
                .collect(),
            ..FactorBlock::default()
        };
        let frames = 4;
        let mut expected = block.points.clone();
        expected.sort_by_key(|p| {
            let a = block
                .surfaces
                .get(p.surface as usize)
                .map_or(frames, |s| s.frame);
            (a, (p.frame as usize).min(frames))
        });
        assert_eq!(order_by_frame_pair(&block, frames).points, expected);
        assert!(!is_ordered_by_frame_pair(&block, frames));
        let ordered = into_ordered_by_frame_pair(block.clone(), frames);
        assert_eq!(ordered.points, expected);
        assert_eq!(ordered.surfaces, block.surfaces);
        assert!(is_ordered_by_frame_pair(&ordered, frames));

        // Many points, many ties, some frames out of range: still the stable sort.
        let frames = 30;
        let surfaces: Vec<Surface> = (0..50).map(|s| surface((s * 7) % (frames + 3))).collect();
        let points: Vec<FactorPoint> = (0..5000)
            .map(|k| point(((k * 31) % 53) as u32, ((k * 17) % 34) as u32, k))
            .collect();
        let key = |p: &FactorPoint| {
            let a = surfaces.get(p.surface as usize).map_or(frames, |s| s.frame);
            (a.min(frames), (p.frame as usize).min(frames))
        };
        let mut expected = points.clone();
        expected.sort_by_key(key);
        let block = FactorBlock {
            surfaces: surfaces.clone(),
            points,
            ..FactorBlock::default()
        };
        assert_eq!(into_ordered_by_frame_pair(block, frames).points, expected);
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
            tangent_from_lidar: crate::kernels::tangent::tangent_from_world(
                &Vector3::new(tilt, 0.2, 1.0).normalize(),
            ) * poses[frame].rotation,
            polynomial: Polynomial {
                coefficients: [0.2, -0.1, 0.05, 0.1, 0.02, 0.01],
            },
            gamma_m: 1.0,
        };
        let point = |surface: u32, frame: u32, x: f64| {
            FactorPoint::new(
                surface,
                frame,
                Vector3::new(1.0 + x, 0.3 - x, 0.4 + 0.5 * x),
                0.5 + x,
            )
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
        let eq = accumulate(&block, &poses, &variable_of, dim, None, Parallelism::Serial);
        let cost = block_cost(&block, &poses, Parallelism::Serial);
        assert_eq!(eq.cost, cost, "the cost of block_cost, bit for bit");
        let known = accumulate(
            &block,
            &poses,
            &variable_of,
            dim,
            Some(cost),
            Parallelism::Serial,
        );
        assert_eq!(
            (known.hessian, known.gradient),
            (eq.hessian.clone(), eq.gradient.clone())
        );
        let (h, g) = dense_reference(&block, &poses, &variable_of, dim);
        let h_got = DMatrix::from_row_slice(dim, dim, &eq.hessian.to_dense());
        assert!((h_got - &h).abs().max() < 1e-12 * h.abs().max());
        assert!(
            (DVector::from_column_slice(&eq.gradient) - &g).abs().max() < 1e-12 * g.abs().max()
        );
        assert_eq!(eq.residuals, block.points.len());
        // H is filled by column ranges in parallel: the same sums, bit for bit.
        let parallel = accumulate(&block, &poses, &variable_of, dim, None, Parallelism::Rayon);
        assert_eq!(parallel, eq);
    }

    #[test]
    fn column_bounds_split_the_blocks_in_even_shares() {
        let frames = 50;
        let pairs = (0..frames).flat_map(|a| (a + 1..frames.min(a + 6)).map(move |b| (a, b)));
        let hessian = BlockHessian::with_pairs(frames, pairs);
        let bounds = column_bounds(&hessian, 5);
        assert_eq!((bounds[0], *bounds.last().unwrap()), (0, frames));
        assert!(bounds.windows(2).all(|w| w[0] <= w[1]));
        let share = |k: usize| {
            hessian.blocks_before_column(bounds[k + 1]) - hessian.blocks_before_column(bounds[k])
        };
        let even = hessian.stored_blocks() / 5;
        for k in 0..5 {
            assert!(
                share(k).abs_diff(even) <= 6,
                "part {k}: {} of {even}",
                share(k)
            );
        }
        // Fewer frames than parts: empty ranges, still covering every column once.
        let small = BlockHessian::with_pairs(3, [(0, 1), (1, 2)]);
        let bounds = column_bounds(&small, 8);
        assert_eq!(
            (bounds[0], *bounds.last().unwrap(), bounds.len()),
            (0, 3, 9)
        );
    }
}
