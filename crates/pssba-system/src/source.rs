//! Where frames come from. A [`SourceSpec`] is one value carried from the command line through
//! the launcher to the ingest stage (as one `--source` argument); [`SourceSpec::open`] gives a
//! [`FrameSource`]: an iterator of frames with an optional length and, when the source can
//! tell before the first frame, its largest frame (which sizes the frames service). A new kind
//! of source is a new variant here and nothing else.

use anyhow::{Context, bail};
use nalgebra::{Isometry3, Point3};
use std::path::PathBuf;

/// The built-in simulated scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimSpec {
    /// Frames.
    pub frames: usize,
    /// Points per frame.
    pub points_per_frame: usize,
    /// Seed of scene noise and pose perturbation.
    pub seed: u64,
}

/// A frame source, as named on the command line.
#[derive(Debug, Clone, PartialEq)]
pub enum SourceSpec {
    /// A dataset folder (frames/*.pcd, poses.txt, optional gt.txt).
    Dataset(PathBuf),
    /// The built-in curved scene, perturbed like `pssba demo`.
    Simulated(SimSpec),
    /// A robot recording (ROS 1 bag, rosbag2 folder, MCAP, `.db3`) or a `pssba run` recording.
    Recording(RecordingSpec),
    /// Live frames from processes outside the system, on the frames service of this instance
    /// (`pssba run --input live --instance NAME`; docs/interface.md). No ingest stage.
    Live(String),
}

/// A recording and how to read frames from it.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RecordingSpec {
    /// The `.bag`, rosbag2 folder, `.mcap` or `.db3`.
    pub path: PathBuf,
    /// Topics, extrinsic, pose gap and the part to read (ignored for `pssba run` recordings,
    /// which carry their own poses).
    pub options: pssba_bag::RecordingOptions,
}

/// A recording opened for frames: a robot recording, or one of ours.
#[derive(Debug)]
pub enum OpenedRecording {
    /// A ROS recording.
    Ros(Box<pssba_bag::Recording>),
    /// A `pssba run` recording.
    Pssba(crate::replay::RecordedRun),
}

impl RecordingSpec {
    /// Opens it: our own recordings are told apart by their topics.
    pub fn open(&self) -> anyhow::Result<OpenedRecording> {
        let bag = pssba_bag::Bag::open(&self.path)?;
        if crate::replay::is_pssba_recording(&bag) {
            tracing::info!(
                "{}: a pssba run recording; replaying its clouds and initial poses",
                self.path.display()
            );
            return Ok(OpenedRecording::Pssba(crate::replay::RecordedRun::open(
                &self.path,
            )?));
        }
        let recording = pssba_bag::Recording::open(&self.path, &self.options)?;
        Ok(OpenedRecording::Ros(Box::new(recording)))
    }
}

impl OpenedRecording {
    /// Number of frames.
    pub fn len(&self) -> usize {
        match self {
            OpenedRecording::Ros(r) => r.frames.len(),
            OpenedRecording::Pssba(r) => r.frames,
        }
    }

    /// True without frames (never after a successful open).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Points of the largest frame, non-finite points included.
    pub fn max_points(&self) -> usize {
        match self {
            OpenedRecording::Ros(r) => r.max_points(),
            OpenedRecording::Pssba(r) => r.max_points,
        }
    }

    /// The frames, decoded one at a time.
    pub fn frames(
        &self,
    ) -> anyhow::Result<Box<dyn Iterator<Item = anyhow::Result<SourceFrame>> + Send>> {
        Ok(match self {
            OpenedRecording::Ros(r) => Box::new(r.frames()?.map(|frame| {
                let frame = frame?;
                Ok(SourceFrame {
                    stamp_s: frame.stamp_s(),
                    points: frame.points,
                    world_from_lidar: frame.world_from_lidar,
                    ground_truth: None,
                })
            })),
            OpenedRecording::Pssba(r) => Box::new(r.frames()?),
        })
    }
}

/// One frame to publish.
#[derive(Debug, Clone)]
pub struct SourceFrame {
    /// Stamp (s).
    pub stamp_s: f64,
    /// Points in the lidar frame (m).
    pub points: Vec<Point3<f64>>,
    /// Initial pose.
    pub world_from_lidar: Isometry3<f64>,
    /// Ground truth, when known.
    pub ground_truth: Option<Isometry3<f64>>,
}

/// An opened source.
pub struct FrameSource {
    frames: Box<dyn Iterator<Item = anyhow::Result<SourceFrame>> + Send>,
    len: Option<usize>,
    max_points: Option<usize>,
}

