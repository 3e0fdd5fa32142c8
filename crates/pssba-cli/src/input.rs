//! The input flags: how `adjust`, `import`, `inspect` and `run` open an input through
//! `pssba-source`'s registry (a dataset folder, a KITTI sequence, a robot recording or a
//! `pssba run` recording, told apart by content).

use crate::cli::RecordingArgs;
use anyhow::{Context, bail};
use nalgebra::{Isometry3, Point3, Quaternion, Translation3, UnitQuaternion};
use pssba_config::RecordingConfig;
use pssba_io::StampedPose;
use pssba_source::{FrameSource, OpenOptions};
use std::path::{Path, PathBuf};

impl RecordingArgs {
    /// The reader's options, checked: these flags over the config's `[recording]` table.
    pub fn options(&self, config: &RecordingConfig) -> anyhow::Result<pssba_bag::RecordingOptions> {
        let extrinsic = match (&self.extrinsic, config.extrinsic.as_slice()) {
            (Some(text), _) => Some(parse_extrinsic(text)?),
            (None, []) => None,
            (None, values) => Some(extrinsic_from(values, "[recording] extrinsic")?),
        };
        let topic = |flag: &Option<String>, key: &str| {
            flag.clone()
                .or_else(|| (!key.is_empty()).then(|| key.to_string()))
        };
        let max_pose_gap = self.max_pose_gap.unwrap_or(config.max_pose_gap_s);
        let frames = self.frames.as_deref().map(parse_range).transpose()?;
        let point_time = match &self.point_time {
            Some(text) => text
                .parse()
                .map_err(|e| anyhow::anyhow!("--point-time '{text}': {e}"))?,
            None => config
                .point_time
                .parse()
                .map_err(|e| anyhow::anyhow!("[recording] point_time: {e}"))?,
        };
        for (name, value) in [("--start", self.start), ("--duration", self.duration)] {
            if let Some(v) = value.filter(|v| !v.is_finite() || *v < 0.0) {
                bail!("{name} is {v}, expected seconds >= 0");
            }
        }
        if !(max_pose_gap.is_finite() && max_pose_gap > 0.0) {
            bail!(
                "the max pose gap is {max_pose_gap} s (--max-pose-gap or [recording] \
                 max_pose_gap_s), expected > 0"
            );
        }
        Ok(pssba_bag::RecordingOptions {
            points_topic: topic(&self.points_topic, &config.points_topic),
            poses_topic: topic(&self.poses_topic, &config.poses_topic),
            extrinsic,
            max_pose_gap_s: max_pose_gap,
            start_s: self.start,
            duration_s: self.duration,
            frames,
            point_time,
        })
    }

    /// How to open an input: these flags over the config's `[recording]` table.
    pub fn open_options(&self, config: &RecordingConfig) -> anyhow::Result<OpenOptions> {
        Ok(OpenOptions {
            recording: self.options(config)?,
            poses: self.poses.clone(),
        })
    }

    /// Opens the input at `path` with the source that recognises it.
    pub fn open(
        &self,
        path: &Path,
        config: &RecordingConfig,
    ) -> anyhow::Result<Box<dyn FrameSource>> {
        Ok(pssba_source::open(path, &self.open_options(config)?)?)
    }
}

