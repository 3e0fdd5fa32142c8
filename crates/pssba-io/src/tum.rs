//! TUM trajectory files: one pose per line, `stamp tx ty tz qx qy qz qw`.

use std::fmt::Write as _;
use std::path::Path;

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};

use crate::IoError;

/// Quaternions with a smaller norm (or a non-finite one) are rejected;
/// all others are normalised.
pub const MIN_QUATERNION_NORM: f64 = 1e-3;

const FIELD_NAMES: [&str; 8] = ["stamp", "tx", "ty", "tz", "qx", "qy", "qz", "qw"];

/// A timestamped pose: the transform from the lidar frame to the world frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StampedPose {
    /// Time stamp in seconds.
    pub stamp: f64,
    /// World from lidar (maps lidar-frame points into the world frame).
    pub world_from_lidar: Isometry3<f64>,
}

impl StampedPose {
    /// Bundles a stamp and a pose.
    pub fn new(stamp: f64, world_from_lidar: Isometry3<f64>) -> Self {
        Self {
            stamp,
            world_from_lidar,
        }
    }
}

/// Reads a TUM file.
///
/// Blank lines and lines starting with `#` are skipped. Every other line
/// must hold exactly 8 finite numbers. Quaternions are normalised; those
/// with norm below [`MIN_QUATERNION_NORM`] are rejected.
pub fn read_tum(path: impl AsRef<Path>) -> Result<Vec<StampedPose>, IoError> {
    let path = path.as_ref();
    let text = std::fs::read_to_string(path).map_err(|e| IoError::io(path, e))?;
    parse_tum(&text, path)
}

/// Parses the text of a TUM file; `name_for_errors` is used in messages.
pub fn parse_tum(
    text: &str,
    name_for_errors: impl AsRef<Path>,
) -> Result<Vec<StampedPose>, IoError> {
    let path = name_for_errors.as_ref();
    let mut poses = Vec::new();
    for (idx, raw) in text.lines().enumerate() {
        let line = idx + 1;
        let trimmed = raw.trim();
        if trimmed.is_empty() || trimmed.starts_with('#') {
            continue;
        }
        let words: Vec<&str> = trimmed.split_whitespace().collect();
        if words.len() != 8 {
            return Err(IoError::TumFieldCount {
                path: path.to_path_buf(),
                line,
                found: words.len(),
            });
        }
        let mut v = [0.0f64; 8];
        for ((slot, word), field) in v.iter_mut().zip(&words).zip(FIELD_NAMES) {
            *slot = word
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| IoError::TumNumber {
                    path: path.to_path_buf(),
                    line,
                    field,
                    value: word.to_string(),
                })?;
        }
        let [stamp, tx, ty, tz, qx, qy, qz, qw] = v;
        let q = Quaternion::new(qw, qx, qy, qz);
        let norm = q.norm();
        if !norm.is_finite() || norm < MIN_QUATERNION_NORM {
            return Err(IoError::TumQuaternion {
                path: path.to_path_buf(),
                line,
                norm,
            });
        }
        let rotation = UnitQuaternion::new_normalize(q);
        let iso = Isometry3::from_parts(Translation3::new(tx, ty, tz), rotation);
        poses.push(StampedPose::new(stamp, iso));
    }
    Ok(poses)
}

/// Writes poses as TUM lines `stamp tx ty tz qx qy qz qw`, every number
/// with 9 decimals. Fails without writing if any value is not finite.
pub fn write_tum(path: impl AsRef<Path>, poses: &[StampedPose]) -> Result<(), IoError> {
    let path = path.as_ref();
    let text = format_tum(poses, path)?;
    std::fs::write(path, text).map_err(|e| IoError::io(path, e))
}

