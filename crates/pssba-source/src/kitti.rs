//! A KITTI odometry sequence folder, as odometries such as kiss-icp read and write it:
//! - `velodyne/NNNNNN.bin`: one scan per file, float32 `x y z intensity` (m), velodyne frame;
//! - `calib.txt`: the line `Tr:` holds cam0_from_velo, 12 numbers, a 3x4 matrix row by row;
//! - `times.txt`: each scan's time (s), one per line; the output TUM is stamped with these;
//! - the initial poses: a KITTI pose file (one 3x4 matrix per line, row by row: the left
//!   camera of scan 0 from the left camera of scan k): `--poses FILE`, else `poses.txt` in the
//!   folder, else the folder's only other `*.txt` (not `calib.txt`, `times.txt`, `gt.txt`);
//! - optionally `gt.txt`, ground truth in the same format.
//!
//! KITTI poses are in the camera convention; the velodyne ones are
//! `world_from_lidar_k = Tr^-1 P_k Tr` with `Tr` = cam0_from_velo: the world is the velodyne
//! frame of the pose file's origin (scan 0 for KITTI's own files).

use crate::registry::{OpenOptions, SourceKind};
use crate::{Frame, FrameSource, Frames, Result, SourceError};
use nalgebra::{Isometry3, Matrix3, Point3, Translation3, UnitQuaternion, Vector3};
use std::path::{Path, PathBuf};
use std::sync::Arc;

const VELODYNE_DIR: &str = "velodyne";
const CALIB_FILE: &str = "calib.txt";
const TIMES_FILE: &str = "times.txt";
const POSES_FILE: &str = "poses.txt";
const GT_FILE: &str = "gt.txt";
/// Bytes of one point: x, y, z, intensity as float32.
const POINT_BYTES: usize = 16;
/// Largest accepted deviation of a pose's rotation block from a rotation (Frobenius norm of
/// `R^T R - I`): KITTI's files carry 6 to 9 significant digits.
const MAX_ROTATION_DEVIATION: f64 = 1e-3;

/// The registry entry.
pub const KIND: SourceKind = SourceKind {
    name: "KITTI odometry sequence",
    looks_for: "a folder with velodyne/*.bin, calib.txt (Tr), times.txt and a KITTI pose \
                file (poses.txt, the folder's only other .txt, or --poses FILE)",
    detect: |path| path.join(VELODYNE_DIR).is_dir() && path.join(CALIB_FILE).is_file(),
    open: |path, options| Ok(Box::new(KittiSequence::open(path, options)?)),
};

/// An opened KITTI sequence: scans listed, poses and times read; points read per frame.
#[derive(Debug)]
pub struct KittiSequence {
    dir: PathBuf,
    scans: Arc<Vec<PathBuf>>,
    stamps_s: Arc<Vec<f64>>,
    world_from_lidar: Arc<Vec<Isometry3<f64>>>,
    ground_truth: Option<Arc<Vec<Isometry3<f64>>>>,
    poses_file: PathBuf,
}

impl KittiSequence {
    fn open(dir: &Path, options: &OpenOptions) -> Result<Self> {
        let scans = list_scans(&dir.join(VELODYNE_DIR))?;
        let calib = dir.join(CALIB_FILE);
        let cam0_from_velo = read_calib_tr(&calib)?;
        let times = dir.join(TIMES_FILE);
        let stamps_s = read_times(&times)?;
        let poses_file = match &options.poses {
            Some(file) => file.clone(),
            None => find_poses_file(dir)?,
        };
        let in_velodyne = |file: &Path| -> Result<Vec<Isometry3<f64>>> {
            Ok(read_kitti_poses(file)?
                .into_iter()
                .map(|cam0_from_cam_k| cam0_from_velo.inverse() * cam0_from_cam_k * cam0_from_velo)
                .collect())
        };
        let world_from_lidar = in_velodyne(&poses_file)?;
        let gt_path = dir.join(GT_FILE);
        let ground_truth = gt_path
            .is_file()
            .then(|| in_velodyne(&gt_path))
            .transpose()?;
        for (file, count) in [
            (&times, stamps_s.len()),
            (&poses_file, world_from_lidar.len()),
            (
                &gt_path,
                ground_truth.as_ref().map_or(scans.len(), Vec::len),
            ),
        ] {
            if count != scans.len() {
                return Err(SourceError::invalid(
                    file,
                    format!(
                        "has {count} lines but {VELODYNE_DIR}/ has {} .bin scans",
                        scans.len()
                    ),
                ));
            }
        }
        Ok(Self {
            dir: dir.to_path_buf(),
            scans: Arc::new(scans),
            stamps_s: Arc::new(stamps_s),
            world_from_lidar: Arc::new(world_from_lidar),
            ground_truth: ground_truth.map(Arc::new),
            poses_file,
        })
    }
}

