//! The ingest stage: reads a dataset folder (or simulates the built-in scene) and publishes
//! each frame into a loaned shared-memory sample, as fast as the consumers take them or at a
//! fixed sensor rate. Ends with an end-of-stream marker.

use crate::shm::{self, publish_from_fn};
use anyhow::Context;
use nalgebra::{Isometry3, Point3};
use pssba_msg::services::{self, names};
use pssba_msg::{FrameHeader, IsometryMsg, PointXyz};
use std::path::PathBuf;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

/// Where frames come from.
#[derive(Debug, Clone, PartialEq)]
pub enum Source {
    /// A dataset folder (frames/*.pcd, poses.txt, optional gt.txt).
    Dataset(PathBuf),
    /// The built-in curved scene, perturbed like `pssba demo`.
    Simulated(SimSpec),
}

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

/// Options of the ingest stage.
#[derive(Debug, Clone)]
pub struct IngestOptions {
    /// iceoryx2 prefix of this run.
    pub prefix: String,
    /// Frame source.
    pub source: Source,
    /// Publish at this rate (Hz) instead of as fast as possible.
    pub rate_hz: Option<f64>,
    /// Publisher backpressure timeout.
    pub backpressure_timeout: Duration,
    /// Largest frame the frames service carries (points).
    pub max_frame_points: usize,
}

fn now_unix_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}

/// Runs the stage until every frame is published.
pub fn run(options: &IngestOptions) -> anyhow::Result<()> {
    let node = services::create_node(&options.prefix, "ingest")?;
    // Before the publisher exists, so no consumer's ready report is missed.
    let ready = shm::listener(&services::event_service(&node, shm::FRAMES_READY)?)?;
    let service = services::frames_service(&node)?;
    let event = services::event_service(&node, names::FRAMES)?;
    let publisher = services::publisher(
        &service,
        options.max_frame_points,
        options.backpressure_timeout,
    )?;
    let notifier = shm::notifier(&event)?;

    // Load before waiting: a dataset that cannot be opened fails fast.
    let (count, mut next): (usize, Box<dyn FnMut(usize) -> anyhow::Result<SourceFrame>>) =
        match &options.source {
            Source::Dataset(dir) => {
                let dataset = pssba_io::Dataset::open(dir)?;
                let count = dataset.len();
                (
                    count,
                    Box::new(move |k| {
                        Ok(SourceFrame {
                            stamp_s: dataset.initial[k].stamp,
                            points: dataset.load_frame(k)?,
                            world_from_lidar: dataset.initial[k].world_from_lidar,
                            ground_truth: dataset
                                .ground_truth
                                .as_ref()
                                .map(|g| g[k].world_from_lidar),
                        })
                    }),
                )
            }
            Source::Simulated(spec) => {
                tracing::info!(
                    "simulating the curved scene: {} frames x {} points, seed {}",
                    spec.frames,
                    spec.points_per_frame,
                    spec.seed
                );
                let mut frames: Vec<Option<SourceFrame>> =
                    simulated_frames(spec).into_iter().map(Some).collect();
                (
                    frames.len(),
                    Box::new(move |k| frames[k].take().context("frame already published")),
                )
            }
        };
    shm::wait_for_ready(
        &node,
        &ready,
        &[shm::ready_id::SMOOTH, shm::ready_id::RECORD],
        Duration::from_secs(60),
    )?;
    let started = Instant::now();
    let period = options.rate_hz.map(|hz| Duration::from_secs_f64(1.0 / hz));
    for k in 0..count {
        if shm::termination_requested(&node) {
            anyhow::bail!("interrupted after {k} of {count} frames");
        }
        let frame = next(k).with_context(|| format!("frame {k}"))?;
        if frame.points.len() > options.max_frame_points {
            anyhow::bail!(
                "frame {k} has {} points; the frames service holds at most {} \
                 (raise system.max_frame_points)",
                frame.points.len(),
                options.max_frame_points
            );
        }
        let header = || FrameHeader {
            sequence: k as u64,
            stamp_s: frame.stamp_s,
            world_from_lidar: IsometryMsg::from_isometry(&frame.world_from_lidar),
            ground_truth: frame
                .ground_truth
                .as_ref()
                .map(IsometryMsg::from_isometry)
                .unwrap_or_default(),
            has_ground_truth: u32::from(frame.ground_truth.is_some()),
            end_of_stream: 0,
            sent_unix_ns: now_unix_ns(),
        };
        let points = &frame.points;
        publish_from_fn(&publisher, &notifier, header, points.len(), |i| PointXyz {
            xyz_m: [points[i].x as f32, points[i].y as f32, points[i].z as f32],
        })
        .with_context(|| format!("publishing frame {k}"))?;
        if (k + 1) % 20 == 0 || k + 1 == count {
            tracing::info!("published {}/{count} frames", k + 1);
        }
        if let Some(period) = period {
            let due = period * (k as u32 + 1);
            if let Some(wait) = due.checked_sub(started.elapsed()) {
                std::thread::sleep(wait);
            }
        }
    }
    let end = FrameHeader {
        sequence: count as u64,
        end_of_stream: 1,
        sent_unix_ns: now_unix_ns(),
        ..FrameHeader::default()
    };
    shm::publish_slice(&publisher, &notifier, end, &[]).context("publishing end of stream")?;
    tracing::info!(
        "all {count} frames published in {:.2} s",
        started.elapsed().as_secs_f64()
    );
    shm::linger_until_unsubscribed(&node, &service, "frames", options.backpressure_timeout);
    Ok(())
}
