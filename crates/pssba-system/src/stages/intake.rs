//! The smooth stage's frame intake: a thread of its own drains the frames service as frames
//! arrive, also while a window is being solved, and hands each frame to the stage's main loop
//! through a bounded backlog. What happens when the backlog is full is the overflow policy
//! (`[system] live_overflow`, docs/interface.md):
//! - `block`: the intake stops draining, the producer's queue fills and its `send` waits:
//!   lossless, for replay (the ingest stage always runs this way);
//! - `drop`: the new frame is dropped and counted, so a live sensor is never stalled.
//!
//! The thread owns its own iceoryx2 node: iceoryx2 ports belong to the thread that made them.

use crate::Error;
use crate::error::bail;
use crate::transport::latency::now_unix_ns;
use crossbeam_channel::{Receiver, Sender, TrySendError, bounded};
use nalgebra::Isometry3;
use pssba_client::frames::ready_id;
use pssba_client::{FrameConsumer, ReceivedFrame};
use pssba_msg::PointXyz;
use pssba_msg::internal::services;
use pssba_msg::node;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// The intake thread's iceoryx2 node name (beside the smooth stage's own node); ingest
/// lingers while it exists.
pub const INTAKE_NODE: &str = "smooth-intake";

pub use pssba_config::{Overflow, ProducerLost};

/// One frame copied out of shared memory.
#[derive(Debug)]
pub struct IncomingFrame {
    /// The producer's sequence number.
    pub sequence: u64,
    /// Sensor stamp (s).
    pub stamp_s: f64,
    /// Initial (odometry) pose.
    pub world_from_lidar: Isometry3<f64>,
    /// Points in the lidar frame (m).
    pub points: Vec<PointXyz>,
    /// Each point's time after the stamp (s), when the producer sent them (layout 2).
    pub point_times_s: Option<Vec<f32>>,
    /// When the producer sent it and when the intake received it (ns since the Unix epoch).
    pub sent_unix_ns: u64,
    /// See `sent_unix_ns`.
    pub received_unix_ns: u64,
}

/// How the stream ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StreamEnd {
    /// The producer's end-of-stream marker.
    Marker,
    /// A live producer vanished without the marker.
    ProducerVanished,
    /// `--frames N` frames were taken.
    FrameLimit,
}

/// Messages from the intake thread.
#[derive(Debug)]
pub enum Intake {
    /// The next frame taken.
    Frame(IncomingFrame),
    /// The stream is over: `received` frames came, `dropped` of them were dropped.
    End {
        /// Why.
        how: StreamEnd,
        /// Frames that arrived.
        received: u64,
        /// Sequence numbers of the frames dropped (policy `drop`).
        dropped: Vec<u64>,
    },
    /// The producer vanished after `received` frames in all; a new one is awaited
    /// ([`ProducerLost::Wait`]). Its frames, which follow, start new windows.
    ProducerLost {
        /// Frames that arrived so far, from every producer.
        received: u64,
    },
    /// The intake failed (its error, with context).
    Failed(String),
}

/// Settings of the intake.
#[derive(Debug, Clone)]
pub struct IntakeOptions {
    /// iceoryx2 prefix of the run.
    pub prefix: String,
    /// The producer is outside the system: its vanishing ends the stream instead of failing it.
    pub live: bool,
    /// What to do when `backlog` frames wait.
    pub overflow: Overflow,
    /// Frames that may wait for the main loop.
    pub backlog: usize,
    /// What a vanished live producer means.
    pub producer_lost: ProducerLost,
    /// Stop after this many frames (0: no limit).
    pub max_frames: u64,
    /// How long to wait for a producer at start-up.
    pub startup_timeout: Duration,
    /// A restarted smooth stage: the stream goes on at this sequence number (the first frame
    /// that was not final), which the ingest stage is asked to send again.
    pub resume_at: Option<u64>,
}

/// The running intake.
#[derive(Debug)]
pub struct IntakeHandle {
    /// Frames, then the end (or a failure).
    pub messages: Receiver<Intake>,
    /// Frames dropped so far.
    pub dropped: Arc<AtomicU64>,
    thread: Option<JoinHandle<()>>,
}

impl IntakeHandle {
    /// Waits for the thread to finish (after the end, a failure or a signal).
    pub fn join(mut self) {
        if let Some(thread) = self.thread.take()
            && thread.join().is_err()
        {
            tracing::error!("the frame intake thread panicked");
        }
    }
}

