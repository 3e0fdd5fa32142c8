//! The `#[repr(C)]` types of the internal services (between the system's own stages): a user
//! header per service plus a slice payload. Plain primitives and arrays only (no Vec, String,
//! Option or nalgebra types).
#![allow(unsafe_code)] // `derive(ZeroCopySend)` emits the `unsafe impl` marker; nothing else.

#[cfg(feature = "core")]
use crate::error::MsgError;
use iceoryx2::prelude::ZeroCopySend;
#[cfg(feature = "core")]
use nalgebra::{Isometry3, Matrix3, Vector3};
#[cfg(feature = "core")]
use pssba_core::geometry::Pose;

/// A world-from-lidar pose as a row-major rotation matrix and a translation, so poses cross
/// process boundaries bit-exactly (the system must match the in-process run to 1e-9).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("pssba::PoseMsg")]
pub struct PoseMsg {
    /// Rotation R, row-major.
    pub rotation: [f64; 9],
    /// Translation t (m).
    pub translation_m: [f64; 3],
}

/// Largest accepted `|R^T R - I|` for a rotation read from shared memory.
#[cfg(feature = "core")]
const ROTATION_TOLERANCE: f64 = 1e-6;

impl PoseMsg {
    /// Words of a pose in an f64 payload.
    pub const WORDS: usize = 12;

    /// From the core's pose type.
    #[cfg(feature = "core")]
    pub fn from_pose(pose: &Pose) -> Self {
        let r = &pose.rotation;
        Self {
            rotation: [
                r[(0, 0)],
                r[(0, 1)],
                r[(0, 2)],
                r[(1, 0)],
                r[(1, 1)],
                r[(1, 2)],
                r[(2, 0)],
                r[(2, 1)],
                r[(2, 2)],
            ],
            translation_m: [pose.translation.x, pose.translation.y, pose.translation.z],
        }
    }

    /// From an isometry.
    #[cfg(feature = "core")]
    pub fn from_isometry(world_from_lidar: &Isometry3<f64>) -> Self {
        Self::from_pose(&Pose::from_isometry(world_from_lidar))
    }

    /// Checked conversion to the core's pose: finite and a rotation.
    #[cfg(feature = "core")]
    pub fn to_pose(&self, message: &'static str, index: u64) -> Result<Pose, MsgError> {
        if !self
            .rotation
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
        let rotation = Matrix3::from_row_slice(&self.rotation);
        let error = (rotation.transpose() * rotation - Matrix3::identity()).norm();
        if error > ROTATION_TOLERANCE {
            return Err(MsgError::NotARotation {
                message,
                index,
                error,
            });
        }
        Ok(Pose {
            rotation,
            translation: Vector3::from(self.translation_m),
        })
    }

    /// The 12 words `[R row-major, t]`.
    pub fn words(&self) -> [f64; 12] {
        let mut w = [0.0; 12];
        w[..9].copy_from_slice(&self.rotation);
        w[9..].copy_from_slice(&self.translation_m);
        w
    }

    /// From 12 words (unchecked; see [`Self::to_pose`]).
    pub fn from_words(words: &[f64]) -> Self {
        let mut msg = Self::default();
        msg.rotation.copy_from_slice(&words[..9]);
        msg.translation_m.copy_from_slice(&words[9..12]);
        msg
    }
}

/// Where one sample sits in a message split over several samples (factor blocks and window
/// results have no size limit; one sample holds at most `system.sample_words` words). The
/// parts of a message are sent in order; see [`crate::codec::parts`].
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("pssba::Parts")]
pub struct Parts {
    /// Message id, unique per publisher (0, 1, 2, ...).
    pub message_id: u64,
    /// Index of this sample in the message (0..count).
    pub index: u32,
    /// Samples in the message (at least 1).
    pub count: u32,
    /// Position of this sample's first word in the whole message.
    pub offset_words: u64,
    /// Words of the whole message.
    pub total_words: u64,
}

/// Kinds of [`BlockHeader`].
pub mod block_kind {
    /// A factor block to solve.
    pub const SOLVE: u32 = 0;
    /// No more blocks: the adjust stage exits.
    pub const SHUTDOWN: u32 = 1;
}

