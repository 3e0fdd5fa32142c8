//! `pssba simulate`: a thin adapter from flags and files to `pssba_sim::simulate_scene`
//! (DESIGN.md sections 4-5): load the scene, simulate, write the dataset folder and meta.json.

use crate::cli::SimulateArgs;
use anyhow::{Context, bail};
use nalgebra::{Isometry3, Point3};
use pssba_io::{Dataset, GT_FILE, POSES_FILE, PcdEncoding, StampedPose};
use pssba_sim::{
    BuiltinScene, Mid360, Raycaster, Scene, SimulatedDataset, SimulationSpec, TriangleMesh,
    path_is_free, simulate_scene_with_progress,
};
use serde_json::json;
use std::path::Path;
use std::time::Instant;

/// Name of the description written next to the dataset.
const META_FILE: &str = "meta.json";

/// The scene named by `--scene`: a built-in name, else an STL path.
fn load_scene(arg: &str, ground: bool) -> anyhow::Result<(Scene, serde_json::Value)> {
    if let Some(builtin) = BuiltinScene::from_name(arg) {
        let scene = builtin.build();
        let meta =
            json!({ "name": scene.name, "source": "builtin", "triangles": scene.mesh.len() });
        return Ok((scene, meta));
    }
    let path = Path::new(arg);
    let is_stl = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("stl"));
    if !is_stl && !path.is_file() {
        let names: Vec<&str> = BuiltinScene::ALL.iter().map(|s| s.name()).collect();
        bail!(
            "--scene '{arg}': unknown scene; expected one of {} or the path of an .stl mesh",
            names.join(", ")
        );
    }
    let triangles = pssba_io::read_stl(path)?;
    let name = path
        .file_stem()
        .map_or_else(|| arg.to_owned(), |s| s.to_string_lossy().into_owned());
    let scene = Scene::from_mesh(&name, TriangleMesh::from_triangles(&triangles), ground)
        .with_context(|| format!("{}: cannot ray-cast this mesh", path.display()))?;
    let meta = json!({
        "name": name,
        "source": "stl",
        "path": arg,
        "triangles": triangles.len(),
        "ground_plane_added": ground,
    });
    Ok((scene, meta))
}

/// Fails before any work if `dir` already holds a dataset.
fn refuse_existing(dir: &Path) -> anyhow::Result<()> {
    for name in [pssba_io::FRAMES_DIR, POSES_FILE, GT_FILE, META_FILE] {
        let existing = dir.join(name);
        if existing.exists() {
            bail!(
                "{}: already exists; refusing to overwrite a dataset (choose another --out)",
                existing.display()
            );
        }
    }
    Ok(())
}

fn stamped(stamps: &[f64], poses: &[Isometry3<f64>]) -> Vec<StampedPose> {
    stamps
        .iter()
        .zip(poses)
        .map(|(&stamp, &world_from_lidar)| StampedPose {
            stamp,
            world_from_lidar,
        })
        .collect()
}

/// meta.json: everything needed to regenerate the dataset and read it right.
fn meta(
    scene: serde_json::Value,
    spec: &SimulationSpec,
    data: &SimulatedDataset,
) -> serde_json::Value {
    let t = &data.trajectory;
    let s = &spec.sensor;
    let counts: Vec<usize> = data.frames.iter().map(Vec::len).collect();
    let mean = counts.iter().sum::<usize>() as f64 / counts.len().max(1) as f64;
    json!({
        "generator": format!("pssba simulate {}", env!("CARGO_PKG_VERSION")),
        "scene": scene,
        "frames": spec.frames,
        "seed": spec.seed,
        "trajectory": {
            "kind": t.kind.name(),
            "centre_m": [t.centre.x, t.centre.y, t.centre.z],
            "radius_m": t.radius_m,
            "speed_m_s": t.speed_m_s,
            "yaw_sway_rad": t.yaw_sway_rad,
            "yaw_sway_hz": t.yaw_sway_hz,
            "climb_m_s": t.climb_m_s,
            "lane_spacing_m": t.lane_spacing_m,
            "lanes": t.lanes,
        },
        "pose_noise": {
            "translation_rms_m": spec.pose_noise.translation_rms_m,
            "rotation_rms_deg": spec.pose_noise.rotation_rms_deg,
        },
        "sensor": {
            "model": "Livox Mid-360-like, MARSIM non-repetitive pattern",
            "rays_per_frame": s.rays_per_frame,
            "frame_rate_hz": s.frame_rate_hz,
            "range_m": [s.min_range_m, s.max_range_m],
            "range_noise_m": s.range_noise_m,
            "elevation_deg": [s.min_elevation_deg, s.max_elevation_deg],
        },
        "points_per_frame": {
            "min": counts.iter().min(),
            "mean": mean,
            "max": counts.iter().max(),
        },
        "motion_within_frames": spec.motion_within_frames,
        "notes": if spec.motion_within_frames {
            "frames/*.pcd in the lidar frame at each frame's stamp, each ray cast from the true \
             pose at its own time (field time: s after the stamp); gt.txt = true \
             world_from_lidar at the stamps; poses.txt = gt with seeded noise"
        } else {
            "frames/*.pcd in the lidar frame, each taken at its pose (no motion within a \
             frame, --still-frames); gt.txt = true world_from_lidar; poses.txt = gt with \
             seeded noise"
        },
    })
}