/// Starts the intake thread.
pub fn start(options: IntakeOptions) -> crate::Result<IntakeHandle> {
    let (tx, rx) = bounded(options.backlog.max(1));
    let dropped = Arc::new(AtomicU64::new(0));
    let dropped_count = Arc::clone(&dropped);
    let thread = std::thread::Builder::new()
        .name("frame-intake".into())
        .spawn(move || {
            if let Err(error) = run(&options, &tx, &dropped_count) {
                // The main loop may be gone already (it stopped on a signal): nothing to tell.
                let _ = tx.send(Intake::Failed(format!("{error:#}")));
            }
        })
        .map_err(|e| crate::Error::from(e).context("starting the frame intake thread"))?;
    Ok(IntakeHandle {
        messages: rx,
        dropped,
        thread: Some(thread),
    })
}

struct Counts {
    received: u64,
    dropped: Vec<u64>,
}

fn run(
    options: &IntakeOptions,
    tx: &Sender<Intake>,
    dropped_count: &AtomicU64,
) -> crate::Result<()> {
    let node = node::create_node(&options.prefix, INTAKE_NODE)?;
    let frames = FrameConsumer::connect(&node, ready_id::SMOOTH, options.startup_timeout)?;
    // Kept while the intake runs: a sample of a publisher that is gone before the ingest
    // stage has connected to it would be lost.
    let _rewind = match options.resume_at {
        Some(first) => {
            frames.resync_at(first);
            Some(request_rewind(&node, first)?)
        }
        None => {
            if !options.live {
                // The ingest stage sends frames again for a restarted record stage.
                frames.skip_repeats();
            }
            None
        }
    };
    let mut counts = Counts {
        received: 0,
        dropped: Vec::new(),
    };
    let limit = (options.max_frames > 0).then_some(options.max_frames);
    let end = |how, counts: Counts| {
        // A closed channel means the main loop has stopped: nothing left to tell it.
        let _ = tx.send(Intake::End {
            how,
            received: counts.received,
            dropped: counts.dropped,
        });
        Ok(())
    };
    // When the system's ingest stage crashed: since when no producer has been connected.
    let mut ingest_lost_at: Option<Instant> = None;
    loop {
        if !options.live && frames.follow_resumed_producer()? {
            tracing::info!(
                "the restarted ingest stage resumes the stream after {} frames",
                counts.received
            );
            ingest_lost_at = None;
        }
        let mut main_gone = false;
        let mut limit_reached = false;
        frames.receive(|frame| -> crate::Result<()> {
            if main_gone || limit_reached {
                return Ok(());
            }
            counts.received += 1;
            main_gone = !hand_over(options.overflow, tx, copy_out(&frame), &mut counts.dropped);
            dropped_count.store(counts.dropped.len() as u64, Ordering::Relaxed);
            limit_reached = limit.is_some_and(|n| counts.received >= n);
            Ok(())
        })?;
        if main_gone {
            return Ok(());
        }
        if limit_reached {
            tracing::info!("took the {} frames asked for (--frames)", counts.received);
            return end(StreamEnd::FrameLimit, counts);
        }
        if frames.ended() {
            return end(StreamEnd::Marker, counts);
        }
        if !options.live && !frames.producer_present() {
            // The ingest stage crashed and its resources were cleaned: the launcher restarts
            // it (it resumes after its last frame) or stops the run.
            let since = *ingest_lost_at.get_or_insert_with(Instant::now);
            if since.elapsed() > options.startup_timeout {
                bail!(
                    Run,
                    "the frame producer left before the end of the stream ({} frames received) and no new one came within {:.0} s",
                    counts.received,
                    options.startup_timeout.as_secs_f64()
                );
            }
        } else if options.live && frames.producer_gone(&node) {
            match live_producer_gone(options, tx, dropped_count, &frames, &node, &mut counts)? {
                AfterLoss::End(how) => return end(how, counts),
                AfterLoss::Stop => return Ok(()),
                AfterLoss::Rejoined => continue,
            }
        }
        if node.wait(Duration::ZERO).is_err() {
            // SIGINT/SIGTERM: the main loop sees it too and stops.
            return Ok(());
        }
        frames.wait(Duration::from_millis(100))?;
    }
}

