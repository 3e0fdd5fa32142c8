//! The ingest stage: takes frames from an input ([`pssba_source::FrameSource`]) and publishes each into a loaned
//! shared-memory sample, as fast as the consumers take them or at a fixed sensor rate. Ends
//! with an end-of-stream marker. The frames service is sized from the source's largest frame
//! when the source knows it up front (replay), else from `system.live_max_frame_points`.

use crate::Config;
use crate::Error;
use crate::error::{Context, bail};
use crate::resume::progress::ProgressFile;
use crate::stages::intake::INTAKE_NODE;
use crate::transport::shm;
#[cfg(doc)]
use pssba_client::FrameConsumer;
use pssba_client::FrameProducer;
use pssba_client::frames::ready_id;
use pssba_msg::internal::services;
use pssba_msg::node;
use pssba_msg::{PointXyz, Stage};
use pssba_source::{FrameSource, Frames, InputSpec};
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// Options of the ingest stage.
#[derive(Debug, Clone)]
pub struct IngestOptions {
    /// iceoryx2 prefix of this run.
    pub prefix: String,
    /// Frame source.
    pub source: InputSpec,
    /// Publish at this rate (Hz) instead of as fast as possible.
    pub rate_hz: Option<f64>,
    /// The run's configuration.
    pub config: Config,
    /// Where the count of frames sent is kept after every send, so a restarted ingest stage
    /// resumes after the last frame its predecessor published ([`ProgressFile`]). If the
    /// crash came between a send and its count, that frame is sent again and the consumers
    /// skip it by its sequence number ([`FrameConsumer::follow_resumed_producer`]). A second
    /// word, 1, marks the end-of-stream marker as sent.
    pub progress: Option<PathBuf>,
}

/// Frames read ahead of the one being sent.
const PREFETCH_FRAMES: usize = 4;

/// `pssba stage ingest`: the options from the stage's arguments ([`crate::stages::table`]).
pub fn main(args: crate::stages::table::StageArgs, config: Config) -> crate::Result<()> {
    let source = args.source.unwrap_or_default();
    let crate::source::SourceSpec::Input(source) = source.parse()? else {
        bail!(
            Usage,
            "--source {source}: live frames come from outside producers, not ingest"
        );
    };
    run(&IngestOptions {
        prefix: args.prefix,
        source,
        rate_hz: args.rate_hz,
        config,
        progress: args.progress,
    })
}

/// Runs the stage until every frame is published and the consumers are done with them.
pub fn run(options: &IngestOptions) -> crate::Result<()> {
    // The progress file holds [frames sent] while frames are sent, [frames sent, 1] once the
    // end-of-stream marker is out.
    let (progress, resume_at, stream_ended) = match &options.progress {
        Some(path) => {
            let (progress, words) = ProgressFile::open(path, Stage::Ingest.name())?;
            let words = words.unwrap_or_default();
            let sent = words.first().copied().unwrap_or(0);
            (Some(progress), sent, words.get(1) == Some(&1))
        }
        None => (None, 0, false),
    };
    // Open before anything waits: a dataset that cannot be opened fails fast.
    let source = options.source.open()?;
    if let Some(total) = source.len()
        && resume_at > total as u64
    {
        bail!(
            Data,
            "the ingest progress file says {resume_at} frames were sent, of {total}"
        );
    }
    let capacity = source
        .max_points()
        .unwrap_or(options.config.system.live_max_frame_points)
        .max(1);
    tracing::info!(
        "{}: {} frames, frames service sized for {capacity} points per frame ({:.1} MiB a slot)",
        source.describe(),
        source
            .len()
            .map_or("an unknown number of".into(), |n| n.to_string()),
        capacity as f64 * std::mem::size_of::<PointXyz>() as f64 / (1 << 20) as f64
    );
    let node = node::create_node(&options.prefix, Stage::Ingest.name())?;
    let rewinds = services::rewind_service(&node)?
        .subscriber_builder()
        .create()
        .map_err(Error::ipc("creating the rewind subscriber"))?;
    let mut producer = FrameProducer::create(
        &node,
        capacity,
        options.config.system.backpressure_timeout(),
    )?;
    producer.start_at(resume_at);
    let mut pass = Pass {
        options,
        node: &node,
        producer: &mut producer,
        progress: progress.as_ref(),
        rewinds: &rewinds,
    };
    let mut rewind_to = if stream_ended {
        // Killed after the end of the stream: the consumers have every frame and will not
        // report ready again. The marker goes out again in case the crash came before it did
        // (a consumer that has it skips the repeat); then stay only to serve rewinds.
        tracing::warn!(
            "restarted after all {resume_at} frames and the end-of-stream marker were sent: \
             sending the marker again, then staying only to serve rewinds"
        );
        pass.producer
            .end_stream()
            .context("publishing end of stream again")?;
        pass.linger()?
    } else {
        pass.producer.wait_for_consumers(
            &node,
            &ready_id::SYSTEM,
            options.config.system.startup_timeout(),
        )?;
        if resume_at > 0 {
            tracing::warn!("restarted: resuming after the {resume_at} frames already published");
        }
        pass.send_then_linger(source.as_ref(), resume_at)?
    };
    while let Some(first) = rewind_to {
        tracing::warn!("a restarted stage asks for the frames from {first} on again");
        pass.producer.start_at(first);
        if let Some(progress) = pass.progress {
            progress.store(&[first])?;
        }
        rewind_to = pass.send_then_linger(source.as_ref(), first)?;
    }
    Ok(())
}

