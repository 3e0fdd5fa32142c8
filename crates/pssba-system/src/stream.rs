//! The smooth stage's frame store: frames in sequence order, copied out of shared memory
//! after validation, with their initial and (once known) final poses.

use crate::latency::LatencyStats;
use anyhow::bail;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use nalgebra::{Isometry3, Point3};
use pssba_msg::{FrameHeader, PointXyz};

/// One received frame.
#[derive(Debug, Clone)]
pub struct StreamFrame {
    /// Sensor stamp (s).
    pub stamp_s: f64,
    /// Points in the lidar frame (m); emptied once no window can need them again.
    pub points: Vec<Point3<f64>>,
    /// Initial pose from the stream.
    pub initial: Isometry3<f64>,
    /// Final pose, once a window has made it final.
    pub final_pose: Option<Isometry3<f64>>,
}

/// Frames received so far.
#[derive(Debug, Default)]
pub struct FrameStore {
    frames: Vec<StreamFrame>,
    finalised: usize,
    ended: bool,
    largest_frame_points: usize,
}

/// Checks a frame header read from shared memory; returns the initial pose.
pub fn validate_frame(
    header: &FrameHeader,
    expected_sequence: usize,
) -> anyhow::Result<Isometry3<f64>> {
    if header.sequence != expected_sequence as u64 {
        bail!(
            "frame sequence {} where {expected_sequence} was expected: a frame was lost or \
             reordered",
            header.sequence
        );
    }
    if !header.stamp_s.is_finite() {
        bail!("frame {}: stamp is not finite", header.sequence);
    }
    Ok(header
        .world_from_lidar
        .to_isometry("frame", header.sequence)?)
}

impl FrameStore {
    /// Drains the subscriber: validates each frame and copies its points out of shared memory.
    pub fn receive(
        &mut self,
        subscriber: &Subscriber<ipc::Service, [PointXyz], FrameHeader>,
        latency: &mut LatencyStats,
    ) -> anyhow::Result<()> {
        while let Some(sample) = subscriber
            .receive()
            .map_err(|e| anyhow::anyhow!("receiving frames: {e:?}"))?
        {
            latency.record(sample.user_header().sent_unix_ns);
            let header = *sample.user_header();
            if self.ended {
                bail!(
                    "frame {} arrived after the end of the stream",
                    header.sequence
                );
            }
            if header.end_of_stream != 0 {
                if header.sequence != self.frames.len() as u64 {
                    bail!(
                        "end of stream after {} frames, but {} were received",
                        header.sequence,
                        self.frames.len()
                    );
                }
                self.ended = true;
                continue;
            }
            let initial = validate_frame(&header, self.frames.len())?;
            let payload = sample.payload();
            self.largest_frame_points = self.largest_frame_points.max(payload.len());
            let points = payload
                .iter()
                .map(|p| {
                    Point3::new(
                        f64::from(p.xyz_m[0]),
                        f64::from(p.xyz_m[1]),
                        f64::from(p.xyz_m[2]),
                    )
                })
                .collect();
            self.frames.push(StreamFrame {
                stamp_s: header.stamp_s,
                points,
                initial,
                final_pose: None,
            });
        }
        Ok(())
    }

    /// Frames received.
    pub fn len(&self) -> usize {
        self.frames.len()
    }

    /// True before the first frame.
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// Frames `[0, finalised)` are final.
    pub fn finalised(&self) -> usize {
        self.finalised
    }

    /// True once the end-of-stream marker arrived.
    pub fn ended(&self) -> bool {
        self.ended
    }

    /// Frame `k`.
    pub fn frame(&self, k: usize) -> &StreamFrame {
        &self.frames[k]
    }

    /// Makes frame `k` final (frames become final in order).
    pub fn set_final(&mut self, k: usize, pose: Isometry3<f64>) {
        self.frames[k].final_pose = Some(pose);
        while self.finalised < self.frames.len() && self.frames[self.finalised].final_pose.is_some()
        {
            self.finalised += 1;
        }
    }

    /// Frees the points of frames before `k`: no later window reaches back that far.
    pub fn forget_before(&mut self, k: usize) {
        let end = k.min(self.frames.len());
        for frame in &mut self.frames[..end] {
            frame.points = Vec::new();
        }
    }

    /// Largest frame seen (points).
    pub fn largest_frame_points(&self) -> usize {
        self.largest_frame_points
    }
}
