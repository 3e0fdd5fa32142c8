//! The services of the system, each built by one function so every process opens it with the
//! same settings (iceoryx2 checks builder settings as requirements between processes).
//!
//! Every publish-subscribe service is lossless (no safe overflow, a publisher waits when a
//! subscriber's buffer is full) and has a paired event service of the same name plus
//! `/event`, on which the publisher notifies after each send so consumers wait on a WaitSet
//! instead of polling.

use crate::types::{BlockHeader, FrameHeader, PointXyz, PoseMsg, PoseSetHeader, ResultHeader};
use iceoryx2::port::{BackpressureAction, BackpressureInfo};
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::{event, publish_subscribe};
use std::time::Duration;

/// Why a node, service or port could not be created.
#[derive(Debug, thiserror::Error)]
#[error("{what}: {reason}")]
pub struct ServiceError {
    /// Which node, service or port.
    pub what: String,
    /// The iceoryx2 error, as text.
    pub reason: String,
}

fn fail(what: impl Into<String>) -> impl FnOnce(String) -> ServiceError {
    let what = what.into();
    move |reason| ServiceError { what, reason }
}

macro_rules! try_ipc {
    ($expr:expr, $what:expr) => {
        $expr.map_err(|e| fail($what)(format!("{e:?}")))?
    };
}

/// Frames (ingest -> smooth, record).
pub type FramesService = publish_subscribe::PortFactory<ipc::Service, [PointXyz], FrameHeader>;
/// Factor blocks (smooth -> adjust).
pub type BlocksService = publish_subscribe::PortFactory<ipc::Service, [f64], BlockHeader>;
/// Adjusted pose sets with the LM report (adjust -> smooth, record).
pub type PoseSetsService = publish_subscribe::PortFactory<ipc::Service, [PoseMsg], PoseSetHeader>;
/// Finished windows (smooth -> record).
pub type ResultsService = publish_subscribe::PortFactory<ipc::Service, [f64], ResultHeader>;
/// The event service paired with a publish-subscribe service.
pub type EventService = event::PortFactory<ipc::Service>;

/// Service names.
pub mod names {
    /// Frames.
    pub const FRAMES: &str = "pssba/frames";
    /// Factor blocks.
    pub const BLOCKS: &str = "pssba/factor_blocks";
    /// Pose sets.
    pub const POSE_SETS: &str = "pssba/pose_sets";
    /// Window results.
    pub const RESULTS: &str = "pssba/results";
}

/// Frames a subscriber may hold queued before the publisher waits (backpressure).
pub const FRAME_BUFFER: usize = 8;

/// Creates this process's node; runs with different `prefix`es never see each other.
pub fn create_node(prefix: &str, name: &str) -> Result<Node<ipc::Service>, ServiceError> {
    let mut config = Config::default();
    config.global.prefix = try_ipc!(
        FileName::new(prefix.as_bytes()),
        format!("prefix {prefix:?}")
    );
    let node_name = try_ipc!(NodeName::new(name), format!("node name {name:?}"));
    Ok(try_ipc!(
        NodeBuilder::new()
            .name(&node_name)
            .config(&config)
            .create::<ipc::Service>(),
        format!("node {name}")
    ))
}

/// Names of the live (alive, not dead) iceoryx2 nodes under `prefix`: tells whether a system
/// or an outside process is attached to a live instance.
pub fn alive_node_names(prefix: &str) -> Result<Vec<String>, ServiceError> {
    use iceoryx2::node::NodeView;
    let mut config = Config::default();
    config.global.prefix = try_ipc!(
        FileName::new(prefix.as_bytes()),
        format!("prefix {prefix:?}")
    );
    let mut names = Vec::new();
    try_ipc!(
        Node::<ipc::Service>::list(&config, |state| {
            if let NodeState::Alive(view) = state
                && let Some(details) = view.details()
            {
                names.push(details.name().as_str().to_string());
            }
            CallbackProgression::Continue
        }),
        format!("listing the nodes of {prefix}")
    );
    Ok(names)
}

fn service_name(name: &str) -> Result<ServiceName, ServiceError> {
    Ok(try_ipc!(
        ServiceName::new(name),
        format!("service name {name:?}")
    ))
}

