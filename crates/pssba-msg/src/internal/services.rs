//! The internal services of the system (between its own stages; outside processes have no
//! business on them), each built by one function so every stage opens it with the same
//! settings, and the table of which stage subscribes to which service, from which every
//! subscriber count is derived.
//!
//! Every internal publish-subscribe service is lossless (no safe overflow, a publisher waits
//! when a subscriber's buffer is full) and has a paired event service of the same name plus
//! `/event`, on which the publisher notifies after each send so consumers wait on a WaitSet
//! instead of polling.

use crate::error::ServiceError;
use crate::internal::types::{BlockHeader, PoseMsg, PoseSetHeader, RecordedAck, ResultHeader};
use crate::lossless_service;
use crate::node::service_name;
use crate::public::services::{FRAME_SUBSCRIBERS, names as public};
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::publish_subscribe;

/// The stages of the system, each a process of its own (`pssba stage NAME`). Their start order,
/// arguments and restart policies are pssba-system's stage table; what each subscribes to is
/// part of the protocol ([`SUBSCRIPTIONS`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Stage {
    /// Reads frames from a source and publishes them.
    Ingest,
    /// Cuts windows, builds factor blocks, publishes results.
    Smooth,
    /// Solves factor blocks (Levenberg-Marquardt).
    Adjust,
    /// Writes the recording.
    Record,
}

impl Stage {
    /// Every stage.
    pub const ALL: [Stage; 4] = [Stage::Ingest, Stage::Smooth, Stage::Adjust, Stage::Record];

    /// Its name: the `pssba stage` subcommand, its iceoryx2 node, its log prefix.
    pub const fn name(self) -> &'static str {
        match self {
            Stage::Ingest => "ingest",
            Stage::Smooth => "smooth",
            Stage::Adjust => "adjust",
            Stage::Record => "record",
        }
    }

    /// The stage called `name`.
    pub fn from_name(name: &str) -> Option<Stage> {
        Stage::ALL.into_iter().find(|s| s.name() == name)
    }
}

impl std::fmt::Display for Stage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Service name suffixes of the internal services (the full name is
/// `pssba/<instance>/<suffix>`).
pub mod names {
    /// Factor blocks (smooth -> adjust).
    pub const BLOCKS: &str = "factor_blocks";
    /// Pose sets (adjust -> smooth, record).
    pub const POSE_SETS: &str = "pose_sets";
    /// Window results (smooth -> record).
    pub const RESULTS: &str = "results";
    /// Rewind requests (a restarted smooth or record stage -> ingest): the sequence number from
    /// which the ingest stage sends the frames again (the first frame that was not final, or
    /// not on disk, when the stage crashed).
    pub const FRAMES_REWIND: &str = "frames/rewind";
    /// What the recorder has on disk (record -> smooth, [`super::RecordedAck`]).
    pub const RESULTS_RECORDED: &str = "results/recorded";
}

/// Factor blocks (smooth -> adjust).
pub type BlocksService = publish_subscribe::PortFactory<ipc::Service, [f64], BlockHeader>;
/// Adjusted pose sets with the LM report (adjust -> smooth, record).
pub type PoseSetsService = publish_subscribe::PortFactory<ipc::Service, [PoseMsg], PoseSetHeader>;
/// Finished windows (smooth -> record).
pub type ResultsService = publish_subscribe::PortFactory<ipc::Service, [f64], ResultHeader>;

// Subscriber counts are exact (every sample slot is shared memory the publisher zeroes), and
// producers wait for exactly this many consumers at start-up. They are counted from one table.

/// Which stage subscribes to which service of the system (outside subscribers of the public
/// outputs are not counted here: those services have their own limits).
pub const SUBSCRIPTIONS: [(Stage, &str); 8] = [
    (Stage::Smooth, public::FRAMES),
    (Stage::Record, public::FRAMES),
    (Stage::Adjust, names::BLOCKS),
    (Stage::Smooth, names::POSE_SETS),
    (Stage::Record, names::POSE_SETS),
    (Stage::Record, names::RESULTS),
    (Stage::Ingest, names::FRAMES_REWIND),
    (Stage::Smooth, names::RESULTS_RECORDED),
];

/// The services `stage` subscribes to, from [`SUBSCRIPTIONS`].
pub fn subscriptions_of(stage: Stage) -> impl Iterator<Item = &'static str> {
    SUBSCRIPTIONS
        .iter()
        .filter(move |(s, _)| *s == stage)
        .map(|(_, service)| *service)
}

