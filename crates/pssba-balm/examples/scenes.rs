//! Measures BALM on the plane-rich room and on the curved scene of pssba-sim: APE (after SE(3)
//! alignment) before and after, wall time, and the outer-iteration reports.
//!
//! `cargo run --release -p pssba-balm --example scenes -- [room|curved] FRAMES POINTS [OUTER [LM]]`
//! (defaults: room 100 20000; curved 20 8000; perturbation 0.2 m / 1 deg RMS, seed 1;
//! OUTER, LM = max outer and LM iterations, defaults from `BalmConfig`; the environment
//! variable BALM_PERTURB_SEED changes the pose-noise seed).

#[path = "../tests/common/room.rs"]
mod room;

use pssba_balm::{BalmConfig, Parallelism, adjust};
use pssba_eval::ape_translation_paired;
use pssba_sim::{SceneSpec, curved_window, perturb_poses};
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let scene = args.first().map_or("room", String::as_str);
    let number =
        |k: usize, default: usize| args.get(k).and_then(|a| a.parse().ok()).unwrap_or(default);
    let (truth, frames) = match scene {
        "curved" => {
            let spec = SceneSpec {
                frames: number(1, 20),
                points_per_frame: number(2, 8000),
                ..SceneSpec::default()
            };
            let window = curved_window(&spec);
            (window.ground_truth, window.frames)
        }
        _ => {
            let truth = room::room_trajectory(number(1, 100));
            let frames = room::scan_room(&truth, number(2, 20000), 0.02, 1);
            (truth, frames)
        }
    };
    let seed = std::env::var("BALM_PERTURB_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1);
    let initial = perturb_poses(&truth, 0.2, 1.0, seed);
    let started = Instant::now();
    let config = BalmConfig {
        max_outer_iterations: number(3, BalmConfig::default().max_outer_iterations),
        max_lm_iterations: number(4, BalmConfig::default().max_lm_iterations),
        ..BalmConfig::default()
    };
    let result = adjust(&frames, &initial, &config, Parallelism::Rayon)?;
    let wall_time_s = started.elapsed().as_secs_f64();
    println!(
        "outer planes  per_layer       dropped  cost_before  cost_after  lm  rms_m    dX       vox_s  time_s"
    );
    for (k, o) in result.outer.iter().enumerate() {
        println!(
            "{k:>5} {:>6}  {:<14} {:>8}  {:>11.4}  {:>10.4}  {:>2}  {:.4}  {:.2e}  {:>5.2}  {:>6.2}",
            o.plane_voxels,
            format!("{:?}", o.plane_voxels_per_layer),
            o.voxels_dropped,
            o.cost_before,
            o.cost_after,
            o.lm_iterations.len(),
            o.rms_distance_m(),
            o.pose_change,
            o.voxelise_time_s,
            o.wall_time_s
        );
    }
    let ape_initial = ape_translation_paired(&truth, &initial)?.rmse_m;
    let ape = ape_translation_paired(&truth, &result.world_from_lidar)?.rmse_m;
    println!(
        "{scene}: {} frames x {} points: APE initial {ape_initial:.4} m -> BALM {ape:.4} m, \
         {wall_time_s:.2} s, converged {}",
        frames.len(),
        frames.first().map_or(0, Vec::len),
        result.converged
    );
    Ok(())
}
