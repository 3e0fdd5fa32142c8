//! `pssba adjust DIR`: load a dataset folder, run the configured method, write the poses.

use crate::cli::AdjustArgs;
use crate::report::{ApeSummary, RunSummary, ape_m, print_scales};
use crate::settings::load_config;
use anyhow::Context;
use pssba_io::{Dataset, StampedPose};
use rayon::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

/// Loads every frame in parallel, logging progress about every 10%.
pub fn load_frames(dataset: &Dataset) -> anyhow::Result<Vec<Vec<nalgebra::Point3<f64>>>> {
    let total = dataset.len();
    let done = AtomicUsize::new(0);
    let step = (total / 10).max(1);
    (0..total)
        .into_par_iter()
        .map(|k| {
            let frame = dataset.load_frame(k)?;
            let n = done.fetch_add(1, Ordering::Relaxed) + 1;
            if n.is_multiple_of(step) || n == total {
                tracing::info!("loaded {n}/{total} frames");
            }
            Ok(frame)
        })
        .collect()
}

fn as_stamped(poses: &[StampedPose]) -> Vec<(f64, nalgebra::Isometry3<f64>)> {
    poses
        .iter()
        .map(|p| (p.stamp, p.world_from_lidar))
        .collect()
}

/// Runs the subcommand.
pub fn run(args: &AdjustArgs) -> anyhow::Result<()> {
    let mut config = load_config(args.config.as_deref())?;
    if let Some(method) = args.method {
        config.method = method.into();
    }
    let dataset = Dataset::open(&args.dir)?;
    tracing::info!(
        "{}: {} frames, method {}",
        args.dir.display(),
        dataset.len(),
        config.method.name()
    );
    let frames = load_frames(&dataset)?;
    let initial: Vec<_> = dataset.initial.iter().map(|p| p.world_from_lidar).collect();
    let started = Instant::now();
    let result = pssba_core::adjust(&frames, &initial, &config)
        .with_context(|| format!("adjusting {}", args.dir.display()))?;
    let wall_time_s = started.elapsed().as_secs_f64();
    print_scales(&result);

    let optimized: Vec<StampedPose> = dataset
        .initial
        .iter()
        .zip(&result.world_from_lidar)
        .map(|(p, pose)| StampedPose {
            stamp: p.stamp,
            world_from_lidar: *pose,
        })
        .collect();
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| args.dir.join(format!("poses_{}.txt", config.method.name())));
    pssba_io::write_tum(&out, &optimized)?;
    let mut outputs = vec![out.display().to_string()];
    eprintln!("wrote {} poses to {}", optimized.len(), out.display());
    if let Some(map) = &args.map {
        pssba_io::write_ply(map, &result.smoothed_cloud)?;
        eprintln!(
            "wrote smoothed cloud ({} points) to {}",
            result.smoothed_cloud.len(),
            map.display()
        );
        outputs.push(map.display().to_string());
    }
    let ape = match &dataset.ground_truth {
        Some(gt) => {
            let summary = ApeSummary {
                initial_m: ape_m(&as_stamped(gt), &as_stamped(&dataset.initial))?,
                optimized_m: ape_m(&as_stamped(gt), &as_stamped(&optimized))?,
            };
            eprintln!(
                "APE vs gt.txt: initial {:.4} m, optimized {:.4} m",
                summary.initial_m, summary.optimized_m
            );
            Some(summary)
        }
        None => None,
    };
    if args.json {
        let summary = RunSummary::new(config.method, &result, ape, wall_time_s, outputs);
        println!("{}", serde_json::to_string_pretty(&summary)?);
    }
    Ok(())
}
