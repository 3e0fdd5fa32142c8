//! The `#[repr(C)]` types of the public services (docs/interface.md): frames in; final poses,
//! window summaries, map chunks and surfaces out. Plain primitives and arrays only, so any
//! language can lay them out.
#![allow(unsafe_code)] // `derive(ZeroCopySend)` emits the `unsafe impl` marker; nothing else.

use crate::error::{MsgError, ServiceError};
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
    /// [`FRAME_LAYOUT_VERSION`] of the producer ([`FRAME_LAYOUT_VERSION_STILL`] is read too);
    /// a consumer refuses any other.
    pub layout_version: u32,
    /// Version 2: the number of points `n` whose times follow them in the payload (0: none,
    /// every point taken at `stamp_s`). The payload is then `n` points and `ceil(n / 3)`
    /// elements carrying the `n` times (f32 s after `stamp_s`, three per element, in point
    /// order, the last padded with 0): [`timed_payload_len`]. Version 1: zero, ignored.
    pub timed_points: u32,
}

/// Version of the frames service's layout and rules (docs/interface.md). Raised whenever
/// what a field means changes, even if the sizes stay. Version 2 added the point times.
pub const FRAME_LAYOUT_VERSION: u32 = 2;

/// The version before point times: still accepted, as frames taken at one instant.
pub const FRAME_LAYOUT_VERSION_STILL: u32 = 1;

/// Payload elements of a version 2 frame of `points` points with their times.
pub const fn timed_payload_len(points: usize) -> usize {
    points + points.div_ceil(3)
}

/// One frame's final pose (`pssba/<instance>/final_poses`, fixed-size payload).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("pssba::FinalPoseMsg")]
pub struct FinalPoseMsg {
    /// The frame's sequence number on the frames service (0, 1, 2, ...).
    pub sequence: u64,
    /// The frame's sensor stamp (s), as it was sent.
    pub stamp_s: f64,
    /// Final world-from-lidar pose.
    pub world_from_lidar: IsometryMsg,
    /// Index of the window that made it final.
    pub window: u64,
    /// 1 if that window failed and the frame kept its (anchor-corrected) initial pose.
    pub kept_initial: u32,
    /// 1 on the end-of-stream marker (`sequence` = frames made final; no pose).
    pub end_of_stream: u32,
}

/// A frame's final pose, as the smooth stage hands it out.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FinalPose {
    /// The frame's sequence number on the frames service.
    pub sequence: u64,
    /// Sensor stamp (s).
    pub stamp_s: f64,
    /// Final world-from-lidar pose.
    pub world_from_lidar: Isometry3<f64>,
}

/// One finished window (`pssba/<instance>/windows`, fixed-size payload), 80 bytes.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("pssba::WindowSummaryMsg")]
pub struct WindowSummaryMsg {
    /// Window index (0, 1, 2, ...).
    pub window: u64,
    /// Sequence number of the first frame this window made final.
    pub first_sequence: u64,
    /// Frames it made final (their poses are on `final_poses`).
    pub final_count: u64,
    /// Points of its smoothed map chunk (on `map`).
    pub map_points: u64,
    /// Its surfaces (on `surfaces`).
    pub surfaces: u64,
    /// Frames the system has dropped so far (overflow policy `drop`).
    pub frames_dropped: u64,
    /// Kernel scale of its last scale (m).
    pub last_gamma_m: f64,
    /// Largest pose change of its last scale (the convergence measure).
    pub last_pose_change: f64,
    /// Scales it ran.
    pub scales_run: u32,
    /// 1 if its schedule converged.
    pub converged: u32,
    /// 1 if its adjustment failed (its frames kept their anchor-corrected initial poses).
    pub failed: u32,
    /// 1 on the end-of-stream marker (`window` = windows published; nothing else set).
    pub end_of_stream: u32,
}

