//! The adjust stage: solves each factor block (DESIGN steps 7-8, Levenberg-Marquardt over the
//! window's free poses) and publishes the adjusted poses with the LM report.

use crate::Config;
use crate::Error;
use crate::error::{Context, bail};
use crate::stages::table::StageArgs;
use crate::transport::shm::{self, WAKE_INTERVAL};
use pssba_core::Parallelism;
use pssba_core::lm::solve_block;
use pssba_msg::Stage;
use pssba_msg::block_kind;
use pssba_msg::internal::services::{self, names};
use pssba_msg::node;
use pssba_msg::{BlockHeader, PoseMsg, PoseSetHeader, Reassembly};
use std::time::Instant;

/// Options of the adjust stage.
#[derive(Debug, Clone)]
pub struct AdjustOptions {
    /// iceoryx2 prefix of this run.
    pub prefix: String,
    /// The run's configuration.
    pub config: Config,
}

/// `pssba stage adjust`: the options from the stage's arguments ([`crate::stages::table`]).
pub fn main(args: StageArgs, config: Config) -> crate::Result<()> {
    run(&AdjustOptions {
        prefix: args.prefix,
        config,
    })
}

/// Largest factor block accepted (words), whatever its header claims.
const MAX_BLOCK_WORDS: u64 = pssba_msg::codec::block::MAX_ITEMS * 8;

/// Runs the stage until the shutdown block arrives.
pub fn run(options: &AdjustOptions) -> crate::Result<()> {
    let stage_started = Instant::now();
    let system = &options.config.system;
    let node = node::create_node(&options.prefix, Stage::Adjust.name())?;
    let blocks_service = services::blocks_service(&node)?;
    let blocks = blocks_service
        .subscriber_builder()
        .create()
        .map_err(Error::ipc("creating the block subscriber"))?;
    let blocks_listener = shm::listener(&node::event_service(&node, names::BLOCKS)?)?;
    connect_to_block_producer(&node, &blocks_service, &blocks, system.startup_timeout())?;
    let poses_service = services::pose_sets_service(&node)?;
    let poses = node::publisher(
        &poses_service,
        options.config.windows.window_frames,
        system.backpressure_timeout(),
    )?;
    let poses_notifier = shm::notifier(&node::event_service(&node, names::POSE_SETS)?)?;
    // The pose sets' consumers (smooth, record) are awaited before the first reply, not here:
    // a run whose windows all fail before reaching this stage sends only the shutdown block,
    // and its consumers may have finished and left before this stage got this far.
    let mut consumers_connected = false;
    let mut solved = 0usize;
    let mut reassembly = Reassembly::default();
    loop {
        while let Some(sample) = blocks.receive().map_err(Error::ipc("receiving blocks"))? {
            let header = *sample.user_header();
            if header.kind == block_kind::SHUTDOWN {
                tracing::info!("{solved} factor blocks solved; shutting down");
                drop(sample);
                drop(blocks);
                shm::linger_until_unsubscribed(
                    &node,
                    &poses_service,
                    "pose sets",
                    system.backpressure_timeout(),
                );
                return Ok(());
            }
            let started = Instant::now();
            // One part: decoded straight from shared memory. Several: appended until whole.
            let decoded = if header.parts.count == 1 {
                decode(
                    &header,
                    sample.payload(),
                    options.config.windows.window_frames,
                )
            } else {
                match reassembly.push(header.parts, sample.payload(), MAX_BLOCK_WORDS) {
                    Ok(None) => continue,
                    Ok(Some(words)) => decode(&header, words, options.config.windows.window_frames),
                    Err(error) => Err(error),
                }
            };
            drop(sample);
            let (reply, adjusted) = answer(&header, decoded, started);
            tracing::debug!(
                window = reply.window,
                scale = reply.scale,
                iterations = reply.iterations,
                solve_s = reply.solve_time_s,
                "block solved"
            );
            if !consumers_connected {
                shm::wait_for_subscribers(
                    &node,
                    &poses_service,
                    services::POSE_SET_SUBSCRIBERS,
                    "pose sets",
                    system.startup_timeout(),
                )?;
                consumers_connected = true;
            }
            shm::publish_slice(&poses, &poses_notifier, reply, &adjusted)
                .context("publishing poses")?;
            if solved == 0 {
                tracing::info!(
                    window = reply.window,
                    scale = reply.scale,
                    "first factor block solved, {:.2} s after this stage started",
                    stage_started.elapsed().as_secs_f64()
                );
            }
            solved += 1;
        }
        if shm::termination_requested(&node) {
            bail!(Run, "interrupted after {solved} blocks");
        }
        blocks_listener
            .timed_wait(|_| {}, WAKE_INTERVAL)
            .map_err(Error::ipc("waiting for blocks"))?;
    }
}

