//! One scale's kernel outcomes gathered into a factor block, residual points in the
//! (surface frame, point frame) order the normal equations sum them in (see
//! [`crate::solve::normal_equations`]).
//!
//! Concatenating the kernels' points and then sorting them ([`into_ordered_by_frame_pair`])
//! took four serial passes over all of them, each into freshly faulted memory (17.6 M points,
//! 420 MB, at the finest scale of a 1000-frame window). Here every surface frame's share of
//! the block is known up front from the kernels' point counts, so each surface frame's run is
//! filled straight from the kernels' lists, the runs in parallel: the same block in one pass.
//!
//! [`into_ordered_by_frame_pair`]: crate::solve::normal_equations::into_ordered_by_frame_pair

use crate::factor::{FactorPoint, Surface};
use crate::parallel::Parallelism;
use nalgebra::Vector3;
use rayon::prelude::*;

/// All the points of `lists` (list `i` holding surface `i`'s points), each given its
/// surface's index, in (surface frame, point frame) order, ties in input order: the points
/// [`crate::solve::normal_equations::into_ordered_by_frame_pair`] would give for the lists
/// concatenated in order. Frames beyond `frames` count as `frames` (they go last), as there.
///
/// # Panics
/// If `surfaces` and `lists` differ in length, or there are more than `u32::MAX` surfaces.
pub fn ordered_by_frame_pair(
    surfaces: &[Surface],
    lists: &[Vec<FactorPoint>],
    frames: usize,
    parallelism: Parallelism,
) -> Vec<FactorPoint> {
    assert_eq!(surfaces.len(), lists.len(), "one point list per surface");
    assert!(
        u32::try_from(surfaces.len()).is_ok(),
        "surface indices are u32"
    );
    // Per surface frame: its surfaces in order, and how many points they hold.
    let buckets = frames + 1;
    let mut members: Vec<Vec<u32>> = vec![Vec::new(); buckets];
    let mut sizes = vec![0usize; buckets];
    for (i, (surface, list)) in surfaces.iter().zip(lists).enumerate() {
        let bucket = surface.frame.min(frames);
        members[bucket].push(i as u32);
        sizes[bucket] += list.len();
    }
    let mut points = zeroed(sizes.iter().sum(), parallelism);
    let mut runs: Vec<&mut [FactorPoint]> = Vec::with_capacity(buckets);
    let mut rest = points.as_mut_slice();
    for &size in &sizes {
        let (run, tail) = rest.split_at_mut(size);
        runs.push(run);
        rest = tail;
    }
    let fill = |(run, members): (&mut [FactorPoint], &Vec<u32>)| {
        fill_run(run, members, lists, frames);
    };
    match parallelism {
        Parallelism::Serial => runs.into_iter().zip(&members).for_each(fill),
        Parallelism::Rayon => runs.into_par_iter().zip(&members).for_each(fill),
    }
    points
}

/// `len` placeholder points, written in parallel (their pages are faulted in by both
/// threads, not one).
fn zeroed(len: usize, parallelism: Parallelism) -> Vec<FactorPoint> {
    let zero = FactorPoint {
        surface: 0,
        frame: 0,
        point_in_lidar: Vector3::zeros(),
        weight: 0.0,
    };
    match parallelism {
        Parallelism::Serial => vec![zero; len],
        Parallelism::Rayon => (0..len).into_par_iter().map(|_| zero).collect(),
    }
}

