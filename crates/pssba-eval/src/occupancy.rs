//! Map sharpness as voxel occupancy: the number of distinct voxels
//! `⌊(p + o) / v⌋` (component-wise floor, edge `v`, grid offset `o`) hit by
//! the points of a map. A better-registered (sharper) map occupies fewer
//! voxels. Because a thin surface lying on a grid plane can straddle two
//! voxel layers at one offset and fill one layer at another, the count is
//! averaged over several seeded sub-voxel grid offsets.

use nalgebra::{Isometry3, Point3, Vector3};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rustc_hash::FxHashSet;

use crate::EvalError;

/// Integer voxel coordinates.
type VoxelKey = (i64, i64, i64);

/// Outcome of one voxel count at one grid offset.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct VoxelCount {
    /// Number of distinct occupied voxels.
    pub occupied: usize,
    /// Points not counted: a non-finite coordinate, or a voxel index outside
    /// the `i64` range.
    pub skipped_points: usize,
}

/// Voxel occupancy averaged over grid offsets.
#[derive(Debug, Clone, PartialEq)]
pub struct OccupancyResult {
    /// `(1/K) Σ_k N(o_k)` over the `K` offsets.
    pub mean_voxels: f64,
    /// Smallest per-offset count.
    pub min: usize,
    /// Largest per-offset count.
    pub max: usize,
    /// `N(o_k)`, parallel to `offsets_m`.
    pub per_offset: Vec<usize>,
    /// The grid offsets `o_k` in metres; the first is `(0, 0, 0)`.
    pub offsets_m: Vec<[f64; 3]>,
    /// Voxel edge length `v` in metres.
    pub voxel_m: f64,
    /// Largest number of skipped points over the offsets (see
    /// [`VoxelCount::skipped_points`]).
    pub skipped_points: usize,
}

/// Number of distinct voxels `⌊(p + offset_m) / voxel_m⌋` occupied by the
/// points. Non-finite points are skipped.
///
/// Returns 0 if `voxel_m` is not finite and positive or `offset_m` is not
/// finite; use [`count_voxels`] to get a typed error and the skipped count.
pub fn occupied_voxels(
    points_world: impl Iterator<Item = Point3<f64>> + Clone,
    voxel_m: f64,
    offset_m: Vector3<f64>,
) -> usize {
    count_voxels(points_world, voxel_m, offset_m).map_or(0, |c| c.occupied)
}

/// Like [`occupied_voxels`], but with typed errors and the skipped count.
///
/// # Errors
/// [`EvalError::InvalidVoxelSize`] unless `voxel_m` is finite and > 0,
/// [`EvalError::NonFinite`] for a non-finite `offset_m`.
pub fn count_voxels(
    points_world: impl Iterator<Item = Point3<f64>>,
    voxel_m: f64,
    offset_m: Vector3<f64>,
) -> Result<VoxelCount, EvalError> {
    check_voxel(voxel_m)?;
    if !offset_m.iter().all(|c| c.is_finite()) {
        return Err(EvalError::NonFinite {
            what: "voxel grid offset",
            index: 0,
        });
    }
    let mut set = FxHashSet::default();
    Ok(count_into(&mut set, points_world, voxel_m, &offset_m))
}

/// Voxel occupancy of a point cloud, averaged over `n_offsets` grid offsets
/// (see [`sub_voxel_offsets`]).
///
/// # Errors
/// [`EvalError::InvalidVoxelSize`] unless `voxel_m` is finite and > 0,
/// [`EvalError::InvalidOffsetCount`] for `n_offsets == 0`.
pub fn occupancy_averaged(
    points: &[Point3<f64>],
    voxel_m: f64,
    n_offsets: usize,
    seed: u64,
) -> Result<OccupancyResult, EvalError> {
    average_over_offsets(points.iter().copied(), voxel_m, n_offsets, seed)
}

/// Voxel occupancy of the map `⋃_f { T_f · p : p ∈ frames[f] }` with
/// `T_f = world_from_lidar[f]`, averaged like [`occupancy_averaged`], without
/// building a merged copy of the map (points are transformed on the fly for
/// every offset).
///
/// # Errors
/// As [`occupancy_averaged`], plus [`EvalError::LengthMismatch`] if the frame
/// and pose counts differ and [`EvalError::NonFinite`] for a non-finite pose.
pub fn occupancy_of_frames(
    frames: &[Vec<Point3<f64>>],
    world_from_lidar: &[Isometry3<f64>],
    voxel_m: f64,
    n_offsets: usize,
    seed: u64,
) -> Result<OccupancyResult, EvalError> {
    if frames.len() != world_from_lidar.len() {
        return Err(EvalError::LengthMismatch {
            left_name: "frames",
            left: frames.len(),
            right_name: "world_from_lidar poses",
            right: world_from_lidar.len(),
        });
    }
    if let Some(index) = world_from_lidar.iter().position(|t| {
        !(t.translation.vector.iter().all(|c| c.is_finite())
            && t.rotation.coords.iter().all(|c| c.is_finite()))
    }) {
        return Err(EvalError::NonFinite {
            what: "world_from_lidar pose",
            index,
        });
    }
    let points = frames
        .iter()
        .zip(world_from_lidar)
        .flat_map(|(frame, pose)| frame.iter().map(move |p| pose * p));
    average_over_offsets(points, voxel_m, n_offsets, seed)
}

