//! The `#[repr(C)]` types of the public frames service (docs/interface.md): plain primitives
//! and arrays only, so any language can lay them out.
#![allow(unsafe_code)] // `derive(ZeroCopySend)` emits the `unsafe impl` marker; nothing else.

use crate::error::MsgError;
use iceoryx2::prelude::ZeroCopySend;
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};

/// One lidar point in the sensor frame (m). f32 like the PCD files it comes from.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("pssba::PointXyz")]
pub struct PointXyz {
    /// x, y, z in the lidar frame (m).
    pub xyz_m: [f32; 3],
}

/// A world-from-lidar pose as a unit quaternion and a translation: the exact bits of an
/// `Isometry3`, so a frame's initial pose reaches the smooth stage unchanged (the schedule is
/// sensitive enough that a 4e-16 change of the input moved a 10-frame result by 5.6 mm).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("pssba::IsometryMsg")]
pub struct IsometryMsg {
    /// Rotation as a unit quaternion `[x, y, z, w]`.
    pub quaternion_xyzw: [f64; 4],
    /// Translation t (m).
    pub translation_m: [f64; 3],
}

/// Largest accepted `| |q| - 1 |` for a quaternion read from shared memory.
const QUATERNION_TOLERANCE: f64 = 1e-9;

impl IsometryMsg {
    /// From an isometry, bit for bit.
    pub fn from_isometry(world_from_lidar: &Isometry3<f64>) -> Self {
        let q = world_from_lidar.rotation.quaternion();
        let t = world_from_lidar.translation.vector;
        Self {
            quaternion_xyzw: [q.i, q.j, q.k, q.w],
            translation_m: [t.x, t.y, t.z],
        }
    }

    /// Checked conversion back: finite, unit quaternion; the bits are kept as they are.
    pub fn to_isometry(
        &self,
        message: &'static str,
        index: u64,
    ) -> Result<Isometry3<f64>, MsgError> {
        if !self
            .quaternion_xyzw
            .iter()
            .chain(&self.translation_m)
            .all(|v| v.is_finite())
        {
            return Err(MsgError::NotFinite {
                message,
                field: "pose",
                index,
            });
        }
        let [x, y, z, w] = self.quaternion_xyzw;
        let q = Quaternion::new(w, x, y, z);
        let error = (q.norm() - 1.0).abs();
        if error > QUATERNION_TOLERANCE {
            return Err(MsgError::NotARotation {
                message,
                index,
                error,
            });
        }
        Ok(Isometry3::from_parts(
            Translation3::from(Vector3::from(self.translation_m)),
            UnitQuaternion::new_unchecked(q),
        ))
    }
}

/// Header of a frame sample (`frames` service, payload `[PointXyz]`).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("pssba::FrameHeader")]
pub struct FrameHeader {
    /// 0, 1, 2, ... in stream order.
    pub sequence: u64,
    /// Sensor time stamp (s).
    pub stamp_s: f64,
    /// Initial (odometry) pose.
    pub world_from_lidar: IsometryMsg,
    /// Ground truth when known (`has_ground_truth != 0`).
    pub ground_truth: IsometryMsg,
    /// 1 when `ground_truth` is valid.
    pub has_ground_truth: u32,
    /// 1 on the end-of-stream marker (no points; `sequence` = number of frames sent).
    pub end_of_stream: u32,
    /// Wall clock at send (ns since the Unix epoch), for transport latency measurements.
    pub sent_unix_ns: u64,
    /// [`FRAME_LAYOUT_VERSION`] of the producer; a consumer refuses any other.
    pub layout_version: u32,
    /// Zero.
    pub reserved: u32,
}

/// Version of the frames service's layout and rules (docs/interface.md). Raised whenever
/// what a field means changes, even if the sizes stay.
pub const FRAME_LAYOUT_VERSION: u32 = 1;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::outputs::FinalPoseMsg;
    use std::mem::{offset_of, size_of};

    /// The layouts docs/interface.md promises to other languages (tools/pssba_live.py asserts
    /// the same sizes on its side).
    #[test]
    fn layouts_match_the_contract() {
        assert_eq!(size_of::<PointXyz>(), 12);
        assert_eq!(size_of::<IsometryMsg>(), 56);
        assert_eq!(size_of::<FrameHeader>(), 152);
        assert_eq!(offset_of!(FrameHeader, world_from_lidar), 16);
        assert_eq!(offset_of!(FrameHeader, ground_truth), 72);
        assert_eq!(offset_of!(FrameHeader, has_ground_truth), 128);
        assert_eq!(offset_of!(FrameHeader, sent_unix_ns), 136);
        assert_eq!(offset_of!(FrameHeader, layout_version), 144);
        assert_eq!(size_of::<FinalPoseMsg>(), 88);
        assert_eq!(offset_of!(FinalPoseMsg, window), 72);
        assert_eq!(offset_of!(FinalPoseMsg, end_of_stream), 84);
    }
}