/// What the intake does after the live producer vanished.
enum AfterLoss {
    /// The stream ends so.
    End(StreamEnd),
    /// The main loop is gone or a signal came: nothing more to do.
    Stop,
    /// A new producer is attached: its frames follow.
    Rejoined,
}

/// The live producer vanished: takes what it sent before it left, then ends the stream or
/// (live_producer_lost = wait) waits for a new producer.
fn live_producer_gone(
    options: &IntakeOptions,
    tx: &Sender<Intake>,
    dropped_count: &AtomicU64,
    frames: &FrameConsumer,
    node: &iceoryx2::node::Node<iceoryx2::prelude::ipc::Service>,
    counts: &mut Counts,
) -> crate::Result<AfterLoss> {
    frames.receive(|frame| -> crate::Result<()> {
        counts.received += 1;
        hand_over(options.overflow, tx, copy_out(&frame), &mut counts.dropped);
        dropped_count.store(counts.dropped.len() as u64, Ordering::Relaxed);
        Ok(())
    })?;
    if frames.ended() {
        return Ok(AfterLoss::End(StreamEnd::Marker));
    }
    frames.end_without_marker();
    if options.producer_lost == ProducerLost::Finish {
        tracing::warn!(
            "the live producer vanished without its end-of-stream marker after {} \
             frames: finishing the frames received",
            counts.received
        );
        return Ok(AfterLoss::End(StreamEnd::ProducerVanished));
    }
    tracing::warn!(
        "the live producer vanished without its end-of-stream marker after {} frames: \
         finishing them and waiting for a new producer (live_producer_lost = wait)",
        counts.received
    );
    if tx
        .send(Intake::ProducerLost {
            received: counts.received,
        })
        .is_err()
    {
        return Ok(AfterLoss::Stop);
    }
    loop {
        if node.wait(Duration::from_millis(100)).is_err() {
            return Ok(AfterLoss::Stop);
        }
        if frames.rejoin()? {
            tracing::info!(
                "a new producer is attached; its frames follow as {} onwards",
                counts.received
            );
            return Ok(AfterLoss::Rejoined);
        }
    }
}

/// Asks the ingest stage to send the frames from `first` on again (after this consumer is
/// attached, so none of them is missed). Used by a restarted smooth or record stage.
pub(crate) fn request_rewind(
    node: &iceoryx2::node::Node<iceoryx2::prelude::ipc::Service>,
    first: u64,
) -> crate::Result<iceoryx2::port::publisher::Publisher<iceoryx2::prelude::ipc::Service, u64, ()>> {
    let publisher = services::rewind_service(node)?
        .publisher_builder()
        .create()
        .map_err(Error::ipc("creating the rewind publisher"))?;
    publisher
        .send_copy(first)
        .map_err(Error::ipc("asking the ingest stage to rewind"))?;
    tracing::info!("restarted: asked the ingest stage for the frames from {first} on again");
    Ok(publisher)
}

/// Copies a frame out of shared memory (the sample goes back to the producer at once).
fn copy_out(frame: &ReceivedFrame<'_>) -> IncomingFrame {
    IncomingFrame {
        sequence: frame.sequence,
        stamp_s: frame.stamp_s,
        world_from_lidar: frame.world_from_lidar,
        points: frame.points.to_vec(),
        point_times_s: frame.point_times_s(),
        sent_unix_ns: frame.sent_unix_ns,
        received_unix_ns: now_unix_ns(),
    }
}

/// Passes a frame to the main loop under the overflow policy; false if the main loop is gone.
fn hand_over(
    overflow: Overflow,
    tx: &Sender<Intake>,
    frame: IncomingFrame,
    dropped: &mut Vec<u64>,
) -> bool {
    let sequence = frame.sequence;
    match overflow {
        Overflow::Block => tx.send(Intake::Frame(frame)).is_ok(),
        Overflow::Drop => match tx.try_send(Intake::Frame(frame)) {
            Ok(()) => true,
            Err(TrySendError::Full(_)) => {
                dropped.push(sequence);
                if dropped.len() == 1 || dropped.len().is_multiple_of(100) {
                    tracing::warn!(
                        "the backlog is full (live_overflow = drop): dropped frame {sequence}, \
                         {} dropped so far",
                        dropped.len()
                    );
                }
                true
            }
            Err(TrySendError::Disconnected(_)) => false,
        },
    }
}
