//! An example consumer: writes each final pose of a live instance as it becomes final, in
//! TUM (`stamp tx ty tz qx qy qz qw`), and exits after the end-of-stream marker.
//!
//! ```sh
//! cargo run --release -p pssba-client --example write_tum -- --instance demo --out final.tum
//! ```

use clap::Parser;
use pssba_client::outputs::FinalPoseSubscriber;
use pssba_client::{instance, services};
use std::io::Write;
use std::path::PathBuf;
use std::time::{Duration, Instant};

#[derive(Debug, Parser)]
struct Args {
    /// The instance of `pssba run --input live`.
    #[arg(long)]
    instance: String,
    /// TUM file to write.
    #[arg(long)]
    out: PathBuf,
    /// Give up after this many seconds without a final pose.
    #[arg(long, default_value_t = 600.0)]
    timeout: f64,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    instance::check(&args.instance)?;
    let node = services::create_node(&instance::prefix(&args.instance), "write_tum")?;
    let poses = FinalPoseSubscriber::create(&node)?;
    let mut out = std::io::BufWriter::new(std::fs::File::create(&args.out)?);
    let mut last = Instant::now();
    let mut written = 0u64;
    loop {
        while let Some(message) = poses.receive()? {
            last = Instant::now();
            if message.end_of_stream != 0 {
                out.flush()?;
                anyhow::ensure!(
                    message.sequence == written,
                    "the system made {} poses final but {written} arrived (this subscriber \
                     fell more than 4096 poses behind)",
                    message.sequence
                );
                eprintln!("write_tum: {written} final poses in {}", args.out.display());
                return Ok(());
            }
            let pose = message
                .world_from_lidar
                .to_isometry("final pose", message.sequence)?;
            let t = pose.translation.vector;
            let q = pose.rotation;
            writeln!(
                out,
                "{:.9} {:.12} {:.12} {:.12} {:.12} {:.12} {:.12} {:.12}",
                message.stamp_s, t.x, t.y, t.z, q.i, q.j, q.k, q.w
            )?;
            written += 1;
        }
        anyhow::ensure!(
            last.elapsed().as_secs_f64() < args.timeout,
            "no final pose for {} s",
            args.timeout
        );
        poses.wait(Duration::from_millis(500))?;
    }
}
