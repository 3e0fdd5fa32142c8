//! Pose messages: `nav_msgs/Odometry`, `geometry_msgs/PoseStamped`,
//! `geometry_msgs/PoseWithCovarianceStamped`, and the transforms of `tf2_msgs/TFMessage`.

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};

use super::cursor::{Cursor, DecodeError, Header, decode_err};

/// A pose message: `parent_from_child` at a stamp.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseMessage {
    /// Header: stamp, and the parent frame (e.g. `camera_init`, `odom`, `map`).
    pub header: Header,
    /// The child frame, when the message names it (Odometry, TransformStamped).
    pub child_frame_id: Option<String>,
    /// Maps points of the child frame into the parent frame.
    pub parent_from_child: Isometry3<f64>,
}

/// A quaternion's norm must be within this factor of 1 to be normalised (else it is garbage).
const QUATERNION_NORM_RANGE: (f64, f64) = (0.5, 2.0);

/// position (3 x f64) then orientation (x, y, z, w as f64): a `geometry_msgs/Pose` or
/// `Transform` (translation, rotation), checked finite and normalised.
fn isometry(cursor: &mut Cursor<'_>, what: &str) -> Result<Isometry3<f64>, DecodeError> {
    let mut v = [0.0; 7];
    for (k, slot) in v.iter_mut().enumerate() {
        *slot = cursor.f64(what)?;
        if !slot.is_finite() {
            let names = ["x", "y", "z", "qx", "qy", "qz", "qw"];
            return Err(decode_err(format!("{what}: {} is {slot}", names[k])));
        }
    }
    let q = Quaternion::new(v[6], v[3], v[4], v[5]);
    let norm = q.norm();
    if !(QUATERNION_NORM_RANGE.0..=QUATERNION_NORM_RANGE.1).contains(&norm) {
        return Err(decode_err(format!(
            "{what}: quaternion ({}, {}, {}, {}) has norm {norm}",
            v[3], v[4], v[5], v[6]
        )));
    }
    Ok(Isometry3::from_parts(
        Translation3::new(v[0], v[1], v[2]),
        UnitQuaternion::from_quaternion(q),
    ))
}

/// `nav_msgs/Odometry` (the pose part; covariance and twist are not read).
pub fn decode_odometry(cursor: &mut Cursor<'_>) -> Result<PoseMessage, DecodeError> {
    let header = cursor.header()?;
    let child = cursor.string("child_frame_id")?;
    let pose = isometry(cursor, "pose.pose")?;
    Ok(PoseMessage {
        header,
        child_frame_id: Some(child),
        parent_from_child: pose,
    })
}

/// `geometry_msgs/PoseStamped` and `PoseWithCovarianceStamped` (whose pose comes first too).
pub fn decode_pose_stamped(cursor: &mut Cursor<'_>) -> Result<PoseMessage, DecodeError> {
    let header = cursor.header()?;
    let pose = isometry(cursor, "pose")?;
    Ok(PoseMessage {
        header,
        child_frame_id: None,
        parent_from_child: pose,
    })
}

/// `tf2_msgs/TFMessage`: every `TransformStamped` in it.
pub fn decode_tf(cursor: &mut Cursor<'_>) -> Result<Vec<PoseMessage>, DecodeError> {
    // A TransformStamped is at least a header (12 bytes), a child name (4) and 7 f64.
    let count = cursor.sequence_len(12 + 4 + 56, "transforms")?;
    (0..count)
        .map(|_| {
            let header = cursor.header()?;
            let child = cursor.string("transforms[].child_frame_id")?;
            let transform = isometry(cursor, "transforms[].transform")?;
            Ok(PoseMessage {
                header,
                child_frame_id: Some(child),
                parent_from_child: transform,
            })
        })
        .collect()
}
