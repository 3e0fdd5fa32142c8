//! A flight that leaves a place and comes back (pssba-sim's `revisit` scene, LIO-like drift),
//! adjusted in plain sliding windows and in the whole-flight pipeline; prints APE of each
//! visit alone, both visits together and the whole flight, the largest frame-to-frame step
//! and the wall time. Issue 38's targets, measured:
//!
//! `cargo run --release -p pssba-core --example revisit_flight -- [EXCURSION_M] [SPEED_M_S]
//! [RAYS] [SEED]` (defaults 100 m, 1.5 m/s, 20000 rays, seed 1).

use nalgebra::Isometry3;
use pssba_core::{
    FlightSettings, MotionPrior, Parallelism, PssBaConfig, WindowSpec, adjust_flight,
};
use pssba_eval::ape_translation_paired;
use pssba_sim::{
    Mid360, OdometryDrift, SimulationSpec, drift_poses, revisit_frames, revisit_scene,
    simulate_scene,
};
use std::time::Instant;

/// Frames whose true position is within this of the place (m) belong to a visit.
const VISIT_RADIUS_M: f64 = 14.0;

fn ape_mm(truth: &[Isometry3<f64>], estimate: &[Isometry3<f64>], frames: &[usize]) -> f64 {
    let pick = |poses: &[Isometry3<f64>]| frames.iter().map(|&k| poses[k]).collect::<Vec<_>>();
    ape_translation_paired(&pick(truth), &pick(estimate)).map_or(f64::NAN, |a| 1000.0 * a.rmse_m)
}

/// Largest frame-to-frame change of the estimate's error against the truth (mm): a jump.
fn largest_jump_mm(truth: &[Isometry3<f64>], estimate: &[Isometry3<f64>]) -> f64 {
    let step = |poses: &[Isometry3<f64>], k: usize| {
        poses[k].translation.vector - poses[k - 1].translation.vector
    };
    (1..truth.len())
        .map(|k| 1000.0 * (step(estimate, k) - step(truth, k)).norm())
        .fold(0.0, f64::max)
}

fn main() {
    let args: Vec<f64> = std::env::args()
        .skip(1)
        .map(|a| a.parse().expect("numbers"))
        .collect();
    let arg = |i: usize, default: f64| args.get(i).copied().unwrap_or(default);
    let (excursion_m, speed_m_s, rays, seed) =
        (arg(0, 100.0), arg(1, 1.5), arg(2, 20000.0), arg(3, 1.0));
    let mut scene = revisit_scene(excursion_m);
    scene.trajectory.speed_m_s = speed_m_s;
    let sensor = Mid360 {
        rays_per_frame: rays as usize,
        max_range_m: 40.0,
        ..Mid360::default()
    };
    let frames = revisit_frames(&scene, sensor.frame_rate_hz);
    let started = Instant::now();
    let data = simulate_scene(
        &scene,
        &SimulationSpec {
            frames,
            seed: seed as u64,
            sensor,
            ..SimulationSpec::default()
        },
    )
    .expect("simulation");
    eprintln!(
        "simulated {frames} frames in {:.1} s",
        started.elapsed().as_secs_f64()
    );
    let truth = &data.ground_truth;
    let initial = drift_poses(truth, OdometryDrift::default(), seed as u64 ^ 0xD81F7);
    let near: Vec<bool> = truth
        .iter()
        .map(|p| p.translation.vector.xy().norm() < VISIT_RADIUS_M)
        .collect();
    let first_far = near.iter().position(|&n| !n).expect("the flight leaves");
    let visit_1: Vec<usize> = (0..first_far).collect();
    let visit_2: Vec<usize> = (first_far..frames).filter(|&k| near[k]).collect();
    let both: Vec<usize> = visit_1.iter().chain(&visit_2).copied().collect();
    let all: Vec<usize> = (0..frames).collect();
    println!(
        "revisit flight: {excursion_m} m out, {speed_m_s} m/s, {frames} frames, {} + {} frames at the place",
        visit_1.len(),
        visit_2.len()
    );
    println!("| | visit 1 | visit 2 | both visits | whole flight | largest jump | wall |");
    println!("|---|---|---|---|---|---|---|");
    let row = |name: &str, estimate: &[Isometry3<f64>], seconds: f64| {
        println!(
            "| {name} | {:.1} mm | {:.1} mm | {:.1} mm | {:.1} mm | {:.1} mm | {seconds:.1} s |",
            ape_mm(truth, estimate, &visit_1),
            ape_mm(truth, estimate, &visit_2),
            ape_mm(truth, estimate, &both),
            ape_mm(truth, estimate, &all),
            largest_jump_mm(truth, estimate),
        );
    };
    row("initial (drift)", &initial, 0.0);
    let config = PssBaConfig::default();
    let spec = WindowSpec {
        window_frames: 100,
        window_stride: 80,
    };
    let plain = FlightSettings {
        enabled: false,
        motion_prior: MotionPrior::default(),
        ..FlightSettings::default()
    };
    // PSSBA_MOTION_PRIOR="M,RAD" overrides the motion prior's sigmas (experiments).
    let motion_prior = std::env::var("PSSBA_MOTION_PRIOR").ok().map_or(
        FlightSettings::default().motion_prior,
        |v| {
            let s: Vec<f64> = v.split(',').map(|x| x.parse().expect("M,RAD")).collect();
            MotionPrior {
                translation_m: s[0],
                rotation_rad: s[1],
            }
        },
    );
    let motion_only = FlightSettings {
        enabled: false,
        motion_prior,
        ..FlightSettings::default()
    };
    let whole = FlightSettings {
        motion_prior,
        ..FlightSettings::default()
    };
    for (name, settings) in [
        ("sliding windows", plain),
        ("sliding windows + motion prior", motion_only),
        ("whole flight", whole),
    ] {
        let started = Instant::now();
        let result = adjust_flight(
            &data.frames,
            &initial,
            &config,
            spec,
            settings,
            Parallelism::Rayon,
        )
        .expect("adjust");
        let seconds = started.elapsed().as_secs_f64();
        row(name, &result.world_from_lidar, seconds);
        for c in &result.closures {
            eprintln!(
                "  window {}: {} old / {} new keyframes, overlap {:.2}, drift {:.3} m (max {:.3}, spread {:.3}), {} moved, align {:.2} s, graph {:.3} s, cost {:.3e} -> {:.3e} in {} its",
                c.window,
                c.old_keyframes.len(),
                c.new_keyframes.len(),
                c.overlap,
                c.mean_correction_m,
                c.max_correction_m,
                c.spread_m,
                c.moved.len(),
                c.align_s,
                c.graph_s,
                c.graph.initial_cost,
                c.graph.final_cost,
                c.graph.iterations
            );
        }
        eprintln!(
            "  keyframes {:?}, failures {:?}",
            result.keyframes, result.failures
        );
        let jumps: Vec<(usize, f64)> = (1..frames)
            .map(|k| {
                (
                    k,
                    largest_jump_mm(&truth[k - 1..=k], &result.world_from_lidar[k - 1..=k]),
                )
            })
            .filter(|j| j.1 > 50.0)
            .collect();
        eprintln!("  jumps over 50 mm: {jumps:?}");
    }
}