impl std::fmt::Debug for FrameSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FrameSource")
            .field("len", &self.len)
            .field("max_points", &self.max_points)
            .finish_non_exhaustive()
    }
}

impl FrameSource {
    /// Frames in the source, when known.
    pub fn frame_count(&self) -> Option<usize> {
        self.len
    }

    /// Points of the largest frame, when known before the first frame.
    pub fn max_points(&self) -> Option<usize> {
        self.max_points
    }
}

impl Iterator for FrameSource {
    type Item = anyhow::Result<SourceFrame>;

    fn next(&mut self) -> Option<Self::Item> {
        self.frames.next()
    }
}

/// The frames of a simulated source (the same scene and perturbation as `pssba demo`).
pub fn simulated_frames(spec: &SimSpec) -> Vec<SourceFrame> {
    let scene = pssba_sim::SceneSpec {
        frames: spec.frames,
        points_per_frame: spec.points_per_frame,
        seed: spec.seed,
        ..pssba_sim::SceneSpec::default()
    };
    let window = pssba_sim::curved_window(&scene);
    let initial =
        pssba_sim::perturb_poses(&window.ground_truth, 0.2, 1.0, spec.seed.wrapping_add(100));
    window
        .frames
        .into_iter()
        .zip(initial)
        .zip(window.ground_truth)
        .enumerate()
        .map(|(k, ((points, world_from_lidar), gt))| SourceFrame {
            stamp_s: k as f64 * 0.1,
            points,
            world_from_lidar,
            ground_truth: Some(gt),
        })
        .collect()
}

impl SourceSpec {
    /// Checks what can be checked before any process starts (the folder opens, every frame's
    /// header reads, the sizes make sense); the error names the folder, file or value.
    pub fn check(&self) -> anyhow::Result<()> {
        match self {
            SourceSpec::Dataset(dir) => {
                pssba_io::Dataset::open(dir)?.largest_frame_points()?;
            }
            SourceSpec::Recording(spec) => {
                spec.open()?;
            }
            SourceSpec::Live(instance) => pssba_client::instance::check(instance)?,
            SourceSpec::Simulated(spec) => {
                if spec.frames < 2 || spec.points_per_frame == 0 {
                    bail!(
                        "the simulated scene needs at least 2 frames and 1 point per frame \
                         (got {} and {})",
                        spec.frames,
                        spec.points_per_frame
                    );
                }
            }
        }
        Ok(())
    }

    /// Opens the source. A dataset folder's frame headers are read here (not the points), so
    /// its largest frame is known before the first frame is sent.
    pub fn open(&self) -> anyhow::Result<FrameSource> {
        self.open_from(0)
    }

    /// Opens the source with its frames from index `first` on (a restarted ingest stage
    /// resuming); `frame_count` still counts every frame. Skipped dataset frames are not read.
    pub fn open_from(&self, first: usize) -> anyhow::Result<FrameSource> {
        match self {
            SourceSpec::Dataset(dir) => {
                let dataset = pssba_io::Dataset::open(dir)?;
                let max_points = dataset.largest_frame_points()?;
                let len = dataset.len();
                let frames = (first.min(len)..len).map(move |k| {
                    Ok(SourceFrame {
                        stamp_s: dataset.initial[k].stamp,
                        points: dataset.load_frame(k)?,
                        world_from_lidar: dataset.initial[k].world_from_lidar,
                        ground_truth: dataset.ground_truth.as_ref().map(|g| g[k].world_from_lidar),
                    })
                });
                Ok(FrameSource {
                    frames: Box::new(frames),
                    len: Some(len),
                    max_points: Some(max_points),
                })
            }
            SourceSpec::Live(instance) => {
                bail!(
                    "live instance {instance}: its frames come from outside producers, not from ingest"
                )
            }
            SourceSpec::Recording(spec) => {
                let recording = spec.open()?;
                Ok(FrameSource {
                    len: Some(recording.len()),
                    max_points: Some(recording.max_points()),
                    frames: Box::new(recording.frames()?.skip(first)),
                })
            }
            SourceSpec::Simulated(spec) => {
                self.check()?;
                tracing::info!(
                    "simulating the curved scene: {} frames x {} points, seed {}",
                    spec.frames,
                    spec.points_per_frame,
                    spec.seed
                );
                let frames = simulated_frames(spec);
                let max_points = frames.iter().map(|f| f.points.len()).max().unwrap_or(0);
                Ok(FrameSource {
                    len: Some(frames.len()),
                    max_points: Some(max_points),
                    frames: Box::new(frames.into_iter().skip(first).map(Ok)),
                })
            }
        }
    }

