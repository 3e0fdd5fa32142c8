//! The record stage: subscribes to frames, adjusted pose sets and window results and writes
//! them to MCAP ([`pssba_recording`], through [`crate::stages::record_book`]). Waits on a WaitSet over
//! the three services' events. Ends when both the end of the frame stream and the end of the
//! run have arrived, or on SIGINT/SIGTERM; either way the MCAP file is finished (summary
//! written). Restarted after a crash, it ends the part its predecessor was writing at the last
//! flush and goes on in a new part: the ingest stage sends the frames after that point again,
//! the smooth stage the windows.

use crate::Config;
use crate::Error;
use crate::error::{Context, bail};
use crate::resume::record_journal::{Committed, RecordJournal, Restored};
use crate::stages::intake::ProducerLost;
use crate::stages::record_book::{Book, EndOfRun};
use crate::stages::table::StageArgs;
use crate::transport::shm;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::waitset::{WaitSet, WaitSetRunResult};
use pssba_client::FrameConsumer;
use pssba_client::frames::ready_id;
use pssba_msg::Stage;
use pssba_msg::internal::services::{self, names};
use pssba_msg::node;
use pssba_msg::result_kind;
use pssba_msg::{PoseMsg, PoseSetHeader, Reassembly, RecordedAck, ResultHeader};
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// Options of the record stage.
#[derive(Debug, Clone)]
pub struct RecordOptions {
    /// iceoryx2 prefix of this run.
    pub prefix: String,
    /// Output MCAP file.
    pub out: PathBuf,
    /// The run's configuration.
    pub config: Config,
    /// Frames come from a process outside the system (see `SmoothOptions::live`).
    pub live: bool,
    /// Where the stage notes how far the recording got ([`crate::resume::record_journal`]), so that,
    /// restarted after a crash, it goes on in a new part.
    pub progress: Option<PathBuf>,
}

/// `pssba stage record`: the options from the stage's arguments ([`crate::stages::table`]).
pub fn main(args: StageArgs, config: Config) -> crate::Result<()> {
    run(&RecordOptions {
        prefix: args.prefix,
        // Required by the stage's row: checked before this runs.
        out: args.out.unwrap_or_default(),
        config,
        live: args.live,
        progress: args.progress,
    })
}

/// Largest window result accepted (words), whatever its header claims.
const MAX_RESULT_WORDS: u64 = pssba_msg::codec::block::MAX_ITEMS * 8;

/// Runs the stage.
pub fn run(options: &RecordOptions) -> crate::Result<()> {
    let (journal, restored) = open_journal(options)?;
    let restart_at = restored.as_ref().map(|r| r.frames.len() as u64);
    let node = node::create_node(&options.prefix, Stage::Record.name())?;
    let (ports, acks) = Ports::open(&node, options)?;
    // Kept while the stage runs: a request whose publisher is gone before the ingest stage
    // has read it would be lost.
    let _rewind = match restart_at {
        Some(first) => {
            ports.frames.resync_at(first);
            Some(crate::stages::intake::request_rewind(&node, first)?)
        }
        None => {
            if !options.live {
                // The ingest stage sends frames again for a restarted smooth stage: recorded
                // once.
                ports.frames.skip_repeats();
            }
            None
        }
    };
    let waitset = WaitSetBuilder::new()
        .create::<ipc::Service>()
        .map_err(Error::ipc("creating the WaitSet"))?;
    let _guards = ports
        .listeners()
        .map(|l| waitset.attach_notification(l))
        .collect::<Result<Vec<_>, _>>()
        .map_err(Error::ipc("attaching listeners"))?;
    // Created last: from here on every way out finishes the file.
    let mut book = Book::open(&options.out, journal, restored, acks)?;
    if restart_at.is_some() {
        // Connected to the smooth stage's results publisher before asking for the windows
        // again: iceoryx2 0.10 drops what is sent to a subscriber whose side of the
        // connection is not set up yet once its buffer is full (see the adjust stage's
        // `connect_to_block_producer`).
        ports
            .results
            .has_samples()
            .map_err(Error::ipc("connecting to the window results"))?;
        book.ack(true)?;
        tracing::warn!(
            "restarted: recording goes on in {} from frame {} and window {}",
            book.path().display(),
            book.frames(),
            book.windows()
        );
    }
    // Whatever ends the loop (the end of the run, a signal, or an error such as a producer
    // vanishing mid-stream), the MCAP file is finished with everything that arrived.
    let received = receive_until_end(&ports, &waitset, &node, options, &mut book);
    let frames_recorded = book.frames();
    let out = book.path().to_path_buf();
    book.finish(received.as_ref().err())?;
    let interrupted = received.with_context(|| {
        format!(
            "recording stopped; {} finished with the {frames_recorded} frames that had arrived",
            out.display()
        )
    })?;
    if interrupted {
        bail!(
            Run,
            "interrupted; {} finished with what had arrived",
            out.display()
        );
    }
    Ok(())
}