/// Deterministic grid offsets: `(0, 0, 0)` followed by `n_offsets − 1`
/// offsets drawn uniformly from `[0, voxel_m)³` with `StdRng::seed_from_u64
/// (seed)` (reproducible for the workspace-pinned `rand` version).
///
/// # Errors
/// As [`occupancy_averaged`].
pub fn sub_voxel_offsets(
    voxel_m: f64,
    n_offsets: usize,
    seed: u64,
) -> Result<Vec<Vector3<f64>>, EvalError> {
    check_voxel(voxel_m)?;
    if n_offsets == 0 {
        return Err(EvalError::InvalidOffsetCount { n_offsets });
    }
    let mut rng = StdRng::seed_from_u64(seed);
    // u ∈ [0, 1) but u·v may round up to v; clamp to keep o < v.
    let mut draw = || (rng.random::<f64>() * voxel_m).min(voxel_m.next_down());
    let mut offsets = Vec::with_capacity(n_offsets);
    offsets.push(Vector3::zeros());
    for _ in 1..n_offsets {
        offsets.push(Vector3::new(draw(), draw(), draw()));
    }
    Ok(offsets)
}

/// Shared implementation of the averaged counts over a re-iterable point source.
fn average_over_offsets(
    points: impl Iterator<Item = Point3<f64>> + Clone,
    voxel_m: f64,
    n_offsets: usize,
    seed: u64,
) -> Result<OccupancyResult, EvalError> {
    let offsets = sub_voxel_offsets(voxel_m, n_offsets, seed)?;
    let mut set = FxHashSet::default();
    let mut per_offset = Vec::with_capacity(offsets.len());
    let mut skipped_points = 0;
    for offset in &offsets {
        let count = count_into(&mut set, points.clone(), voxel_m, offset);
        per_offset.push(count.occupied);
        skipped_points = skipped_points.max(count.skipped_points);
    }
    let min = per_offset.iter().copied().min().unwrap_or(0);
    let max = per_offset.iter().copied().max().unwrap_or(0);
    let mean_voxels = per_offset.iter().sum::<usize>() as f64 / per_offset.len() as f64;
    Ok(OccupancyResult {
        mean_voxels,
        min,
        max,
        per_offset,
        offsets_m: offsets.iter().map(|o| [o.x, o.y, o.z]).collect(),
        voxel_m,
        skipped_points,
    })
}

/// Counts into a reusable set (cleared first); inputs already validated.
fn count_into(
    set: &mut FxHashSet<VoxelKey>,
    points: impl Iterator<Item = Point3<f64>>,
    voxel_m: f64,
    offset: &Vector3<f64>,
) -> VoxelCount {
    set.clear();
    let mut skipped_points = 0;
    for p in points {
        match voxel_key(&p, offset, voxel_m) {
            Some(key) => {
                set.insert(key);
            }
            None => skipped_points += 1,
        }
    }
    VoxelCount {
        occupied: set.len(),
        skipped_points,
    }
}

/// `⌊(p + o) / v⌋` per axis, or `None` if non-finite or outside `i64`.
fn voxel_key(p: &Point3<f64>, offset: &Vector3<f64>, voxel_m: f64) -> Option<VoxelKey> {
    // 2^63: the exclusive upper bound of i64, exactly representable as f64.
    const LIMIT: f64 = 9_223_372_036_854_775_808.0;
    let index = |c: f64, o: f64| {
        let f = ((c + o) / voxel_m).floor();
        // NaN/∞ fail the range test; otherwise `as` is exact (an integer in range).
        (-LIMIT..LIMIT).contains(&f).then_some(f as i64)
    };
    Some((
        index(p.x, offset.x)?,
        index(p.y, offset.y)?,
        index(p.z, offset.z)?,
    ))
}

/// Rejects non-positive or non-finite voxel sizes.
fn check_voxel(voxel_m: f64) -> Result<(), EvalError> {
    if voxel_m.is_finite() && voxel_m > 0.0 {
        Ok(())
    } else {
        Err(EvalError::InvalidVoxelSize { voxel_m })
    }
}
