//! Validation of a frame read from shared memory, and what can stop the frames protocol
//! (the ports that use them are pssba-client's `FrameProducer` and `FrameConsumer`).

use crate::error::{MsgError, ServiceError};
use crate::public::types::{
    FRAME_LAYOUT_VERSION, FRAME_LAYOUT_VERSION_STILL, FrameHeader, PointXyz, timed_payload_len,
};
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
    /// Version 2 with times: the payload's elements after the points, three times (s after
    /// the stamp) each, checked finite and within 1 s; see [`Self::point_times_s`].
    pub packed_times: Option<&'a [PointXyz]>,
    /// When the producer sent it (ns since the Unix epoch; 0 if unknown).
    pub sent_unix_ns: u64,
}

/// Most a point's time may lie from its frame's stamp (s): a frame spans 0.1 s at 10 Hz.
pub const MAX_POINT_TIME_S: f32 = 1.0;

impl ReceivedFrame<'_> {
    /// Each point's time after the stamp (s), when the producer sent them.
    pub fn point_times_s(&self) -> Option<Vec<f32>> {
        self.packed_times
            .map(|packed| unpack_times(packed, self.points.len()))
    }
}

fn unpack_times(packed: &[PointXyz], points: usize) -> Vec<f32> {
    packed.iter().flat_map(|p| p.xyz_m).take(points).collect()
}

/// Element `slot` of the times that follow the points in a version 2 payload.
pub fn packed_time_slot(times_s: &[f32], slot: usize) -> PointXyz {
    let at = |i: usize| times_s.get(3 * slot + i).copied().unwrap_or(0.0);
    PointXyz {
        xyz_m: [at(0), at(1), at(2)],
    }
}

/// Refuses a time that is not finite or beyond [`MAX_POINT_TIME_S`] of the stamp, naming the
/// frame and the point.
pub fn check_point_times(sequence: u64, times_s: &[f32]) -> Result<(), FrameError> {
    match times_s
        .iter()
        .position(|t| !t.is_finite() || t.abs() > MAX_POINT_TIME_S)
    {
        None => Ok(()),
        Some(i) => Err(FrameError::Sequence(format!(
            "frame {sequence}: point {i}'s time {} s is not finite or more than \
             {MAX_POINT_TIME_S} s from the stamp",
            times_s[i]
        ))),
    }
}

/// Splits a payload into its points and packed times (layout versions 1 and 2).
fn split_payload<'a>(
    header: &FrameHeader,
    payload: &'a [PointXyz],
) -> Result<(&'a [PointXyz], Option<&'a [PointXyz]>), FrameError> {
    let sequence = header.sequence;
    match header.layout_version {
        FRAME_LAYOUT_VERSION_STILL => Ok((payload, None)),
        FRAME_LAYOUT_VERSION if header.timed_points == 0 => Ok((payload, None)),
        FRAME_LAYOUT_VERSION => {
            let points = header.timed_points as usize;
            if payload.len() != timed_payload_len(points) {
                return Err(FrameError::Sequence(format!(
                    "frame {sequence}: timed_points {points} needs {} payload elements (the \
                     points, then their times three to an element), the sample has {}",
                    timed_payload_len(points),
                    payload.len()
                )));
            }
            let (points_part, packed) = payload.split_at(points);
            check_point_times(sequence, &unpack_times(packed, points))?;
            Ok((points_part, Some(packed)))
        }
        other => Err(FrameError::Sequence(format!(
            "frame {sequence}: layout version {other} where this system reads versions \
             {FRAME_LAYOUT_VERSION_STILL} and {FRAME_LAYOUT_VERSION} (docs/interface.md)"
        ))),
    }
}

/// Checks a frame read from shared memory against the sequence expected next, and splits a
/// version 2 payload into points and times (also the fuzzing entry point of frame
/// validation).
pub fn check_frame<'a>(
    header: &FrameHeader,
    expected_sequence: u64,
    payload: &'a [PointXyz],
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
    let (points, packed_times) = split_payload(header, payload)?;
    Ok(ReceivedFrame {
        sequence: header.sequence,
        stamp_s: header.stamp_s,
        world_from_lidar,
        ground_truth,
        points,
        packed_times,
        sent_unix_ns: header.sent_unix_ns,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::public::types::IsometryMsg;

    fn header(layout_version: u32, timed_points: u32) -> FrameHeader {
        FrameHeader {
            sequence: 4,
            stamp_s: 10.0,
            world_from_lidar: IsometryMsg::from_isometry(&Isometry3::identity()),
            layout_version,
            timed_points,
            ..FrameHeader::default()
        }
    }

    fn point(i: usize) -> PointXyz {
        PointXyz {
            xyz_m: [i as f32, 1.0, 2.0],
        }
    }

    /// Five points and their times: five points, then two elements of three times (the last
    /// padded), read back as sent; version 1 and version 2 without times carry none.
    #[test]
    fn version_2_payloads_split_into_points_and_times() {
        let times = [0.0f32, 0.02, -0.01, 0.099, 0.05];
        let mut payload: Vec<PointXyz> = (0..5).map(point).collect();
        payload.extend((0..2).map(|slot| packed_time_slot(&times, slot)));
        assert_eq!(payload.len(), timed_payload_len(5));
        let frame = check_frame(&header(2, 5), 4, &payload).expect("valid");
        assert_eq!(frame.points, &payload[..5]);
        assert_eq!(frame.point_times_s(), Some(times.to_vec()));
        for version in [1, 2] {
            let plain = check_frame(&header(version, 0), 4, &payload).expect("valid");
            assert_eq!(plain.points.len(), 7);
            assert_eq!(plain.point_times_s(), None);
        }
    }

    #[test]
    fn bad_times_and_layouts_are_refused_naming_the_frame() {
        let message = |h: FrameHeader, payload: &[PointXyz]| {
            check_frame(&h, 4, payload).unwrap_err().to_string()
        };
        let mut payload: Vec<PointXyz> = (0..3).map(point).collect();
        payload.push(packed_time_slot(&[0.0, f32::NAN, 0.01], 0));
        let nan = message(header(2, 3), &payload);
        assert!(nan.contains("frame 4: point 1's time NaN"), "{nan}");
        payload[3] = packed_time_slot(&[0.0, 0.01, -1.5], 0);
        let far = message(header(2, 3), &payload);
        assert!(far.contains("point 2's time -1.5 s"), "{far}");
        let short = message(header(2, 3), &payload[..3]);
        assert!(
            short.contains("timed_points 3 needs 4 payload elements") && short.contains("has 3"),
            "{short}"
        );
        let unknown = message(header(7, 0), &payload);
        assert!(unknown.contains("layout version 7"), "{unknown}");
    }
}