/// The journal of a restartable recording and what an earlier process of the stage left in it.
fn open_journal(
    options: &RecordOptions,
) -> crate::Result<(Option<RecordJournal>, Option<Restored>)> {
    let Some(path) = &options.progress else {
        return Ok((None, None));
    };
    let (mut journal, restored) = RecordJournal::open(path)?;
    if restored.is_none() {
        // From here on a restart is told apart from a first start.
        journal.commit(Committed {
            part: 1,
            ..Committed::default()
        })?;
    }
    Ok((Some(journal), restored))
}

/// What the stage reads: pose sets, window results and frames, with their listeners.
struct Ports {
    poses: Subscriber<ipc::Service, [PoseMsg], PoseSetHeader>,
    results: Subscriber<ipc::Service, [f64], ResultHeader>,
    listeners: [Listener<ipc::Service>; 2],
    frames: FrameConsumer,
}

/// The publisher of the confirmations of what is on disk (the [`Book`] owns it).
type Acks = Publisher<ipc::Service, RecordedAck, ()>;

impl Ports {
    fn open(node: &Node<ipc::Service>, options: &RecordOptions) -> crate::Result<(Self, Acks)> {
        let poses = services::pose_sets_service(node)?
            .subscriber_builder()
            .create()
            .map_err(Error::ipc("creating a subscriber"))?;
        let results = services::results_service(node)?
            .subscriber_builder()
            .create()
            .map_err(Error::ipc("creating a subscriber"))?;
        let acks = services::recorded_service(node)?
            .publisher_builder()
            .create()
            .map_err(Error::ipc("creating the recorded-windows publisher"))?;
        let listeners = [
            shm::listener(&node::event_service(node, names::POSE_SETS)?)?,
            shm::listener(&node::event_service(node, names::RESULTS)?)?,
        ];
        let frames = FrameConsumer::connect(
            node,
            ready_id::RECORD,
            options.config.system.startup_timeout(),
        )?;
        let ports = Self {
            poses,
            results,
            listeners,
            frames,
        };
        Ok((ports, acks))
    }

    /// Every listener the WaitSet wakes on.
    fn listeners(&self) -> impl Iterator<Item = &Listener<ipc::Service>> {
        self.listeners.iter().chain([self.frames.listener()])
    }
}

