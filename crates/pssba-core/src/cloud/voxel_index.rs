//! The merged cloud of one scale bucketed by voxel, with a kd-tree over the voxel centroids
//! for the kernels' radius queries (the centroids' own normal neighbourhoods come from a grid,
//! see [`crate::cloud::neighbour_grid`]).
//!
//! With 100 overlapping frames every voxel holds points of many frames, so the centroid tree
//! is an order of magnitude smaller than a tree over every point (1.24 M points vs about 0.1 M
//! voxels on a 100 x 20k window) and is built in a fraction of the time, while radius queries
//! over the points stay exact: a point lies at most its voxel's offset from the voxel's
//! centroid, so the voxels whose centroid is within `radius + offset` hold every point within
//! `radius`; a voxel wholly inside is taken as is, the others are checked point by point.

use crate::cloud::voxel_sort::group_by_voxel;
use crate::parallel::{Parallelism, map_indexed};
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::Vector3;
use rustc_hash::FxHashMap;

/// Voxels of a voxel-major point array (each voxel's points stored together) and a kd-tree
/// over their centroids. The index does not own the points: queries take the array it was
/// built for (see [`VoxelIndex::voxel_major`]).
#[derive(Debug)]
pub struct VoxelIndex {
    centroids: Vec<[f64; 3]>,
    /// Voxel of each point (non-decreasing).
    voxel_of: Vec<u32>,
    /// Points of voxel `v`: `first_point[v]..first_point[v + 1]`.
    first_point: Vec<u32>,
    /// Largest distance of a point from its voxel's centroid, per voxel (m).
    offset_m: Vec<f64>,
    /// Largest of `offset_m`.
    max_offset_m: f64,
    tree: ImmutableKdTree<f64, 3>,
}

/// Integer coordinates of a voxel.
pub type VoxelKey = (i64, i64, i64);

/// Integer voxel key of `p` for voxel edge `voxel_m`.
#[inline]
pub fn voxel_key(p: &[f64; 3], voxel_m: f64) -> VoxelKey {
    key_with_inverse(p, 1.0 / voxel_m)
}

/// [`voxel_key`] with the inverse edge precomputed (a multiplication instead of a division
/// per coordinate; hashing millions of points per scale, it shows).
#[inline]
fn key_with_inverse(p: &[f64; 3], inverse_voxel_m: f64) -> VoxelKey {
    (
        floor_to_i64(p[0] * inverse_voxel_m),
        floor_to_i64(p[1] * inverse_voxel_m),
        floor_to_i64(p[2] * inverse_voxel_m),
    )
}

/// `x.floor() as i64` (saturating, NaN to 0) without a call to libm's `floor`, which the
/// x86-64 baseline has no instruction for: truncate, then step down below a negative
/// non-integer.
#[inline]
fn floor_to_i64(x: f64) -> i64 {
    let truncated = x as i64;
    truncated.saturating_sub(i64::from((truncated as f64) > x))
}

/// Voxel keys in order of first occurrence, with the running sum and count of each.
#[derive(Default)]
struct VoxelSums {
    slot_of_key: FxHashMap<VoxelKey, u32>,
    keys: Vec<VoxelKey>,
    sums: Vec<(Vector3<f64>, u32)>,
    /// The last key added and its slot: consecutive points often share a voxel (always
    /// within a voxel-major cloud), and then the hash lookup is skipped.
    last: Option<(VoxelKey, u32)>,
}

impl VoxelSums {
    /// Room for `voxels` voxels without a rehash.
    fn with_capacity(voxels: usize) -> Self {
        Self {
            slot_of_key: FxHashMap::with_capacity_and_hasher(voxels, Default::default()),
            keys: Vec::with_capacity(voxels),
            sums: Vec::with_capacity(voxels),
            last: None,
        }
    }

