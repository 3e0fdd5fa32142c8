//! `pssba eval ape` and `pssba eval occupancy`.

use crate::cli::{ApeArgs, OccupancyArgs};
use anyhow::{Context, bail};

/// Translation APE after SE(3) Umeyama alignment.
pub fn run_ape(args: &ApeArgs) -> anyhow::Result<()> {
    let stamped = |path: &std::path::Path| -> anyhow::Result<Vec<(f64, nalgebra::Isometry3<f64>)>> {
        Ok(pssba_io::read_tum(path)?
            .into_iter()
            .map(|p| (p.stamp, p.world_from_lidar))
            .collect())
    };
    let gt = stamped(&args.gt)?;
    let est = stamped(&args.est)?;
    let ape = pssba_eval::ape_translation(&gt, &est, args.max_diff).with_context(|| {
        format!(
            "APE of {} against {}",
            args.est.display(),
            args.gt.display()
        )
    })?;
    if args.json {
        let doc = serde_json::json!({
            "rmse_m": ape.rmse_m, "mean_m": ape.mean_m, "median_m": ape.median_m,
            "max_m": ape.max_m, "min_m": ape.min_m, "std_m": ape.std_m, "matched": ape.matched,
            "alignment": "se3 umeyama (no scale)",
        });
        println!("{}", serde_json::to_string_pretty(&doc)?);
    } else {
        println!(
            "APE (translation, m) after SE(3) Umeyama alignment, {} matched poses",
            ape.matched
        );
        println!(
            "  rmse   {:.6}\n  mean   {:.6}\n  median {:.6}\n  std    {:.6}\n  min    {:.6}\n  max    {:.6}",
            ape.rmse_m, ape.mean_m, ape.median_m, ape.std_m, ape.min_m, ape.max_m
        );
    }
    Ok(())
}

/// Occupied voxels of the merged cloud, averaged over seeded sub-voxel grid offsets.
pub fn run_occupancy(args: &OccupancyArgs) -> anyhow::Result<()> {
    let source = pssba_source::open(&args.dir, &pssba_source::OpenOptions::default())?;
    let poses = pssba_io::read_tum(&args.poses)?;
    if Some(poses.len()) != source.len() {
        bail!(
            "{}: {} poses but {} has {} frames",
            args.poses.display(),
            poses.len(),
            args.dir.display(),
            source
                .len()
                .map_or("an unknown number of".into(), |n| n.to_string())
        );
    }
    let frames: Vec<_> = source.read_all()?.into_iter().map(|f| f.points).collect();
    let world_from_lidar: Vec<_> = poses.iter().map(|p| p.world_from_lidar).collect();
    let occupancy = pssba_eval::occupancy_of_frames(
        &frames,
        &world_from_lidar,
        args.voxel,
        args.offsets,
        args.seed,
    )?;
    if args.json {
        let doc = serde_json::json!({
            "mean_voxels": occupancy.mean_voxels, "min": occupancy.min, "max": occupancy.max,
            "per_offset": occupancy.per_offset, "offsets_m": occupancy.offsets_m,
            "voxel_m": occupancy.voxel_m, "skipped_points": occupancy.skipped_points,
            "note": "mean over seeded sub-voxel grid offsets; fewer voxels = sharper map",
        });
        println!("{}", serde_json::to_string_pretty(&doc)?);
    } else {
        println!(
            "occupied {:.3} m voxels: {:.1} (mean over {} seeded sub-voxel grid offsets, seed {}; min {}, max {}); fewer = sharper",
            occupancy.voxel_m,
            occupancy.mean_voxels,
            occupancy.per_offset.len(),
            args.seed,
            occupancy.min,
            occupancy.max
        );
    }
    Ok(())
}