/// One surface frame's run: the points of the surfaces `members` (ascending), stably sorted by
/// point frame, each given its surface's index. `run` holds exactly that many points.
fn fill_run(run: &mut [FactorPoint], members: &[u32], lists: &[Vec<FactorPoint>], frames: usize) {
    let point_frame = |p: &FactorPoint| (p.frame as usize).min(frames);
    let members = || members.iter().map(|&i| (i, &lists[i as usize]));
    // Counting sort: next[k] is where the next point of point frame k goes.
    let mut next = vec![0usize; frames + 2];
    for (_, list) in members() {
        list.iter().for_each(|p| next[point_frame(p) + 1] += 1);
    }
    for k in 0..=frames {
        next[k + 1] += next[k];
    }
    debug_assert_eq!(next[frames + 1], run.len());
    for (surface, list) in members() {
        for p in list {
            let slot = &mut next[point_frame(p)];
            run[*slot] = FactorPoint { surface, ..*p };
            *slot += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::factor::FactorBlock;
    use crate::kernels::fit::Polynomial;
    use crate::solve::normal_equations::into_ordered_by_frame_pair;
    use nalgebra::Matrix3;
    use rand::{Rng, SeedableRng, rngs::StdRng};

    /// Kernels' outcomes as `extract_block` makes them: a surface on some frame with points of
    /// other frames (some frames out of range, to check they go last).
    fn outcomes(seed: u64, kernels: usize, frames: usize) -> Vec<(Surface, Vec<FactorPoint>)> {
        let mut rng = StdRng::seed_from_u64(seed);
        (0..kernels)
            .map(|k| {
                let frame = rng.random_range(0..frames + 2);
                let surface = Surface {
                    frame,
                    kernel_in_lidar: Vector3::new(k as f64, 0.0, 1.0),
                    tangent_from_lidar: Matrix3::identity(),
                    polynomial: Polynomial {
                        coefficients: [0.0; 6],
                    },
                    gamma_m: 0.4,
                };
                let points = (0..rng.random_range(0..40))
                    .map(|j| {
                        let point_frame = rng.random_range(0..frames as u32 + 2);
                        // `surface` left wrong on purpose: the assembly sets it.
                        let p = Vector3::new(k as f64, j as f64, rng.random());
                        FactorPoint::new(u32::MAX, point_frame, p, rng.random())
                    })
                    .collect();
                (surface, points)
            })
            .collect()
    }

    /// The old way: concatenate in order, then the two stable counting sorts.
    fn concatenated_then_sorted(
        accepted: &[(Surface, Vec<FactorPoint>)],
        frames: usize,
    ) -> FactorBlock {
        let mut block = FactorBlock::default();
        for (i, (surface, points)) in accepted.iter().enumerate() {
            block.surfaces.push(surface.clone());
            block.points.extend(points.iter().map(|p| FactorPoint {
                surface: i as u32,
                ..*p
            }));
        }
        into_ordered_by_frame_pair(block, frames)
    }

    #[test]
    fn equals_concatenating_then_sorting_serial_and_parallel() {
        for (seed, kernels, frames) in [(1, 500, 12), (2, 3000, 100), (3, 1, 2), (4, 0, 5)] {
            let accepted = outcomes(seed, kernels, frames);
            let expected = concatenated_then_sorted(&accepted, frames);
            let (surfaces, lists): (Vec<Surface>, Vec<Vec<FactorPoint>>) =
                accepted.into_iter().unzip();
            assert_eq!(surfaces, expected.surfaces);
            for parallelism in [Parallelism::Serial, Parallelism::Rayon] {
                let points = ordered_by_frame_pair(&surfaces, &lists, frames, parallelism);
                assert_eq!(points, expected.points, "seed {seed}, {parallelism:?}");
            }
        }
    }

    #[test]
    fn a_surface_frames_run_is_filled_even_when_one_frame_holds_every_surface() {
        // All surfaces on frame 0: one run, sorted by point frame, ties in input order.
        let accepted: Vec<_> = outcomes(7, 200, 9)
            .into_iter()
            .map(|(mut s, p)| {
                s.frame = 0;
                (s, p)
            })
            .collect();
        let (surfaces, lists): (Vec<Surface>, Vec<Vec<FactorPoint>>) = accepted.into_iter().unzip();
        let points = ordered_by_frame_pair(&surfaces, &lists, 9, Parallelism::Rayon);
        let total: usize = lists.iter().map(Vec::len).sum();
        assert_eq!(points.len(), total);
        let key = |p: &FactorPoint| ((p.frame as usize).min(9), p.surface);
        assert!(points.windows(2).all(|w| key(&w[0]) <= key(&w[1])));
    }
}