/// Runs the subcommand.
pub fn run(args: &SimulateArgs) -> anyhow::Result<()> {
    if args.frames == 0 {
        bail!("--frames must be at least 1 (got 0)");
    }
    if args.points_per_frame == 0 {
        bail!("--points-per-frame must be at least 1 (got 0)");
    }
    refuse_existing(&args.out)?;
    let (mut scene, scene_meta) = load_scene(&args.scene, !args.no_ground)?;
    if let Some(speed) = args.speed {
        if !(speed.is_finite() && (0.01..=30.0).contains(&speed)) {
            bail!("--speed {speed}: expected 0.01 to 30 m/s");
        }
        scene.trajectory.speed_m_s = speed;
    }
    if args.head_turns {
        scene.trajectory.yaw_sway_rad = 0.55;
        scene.trajectory.yaw_sway_hz = 0.6;
    }
    let spec = SimulationSpec {
        frames: args.frames,
        seed: args.seed,
        trajectory: args.trajectory.map(Into::into),
        pose_noise: args.pose_noise,
        sensor: Mid360 {
            rays_per_frame: args.points_per_frame,
            ..Mid360::default()
        },
        parallel: true,
        motion_within_frames: !args.still_frames,
    };
    let flown = spec
        .trajectory
        .map_or(scene.trajectory, |k| scene.trajectory.with_kind(k));
    let positions: Vec<Point3<f64>> = flown
        .world_from_lidar(spec.frames, spec.sensor.frame_rate_hz)
        .iter()
        .map(|p| Point3::from(p.translation.vector))
        .collect();
    if !path_is_free(&Raycaster::new(&scene.mesh)?, &positions, false) {
        tracing::warn!(
            "the {} path passes within 2 m of (or through) the '{}' geometry",
            flown.kind.name(),
            scene.name
        );
    }
    tracing::info!(
        "simulating {} frames of '{}' ({} triangles): {} of radius {:.1} m at z {:.1} m, seed {}",
        spec.frames,
        scene.name,
        scene.mesh.len(),
        flown.kind.name(),
        flown.radius_m,
        flown.centre.z,
        spec.seed
    );
    let started = Instant::now();
    let step = (spec.frames / 10).max(1);
    let data = simulate_scene_with_progress(&scene, &spec, |done, total| {
        if done % step == 0 || done == total {
            tracing::info!("simulated {done}/{total} frames");
        }
    })?;
    let simulate_s = started.elapsed().as_secs_f64();
    Dataset::write_with_times(
        &args.out,
        &data.frames,
        data.point_times_s.as_deref(),
        &stamped(&data.stamps, &data.initial),
        Some(&stamped(&data.stamps, &data.ground_truth)),
        PcdEncoding::Binary,
    )?;
    let meta_path = args.out.join(META_FILE);
    let text = serde_json::to_string_pretty(&meta(scene_meta, &spec, &data))?;
    std::fs::write(&meta_path, text + "\n")
        .with_context(|| format!("{}: cannot write", meta_path.display()))?;
    let points: usize = data.frames.iter().map(Vec::len).sum();
    tracing::info!(
        "wrote {} frames ({:.0} points per frame) to {} (simulation {:.2} s)",
        data.frames.len(),
        points as f64 / data.frames.len() as f64,
        args.out.display(),
        simulate_s
    );
    Ok(())
}
