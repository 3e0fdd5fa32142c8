//! Validation of a frame read from shared memory, and what can stop the frames protocol
//! (the ports that use them are pssba-client's `FrameProducer` and `FrameConsumer`).

use crate::error::{MsgError, ServiceError};
use crate::public::types::{FrameHeader, PointXyz};
use nalgebra::Isometry3;

/// Why the protocol could not go on.
#[derive(Debug, thiserror::Error)]
pub enum FrameError {
    /// A service or port could not be opened.
    #[error(transparent)]
    Service(#[from] ServiceError),
    /// A frame failed validation.
    #[error(transparent)]
    Invalid(#[from] MsgError),
    /// The frames broke the sequence rules.
    #[error("{0}")]
    Sequence(String),
    /// iceoryx2 failed, or the wait was interrupted or timed out.
    #[error("{0}")]
    Transport(String),
}

/// One validated frame, borrowed from shared memory.
#[derive(Debug)]
pub struct ReceivedFrame<'a> {
    /// 0, 1, 2, ... in stream order, across producers (`FrameConsumer::rejoin`).
    pub sequence: u64,
    /// Sensor stamp (s).
    pub stamp_s: f64,
    /// Initial (odometry) pose.
    pub world_from_lidar: Isometry3<f64>,
    /// Ground truth, when the producer knows it.
    pub ground_truth: Option<Isometry3<f64>>,
    /// Points in the lidar frame (m), f32.
    pub points: &'a [PointXyz],
    /// When the producer sent it (ns since the Unix epoch; 0 if unknown).
    pub sent_unix_ns: u64,
}

/// Checks a frame read from shared memory against the sequence expected next (also the
/// fuzzing entry point of frame validation).
pub fn check_frame<'a>(
    header: &FrameHeader,
    expected_sequence: u64,
    points: &'a [PointXyz],
) -> Result<ReceivedFrame<'a>, FrameError> {
    if header.sequence != expected_sequence {
        return Err(FrameError::Sequence(format!(
            "frame sequence {} where {expected_sequence} was expected: a frame was lost or \
             reordered",
            header.sequence
        )));
    }
    if !header.stamp_s.is_finite() {
        return Err(FrameError::Sequence(format!(
            "frame {}: stamp is not finite",
            header.sequence
        )));
    }
    let world_from_lidar = header
        .world_from_lidar
        .to_isometry("frame", header.sequence)?;
    let ground_truth = match header.has_ground_truth {
        0 => None,
        _ => Some(
            header
                .ground_truth
                .to_isometry("frame ground truth", header.sequence)?,
        ),
    };
    Ok(ReceivedFrame {
        sequence: header.sequence,
        stamp_s: header.stamp_s,
        world_from_lidar,
        ground_truth,
        points,
        sent_unix_ns: header.sent_unix_ns,
    })
}