macro_rules! pubsub {
    ($node:expr, $name:expr, $payload:ty, $header:ty, $subscribers:expr, $buffer:expr) => {{
        Ok(try_ipc!(
            $node
                .service_builder(&service_name($name)?)
                .publish_subscribe::<$payload>()
                .user_header::<$header>()
                .max_publishers(1)
                .max_subscribers($subscribers)
                .history_size(0)
                .subscriber_max_buffer_size($buffer)
                .subscriber_max_borrowed_samples(1)
                .enable_safe_overflow(false)
                .open_or_create(),
            format!("service {}", $name)
        ))
    }};
}

// Subscriber counts are exact (every sample slot is shared memory the publisher zeroes), and
// producers wait for exactly this many consumers at start-up.

/// Consumers of frames: smooth and record.
pub const FRAME_SUBSCRIBERS: usize = 2;
/// Consumers of factor blocks: adjust.
pub const BLOCK_SUBSCRIBERS: usize = 1;
/// Consumers of pose sets: smooth and record.
pub const POSE_SET_SUBSCRIBERS: usize = 2;
/// Consumers of window results: record.
pub const RESULT_SUBSCRIBERS: usize = 1;

/// Opens or creates the frames service.
pub fn frames_service(node: &Node<ipc::Service>) -> Result<FramesService, ServiceError> {
    pubsub!(
        node,
        names::FRAMES,
        [PointXyz],
        FrameHeader,
        FRAME_SUBSCRIBERS,
        FRAME_BUFFER
    )
}

/// Opens or creates the factor-block service.
pub fn blocks_service(node: &Node<ipc::Service>) -> Result<BlocksService, ServiceError> {
    pubsub!(
        node,
        names::BLOCKS,
        [f64],
        BlockHeader,
        BLOCK_SUBSCRIBERS,
        1
    )
}

/// Opens or creates the pose-set service.
pub fn pose_sets_service(node: &Node<ipc::Service>) -> Result<PoseSetsService, ServiceError> {
    pubsub!(
        node,
        names::POSE_SETS,
        [PoseMsg],
        PoseSetHeader,
        POSE_SET_SUBSCRIBERS,
        8
    )
}

/// Opens or creates the window-result service.
pub fn results_service(node: &Node<ipc::Service>) -> Result<ResultsService, ServiceError> {
    pubsub!(
        node,
        names::RESULTS,
        [f64],
        ResultHeader,
        RESULT_SUBSCRIBERS,
        2
    )
}

/// Opens or creates the event service paired with publish-subscribe service `name`.
pub fn event_service(node: &Node<ipc::Service>, name: &str) -> Result<EventService, ServiceError> {
    let event_name = format!("{name}/event");
    Ok(try_ipc!(
        node.service_builder(&service_name(&event_name)?)
            .event()
            .max_notifiers(4)
            .max_listeners(4)
            .open_or_create(),
        format!("event service {event_name}")
    ))
}

/// The backpressure handler of every publisher: wait (iceoryx2's adaptive wait, not a spin)
/// while a subscriber's buffer is full, give up after `timeout` so a stuck consumer makes the
/// send fail with an error instead of hanging the producer forever.
pub fn backpressure_handler(
    timeout: Duration,
) -> impl Fn(&BackpressureInfo) -> BackpressureAction + Send + 'static {
    move |info: &BackpressureInfo| {
        if info.elapsed_time > timeout {
            BackpressureAction::DiscardDataAndFail
        } else {
            BackpressureAction::Retry
        }
    }
}

/// Creates a publisher whose samples hold up to `max_slice_len` elements, allocated once
/// (static: iceoryx2 0.10 can lose a sample when a growing segment is replaced before a
/// subscriber has mapped it, seen here as a missing frame), with the shared backpressure
/// handler.
pub fn publisher<P, H>(
    service: &publish_subscribe::PortFactory<ipc::Service, [P], H>,
    max_slice_len: usize,
    backpressure_timeout: Duration,
) -> Result<iceoryx2::port::publisher::Publisher<ipc::Service, [P], H>, ServiceError>
where
    P: std::fmt::Debug + ZeroCopySend + 'static,
    H: std::fmt::Debug + ZeroCopySend + 'static,
{
    Ok(try_ipc!(
        service
            .publisher_builder()
            .initial_max_slice_len(max_slice_len.max(1))
            .allocation_strategy(AllocationStrategy::Static)
            .max_loaned_samples(1)
            .set_backpressure_handler(backpressure_handler(backpressure_timeout))
            .create(),
        "publisher"
    ))
}
