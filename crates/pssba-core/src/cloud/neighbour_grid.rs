//! The k nearest points of a point set within a radius, for every point of the set, by a
//! uniform grid: the normal neighbourhoods of a cloud's voxel centroids (DESIGN step 2).
//!
//! The kd-tree query it replaced cost about 2 us per centroid (a third of the wall time on the
//! sparse crane flight, where every scale has some 65k centroids). With cells twice the
//! radius of a query's first look wide, that ball meets at most two cells per axis, so most
//! queries read at most eight cells and need no tree descent.

use crate::cloud::voxel_index::{VoxelKey, voxel_key};
use crate::parallel::{Parallelism, map_indexed};
use rustc_hash::FxHashMap;
use std::cell::RefCell;

/// The points bucketed by cell of edge twice the query radius.
struct CellGrid<'a> {
    points: &'a [[f64; 3]],
    cell_m: f64,
    /// Points of each occupied cell: `members[range]`, ascending point index.
    cells: FxHashMap<VoxelKey, (u32, u32)>,
    members: Vec<u32>,
}

impl<'a> CellGrid<'a> {
    fn new(points: &'a [[f64; 3]], cell_m: f64, parallelism: Parallelism) -> Self {
        let keys = map_indexed(points.len(), parallelism, |i| voxel_key(&points[i], cell_m));
        let mut members: Vec<u32> = (0..points.len() as u32).collect();
        // Stable: each cell's points stay in ascending index order.
        members.sort_by_key(|&i| keys[i as usize]);
        let mut cells = FxHashMap::default();
        let mut start = 0;
        while start < members.len() {
            let key = keys[members[start] as usize];
            let end = start + members[start..].partition_point(|&i| keys[i as usize] == key);
            cells.insert(key, (start as u32, end as u32));
            start = end;
        }
        Self {
            points,
            cell_m,
            cells,
            members,
        }
    }

    /// Into `found`: every point within `radius_m` of `query` as (squared distance, index).
    fn within(&self, query: &[f64; 3], radius_m: f64, found: &mut Vec<(f64, u32)>) {
        let low = voxel_key(
            &[
                query[0] - radius_m,
                query[1] - radius_m,
                query[2] - radius_m,
            ],
            self.cell_m,
        );
        let high = voxel_key(
            &[
                query[0] + radius_m,
                query[1] + radius_m,
                query[2] + radius_m,
            ],
            self.cell_m,
        );
        let radius_sq = radius_m * radius_m;
        for x in low.0..=high.0 {
            for y in low.1..=high.1 {
                for z in low.2..=high.2 {
                    let Some(&(start, end)) = self.cells.get(&(x, y, z)) else {
                        continue;
                    };
                    for &i in &self.members[start as usize..end as usize] {
                        let p = &self.points[i as usize];
                        let d_sq = (p[0] - query[0]).powi(2)
                            + (p[1] - query[1]).powi(2)
                            + (p[2] - query[2]).powi(2);
                        if d_sq <= radius_sq {
                            found.push((d_sq, i));
                        }
                    }
                }
            }
        }
    }
}

/// Radius of a query's first look, as a fraction of the full radius (see [`nearest_within`]).
const FIRST_RADIUS_FRACTION: f64 = 2.0 / 3.0;

thread_local! {
    /// Per-thread candidate buffer of [`nearest_within`].
    static FOUND: RefCell<Vec<(f64, u32)>> = const { RefCell::new(Vec::new()) };
}

