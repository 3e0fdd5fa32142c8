//! `pssba inspect INPUT`: what an input holds, and what `adjust`/`import`/`run` would read: a
//! recording's topics and the frames it gives; another source's frames.

use crate::cli::InspectArgs;
use pssba_bag::{Bag, Container, ExtrinsicSource, Recording, stamp_s};
use pssba_config::RecordingConfig;

/// Runs the subcommand. A recording that cannot give frames is reported (with the reason), not
/// an error: listing its topics is what this command is for.
pub fn run(args: &InspectArgs) -> anyhow::Result<()> {
    let settings = pssba_config::Config::load(args.config.as_deref())?;
    let kind = pssba_source::detect(&args.bag)?;
    if Container::detect(&args.bag).is_none() {
        return inspect_source(args, &settings.recording, kind.name);
    }
    let options = args.recording.options(&settings.recording)?;
    let bag = Bag::open(&args.bag)?;
    let (start, end) = bag.time_range_ns().unwrap_or((0, 0));
    let duration_s = (end - start) as f64 * 1e-9;
    let plan = if pssba_source::is_pssba_recording(&bag) {
        Err(
            "a pssba run recording: its /lidar/points clouds and /pssba/poses/initial poses are \
             replayed as they are"
                .to_string(),
        )
    } else {
        Recording::open(&args.bag, &options).map_err(|e| e.to_string())
    };
    if args.json {
        let topics: Vec<_> = bag
            .topics()
            .iter()
            .map(|t| serde_json::json!({"name": t.name, "type": t.type_name, "count": t.count}))
            .collect();
        let mut out = serde_json::json!({
            "path": args.bag.display().to_string(),
            "container": bag.container().describe(),
            "bytes": bag.size_bytes(),
            "start_s": stamp_s(start),
            "duration_s": duration_s,
            "topics": topics,
        });
        match &plan {
            Ok(r) => {
                let t = r.extrinsic.translation.vector;
                let q = r.extrinsic.rotation.coords;
                out["frames"] = serde_json::json!({
                    "points_topic": r.points_topic.name,
                    "poses_topic": r.poses_topic.name,
                    "cloud_frame": r.cloud_frame,
                    "world_frame": r.world_frame,
                    "clouds_in_world": r.clouds_in_world,
                    "extrinsic": [t.x, t.y, t.z, q.x, q.y, q.z, q.w],
                    "extrinsic_source": format!("{:?}", r.extrinsic_source),
                    "frames": r.frames.len(),
                    "largest_frame_points": r.max_points(),
                    "skipped": r.skipped,
                    "frame_period_s": frame_period_s(r),
                    "point_time": r.point_time,
                });
            }
            Err(reason) => out["frames_error"] = serde_json::json!(reason),
        }
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    println!(
        "{}: {}, {:.1} MB",
        args.bag.display(),
        bag.container().describe(),
        bag.size_bytes() as f64 / 1e6
    );
    println!(
        "time: {:.3} s from {:.3} (epoch s)",
        duration_s,
        stamp_s(start)
    );
    println!(
        "{:<32} {:<44} {:>9} {:>8}",
        "topic", "type", "messages", "Hz"
    );
    for t in bag.topics() {
        let rate = if duration_s > 0.0 && t.count > 1 {
            format!("{:.1}", (t.count - 1) as f64 / duration_s)
        } else {
            "-".into()
        };
        println!(
            "{:<32} {:<44} {:>9} {:>8}",
            t.name, t.type_name, t.count, rate
        );
    }
    match plan {
        Ok(r) => {
            println!(
                "would read: clouds {} ({}), poses {} ({} poses, {} -> {})",
                r.points_topic.name,
                r.cloud_frame,
                r.poses_topic.name,
                r.pose_count,
                r.world_frame,
                r.body_frame.as_deref().unwrap_or("(unnamed)")
            );
            let t = r.extrinsic.translation.vector;
            let q = r.extrinsic.rotation.coords;
            let from = match &r.extrinsic_source {
                ExtrinsicSource::Given => "--extrinsic".to_string(),
                ExtrinsicSource::Tf { body, lidar } => format!("tf {body} -> {lidar}"),
                ExtrinsicSource::SameFrame => "clouds in the body frame".into(),
                ExtrinsicSource::AssumedIdentity => {
                    "nothing links the frames: identity (set --extrinsic)".into()
                }
            };
            println!(
                "extrinsic body_from_lidar: t {:.4} {:.4} {:.4}, q {:.6} {:.6} {:.6} {:.6} ({from})",
                t.x, t.y, t.z, q.x, q.y, q.z, q.w
            );
            if r.clouds_in_world {
                println!(
                    "clouds are in the world frame {}: taken back into the sensor frame",
                    r.world_frame
                );
            }
            match &r.point_time {
                Some(c) => println!("point times: {}", c.describe()),
                None if r.clouds_in_world => {
                    println!("point times: not read (world-frame clouds are de-skewed already)")
                }
                None => println!(
                    "point times: none (every point at its frame's stamp; --point-time names a \
                     field)"
                ),
            }
            if let Some(period) = frame_period_s(&r) {
                println!("frames every {:.1} ms (median)", period * 1e3);
            }
            let s = &r.skipped;
            println!(
                "frames: {} (largest {} points); skipped: {} not selected, {} outside the pose range, {} across a pose gap, {} out of order",
                r.frames.len(),
                r.max_points(),
                s.not_selected,
                s.outside_pose_range,
                s.pose_gap,
                s.out_of_order
            );
        }
        Err(reason) => println!("frames: none can be read as given: {reason}"),
    }
    Ok(())
}

/// The median time between planned frames (s).
fn frame_period_s(r: &pssba_bag::Recording) -> Option<f64> {
    let mut steps: Vec<i64> = r
        .frames
        .windows(2)
        .map(|w| w[1].stamp_ns - w[0].stamp_ns)
        .collect();
    steps.sort_unstable();
    steps.get(steps.len() / 2).map(|&ns| ns as f64 * 1e-9)
}

/// An input that is not a recording (a dataset folder, a KITTI sequence): its frames.
fn inspect_source(args: &InspectArgs, config: &RecordingConfig, kind: &str) -> anyhow::Result<()> {
    let source = args.recording.open(&args.bag, config)?;
    let mut summary = source.metadata();
    summary["kind"] = serde_json::json!(kind);
    summary["frames"] = serde_json::json!(source.len());
    summary["largest_frame_points"] = serde_json::json!(source.max_points());
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
        return Ok(());
    }
    let count = |n: Option<usize>| n.map_or("unknown".to_string(), |n| n.to_string());
    println!("{}: {kind}", args.bag.display());
    println!(
        "frames: {} (largest {} points)",
        count(source.len()),
        count(source.max_points())
    );
    Ok(())
}
