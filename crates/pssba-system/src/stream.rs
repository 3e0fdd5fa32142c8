//! The smooth stage's side of the frames service: each validated frame
//! ([`pssba_msg::FrameConsumer`]) has its points copied out of shared memory into the
//! sliding-window driver ([`SlidingWindows`]).

use crate::latency::{FinalLag, LatencyStats};
use nalgebra::Point3;
use pssba_core::SlidingWindows;
use pssba_msg::FrameConsumer;

/// Drains `consumer` into `stream`; the end-of-stream marker ends the stream. Returns the
/// largest frame seen (points).
pub fn receive_frames(
    consumer: &FrameConsumer,
    stream: &mut SlidingWindows,
    latency: &mut LatencyStats,
    lag: &mut FinalLag,
) -> anyhow::Result<usize> {
    let mut largest = 0;
    consumer.receive(|frame| -> anyhow::Result<()> {
        latency.record(frame.sent_unix_ns);
        largest = largest.max(frame.points.len());
        let points = frame
            .points
            .iter()
            .map(|p| {
                Point3::new(
                    f64::from(p.xyz_m[0]),
                    f64::from(p.xyz_m[1]),
                    f64::from(p.xyz_m[2]),
                )
            })
            .collect();
        let sequence = stream.push_frame(frame.stamp_s, points, frame.world_from_lidar)?;
        lag.sent(sequence, frame.sent_unix_ns);
        Ok(())
    })?;
    if consumer.ended() && !stream.ended() {
        stream.end_stream();
    }
    Ok(largest)
}