    /// Adds a point, returning its voxel's slot.
    #[inline]
    fn add(&mut self, key: VoxelKey, p: Vector3<f64>, count: u32) -> u32 {
        let slot = match self.last {
            Some((last_key, slot)) if last_key == key => slot,
            _ => {
                let slot = *self.slot_of_key.entry(key).or_insert_with(|| {
                    self.keys.push(key);
                    self.sums.push((Vector3::zeros(), 0));
                    (self.sums.len() - 1) as u32
                });
                self.last = Some((key, slot));
                slot
            }
        };
        let entry = &mut self.sums[slot as usize];
        entry.0 += p;
        entry.1 += count;
        slot
    }

    fn centroids(&self) -> Vec<Vector3<f64>> {
        self.sums.iter().map(|(sum, n)| sum / *n as f64).collect()
    }
}

/// Centroid of each occupied voxel of edge `voxel_m`, in order of first occurrence.
pub fn voxel_centroids(points: &[Vector3<f64>], voxel_m: f64) -> Vec<Vector3<f64>> {
    // At most one voxel per point: room for all of them spares the rehashes of a growing
    // table (a frame is small enough that the bound costs little memory).
    let mut voxels = VoxelSums::with_capacity(points.len());
    let inverse_voxel_m = 1.0 / voxel_m;
    for p in points {
        voxels.add(key_with_inverse(&(*p).into(), inverse_voxel_m), *p, 1);
    }
    voxels.centroids()
}

/// Large clouds are hashed in this many fixed parts, merged in order, whatever the thread
/// count: serial and parallel runs give bit-identical centroids.
const HASH_PARTS: usize = 8;

/// The occupied voxels of a cloud, numbered (slots) in order of first occurrence.
#[derive(Debug)]
pub struct VoxelSlots {
    /// Slot of each point.
    pub slot_of: Vec<u32>,
    /// Centroid of each slot's points.
    pub centroids: Vec<Vector3<f64>>,
    /// Points in each slot.
    pub counts: Vec<u32>,
}

/// The voxel slot of every point, the centroid and the point count of each occupied voxel,
/// the cloud hashed in parts in parallel. The centroids may differ in the last bits from one
/// serial pass over the points (the sums are added part by part).
pub fn voxel_slots_in_parts(
    points: &[[f64; 3]],
    voxel_m: f64,
    parallelism: Parallelism,
) -> VoxelSlots {
    let part_len = points.len().div_ceil(HASH_PARTS).max(1);
    let parts: Vec<&[[f64; 3]]> = points.chunks(part_len).collect();
    let hashed = map_indexed(parts.len(), parallelism, |k| {
        let mut voxels = VoxelSums::default();
        let slots: Vec<u32> = parts[k]
            .iter()
            .map(|p| voxels.add(key_with_inverse(p, 1.0 / voxel_m), Vector3::from(*p), 1))
            .collect();
        (slots, voxels)
    });
    // Parts in order, each part's voxels in its order of first occurrence: the global order
    // of first occurrence.
    let mut merged = VoxelSums::default();
    let global_of_local: Vec<Vec<u32>> = hashed
        .iter()
        .map(|(_, part)| {
            (part.keys.iter().zip(&part.sums))
                .map(|(&key, &(sum, n))| merged.add(key, sum, n))
                .collect()
        })
        .collect();
    let slots = map_indexed(points.len(), parallelism, |i| {
        let (k, local) = (i / part_len, i % part_len);
        global_of_local[k][hashed[k].0[local] as usize]
    });
    VoxelSlots {
        slot_of: slots,
        centroids: merged.centroids(),
        counts: merged.sums.iter().map(|&(_, n)| n).collect(),
    }
}

/// Spreads the low 21 bits of `x` to every third bit (bits 0, 3, 6, ...).
fn spread_3(x: u64) -> u64 {
    let mut x = x & 0x1f_ffff;
    x = (x | (x << 32)) & 0x001f_0000_0000_ffff;
    x = (x | (x << 16)) & 0x001f_0000_ff00_00ff;
    x = (x | (x << 8)) & 0x100f_00f0_0f00_f00f;
    x = (x | (x << 4)) & 0x10c3_0c30_c30c_30c3;
    (x | (x << 2)) & 0x1249_2492_4924_9249
}

