//! `pssba import INPUT --out DIR`: any input's frames and initial poses (a recording, a KITTI
//! sequence...) as a dataset folder, written frame by frame (the input is never held whole).

use crate::cli::ImportArgs;
use anyhow::{Context, bail};
use pssba_io::{FRAMES_DIR, GT_FILE, POSES_FILE, PcdEncoding, StampedPose};
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
    let settings = pssba_config::Config::load(args.config.as_deref())?;
    let source = args.recording.open(&args.bag, &settings.recording)?;
    let total = source.len().unwrap_or(0);
    std::fs::create_dir_all(&frames_dir)
        .with_context(|| format!("creating {}", frames_dir.display()))?;
    // A failed import leaves no half dataset behind (it would open as a shorter flight).
    let written = write_frames(source.as_ref(), &frames_dir, total);
    let (initial, ground_truth, points_written) = match written {
        Ok(done) => done,
        Err(error) => {
            if let Err(cleanup) = std::fs::remove_dir_all(&frames_dir) {
                tracing::warn!("could not remove {}: {cleanup}", frames_dir.display());
            }
            return Err(error.context(format!(
                "importing {} (nothing was written to {})",
                args.bag.display(),
                args.out.display()
            )));
        }
    };
    pssba_io::write_tum(args.out.join(POSES_FILE), &initial)?;
    if let Some(gt) = ground_truth.filter(|g| !g.is_empty()) {
        pssba_io::write_tum(args.out.join(GT_FILE), &gt)?;
    }
    let meta_path = args.out.join("meta.json");
    std::fs::write(
        &meta_path,
        serde_json::to_string_pretty(&source.metadata())?,
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

/// Frames as PCDs in `frames_dir`, and the initial (and true, when every frame has one) poses.
fn write_frames(
    source: &dyn pssba_source::FrameSource,
    frames_dir: &std::path::Path,
    total: usize,
) -> anyhow::Result<(Vec<StampedPose>, Option<Vec<StampedPose>>, usize)> {
    let step = (total / 10).max(1);
    let mut initial = Vec::with_capacity(total);
    let mut ground_truth = Some(Vec::with_capacity(total));
    let mut points_written = 0usize;
    for (k, frame) in source.frames_from(0)?.enumerate() {
        let frame = frame?;
        // Point times, when the input has them, go into a `time` field (s after the stamp).
        let path = frames_dir.join(format!("{k:06}.pcd"));
        let bytes = pssba_io::pcd_to_bytes_with_times(
            &frame.points,
            frame.point_times_s.as_deref(),
            PcdEncoding::Binary,
            pssba_io::PcdPrecision::F32,
            &path,
        )?;
        std::fs::write(&path, bytes).with_context(|| format!("writing {}", path.display()))?;
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
    Ok((initial, ground_truth, points_written))
}
