//! The smooth stage: a thin adapter around the whole-flight driver
//! ([`pssba_core::FlightWindows`]: sliding windows, keyframes, loop closure). Frames come in
//! from shared memory; each scale's factor block (DESIGN steps 1-6, extracted here) goes to
//! the adjust stage, whose poses (steps 7-8) start the next scale; a revisit's alignment and
//! pose graph run here; each finished window is published: final poses, the earlier final
//! poses its loop closure moved, surfaces, smoothed cloud, per-scale reports, or why it failed.

use crate::Error;
use crate::error::{Context, bail};
use crate::resume::retained::Retained;
use crate::resume::smooth_state::{Resume, SmoothProgress};
use crate::stages::intake::{self, IntakeOptions, Overflow};
use crate::stages::outputs::Outputs;
use crate::stages::stream::Feed;
use crate::stages::table::StageArgs;
use crate::transport::shm::{self, WAKE_INTERVAL};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use nalgebra::Isometry3;
use pssba_core::geometry::Pose;
use pssba_core::lm::LmReport;
use pssba_core::sliding::FinalFrame;
use pssba_core::sliding::SolveError;
use pssba_core::{
    FlightStep, FlightWindows, Parallelism, ProgressiveRun, ScaleStep, SlidingWindows,
};
use pssba_msg::Stage;
use pssba_msg::internal::services::{self, names};
use pssba_msg::node;
use pssba_msg::{BlockHeader, FinalPose, PoseMsg, PoseSetHeader, ResultHeader, WindowResult};
use pssba_msg::{block_kind, result_kind};
use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

/// Options of the smooth stage.
#[derive(Debug, Clone)]
pub struct SmoothOptions {
    /// iceoryx2 prefix of this run.
    pub prefix: String,
    /// The run's configuration.
    pub config: crate::Config,
    /// Frames come from a process outside the system (`pssba run --input live`): its
    /// vanishing without the end-of-stream marker ends the stream instead of failing it.
    pub live: bool,
    /// Where the stage keeps its progress after each window ([`crate::resume::smooth_state`]), so that,
    /// restarted after a crash, it goes on after the last window it published.
    pub progress: Option<PathBuf>,
}

/// `pssba stage smooth`: the options from the stage's arguments ([`crate::stages::table`]).
pub fn main(args: StageArgs, config: crate::Config) -> crate::Result<()> {
    run(&SmoothOptions {
        prefix: args.prefix,
        config,
        live: args.live,
        progress: args.progress,
    })
}

struct Ports {
    node: Node<ipc::Service>,
    blocks_service: services::BlocksService,
    results_service: services::ResultsService,
    blocks: Publisher<ipc::Service, [f64], BlockHeader>,
    blocks_notifier: Notifier<ipc::Service>,
    poses: Subscriber<ipc::Service, [PoseMsg], PoseSetHeader>,
    poses_listener: Listener<ipc::Service>,
    results: Publisher<ipc::Service, [f64], ResultHeader>,
    results_notifier: Notifier<ipc::Service>,
}

fn open_ports(options: &SmoothOptions) -> crate::Result<Ports> {
    let system = &options.config.system;
    let node = node::create_node(&options.prefix, Stage::Smooth.name())?;
    let blocks_service = services::blocks_service(&node)?;
    let poses_service = services::pose_sets_service(&node)?;
    let results_service = services::results_service(&node)?;
    let ports = Ports {
        blocks: node::publisher(
            &blocks_service,
            system.sample_words,
            system.backpressure_timeout(),
        )?,
        blocks_notifier: shm::notifier(&node::event_service(&node, names::BLOCKS)?)?,
        poses: poses_service
            .subscriber_builder()
            .create()
            .map_err(Error::ipc("creating a subscriber"))?,
        poses_listener: shm::listener(&node::event_service(&node, names::POSE_SETS)?)?,
        results: node::publisher(
            &results_service,
            system.sample_words,
            system.backpressure_timeout(),
        )?,
        results_notifier: shm::notifier(&node::event_service(&node, names::RESULTS)?)?,
        node,
        blocks_service,
        results_service,
    };
    // adjust, and record for the results.
    shm::wait_for_subscribers(
        &ports.node,
        &ports.blocks_service,
        services::BLOCK_SUBSCRIBERS,
        "factor blocks",
        system.startup_timeout(),
    )?;
    shm::wait_for_subscribers(
        &ports.node,
        &ports.results_service,
        services::RESULT_SUBSCRIBERS,
        "results",
        system.startup_timeout(),
    )?;
    Ok(ports)
}