/// The rank of each voxel (given by its centroid) in Z-order (Morton order) of its grid
/// coordinates, ties (coordinates beyond 21 bits of span) by slot. In a cloud stored in first
/// occurrence order, the voxels of one neighbourhood lie far apart: the first frame's scan
/// lines come first. In Z-order a radius query reads a few runs of memory, and kernels taken
/// in the cloud's order (see `ScaleCloud::sample_kernels`) share their neighbours' cache
/// lines with the kernels before them.
fn z_order_ranks(centroids: &[Vector3<f64>], voxel_m: f64) -> Vec<u32> {
    let keys: Vec<VoxelKey> = centroids
        .iter()
        .map(|c| voxel_key(&(*c).into(), voxel_m))
        .collect();
    let low = keys.iter().fold((i64::MAX, i64::MAX, i64::MAX), |m, k| {
        (m.0.min(k.0), m.1.min(k.1), m.2.min(k.2))
    });
    let code = |k: &VoxelKey| {
        let axis = |x: i64, low: i64| spread_3(x.saturating_sub(low).min(0x1f_ffff) as u64);
        axis(k.0, low.0) | axis(k.1, low.1) << 1 | axis(k.2, low.2) << 2
    };
    // Each code computed once, not in every comparison of the sort.
    let mut coded: Vec<(u64, u32)> = (keys.iter().zip(0u32..))
        .map(|(key, slot)| (code(key), slot))
        .collect();
    coded.sort_unstable();
    let mut rank = vec![0u32; centroids.len()];
    for (r, &(_, slot)) in coded.iter().enumerate() {
        rank[slot as usize] = r as u32;
    }
    rank
}

/// A cloud put in voxel-major order by [`VoxelIndex::voxel_major`].
#[derive(Debug)]
pub struct VoxelMajor {
    /// The index over [`Self::points`].
    pub index: VoxelIndex,
    /// Entry `k` is the input position of the point stored at position `k`.
    pub order: Vec<u32>,
    /// The input points in that order (voxel after voxel): the array queries take.
    pub points: Vec<[f64; 3]>,
}

impl VoxelIndex {
    /// Indexes `points` by voxel of edge `voxel_m` and returns the index with the points put
    /// in the order it is built on (voxel-major) and that order. Voxels come in Z-order of
    /// their grid coordinates (see [`z_order_ranks`]); within a voxel the points keep their
    /// input order (so frame-major input stays frame-ordered per voxel).
    ///
    /// # Panics
    /// If there are more than `u32::MAX` points.
    pub fn voxel_major(points: &[[f64; 3]], voxel_m: f64, parallelism: Parallelism) -> VoxelMajor {
        assert!(u32::try_from(points.len()).is_ok(), "too many points");
        let VoxelSlots {
            slot_of,
            centroids,
            counts,
        } = voxel_slots_in_parts(points, voxel_m, parallelism);
        // Voxels near in space are stored near in memory (see `z_order_ranks`).
        let rank = z_order_ranks(&centroids, voxel_m);
        let mut by_rank = vec![[0.0; 3]; centroids.len()];
        for (slot, centroid) in centroids.iter().enumerate() {
            by_rank[rank[slot] as usize] = (*centroid).into();
        }
        let centroids = by_rank;
        let slot_of = map_indexed(slot_of.len(), parallelism, |i| rank[slot_of[i] as usize]);
        // Counting sort by voxel: where each voxel's points start.
        let mut first_point = vec![0u32; centroids.len() + 1];
        for (slot, &count) in counts.iter().enumerate() {
            first_point[rank[slot] as usize + 1] = count;
        }
        for v in 0..centroids.len() {
            first_point[v + 1] += first_point[v];
        }
        // The offsets below then read each voxel's points in memory order.
        let grouped = group_by_voxel(points, &slot_of, &first_point, parallelism);
        drop(slot_of);
        let (order, sorted, voxel_of) = (grouped.order, grouped.points, grouped.voxel_of);
        let tree = ImmutableKdTree::new_from_slice(&centroids);
        let mut index = Self {
            centroids,
            voxel_of,
            first_point,
            offset_m: Vec::new(),
            max_offset_m: 0.0,
            tree,
        };
        index.refresh_offsets(&sorted, parallelism);
        VoxelMajor {
            index,
            order,
            points: sorted,
        }
    }

