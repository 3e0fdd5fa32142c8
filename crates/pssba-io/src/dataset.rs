//! The dataset folder: `frames/*.pcd`, `poses.txt`, optional `gt.txt`.

use std::path::{Path, PathBuf};

use nalgebra::Point3;

use crate::tum::format_tum;
use crate::{
    IoError, PcdEncoding, PcdPrecision, StampedPose, pcd_point_count, pcd_to_bytes_with_times,
    read_pcd, read_pcd_with_times, read_tum,
};

/// Sub-folder holding one PCD per frame.
pub const FRAMES_DIR: &str = "frames";
/// Initial poses (TUM), one per frame.
pub const POSES_FILE: &str = "poses.txt";
/// Ground-truth poses (TUM), optional.
pub const GT_FILE: &str = "gt.txt";

/// An opened dataset folder. Frames are loaded lazily with
/// [`Dataset::load_frame`].
#[derive(Debug, Clone, PartialEq)]
pub struct Dataset {
    /// The dataset folder.
    pub dir: PathBuf,
    /// `frames/*.pcd`, sorted by file name.
    pub frame_paths: Vec<PathBuf>,
    /// Initial poses from `poses.txt`, one per frame.
    pub initial: Vec<StampedPose>,
    /// Ground truth from `gt.txt`, one per frame, if that file exists.
    pub ground_truth: Option<Vec<StampedPose>>,
}

fn dataset_err(path: &Path, message: String) -> IoError {
    IoError::Dataset {
        path: path.to_path_buf(),
        message,
    }
}

/// The `.pcd` files directly inside `frames`, sorted by file name.
fn list_frames(frames: &Path) -> Result<Vec<PathBuf>, IoError> {
    let entries = std::fs::read_dir(frames).map_err(|e| IoError::io(frames, e))?;
    let mut paths = Vec::new();
    for entry in entries {
        let path = entry.map_err(|e| IoError::io(frames, e))?.path();
        let is_pcd = path
            .extension()
            .is_some_and(|ext| ext.eq_ignore_ascii_case("pcd"));
        if is_pcd && path.is_file() {
            paths.push(path);
        }
    }
    paths.sort_by(|a, b| a.file_name().cmp(&b.file_name()));
    Ok(paths)
}

impl Dataset {
    /// Opens a dataset folder: lists `frames/*.pcd` (sorted by file name),
    /// reads `poses.txt` and, if present, `gt.txt`. Any `meta.json` is
    /// ignored.
    ///
    /// Fails if `frames/` is missing or has no `.pcd` file, if `poses.txt`
    /// is missing or malformed, or if a pose file's count differs from the
    /// number of frames.
    pub fn open(dir: impl AsRef<Path>) -> Result<Dataset, IoError> {
        let dir = dir.as_ref().to_path_buf();
        let frames_dir = dir.join(FRAMES_DIR);
        if !frames_dir.is_dir() {
            return Err(dataset_err(&dir, format!("missing folder {FRAMES_DIR}/")));
        }
        let frame_paths = list_frames(&frames_dir)?;
        if frame_paths.is_empty() {
            return Err(dataset_err(&frames_dir, "no .pcd files".into()));
        }
        let poses_path = dir.join(POSES_FILE);
        if !poses_path.is_file() {
            return Err(dataset_err(&dir, format!("missing {POSES_FILE}")));
        }
        let check_count = |path: &Path, poses: &[StampedPose]| {
            if poses.len() == frame_paths.len() {
                return Ok(());
            }
            let msg = format!(
                "has {} poses but {FRAMES_DIR}/ has {} .pcd files",
                poses.len(),
                frame_paths.len()
            );
            Err(dataset_err(path, msg))
        };
        let initial = read_tum(&poses_path)?;
        check_count(&poses_path, &initial)?;
        let gt_path = dir.join(GT_FILE);
        let ground_truth = if gt_path.exists() {
            let gt = read_tum(&gt_path)?;
            check_count(&gt_path, &gt)?;
            Some(gt)
        } else {
            None
        };
        Ok(Dataset {
            dir,
            frame_paths,
            initial,
            ground_truth,
        })
    }

    /// Number of frames.
    pub fn len(&self) -> usize {
        self.frame_paths.len()
    }

    /// True if the dataset has no frames (never the case after [`Dataset::open`]).
    pub fn is_empty(&self) -> bool {
        self.frame_paths.is_empty()
    }

