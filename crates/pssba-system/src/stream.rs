//! The smooth stage's side of the frames service: validates each frame read from shared
//! memory and copies its points into the sliding-window driver ([`SlidingWindows`]).

use crate::latency::{FinalLag, LatencyStats};
use anyhow::bail;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use nalgebra::{Isometry3, Point3};
use pssba_core::SlidingWindows;
use pssba_msg::{FrameHeader, PointXyz};

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

/// Drains `subscriber` into `stream`: every frame validated, its points copied out of shared
/// memory; the end-of-stream marker ends the stream. Returns the largest frame seen (points).
pub fn receive_frames(
    subscriber: &Subscriber<ipc::Service, [PointXyz], FrameHeader>,
    stream: &mut SlidingWindows,
    latency: &mut LatencyStats,
    lag: &mut FinalLag,
) -> anyhow::Result<usize> {
    let mut largest = 0;
    while let Some(sample) = subscriber
        .receive()
        .map_err(|e| anyhow::anyhow!("receiving frames: {e:?}"))?
    {
        latency.record(sample.user_header().sent_unix_ns);
        let header = *sample.user_header();
        if stream.ended() {
            bail!(
                "frame {} arrived after the end of the stream",
                header.sequence
            );
        }
        if header.end_of_stream != 0 {
            if header.sequence != stream.len() as u64 {
                bail!(
                    "end of stream after {} frames, but {} were received",
                    header.sequence,
                    stream.len()
                );
            }
            stream.end_stream();
            continue;
        }
        let initial = validate_frame(&header, stream.len())?;
        let payload = sample.payload();
        largest = largest.max(payload.len());
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
        let sequence = stream.push_frame(header.stamp_s, points, initial)?;
        lag.sent(sequence, header.sent_unix_ns);
    }
    Ok(largest)
}