/// Where a map or surface sample sits in its window's chunk (user header), 32 bytes.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("pssba::ChunkHeader")]
pub struct ChunkHeader {
    /// Window index.
    pub window: u64,
    /// Index of this sample's first item within the window's chunk.
    pub first_item: u64,
    /// Items in the window's whole chunk.
    pub total_items: u64,
    /// This sample's number, 0-based.
    pub part: u32,
    /// Samples of the window's chunk.
    pub parts: u32,
}

/// One surface of a window, in the world frame (`pssba/<instance>/surfaces`), 160 bytes: the
/// paper's local polynomial z = f(x, y) in its kernel's tangent frame.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("pssba::SurfaceMsg")]
pub struct SurfaceMsg {
    /// Sequence number of the frame whose point is the kernel.
    pub frame_sequence: u64,
    /// The kernel point in the world (m).
    pub kernel_in_world_m: [f64; 3],
    /// Rotation tangent-from-world, row-major (the tangent frame's z is the surface normal).
    pub tangent_from_world: [f64; 9],
    /// Coefficients of f(x, y) = c0 + c1 x + c2 y + c3 x^2 + c4 x y + c5 y^2 (x, y, f in m,
    /// relative to the kernel point).
    pub coefficients: [f64; 6],
    /// Kernel radius gamma (m) of the scale.
    pub gamma_m: f64,
}

/// What a chunk sample holds, checked: `first_item + len <= total_items`, `part < parts`.
pub fn checked(header: &ChunkHeader, len: usize) -> Result<ChunkHeader, ServiceError> {
    let fits = header
        .first_item
        .checked_add(len as u64)
        .is_some_and(|end| end <= header.total_items)
        && header.part < header.parts;
    if fits {
        Ok(*header)
    } else {
        Err(ServiceError {
            what: format!("window {} chunk", header.window),
            reason: format!(
                "inconsistent header: part {} of {}, items {}+{len} of {}",
                header.part, header.parts, header.first_item, header.total_items
            ),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::mem::{align_of, offset_of, size_of};

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
        assert_eq!(offset_of!(FrameHeader, timed_points), 148);
        assert_eq!(size_of::<FinalPoseMsg>(), 88);
        assert_eq!(offset_of!(FinalPoseMsg, window), 72);
        assert_eq!(offset_of!(FinalPoseMsg, end_of_stream), 84);
    }

    /// The layouts docs/interface.md promises to other languages.
    #[test]
    fn window_layouts_match_the_contract() {
        assert_eq!(size_of::<WindowSummaryMsg>(), 80);
        assert_eq!(offset_of!(WindowSummaryMsg, last_gamma_m), 48);
        assert_eq!(offset_of!(WindowSummaryMsg, scales_run), 64);
        assert_eq!(offset_of!(WindowSummaryMsg, end_of_stream), 76);
        assert_eq!(size_of::<ChunkHeader>(), 32);
        assert_eq!(offset_of!(ChunkHeader, parts), 28);
        assert_eq!(size_of::<SurfaceMsg>(), 160);
        assert_eq!(offset_of!(SurfaceMsg, tangent_from_world), 32);
        assert_eq!(offset_of!(SurfaceMsg, coefficients), 104);
        assert_eq!(offset_of!(SurfaceMsg, gamma_m), 152);
        assert_eq!(align_of::<SurfaceMsg>(), 8);
    }

    #[test]
    fn inconsistent_chunk_headers_are_refused() {
        let good = ChunkHeader {
            window: 1,
            first_item: 10,
            total_items: 20,
            part: 1,
            parts: 2,
        };
        assert!(checked(&good, 10).is_ok());
        assert!(checked(&good, 11).is_err());
        assert!(checked(&ChunkHeader { part: 2, ..good }, 5).is_err());
        let overflow = ChunkHeader {
            first_item: u64::MAX,
            ..good
        };
        assert!(checked(&overflow, 1).is_err());
    }
}