    /// Reads frame `k` (sensor-frame points, NaN points included).
    pub fn load_frame(&self, k: usize) -> Result<Vec<Point3<f64>>, IoError> {
        let path = self.frame_paths.get(k).ok_or_else(|| IoError::FrameIndex {
            path: self.dir.clone(),
            index: k,
            count: self.frame_paths.len(),
        })?;
        read_pcd(path)
    }

    /// Reads frame `k` with its points' times after the frame's stamp (s), when its PCD has
    /// a `time` field ([`crate::TIME_FIELD`]).
    pub fn load_frame_with_times(&self, k: usize) -> Result<crate::TimedPoints, IoError> {
        let path = self.frame_paths.get(k).ok_or_else(|| IoError::FrameIndex {
            path: self.dir.clone(),
            index: k,
            count: self.frame_paths.len(),
        })?;
        read_pcd_with_times(path)
    }

    /// Points of the largest frame, from the frames' headers only (fast: no point is read).
    pub fn largest_frame_points(&self) -> Result<usize, IoError> {
        self.frame_paths
            .iter()
            .try_fold(0, |largest, path| Ok(largest.max(pcd_point_count(path)?)))
    }

    /// Creates a dataset folder at `dir`: `frames/000000.pcd, ...` (x y z
    /// as f32 in the given encoding), `poses.txt` and, if given, `gt.txt`.
    /// Returns the result of [`Dataset::open`] on the new folder.
    ///
    /// To avoid mixing with stale data, fails if `dir/frames`,
    /// `dir/poses.txt` or `dir/gt.txt` already exist. Also fails (before
    /// writing anything) if `frames` is empty, if a pose count differs from
    /// the frame count, or if a pose is not finite. `dir` itself may exist.
    pub fn write(
        dir: impl AsRef<Path>,
        frames: &[Vec<Point3<f64>>],
        initial: &[StampedPose],
        gt: Option<&[StampedPose]>,
        encoding: PcdEncoding,
    ) -> Result<Dataset, IoError> {
        Self::write_with_times(dir, frames, None, initial, gt, encoding)
    }

    /// [`Dataset::write`], with each frame's point times (s after its stamp, one per point)
    /// in a `time` field of its PCD when `times_s` is given.
    pub fn write_with_times(
        dir: impl AsRef<Path>,
        frames: &[Vec<Point3<f64>>],
        times_s: Option<&[Vec<f32>]>,
        initial: &[StampedPose],
        gt: Option<&[StampedPose]>,
        encoding: PcdEncoding,
    ) -> Result<Dataset, IoError> {
        let dir = dir.as_ref().to_path_buf();
        if let Some(times) = times_s {
            let counts_differ = times.len() != frames.len()
                || times.iter().zip(frames).any(|(t, f)| t.len() != f.len());
            if counts_differ {
                let msg = "point times: not one per point of every frame".to_string();
                return Err(dataset_err(&dir, msg));
            }
        }
        let frames_dir = dir.join(FRAMES_DIR);
        let poses_path = dir.join(POSES_FILE);
        let gt_path = dir.join(GT_FILE);
        if frames.is_empty() {
            return Err(dataset_err(&dir, "no frames to write".into()));
        }
        for (name, count) in [
            (POSES_FILE, Some(initial.len())),
            (GT_FILE, gt.map(<[_]>::len)),
        ] {
            if let Some(count) = count.filter(|&c| c != frames.len()) {
                let msg = format!("{name}: {count} poses given for {} frames", frames.len());
                return Err(dataset_err(&dir, msg));
            }
        }
        for existing in [&frames_dir, &poses_path, &gt_path] {
            if existing.exists() {
                let msg = "already exists; refusing to overwrite a dataset".to_string();
                return Err(dataset_err(existing, msg));
            }
        }
        let poses_text = format_tum(initial, &poses_path)?;
        let gt_text = gt.map(|g| format_tum(g, &gt_path)).transpose()?;
        std::fs::create_dir_all(&frames_dir).map_err(|e| IoError::io(&frames_dir, e))?;
        for (k, points) in frames.iter().enumerate() {
            let path = frames_dir.join(format!("{k:06}.pcd"));
            let times = times_s.map(|t| t[k].as_slice());
            let bytes = pcd_to_bytes_with_times(points, times, encoding, PcdPrecision::F32, &path)?;
            std::fs::write(&path, bytes).map_err(|e| IoError::io(&path, e))?;
        }
        std::fs::write(&poses_path, poses_text).map_err(|e| IoError::io(&poses_path, e))?;
        if let Some(text) = gt_text {
            std::fs::write(&gt_path, text).map_err(|e| IoError::io(&gt_path, e))?;
        }
        Dataset::open(&dir)
    }
}
