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

type FinalPosesService =
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, FinalPoseMsg, ()>;

/// Opens or creates `pssba/<instance>/final_poses` with the settings of docs/interface.md.
fn final_poses_service(node: &Node<ipc::Service>) -> Result<FinalPosesService, ServiceError> {
    let name = services::service_name(node, FINAL_POSES)?;
    node.service_builder(&name)
        .publish_subscribe::<FinalPoseMsg>()
        .max_publishers(1)
        .max_subscribers(FINAL_POSE_SUBSCRIBERS)
        .history_size(FINAL_POSE_HISTORY)
        .subscriber_max_buffer_size(FINAL_POSE_HISTORY)
        .subscriber_max_borrowed_samples(8)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| ipc_error(name.as_str(), e))
}

/// An outside subscriber of the final poses: one of up to [`FINAL_POSE_SUBSCRIBERS`]; it first
/// receives the last [`FINAL_POSE_HISTORY`] poses, then each pose as it becomes final.
#[derive(Debug)]
pub struct FinalPoseSubscriber {
    subscriber: iceoryx2::port::subscriber::Subscriber<ipc::Service, FinalPoseMsg, ()>,
    listener: iceoryx2::port::listener::Listener<ipc::Service>,
}

impl FinalPoseSubscriber {
    /// Subscribes on `node` (whose prefix names the instance).
    pub fn create(node: &Node<ipc::Service>) -> Result<Self, ServiceError> {
        let subscriber = final_poses_service(node)?
            .subscriber_builder()
            .create()
            .map_err(|e| ipc_error("final pose subscriber", e))?;
        let listener = services::event_service(node, FINAL_POSES)?
            .listener_builder()
            .create()
            .map_err(|e| ipc_error("final pose listener", e))?;
        Ok(Self {
            subscriber,
            listener,
        })
    }

    /// The next final pose waiting (or the end-of-stream marker), if any. Check its pose with
    /// [`crate::IsometryMsg::to_isometry`] before use: nothing read from shared memory is
    /// trusted.
    pub fn receive(&self) -> Result<Option<FinalPoseMsg>, ServiceError> {
        let sample = self
            .subscriber
            .receive()
            .map_err(|e| ipc_error("receiving a final pose", e))?;
        Ok(sample.map(|s| *s.payload()))
    }

    /// Blocks until a final pose is notified or `timeout` passes.
    pub fn wait(&self, timeout: std::time::Duration) -> Result<(), ServiceError> {
        crate::error::woken(self.listener.timed_wait(|_| {}, timeout))
            .map_err(|e| ipc_error("waiting for final poses", e))
    }
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
        let service = final_poses_service(node)?;
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

    /// Final poses published so far.
    pub fn sent(&self) -> u64 {
        self.sent
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