    /// What the source is, for logs and summaries.
    pub fn describe(&self) -> String {
        match self {
            SourceSpec::Dataset(dir) => dir.display().to_string(),
            SourceSpec::Recording(spec) => spec.path.display().to_string(),
            SourceSpec::Live(instance) => format!(
                "live frames from outside producers on pssba/{instance}/frames (iceoryx2 prefix {})",
                pssba_client::instance::prefix(instance)
            ),
            SourceSpec::Simulated(spec) => format!(
                "built-in curved scene, {} frames x {} points, seed {}",
                spec.frames, spec.points_per_frame, spec.seed
            ),
        }
    }
}

const DATASET_PREFIX: &str = "dataset:";
const SIM_PREFIX: &str = "sim:";
const RECORDING_PREFIX: &str = "recording:";
const LIVE_PREFIX: &str = "live:";

/// `dataset:DIR`, `sim:FRAMES,POINTS,SEED` or `recording:{JSON of RecordingSpec}`: the
/// `--source` argument of `pssba stage ingest`.
impl std::fmt::Display for SourceSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SourceSpec::Dataset(dir) => write!(f, "{DATASET_PREFIX}{}", dir.display()),
            SourceSpec::Live(instance) => write!(f, "{LIVE_PREFIX}{instance}"),
            SourceSpec::Recording(spec) => {
                let json = serde_json::to_string(spec).map_err(|_| std::fmt::Error)?;
                write!(f, "{RECORDING_PREFIX}{json}")
            }
            SourceSpec::Simulated(s) => write!(
                f,
                "{SIM_PREFIX}{},{},{}",
                s.frames, s.points_per_frame, s.seed
            ),
        }
    }
}

impl std::str::FromStr for SourceSpec {
    type Err = anyhow::Error;

    fn from_str(text: &str) -> anyhow::Result<Self> {
        if let Some(dir) = text.strip_prefix(DATASET_PREFIX) {
            return Ok(SourceSpec::Dataset(PathBuf::from(dir)));
        }
        if let Some(instance) = text.strip_prefix(LIVE_PREFIX) {
            return Ok(SourceSpec::Live(instance.to_string()));
        }
        if let Some(json) = text.strip_prefix(RECORDING_PREFIX) {
            let spec = serde_json::from_str(json)
                .with_context(|| format!("source '{text}': expected recording:{{JSON}}"))?;
            return Ok(SourceSpec::Recording(spec));
        }
        if let Some(values) = text.strip_prefix(SIM_PREFIX) {
            let numbers: Vec<u64> = values
                .split(',')
                .map(|v| v.trim().parse::<u64>())
                .collect::<Result<_, _>>()
                .with_context(|| format!("source '{text}': expected sim:FRAMES,POINTS,SEED"))?;
            let [frames, points, seed] = numbers[..] else {
                bail!("source '{text}': expected sim:FRAMES,POINTS,SEED");
            };
            return Ok(SourceSpec::Simulated(SimSpec {
                frames: frames as usize,
                points_per_frame: points as usize,
                seed,
            }));
        }
        bail!("source '{text}': expected dataset:DIR or sim:FRAMES,POINTS,SEED")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_source_argument_round_trips() {
        for spec in [
            SourceSpec::Dataset(PathBuf::from("/data/flight 1")),
            SourceSpec::Simulated(SimSpec {
                frames: 200,
                points_per_frame: 8000,
                seed: 1,
            }),
            SourceSpec::Recording(RecordingSpec {
                path: PathBuf::from("/data/flight.bag"),
                options: pssba_bag::RecordingOptions {
                    points_topic: Some("/livox/lidar".into()),
                    extrinsic: Some(Isometry3::translation(0.1, 0.0, -0.2)),
                    frames: Some(3..40),
                    ..Default::default()
                },
            }),
        ] {
            let parsed: SourceSpec = spec.to_string().parse().expect("parses");
            assert_eq!(parsed, spec);
        }
        for bad in ["", "sim:1,2", "sim:a,b,c", "folder"] {
            assert!(bad.parse::<SourceSpec>().is_err(), "{bad}");
        }
    }

    #[test]
    fn a_simulated_source_knows_its_size_up_front() {
        let spec = SourceSpec::Simulated(SimSpec {
            frames: 3,
            points_per_frame: 500,
            seed: 1,
        });
        let source = spec.open().expect("opens");
        assert_eq!(source.frame_count(), Some(3));
        let max = source.max_points().expect("known");
        let frames: Vec<_> = source.collect::<anyhow::Result<_>>().expect("frames");
        assert_eq!(
            frames.iter().map(|f: &SourceFrame| f.points.len()).max(),
            Some(max)
        );
    }
}