/// Records what arrives until both the frame stream and the run have ended; true if a signal
/// ended it first.
fn receive_until_end(
    ports: &Ports,
    waitset: &WaitSet<ipc::Service>,
    node: &Node<ipc::Service>,
    options: &RecordOptions,
    book: &mut Book,
) -> crate::Result<bool> {
    let frames = &ports.frames;
    let mut reassembly = Reassembly::default();
    // `--frames N` (live): frames from N on are taken off the queue but not recorded.
    let limit = match options.config.system.live_max_frames {
        n if options.live && n > 0 => n,
        _ => u64::MAX,
    };
    let wait_for_producer = options.config.system.live_producer_lost == ProducerLost::Wait;
    let mut frames_ended = false;
    let mut producer_lost = false;
    // Since when the end of the run has come but a window or frame before it has not.
    let mut stalled_since: Option<Instant> = None;
    while !(frames_ended && book.run_ended()) {
        let outcome = waitset
            .wait_and_process_once_with_timeout(
                |_| CallbackProgression::Continue,
                Duration::from_secs(1),
            )
            .map_err(Error::ipc("waiting"))?;
        for listener in ports.listeners() {
            listener
                .try_wait(|_| {})
                .map_err(Error::ipc("collecting events"))?;
        }
        if !options.live && frames.follow_resumed_producer()? {
            tracing::info!(
                "the restarted ingest stage resumes the stream after {} frames",
                frames.received()
            );
        }
        if producer_lost && frames.rejoin()? {
            tracing::info!("a new live producer is attached");
            producer_lost = false;
        }
        record_frames(frames, book, limit)?;
        if options.live && !frames.ended() && frames.producer_gone(node) {
            // Drain what it sent before it left; the stream ends there, or a new producer
            // is awaited (live_producer_lost = wait).
            record_frames(frames, book, limit)?;
            if !frames.ended() {
                tracing::warn!("the live producer vanished without its end-of-stream marker");
                frames.end_without_marker();
                producer_lost = wait_for_producer;
            }
        }
        frames_ended = (frames.ended() && !producer_lost) || frames.received() >= limit;
        record_results(&ports.results, &mut reassembly, book)?;
        // After the results: every pose set was sent before the result it went into, so
        // once the end of the run is read, so is the last LM report.
        while let Some(sample) = ports
            .poses
            .receive()
            .map_err(|e| Error::Ipc(format!("{e:?}")))?
        {
            // A restarted adjust stage answers the block its predecessor may have
            // answered already: each block is recorded once.
            book.solve(sample.user_header())?;
        }
        match book.waiting_for() {
            // A restarted recorder's lost windows and frames come again soon after.
            Some(what) if frames_ended => {
                let since = *stalled_since.get_or_insert_with(Instant::now);
                if since.elapsed() > options.config.system.startup_timeout() {
                    bail!(
                        Run,
                        "the run ended, but {what} (waited {:.0} s)",
                        since.elapsed().as_secs_f64()
                    );
                }
            }
            _ => stalled_since = None,
        }
        book.flush()?;
        if matches!(
            outcome,
            WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt
        ) || shm::termination_requested(node)
        {
            return Ok(true);
        }
    }
    Ok(false)
}

/// Records every window result waiting (and the end of the run); an invalid one is logged
/// and dropped.
fn record_results(
    results: &Subscriber<ipc::Service, [f64], ResultHeader>,
    reassembly: &mut Reassembly,
    book: &mut Book,
) -> crate::Result<()> {
    while let Some(sample) = results
        .receive()
        .map_err(|e| Error::Ipc(format!("{e:?}")))?
    {
        let header = *sample.user_header();
        if header.kind == result_kind::END_OF_RUN {
            book.end_of_run(EndOfRun {
                windows: header.window,
                frames_taken: header.final_count,
                frames_dropped: header.frames_dropped,
            })?;
            continue;
        }
        // One part: decoded straight from shared memory. Several: appended until whole.
        let decoded = if header.parts.count == 1 {
            pssba_msg::decode_result(&header, sample.payload())
        } else {
            match reassembly.push(header.parts, sample.payload(), MAX_RESULT_WORDS) {
                Ok(None) => continue,
                Ok(Some(words)) => pssba_msg::decode_result(&header, words),
                Err(error) => Err(error),
            }
        };
        match decoded {
            Ok(result) => book.window(result)?,
            Err(error) => tracing::error!("dropping an invalid window result: {error}"),
        }
    }
    Ok(())
}

/// Records every frame waiting on the frames service whose sequence is below `limit`.
fn record_frames(frames: &FrameConsumer, book: &mut Book, limit: u64) -> crate::Result<()> {
    frames.receive(|frame| -> crate::Result<()> {
        if frame.sequence >= limit {
            return Ok(());
        }
        let points: Vec<[f32; 3]> = frame.points.iter().map(|p| p.xyz_m).collect();
        let times_s = frame.point_times_s();
        book.frame(
            frame.stamp_s,
            &points,
            times_s.as_deref(),
            frame.world_from_lidar,
            frame.ground_truth,
        )?;
        book.flush()
    })
}
