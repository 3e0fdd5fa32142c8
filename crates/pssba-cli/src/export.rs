//! `pssba export RUN.mcap [--poses F.tum] [--map F.ply|F.pcd]`: the flight out of a recording,
//! all its parts (`pssba_recording::export`); `pssba run` writes the same files beside its
//! recording through [`write_flight`].

use crate::cli::ExportArgs;
use anyhow::bail;
use pssba_io::{PcdEncoding, StampedPose};
use pssba_recording::{VoxelMap, add_flight_to_map, final_trajectory};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// A map file's format, from its extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum MapFormat {
    Ply,
    Pcd,
}

fn map_format(path: &Path) -> anyhow::Result<MapFormat> {
    let extension = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_lowercase);
    match extension.as_deref() {
        Some("ply") => Ok(MapFormat::Ply),
        Some("pcd") => Ok(MapFormat::Pcd),
        _ => bail!(
            "--map {}: the extension says the format, .ply or .pcd",
            path.display()
        ),
    }
}

/// What was written.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FlightWritten {
    /// Frames with a final pose (lines of the TUM file).
    pub frames: usize,
    /// Map points (voxels), when a map was asked for.
    pub map_points: usize,
}

/// Writes the final trajectory of the run recorded to `recording` to `poses` (TUM) and its
/// map, reduced to `voxel_m` voxels, to each of `maps` (.ply or .pcd).
pub fn write_flight(
    recording: &Path,
    poses: Option<&Path>,
    maps: &[PathBuf],
    voxel_m: f64,
) -> anyhow::Result<FlightWritten> {
    let formats = maps
        .iter()
        .map(|path| map_format(path))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let mut map = VoxelMap::new(voxel_m)?;
    let trajectory = final_trajectory(recording)?;
    if trajectory.is_empty() {
        bail!(
            "{}: no frame has a final pose (the run ended before its first window)",
            recording.display()
        );
    }
    let mut written = FlightWritten {
        frames: trajectory.len(),
        map_points: 0,
    };
    if let Some(path) = poses {
        let stamped: Vec<StampedPose> = trajectory
            .iter()
            .map(|p| StampedPose::new(p.stamp_s(), p.world_from_lidar))
            .collect();
        pssba_io::write_tum(path, &stamped)?;
        tracing::info!("wrote {} ({} final poses)", path.display(), stamped.len());
    }
    if maps.is_empty() {
        return Ok(written);
    }
    let total = trajectory.len();
    let step = (total / 10).max(1);
    add_flight_to_map(recording, &trajectory, &mut map, |done| {
        if done % step == 0 || done == total {
            tracing::info!("map: {done}/{total} frames");
        }
    })?;
    let points = map.points();
    written.map_points = points.len();
    for (path, format) in maps.iter().zip(formats) {
        match format {
            MapFormat::Ply => pssba_io::write_ply(path, &points)?,
            MapFormat::Pcd => pssba_io::write_pcd(path, &points, PcdEncoding::Binary)?,
        }
        tracing::info!(
            "wrote {} ({} points, {voxel_m} m voxels, world frame)",
            path.display(),
            points.len()
        );
    }
    Ok(written)
}

/// Runs the subcommand.
pub fn run(args: &ExportArgs) -> anyhow::Result<()> {
    let started = Instant::now();
    if args.poses.is_none() && args.map.is_none() {
        bail!("nothing to export: give --poses F.tum, --map F.ply|F.pcd, or both");
    }
    let config = pssba_config::Config::load(args.config.as_deref())?;
    let voxel_m = args.map_voxel.unwrap_or(config.output.map_voxel_m);
    let maps: Vec<PathBuf> = args.map.iter().cloned().collect();
    let written = write_flight(&args.recording, args.poses.as_deref(), &maps, voxel_m)?;
    tracing::info!(
        "exported {} frames{} in {:.1} s",
        written.frames,
        if args.map.is_some() {
            format!(", {} map points", written.map_points)
        } else {
            String::new()
        },
        started.elapsed().as_secs_f64()
    );
    Ok(())
}
