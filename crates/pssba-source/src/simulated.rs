//! The built-in simulated scene: the curved scene of `pssba demo`, its poses perturbed by
//! 0.2 m / 1 deg RMS, stamped every 0.1 s, with its ground truth.

use crate::{Frame, FrameSource, Frames, Result, SourceError};
use std::sync::Arc;

/// The simulated scene's size and seed.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimSpec {
    /// Frames.
    pub frames: usize,
    /// Points per frame.
    pub points_per_frame: usize,
    /// Seed of scene noise and pose perturbation.
    pub seed: u64,
}

impl SimSpec {
    /// Checks the sizes.
    pub fn check(&self) -> Result<()> {
        if self.frames < 2 || self.points_per_frame == 0 {
            return Err(SourceError::Settings(format!(
                "the simulated scene needs at least 2 frames and 1 point per frame \
                 (got {} and {})",
                self.frames, self.points_per_frame
            )));
        }
        Ok(())
    }

    /// What it is, for logs.
    pub fn describe(&self) -> String {
        format!(
            "built-in curved scene, {} frames x {} points, seed {}",
            self.frames, self.points_per_frame, self.seed
        )
    }
}

/// The frames of a simulated source (the same scene and perturbation as `pssba demo`).
pub fn simulated_frames(spec: &SimSpec) -> Vec<Frame> {
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
        .map(|(k, ((points, world_from_lidar), gt))| Frame {
            stamp_s: k as f64 * 0.1,
            points,
            world_from_lidar,
            ground_truth: Some(gt),
            point_times_s: None,
        })
        .collect()
}

/// The simulated scene, simulated once when opened.
#[derive(Debug)]
pub struct Simulated {
    spec: SimSpec,
    frames: Arc<Vec<Frame>>,
}

impl Simulated {
    /// Simulates the scene.
    pub fn new(spec: &SimSpec) -> Result<Self> {
        spec.check()?;
        tracing::info!(
            "simulating the curved scene: {} frames x {} points, seed {}",
            spec.frames,
            spec.points_per_frame,
            spec.seed
        );
        Ok(Self {
            spec: *spec,
            frames: Arc::new(simulated_frames(spec)),
        })
    }
}

impl FrameSource for Simulated {
    fn kind(&self) -> &'static str {
        "simulated scene"
    }

    fn describe(&self) -> String {
        self.spec.describe()
    }

    fn len(&self) -> Option<usize> {
        Some(self.frames.len())
    }

    fn max_points(&self) -> Option<usize> {
        Some(
            self.frames
                .iter()
                .map(|f| f.points.len())
                .max()
                .unwrap_or(0),
        )
    }

    fn frames_from(&self, first: usize) -> Result<Frames> {
        let frames = Arc::clone(&self.frames);
        Ok(Box::new(
            (first.min(frames.len())..frames.len()).map(move |k| Ok(frames[k].clone())),
        ))
    }
}
