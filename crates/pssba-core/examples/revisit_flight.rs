//! Flights that come back to places they saw (issue 38's targets, measured), adjusted in plain
//! sliding windows, with the motion prior alone, and in the whole-flight pipeline; prints, per
//! place, the APE of each visit alone and of all visits together, the whole flight's APE, the
//! largest frame-to-frame jump of the error and the wall time.
//!
//! `cargo run --release -p pssba-core --example revisit_flight -- FLIGHT [SPEED_M_S] [RAYS]
//! [SEED] [EXCURSION_M]`:
//! - `revisit` (default): pssba-sim's revisit scene, around the place, `EXCURSION_M` (100 m)
//!   out over open ground and back, around the place again; 1.5 m/s.
//! - `survey`: a lawnmower over the same scene, four 80 m rows 10 m apart south of the place,
//!   flown there and back (rows 0-2 twice); 3 m/s.
//!
//! Initial poses: LIO-like drift (`pssba_sim::OdometryDrift::default()`). 20000 rays of 40 m
//! by default. `PSSBA_MOTION_PRIOR="M,RAD"` overrides the motion prior's sigmas;
//! `PSSBA_ONE_WINDOW=1` adds one window of all frames.

use nalgebra::{Isometry3, Point3};
use pssba_core::{
    FlightSettings, MotionPrior, Parallelism, PssBaConfig, WindowSpec, adjust_flight,
};
use pssba_eval::ape_translation_paired;
use pssba_sim::{
    Mid360, OdometryDrift, Scene, SimulationSpec, TrajectoryKind, drift_poses, revisit_frames,
    revisit_scene, simulate_scene,
};
use std::time::Instant;

/// Frames whose true position is within this of the place (m) belong to a revisit-flight visit.
const VISIT_RADIUS_M: f64 = 14.0;
/// Survey rows: count, spacing (m), half length (m), centre.
const ROWS: usize = 4;
const ROW_SPACING_M: f64 = 10.0;

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

/// Consecutive runs of frames for which `label` gives the same `Some`.
fn runs(labels: &[Option<usize>]) -> Vec<(usize, Vec<usize>)> {
    let mut out: Vec<(usize, Vec<usize>)> = Vec::new();
    for (k, label) in labels.iter().enumerate() {
        let Some(l) = *label else { continue };
        match out.last_mut() {
            Some((last, frames)) if *last == l && frames.last() == Some(&(k - 1)) => frames.push(k),
            _ => out.push((l, vec![k])),
        }
    }
    out
}