/// Rewind requests of the run (a restarted smooth or record stage).
type Rewinds = iceoryx2::port::subscriber::Subscriber<iceoryx2::prelude::ipc::Service, u64, ()>;

/// One pass over the source: from the start, a restart's resume point, or a rewind.
struct Pass<'a> {
    options: &'a IngestOptions,
    node: &'a iceoryx2::node::Node<iceoryx2::prelude::ipc::Service>,
    producer: &'a mut FrameProducer,
    progress: Option<&'a ProgressFile>,
    rewinds: &'a Rewinds,
}

impl Pass<'_> {
    /// The earliest frame a restarted smooth stage asked for, if one did.
    fn rewind_requested(&self) -> crate::Result<Option<u64>> {
        let mut first: Option<u64> = None;
        while let Some(sample) = self
            .rewinds
            .receive()
            .map_err(Error::ipc("receiving rewind requests"))?
        {
            first = Some(first.map_or(*sample, |f| f.min(*sample)));
        }
        Ok(first)
    }

    /// Sends the source's frames; returns where to rewind to if a restarted smooth stage asked.
    fn send_all(&mut self, count: Option<usize>, to_send: Frames) -> crate::Result<Option<u64>> {
        let of_count = count.map_or(String::new(), |n| format!("/{n}"));
        let first = self.producer.sent() as usize;
        let started = Instant::now();
        let period = self
            .options
            .rate_hz
            .map(|hz| Duration::from_secs_f64(1.0 / hz));
        // Frames are read a few ahead on another thread, so reading a file overlaps sending
        // the previous frame (and a replay at a fixed rate is not delayed by the disk).
        let (prefetched, frames) = crossbeam_channel::bounded(PREFETCH_FRAMES);
        let reader = std::thread::spawn(move || {
            for frame in to_send {
                if prefetched.send(frame).is_err() {
                    break;
                }
            }
        });
        let mut rewind = None;
        for (k, frame) in (first..).zip(frames.iter()) {
            if shm::termination_requested(self.node) {
                bail!(Run, "interrupted after {k}{of_count} frames");
            }
            rewind = self.rewind_requested()?;
            if rewind.is_some() {
                break;
            }
            let frame = frame.with_context(|| format!("frame {k}"))?;
            let points = &frame.points;
            self.producer
                .send(
                    frame.stamp_s,
                    &frame.world_from_lidar,
                    frame.ground_truth.as_ref(),
                    points.len(),
                    |i| PointXyz {
                        xyz_m: [points[i].x as f32, points[i].y as f32, points[i].z as f32],
                    },
                    frame.point_times_s.as_deref(),
                )
                .with_context(|| format!("publishing frame {k}"))?;
            let sent = k + 1;
            tracing::debug!(sequence = k, "frame sent");
            if let Some(progress) = self.progress {
                progress.store(&[sent as u64])?;
            }
            if sent.is_multiple_of(20) || Some(sent) == count {
                tracing::info!("published {sent}{of_count} frames");
            }
            if let Some(period) = period {
                let due = period * ((k - first) as u32 + 1);
                if let Some(wait) = due.checked_sub(started.elapsed()) {
                    std::thread::sleep(wait);
                }
            }
        }
        let sent = self.producer.sent();
        drop(frames);
        if reader.join().is_err() {
            bail!(Run, "the frame reader thread panicked after {sent} frames");
        }
        if rewind.is_none() {
            tracing::info!(
                "all {sent} frames published in {:.2} s",
                started.elapsed().as_secs_f64()
            );
        }
        Ok(rewind)
    }

    /// Sends the source's frames and the end-of-stream marker, then lingers; returns where to
    /// rewind to if a restarted stage asked.
    fn send_then_linger(
        &mut self,
        source: &dyn FrameSource,
        first: u64,
    ) -> crate::Result<Option<u64>> {
        let frames = source.frames_from(first as usize)?;
        if let Some(first) = self.send_all(source.len(), frames)? {
            return Ok(Some(first));
        }
        // Marked before it is sent: a restart after this point sends the marker again.
        if let Some(progress) = self.progress {
            progress.store(&[self.producer.sent(), 1])?;
        }
        self.producer
            .end_stream()
            .context("publishing end of stream")?;
        tracing::info!("end-of-stream marker sent; staying while a consumer may need frames");
        self.linger()
    }

    /// Stays while a consumer is attached (the samples in flight live in this process's shared
    /// memory) or a smooth or record stage exists, alive or crashed (its replacement may ask
    /// for frames again: the returned rewind point). Checks every 10 ms (shutdown only).
    fn linger(&self) -> crate::Result<Option<u64>> {
        let restartable = [Stage::Smooth.name(), INTAKE_NODE, Stage::Record.name()];
        let restartable_consumer_exists = || {
            node::node_names(&self.options.prefix).is_ok_and(|nodes| {
                nodes
                    .iter()
                    .any(|(name, _)| restartable.contains(&name.as_str()))
            })
        };
        loop {
            if let Some(first) = self.rewind_requested()? {
                return Ok(Some(first));
            }
            if !self.producer.has_consumers() && !restartable_consumer_exists() {
                return Ok(None);
            }
            if self.node.wait(Duration::from_millis(10)).is_err() {
                return Ok(None);
            }
        }
    }
}