/// Runs the stage until the stream has ended and every frame is final.
pub fn run(options: &SmoothOptions) -> crate::Result<()> {
    let (progress, resume) = SmoothProgress::open(options.progress.as_deref())?;
    if let Some(resume) = &resume {
        tracing::warn!(
            "restarted (incarnation {}): going on after {} windows and the {} frames they \
             made final, {} of them anchors of the next window",
            progress.incarnation,
            resume.windows_done,
            resume.frames_final,
            resume.anchors.len()
        );
    }
    let intake = start_intake(options, resume.as_ref())?;
    let ports = open_ports(options)?;
    let mut state = State::new(options, &ports, progress, resume)?;
    let sample_words = options.config.system.sample_words;
    loop {
        state
            .feed
            .drain(&intake.messages, state.stream.windows_mut())?;
        while state.finish_next_window(&ports, options, &intake)? {}
        if state.stream.windows().is_done() {
            if state.feed.segment_ended {
                // A vanished producer's frames are all final: the next producer's frames start
                // new windows (a restarted odometry may start a new world frame).
                log_failures(state.stream.windows());
                state.feed.window_offset += state.stream.windows().windows_done() as u64;
                state.stream = FlightWindows::new(
                    options.config.windows.spec(),
                    options.config.flight.settings(),
                )?;
                state.feed.start_segment(state.stream.windows_mut())?;
                continue;
            }
            if state.feed.end.is_some() {
                break;
            }
        }
        if shm::termination_requested(&ports.node) {
            bail!(
                Run,
                "interrupted with {} frames received, {} final",
                state.stream.windows().len(),
                state.stream.windows().finalised()
            );
        }
        state
            .sinks
            .retained
            .serve(&ports.results, &ports.results_notifier, sample_words)?;
        state
            .feed
            .wait(&intake.messages, state.stream.windows_mut(), WAKE_INTERVAL)?;
    }
    intake.join();
    let Feed {
        latency,
        lag,
        largest_frame,
        ..
    } = &state.feed;
    latency.log_summary(*largest_frame, options.config.windows.window_frames);
    lag.log_summary();
    log_failures(state.stream.windows());
    state.sinks.outputs.end_stream()?;
    end_run(ports, options, state)
}

/// Starts the frame intake thread, at the first frame not yet final when resumed.
fn start_intake(
    options: &SmoothOptions,
    resume: Option<&Resume>,
) -> crate::Result<intake::IntakeHandle> {
    let system = &options.config.system;
    intake::start(IntakeOptions {
        prefix: options.prefix.clone(),
        live: options.live,
        // Replay is always lossless: the ingest stage waits instead of losing frames.
        overflow: if options.live {
            system.live_overflow
        } else {
            Overflow::Block
        },
        backlog: system.live_backlog_frames,
        producer_lost: system.live_producer_lost,
        max_frames: if options.live {
            system.live_max_frames
        } else {
            0
        },
        startup_timeout: system.startup_timeout(),
        resume_at: resume.map(Resume::first_frame),
    })
}

/// What the stage carries from window to window.
struct State {
    feed: Feed,
    stream: FlightWindows,
    /// The final poses of the last `overlap` final frames (the next window's anchors).
    anchors: VecDeque<Isometry3<f64>>,
    overlap: usize,
    message_id: u64,
    sinks: Sinks,
    progress: SmoothProgress,
}

impl State {
    fn new(
        options: &SmoothOptions,
        ports: &Ports,
        progress: SmoothProgress,
        resume: Option<Resume>,
    ) -> crate::Result<Self> {
        let mut feed = Feed::default();
        let overlap = options.config.windows.window_frames - options.config.windows.window_stride;
        let stream = match resume {
            Some(resume) => {
                feed.resume(resume.windows_done, resume.first_frame());
                FlightWindows::resume(
                    options.config.windows.spec(),
                    options.config.flight.settings(),
                    resume.anchors,
                )?
            }
            None => FlightWindows::new(
                options.config.windows.spec(),
                options.config.flight.settings(),
            )?,
        };
        Ok(Self {
            feed,
            stream,
            anchors: VecDeque::with_capacity(overlap + 1),
            overlap,
            message_id: progress.first_message_id(),
            sinks: Sinks {
                outputs: Outputs::create(&ports.node)?,
                retained: Retained::create(&ports.node)?,
            },
            progress,
        })
    }