/// Header of a factor block (`factor_blocks` service, payload `[f64]`; layout in
/// [`crate::codec::block`]).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("pssba::BlockHeader")]
pub struct BlockHeader {
    /// [`block_kind`].
    pub kind: u32,
    /// Scale index within the window.
    pub scale: u32,
    /// Window index.
    pub window: u64,
    /// Kernel width (m).
    pub gamma_m: f64,
    /// Cauchy loss scale (m).
    pub robust_scale_m: f64,
    /// Frames in the window (poses and fixed flags in the payload).
    pub frame_count: u64,
    /// Surfaces in the payload.
    pub surface_count: u64,
    /// Residual points in the payload.
    pub point_count: u64,
    /// LM: maximum linearisations.
    pub max_iterations: u64,
    /// LM: initial damping.
    pub initial_lambda: f64,
    /// LM: pose prior sigma, translation (m; infinite = none).
    pub prior_translation_m: f64,
    /// LM: pose prior sigma, rotation (rad; infinite = none).
    pub prior_rotation_rad: f64,
    /// LM: motion prior sigma on consecutive frames' relative translation (m; infinite =
    /// none).
    pub motion_translation_m: f64,
    /// LM: motion prior sigma on relative rotation (rad; infinite = none).
    pub motion_rotation_rad: f64,
    /// This sample's place in the message.
    pub parts: Parts,
}

/// Header of an adjusted pose set (`pose_sets` service, payload `[PoseMsg]`, one per window
/// frame): the LM report of one scale.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("pssba::PoseSetHeader")]
pub struct PoseSetHeader {
    /// Window index (echoes the block).
    pub window: u64,
    /// Scale index (echoes the block).
    pub scale: u32,
    /// 1 if the block could not be used (the poses are the input poses).
    pub rejected: u32,
    /// Robust cost before LM.
    pub cost_before: f64,
    /// Robust cost after LM.
    pub cost_after: f64,
    /// LM linearisations.
    pub iterations: u64,
    /// Residuals linking two frames.
    pub residuals: u64,
    /// Free frames without residuals.
    pub unconstrained_frames: u64,
    /// Wall time of the solve (s).
    pub solve_time_s: f64,
    /// The message id of the factor block answered (its [`Parts::message_id`]): a sender
    /// matches answers by it, so an answer to an older block (from before a stage restarted)
    /// is never taken for the answer to a newer one.
    pub block_id: u64,
}

/// Kinds of [`ResultHeader`].
pub mod result_kind {
    /// A finished window.
    pub const WINDOW: u32 = 0;
    /// The run is over: no more windows.
    pub const END_OF_RUN: u32 = 1;
}

/// Header of a finished window (`results` service, payload `[f64]`; layout in
/// [`crate::codec::result`]).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("pssba::ResultHeader")]
pub struct ResultHeader {
    /// [`result_kind`].
    pub kind: u32,
    /// 1 if the schedule converged (T_conv reached).
    pub converged: u32,
    /// Window index.
    pub window: u64,
    /// Frames whose final pose this message carries.
    pub final_count: u64,
    /// Frames made final earlier whose final pose this window's loop closure moved (after
    /// the finals in the payload).
    pub revised_count: u64,
    /// World surfaces of the last scale.
    pub surface_count: u64,
    /// Smoothed map points (world).
    pub map_point_count: u64,
    /// Scale reports.
    pub scale_count: u64,
    /// 1 if the window's adjustment failed: its frames kept their corrected initial poses.
    pub failed: u32,
    /// Bytes of the failure message (UTF-8, one byte per payload word, at the end).
    pub error_bytes: u32,
    /// Frames the smooth stage has dropped so far (live input, overflow policy `drop`).
    pub frames_dropped: u64,
    /// This sample's place in the message.
    pub parts: Parts,
}

/// What the record stage has on disk (`results/recorded` service, record -> smooth): the
/// smooth stage keeps each window's result until the recorder confirms it, and sends what a
/// restarted recorder lost again.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("pssba::RecordedAck")]
pub struct RecordedAck {
    /// Windows recorded (0..next_window are on disk).
    pub next_window: u64,
    /// 1 if the end-of-run marker is on disk.
    pub end_of_run: u32,
    /// 1 from a restarted recorder: send every kept result from `next_window` on again.
    pub replay: u32,
}
