//! The world cloud of one scale (DESIGN steps 1-3): per-frame voxel downsampling in each
//! frame's own lidar coordinates (independent of the poses, so a run reuses it while the
//! downsampling edge stays the same), the world points, a voxel index over the merged cloud,
//! and PCA normals.

use crate::geometry::Pose;
use crate::normals::{estimate_normals, orient_towards};
use crate::parallel::{Parallelism, map_indexed};
use crate::voxel_index::{VoxelIndex, voxel_centroids, voxel_slots_in_parts};
use nalgebra::Vector3;
use std::sync::Arc;

/// Normal neighbourhoods are searched within this many downsampling voxels.
const NORMAL_RADIUS_PER_VOXEL: f64 = 3.0;

/// Centroids of the occupied voxels of one frame (order: first occurrence), which lowers the
/// range noise and bounds the points per kernel.
pub fn voxel_downsample(points: &[Vector3<f64>], voxel_m: f64) -> Vec<Vector3<f64>> {
    voxel_centroids(points, voxel_m)
}

/// Every frame's points downsampled with voxel edge `voxel_m` (in its lidar frame), frame
/// after frame in one buffer that the clouds of the scales with this edge share.
#[derive(Debug, Clone)]
pub struct DownsampledFrames {
    /// Voxel edge (m).
    pub voxel_m: f64,
    /// Downsampled lidar-frame points, frame after frame.
    points: Arc<Vec<Vector3<f64>>>,
    /// Frame k's points are `points[first_of_frame[k]..first_of_frame[k + 1]]`.
    first_of_frame: Vec<usize>,
}

impl DownsampledFrames {
    /// Downsamples every frame.
    pub fn new(frames: &[Vec<Vector3<f64>>], voxel_m: f64, parallelism: Parallelism) -> Self {
        let per_frame = map_indexed(frames.len(), parallelism, |k| {
            voxel_downsample(&frames[k], voxel_m)
        });
        let first_of_frame = std::iter::once(0)
            .chain(per_frame.iter().scan(0, |end, points| {
                *end += points.len();
                Some(*end)
            }))
            .collect();
        Self {
            voxel_m,
            points: Arc::new(per_frame.concat()),
            first_of_frame,
        }
    }

    /// Frame `k`'s downsampled points.
    pub fn frame(&self, k: usize) -> &[Vector3<f64>] {
        &self.points[self.first_of_frame[k]..self.first_of_frame[k + 1]]
    }
}

