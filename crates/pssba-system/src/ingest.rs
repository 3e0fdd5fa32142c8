//! The ingest stage: takes frames from a [`FrameSource`] and publishes each into a loaned
//! shared-memory sample, as fast as the consumers take them or at a fixed sensor rate. Ends
//! with an end-of-stream marker. The frames service is sized from the source's largest frame
//! when the source knows it up front (replay), else from `system.live_max_frame_points`.

use crate::SystemConfig;
use crate::shm;
use crate::source::SourceSpec;
use anyhow::{Context, bail};
#[cfg(doc)]
use pssba_msg::FrameConsumer;
use pssba_msg::frames::ready_id;
use pssba_msg::services;
use pssba_msg::{FrameProducer, PointXyz};
use std::io::Read;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Options of the ingest stage.
#[derive(Debug, Clone)]
pub struct IngestOptions {
    /// iceoryx2 prefix of this run.
    pub prefix: String,
    /// Frame source.
    pub source: SourceSpec,
    /// Publish at this rate (Hz) instead of as fast as possible.
    pub rate_hz: Option<f64>,
    /// The process system's settings.
    pub system: SystemConfig,
    /// Where the count of frames sent is kept after every send, so a restarted ingest stage
    /// resumes after the last frame its predecessor published ([`Progress`]).
    pub progress: Option<PathBuf>,
}

/// The count of frames sent, kept in a small file (8 bytes, little-endian) rewritten after
/// every send. It outlives a crash of this process (the page cache keeps it; no fsync: the
/// file only has to survive the process, not the machine). A restarted stage resumes at the
/// count; if the crash came between a send and its count, that frame is sent again and the
/// consumers skip it by its sequence number ([`FrameConsumer::follow_resumed_producer`]).
#[derive(Debug)]
struct Progress {
    file: std::fs::File,
}

impl Progress {
    /// Opens (or creates) the file and reads the count kept there (0 when new or empty).
    fn open(path: &Path) -> anyhow::Result<(Self, u64)> {
        let mut file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(path)
            .with_context(|| format!("opening the ingest progress file {}", path.display()))?;
        let mut bytes = Vec::new();
        file.read_to_end(&mut bytes)
            .with_context(|| format!("reading {}", path.display()))?;
        let sent = match bytes.len() {
            0 => 0,
            8 => u64::from_le_bytes(bytes.try_into().unwrap_or_default()),
            n => bail!(
                "the ingest progress file {} holds {n} bytes; expected 8 (a frame count)",
                path.display()
            ),
        };
        Ok((Self { file }, sent))
    }

    fn store(&self, sent: u64) -> anyhow::Result<()> {
        self.file
            .write_all_at(&sent.to_le_bytes(), 0)
            .context("updating the ingest progress file")
    }
}

/// Frames read ahead of the one being sent.
const PREFETCH_FRAMES: usize = 4;

/// Runs the stage until every frame is published.
pub fn run(options: &IngestOptions) -> anyhow::Result<()> {
    let (progress, resume_at) = match &options.progress {
        Some(path) => {
            let (progress, sent) = Progress::open(path)?;
            (Some(progress), sent)
        }
        None => (None, 0),
    };
    // Open before anything waits: a dataset that cannot be opened fails fast.
    let source = options.source.open_from(resume_at as usize)?;
    if let Some(total) = source.frame_count()
        && resume_at > total as u64
    {
        bail!("the ingest progress file says {resume_at} frames were sent, of {total}");
    }
    let capacity = source
        .max_points()
        .unwrap_or(options.system.live_max_frame_points)
        .max(1);
    let count = source.frame_count();
    tracing::info!(
        "{}: {} frames, frames service sized for {capacity} points per frame ({:.1} MiB a slot)",
        options.source.describe(),
        count.map_or("an unknown number of".into(), |n| n.to_string()),
        capacity as f64 * std::mem::size_of::<PointXyz>() as f64 / (1 << 20) as f64
    );
    let node = services::create_node(&options.prefix, "ingest")?;
    let mut producer =
        FrameProducer::create(&node, capacity, options.system.backpressure_timeout())?;
    producer.start_at(resume_at);
    producer.wait_for_consumers(&node, &ready_id::SYSTEM, options.system.startup_timeout())?;
    if resume_at > 0 {
        tracing::warn!("restarted: resuming after the {resume_at} frames already published");
    }
    let started = Instant::now();
    let period = options.rate_hz.map(|hz| Duration::from_secs_f64(1.0 / hz));
    let of_count = count.map_or(String::new(), |n| format!("/{n}"));
    // Frames are read a few ahead on another thread, so reading a file overlaps sending the
    // previous frame (and a replay at a fixed rate is not delayed by the disk).
    let (prefetched, frames) = crossbeam_channel::bounded(PREFETCH_FRAMES);
    let reader = std::thread::spawn(move || {
        for frame in source {
            if prefetched.send(frame).is_err() {
                break;
            }
        }
    });
    for (k, frame) in (resume_at as usize..).zip(frames.iter()) {
        if shm::termination_requested(&node) {
            bail!("interrupted after {k}{of_count} frames");
        }
        let frame = frame.with_context(|| format!("frame {k}"))?;
        let points = &frame.points;
        producer
            .send(
                frame.stamp_s,
                &frame.world_from_lidar,
                frame.ground_truth.as_ref(),
                points.len(),
                |i| PointXyz {
                    xyz_m: [points[i].x as f32, points[i].y as f32, points[i].z as f32],
                },
            )
            .with_context(|| format!("publishing frame {k}"))?;
        let sent = k + 1;
        tracing::debug!(sequence = k, "frame sent");
        if let Some(progress) = &progress {
            progress.store(sent as u64)?;
        }
        if sent.is_multiple_of(20) || Some(sent) == count {
            tracing::info!("published {sent}{of_count} frames");
        }
        if let Some(period) = period {
            let due = period * ((k - resume_at as usize) as u32 + 1);
            if let Some(wait) = due.checked_sub(started.elapsed()) {
                std::thread::sleep(wait);
            }
        }
    }
    let sent = producer.sent();
    drop(frames);
    if reader.join().is_err() {
        bail!("the frame reader thread panicked after {sent} frames");
    }
    producer.end_stream().context("publishing end of stream")?;
    tracing::info!(
        "all {sent} frames published in {:.2} s",
        started.elapsed().as_secs_f64()
    );
    producer.linger(&node, options.system.backpressure_timeout());
    Ok(())
}