    /// Solves the next window if its frames are in and publishes it; false if none is ready.
    fn finish_next_window(
        &mut self,
        ports: &Ports,
        options: &SmoothOptions,
        intake: &intake::IntakeHandle,
    ) -> crate::Result<bool> {
        let started = Instant::now();
        let window_offset = self.feed.window_offset;
        let message_id = &mut self.message_id;
        let solve = |window: usize, run: &ProgressiveRun, step: &ScaleStep| {
            let window = window_offset + window as u64;
            remote_solve(ports, options, window, run, step, message_id)
                .map_err(|e| SolveError::from(format!("{e:#}")))
        };
        let Some(step) = self
            .stream
            .run_next(&options.config.algorithm, Parallelism::Rayon, solve)
        else {
            return Ok(false);
        };
        let sequences: Vec<u64> = step
            .outcome
            .finals
            .iter()
            .map(|f| self.feed.sequence(f.sequence))
            .collect();
        let (lag_min_s, lag_max_s) = self
            .feed
            .lag
            .finalised(sequences.into_iter().map(|k| k as usize))
            .unwrap_or((0.0, 0.0));
        let dropped = intake.dropped.load(Ordering::Relaxed);
        // The next window's anchors, as final as they are now (a loop closure moves them).
        let windows = self.stream.windows();
        let finalised = windows.finalised();
        self.anchors = (finalised.saturating_sub(self.overlap)..finalised)
            .filter_map(|k| windows.final_pose(k))
            .collect();
        let sample_words = options.config.system.sample_words;
        publish_window(
            ports,
            options,
            step,
            &self.feed,
            dropped,
            &mut self.sinks,
            &mut self.message_id,
        )?;
        self.sinks
            .retained
            .serve(&ports.results, &ports.results_notifier, sample_words)?;
        self.progress.store(&Resume {
            windows_done: self.feed.window_offset + self.stream.windows().windows_done() as u64,
            frames_final: self.feed.frames_final(self.stream.windows()),
            anchors: self.anchors.iter().copied().collect(),
        })?;
        tracing::info!(
            "progress: frames in {}, windows done {}, {} frames final ({:.1} s for this \
             window; its frames final {lag_min_s:.1}-{lag_max_s:.1} s after they were sent)",
            self.stream.windows().len(),
            self.stream.windows().windows_done(),
            self.stream.windows().finalised(),
            started.elapsed().as_secs_f64()
        );
        Ok(true)
    }
}

/// After the last window: the end-of-run result to the recorder, the shutdown block to the
/// adjust stage, then serving the recorder until it has everything.
fn end_run(ports: Ports, options: &SmoothOptions, mut state: State) -> crate::Result<()> {
    let system = &options.config.system;
    let (feed, stream, message_id) = (&state.feed, &state.stream, state.message_id);
    let dropped = &feed.dropped;
    let end = ResultHeader {
        kind: result_kind::END_OF_RUN,
        window: feed.window_offset + stream.windows().windows_done() as u64,
        final_count: feed.frames_taken(),
        frames_dropped: dropped.len() as u64,
        ..ResultHeader::default()
    };
    shm::publish_parts(
        &ports.results,
        &ports.results_notifier,
        end,
        message_id,
        0,
        system.sample_words,
        std::iter::empty(),
    )?;
    state.sinks.retained.keep_end(end, message_id);
    let shutdown = BlockHeader {
        kind: block_kind::SHUTDOWN,
        ..BlockHeader::default()
    };
    let send_shutdown = || {
        shm::publish_parts(
            &ports.blocks,
            &ports.blocks_notifier,
            shutdown,
            message_id + 1,
            0,
            system.sample_words,
            std::iter::empty(),
        )
    };
    let told = shm::subscriber_ids(&ports.blocks_service);
    send_shutdown()?;
    tracing::info!(
        "{} frames final in {} windows; {} frames dropped",
        feed.frames_taken(),
        feed.window_offset + stream.windows().windows_done() as u64,
        dropped.len()
    );
    let Ports {
        node,
        poses,
        blocks_service,
        results_service,
        results,
        results_notifier,
        ..
    } = ports;
    // Consumers first: the adjust stage lingers until this stage stops reading its poses.
    drop(poses);
    serve_recorder_to_the_end(
        &options.prefix,
        &node,
        &mut state.sinks.retained,
        &results,
        &results_notifier,
        system.sample_words,
    )?;
    drop(results_service);
    // An adjust stage restarted after the shutdown block was sent is told again.
    shm::linger_telling_newcomers(
        &node,
        &blocks_service,
        told,
        "factor blocks",
        system.backpressure_timeout(),
        send_shutdown,
    )
}

