//! The flight out of a recording (`pssba export`, and the files `pssba run` writes beside
//! its MCAP): the final trajectory, every final frame's stamp and pose (world from lidar),
//! and the map, every final frame's recorded points in the world frame, voxel-downsampled.
//! Both read all parts of a run ([`crate::existing_parts`]) as one, streaming: memory is the
//! trajectory and the map's voxels, never the clouds.

use crate::RecordingError;
use crate::read::{cloud_points, isometries};
use crate::write::{existing_parts, topics};
use foxglove::Decode;
use foxglove::schemas::{FrameTransform, PointCloud, PosesInFrame};
use nalgebra::{Isometry3, Point3, Quaternion, Translation3, UnitQuaternion};
use std::collections::{BTreeMap, HashMap, HashSet};
use std::path::Path;

/// A frame's final pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FinalPose {
    /// The frame's stamp as recorded (ns since the epoch of the input's clock).
    pub stamp_ns: u64,
    /// World from lidar.
    pub world_from_lidar: Isometry3<f64>,
}

impl FinalPose {
    /// The stamp in seconds.
    pub fn stamp_s(&self) -> f64 {
        self.stamp_ns as f64 * 1e-9
    }
}

fn stamp_ns(stamp: Option<foxglove::schemas::Timestamp>) -> Option<u64> {
    stamp.map(|t| u64::from(t.sec()) * 1_000_000_000 + u64::from(t.nsec()))
}

/// Every message of every part of the run to `out`, in order, as (part, topic, data).
fn for_each_message(
    out: &Path,
    mut visit: impl FnMut(&Path, &str, &[u8]) -> crate::Result<()>,
) -> crate::Result<()> {
    for path in existing_parts(out) {
        let reader = pssba_bag::mcap_message_reader(&path)
            .map_err(|e| RecordingError::read(&path, e.to_string()))?;
        for message in reader {
            let message =
                message.map_err(|e| RecordingError::read(&path, format!("bad record: {e}")))?;
            visit(&path, &message.channel.topic, &message.data)?;
        }
    }
    Ok(())
}

/// The final trajectory of the run to `out`, in stamp order.
///
/// The stamps are those of the `/tf` transforms, one per frame made final (a frame a
/// restarted recorder wrote twice counts once, the later pose kept). The poses are those
/// of the last `/pssba/poses/optimized` message, the whole run's final poses in the same
/// order, when it holds one per stamp; otherwise (a run cut before its last trajectory was
/// written) the transforms' own.
pub fn final_trajectory(out: &Path) -> crate::Result<Vec<FinalPose>> {
    let mut by_stamp: BTreeMap<u64, Isometry3<f64>> = BTreeMap::new();
    let mut last_optimized: Vec<Isometry3<f64>> = Vec::new();
    for_each_message(out, |path, topic, data| {
        match topic {
            topics::TF => {
                let tf = FrameTransform::decode(data).map_err(|e| decoding(path, topic, e))?;
                let stamp = stamp_ns(tf.timestamp)
                    .ok_or_else(|| RecordingError::read(path, "a /tf message without a stamp"))?;
                by_stamp.insert(stamp, transform_isometry(&tf));
            }
            topics::OPTIMIZED => {
                let poses = PosesInFrame::decode(data).map_err(|e| decoding(path, topic, e))?;
                last_optimized = isometries(&poses);
            }
            _ => {}
        }
        Ok(())
    })?;
    let from_trajectory = last_optimized.len() == by_stamp.len();
    Ok(by_stamp
        .into_iter()
        .enumerate()
        .map(|(k, (stamp_ns, from_tf))| FinalPose {
            stamp_ns,
            world_from_lidar: if from_trajectory {
                last_optimized[k]
            } else {
                from_tf
            },
        })
        .collect())
}

fn decoding(path: &Path, topic: &str, error: impl std::fmt::Display) -> RecordingError {
    RecordingError::read(path, format!("decoding {topic}: {error}"))
}

fn transform_isometry(tf: &FrameTransform) -> Isometry3<f64> {
    let t = tf.translation.unwrap_or_default();
    let q = tf.rotation.unwrap_or_default();
    Isometry3::from_parts(
        Translation3::new(t.x, t.y, t.z),
        UnitQuaternion::from_quaternion(Quaternion::new(q.w, q.x, q.y, q.z)),
    )
}

/// Points reduced to one per voxel (the centroid of the points that fell in it).
#[derive(Debug, Clone)]
pub struct VoxelMap {
    voxel_m: f64,
    cells: HashMap<[i64; 3], ([f64; 3], u64)>,
}

