//! Frames taken while the sensor moves (issue 39's targets, measured): each flight simulated
//! twice from the same seed, with still frames (every ray from the frame's pose) and with
//! every ray from the true pose at its own time, then adjusted from the same initial poses:
//! - still frames (the reference),
//! - moving frames, times ignored (what the adjuster did before),
//! - moving frames de-skewed once from the initial poses, then adjusted as still frames,
//! - moving frames with their times: every scale de-skews along its current poses.
//!
//! APE (SE(3)-aligned, as everywhere in the bench) and the error at the stamps without any
//! alignment (the gauge frame 0 starts at its true pose): on an orbit a time shift of the
//! whole trajectory is a rotation about its centre, which the alignment removes. Against the
//! true pose at each frame's stamp (its first ray); wall time of the adjustment.
//!
//! `cargo run --release -p pssba-core --example moving_frames -- [SCENE] [FRAMES] [RAYS] [SEED]`
//! (defaults: curved 100 20000 1). Flights: a UAV along the scene's orbit at 1.5, 3 and 5 m/s,
//! and a helmet at 1.2 m/s whose wearer turns the head (yaw +-0.55 rad at 0.6 Hz, up to 119
//! deg/s).

use nalgebra::Isometry3;
use pssba_core::{Parallelism, PointTimes, PssBaConfig, Window, adjust_window, deskew_frames};
use pssba_eval::ape_translation_paired;
use pssba_sim::{BuiltinScene, Mid360, SimulatedDataset, SimulationSpec, simulate_scene};
use std::time::Instant;

/// One flight profile.
struct Flight {
    name: &'static str,
    speed_m_s: f64,
    yaw_sway_rad: f64,
    yaw_sway_hz: f64,
}

const FLIGHTS: [Flight; 4] = [
    Flight {
        name: "UAV 1.5 m/s",
        speed_m_s: 1.5,
        yaw_sway_rad: 0.0,
        yaw_sway_hz: 0.0,
    },
    Flight {
        name: "UAV 3 m/s",
        speed_m_s: 3.0,
        yaw_sway_rad: 0.0,
        yaw_sway_hz: 0.0,
    },
    Flight {
        name: "UAV 5 m/s",
        speed_m_s: 5.0,
        yaw_sway_rad: 0.0,
        yaw_sway_hz: 0.0,
    },
    Flight {
        name: "helmet 1.2 m/s, head turns",
        speed_m_s: 1.2,
        yaw_sway_rad: 0.55,
        yaw_sway_hz: 0.6,
    },
];

fn ape_mm(truth: &[Isometry3<f64>], estimate: &[Isometry3<f64>]) -> f64 {
    ape_translation_paired(truth, estimate).map_or(f64::NAN, |a| 1000.0 * a.rmse_m)
}

/// Median and largest yaw rate between consecutive true poses (deg/s).
fn yaw_rates_deg_s(truth: &[Isometry3<f64>], rate_hz: f64) -> (f64, f64) {
    let mut rates: Vec<f64> = truth
        .windows(2)
        .map(|p| {
            (p[0].rotation.inverse() * p[1].rotation)
                .angle()
                .to_degrees()
                * rate_hz
        })
        .collect();
    rates.sort_by(f64::total_cmp);
    (rates[rates.len() / 2], rates[rates.len() - 1])
}

/// RMS (mm) of the translation error at each frame's stamp, without any alignment: frame 0,
/// the gauge, starts at its true pose.
fn stamp_error_mm(truth: &[Isometry3<f64>], estimate: &[Isometry3<f64>]) -> f64 {
    let sum: f64 = truth
        .iter()
        .zip(estimate)
        .map(|(t, e)| (t.translation.vector - e.translation.vector).norm_squared())
        .sum();
    1000.0 * (sum / truth.len() as f64).sqrt()
}

/// A run's APE (SE(3)-aligned) and error at the stamps (mm), and its wall time (s).
struct Outcome {
    ape_mm: f64,
    stamp_mm: f64,
    seconds: f64,
}

impl std::fmt::Display for Outcome {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:.2} / {:.2} mm", self.ape_mm, self.stamp_mm)
    }
}

/// Adjusts `frames` (with `times` if given) from the dataset's initial poses, frame 0 (the
/// gauge) at its true pose.
fn adjust(
    data: &SimulatedDataset,
    frames: &[Vec<nalgebra::Point3<f64>>],
    times: Option<PointTimes<'_>>,
) -> Outcome {
    let mut initial = data.initial.clone();
    initial[0] = data.ground_truth[0];
    let started = Instant::now();
    let result = adjust_window(
        Window {
            frames,
            world_from_lidar: &initial,
            fixed: None,
            times,
        },
        &PssBaConfig::default(),
        Parallelism::Rayon,
    )
    .expect("adjustment");
    Outcome {
        seconds: started.elapsed().as_secs_f64(),
        ape_mm: ape_mm(&data.ground_truth, &result.world_from_lidar),
        stamp_mm: stamp_error_mm(&data.ground_truth, &result.world_from_lidar),
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let scene_name = args.first().map_or("curved", String::as_str);
    let number = |i: usize, default: u64| {
        args.get(i)
            .map_or(default, |a| a.parse().expect("a whole number"))
    };
    let (frames, rays, seed) = (number(1, 100), number(2, 20000), number(3, 1));
    let base = BuiltinScene::from_name(scene_name)
        .expect("scene: hangar, curved, truss or street")
        .build();
    println!("{scene_name}: {frames} frames of {rays} rays, seed {seed}");
    println!(
        "APE (SE(3)-aligned) / error at the stamps (no alignment; the gauge frame at its true pose)"
    );
    println!(
        "| flight | yaw rate median / max (deg/s) | still frames | moving, times ignored | moving, de-skewed once from the initial poses | moving, de-skewed at every scale | APE x still | wall s (still / every scale) |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for flight in &FLIGHTS {
        let mut scene = base.clone();
        scene.trajectory.speed_m_s = flight.speed_m_s;
        scene.trajectory.yaw_sway_rad = flight.yaw_sway_rad;
        scene.trajectory.yaw_sway_hz = flight.yaw_sway_hz;
        let spec = SimulationSpec {
            frames: frames as usize,
            seed,
            sensor: Mid360 {
                rays_per_frame: rays as usize,
                ..Mid360::default()
            },
            ..SimulationSpec::default()
        };
        let still = simulate_scene(&scene, &spec).expect("still frames");
        let moving = simulate_scene(
            &scene,
            &SimulationSpec {
                motion_within_frames: true,
                ..spec
            },
        )
        .expect("moving frames");
        assert_eq!(still.ground_truth, moving.ground_truth);
        assert_eq!(still.initial, moving.initial);
        let offsets = moving.point_times_s.as_ref().expect("point times");
        let times = PointTimes {
            stamps_s: &moving.stamps,
            offsets_s: offsets,
        };
        let (median, max) = yaw_rates_deg_s(&still.ground_truth, spec.sensor.frame_rate_hz);
        let still_run = adjust(&still, &still.frames, None);
        let ignored = adjust(&moving, &moving.frames, None);
        let once = deskew_frames(&moving.frames, times, &moving.initial).expect("de-skew");
        let once = adjust(&moving, &once, None);
        let every = adjust(&moving, &moving.frames, Some(times));
        println!(
            "| {} | {median:.0} / {max:.0} | {still_run} | {ignored} | {once} | {every} | {:.2} | {:.1} / {:.1} |",
            flight.name,
            every.ape_mm / still_run.ape_mm,
            still_run.seconds,
            every.seconds
        );
    }
}