    /// After the points of `points` (the voxel-major array of this index) have moved, each
    /// voxel's offset is measured again from its centroid as built, so queries stay exact
    /// over the moved points (the voxels keep their points and the kd-tree its centroids;
    /// only the offsets grow with the motion).
    pub fn refresh_offsets(&mut self, points: &[[f64; 3]], parallelism: Parallelism) {
        assert_eq!(
            points.len(),
            self.voxel_of.len(),
            "the array the index was built on"
        );
        let offset_sq = map_indexed(self.centroids.len(), parallelism, |v| {
            self.points_of(v)
                .map(|i| distance_sq(&points[i], &self.centroids[v]))
                .fold(0.0, f64::max)
        });
        (self.offset_m, self.max_offset_m) = offsets_with_slack(offset_sq);
    }

    /// Mean of each voxel's points in `points` (the voxel-major array of this index): the
    /// centroids at the points' current positions.
    pub fn point_means(&self, points: &[[f64; 3]], parallelism: Parallelism) -> Vec<[f64; 3]> {
        map_indexed(self.centroids.len(), parallelism, |v| {
            let range = self.points_of(v);
            let count = range.len().max(1) as f64;
            let sum = range.fold(Vector3::zeros(), |sum: Vector3<f64>, i| {
                sum + Vector3::from(points[i])
            });
            (sum / count).into()
        })
    }

    /// Centroid of each occupied voxel (as built).
    pub fn centroids(&self) -> &[[f64; 3]] {
        &self.centroids
    }

    /// Voxel of point `i`.
    #[inline]
    pub fn voxel_of(&self, i: usize) -> usize {
        self.voxel_of[i] as usize
    }

    /// Points of voxel `v`.
    #[inline]
    pub fn points_of(&self, v: usize) -> std::ops::Range<usize> {
        self.first_point[v] as usize..self.first_point[v + 1] as usize
    }

    /// Appends to `out` the index of every point of `points` (the array this index was built
    /// on) within `radius_m` of `center` that lies in a voxel `keep_voxel` accepts; ascending
    /// within a voxel, voxels in no particular order.
    pub fn within(
        &self,
        points: &[[f64; 3]],
        center: &[f64; 3],
        radius_m: f64,
        keep_voxel: impl Fn(usize) -> bool,
        out: &mut Vec<usize>,
    ) {
        let reach = radius_m + self.max_offset_m;
        let radius_sq = radius_m * radius_m;
        for voxel in self
            .tree
            .within_unsorted::<SquaredEuclidean>(center, reach * reach)
        {
            let v = voxel.item as usize;
            let to_centroid_m = voxel.distance.sqrt();
            if to_centroid_m > radius_m + self.offset_m[v] || !keep_voxel(v) {
                continue;
            }
            let range = self.points_of(v);
            if to_centroid_m + self.offset_m[v] <= radius_m {
                // The whole voxel lies inside the ball.
                out.extend(range);
            } else {
                out.extend(range.filter(|&i| distance_sq(&points[i], center) <= radius_sq));
            }
        }
    }
}

/// Per-voxel offsets (m) from their squared values, with a hair of slack that covers the
/// rounding of the distance computations, and the largest of them.
fn offsets_with_slack(offset_sq: Vec<f64>) -> (Vec<f64>, f64) {
    let offset_m: Vec<f64> = offset_sq
        .into_iter()
        .map(|d| d.sqrt() * (1.0 + 1e-9) + 1e-12)
        .collect();
    let max_offset_m = offset_m.iter().copied().fold(0.0, f64::max);
    (offset_m, max_offset_m)
}

