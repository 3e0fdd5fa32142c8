//! `pssba import BAG --out DIR`: a recording's frames and initial poses as a dataset folder,
//! written frame by frame (the recording is never held whole).

use crate::cli::ImportArgs;
use crate::inspect::skipped_json;
use anyhow::{Context, bail};
use pssba_io::{FRAMES_DIR, GT_FILE, POSES_FILE, PcdEncoding, StampedPose};
use pssba_system::source::OpenedRecording;
use std::time::Instant;

/// Runs the subcommand.
pub fn run(args: &ImportArgs) -> anyhow::Result<()> {
    let started = Instant::now();
    let frames_dir = args.out.join(FRAMES_DIR);
    for existing in [
        frames_dir.clone(),
        args.out.join(POSES_FILE),
        args.out.join(GT_FILE),
    ] {
        if existing.exists() {
            bail!(
                "{}: already exists; refusing to overwrite a dataset",
                existing.display()
            );
        }
    }
    let settings = crate::settings::load_settings(args.config.as_deref())?;
    let recording = args
        .recording
        .spec(&args.bag, &settings.recording)?
        .open()?;
    let total = recording.len();
    std::fs::create_dir_all(&frames_dir)
        .with_context(|| format!("creating {}", frames_dir.display()))?;
    let step = (total / 10).max(1);
    let mut initial = Vec::with_capacity(total);
    let mut ground_truth = Some(Vec::with_capacity(total));
    let mut points_written = 0usize;
    for (k, frame) in recording.frames()?.enumerate() {
        let frame = frame?;
        pssba_io::write_pcd(
            frames_dir.join(format!("{k:06}.pcd")),
            &frame.points,
            PcdEncoding::Binary,
        )?;
        points_written += frame.points.len();
        initial.push(StampedPose::new(frame.stamp_s, frame.world_from_lidar));
        match (frame.ground_truth, &mut ground_truth) {
            (Some(gt), Some(list)) => list.push(StampedPose::new(frame.stamp_s, gt)),
            _ => ground_truth = None,
        }
        if (k + 1) % step == 0 || k + 1 == total {
            tracing::info!("imported {}/{total} frames", k + 1);
        }
    }
    pssba_io::write_tum(args.out.join(POSES_FILE), &initial)?;
    if let Some(gt) = ground_truth.filter(|g| !g.is_empty()) {
        pssba_io::write_tum(args.out.join(GT_FILE), &gt)?;
    }
    let meta_path = args.out.join("meta.json");
    std::fs::write(
        &meta_path,
        serde_json::to_string_pretty(&meta(args, &recording))?,
    )
    .with_context(|| format!("writing {}", meta_path.display()))?;
    let dataset = pssba_io::Dataset::open(&args.out)?;
    eprintln!(
        "wrote {} frames ({points_written} points) to {} in {:.1} s",
        dataset.len(),
        args.out.display(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// meta.json: where the frames came from.
fn meta(args: &ImportArgs, recording: &OpenedRecording) -> serde_json::Value {
    let source = args.bag.display().to_string();
    match recording {
        OpenedRecording::Pssba(run) => serde_json::json!({
            "source": source,
            "kind": "pssba run recording",
            "frames": run.frames,
        }),
        OpenedRecording::Ros(r) => {
            let t = r.extrinsic.translation.vector;
            let q = r.extrinsic.rotation.coords;
            serde_json::json!({
                "source": source,
                "kind": r.bag().container().describe(),
                "points_topic": {"name": r.points_topic.name, "type": r.points_topic.type_name},
                "poses_topic": {"name": r.poses_topic.name, "type": r.poses_topic.type_name},
                "world_frame": r.world_frame,
                "body_frame": r.body_frame,
                "cloud_frame": r.cloud_frame,
                "clouds_in_world_frame": r.clouds_in_world,
                "body_from_lidar": {
                    "translation_m": [t.x, t.y, t.z],
                    "quaternion_xyzw": [q.x, q.y, q.z, q.w],
                    "source": format!("{:?}", r.extrinsic_source),
                },
                "max_pose_gap_s": r.max_pose_gap_s,
                "frames": r.frames.len(),
                "frame_message_indices": r.frames.iter().map(|f| f.message_index).collect::<Vec<_>>(),
                "skipped": skipped_json(&r.skipped),
                "stamps": "the clouds' header stamps (s since the epoch)",
            })
        }
    }
}