/// The scene, its frame count and, from the truth, the places: each a list of visits.
fn flight(
    name: &str,
    speed_m_s: f64,
    excursion_m: f64,
) -> (
    Scene,
    usize,
    Box<dyn Fn(&[Isometry3<f64>]) -> Vec<Vec<Vec<usize>>>>,
) {
    let mut scene = revisit_scene(excursion_m);
    scene.trajectory.speed_m_s = speed_m_s;
    if name == "survey" {
        let t = &mut scene.trajectory;
        t.kind = TrajectoryKind::Lawnmower;
        t.centre = Point3::new(20.0, -24.0, t.centre.z);
        t.radius_m = 40.0;
        t.lane_spacing_m = ROW_SPACING_M;
        t.lanes = ROWS;
        t.start_along_m = 0.0;
        let legs = 2 * ROWS - 1;
        let leg_m = 2.0 * t.radius_m + std::f64::consts::PI * 0.5 * ROW_SPACING_M;
        let frames =
            (legs as f64 * leg_m - std::f64::consts::PI * 0.5 * ROW_SPACING_M) / speed_m_s * 10.0;
        let y0 = t.centre.y - 0.5 * (ROWS - 1) as f64 * ROW_SPACING_M;
        let places = move |truth: &[Isometry3<f64>]| {
            let labels: Vec<Option<usize>> = truth
                .iter()
                .map(|p| {
                    let row = ((p.translation.y - y0) / ROW_SPACING_M).round();
                    let off = (p.translation.y - (y0 + row * ROW_SPACING_M)).abs();
                    (off < 0.01 && (0.0..ROWS as f64).contains(&row)).then_some(row as usize)
                })
                .collect();
            let mut by_row: Vec<Vec<Vec<usize>>> = vec![Vec::new(); ROWS];
            for (row, frames) in runs(&labels) {
                by_row[row].push(frames);
            }
            by_row.retain(|visits| visits.len() > 1);
            by_row
        };
        return (scene, frames.floor() as usize, Box::new(places));
    }
    let frames = revisit_frames(&scene, 10.0);
    let places = |truth: &[Isometry3<f64>]| {
        let labels: Vec<Option<usize>> = truth
            .iter()
            .map(|p| (p.translation.vector.xy().norm() < VISIT_RADIUS_M).then_some(0))
            .collect();
        vec![runs(&labels).into_iter().map(|(_, f)| f).collect()]
    };
    (scene, frames, Box::new(places))
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let name = args.first().map_or("revisit", String::as_str);
    let number = |i: usize, default: f64| {
        args.get(i)
            .map_or(default, |a| a.parse().expect("a number"))
    };
    let survey = name == "survey";
    let speed_m_s = number(1, if survey { 3.0 } else { 1.5 });
    let (rays, seed, excursion_m) = (number(2, 20000.0), number(3, 1.0), number(4, 100.0));
    let (scene, frames, places) = flight(name, speed_m_s, excursion_m);
    let sensor = Mid360 {
        rays_per_frame: rays as usize,
        max_range_m: 40.0,
        ..Mid360::default()
    };
    let started = Instant::now();
    let spec = SimulationSpec {
        frames,
        seed: seed as u64,
        sensor,
        ..SimulationSpec::default()
    };
    let data = simulate_scene(&scene, &spec).expect("simulation");
    eprintln!(
        "simulated {frames} frames in {:.1} s",
        started.elapsed().as_secs_f64()
    );
    let truth = &data.ground_truth;
    let initial = drift_poses(truth, OdometryDrift::default(), seed as u64 ^ 0xD81F7);
    let places = places(truth);
    let visits: Vec<String> = places
        .iter()
        .map(|p| {
            p.iter()
                .map(|v| v.len().to_string())
                .collect::<Vec<_>>()
                .join("+")
        })
        .collect();
    println!(
        "{name} flight: {speed_m_s} m/s, {frames} frames, seed {seed}, {} places seen again (frames per visit: {})",
        places.len(),
        visits.join(", ")
    );
    println!(
        "| | each visit alone (worst) | all visits together (worst place) | whole flight | largest jump | wall |"
    );
    println!("|---|---|---|---|---|---|");
    let row = |label: &str, estimate: &[Isometry3<f64>], seconds: f64| {
        let each = places
            .iter()
            .flat_map(|p| p.iter().map(|v| ape_mm(truth, estimate, v)))
            .fold(0.0, f64::max);
        let together = places
            .iter()
            .map(|p| ape_mm(truth, estimate, &p.concat()))
            .fold(0.0, f64::max);
        let all: Vec<usize> = (0..truth.len()).collect();
        println!(
            "| {label} | {each:.1} mm | {together:.1} mm | {:.1} mm | {:.1} mm | {seconds:.1} s |",
            ape_mm(truth, estimate, &all),
            largest_jump_mm(truth, estimate),
        );
    };
    row("initial (drift)", &initial, 0.0);
    let config = PssBaConfig::default();
    let windows = WindowSpec {
        window_frames: 100,
        window_stride: 80,
    };
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
    let plain = FlightSettings {
        enabled: false,
        motion_prior: MotionPrior::default(),
        ..FlightSettings::default()
    };
    let motion_only = FlightSettings {
        enabled: false,
        motion_prior,
        ..FlightSettings::default()
    };
    let whole = FlightSettings {
        motion_prior,
        ..FlightSettings::default()
    };
    for (label, settings) in [
        ("sliding windows", plain),
        ("sliding windows + motion prior", motion_only),
        ("whole flight", whole),
    ] {
        let started = Instant::now();
        let result = adjust_flight(
            &data.frames,
            &initial,
            &config,
            windows,
            settings,
            Parallelism::Rayon,
        )
        .expect("adjust");
        let seconds = started.elapsed().as_secs_f64();
        row(label, &result.world_from_lidar, seconds);
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
            "  keyframes {:?}, failures {}",
            result.keyframes,
            result.failures.len()
        );
    }
    // PSSBA_ONE_WINDOW=1: also one window of all frames (the paper's setting; slow).
    if std::env::var("PSSBA_ONE_WINDOW").is_ok_and(|v| v == "1") {
        let started = Instant::now();
        let result = pssba_core::adjust(&data.frames, &initial, &config).expect("one window");
        let seconds = started.elapsed().as_secs_f64();
        row(
            "one window of all frames",
            &result.world_from_lidar,
            seconds,
        );
    }
}