/// Stays while a record stage exists, alive or crashed (its replacement may ask for the
/// windows it lost), answering its requests. Checks every 10 ms; a SIGTERM (the launcher
/// stopping the run) ends it.
fn serve_recorder_to_the_end(
    prefix: &str,
    node: &Node<ipc::Service>,
    retained: &mut Retained,
    results: &Publisher<ipc::Service, [f64], ResultHeader>,
    notifier: &Notifier<ipc::Service>,
    sample_words: usize,
) -> crate::Result<()> {
    let record_exists = || {
        node::node_names(prefix)
            .is_ok_and(|nodes| nodes.iter().any(|(name, _)| name == Stage::Record.name()))
    };
    loop {
        retained.serve(results, notifier, sample_words)?;
        if !record_exists() || node.wait(Duration::from_millis(10)).is_err() {
            if !retained.is_empty() {
                tracing::debug!("{} window results were never confirmed", retained.len());
            }
            return Ok(());
        }
    }
}

/// Where a finished window goes besides the recorder.
struct Sinks {
    /// Outside subscribers (docs/interface.md): each frame's final pose as it is final, each
    /// window's summary, map chunk and surfaces.
    outputs: Outputs,
    /// The results until the recorder has them on disk (a restarted one asks for them again).
    retained: Retained,
}

/// Logs the failed windows of a stream (indices within the stream).
fn log_failures(stream: &SlidingWindows) {
    for failure in stream.failures() {
        tracing::error!(
            "window {} failed; frames {}..{} kept their initial poses: {}",
            failure.index,
            failure.kept_initial.start,
            failure.kept_initial.end,
            failure.error
        );
    }
}

/// Publishes a finished window (failed windows too: their frames' poses and the reason) to the
/// recorder, then to outside subscribers.
fn publish_window(
    ports: &Ports,
    options: &SmoothOptions,
    step: FlightStep,
    feed: &Feed,
    frames_dropped: u64,
    sinks: &mut Sinks,
    message_id: &mut u64,
) -> crate::Result<()> {
    let FlightStep {
        outcome, revised, ..
    } = step;
    let final_pose = |f: &FinalFrame| FinalPose {
        sequence: feed.sequence(f.sequence),
        stamp_s: f.stamp_s,
        world_from_lidar: f.world_from_lidar,
    };
    let finals = outcome.finals.iter().map(final_pose).collect();
    let revised: Vec<FinalPose> = revised.iter().map(final_pose).collect();
    let message = match outcome.result {
        Ok(mut result) => WindowResult {
            window: feed.window_offset + outcome.index as u64,
            converged: result.converged,
            finals,
            revised,
            surfaces: {
                // Stream indices -> the producer's sequence numbers.
                for surface in &mut result.surfaces {
                    surface.frame = feed.sequence(surface.frame) as usize;
                }
                result.surfaces
            },
            map: result.smoothed_cloud,
            scales: result.scales,
            failure: None,
            frames_dropped,
        },
        Err(error) => WindowResult {
            window: feed.window_offset + outcome.index as u64,
            converged: false,
            finals,
            revised,
            surfaces: Vec::new(),
            map: Vec::new(),
            scales: Vec::new(),
            failure: Some(error.to_string()),
            frames_dropped,
        },
    };
    let (header, words) = pssba_msg::encode_result(&message);
    shm::publish_parts(
        &ports.results,
        &ports.results_notifier,
        header,
        *message_id,
        words.len(),
        options.config.system.sample_words,
        words.iter().copied(),
    )
    .context("publishing the window result")?;
    sinks
        .retained
        .keep(message.window, header, words, *message_id);
    *message_id += 1;
    sinks.outputs.publish(&message)?;
    Ok(())
}