impl FrameSource for KittiSequence {
    fn kind(&self) -> &'static str {
        KIND.name
    }

    fn describe(&self) -> String {
        self.dir.display().to_string()
    }

    fn len(&self) -> Option<usize> {
        Some(self.scans.len())
    }

    /// From the files' sizes: 16 bytes a point.
    fn max_points(&self) -> Option<usize> {
        self.scans
            .iter()
            .map(|scan| std::fs::metadata(scan).map(|m| m.len() as usize / POINT_BYTES))
            .try_fold(0, |largest, n| n.map(|n| largest.max(n)))
            .ok()
    }

    fn frames_from(&self, first: usize) -> Result<Frames> {
        let (scans, stamps, poses) = (
            Arc::clone(&self.scans),
            Arc::clone(&self.stamps_s),
            Arc::clone(&self.world_from_lidar),
        );
        let ground_truth = self.ground_truth.clone();
        Ok(Box::new((first.min(scans.len())..scans.len()).map(
            move |k| {
                Ok(Frame {
                    stamp_s: stamps[k],
                    points: read_scan(&scans[k])?,
                    world_from_lidar: poses[k],
                    ground_truth: ground_truth.as_ref().map(|g| g[k]),
                    // KITTI's scans are de-skewed already.
                    point_times_s: None,
                })
            },
        )))
    }

    fn metadata(&self) -> serde_json::Value {
        serde_json::json!({
            "source": self.describe(),
            "kind": KIND.name,
            "frames": self.scans.len(),
            "poses_file": self.poses_file.display().to_string(),
            "ground_truth": self.ground_truth.is_some(),
            "poses": "world_from_lidar = Tr^-1 P_k Tr (velodyne frame), Tr from calib.txt",
            "stamps": "times.txt (s)",
        })
    }
}

/// `velodyne/*.bin`, sorted by file name.
fn list_scans(folder: &Path) -> Result<Vec<PathBuf>> {
    let io = |e| SourceError::invalid(folder, format!("cannot list: {e}"));
    let mut scans = Vec::new();
    for entry in std::fs::read_dir(folder).map_err(io)? {
        let path = entry.map_err(io)?.path();
        if path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("bin"))
            && path.is_file()
        {
            scans.push(path);
        }
    }
    if scans.is_empty() {
        return Err(SourceError::invalid(folder, "no .bin scans"));
    }
    scans.sort_by(|a, b| a.file_name().cmp(&b.file_name()));
    Ok(scans)
}

/// One scan's points (intensity dropped).
fn read_scan(path: &Path) -> Result<Vec<Point3<f64>>> {
    let bytes = std::fs::read(path).map_err(|e| SourceError::invalid(path, e.to_string()))?;
    if !bytes.len().is_multiple_of(POINT_BYTES) {
        return Err(SourceError::invalid(
            path,
            format!(
                "{} bytes is not a whole number of {POINT_BYTES}-byte points (float32 x y z intensity)",
                bytes.len()
            ),
        ));
    }
    let float = |b: &[u8]| f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    Ok(bytes
        .chunks_exact(POINT_BYTES)
        .map(|p| Point3::new(float(&p[0..4]), float(&p[4..8]), float(&p[8..12])))
        .collect())
}

fn read_text(path: &Path) -> Result<String> {
    std::fs::read_to_string(path).map_err(|e| SourceError::invalid(path, e.to_string()))
}

/// Whitespace-separated finite numbers of one line.
fn numbers(text: &str, path: &Path, line: usize) -> Result<Vec<f64>> {
    text.split_whitespace()
        .map(|word| {
            word.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    SourceError::invalid(
                        path,
                        format!("line {line}: '{word}' is not a finite number"),
                    )
                })
        })
        .collect()
}

