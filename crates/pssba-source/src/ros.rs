//! Robot recordings, one registry entry per container (ROS 1 bag, rosbag2 folder, bare MCAP,
//! bare sqlite3 `.db3`), all read by `pssba-bag`: each cloud message a frame at its header
//! stamp, its initial pose from the pose topic, the extrinsic from `/tf_static`.

use crate::registry::{OpenOptions, SourceKind};
use crate::{Frame, FrameSource, Frames, Result};
use pssba_bag::{Container, Recording};
use std::path::Path;

/// A ROS 1 bag.
pub const ROS1_BAG: SourceKind = SourceKind {
    name: "ROS 1 bag",
    looks_for: "a file starting with '#ROSBAG V2.0'",
    detect: |path| Container::detect(path) == Some(Container::Ros1),
    open,
};

/// A rosbag2 folder.
pub const ROSBAG2_FOLDER: SourceKind = SourceKind {
    name: "rosbag2 folder",
    looks_for: "a folder with metadata.yaml listing .mcap or .db3 storage files",
    detect: |path| {
        matches!(
            Container::detect(path),
            Some(Container::Rosbag2Mcap | Container::Rosbag2Sqlite)
        )
    },
    open,
};

/// A bare MCAP file with ROS 2 messages.
pub const MCAP_FILE: SourceKind = SourceKind {
    name: "MCAP file",
    looks_for: "a file starting with the MCAP magic (ROS 2 messages, cdr)",
    detect: |path| Container::detect(path) == Some(Container::Mcap),
    open,
};

/// A bare rosbag2 sqlite3 file.
pub const SQLITE_FILE: SourceKind = SourceKind {
    name: "rosbag2 sqlite3 file",
    looks_for: "a file starting with 'SQLite format 3' (a rosbag2 .db3)",
    detect: |path| Container::detect(path) == Some(Container::Sqlite),
    open,
};

fn open(path: &Path, options: &OpenOptions) -> Result<Box<dyn FrameSource>> {
    if let Some(poses) = &options.poses {
        return Err(crate::SourceError::Settings(format!(
            "--poses {}: a robot recording takes its poses from a pose topic (--poses-topic)",
            poses.display()
        )));
    }
    let recording = Recording::open(path, &options.recording)?;
    Ok(Box::new(RosRecording { recording }))
}

/// An opened robot recording.
#[derive(Debug)]
pub struct RosRecording {
    recording: Recording,
}

impl FrameSource for RosRecording {
    fn kind(&self) -> &'static str {
        self.recording.bag().container().describe()
    }

    fn describe(&self) -> String {
        self.recording.bag().path().display().to_string()
    }

    fn len(&self) -> Option<usize> {
        Some(self.recording.frames.len())
    }

    fn max_points(&self) -> Option<usize> {
        Some(self.recording.max_points())
    }

    fn frames_from(&self, first: usize) -> Result<Frames> {
        Ok(Box::new(self.recording.frames()?.skip(first).map(
            |frame| {
                let frame = frame?;
                Ok(Frame {
                    stamp_s: frame.stamp_s(),
                    points: frame.points,
                    world_from_lidar: frame.world_from_lidar,
                    ground_truth: None,
                    point_times_s: frame.point_times_s,
                })
            },
        )))
    }

    fn metadata(&self) -> serde_json::Value {
        let r = &self.recording;
        let t = r.extrinsic.translation.vector;
        let q = r.extrinsic.rotation.coords;
        serde_json::json!({
            "source": self.describe(),
            "kind": self.kind(),
            "points_topic": {"name": r.points_topic.name, "type": r.points_topic.type_name},
            "poses_topic": {"name": r.poses_topic.name, "type": r.poses_topic.type_name},
            "world_frame": r.world_frame,
            "body_frame": r.body_frame,
            "cloud_frame": r.cloud_frame,
            "clouds_in_world_frame": r.clouds_in_world,
            "body_from_lidar": {
                "translation_m": [t.x, t.y, t.z],
                "quaternion_xyzw": [q.x, q.y, q.z, q.w],
                "source": format!("{:?}", r.extrinsic_source),
            },
            "max_pose_gap_s": r.max_pose_gap_s,
            "point_time": r.point_time,
            "frames": r.frames.len(),
            "frame_message_indices": r.frames.iter().map(|f| f.message_index).collect::<Vec<_>>(),
            "skipped": r.skipped,
            "stamps": "the clouds' header stamps (s since the epoch)",
        })
    }
}
