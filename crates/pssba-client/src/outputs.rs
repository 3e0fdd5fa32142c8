//! What the system publishes for outside subscribers (docs/interface.md): each frame's final
//! pose as it becomes final, on `pssba/<instance>/final_poses`, and a final pose again when a
//! loop closure moves it, on `pssba/<instance>/revised_poses` (same layout; `window` is the
//! window whose closure moved it). Any number of subscribers, up to
//! [`FINAL_POSE_SUBSCRIBERS`]; a slow or dead one never stalls the pipeline (safe overflow: its
//! oldest unread pose is overwritten); one that joins late gets the last
//! [`FINAL_POSE_HISTORY`] poses first.

use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::prelude::*;
use pssba_msg::ServiceError;
use pssba_msg::node::{event_service, woken};
use pssba_msg::public::services::{final_poses_service, revised_poses_service};
use pssba_msg::public::types::IsometryMsg;

pub use pssba_msg::public::services::names::{FINAL_POSES, REVISED_POSES};
pub use pssba_msg::public::services::{FINAL_POSE_HISTORY, FINAL_POSE_SUBSCRIBERS};
pub use pssba_msg::public::types::{FinalPose, FinalPoseMsg};

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
        Self::create_on(node, FINAL_POSES)
    }

    /// Subscribes to the revised poses: a final pose published again because a loop closure
    /// moved it (the last one received for a sequence is its pose).
    pub fn create_revised(node: &Node<ipc::Service>) -> Result<Self, ServiceError> {
        Self::create_on(node, REVISED_POSES)
    }

    fn create_on(node: &Node<ipc::Service>, suffix: &str) -> Result<Self, ServiceError> {
        let service = if suffix == REVISED_POSES {
            revised_poses_service(node)?
        } else {
            final_poses_service(node)?
        };
        let subscriber = service
            .subscriber_builder()
            .create()
            .map_err(|e| ipc_error("final pose subscriber", e))?;
        let listener = event_service(node, suffix)?
            .listener_builder()
            .create()
            .map_err(|e| ipc_error("final pose listener", e))?;
        Ok(Self {
            subscriber,
            listener,
        })
    }

    /// The next final pose waiting (or the end-of-stream marker), if any. Check its pose with
    /// [`IsometryMsg::to_isometry`] before use: nothing read from shared memory is
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
        woken(self.listener.timed_wait(|_| {}, timeout))
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

impl FinalPosePublisher {
    /// Creates the service and its publisher.
    pub fn create(node: &Node<ipc::Service>) -> Result<Self, ServiceError> {
        Self::create_on(node, final_poses_service(node)?, FINAL_POSES)
    }

    /// The publisher of the revised poses (`revised_poses`).
    pub fn create_revised(node: &Node<ipc::Service>) -> Result<Self, ServiceError> {
        Self::create_on(node, revised_poses_service(node)?, REVISED_POSES)
    }

    fn create_on(
        node: &Node<ipc::Service>,
        service: pssba_msg::public::services::FinalPosesService,
        suffix: &str,
    ) -> Result<Self, ServiceError> {
        let publisher = service
            .publisher_builder()
            .create()
            .map_err(|e| ipc_error("final pose publisher", e))?;
        let notifier = event_service(node, suffix)?
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
