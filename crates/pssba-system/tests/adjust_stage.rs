//! The adjust stage run in-process against a hand-made smooth stage.

use iceoryx2::node::Node;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::prelude::ipc;
use pssba_msg::BlockHeader;
use pssba_msg::block_kind;
use pssba_msg::internal::services::{self, BlocksService, names};
use pssba_msg::node;
use pssba_system::adjust::{self, AdjustOptions};
use pssba_system::shm;
use pssba_system::{Config, SystemConfig};
use std::thread::JoinHandle;
use std::time::Duration;

/// The smooth stage's side of the factor blocks, under a prefix of its own.
struct SmoothSide {
    prefix: String,
    system: SystemConfig,
    node: Node<ipc::Service>,
    blocks_service: BlocksService,
    blocks: Publisher<ipc::Service, [f64], BlockHeader>,
    notifier: Notifier<ipc::Service>,
}

impl SmoothSide {
    fn new(test: &str) -> Self {
        let prefix = format!("{}{test}-", pssba_system::launcher::unique_prefix());
        let system = SystemConfig {
            startup_timeout_s: 5.0,
            backpressure_timeout_s: 5.0,
            ..SystemConfig::default()
        };
        let node = node::create_node(&prefix, "smooth").expect("node");
        let blocks_service = services::blocks_service(&node).expect("blocks service");
        let blocks = node::publisher(
            &blocks_service,
            system.sample_words,
            system.backpressure_timeout(),
        )
        .expect("blocks publisher");
        let event = node::event_service(&node, names::BLOCKS).expect("event service");
        let notifier = shm::notifier(&event).expect("notifier");
        Self {
            prefix,
            system,
            node,
            blocks_service,
            blocks,
            notifier,
        }
    }

    /// Starts an adjust stage on a thread and waits until it subscribes to the blocks.
    fn start_adjust(&self) -> JoinHandle<pssba_system::Result<()>> {
        let options = AdjustOptions {
            prefix: self.prefix.clone(),
            config: Config {
                system: self.system.clone(),
                ..Config::default()
            },
        };
        let stage = std::thread::spawn(move || adjust::run(&options));
        shm::wait_for_subscribers(
            &self.node,
            &self.blocks_service,
            1,
            "factor blocks",
            Duration::from_secs(10),
        )
        .expect("the adjust stage subscribes");
        stage
    }

    fn send_shutdown(&self) -> pssba_system::Result<()> {
        let shutdown = BlockHeader {
            kind: block_kind::SHUTDOWN,
            ..BlockHeader::default()
        };
        shm::publish_slice(&self.blocks, &self.notifier, shutdown, &[] as &[f64])
    }
}

/// A run whose windows all failed before reaching the adjust stage sends it only the
/// shutdown block, and the pose sets' consumers may be gone before it is read. The stage
/// must then stop cleanly instead of waiting for consumers that will never come (this once
/// failed a live run after the start-up timeout, in CI).
#[test]
fn a_shutdown_with_no_block_before_it_needs_no_pose_set_consumers() {
    // The smooth side sends the shutdown block and never subscribes to the pose sets.
    let smooth = SmoothSide::new("no-consumers");
    let stage = smooth.start_adjust();
    smooth.send_shutdown().expect("sent");
    let result = stage.join().expect("the stage does not panic");
    // Before the fix: "pose sets: only 0 of 2 consumers connected after 5 s".
    assert!(result.is_ok(), "{result:?}");
}

/// An adjust stage restarted after the shutdown block was sent never got it: the smooth
/// stage's last wait sends it again to the newcomer, which then stops (before, the smooth
/// stage waited out its backpressure timeout, 120 s by default, and the newcomer stayed).
#[test]
fn an_adjust_stage_restarted_after_the_shutdown_is_told_again() {
    let smooth = SmoothSide::new("restarted");
    let first = smooth.start_adjust();
    let told = shm::subscriber_ids(&smooth.blocks_service);
    smooth.send_shutdown().expect("sent");
    assert!(first.join().expect("no panic").is_ok());
    // The restarted stage subscribes after the shutdown block went out.
    let restarted = smooth.start_adjust();

    shm::linger_telling_newcomers(
        &smooth.node,
        &smooth.blocks_service,
        told,
        "factor blocks",
        smooth.system.backpressure_timeout(),
        || smooth.send_shutdown(),
    )
    .expect("lingered");
    assert!(
        shm::subscriber_ids(&smooth.blocks_service).is_empty(),
        "the restarted adjust stage is still subscribed"
    );
    let result = restarted.join().expect("no panic");
    assert!(result.is_ok(), "{result:?}");
}
