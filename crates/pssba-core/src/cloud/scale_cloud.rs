//! The world cloud of one scale (DESIGN steps 1-3): per-frame voxel downsampling in each
//! frame's own lidar coordinates (independent of the poses, so a run reuses it while the
//! downsampling edge stays the same), the world points, a voxel index over the merged cloud,
//! and PCA normals.

use crate::cloud::normals::{NeighbourLists, normals_over, orient_towards};
use crate::cloud::voxel_index::{VoxelIndex, VoxelSlots, voxel_centroids, voxel_slots_in_parts};
use crate::geometry::Pose;
use crate::parallel::{Parallelism, map_indexed};
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
    /// see `VoxelIndex`), each voxel's points in ascending frame order.
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
    /// Frame k's points in `lidar_frame_major` are `first_of_frame[k]..first_of_frame[k + 1]`.
    first_of_frame: Vec<usize>,
    /// Position in `lidar_frame_major` of each point. Lidar points are looked up when needed
    /// (kernels and residual points, a fraction of the cloud) instead of being reordered.
    source: Vec<u32>,
    /// Per voxel of `index`, the voxels whose centroids its normal is fitted to.
    voxel_neighbours: NeighbourLists,
    /// Downsampling edge (m).
    pub downsample_m: f64,
    /// The poses the voxels and normal neighbourhoods were built at (see [`Self::refresh`]).
    built_poses: Vec<Pose>,

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
        let lidar_frame_major = Arc::clone(&downsampled.points);
        // Frame of each point, frame-major: read in order here, instead of a search of
        // `first_of_frame` per point.
        let frame_of_source: Vec<u32> = (0..first_of_frame.len() - 1)
            .flat_map(|k| std::iter::repeat_n(k as u32, first_of_frame[k + 1] - first_of_frame[k]))
            .collect();
        let world_frame_major: Vec<[f64; 3]> =
            map_indexed(lidar_frame_major.len(), parallelism, |i| {
                poses[frame_of_source[i] as usize]
                    .apply(&lidar_frame_major[i])
                    .into()
            });
        // Voxel-major storage: a neighbour query then reads whole voxels in memory order.
        let downsample_m = downsampled.voxel_m;
        let built = VoxelIndex::voxel_major(&world_frame_major, downsample_m, parallelism);
        drop(world_frame_major);
        let (index, source, points_world) = (built.index, built.order, built.points);
        let frame_of = map_indexed(source.len(), parallelism, |i| {
            frame_of_source[source[i] as usize]
        });
        drop(frame_of_source);
        let normals_started = std::time::Instant::now();
        // The normal of a merged voxel: PCA over the nearest centroids of the merged cloud
        // (many frames averaged, so less range noise than any frame's points); each point
        // orients its voxel's normal towards its own sensor.
        let voxel_neighbours = NeighbourLists::nearest(
            index.centroids(),
            normal_neighbours,
            NORMAL_RADIUS_PER_VOXEL * downsample_m,
            parallelism,
        );
        let voxel_normals = normals_over(index.centroids(), &voxel_neighbours, parallelism);
        let normal_sign = normal_signs(
            &points_world,
            &frame_of,
            &index,
            &voxel_normals,
            poses,
            parallelism,
        );
        Self {
            points_world,
            frame_of,
            index,
            voxel_normals,
            normal_sign,
            lidar_frame_major,
            first_of_frame: first_of_frame.clone(),
            source,
            voxel_neighbours,
            downsample_m,
            built_poses: poses.to_vec(),
            normals_s: normals_started.elapsed().as_secs_f64(),
        }
    }

    /// Moves the cloud's points to new poses without building it again, when few of them have
    /// moved far since it was built: false (and the cloud unchanged) when more than
    /// `max_far_fraction` of the points lie farther than `max_drift_m` from where they were
    /// when the voxels were made. Otherwise the world points move, each voxel's offset is
    /// measured again (radius queries stay exact, see `VoxelIndex::refresh_offsets`), and
    /// each voxel's normal is fitted again over the moved centroids of the neighbour voxels it
    /// was fitted to (the neighbour search is skipped). The voxels keep the points they were
    /// built with, so they group points that still lie together as long as the moves stay
    /// small against the downsampling edge.
    pub fn refresh(
        &mut self,
        poses: &[Pose],
        max_drift_m: f64,
        max_far_fraction: f64,
        parallelism: Parallelism,
    ) -> bool {
        assert_eq!(poses.len(), self.built_poses.len(), "one pose per frame");
        let started = std::time::Instant::now();
        let (lidar, source, frame_of) = (&self.lidar_frame_major, &self.source, &self.frame_of);
        let world = |i: usize, poses: &[Pose]| {
            poses[frame_of[i] as usize].apply(&lidar[source[i] as usize])
        };
        // Counted frame by frame over the lidar points in memory order first, not stored: a
        // refused refresh then costs no memory beside the cloud (at 1000 frames the moved
        // points alone would be 290 MB).
        let max_drift_sq = max_drift_m * max_drift_m;
        let far: usize = map_indexed(self.built_poses.len(), parallelism, |k| {
            let (now, then) = (&poses[k], &self.built_poses[k]);
            lidar[self.first_of_frame[k]..self.first_of_frame[k + 1]]
                .iter()
                .filter(|p| (now.apply(p) - then.apply(p)).norm_squared() > max_drift_sq)
                .count()
        })
        .into_iter()
        .sum();
        if far as f64 > max_far_fraction * source.len() as f64 {
            tracing::debug!(
                far,
                points = source.len(),
                "points moved too far to move the cloud"
            );
            return false;
        }
        let points_world = map_indexed(source.len(), parallelism, |i| world(i, poses).into());
        self.points_world = points_world;
        self.index.refresh_offsets(&self.points_world, parallelism);
        let normals_started = std::time::Instant::now();
        let centroids_now = self.index.point_means(&self.points_world, parallelism);
        self.voxel_normals = normals_over(&centroids_now, &self.voxel_neighbours, parallelism);
        self.normal_sign = normal_signs(
            &self.points_world,
            &self.frame_of,
            &self.index,
            &self.voxel_normals,
            poses,
            parallelism,
        );
        self.normals_s = normals_started.elapsed().as_secs_f64();
        tracing::debug!(
            far,
            refresh_s = started.elapsed().as_secs_f64(),
            "cloud moved to the new poses"
        );
        true
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
        self.retain_facing_then(neighbours, normal, min_cos, |_| {});
    }

    /// [`Self::retain_facing`], handing each kept point to `kept` in order (so a caller's
    /// next pass over the kept points rides along instead of reading them again).
    pub fn retain_facing_then(
        &self,
        neighbours: &mut Vec<usize>,
        normal: &Vector3<f64>,
        min_cos: f64,
        mut kept: impl FnMut(usize),
    ) {
        // Neighbours come voxel by voxel (see `within_with_normal`): each run of one voxel
        // is tested against the gate once, then each point only by its orientation sign. A
        // plain loop rather than `Vec::retain`, whose per-element closure was not inlined.
        let len = neighbours.len();
        let (mut read, mut write) = (0, 0);
        while read < len {
            let voxel = self.index.voxel_of(neighbours[read]);
            let (as_is, flipped) = self.voxel_normals[voxel].map_or((false, false), |n| {
                (n.dot(normal) >= min_cos, (-n).dot(normal) >= min_cos)
            });
            while read < len {
                let j = neighbours[read];
                if self.index.voxel_of(j) != voxel {
                    break;
                }
                let keep = match self.normal_sign[j] {
                    1 => as_is,
                    -1 => flipped,
                    _ => false,
                };
                if keep {
                    kept(j);
                    neighbours[write] = j;
                    write += 1;
                }
                read += 1;
            }
        }
        neighbours.truncate(write);
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
        let VoxelSlots {
            slot_of, centroids, ..
        } = voxel_slots_in_parts(&self.points_world, gamma_m, parallelism);
        // Each fixed part of the cloud finds its nearest point per voxel; parts are merged in
        // order and a later part wins only when strictly nearer: the first nearest point, as
        // one pass over the cloud would find it, whatever the thread count.
        const PARTS: usize = 8;
        let part_len = slot_of.len().div_ceil(PARTS).max(1);
        let nearest_in_part = map_indexed(slot_of.len().div_ceil(part_len), parallelism, |k| {
            let mut nearest = vec![(f64::INFINITY, 0usize); centroids.len()];
            let start = k * part_len;
            for (i, &slot) in (start..).zip(&slot_of[start..(start + part_len).min(slot_of.len())])
            {
                let slot = slot as usize;
                let d = (self.world(i) - centroids[slot]).norm_squared();
                if d < nearest[slot].0 {
                    nearest[slot] = (d, i);
                }
            }
            nearest
        });
        let mut nearest = vec![(f64::INFINITY, 0usize); centroids.len()];
        for part in nearest_in_part {
            for (best, candidate) in nearest.iter_mut().zip(part) {
                if candidate.0 < best.0 {
                    *best = candidate;
                }
            }
        }
        nearest.into_iter().map(|(_, i)| i).collect()
    }
}