/// Stages that may ask for a rewind at once (a restarted smooth stage keeps its request's
/// publisher while it runs).
const REWIND_PUBLISHERS: usize = 2;

/// Confirmations of the recorder (one [`RecordedAck`]).
pub type RecordedService = publish_subscribe::PortFactory<ipc::Service, RecordedAck, ()>;

/// Rewind requests (one u64: a sequence number).
pub type RewindService = publish_subscribe::PortFactory<ipc::Service, u64, ()>;

const fn same(a: &str, b: &str) -> bool {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    if a.len() != b.len() {
        return false;
    }
    let mut k = 0;
    while k < a.len() {
        if a[k] != b[k] {
            return false;
        }
        k += 1;
    }
    true
}

/// Stages subscribed to `service` in [`SUBSCRIPTIONS`].
pub const fn subscribers_of(service: &str) -> usize {
    let mut count = 0;
    let mut k = 0;
    while k < SUBSCRIPTIONS.len() {
        if same(SUBSCRIPTIONS[k].1, service) {
            count += 1;
        }
        k += 1;
    }
    count
}

/// Consumers of factor blocks.
pub const BLOCK_SUBSCRIBERS: usize = subscribers_of(names::BLOCKS);
/// Consumers of pose sets.
pub const POSE_SET_SUBSCRIBERS: usize = subscribers_of(names::POSE_SETS);
/// Consumers of window results.
pub const RESULT_SUBSCRIBERS: usize = subscribers_of(names::RESULTS);
/// Consumers of rewind requests.
pub const REWIND_SUBSCRIBERS: usize = subscribers_of(names::FRAMES_REWIND);
/// Consumers of the recorder's confirmations.
pub const RECORDED_SUBSCRIBERS: usize = subscribers_of(names::RESULTS_RECORDED);
// The frames service (public) admits exactly the system's frame consumers.
const _: () = assert!(subscribers_of(public::FRAMES) == FRAME_SUBSCRIBERS);

/// Opens or creates the factor-block service.
pub fn blocks_service(node: &Node<ipc::Service>) -> Result<BlocksService, ServiceError> {
    lossless_service!(
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
    lossless_service!(
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
    lossless_service!(
        node,
        names::RESULTS,
        [f64],
        ResultHeader,
        RESULT_SUBSCRIBERS,
        2
    )
}

/// Opens or creates the rewind-request service. A request is never waited for (safe
/// overflow: the newest requests are kept).
pub fn rewind_service(node: &Node<ipc::Service>) -> Result<RewindService, ServiceError> {
    let name = service_name(node, names::FRAMES_REWIND)?;
    node.service_builder(&name)
        .publish_subscribe::<u64>()
        .max_publishers(REWIND_PUBLISHERS)
        .max_subscribers(REWIND_SUBSCRIBERS)
        .history_size(0)
        .subscriber_max_buffer_size(4)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| ServiceError::ipc(format!("service {}", name.as_str()), e))
}

/// Opens or creates the recorder's confirmation service. Only the newest confirmation
/// matters, so it is never waited for (safe overflow); a replay request is sent once, when a
/// restarted recorder has subscribed to the results.
pub fn recorded_service(node: &Node<ipc::Service>) -> Result<RecordedService, ServiceError> {
    let name = service_name(node, names::RESULTS_RECORDED)?;
    node.service_builder(&name)
        .publish_subscribe::<RecordedAck>()
        .max_publishers(1)
        .max_subscribers(RECORDED_SUBSCRIBERS)
        .history_size(0)
        .subscriber_max_buffer_size(8)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| ServiceError::ipc(format!("service {}", name.as_str()), e))
}
