//! The record stage: subscribes to frames, adjusted pose sets and window results and writes
//! them to MCAP ([`crate::mcap_out`]). Waits on a WaitSet over the three services' events.
//! Ends when both the end of the frame stream and the end of the run have arrived, or on
//! SIGINT/SIGTERM; either way the MCAP file is finished (summary written).

use crate::SystemConfig;
use crate::intake::ProducerLost;
use crate::mcap_out::{self, McapRecorder};
use crate::shm;
use anyhow::{Context, bail};
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;
use pssba_msg::frames::ready_id;
use pssba_msg::services::{self, names};
use pssba_msg::types::result_kind;
use pssba_msg::{FrameConsumer, Reassembly};
use std::io::BufWriter;
use std::path::PathBuf;
use std::time::Duration;

/// Options of the record stage.
#[derive(Debug, Clone)]
pub struct RecordOptions {
    /// iceoryx2 prefix of this run.
    pub prefix: String,
    /// Output MCAP file.
    pub out: PathBuf,
    /// The process system's settings.
    pub system: SystemConfig,
    /// Frames come from a process outside the system (see `SmoothOptions::live`).
    pub live: bool,
}

/// Largest window result accepted (words), whatever its header claims.
const MAX_RESULT_WORDS: u64 = pssba_msg::block::MAX_ITEMS * 8;

/// Runs the stage.
pub fn run(options: &RecordOptions) -> anyhow::Result<()> {
    let node = services::create_node(&options.prefix, "record")?;
    let sub_err = |e| anyhow::anyhow!("creating a subscriber: {e:?}");
    let poses = services::pose_sets_service(&node)?
        .subscriber_builder()
        .create()
        .map_err(sub_err)?;
    let results = services::results_service(&node)?
        .subscriber_builder()
        .create()
        .map_err(sub_err)?;
    let listeners = [
        shm::listener(&services::event_service(&node, names::POSE_SETS)?)?,
        shm::listener(&services::event_service(&node, names::RESULTS)?)?,
    ];
    let frames = FrameConsumer::connect(&node, ready_id::RECORD, options.system.startup_timeout())?;
    if !options.live {
        // The ingest stage sends frames again for a restarted smooth stage: recorded once.
        frames.skip_repeats();
    }
    let waitset = WaitSetBuilder::new()
        .create::<ipc::Service>()
        .map_err(|e| anyhow::anyhow!("creating the WaitSet: {e:?}"))?;
    let _guards = listeners
        .iter()
        .chain([frames.listener()])
        .map(|l| waitset.attach_notification(l))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| anyhow::anyhow!("attaching listeners: {e:?}"))?;
    // Created last: from here on every way out finishes the file.
    let file = std::fs::File::create(&options.out)
        .with_context(|| format!("creating {}", options.out.display()))?;
    let mut recorder = McapRecorder::new(BufWriter::new(file))?;

    // Whatever ends the loop (the end of the run, a signal, or an error such as a producer
    // vanishing mid-stream), the MCAP file is finished with everything that arrived.
    let mut reassembly = Reassembly::default();
    let mut clean = CleanEnd {
        path: &options.out,
        len: 0,
    };
    let mut solves_seen = std::collections::HashSet::new();
    // `--frames N` (live): frames from N on are taken off the queue but not recorded.
    let limit = match options.system.live_max_frames {
        n if options.live && n > 0 => n,
        _ => u64::MAX,
    };
    let wait_for_producer = options.system.live_producer_lost == ProducerLost::Wait;
    let mut receive_until_end = || -> anyhow::Result<bool> {
        let mut frames_ended = false;
        let mut run_ended = false;
        let mut producer_lost = false;
        while !(frames_ended && run_ended) {
            let outcome = waitset
                .wait_and_process_once_with_timeout(
                    |_| CallbackProgression::Continue,
                    Duration::from_secs(1),
                )
                .map_err(|e| anyhow::anyhow!("waiting: {e:?}"))?;
            for listener in listeners.iter().chain([frames.listener()]) {
                listener
                    .try_wait(|_| {})
                    .map_err(|e| anyhow::anyhow!("collecting events: {e:?}"))?;
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
            record_frames(&frames, &mut recorder, limit, &mut clean)?;
            if options.live && !frames.ended() && frames.producer_gone(&node) {
                // Drain what it sent before it left; the stream ends there, or a new producer
                // is awaited (live_producer_lost = wait).
                record_frames(&frames, &mut recorder, limit, &mut clean)?;
                if !frames.ended() {
                    tracing::warn!("the live producer vanished without its end-of-stream marker");
                    frames.end_without_marker();
                    producer_lost = wait_for_producer;
                }
            }
            frames_ended = (frames.ended() && !producer_lost) || frames.received() >= limit;
            while let Some(sample) = poses.receive().map_err(|e| anyhow::anyhow!("{e:?}"))? {
                let header = sample.user_header();
                // A restarted adjust stage answers the block its predecessor may have
                // answered already: each block is recorded once.
                if solves_seen.insert(header.block_id) {
                    recorder.add_solve(header)?;
                }
            }
            while let Some(sample) = results.receive().map_err(|e| anyhow::anyhow!("{e:?}"))? {
                let header = *sample.user_header();
                if header.kind == result_kind::END_OF_RUN {
                    recorder.add_end_of_run(header.final_count, header.frames_dropped)?;
                    run_ended = true;
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
                    Ok(result) => recorder.add_window(&result)?,
                    Err(error) => tracing::error!("dropping an invalid window result: {error}"),
                }
            }
            clean.flush(&mut recorder)?;
            if matches!(
                outcome,
                WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt
            ) || shm::termination_requested(&node)
            {
                return Ok(true);
            }
        }
        Ok(false)
    };
    let received = receive_until_end();
    let clean_len = clean.len;
    let frames_recorded = recorder.frames();
    if let Err(finishing) = recorder.finish() {
        // A full disk fails the write that stopped the loop and the summary alike. The file
        // is cut back to its last whole record and ended there, so what was written before
        // stays readable; the error says both failures, the file and how far it got.
        let cause = match received {
            Err(error) => format!("{error:#}; then "),
            Ok(_) => String::new(),
        };
        let ended = match mcap_out::end_cut_file(&options.out, clean_len) {
            Ok(()) => format!(
                "it is ended after its first {clean_len} bytes (the last flush) and readable \
                 up to there"
            ),
            Err(error) => format!("it could not be ended either ({error:#})"),
        };
        bail!(
            "recording to {} failed with {frames_recorded} frames taken: {cause}finishing the file \
             failed too ({finishing:#}); {ended}",
            options.out.display()
        );
    }
    tracing::info!("wrote {} ({frames_recorded} frames)", options.out.display());
    let interrupted = received.with_context(|| {
        format!(
            "recording stopped; {} finished with the {frames_recorded} frames that had arrived",
            options.out.display()
        )
    })?;
    if interrupted {
        bail!(
            "interrupted; {} finished with what had arrived",
            options.out.display()
        );
    }
    Ok(())
}