/// `tx,ty,tz,qx,qy,qz,qw` as body_from_lidar.
fn parse_extrinsic(text: &str) -> anyhow::Result<Isometry3<f64>> {
    let values: Vec<f64> = text
        .split(',')
        .map(|v| v.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .with_context(|| {
            format!("--extrinsic '{text}': expected 7 numbers tx,ty,tz,qx,qy,qz,qw")
        })?;
    extrinsic_from(&values, &format!("--extrinsic '{text}'"))
}

/// `[tx, ty, tz, qx, qy, qz, qw]` as body_from_lidar; `what` names the origin in errors.
fn extrinsic_from(values: &[f64], what: &str) -> anyhow::Result<Isometry3<f64>> {
    let [tx, ty, tz, qx, qy, qz, qw] = values[..] else {
        bail!(
            "{what}: expected 7 numbers tx,ty,tz,qx,qy,qz,qw, got {}",
            values.len()
        );
    };
    let q = Quaternion::new(qw, qx, qy, qz);
    if values.iter().any(|v| !v.is_finite()) || (q.norm() - 1.0).abs() > 1e-3 {
        bail!(
            "{what}: the numbers must be finite and the quaternion unit (norm {})",
            q.norm()
        );
    }
    Ok(Isometry3::from_parts(
        Translation3::new(tx, ty, tz),
        UnitQuaternion::from_quaternion(q),
    ))
}

/// `A..B` (B excluded).
fn parse_range(text: &str) -> anyhow::Result<std::ops::Range<usize>> {
    let parsed = text
        .split_once("..")
        .and_then(|(a, b)| Some((a.trim().parse().ok()?, b.trim().parse().ok()?)));
    match parsed {
        Some((a, b)) if a < b => Ok(a..b),
        _ => bail!("--frames '{text}': expected A..B with A < B (0-based, B excluded)"),
    }
}

/// Frames and poses loaded whole, for an in-process adjustment.
#[derive(Debug)]
pub struct Loaded {
    /// Points per frame, sensor frame.
    pub frames: Vec<Vec<Point3<f64>>>,
    /// Initial poses with the frames' stamps.
    pub initial: Vec<StampedPose>,
    /// Ground truth, when the input has it.
    pub ground_truth: Option<Vec<StampedPose>>,
    /// Each point's time after its frame's stamp (s), when some frame has point times (the
    /// others' points all at 0).
    pub point_times_s: Option<Vec<Vec<f32>>>,
    /// Where outputs go by default, and their name's prefix.
    pub default_out: (PathBuf, String),
}

/// Reads every frame of the input at `path`.
pub fn load(path: &Path, source: &dyn FrameSource) -> anyhow::Result<Loaded> {
    let frames = source.read_all()?;
    let total = frames.len();
    let mut loaded = Loaded {
        frames: Vec::with_capacity(total),
        initial: Vec::with_capacity(total),
        ground_truth: Some(Vec::with_capacity(total)),
        point_times_s: None,
        default_out: default_out(path),
    };
    let any_times = frames.iter().any(|f| f.point_times_s.is_some());
    let mut times = Vec::with_capacity(if any_times { total } else { 0 });
    for frame in frames {
        if any_times {
            let n = frame.points.len();
            times.push(frame.point_times_s.unwrap_or_else(|| vec![0.0; n]));
        }
        loaded.frames.push(frame.points);
        loaded
            .initial
            .push(StampedPose::new(frame.stamp_s, frame.world_from_lidar));
        match (frame.ground_truth, &mut loaded.ground_truth) {
            (Some(gt), Some(list)) => list.push(StampedPose::new(frame.stamp_s, gt)),
            _ => loaded.ground_truth = None,
        }
    }
    loaded.point_times_s = any_times.then_some(times);
    Ok(loaded)
}

/// Outputs of a recording `.../NAME.bag` go to `.../NAME_...`; of a folder, inside it.
fn default_out(path: &Path) -> (PathBuf, String) {
    if path.is_dir() {
        return (path.to_path_buf(), String::new());
    }
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    (dir, format!("{stem}_"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn extrinsic_and_range_arguments() {
        let t = parse_extrinsic("0.1, -0.05, 0.2, 0, 0, 0, 1").expect("parses");
        assert_eq!(t.translation.vector.y, -0.05);
        assert!(parse_extrinsic("1,2,3").is_err());
        assert!(parse_extrinsic("0,0,0,0,0,0,2").is_err());
        assert_eq!(parse_range("3..10").expect("range"), 3..10);
        for bad in ["10..3", "3", "a..b"] {
            assert!(parse_range(bad).is_err(), "{bad}");
        }
    }
}
