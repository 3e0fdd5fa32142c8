//! Read throughput of recordings against a PCD dataset folder: for each path, the planning
//! pass (topics, poses, cloud headers) and the frame pass (every cloud decoded), in MB/s of the
//! stored bytes and frames/s. A path with `frames/` is read as a dataset folder (one frame at a
//! time, one thread, as ingest reads it).
//!
//! `cargo run --release -p pssba-bag --example read_throughput -- DATASET_DIR BAG...`
//! (tools/make_bag_fixtures.py --no-verify writes the bags of a simulated folder).

use std::path::{Path, PathBuf};
use std::time::Instant;

use pssba_bag::{Recording, RecordingOptions};

fn folder_bytes(path: &Path) -> u64 {
    if path.is_file() {
        return std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
    }
    std::fs::read_dir(path)
        .map(|entries| {
            entries
                .filter_map(Result::ok)
                .map(|e| folder_bytes(&e.path()))
                .sum()
        })
        .unwrap_or(0)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let paths: Vec<PathBuf> = std::env::args_os().skip(1).map(PathBuf::from).collect();
    println!("| input | MB | frames | points | plan s | read s | MB/s | frames/s |");
    println!("|---|---|---|---|---|---|---|---|");
    for path in paths {
        let mb = folder_bytes(&path) as f64 / 1e6;
        let started = Instant::now();
        let (frames, points, plan_s) = if path.join("frames").is_dir() {
            let dataset = pssba_io::Dataset::open(&path)?;
            let plan_s = started.elapsed().as_secs_f64();
            let mut points = 0;
            for k in 0..dataset.len() {
                points += dataset.load_frame(k)?.len();
            }
            (dataset.len(), points, plan_s)
        } else {
            let recording = Recording::open(&path, &RecordingOptions::default())?;
            let plan_s = started.elapsed().as_secs_f64();
            let mut points = 0;
            let mut frames = 0;
            for frame in recording.frames()? {
                points += frame?.points.len();
                frames += 1;
            }
            (frames, points, plan_s)
        };
        let total_s = started.elapsed().as_secs_f64();
        println!(
            "| {} | {mb:.1} | {frames} | {points} | {plan_s:.3} | {:.3} | {:.0} | {:.0} |",
            path.display(),
            total_s - plan_s,
            mb / total_s,
            frames as f64 / total_s
        );
    }
    Ok(())
}