/// A 3x4 matrix, row by row, as a rigid transform; the error says what is wrong.
fn isometry_from_3x4(v: &[f64]) -> std::result::Result<Isometry3<f64>, String> {
    let [r00, r01, r02, tx, r10, r11, r12, ty, r20, r21, r22, tz] = v[..] else {
        return Err(format!(
            "expected 12 numbers (a 3x4 matrix row by row), got {}",
            v.len()
        ));
    };
    let r = Matrix3::new(r00, r01, r02, r10, r11, r12, r20, r21, r22);
    let deviation = (r.transpose() * r - Matrix3::identity()).norm();
    if deviation > MAX_ROTATION_DEVIATION || r.determinant() <= 0.0 {
        return Err(format!(
            "the 3x3 block is not a rotation (|R^T R - I| = {deviation:.2e}, det {:.4})",
            r.determinant()
        ));
    }
    Ok(Isometry3::from_parts(
        Translation3::from(Vector3::new(tx, ty, tz)),
        UnitQuaternion::from_matrix(&r),
    ))
}

/// cam0_from_velo from the `Tr:` line.
fn read_calib_tr(path: &Path) -> Result<Isometry3<f64>> {
    let text = read_text(path)?;
    for (idx, line) in text.lines().enumerate() {
        if let Some(rest) = line.trim().strip_prefix("Tr:") {
            let values = numbers(rest, path, idx + 1)?;
            return isometry_from_3x4(&values)
                .map_err(|e| SourceError::invalid(path, format!("line {} (Tr): {e}", idx + 1)));
        }
    }
    Err(SourceError::invalid(
        path,
        "no 'Tr:' line (cam0 from velodyne, 12 numbers)",
    ))
}

/// One time (s) per non-empty line.
fn read_times(path: &Path) -> Result<Vec<f64>> {
    let text = read_text(path)?;
    let mut stamps = Vec::new();
    for (idx, line) in text.lines().enumerate() {
        match numbers(line, path, idx + 1)?[..] {
            [] => {}
            [t] => stamps.push(t),
            ref more => {
                return Err(SourceError::invalid(
                    path,
                    format!(
                        "line {}: expected one time (s), got {} numbers",
                        idx + 1,
                        more.len()
                    ),
                ));
            }
        }
    }
    Ok(stamps)
}

/// A KITTI pose file: one 3x4 matrix per non-empty line.
fn read_kitti_poses(path: &Path) -> Result<Vec<Isometry3<f64>>> {
    let text = read_text(path)?;
    let mut poses = Vec::new();
    for (idx, line) in text.lines().enumerate() {
        let values = numbers(line, path, idx + 1)?;
        if values.is_empty() {
            continue;
        }
        poses.push(
            isometry_from_3x4(&values)
                .map_err(|e| SourceError::invalid(path, format!("line {}: {e}", idx + 1)))?,
        );
    }
    Ok(poses)
}

/// `poses.txt`, else the folder's only other `.txt`.
fn find_poses_file(dir: &Path) -> Result<PathBuf> {
    let named = dir.join(POSES_FILE);
    if named.is_file() {
        return Ok(named);
    }
    let others: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| SourceError::invalid(dir, format!("cannot list: {e}")))?
        .filter_map(|entry| entry.ok().map(|e| e.path()))
        .filter(|p| {
            p.is_file()
                && p.extension().is_some_and(|e| e == "txt")
                && p.file_name().is_some_and(|name| {
                    ![CALIB_FILE, TIMES_FILE, GT_FILE].contains(&name.to_string_lossy().as_ref())
                })
        })
        .collect();
    match &others[..] {
        [only] => Ok(only.clone()),
        [] => Err(SourceError::invalid(
            dir,
            format!(
                "a KITTI sequence without initial poses: put them in {POSES_FILE} (KITTI format, \
                 as kiss-icp writes them) or pass --poses FILE"
            ),
        )),
        several => Err(SourceError::invalid(
            dir,
            format!(
                "several .txt files could hold the initial poses ({}): name one with --poses FILE",
                several
                    .iter()
                    .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_3x4_matrix_must_hold_a_rotation() {
        let identity = [1., 0., 0., 1., 0., 1., 0., 2., 0., 0., 1., 3.];
        let pose = isometry_from_3x4(&identity).expect("identity rotation");
        assert_eq!(pose.translation.vector, Vector3::new(1.0, 2.0, 3.0));
        let scaled = [2., 0., 0., 0., 0., 2., 0., 0., 0., 0., 2., 0.];
        assert!(
            isometry_from_3x4(&scaled)
                .expect_err("scaled")
                .contains("not a rotation")
        );
        let mirrored = [-1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0.];
        assert!(isometry_from_3x4(&mirrored).is_err());
        assert!(
            isometry_from_3x4(&identity[..11])
                .expect_err("short")
                .contains("12 numbers")
        );
    }
}