/// The reply to a block: its adjusted poses and LM report, or a refusal (with no poses) if it
/// did not decode.
fn answer(
    header: &BlockHeader,
    decoded: Result<pssba_msg::BlockMessage, pssba_msg::MsgError>,
    started: Instant,
) -> (PoseSetHeader, Vec<PoseMsg>) {
    match decoded {
        Ok(message) => {
            let (adjusted, lm) = solve_block(
                &message.block,
                &message.poses,
                &message.fixed,
                &message.settings,
                Parallelism::Rayon,
            );
            let reply = PoseSetHeader {
                window: message.window,
                scale: message.scale,
                rejected: 0,
                cost_before: lm.cost_before,
                cost_after: lm.cost_after,
                iterations: lm.iterations as u64,
                residuals: lm.residuals as u64,
                unconstrained_frames: lm.unconstrained_frames as u64,
                solve_time_s: started.elapsed().as_secs_f64(),
                block_id: header.parts.message_id,
            };
            let adjusted: Vec<PoseMsg> = adjusted.iter().map(PoseMsg::from_pose).collect();
            (reply, adjusted)
        }
        Err(error) => {
            tracing::error!("refusing a factor block: {error}");
            let reply = PoseSetHeader {
                window: header.window,
                scale: header.scale,
                rejected: 1,
                block_id: header.parts.message_id,
                ..PoseSetHeader::default()
            };
            (reply, Vec::new())
        }
    }
}

/// Validates and decodes a whole block; a window larger than the pose-set service is refused.
fn decode(
    header: &BlockHeader,
    words: &[f64],
    max_window_frames: usize,
) -> Result<pssba_msg::BlockMessage, pssba_msg::MsgError> {
    let max_frames = max_window_frames as u64;
    if header.frame_count > max_frames {
        return Err(pssba_msg::MsgError::TooLarge {
            message: "factor block",
            field: "frame_count",
            value: header.frame_count,
            limit: max_frames,
        });
    }
    pssba_msg::decode_block(header, words)
}

/// Connects the block subscriber to the smooth stage's publisher as soon as it exists.
/// iceoryx2 0.10 drops, without an error, a sample sent to a subscriber whose side of the
/// connection is not yet set up (its first `receive` after the publisher appeared) once that
/// subscriber's buffer (one sample) is full: a factor block of several parts sent before
/// then lost all but its first part. Checks every 10 ms (start-up only); gives up quietly
/// after `timeout` or on a termination request (the main loop sees to both).
fn connect_to_block_producer(
    node: &iceoryx2::node::Node<iceoryx2::prelude::ipc::Service>,
    service: &pssba_msg::internal::services::BlocksService,
    blocks: &iceoryx2::port::subscriber::Subscriber<
        iceoryx2::prelude::ipc::Service,
        [f64],
        BlockHeader,
    >,
    timeout: std::time::Duration,
) -> crate::Result<()> {
    use iceoryx2::service::port_factory::PortFactory;
    let started = Instant::now();
    while service.dynamic_config().number_of_publishers() == 0 {
        // No smooth stage (yet): the loop below waits for blocks as before.
        if started.elapsed() > timeout || node.wait(std::time::Duration::from_millis(10)).is_err() {
            return Ok(());
        }
    }
    blocks
        .has_samples()
        .map_err(Error::ipc("connecting to the factor blocks"))?;
    Ok(())
}