/// Formats poses as the text [`write_tum`] writes.
pub fn format_tum(
    poses: &[StampedPose],
    name_for_errors: impl AsRef<Path>,
) -> Result<String, IoError> {
    let mut text = String::with_capacity(poses.len() * 100);
    for (index, pose) in poses.iter().enumerate() {
        let t = pose.world_from_lidar.translation.vector;
        let q = pose.world_from_lidar.rotation.coords; // [i, j, k, w]
        let values = [pose.stamp, t.x, t.y, t.z, q.x, q.y, q.z, q.w];
        if values.iter().any(|v| !v.is_finite()) {
            return Err(IoError::NonFinitePose {
                path: name_for_errors.as_ref().to_path_buf(),
                index,
            });
        }
        let [s, tx, ty, tz, qx, qy, qz, qw] = values;
        // Writing to a String cannot fail.
        let _ = writeln!(
            text,
            "{s:.9} {tx:.9} {ty:.9} {tz:.9} {qx:.9} {qy:.9} {qz:.9} {qw:.9}"
        );
    }
    Ok(text)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn pose(k: f64) -> StampedPose {
        let rot = UnitQuaternion::from_scaled_axis(Vector3::new(0.1 * k, -0.2, 0.3 + k));
        let iso = Isometry3::from_parts(Translation3::new(k, -2.5 * k, 1e3 + k), rot);
        StampedPose::new(1_700_000_000.123_456 + k, iso)
    }

    #[test]
    fn round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("poses.txt");
        let poses: Vec<_> = (0..5).map(|k| pose(k as f64)).collect();
        write_tum(&path, &poses).unwrap();
        let back = read_tum(&path).unwrap();
        assert_eq!(back.len(), poses.len());
        for (a, b) in poses.iter().zip(&back) {
            assert!((a.stamp - b.stamp).abs() < 1e-6);
            let d = a.world_from_lidar.inverse() * b.world_from_lidar;
            assert!(d.translation.vector.norm() < 1e-8);
            assert!(d.rotation.angle() < 1e-8);
        }
    }

    #[test]
    fn skips_comments_and_normalises() {
        let text = "# stamp tx ty tz qx qy qz qw\n\n  1 0 0 0 0 0 0 2\n   # indented\n2 1 2 3 0 0 0.0001 1.0005\n";
        let poses = parse_tum(text, "p.txt").unwrap();
        assert_eq!(poses.len(), 2);
        assert_eq!(
            poses[0].world_from_lidar.rotation,
            UnitQuaternion::identity()
        );
        assert_eq!(
            poses[1].world_from_lidar.translation.vector,
            Vector3::new(1.0, 2.0, 3.0)
        );
        assert!((poses[1].world_from_lidar.rotation.norm() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn errors_name_path_and_line() {
        let cases = [
            (
                "1 2 3\n",
                "p.txt: line 1: expected 8 numbers (stamp tx ty tz qx qy qz qw), found 3",
            ),
            ("# c\n1 2 3 4 0 0 0 1 9\n", "line 2: expected 8 numbers"),
            ("\n\n1 2 x 4 0 0 0 1\n", "p.txt: line 3: ty is 'x'"),
            (
                "1 nan 3 4 0 0 0 1\n",
                "line 1: tx is 'nan', expected a finite number",
            ),
            ("1 2 3 4 0 0 0 inf\n", "line 1: qw is 'inf'"),
            (
                "1 2 3 4 0 0 0 0\n",
                "p.txt: line 1: quaternion (qx qy qz qw) has norm 0",
            ),
        ];
        for (text, expected) in cases {
            let msg = parse_tum(text, "p.txt").unwrap_err().to_string();
            assert!(msg.contains(expected), "{msg:?} lacks {expected:?}");
        }
    }

    #[test]
    fn missing_file_and_non_finite_write() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("nope.txt");
        let msg = read_tum(&path).unwrap_err().to_string();
        assert!(msg.contains("nope.txt"), "{msg}");
        let mut bad = pose(1.0);
        bad.stamp = f64::NAN;
        let msg = write_tum(&path, &[pose(0.0), bad]).unwrap_err().to_string();
        assert!(msg.contains("nope.txt: pose 1"), "{msg}");
        assert!(!path.exists());
    }
}