#[inline]
fn distance_sq(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng, rngs::StdRng};

    fn brute_force(points: &[[f64; 3]], center: &[f64; 3], radius_m: f64) -> Vec<usize> {
        (0..points.len())
            .filter(|&i| distance_sq(&points[i], center) <= radius_m * radius_m)
            .collect()
    }

    #[test]
    fn floor_matches_the_standard_floor() {
        let special = [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            -1.0 - f64::EPSILON,
            1e18,
            -1e18,
            9.3e18,
            -9.3e18,
            1e300,
            -1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            f64::MIN_POSITIVE,
            -f64::MIN_POSITIVE,
        ];
        let mut rng = StdRng::seed_from_u64(3);
        let random = (0..100_000).map(|_| rng.random_range(-1e4..1e4));
        for x in special.into_iter().chain(random) {
            assert_eq!(floor_to_i64(x), x.floor() as i64, "{x}");
        }
    }

    fn voxel_major(points: &[[f64; 3]], voxel_m: f64) -> (Vec<[f64; 3]>, VoxelIndex) {
        let built = VoxelIndex::voxel_major(points, voxel_m, Parallelism::Serial);
        let gathered: Vec<[f64; 3]> = built.order.iter().map(|&i| points[i as usize]).collect();
        assert_eq!(built.points, gathered, "the points in the order");
        (built.points, built.index)
    }

    #[test]
    fn radius_queries_match_brute_force() {
        let mut rng = StdRng::seed_from_u64(7);
        // Clustered points: a wavy sheet plus scattered outliers.
        let points: Vec<[f64; 3]> = (0..3000)
            .map(|i| {
                let (x, y): (f64, f64) = (rng.random_range(-3.0..3.0), rng.random_range(-3.0..3.0));
                let z = if i % 10 == 0 {
                    rng.random_range(-2.0..2.0)
                } else {
                    0.3 * (x * 1.3).sin() + rng.random_range(-0.02..0.02)
                };
                [x, y, z]
            })
            .collect();
        for voxel_m in [0.05, 0.2, 0.7] {
            let (sorted, index) = voxel_major(&points, voxel_m);
            for q in 0..40 {
                let center = sorted[q * 61];
                for radius_m in [0.1, 0.45, 1.5] {
                    let mut got = Vec::new();
                    index.within(&sorted, &center, radius_m, |_| true, &mut got);
                    got.sort_unstable();
                    assert_eq!(got, brute_force(&sorted, &center, radius_m));
                }
            }
        }
    }

    #[test]
    fn queries_stay_exact_over_moved_points_once_offsets_are_refreshed() {
        let mut rng = StdRng::seed_from_u64(11);
        let points: Vec<[f64; 3]> = (0..2000)
            .map(|_| {
                let (x, y): (f64, f64) = (rng.random_range(-2.0..2.0), rng.random_range(-2.0..2.0));
                [x, y, 0.2 * (x * 2.0).cos() + rng.random_range(-0.01..0.01)]
            })
            .collect();
        let (sorted, mut index) = voxel_major(&points, 0.2);
        // Every point moves by up to 9 cm, some across voxel borders.
        let moved: Vec<[f64; 3]> = sorted
            .iter()
            .map(|p| {
                let d = 0.09 / 3f64.sqrt();
                [
                    p[0] + rng.random_range(-d..d),
                    p[1] + rng.random_range(-d..d),
                    p[2] + rng.random_range(-d..d),
                ]
            })
            .collect();
        index.refresh_offsets(&moved, Parallelism::Rayon);
        for q in 0..50 {
            let center = moved[q * 37];
            for radius_m in [0.1, 0.4, 1.0] {
                let mut got = Vec::new();
                index.within(&moved, &center, radius_m, |_| true, &mut got);
                got.sort_unstable();
                assert_eq!(
                    got,
                    brute_force(&moved, &center, radius_m),
                    "radius {radius_m}"
                );
            }
        }
        // The means follow the moved points.
        let means = index.point_means(&moved, Parallelism::Serial);
        for (v, mean) in means.iter().enumerate() {
            let range = index.points_of(v);
            let n = range.len() as f64;
            let x = range.map(|i| moved[i][0]).sum::<f64>() / n;
            assert!((mean[0] - x).abs() < 1e-12);
        }
    }

    #[test]
    fn voxel_major_order_is_a_stable_grouping_of_the_points() {
        let points: Vec<[f64; 3]> = (0..500)
            .map(|i| {
                [
                    (i % 17) as f64 * 0.13,
                    (i % 5) as f64 * 0.31,
                    (i / 50) as f64 * 0.2,
                ]
            })
            .collect();
        let order = VoxelIndex::voxel_major(&points, 0.5, Parallelism::Serial).order;
        let mut seen = vec![false; points.len()];
        order.iter().for_each(|&i| seen[i as usize] = true);
        assert!(seen.iter().all(|&s| s), "a permutation");
        let (sorted, index) = voxel_major(&points, 0.5);
        for v in 0..index.centroids().len() {
            let range = index.points_of(v);
            assert!(order[range.clone()].windows(2).all(|w| w[0] < w[1]));
            for i in range {
                assert_eq!(index.voxel_of(i), v);
                assert_eq!(
                    voxel_key(&sorted[i], 0.5),
                    voxel_key(&sorted[index.points_of(v).start], 0.5)
                );
            }
        }
    }

    /// One serial pass over the points: the reference of [`voxel_slots_in_parts`].
    fn voxel_slots(
        points: impl Iterator<Item = [f64; 3]>,
        voxel_m: f64,
    ) -> (Vec<u32>, Vec<Vector3<f64>>) {
        let mut voxels = VoxelSums::default();
        let slots = points
            .map(|p| voxels.add(key_with_inverse(&p, 1.0 / voxel_m), Vector3::from(p), 1))
            .collect();
        (slots, voxels.centroids())
    }

    #[test]
    fn slots_in_parts_match_the_serial_slots() {
        let points: Vec<[f64; 3]> = (0..5000)
            .map(|i| {
                let a = i as f64 * 0.37;
                [a.sin() * 4.0, (a * 0.7).cos() * 3.0, (i % 13) as f64 * 0.05]
            })
            .collect();
        let (serial_slots, serial_centroids) = voxel_slots(points.iter().copied(), 0.3);
        let parts = voxel_slots_in_parts(&points, 0.3, Parallelism::Serial);
        let rayon = voxel_slots_in_parts(&points, 0.3, Parallelism::Rayon);
        let (parts_slots, parts_centroids) = (&parts.slot_of, &parts.centroids);
        assert_eq!(&serial_slots, parts_slots);
        assert_eq!(parts_slots, &rayon.slot_of);
        assert_eq!(parts_centroids, &rayon.centroids);
        assert_eq!(parts.counts, rayon.counts);
        for (slot, &count) in parts.counts.iter().enumerate() {
            let members = serial_slots.iter().filter(|&&s| s as usize == slot).count();
            assert_eq!(count as usize, members);
        }
        for (a, b) in serial_centroids.iter().zip(parts_centroids) {
            assert!((a - b).norm() < 1e-12);
        }
    }

    #[test]
    fn z_order_interleaves_the_coordinates_bits() {
        let spread_by_loop = |x: u64| (0..21).fold(0, |out, b| out | ((x >> b) & 1) << (3 * b));
        for x in [
            0, 1, 2, 3, 5, 0x1f_ffff, 0x15_5555, 0x0a_aaaa, 123_456, 0x3f_ffff,
        ] {
            assert_eq!(spread_3(x), spread_by_loop(x & 0x1f_ffff), "x = {x:#x}");
        }
        // Eight voxels of a 2 x 2 x 2 block: x varies fastest, then y, then z.
        let voxel_m = 0.5;
        let centroids: Vec<Vector3<f64>> = [(1, 1, 1), (0, 0, 0), (1, 0, 0), (0, 1, 1)]
            .iter()
            .map(|&(x, y, z)| {
                Vector3::new(x as f64 + 0.5, y as f64 + 0.5, z as f64 + 0.5) * voxel_m
            })
            .collect();
        // Codes: (1,1,1) -> 7, (0,0,0) -> 0, (1,0,0) -> 1, (0,1,1) -> 6.
        assert_eq!(z_order_ranks(&centroids, voxel_m), vec![3, 0, 1, 2]);
    }

    #[test]
    fn empty_cloud_answers_nothing() {
        let index = VoxelIndex::voxel_major(&[], 0.2, Parallelism::Serial).index;
        let mut out = Vec::new();
        index.within(&[], &[0.0; 3], 1.0, |_| true, &mut out);
        assert!(out.is_empty());
    }
}
