//! The adjust stage run in-process against a hand-made smooth stage.

use pssba_msg::BlockHeader;
use pssba_msg::services::{self, names};
use pssba_msg::types::block_kind;
use pssba_system::SystemConfig;
use pssba_system::adjust::{self, AdjustOptions};
use pssba_system::shm;
use std::time::Duration;

/// A run whose windows all failed before reaching the adjust stage sends it only the
/// shutdown block, and the pose sets' consumers may be gone before it is read. The stage
/// must then stop cleanly instead of waiting for consumers that will never come (this once
/// failed a live run after the start-up timeout, in CI).
#[test]
fn a_shutdown_with_no_block_before_it_needs_no_pose_set_consumers() {
    let prefix = format!("{}adjust-test-", pssba_system::launcher::unique_prefix());
    let system = SystemConfig {
        startup_timeout_s: 5.0,
        backpressure_timeout_s: 5.0,
        ..SystemConfig::default()
    };
    let options = AdjustOptions {
        prefix: prefix.clone(),
        system: system.clone(),
    };
    let stage = std::thread::spawn(move || adjust::run(&options));

    // The smooth stage's side: wait for the adjust stage's block subscriber, send the
    // shutdown block and leave, never subscribing to the pose sets.
    let node = services::create_node(&prefix, "smooth").expect("node");
    let blocks_service = services::blocks_service(&node).expect("blocks service");
    let blocks = services::publisher(
        &blocks_service,
        system.sample_words,
        system.backpressure_timeout(),
    )
    .expect("blocks publisher");
    let notifier = shm::notifier(&services::event_service(&node, names::BLOCKS).expect("event"))
        .expect("notifier");
    shm::wait_for_subscribers(
        &node,
        &blocks_service,
        1,
        "factor blocks",
        Duration::from_secs(10),
    )
    .expect("the adjust stage subscribes");
    let shutdown = BlockHeader {
        kind: block_kind::SHUTDOWN,
        ..BlockHeader::default()
    };
    shm::publish_slice(&blocks, &notifier, shutdown, &[] as &[f64]).expect("sent");

    let result = stage.join().expect("the stage does not panic");
    // Before the fix: "pose sets: only 0 of 2 consumers connected after 5 s".
    assert!(result.is_ok(), "{result:?}");
}

/// An adjust stage restarted after the shutdown block was sent never got it: the smooth
/// stage's last wait sends it again to the newcomer, which then stops (before, the smooth
/// stage waited out its backpressure timeout, 120 s by default, and the newcomer stayed).
#[test]
fn an_adjust_stage_restarted_after_the_shutdown_is_told_again() {
    let prefix = format!("{}adjust-late-", pssba_system::launcher::unique_prefix());
    let system = SystemConfig {
        startup_timeout_s: 5.0,
        backpressure_timeout_s: 5.0,
        ..SystemConfig::default()
    };
    let start_adjust = || {
        let options = AdjustOptions {
            prefix: prefix.clone(),
            system: system.clone(),
        };
        std::thread::spawn(move || adjust::run(&options))
    };
    let node = services::create_node(&prefix, "smooth").expect("node");
    let blocks_service = services::blocks_service(&node).expect("blocks service");
    let blocks = services::publisher(
        &blocks_service,
        system.sample_words,
        system.backpressure_timeout(),
    )
    .expect("blocks publisher");
    let notifier = shm::notifier(&services::event_service(&node, names::BLOCKS).expect("event"))
        .expect("notifier");
    let shutdown = BlockHeader {
        kind: block_kind::SHUTDOWN,
        ..BlockHeader::default()
    };
    let send_shutdown = || shm::publish_slice(&blocks, &notifier, shutdown, &[] as &[f64]);
    let wait = Duration::from_secs(10);

    let first = start_adjust();
    shm::wait_for_subscribers(&node, &blocks_service, 1, "factor blocks", wait).expect("first");
    let told = shm::subscriber_ids(&blocks_service);
    send_shutdown().expect("sent");
    assert!(first.join().expect("no panic").is_ok());
    // The restarted stage subscribes after the shutdown block went out.
    let restarted = start_adjust();
    shm::wait_for_subscribers(&node, &blocks_service, 1, "factor blocks", wait).expect("again");

    shm::linger_telling_newcomers(
        &node,
        &blocks_service,
        told,
        "factor blocks",
        system.backpressure_timeout(),
        send_shutdown,
    )
    .expect("lingered");
    assert!(
        shm::subscriber_ids(&blocks_service).is_empty(),
        "the restarted adjust stage is still subscribed"
    );
    let result = restarted.join().expect("no panic");
    assert!(result.is_ok(), "{result:?}");
}
