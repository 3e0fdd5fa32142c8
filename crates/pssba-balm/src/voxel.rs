//! Adaptive voxelisation (BALM2 section "adaptive voxelization"): a world grid of root voxels,
//! each cut into an octree until its points lie on a plane. A voxel is kept as a plane when
//! `lambda_min / lambda_mid` of its world covariance is below the layer's threshold and it
//! holds enough points from enough frames; otherwise it is cut in eight (down to
//! `octree_layers` layers in total, root included) or, on the deepest layer, dropped.

use crate::BalmConfig;
use crate::cluster::{PointCluster, sorted_eigen};
use nalgebra::{Matrix3, Vector3};
use pssba_core::geometry::Pose;
use pssba_core::parallel::{Parallelism, map_indexed};
use rustc_hash::FxHashMap;
use serde::Serialize;

/// A plane voxel: the point cluster of every frame that sees it, in frame order.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PlaneVoxel {
    /// Octree layer, 0 = root voxel.
    pub layer: usize,
    /// `(frame, cluster)` for each frame with points in the voxel, frames ascending.
    pub clusters: Vec<(usize, PointCluster)>,
}

/// The outcome of one voxelisation.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Voxelisation {
    /// Plane voxels, ordered by root voxel key, then octree order (deterministic).
    pub planes: Vec<PlaneVoxel>,
    /// Voxels (any layer) that were neither planes nor cut: too few points or frames, or not
    /// planar on the deepest layer.
    pub dropped: usize,
}

impl Voxelisation {
    /// Plane voxels on each layer (index = layer).
    pub fn planes_per_layer(&self, layers: usize) -> Vec<usize> {
        let mut counts = vec![0; layers];
        for voxel in &self.planes {
            counts[voxel.layer.min(layers - 1)] += 1;
        }
        counts
    }
}

/// A point reference: (frame, index in the frame).
type PointRef = (u32, u32);

/// Voxelises `frames_lidar` (finite points only) at `world_from_lidar`.
pub fn voxelise(
    frames_lidar: &[Vec<Vector3<f64>>],
    world_from_lidar: &[Pose],
    config: &BalmConfig,
    parallelism: Parallelism,
) -> Voxelisation {
    let points_world: Vec<Vec<Vector3<f64>>> = map_indexed(frames_lidar.len(), parallelism, |k| {
        frames_lidar[k]
            .iter()
            .map(|p| world_from_lidar[k].apply(p))
            .collect()
    });
    let mut roots: FxHashMap<[i64; 3], Vec<PointRef>> = FxHashMap::default();
    for (frame, points) in points_world.iter().enumerate() {
        for (index, p) in points.iter().enumerate() {
            let key = (p / config.voxel_size_m).map(|v| v.floor() as i64);
            roots
                .entry([key.x, key.y, key.z])
                .or_default()
                .push((frame as u32, index as u32));
        }
    }
    let mut keys: Vec<[i64; 3]> = roots.keys().copied().collect();
    keys.sort_unstable();
    let cutter = Cutter {
        frames_lidar,
        points_world: &points_world,
        config,
    };
    let per_root = map_indexed(keys.len(), parallelism, |k| {
        let corner = Vector3::from(keys[k].map(|v| v as f64)) * config.voxel_size_m;
        let mut out = Voxelisation::default();
        cutter.cut(&roots[&keys[k]], corner, config.voxel_size_m, 0, &mut out);
        out
    });
    per_root
        .into_iter()
        .fold(Voxelisation::default(), |mut all, mut one| {
            all.planes.append(&mut one.planes);
            all.dropped += one.dropped;
            all
        })
}

/// The recursive octree cut over shared, read-only point data.
struct Cutter<'a> {
    frames_lidar: &'a [Vec<Vector3<f64>>],
    points_world: &'a [Vec<Vector3<f64>>],
    config: &'a BalmConfig,
}

impl Cutter<'_> {
    fn world(&self, (frame, index): PointRef) -> &Vector3<f64> {
        &self.points_world[frame as usize][index as usize]
    }

    /// Tests the voxel with lower corner `corner` and edge `size_m`; keeps, cuts or drops it.
    fn cut(
        &self,
        points: &[PointRef],
        corner: Vector3<f64>,
        size_m: f64,
        layer: usize,
        out: &mut Voxelisation,
    ) {
        let frames_seen = 1 + points.windows(2).filter(|w| w[0].0 != w[1].0).count();
        // Children hold subsets: too few points or frames can only get worse below.
        if points.len() < self.config.min_points_per_voxel
            || frames_seen < self.config.min_frames_per_voxel
        {
            out.dropped += 1;
            return;
        }
        let deepest = layer + 1 >= self.config.octree_layers;
        let threshold = if deepest {
            self.config.plane_eigen_ratio_deepest
        } else {
            self.config.plane_eigen_ratio
        };
        let centre = corner + Vector3::repeat(0.5 * size_m);
        let (values, _) = sorted_eigen(&self.covariance(points, &centre));
        if values[0] < threshold * values[1] {
            out.planes.push(PlaneVoxel {
                layer,
                clusters: self.clusters(points),
            });
            return;
        }
        if deepest {
            out.dropped += 1;
            return;
        }
        let mut children: [Vec<PointRef>; 8] = Default::default();
        for &r in points {
            let p = self.world(r);
            let octant = usize::from(p.x >= centre.x)
                | usize::from(p.y >= centre.y) << 1
                | usize::from(p.z >= centre.z) << 2;
            children[octant].push(r);
        }
        let half = 0.5 * size_m;
        for (octant, child) in children.iter().enumerate() {
            if child.is_empty() {
                continue;
            }
            let offset = Vector3::new(
                (octant & 1) as f64,
                ((octant >> 1) & 1) as f64,
                ((octant >> 2) & 1) as f64,
            ) * half;
            self.cut(child, corner + offset, half, layer + 1, out);
        }
    }

    /// World covariance of `points`, computed about `centre` for accuracy.
    fn covariance(&self, points: &[PointRef], centre: &Vector3<f64>) -> Matrix3<f64> {
        let n = points.len() as f64;
        let mean = points
            .iter()
            .fold(Vector3::zeros(), |acc, &r| acc + (self.world(r) - centre))
            / n;
        points.iter().fold(Matrix3::zeros(), |acc, &r| {
            let d = self.world(r) - centre - mean;
            acc + d * d.transpose()
        }) / n
    }

    /// One cluster per frame; `points` is ordered by frame, so each frame's run is contiguous.
    fn clusters(&self, points: &[PointRef]) -> Vec<(usize, PointCluster)> {
        points
            .chunk_by(|a, b| a.0 == b.0)
            .map(|run| {
                let frame = run[0].0 as usize;
                let lidar = &self.frames_lidar[frame];
                let cluster =
                    PointCluster::from_points(run.iter().map(|&(_, i)| &lidar[i as usize]));
                (frame, cluster)
            })
            .collect()
    }
}
