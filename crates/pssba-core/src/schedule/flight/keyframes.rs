//! Keyframes of the final trajectory (DESIGN section 9): a final frame becomes one every
//! `keyframe_step_m` or `keyframe_step_deg`; it keeps a downsampled cloud in its own frame
//! (bounded memory: 12 bytes a point) and the point-to-plane information of that cloud, which
//! says which directions its scene constrains. Positions are looked up in a k-d tree (kiddo)
//! to find the places a window sees again.

use crate::cloud::eigen3::smallest_eigenpair;
use crate::cloud::scale_cloud::voxel_downsample;
use crate::cloud::voxel_index::{VoxelKey, voxel_key};
use crate::geometry::Pose;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{Matrix3, Matrix6, Point3, Vector3, Vector6};
use rustc_hash::{FxHashMap, FxHashSet};

/// Edge (m) of the voxels whose points give one plane of [`geometry_information`].
const PLANE_VOXEL_M: f64 = 1.0;
/// Points a voxel needs for its plane.
const PLANE_MIN_POINTS: usize = 5;

/// One keyframe.
#[derive(Debug, Clone)]
pub struct Keyframe {
    /// Stream index of the frame.
    pub sequence: usize,
    /// Distance flown from the first frame to this one (m), along the final poses when it
    /// became a keyframe.
    pub path_m: f64,
    /// Downsampled points in the lidar frame (m).
    pub points: Vec<[f32; 3]>,
    /// Point-to-plane information per point, `[rotation; translation]` in the lidar frame.
    pub geometry: Matrix6<f64>,
    /// Its pose relative to the keyframe before, as the windows made them final (`None` for
    /// the first): the graph's measurement between the two.
    pub from_previous: Option<Pose>,
}

impl Keyframe {
    /// A keyframe of `points` (lidar frame), downsampled to `voxel_m`.
    pub fn new(
        sequence: usize,
        path_m: f64,
        from_previous: Option<Pose>,
        points: &[Point3<f64>],
        voxel_m: f64,
    ) -> Self {
        let coords: Vec<Vector3<f64>> = points.iter().map(|p| p.coords).collect();
        let reduced = voxel_downsample(&coords, voxel_m);
        Self {
            sequence,
            path_m,
            from_previous,
            geometry: geometry_information(&reduced),
            points: reduced
                .iter()
                .map(|p| [p.x as f32, p.y as f32, p.z as f32])
                .collect(),
        }
    }

    /// The points as the adjustment takes them.
    pub fn cloud(&self) -> Vec<Point3<f64>> {
        self.points
            .iter()
            .map(|p| Point3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2])))
            .collect()
    }
}

/// `sum_v w_v J_v^T J_v / sum_v w_v` over the planes of `points` (one per 1 m voxel with at
/// least 5 points, its PCA normal, weighted by its point count), `J = [(p x n)^T, n^T]`: how a
/// small motion `[a; dt]` of the frame moves its points off their planes (`n . (a x p + dt)`).
pub fn geometry_information(points: &[Vector3<f64>]) -> Matrix6<f64> {
    let mut voxels: FxHashMap<_, Vec<usize>> = FxHashMap::default();
    for (i, p) in points.iter().enumerate() {
        voxels
            .entry(voxel_key(&[p.x, p.y, p.z], PLANE_VOXEL_M))
            .or_default()
            .push(i);
    }
    let mut information = Matrix6::zeros();
    let mut weight = 0.0;
    for members in voxels.values().filter(|m| m.len() >= PLANE_MIN_POINTS) {
        let n = members.len() as f64;
        let mean = members.iter().map(|&i| points[i]).sum::<Vector3<f64>>() / n;
        let covariance = members
            .iter()
            .map(|&i| (points[i] - mean) * (points[i] - mean).transpose())
            .sum::<Matrix3<f64>>()
            / n;
        let Some((values, normal)) = smallest_eigenpair(&covariance) else {
            continue;
        };
        // A plane, not a blob or a line.
        if values[0] > 0.1 * values[1] {
            continue;
        }
        let moment = mean.cross(&normal);
        let j = Vector6::new(moment.x, moment.y, moment.z, normal.x, normal.y, normal.z);
        information += n * j * j.transpose();
        weight += n;
    }
    if weight > 0.0 {
        information / weight
    } else {
        information
    }
}

