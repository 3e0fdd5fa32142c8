//! An example producer: replays a dataset folder (frames/*.pcd, poses.txt) into a live
//! instance at sensor rate, as a LIO process on the drone would publish its de-skewed frames.
//!
//! ```sh
//! pssba run --input live --instance demo --out /tmp/live.mcap &
//! cargo run --release -p pssba-client --example replay_folder -- /tmp/scene --instance demo --rate 10
//! ```
//!
//! `--duration S` keeps going for S seconds by playing the folder forwards, then backwards,
//! and so on (the trajectory stays continuous; stamps keep increasing at the rate): a soak
//! test of any length from a short folder.

use anyhow::Context;
use clap::Parser;
use pssba_client::{FrameProducer, PointXyz, instance, services};
use std::path::PathBuf;
use std::time::{Duration, Instant};

#[derive(Debug, Parser)]
struct Args {
    /// Dataset folder: frames/*.pcd and poses.txt (TUM).
    dir: PathBuf,
    /// The instance of `pssba run --input live`.
    #[arg(long)]
    instance: String,
    /// Frames per second.
    #[arg(long, default_value_t = 10.0)]
    rate: f64,
    /// Keep publishing for this many seconds (forwards, backwards, ...); default: the folder
    /// once.
    #[arg(long)]
    duration: Option<f64>,
    /// How long to wait for the system's frame consumers (s).
    #[arg(long, default_value_t = 60.0)]
    timeout: f64,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    anyhow::ensure!(
        args.rate.is_finite() && args.rate > 0.0,
        "--rate {}: must be > 0",
        args.rate
    );
    instance::check(&args.instance)?;
    let dataset = pssba_io::Dataset::open(&args.dir)?;
    let frames: Vec<Vec<PointXyz>> = (0..dataset.len())
        .map(|k| {
            let points = dataset.load_frame(k)?;
            Ok(points
                .iter()
                .map(|p| PointXyz {
                    xyz_m: [p.x as f32, p.y as f32, p.z as f32],
                })
                .collect())
        })
        .collect::<anyhow::Result<_>>()
        .with_context(|| format!("reading {}", args.dir.display()))?;
    let capacity = frames.iter().map(Vec::len).max().unwrap_or(1);

    let node = services::create_node(&instance::prefix(&args.instance), "replay_folder")?;
    let timeout = Duration::from_secs_f64(args.timeout);
    let mut producer = FrameProducer::create(&node, capacity, timeout)?;
    producer.wait_for_consumers(&node, &pssba_client::frames::ready_id::SYSTEM, timeout)?;

    let period = Duration::from_secs_f64(1.0 / args.rate);
    let total = match args.duration {
        Some(seconds) => (seconds * args.rate).ceil() as usize,
        None => frames.len(),
    };
    let started = Instant::now();
    let first_stamp = dataset.initial.first().map_or(0.0, |p| p.stamp);
    for k in 0..total {
        // Forwards, then backwards, ...: frame index of step k.
        let n = frames.len();
        let cycle = k % (2 * n - 1).max(1);
        let index = if cycle < n { cycle } else { 2 * n - 2 - cycle };
        let due = started + period * k as u32;
        std::thread::sleep(due.saturating_duration_since(Instant::now()));
        let stamp_s = first_stamp + k as f64 / args.rate;
        let points = &frames[index];
        producer.send(
            stamp_s,
            &dataset.initial[index].world_from_lidar,
            None,
            points.len(),
            |i| points[i],
            None,
        )?;
        if (k + 1) % 600 == 0 {
            eprintln!("replay_folder: {} frames sent", k + 1);
        }
    }
    producer.end_stream()?;
    eprintln!(
        "replay_folder: sent {total} frames and the end-of-stream marker in {:.1} s",
        started.elapsed().as_secs_f64()
    );
    producer.linger(&node, Duration::from_secs(600));
    Ok(())
}