impl VoxelMap {
    /// An empty map of `voxel_m` voxels (a positive, finite size, else an error naming it).
    pub fn new(voxel_m: f64) -> crate::Result<VoxelMap> {
        if !(voxel_m.is_finite() && voxel_m > 0.0) {
            return Err(RecordingError::Settings(format!(
                "map voxel size {voxel_m} m: must be a positive number of metres"
            )));
        }
        Ok(VoxelMap {
            voxel_m,
            cells: HashMap::new(),
        })
    }

    /// Adds a point (non-finite points are skipped).
    pub fn add(&mut self, p: &Point3<f64>) {
        if !(p.x.is_finite() && p.y.is_finite() && p.z.is_finite()) {
            return;
        }
        let key = [p.x, p.y, p.z].map(|v| (v / self.voxel_m).floor() as i64);
        let (sum, count) = self.cells.entry(key).or_insert(([0.0; 3], 0));
        for (s, v) in sum.iter_mut().zip([p.x, p.y, p.z]) {
            *s += v;
        }
        *count += 1;
    }

    /// Voxels holding a point.
    pub fn len(&self) -> usize {
        self.cells.len()
    }

    /// Whether no point was added.
    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }

    /// One point per voxel, in voxel order (the same input gives the same file).
    pub fn points(&self) -> Vec<Point3<f64>> {
        let mut cells: Vec<_> = self.cells.iter().collect();
        cells.sort_unstable_by_key(|(key, _)| **key);
        cells
            .into_iter()
            .map(|(_, (sum, count))| {
                let n = *count as f64;
                Point3::new(sum[0] / n, sum[1] / n, sum[2] / n)
            })
            .collect()
    }
}

/// The map of the run to `out`: each frame of `trajectory` (matched to its `/lidar/points`
/// cloud by stamp) in the world frame, into `map`. Frames without a final pose (dropped, or
/// after a cut) are left out; `progress(frames_added)` is called after each frame. Returns
/// the frames added.
pub fn add_flight_to_map(
    out: &Path,
    trajectory: &[FinalPose],
    map: &mut VoxelMap,
    mut progress: impl FnMut(usize),
) -> crate::Result<usize> {
    // Points with times are de-skewed along the final trajectory (its frames in stamp order).
    let mut ordered: Vec<&FinalPose> = trajectory.iter().collect();
    ordered.sort_by_key(|p| p.stamp_ns);
    let track: Vec<Isometry3<f64>> = ordered.iter().map(|p| p.world_from_lidar).collect();
    let stamps_s: Vec<f64> = ordered.iter().map(|p| p.stamp_s()).collect();
    let index: HashMap<u64, usize> = (ordered.iter().enumerate())
        .map(|(k, p)| (p.stamp_ns, k))
        .collect();
    let mut seen = HashSet::new();
    for_each_message(out, |path, topic, data| {
        if topic != topics::POINTS {
            return Ok(());
        }
        let cloud = PointCloud::decode(data).map_err(|e| decoding(path, topic, e))?;
        let Some(stamp) = stamp_ns(cloud.timestamp) else {
            return Err(RecordingError::read(
                path,
                "a /lidar/points cloud without a stamp",
            ));
        };
        let Some(&k) = index.get(&stamp) else {
            return Ok(());
        };
        let world_from_lidar = track[k];
        if !seen.insert(stamp) {
            return Ok(());
        }
        let mut points = cloud_points(&cloud)
            .map_err(|e| RecordingError::read(path, format!("{topic}: {e}")))?;
        let times = crate::read::cloud_point_times(&cloud)
            .map_err(|e| RecordingError::read(path, format!("{topic}: {e}")))?;
        if let Some(offsets_s) = times {
            points = pssba_core::deskew_frame_along(&points, &offsets_s, &track, &stamps_s, k)
                .map_err(|e| {
                    RecordingError::read(path, format!("{topic}, frame at {stamp} ns: {e}"))
                })?;
        }
        for p in &points {
            map.add(&(world_from_lidar * p));
        }
        progress(seen.len());
        Ok(())
    })?;
    Ok(seen.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_voxel_keeps_the_centroid_of_its_points() {
        let mut map = VoxelMap::new(1.0).expect("size");
        map.add(&Point3::new(0.2, 0.2, 0.2));
        map.add(&Point3::new(0.4, 0.6, 0.8));
        map.add(&Point3::new(-0.5, 0.5, 0.5));
        map.add(&Point3::new(f64::NAN, 0.0, 0.0));
        assert_eq!(map.len(), 2);
        let points = map.points();
        assert_eq!(points[0], Point3::new(-0.5, 0.5, 0.5));
        assert!((points[1] - Point3::new(0.3, 0.4, 0.5)).norm() < 1e-12);
    }

    #[test]
    fn a_voxel_size_that_is_not_positive_is_refused() {
        for size in [0.0, -0.1, f64::NAN, f64::INFINITY] {
            let error = VoxelMap::new(size).expect_err("refused");
            assert!(error.to_string().contains("voxel size"), "{error}");
        }
    }
}
