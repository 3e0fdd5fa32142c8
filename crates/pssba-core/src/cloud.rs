//! The world cloud of one scale (DESIGN steps 1-3): per-frame voxel downsampling in each
//! frame's own lidar coordinates (independent of the poses), the world points, a kd-tree,
//! and PCA normals.

use crate::geometry::Pose;
use crate::normals::{estimate_normals, orient_towards};
use crate::parallel::{Parallelism, map_indexed};
use kiddo::ImmutableKdTree;
use nalgebra::Vector3;
use rustc_hash::FxHashMap;

/// Normal neighbourhoods are searched within this many downsampling voxels.
const NORMAL_RADIUS_PER_VOXEL: f64 = 3.0;

/// Integer coordinates of a voxel.
pub type VoxelKey = (i64, i64, i64);

/// Integer voxel key of `p` for voxel edge `voxel_m`.
#[inline]
pub fn voxel_key(p: &Vector3<f64>, voxel_m: f64) -> VoxelKey {
    (
        (p.x / voxel_m).floor() as i64,
        (p.y / voxel_m).floor() as i64,
        (p.z / voxel_m).floor() as i64,
    )
}

/// The voxel slot of every point (slots numbered in order of first occurrence) and the
/// centroid of each occupied voxel.
fn voxel_slots(
    points: impl Iterator<Item = Vector3<f64>>,
    voxel_m: f64,
) -> (Vec<usize>, Vec<Vector3<f64>>) {
    let mut slot_of_key: FxHashMap<VoxelKey, usize> = FxHashMap::default();
    let mut sums: Vec<(Vector3<f64>, u32)> = Vec::new();
    let slots = points
        .map(|p| {
            let slot = *slot_of_key
                .entry(voxel_key(&p, voxel_m))
                .or_insert_with(|| {
                    sums.push((Vector3::zeros(), 0));
                    sums.len() - 1
                });
            sums[slot].0 += p;
            sums[slot].1 += 1;
            slot
        })
        .collect();
    let centroids = sums.into_iter().map(|(sum, n)| sum / n as f64).collect();
    (slots, centroids)
}

/// Centroids of the occupied voxels of one frame (order: first occurrence), which lowers the
/// range noise and bounds the points per kernel.
pub fn voxel_downsample(points: &[Vector3<f64>], voxel_m: f64) -> Vec<Vector3<f64>> {
    voxel_slots(points.iter().copied(), voxel_m).1
}

/// [`voxel_slots`] of the merged all-frame cloud.
fn merge_voxels(points_world: &[[f64; 3]], voxel_m: f64) -> (Vec<usize>, Vec<Vector3<f64>>) {
    voxel_slots(points_world.iter().map(|p| Vector3::from(*p)), voxel_m)
}

/// All frames' downsampled points at one scale, in world and lidar coordinates.
#[derive(Debug)]
pub struct ScaleCloud {
    /// World coordinates (m), as the kd-tree stores them.
    pub points_world: Vec<[f64; 3]>,
    /// The same points in their own lidar frame (m).
    pub points_lidar: Vec<Vector3<f64>>,
    /// Frame index of each point.
    pub frame_of: Vec<u32>,
    /// Oriented PCA normal of each point (`None` where PCA failed).
    pub normals: Vec<Option<Vector3<f64>>>,
    /// kd-tree over `points_world` (items are indices).
    pub tree: ImmutableKdTree<f64, 3>,
}

impl ScaleCloud {
    /// Builds the cloud from per-frame lidar points (already finite) and current poses.
    pub fn build(
        frames: &[Vec<Vector3<f64>>],
        poses: &[Pose],
        downsample_m: f64,
        normal_neighbours: usize,
        parallelism: Parallelism,
    ) -> Self {
        let downsampled = map_indexed(frames.len(), parallelism, |k| {
            voxel_downsample(&frames[k], downsample_m)
        });
        let total: usize = downsampled.iter().map(Vec::len).sum();
        let mut points_world = Vec::with_capacity(total);
        let mut points_lidar = Vec::with_capacity(total);
        let mut frame_of = Vec::with_capacity(total);
        for (k, points) in downsampled.into_iter().enumerate() {
            for p in points {
                points_world.push(poses[k].apply(&p).into());
                points_lidar.push(p);
                frame_of.push(k as u32);
            }
        }
        let tree = ImmutableKdTree::new_from_slice(&points_world);
        // One k-nearest search per occupied voxel of the merged cloud (its centroid stands in
        // for every point in it), over all frames' points; each point orients the shared
        // normal towards its own sensor.
        let (slot_of, centroids) = merge_voxels(&points_world, downsample_m);
        let queries: Vec<[f64; 3]> = centroids.into_iter().map(Into::into).collect();
        let shared = estimate_normals(
            &queries,
            &points_world,
            &tree,
            normal_neighbours,
            NORMAL_RADIUS_PER_VOXEL * downsample_m,
            parallelism,
        );
        let normals = map_indexed(points_world.len(), parallelism, |i| {
            let origin = poses[frame_of[i] as usize].translation;
            shared[slot_of[i]].map(|n| orient_towards(n, &Vector3::from(points_world[i]), &origin))
        });
        Self {
            points_world,
            points_lidar,
            frame_of,
            normals,
            tree,
        }
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.points_world.len()
    }

    /// True when the cloud holds no point.
    pub fn is_empty(&self) -> bool {
        self.points_world.is_empty()
    }

    /// World point `i` as a vector.
    #[inline]
    pub fn world(&self, i: usize) -> Vector3<f64> {
        Vector3::from(self.points_world[i])
    }

    /// Kernel sampling (DESIGN step 3): a voxel grid of edge `gamma_m` over the world cloud,
    /// one kernel per occupied voxel: the real point nearest the voxel's centroid.
    pub fn sample_kernels(&self, gamma_m: f64) -> Vec<usize> {
        let (slot_of, centroids) = merge_voxels(&self.points_world, gamma_m);
        let mut nearest = vec![(f64::INFINITY, 0usize); centroids.len()];
        for (i, &slot) in slot_of.iter().enumerate() {
            let d = (self.world(i) - centroids[slot]).norm_squared();
            if d < nearest[slot].0 {
                nearest[slot] = (d, i);
            }
        }
        nearest.into_iter().map(|(_, i)| i).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn downsample_averages_each_voxel() {
        let pts = vec![
            Vector3::new(0.1, 0.1, 0.1),
            Vector3::new(0.3, 0.3, 0.3),
            Vector3::new(1.5, 0.0, 0.0),
        ];
        let out = voxel_downsample(&pts, 1.0);
        assert_eq!(out.len(), 2);
        assert!((out[0] - Vector3::new(0.2, 0.2, 0.2)).norm() < 1e-12);
    }
}
