//! What the system publishes for outside subscribers (docs/interface.md): each frame's final
//! pose as it becomes final, on `pssba/<instance>/final_poses`. Any number of subscribers, up to
//! [`FINAL_POSE_SUBSCRIBERS`]; a slow or dead one never stalls the pipeline (safe overflow: its
//! oldest unread pose is overwritten); one that joins late gets the last
//! [`FINAL_POSE_HISTORY`] poses first.

use crate::services::{self, ServiceError};
use crate::types::IsometryMsg;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::prelude::*;
use nalgebra::Isometry3;

/// The final poses' service (suffix; `pssba/<instance>/final_poses`).
pub const FINAL_POSES: &str = services::names::FINAL_POSES;
/// Most outside subscribers of the final poses at once.
pub const FINAL_POSE_SUBSCRIBERS: usize = 8;
/// Final poses a late subscriber receives first (and each subscriber's queue length).
pub const FINAL_POSE_HISTORY: usize = 4096;

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

/// The publisher of final poses (the smooth stage).
#[derive(Debug)]
pub struct FinalPosePublisher {
    publisher: Publisher<ipc::Service, FinalPoseMsg, ()>,
    notifier: Notifier<ipc::Service>,
    sent: u64,
}

fn ipc_error(what: &str, e: impl std::fmt::Debug) -> ServiceError {
    ServiceError::ipc(what, e)
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

impl FinalPosePublisher {
    /// Creates the service and its publisher.
    pub fn create(node: &Node<ipc::Service>) -> Result<Self, ServiceError> {
        let name = services::service_name(node, FINAL_POSES)?;
        let service = node
            .service_builder(&name)
            .publish_subscribe::<FinalPoseMsg>()
            .max_publishers(1)
            .max_subscribers(FINAL_POSE_SUBSCRIBERS)
            .history_size(FINAL_POSE_HISTORY)
            .subscriber_max_buffer_size(FINAL_POSE_HISTORY)
            .subscriber_max_borrowed_samples(8)
            .enable_safe_overflow(true)
            .open_or_create()
            .map_err(|e| ipc_error(name.as_str(), e))?;
        let publisher = service
            .publisher_builder()
            .create()
            .map_err(|e| ipc_error("final pose publisher", e))?;
        let notifier = services::event_service(node, FINAL_POSES)?
            .notifier_builder()
            .create()
            .map_err(|e| ipc_error("final pose notifier", e))?;
        Ok(Self {
            publisher,
            notifier,
            sent: 0,
        })
    }

    fn send(&mut self, message: FinalPoseMsg) -> Result<(), ServiceError> {
        self.publisher
            .send_copy(message)
            .map_err(|e| ipc_error("sending a final pose", e))?;
        self.notifier
            .notify()
            .map_err(|e| ipc_error("notifying a final pose", e))?;
        Ok(())
    }

    /// Publishes the final poses of one window.
    pub fn publish(
        &mut self,
        window: u64,
        failed: bool,
        finals: &[FinalPose],
    ) -> Result<(), ServiceError> {
        for f in finals {
            self.send(FinalPoseMsg {
                sequence: f.sequence,
                stamp_s: f.stamp_s,
                world_from_lidar: IsometryMsg::from_isometry(&f.world_from_lidar),
                window,
                kept_initial: u32::from(failed),
                end_of_stream: 0,
            })?;
            self.sent += 1;
        }
        Ok(())
    }

    /// Publishes the end-of-stream marker.
    pub fn end_stream(&mut self) -> Result<(), ServiceError> {
        self.send(FinalPoseMsg {
            sequence: self.sent,
            end_of_stream: 1,
            ..FinalPoseMsg::default()
        })
    }
}
