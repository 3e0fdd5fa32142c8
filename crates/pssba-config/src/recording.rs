//! The `[recording]` table: defaults of the recording flags (`--points-topic` ...) of
//! `pssba adjust|import|inspect|run` on a robot recording.

use serde::{Deserialize, Serialize};

/// The `[recording]` table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RecordingConfig {
    /// Cloud topic; empty: the only one.
    pub points_topic: String,
    /// Pose topic; empty: the only one.
    pub poses_topic: String,
    /// body_from_lidar `[tx, ty, tz, qx, qy, qz, qw]`; empty: from /tf_static, else identity.
    pub extrinsic: Vec<f64>,
    /// Largest gap (s) between the two poses a cloud's pose is interpolated from.
    pub max_pose_gap_s: f64,
    /// Each point's time: `auto`, `none`, `FIELD` or `FIELD:UNIT` (see `--point-time`).
    pub point_time: String,
}

impl Default for RecordingConfig {
    fn default() -> Self {
        RecordingConfig {
            points_topic: String::new(),
            poses_topic: String::new(),
            extrinsic: Vec::new(),
            max_pose_gap_s: pssba_bag::recording::DEFAULT_MAX_POSE_GAP_S,
            point_time: "auto".into(),
        }
    }
}

impl RecordingConfig {
    /// Checks the values that need no recording to check (the flags that override them are
    /// checked with them, when a recording is opened).
    pub fn validate(&self) -> Result<(), String> {
        if !(self.max_pose_gap_s.is_finite() && self.max_pose_gap_s > 0.0) {
            return Err(format!(
                "recording.max_pose_gap_s = {} must be a positive number of seconds",
                self.max_pose_gap_s
            ));
        }
        self.point_time
            .parse::<pssba_bag::msg::PointTimeChoice>()
            .map_err(|e| format!("recording.point_time: {e}"))?;
        Ok(())
    }
}