/// Publishes the step's factor block and waits for the adjust stage's poses. If the adjust
/// stage crashes meanwhile, its replacement (a new subscriber of the blocks service, started by
/// the launcher after iceoryx2 cleaned the dead one's ports) is sent the block again under the
/// same id; answers are matched by block id, so a second answer to the same block, or an
/// answer to a block of a smooth stage that crashed, is ignored.
fn remote_solve(
    ports: &Ports,
    options: &SmoothOptions,
    window: u64,
    run: &ProgressiveRun,
    step: &ScaleStep,
    message_id: &mut u64,
) -> crate::Result<(Vec<Pose>, LmReport)> {
    let header = pssba_msg::block_header(
        window,
        step.index as u32,
        &step.block,
        run.poses(),
        &step.settings,
    );
    let total = pssba_msg::block_len(
        run.poses().len(),
        step.block.surfaces.len(),
        step.block.points.len(),
    );
    // Sent again (to a restarted adjust stage) under the same id.
    let block_id = *message_id;
    *message_id += 1;
    let send = || -> crate::Result<Vec<u128>> {
        let sent_to = shm::subscriber_ids(&ports.blocks_service);
        shm::publish_parts(
            &ports.blocks,
            &ports.blocks_notifier,
            header,
            block_id,
            total,
            options.config.system.sample_words,
            pssba_msg::block_words(&step.block, run.poses(), run.fixed()),
        )
        .context("publishing a factor block")?;
        tracing::debug!(window, scale = step.index, block_id, "factor block sent");
        Ok(sent_to)
    };
    let mut sent_to = send()?;
    let timeout = Duration::from_secs_f64(options.config.system.reply_timeout_s);
    let mut sent = Instant::now();
    loop {
        if let Some(reply) = take_reply(ports, block_id, run.poses().len())? {
            return Ok(reply);
        }
        let subscribers = shm::subscriber_ids(&ports.blocks_service);
        if subscribers.iter().any(|id| !sent_to.contains(id)) {
            tracing::warn!(
                window,
                scale = step.index,
                "a new adjust stage is attached (the last one crashed): sending the pending \
                 factor block again"
            );
            sent_to = send()?;
            sent = Instant::now();
        }
        if sent.elapsed() > timeout {
            bail!(
                Run,
                "no poses from the adjust stage within {:.0} s",
                timeout.as_secs_f64()
            );
        }
        if shm::termination_requested(&ports.node) {
            bail!(Run, "interrupted while waiting for the adjust stage");
        }
        ports
            .poses_listener
            .timed_wait(|_| {}, WAKE_INTERVAL)
            .map_err(Error::ipc("waiting for poses"))?;
    }
}

/// The adjust stage's answer to block `block_id`, if it has come (answers to earlier blocks
/// are skipped); a refusal or a pose set of the wrong size is an error.
fn take_reply(
    ports: &Ports,
    block_id: u64,
    frame_count: usize,
) -> crate::Result<Option<(Vec<Pose>, LmReport)>> {
    while let Some(sample) = ports
        .poses
        .receive()
        .map_err(Error::ipc("receiving poses"))?
    {
        let h = *sample.user_header();
        if h.block_id != block_id {
            tracing::warn!(
                "ignoring poses for window {} scale {} (block {}, an earlier one)",
                h.window,
                h.scale,
                h.block_id
            );
            continue;
        }
        if h.rejected != 0 {
            bail!(Run, "the adjust stage rejected the factor block");
        }
        if sample.payload().len() != frame_count {
            bail!(
                Data,
                "poses from the adjust stage: {} poses for a {}-frame window",
                sample.payload().len(),
                frame_count
            );
        }
        let poses = sample
            .payload()
            .iter()
            .enumerate()
            .map(|(k, p)| p.to_pose("pose set", k as u64))
            .collect::<Result<Vec<_>, _>>()?;
        let lm = LmReport {
            cost_before: h.cost_before,
            cost_after: h.cost_after,
            iterations: h.iterations as usize,
            residuals: h.residuals as usize,
            unconstrained_frames: h.unconstrained_frames as usize,
        };
        return Ok(Some((poses, lm)));
    }
    Ok(None)
}