/// The keyframes so far and an index over their positions.
#[derive(Debug, Default)]
pub struct Keyframes {
    frames: Vec<Keyframe>,
    /// Positions at the last [`Self::reindex`], in the order of `frames`.
    index: Option<ImmutableKdTree<f64, 3>>,
}

impl Keyframes {
    /// Keyframes in stream order.
    pub fn all(&self) -> &[Keyframe] {
        &self.frames
    }

    /// The last keyframe.
    pub fn last(&self) -> Option<&Keyframe> {
        self.frames.last()
    }

    /// Appends a keyframe (sequences must grow).
    pub fn push(&mut self, keyframe: Keyframe) {
        debug_assert!(self.last().is_none_or(|k| k.sequence < keyframe.sequence));
        self.frames.push(keyframe);
    }

    /// Points held by all keyframes.
    pub fn points(&self) -> usize {
        self.frames.iter().map(|k| k.points.len()).sum()
    }

    /// Rebuilds the position index from `pose_of(sequence)` (poses move when a loop closes).
    pub fn reindex(&mut self, pose_of: impl Fn(usize) -> Pose) {
        let positions: Vec<[f64; 3]> = self
            .frames
            .iter()
            .map(|k| pose_of(k.sequence).translation.into())
            .collect();
        self.index = (!positions.is_empty()).then(|| ImmutableKdTree::new_from_slice(&positions));
    }

    /// Frees the cloud of keyframe `i` (an older keyframe holds its place); its pose, path
    /// and information stay for the pose graph.
    pub fn release_cloud(&mut self, i: usize) {
        if let Some(keyframe) = self.frames.get_mut(i) {
            keyframe.points = Vec::new();
        }
    }

    /// Indices (into [`Self::all`]) of the keyframes within `radius_m` of `position` at the
    /// last [`Self::reindex`].
    pub fn near(&self, position: &Vector3<f64>, radius_m: f64) -> Vec<usize> {
        let Some(index) = &self.index else {
            return Vec::new();
        };
        let mut found: Vec<usize> = index
            .within_unsorted::<SquaredEuclidean>(
                &[position.x, position.y, position.z],
                radius_m * radius_m,
            )
            .into_iter()
            .map(|n| n.item as usize)
            .collect();
        found.sort_unstable();
        found
    }
}

/// Occupied voxels (edge `voxel_m`) of keyframe clouds in the world.
pub fn occupied(
    keyframes: &[&Keyframe],
    pose_of: impl Fn(usize) -> Pose,
    voxel_m: f64,
) -> FxHashSet<VoxelKey> {
    let mut voxels = FxHashSet::default();
    for keyframe in keyframes {
        let pose = pose_of(keyframe.sequence);
        for p in &keyframe.points {
            let world = pose.apply(&Vector3::new(
                f64::from(p[0]),
                f64::from(p[1]),
                f64::from(p[2]),
            ));
            voxels.insert(voxel_key(&[world.x, world.y, world.z], voxel_m));
        }
    }
    voxels
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flat_ground_constrains_height_roll_and_pitch_only() {
        let ground: Vec<Vector3<f64>> = (-80..80)
            .flat_map(|x| {
                (-80..80).map(move |y| Vector3::new(0.25 * x as f64, 0.25 * y as f64, -3.0))
            })
            .collect();
        let g = geometry_information(&ground);
        // x, y translation and yaw: nothing.
        for k in [2, 3, 4] {
            assert!(g[(k, k)].abs() < 1e-9, "{k}: {}", g[(k, k)]);
        }
        assert!((g[(5, 5)] - 1.0).abs() < 1e-9, "{g}");
        assert!(g[(0, 0)] > 10.0 && g[(1, 1)] > 10.0);
    }
}