/// Records every frame waiting on the frames service whose sequence is below `limit`.
fn record_frames<W: std::io::Write + std::io::Seek>(
    frames: &FrameConsumer,
    recorder: &mut McapRecorder<W>,
    limit: u64,
    clean: &mut CleanEnd<'_>,
) -> anyhow::Result<()> {
    frames.receive(|frame| -> anyhow::Result<()> {
        if frame.sequence >= limit {
            return Ok(());
        }
        let points: Vec<[f32; 3]> = frame.points.iter().map(|p| p.xyz_m).collect();
        recorder.add_frame(
            frame.stamp_s,
            &points,
            frame.world_from_lidar,
            frame.ground_truth,
        )?;
        clean.flush(recorder)
    })
}

/// Where the file last ended on a whole record ([`McapRecorder::flush`]): a later failed
/// write (a full disk) is cut back there ([`mcap_out::end_cut_file`]).
struct CleanEnd<'a> {
    path: &'a std::path::Path,
    len: u64,
}

impl CleanEnd<'_> {
    fn flush<W: std::io::Write + std::io::Seek>(
        &mut self,
        recorder: &mut McapRecorder<W>,
    ) -> anyhow::Result<()> {
        recorder.flush()?;
        self.len = std::fs::metadata(self.path).map_or(self.len, |m| m.len());
        Ok(())
    }
}