/// For every point of `points`, its at most `k` nearest points of `points` within `radius_m`
/// (itself included, at distance 0), nearest first, ties by index.
pub fn nearest_within(
    points: &[[f64; 3]],
    k: usize,
    radius_m: f64,
    parallelism: Parallelism,
) -> Vec<Vec<u32>> {
    assert!(u32::try_from(points.len()).is_ok(), "too many points");
    if points.is_empty() || k == 0 {
        return vec![Vec::new(); points.len()];
    }
    // Most points have their k nearest well inside the radius (a surface's voxel centroids:
    // 12 within 2 voxels of a 3-voxel radius), so each query first looks within a smaller
    // ball. Where that holds k points, they are the k nearest within the full radius too
    // (every other point is farther than all of them), so the result is the same; elsewhere
    // the query is repeated with the full radius. Cells are as wide as the first ball's
    // diameter: it meets at most 2 cells per axis (the full ball at most 3).
    let first_radius_m = FIRST_RADIUS_FRACTION * radius_m;
    let cell_m = (2.0 * first_radius_m).max(f64::MIN_POSITIVE);
    let grid = CellGrid::new(points, cell_m, parallelism);
    let closer = |a: &(f64, u32), b: &(f64, u32)| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1));
    map_indexed(points.len(), parallelism, |q| {
        FOUND.with_borrow_mut(|found| {
            found.clear();
            grid.within(&points[q], first_radius_m, found);
            if found.len() < k {
                found.clear();
                grid.within(&points[q], radius_m, found);
            }
            if found.len() > k {
                found.select_nth_unstable_by(k - 1, closer);
                found.truncate(k);
            }
            found.sort_unstable_by(closer);
            found.iter().map(|&(_, i)| i).collect()
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use kiddo::{ImmutableKdTree, SquaredEuclidean};
    use rand::{Rng, SeedableRng, rngs::StdRng};
    use std::num::NonZero;

    /// A wavy sheet with a sparse scatter around it, at any coordinates' sign.
    fn cloud(seed: u64) -> Vec<[f64; 3]> {
        let mut rng = StdRng::seed_from_u64(seed);
        let sheet = (0..1500).map(|_| {
            let (x, y): (f64, f64) = (rng.random_range(-3.0..3.0), rng.random_range(-3.0..3.0));
            [x, y, 0.3 * (x * 1.7).sin() + 0.05 * y]
        });
        let sheet: Vec<[f64; 3]> = sheet.collect();
        let scatter = (0..300).map(|_| {
            [
                rng.random_range(-20.0..20.0),
                rng.random_range(-20.0..20.0),
                rng.random_range(-5.0..5.0),
            ]
        });
        sheet.into_iter().chain(scatter).collect()
    }

    #[test]
    fn matches_the_kd_tree_query() {
        for (seed, k, radius_m) in [(1, 12, 0.6), (2, 5, 0.3), (3, 12, 2.0), (4, 1, 0.1)] {
            let points = cloud(seed);
            let tree: ImmutableKdTree<f64, 3> = ImmutableKdTree::new_from_slice(&points);
            let got = nearest_within(&points, k, radius_m, Parallelism::Serial);
            for (q, list) in got.iter().enumerate() {
                let expected: Vec<u32> = tree
                    .nearest_n_within::<SquaredEuclidean>(
                        &points[q],
                        radius_m * radius_m,
                        NonZero::new(k).unwrap(),
                        true,
                    )
                    .iter()
                    .map(|n| n.item as u32)
                    .collect();
                assert_eq!(list, &expected, "seed {seed}, point {q}");
                assert_eq!(list.first(), Some(&(q as u32)));
            }
        }
    }

    #[test]
    fn serial_and_parallel_agree_and_degenerate_inputs_answer() {
        let points = cloud(5);
        let serial = nearest_within(&points, 12, 0.5, Parallelism::Serial);
        assert_eq!(serial, nearest_within(&points, 12, 0.5, Parallelism::Rayon));
        assert!(nearest_within(&[], 12, 0.5, Parallelism::Serial).is_empty());
        assert_eq!(
            nearest_within(&points[..3], 0, 0.5, Parallelism::Serial),
            vec![Vec::<u32>::new(); 3]
        );
        // Duplicates: ties by index.
        let twins = [[1.0, 2.0, 3.0]; 4];
        let lists = nearest_within(&twins, 3, 0.1, Parallelism::Serial);
        assert_eq!(lists[2], vec![0, 1, 2]);
    }
}
