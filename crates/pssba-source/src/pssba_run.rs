//! Our own `pssba run` recordings as input: frame k is the k-th `/lidar/points` cloud (lidar
//! frame, foxglove `PointCloud`), its initial pose the k-th pose of the last
//! `/pssba/poses/initial` message (and its ground truth, when recorded, the k-th of the last
//! `/pssba/poses/ground_truth`). Two streaming passes: the poses first, then one cloud at a
//! time.

use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

use foxglove::Decode;
use foxglove::schemas::{PointCloud, PosesInFrame};
use nalgebra::Isometry3;

use crate::registry::SourceKind;
use crate::{Frame, FrameSource, Frames, Result, SourceError};
use pssba_recording::{cloud_point_times, cloud_points, isometries, topics};

/// The registry entry.
pub const KIND: SourceKind = SourceKind {
    name: "pssba run recording",
    looks_for: "an MCAP file with the /lidar/points and /pssba/poses/initial topics `pssba run` writes",
    detect: |path| {
        pssba_bag::Container::detect(path).is_some()
            && pssba_bag::Bag::open(path).is_ok_and(|bag| is_pssba_recording(&bag))
    },
    open: |path, options| {
        if options.poses.is_some() {
            return Err(SourceError::Settings(
                "--poses: a pssba run recording replays its own initial poses".into(),
            ));
        }
        tracing::info!(
            "{}: a pssba run recording; replaying its clouds and initial poses",
            path.display()
        );
        Ok(Box::new(RecordedRun::open(path)?))
    },
};

/// True when a recording's topics are those `pssba run` writes.
pub fn is_pssba_recording(bag: &pssba_bag::Bag) -> bool {
    bag.topic(topics::POINTS).is_some() && bag.topic(topics::INITIAL).is_some()
}

/// A `pssba run` recording, read as frames.
#[derive(Debug, Clone)]
pub struct RecordedRun {
    path: PathBuf,
    initial: Vec<Isometry3<f64>>,
    ground_truth: Vec<Isometry3<f64>>,
    /// Frames (clouds that have an initial pose).
    pub frames: usize,
    /// Points of the largest cloud.
    pub max_points: usize,
}

fn messages(path: &Path) -> Result<pssba_bag::mcap_stream::MessageReader<BufReader<File>>> {
    Ok(pssba_bag::mcap_message_reader(path)?)
}

impl RecordedRun {
    /// The first pass: the last trajectories, and the clouds' count and largest size.
    pub fn open(path: &Path) -> Result<RecordedRun> {
        let mut initial = Vec::new();
        let mut ground_truth = Vec::new();
        let (mut clouds, mut max_points) = (0usize, 0usize);
        for message in messages(path)? {
            let message =
                message.map_err(|e| SourceError::invalid(path, format!("bad record: {e}")))?;
            let topic = message.channel.topic.as_str();
            let slot = match topic {
                topics::INITIAL => &mut initial,
                topics::GROUND_TRUTH => &mut ground_truth,
                topics::POINTS => {
                    let cloud = PointCloud::decode(&message.data[..]).map_err(|e| {
                        SourceError::invalid(path, format!("topic {topic}, message {clouds}: {e}"))
                    })?;
                    let stride = (cloud.point_stride as usize).max(1);
                    max_points = max_points.max(cloud.data.len() / stride);
                    clouds += 1;
                    continue;
                }
                _ => continue,
            };
            let poses = PosesInFrame::decode(&message.data[..])
                .map_err(|e| SourceError::invalid(path, format!("decoding {topic}: {e}")))?;
            *slot = isometries(&poses);
        }
        if clouds == 0 || initial.is_empty() {
            return Err(SourceError::invalid(
                path,
                format!(
                    "a pssba recording without clouds ({clouds} on {}) or initial poses ({} on {})",
                    topics::POINTS,
                    initial.len(),
                    topics::INITIAL
                ),
            ));
        }
        if clouds != initial.len() {
            tracing::warn!(
                "{}: {clouds} clouds but {} initial poses; replaying the first {}",
                path.display(),
                initial.len(),
                clouds.min(initial.len())
            );
        }
        if ground_truth.len() != initial.len() {
            ground_truth.clear();
        }
        Ok(RecordedRun {
            path: path.to_path_buf(),
            frames: clouds.min(initial.len()),
            initial,
            ground_truth,
            max_points,
        })
    }

    /// The second pass: frames, one cloud decoded at a time.
    pub fn frames(&self) -> Result<impl Iterator<Item = Result<Frame>> + Send + 'static> {
        let run = self.clone();
        let mut reader = messages(&self.path)?;
        let mut k = 0usize;
        Ok(std::iter::from_fn(move || {
            if k >= run.frames {
                return None;
            }
            for message in reader.by_ref() {
                let message = match message {
                    Ok(m) => m,
                    Err(e) => {
                        return Some(Err(SourceError::invalid(
                            &run.path,
                            format!("bad record: {e}"),
                        )));
                    }
                };
                if message.channel.topic != topics::POINTS {
                    continue;
                }
                let frame = PointCloud::decode(&message.data[..])
                    .map_err(|e| e.to_string())
                    .and_then(|cloud| {
                        let times = cloud_point_times(&cloud)?;
                        Ok((cloud.timestamp, cloud_points(&cloud)?, times))
                    })
                    .map(|(stamp, points, point_times_s)| Frame {
                        stamp_s: stamp
                            .map_or(0.0, |t| f64::from(t.sec()) + f64::from(t.nsec()) * 1e-9),
                        points,
                        world_from_lidar: run.initial[k],
                        ground_truth: run.ground_truth.get(k).copied(),
                        point_times_s,
                    })
                    .map_err(|e| {
                        SourceError::invalid(
                            &run.path,
                            format!("topic {}, message {k}: {e}", topics::POINTS),
                        )
                    });
                k += 1;
                return Some(frame);
            }
            k = run.frames;
            Some(Err(SourceError::invalid(
                &run.path,
                format!("ended before cloud {k}"),
            )))
        }))
    }
}

impl FrameSource for RecordedRun {
    fn kind(&self) -> &'static str {
        KIND.name
    }

    fn describe(&self) -> String {
        self.path.display().to_string()
    }

    fn len(&self) -> Option<usize> {
        Some(self.frames)
    }

    fn max_points(&self) -> Option<usize> {
        Some(self.max_points)
    }

    fn frames_from(&self, first: usize) -> Result<Frames> {
        Ok(Box::new(self.frames()?.skip(first)))
    }

    fn metadata(&self) -> serde_json::Value {
        serde_json::json!({
            "source": self.describe(),
            "kind": KIND.name,
            "frames": self.frames,
        })
    }
}