/// Per point, the sign that turns its voxel's normal towards its own sensor (+1 or -1; 0
/// where the voxel has no normal).
fn normal_signs(
    points_world: &[[f64; 3]],
    frame_of: &[u32],
    index: &VoxelIndex,
    voxel_normals: &[Option<Vector3<f64>>],
    poses: &[Pose],
    parallelism: Parallelism,
) -> Vec<i8> {
    map_indexed(points_world.len(), parallelism, |i| {
        let origin = &poses[frame_of[i] as usize].translation;
        let towards = |n: Vector3<f64>| orient_towards(n, &Vector3::from(points_world[i]), origin);
        match voxel_normals[index.voxel_of(i)] {
            Some(n) if towards(n) == n => 1,
            Some(_) => -1,
            None => 0,
        }
    })
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

    /// Frames of a wavy sheet and their poses (5 sensors above it).
    fn sheet_frames() -> (Vec<Vec<Vector3<f64>>>, Vec<Pose>) {
        let sheet: Vec<Vector3<f64>> = (0..2500)
            .map(|i| {
                let (x, y) = ((i % 50) as f64 * 0.05, (i / 50) as f64 * 0.05);
                Vector3::new(x, y, 0.3 * (1.5 * x).sin() * (1.1 * y).cos())
            })
            .collect();
        let poses: Vec<Pose> = (0..5)
            .map(|k| Pose {
                rotation: nalgebra::Matrix3::identity(),
                translation: Vector3::new(0.3 * k as f64, 1.0, 3.0),
            })
            .collect();
        let frames = poses
            .iter()
            .map(|pose| sheet.iter().map(|p| p - pose.translation).collect())
            .collect();
        (frames, poses)
    }

    /// Each of `poses` moved: frame k by `scale_m` times its own direction, and turned by
    /// `scale_m / 10` rad about z.
    fn moved(poses: &[Pose], scale_m: f64) -> Vec<Pose> {
        poses
            .iter()
            .enumerate()
            .map(|(k, pose)| {
                let direction = Vector3::new(1.0, -0.5 * k as f64, 0.3).normalize();
                let turn = nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), scale_m / 10.0);
                Pose {
                    rotation: turn.matrix() * pose.rotation,
                    translation: pose.translation + scale_m * direction,
                }
            })
            .collect()
    }

    #[test]
    fn a_refreshed_cloud_answers_as_a_cloud_built_at_the_new_poses() {
        let (frames, poses) = sheet_frames();
        let edge_m = 0.1;
        let built = ScaleCloud::build(&frames, &poses, edge_m, 8, Parallelism::Serial);
        let now = moved(&poses, 0.02);
        let mut refreshed = built;
        assert!(
            refreshed.refresh(&now, 0.5 * edge_m, 0.1, Parallelism::Rayon),
            "2 cm moves are small against a 10 cm edge"
        );
        let fresh = ScaleCloud::build(&frames, &now, edge_m, 8, Parallelism::Serial);
        assert_eq!(refreshed.len(), fresh.len());
        // The same points (by frame and lidar coordinates), in another order.
        let identity = |cloud: &ScaleCloud, i: usize| {
            let l = cloud.lidar(i);
            (
                cloud.frame_of[i],
                l.x.to_bits(),
                l.y.to_bits(),
                l.z.to_bits(),
            )
        };
        let position_in_fresh: std::collections::HashMap<_, usize> =
            (0..fresh.len()).map(|i| (identity(&fresh, i), i)).collect();
        let mut worst_normal_deg: f64 = 0.0;
        for i in 0..refreshed.len() {
            let j = position_in_fresh[&identity(&refreshed, i)];
            assert!((refreshed.world(i) - fresh.world(j)).norm() < 1e-12);
            let (a, b) = (
                refreshed.normal(i).expect("normal"),
                fresh.normal(j).expect("normal"),
            );
            worst_normal_deg = worst_normal_deg.max(a.dot(&b).clamp(-1.0, 1.0).acos().to_degrees());
        }
        // Same neighbourhoods up to the voxel grouping: normals agree within a few degrees.
        assert!(
            worst_normal_deg < 5.0,
            "normals {worst_normal_deg} deg apart"
        );
        // Radius queries are exact over the moved points.
        for center in (0..refreshed.len()).step_by(97) {
            let mut got = Vec::new();
            refreshed.within_with_normal(center, 0.3, &mut got);
            let mut got: Vec<_> = got.iter().map(|&i| identity(&refreshed, i)).collect();
            let mut expected: Vec<_> = (0..fresh.len())
                .filter(|&j| (fresh.world(j) - refreshed.world(center)).norm() <= 0.3)
                .map(|j| identity(&fresh, j))
                .collect();
            got.sort_unstable();
            expected.sort_unstable();
            assert_eq!(got, expected, "around point {center}");
        }
    }

    #[test]
    fn a_cloud_whose_points_moved_far_is_not_refreshed() {
        let (frames, poses) = sheet_frames();
        let mut cloud = ScaleCloud::build(&frames, &poses, 0.1, 8, Parallelism::Serial);
        let before = cloud.points_world.clone();
        let far = moved(&poses, 0.2);
        assert!(
            !cloud.refresh(&far, 0.05, 0.1, Parallelism::Serial),
            "20 cm moves against a 5 cm limit"
        );
        // Unchanged, and it still refreshes where the poses stay put.
        assert_eq!(cloud.points_world, before);
        assert!(cloud.refresh(&poses, 0.05, 0.0, Parallelism::Serial));
    }

    #[test]
    fn retain_facing_matches_the_per_point_gate() {
        let cloud = two_sided_cloud();
        let signs: std::collections::HashSet<i8> = cloud.normal_sign.iter().copied().collect();
        assert!(
            signs.contains(&1) && signs.contains(&-1),
            "both orientations present"
        );
        // Whole voxels in order (as the radius query gives them), and voxels interleaved.
        let in_order: Vec<usize> = (0..cloud.len()).collect();
        let interleaved: Vec<usize> = (0..cloud.len()).rev().step_by(3).chain(0..7).collect();
        for (order, normal) in [&in_order, &interleaved].into_iter().flat_map(|order| {
            [
                Vector3::z(),
                -Vector3::z(),
                Vector3::new(0.3, -0.2, 0.9).normalize(),
            ]
            .map(|normal| (order, normal))
        }) {
            for gate_deg in [10.0f64, 45.0, 60.0, 95.0, 150.0] {
                let min_cos = gate_deg.to_radians().cos();
                let mut kept = order.clone();
                cloud.retain_facing(&mut kept, &normal, min_cos);
                let expected: Vec<usize> = order
                    .iter()
                    .copied()
                    .filter(|&j| cloud.normal(j).is_some_and(|n| n.dot(&normal) >= min_cos))
                    .collect();
                assert_eq!(kept, expected, "normal {normal:?}, gate {gate_deg} deg");
            }
        }
    }

    #[test]
    fn kernels_are_the_first_points_nearest_their_voxel_centroids() {
        let (frames, poses) = sheet_frames();
        let cloud = ScaleCloud::build(&frames, &poses, 0.05, 8, Parallelism::Serial);
        for gamma_m in [0.07, 0.3, 1.0] {
            let VoxelSlots {
                slot_of, centroids, ..
            } = voxel_slots_in_parts(&cloud.points_world, gamma_m, Parallelism::Serial);
            // One pass over the cloud: the first point at the least distance per voxel.
            let mut expected = vec![(f64::INFINITY, 0usize); centroids.len()];
            for (i, &slot) in slot_of.iter().enumerate() {
                let d = (cloud.world(i) - centroids[slot as usize]).norm_squared();
                if d < expected[slot as usize].0 {
                    expected[slot as usize] = (d, i);
                }
            }
            let expected: Vec<usize> = expected.into_iter().map(|(_, i)| i).collect();
            assert_eq!(cloud.sample_kernels(gamma_m, Parallelism::Serial), expected);
            assert_eq!(cloud.sample_kernels(gamma_m, Parallelism::Rayon), expected);
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
