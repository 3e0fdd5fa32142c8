//! The smooth stage's side of the frame intake ([`crate::stages::intake`]): each frame taken is pushed
//! into the sliding-window driver ([`SlidingWindows`]), and the producer's sequence number of
//! each stream index is kept, so final poses and surfaces name frames as the producer does
//! even when frames were dropped.

use crate::error::bail;
use crate::stages::intake::{IncomingFrame, Intake, StreamEnd};
use crate::transport::latency::{FinalLag, LatencyStats};
use crossbeam_channel::{Receiver, RecvTimeoutError, TryRecvError};
use nalgebra::Point3;
use pssba_core::SlidingWindows;
use std::time::Duration;

/// What the smooth stage knows of the stream so far. A live producer that vanishes, when a
/// new one is awaited, ends a *segment*: its frames are finished as at the end of a stream,
/// and the next producer's frames go to a new [`SlidingWindows`] (see `live_producer_lost`).
#[derive(Debug, Default)]
pub struct Feed {
    /// The stream sequence number of each index of the current segment's windows.
    pub sequences: Vec<u64>,
    /// Windows of earlier segments.
    pub window_offset: u64,
    /// True once the current segment's producer has vanished and a new one is awaited.
    pub segment_ended: bool,
    /// Frames of the next segment that arrived before the current one was finished.
    next_segment: Vec<IncomingFrame>,
    /// Frames taken in earlier segments.
    earlier_frames: u64,
    /// Points of the largest frame.
    pub largest_frame: usize,
    /// How the stream ended, once it has.
    pub end: Option<StreamEnd>,
    /// Sequence numbers of the frames dropped (policy `drop`).
    pub dropped: Vec<u64>,
    /// Frame transport latencies (producer send -> intake).
    pub latency: LatencyStats,
    /// Frame send -> final pose delays.
    pub lag: FinalLag,
}

impl Feed {
    /// Takes every message waiting, without blocking.
    pub fn drain(
        &mut self,
        intake: &Receiver<Intake>,
        stream: &mut SlidingWindows,
    ) -> crate::Result<()> {
        loop {
            match intake.try_recv() {
                Ok(message) => self.take(message, stream)?,
                Err(TryRecvError::Empty) => return Ok(()),
                Err(TryRecvError::Disconnected) => return self.intake_gone(),
            }
        }
    }

    /// Waits up to `timeout` for one message and takes it.
    pub fn wait(
        &mut self,
        intake: &Receiver<Intake>,
        stream: &mut SlidingWindows,
        timeout: Duration,
    ) -> crate::Result<()> {
        match intake.recv_timeout(timeout) {
            Ok(message) => self.take(message, stream),
            Err(RecvTimeoutError::Timeout) => Ok(()),
            Err(RecvTimeoutError::Disconnected) => self.intake_gone(),
        }
    }

    fn intake_gone(&self) -> crate::Result<()> {
        if self.end.is_none() {
            bail!(Run, "the frame intake stopped before the end of the stream");
        }
        Ok(())
    }

    /// Frames taken so far, in every segment.
    pub fn frames_taken(&self) -> u64 {
        self.earlier_frames + self.sequences.len() as u64 + self.next_segment.len() as u64
    }

    /// A smooth stage restarted after a crash goes on after `windows_done` windows and the
    /// `frames_final` frames they made final (its frames start at that sequence number).
    pub fn resume(&mut self, windows_done: u64, frames_final: u64) {
        self.window_offset = windows_done;
        self.earlier_frames = frames_final;
    }

    /// Frames final so far, in every segment (and before a restart), given the current
    /// segment's `stream`.
    pub fn frames_final(&self, stream: &SlidingWindows) -> u64 {
        self.earlier_frames + stream.finalised() as u64
    }

    /// Starts the next segment on an empty `stream` with the frames that arrived for it.
    pub fn start_segment(&mut self, stream: &mut SlidingWindows) -> crate::Result<()> {
        self.earlier_frames += self.sequences.len() as u64;
        self.sequences.clear();
        self.segment_ended = false;
        for frame in std::mem::take(&mut self.next_segment) {
            self.push(frame, stream)?;
        }
        if self.end.is_some() {
            stream.end_stream();
        }
        Ok(())
    }

    fn push(&mut self, frame: IncomingFrame, stream: &mut SlidingWindows) -> crate::Result<()> {
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
        stream.push_moving_frame(
            frame.stamp_s,
            points,
            frame.point_times_s,
            frame.world_from_lidar,
        )?;
        self.sequences.push(frame.sequence);
        self.lag.sent(frame.sequence as usize, frame.sent_unix_ns);
        Ok(())
    }

    fn take(&mut self, message: Intake, stream: &mut SlidingWindows) -> crate::Result<()> {
        match message {
            Intake::Frame(frame) => {
                self.latency
                    .record_received(frame.sent_unix_ns, frame.received_unix_ns);
                self.largest_frame = self.largest_frame.max(frame.points.len());
                if self.segment_ended {
                    self.next_segment.push(frame);
                } else {
                    self.push(frame, stream)?;
                }
            }
            Intake::ProducerLost { received } => {
                tracing::info!(
                    "finishing the {} frames of the vanished producer ({received} in all)",
                    self.sequences.len()
                );
                self.segment_ended = true;
                stream.end_stream();
            }
            Intake::End {
                how,
                received,
                dropped,
            } => {
                if !dropped.is_empty() {
                    tracing::warn!(
                        "{} of {received} frames were dropped (live_overflow = drop): {}",
                        dropped.len(),
                        ranges(&dropped)
                    );
                }
                self.dropped = dropped;
                self.end = Some(how);
                stream.end_stream();
            }
            Intake::Failed(error) => bail!(Run, "{error}"),
        }
        Ok(())
    }

    /// The producer's sequence number of stream index `index`.
    pub fn sequence(&self, index: usize) -> u64 {
        self.sequences.get(index).copied().unwrap_or(index as u64)
    }
}

/// `3..=7, 12` style list of sorted sequence numbers.
fn ranges(sorted: &[u64]) -> String {
    let mut parts = Vec::new();
    let mut k = 0;
    while k < sorted.len() {
        let start = sorted[k];
        let mut end = start;
        while k + 1 < sorted.len() && sorted[k + 1] == end + 1 {
            k += 1;
            end = sorted[k];
        }
        parts.push(if start == end {
            start.to_string()
        } else {
            format!("{start}..={end}")
        });
        k += 1;
    }
    parts.join(", ")
}

#[cfg(test)]
mod tests {
    #[test]
    fn ranges_are_compact() {
        assert_eq!(super::ranges(&[3, 4, 5, 9, 11, 12]), "3..=5, 9, 11..=12");
        assert_eq!(super::ranges(&[]), "");
    }
}
