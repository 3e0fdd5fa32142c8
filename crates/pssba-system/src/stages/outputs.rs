//! What the smooth stage publishes for outside subscribers (docs/interface.md): each frame's
//! final pose, a final pose again when a loop closure moves it, and each window's summary,
//! smoothed map chunk and surfaces. Every one of these
//! services overwrites a slow subscriber's oldest samples, so none can stall the pipeline.

use iceoryx2::prelude::*;
use pssba_client::outputs::FinalPosePublisher;
use pssba_client::windows::{SurfaceMsg, WindowPublisher, WindowSummaryMsg};
use pssba_msg::{PointXyz, WindowResult};

/// The smooth stage's outside-facing publishers.
#[derive(Debug)]
pub struct Outputs {
    final_poses: FinalPosePublisher,
    revised_poses: FinalPosePublisher,
    windows: WindowPublisher,
}

impl Outputs {
    /// Creates the services on `node`.
    pub fn create(node: &Node<ipc::Service>) -> crate::Result<Self> {
        Ok(Self {
            final_poses: FinalPosePublisher::create(node)?,
            revised_poses: FinalPosePublisher::create_revised(node)?,
            windows: WindowPublisher::create(node)?,
        })
    }

    /// Publishes a finished window: its map chunk and surfaces, its summary, then its frames'
    /// final poses.
    pub fn publish(&mut self, result: &WindowResult) -> crate::Result<()> {
        let failed = result.failure.is_some();
        let map: Vec<PointXyz> = result
            .map
            .iter()
            .map(|p| PointXyz {
                xyz_m: [p.x as f32, p.y as f32, p.z as f32],
            })
            .collect();
        let surfaces: Vec<SurfaceMsg> = result
            .surfaces
            .iter()
            .map(|s| {
                let r = s.tangent_from_world;
                SurfaceMsg {
                    frame_sequence: s.frame as u64,
                    kernel_in_world_m: [
                        s.kernel_in_world.x,
                        s.kernel_in_world.y,
                        s.kernel_in_world.z,
                    ],
                    tangent_from_world: std::array::from_fn(|k| r[(k / 3, k % 3)]),
                    coefficients: s.coefficients,
                    gamma_m: s.gamma_m,
                }
            })
            .collect();
        let last = result.scales.last();
        let summary = WindowSummaryMsg {
            window: result.window,
            first_sequence: result.finals.first().map_or(0, |f| f.sequence),
            final_count: result.finals.len() as u64,
            frames_dropped: result.frames_dropped,
            last_gamma_m: last.map_or(0.0, |s| s.gamma_m),
            last_pose_change: last.map_or(0.0, |s| s.pose_change),
            scales_run: result.scales.len() as u32,
            converged: u32::from(result.converged),
            failed: u32::from(failed),
            ..WindowSummaryMsg::default()
        };
        self.windows.publish(summary, &map, &surfaces)?;
        self.final_poses
            .publish(result.window, failed, &result.finals)?;
        self.revised_poses
            .publish(result.window, false, &result.revised)?;
        Ok(())
    }

    /// Publishes the end-of-stream markers.
    pub fn end_stream(&mut self) -> crate::Result<()> {
        self.windows.end_stream()?;
        self.final_poses.end_stream()?;
        self.revised_poses.end_stream()?;
        Ok(())
    }
}