/// All frames' downsampled points at one scale, in world and lidar coordinates.
#[derive(Debug)]
pub struct ScaleCloud {
    /// World coordinates (m). Points are stored voxel after voxel (of the downsampling edge,
    /// see [`VoxelIndex`]), each voxel's points in ascending frame order.
    pub points_world: Vec<[f64; 3]>,
    /// Frame index of each point.
    pub frame_of: Vec<u32>,
    /// The merged cloud by voxel of the downsampling edge, for neighbour queries.
    pub index: VoxelIndex,
    /// PCA normal of each voxel of `index`, unoriented (`None` where PCA failed); every point
    /// of the voxel shares it, oriented towards its own sensor by [`Self::normal`]. Kept per
    /// voxel rather than per point: 32 bytes a point, 300 MB over 1000 frames.
    voxel_normals: Vec<Option<Vector3<f64>>>,
    /// Per point, the sign that turns its voxel's normal towards the point's own sensor
    /// (+1 or -1; 0 where the voxel has no normal): one byte instead of a lookup of the
    /// frame's origin on every query, the hottest loop of the kernel extraction.
    normal_sign: Vec<i8>,
    /// Every frame's lidar points, frame after frame (the input order), shared with the
    /// [`DownsampledFrames`] the cloud was built from.
    lidar_frame_major: Arc<Vec<Vector3<f64>>>,
    /// Position in `lidar_frame_major` of each point. Lidar points are looked up when needed
    /// (kernels and residual points, a fraction of the cloud) instead of being reordered.
    source: Vec<u32>,
    /// Wall time of the normals (s), of [`Self::from_downsampled`].
    pub normals_s: f64,
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
        let downsampled = DownsampledFrames::new(frames, downsample_m, parallelism);
        Self::from_downsampled(&downsampled, poses, normal_neighbours, parallelism)
    }

    /// Builds the cloud from frames downsampled beforehand.
    pub fn from_downsampled(
        downsampled: &DownsampledFrames,
        poses: &[Pose],
        normal_neighbours: usize,
        parallelism: Parallelism,
    ) -> Self {
        let first_of_frame = &downsampled.first_of_frame;
        let frame_of_source = |i: usize| (first_of_frame.partition_point(|&o| o <= i) - 1) as u32;
        let lidar_frame_major = Arc::clone(&downsampled.points);
        let world_frame_major: Vec<[f64; 3]> =
            map_indexed(lidar_frame_major.len(), parallelism, |i| {
                poses[frame_of_source(i) as usize]
                    .apply(&lidar_frame_major[i])
                    .into()
            });
        // Voxel-major storage: a neighbour query then reads whole voxels in memory order.
        let downsample_m = downsampled.voxel_m;
        let (index, source) =
            VoxelIndex::voxel_major(&world_frame_major, downsample_m, parallelism);
        let points_world = map_indexed(source.len(), parallelism, |i| {
            world_frame_major[source[i] as usize]
        });
        drop(world_frame_major);
        let frame_of = map_indexed(source.len(), parallelism, |i| {
            frame_of_source(source[i] as usize)
        });
        let normals_started = std::time::Instant::now();
        // The normal of a merged voxel: PCA over the nearest centroids of the merged cloud
        // (many frames averaged, so less range noise than any frame's points); each point
        // orients its voxel's normal towards its own sensor.
        let voxel_normals = estimate_normals(
            index.centroids(),
            index.centroids(),
            index.centroid_tree(),
            normal_neighbours,
            NORMAL_RADIUS_PER_VOXEL * downsample_m,
            parallelism,
        );
        let normal_sign = map_indexed(points_world.len(), parallelism, |i| {
            let origin = &poses[frame_of[i] as usize].translation;
            let towards =
                |n: Vector3<f64>| orient_towards(n, &Vector3::from(points_world[i]), origin);
            match voxel_normals[index.voxel_of(i)] {
                Some(n) if towards(n) == n => 1,
                Some(_) => -1,
                None => 0,
            }
        });
        Self {
            points_world,
            frame_of,
            index,
            voxel_normals,
            normal_sign,
            lidar_frame_major,
            source,
            normals_s: normals_started.elapsed().as_secs_f64(),
        }
    }

    /// Oriented PCA normal of point `i` (`None` where PCA failed): its voxel's normal, turned
    /// towards the sensor of the point's frame.
    #[inline]
    pub fn normal(&self, i: usize) -> Option<Vector3<f64>> {
        let n = self.voxel_normals[self.index.voxel_of(i)]?;
        Some(if self.normal_sign[i] < 0 { -n } else { n })
    }

    /// Keeps the points of `neighbours` whose oriented normal lies within the gate of
    /// `normal` (`n . normal >= min_cos`). Consecutive neighbours mostly share a voxel
    /// (queries return whole voxels), so the voxel's dot product is computed once and each
    /// point only contributes its orientation sign.
    pub fn retain_facing(&self, neighbours: &mut Vec<usize>, normal: &Vector3<f64>, min_cos: f64) {
        // Per voxel: (passes as is, passes flipped).
        let mut last: Option<(usize, (bool, bool))> = None;
        neighbours.retain(|&j| {
            let voxel = self.index.voxel_of(j);
            let (as_is, flipped) = match last {
                Some((v, passes)) if v == voxel => passes,
                _ => {
                    let passes = self.voxel_normals[voxel].map_or((false, false), |n| {
                        (n.dot(normal) >= min_cos, (-n).dot(normal) >= min_cos)
                    });
                    last = Some((voxel, passes));
                    passes
                }
            };
            match self.normal_sign[j] {
                1 => as_is,
                -1 => flipped,
                _ => false,
            }
        });
    }

    /// Point `i` in its own frame's lidar coordinates (m).
    #[inline]
    pub fn lidar(&self, i: usize) -> Vector3<f64> {
        self.lidar_frame_major[self.source[i] as usize]
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

    /// Appends to `out` every point with a normal within `radius_m` of point `center`
    /// (unordered).
    pub fn within_with_normal(&self, center: usize, radius_m: f64, out: &mut Vec<usize>) {
        self.index.within(
            &self.points_world,
            &self.points_world[center],
            radius_m,
            |v| self.voxel_normals[v].is_some(),
            out,
        );
    }

    /// Kernel sampling (DESIGN step 3): a voxel grid of edge `gamma_m` over the world cloud,
    /// one kernel per occupied voxel: the real point nearest the voxel's centroid.
    pub fn sample_kernels(&self, gamma_m: f64, parallelism: Parallelism) -> Vec<usize> {
        let (slot_of, centroids) = voxel_slots_in_parts(&self.points_world, gamma_m, parallelism);
        let mut nearest = vec![(f64::INFINITY, 0usize); centroids.len()];
        for (i, &slot) in slot_of.iter().enumerate() {
            let slot = slot as usize;
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

    /// A wavy sheet seen by three sensors, two above and one below it (so points of one
    /// voxel carry opposite orientations).
    fn two_sided_cloud() -> ScaleCloud {
        let sheet: Vec<Vector3<f64>> = (0..900)
            .map(|i| {
                let (x, y) = ((i % 30) as f64 * 0.07, (i / 30) as f64 * 0.07);
                Vector3::new(x, y, 0.4 * (1.5 * x).sin() * (1.1 * y).cos())
            })
            .collect();
        let poses: Vec<Pose> = [3.0, 5.0, -4.0]
            .iter()
            .map(|&height| Pose {
                rotation: nalgebra::Matrix3::identity(),
                translation: Vector3::new(1.0, 1.0, height),
            })
            .collect();
        let frames: Vec<Vec<Vector3<f64>>> = poses
            .iter()
            .map(|pose| sheet.iter().map(|p| p - pose.translation).collect())
            .collect();
        ScaleCloud::build(&frames, &poses, 0.1, 8, Parallelism::Serial)
    }

    #[test]
    fn retain_facing_matches_the_per_point_gate() {
        let cloud = two_sided_cloud();
        let signs: std::collections::HashSet<i8> = cloud.normal_sign.iter().copied().collect();
        assert!(
            signs.contains(&1) && signs.contains(&-1),
            "both orientations present"
        );
        let everything: Vec<usize> = (0..cloud.len()).collect();
        for normal in [
            Vector3::z(),
            -Vector3::z(),
            Vector3::new(0.3, -0.2, 0.9).normalize(),
        ] {
            for gate_deg in [10.0f64, 45.0, 60.0, 95.0, 150.0] {
                let min_cos = gate_deg.to_radians().cos();
                let mut kept = everything.clone();
                cloud.retain_facing(&mut kept, &normal, min_cos);
                let expected: Vec<usize> = everything
                    .iter()
                    .copied()
                    .filter(|&j| cloud.normal(j).is_some_and(|n| n.dot(&normal) >= min_cos))
                    .collect();
                assert_eq!(kept, expected, "normal {normal:?}, gate {gate_deg} deg");
            }
        }
    }

    #[test]
    fn normals_face_their_own_sensor() {
        let cloud = two_sided_cloud();
        let origins = [3.0, 5.0, -4.0];
        for i in 0..cloud.len() {
            if let Some(n) = cloud.normal(i) {
                let sensor = Vector3::new(1.0, 1.0, origins[cloud.frame_of[i] as usize]);
                assert!(n.dot(&(sensor - cloud.world(i))) >= 0.0, "point {i}");
            }
        }
    }
}
