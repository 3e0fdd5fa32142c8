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
//! `PSSBA_ONE_WINDOW=1` adds one window of all frames. `PSSBA_MINUTES=60` flies the flight on
//! for an hour instead (the survey's rows over and over), streamed frame by frame into the
//! whole-flight pipeline alone, and reports memory and time per frame every 5 minutes.

use nalgebra::Isometry3;
use pssba_core::{
    FlightSettings, FlightWindows, GlobalPass, MotionPrior, Parallelism, PssBaConfig, WindowSpec,
    adjust_flight,
};
use pssba_eval::ape_translation_paired;
use pssba_sim::{
    Mid360, OdometryDrift, SURVEY_ROW_SPACING_M, SURVEY_ROWS, Scene, SceneScanner, SimulationSpec,
    drift_poses, revisit_frames, revisit_scene, simulate_scene, survey_frames, survey_scene,
};
use std::time::Instant;

/// Frames whose true position is within this of the place (m) belong to a revisit-flight visit.
const VISIT_RADIUS_M: f64 = 14.0;

fn ape_mm(truth: &[Isometry3<f64>], estimate: &[Isometry3<f64>], frames: &[usize]) -> f64 {
    let pick = |poses: &[Isometry3<f64>]| frames.iter().map(|&k| poses[k]).collect::<Vec<_>>();
    ape_translation_paired(&pick(truth), &pick(estimate)).map_or(f64::NAN, |a| 1000.0 * a.rmse_m)
}

/// From the truth, the places seen again: each a list of visits, each a list of frames.
type Places = Box<dyn Fn(&[Isometry3<f64>]) -> Vec<Vec<Vec<usize>>>>;

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
fn flight(name: &str, speed_m_s: f64, excursion_m: f64) -> (Scene, usize, Places) {
    if name == "survey" {
        let scene = survey_scene(speed_m_s);
        let frames = survey_frames(&scene, 10.0);
        let t = &scene.trajectory;
        let y0 = t.centre.y - 0.5 * (SURVEY_ROWS - 1) as f64 * SURVEY_ROW_SPACING_M;
        let places = move |truth: &[Isometry3<f64>]| {
            let labels: Vec<Option<usize>> = truth
                .iter()
                .map(|p| {
                    let row = ((p.translation.y - y0) / SURVEY_ROW_SPACING_M).round();
                    let off = (p.translation.y - (y0 + row * SURVEY_ROW_SPACING_M)).abs();
                    (off < 0.01 && (0.0..SURVEY_ROWS as f64).contains(&row)).then_some(row as usize)
                })
                .collect();
            let mut by_row: Vec<Vec<Vec<usize>>> = vec![Vec::new(); SURVEY_ROWS];
            for (row, frames) in runs(&labels) {
                by_row[row].push(frames);
            }
            by_row.retain(|visits| visits.len() > 1);
            by_row
        };
        return (scene, frames, Box::new(places));
    }
    let mut scene = revisit_scene(excursion_m);
    scene.trajectory.speed_m_s = speed_m_s;
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

/// Resident and peak resident memory of this process (MB), from `/proc/self/status`.
fn memory_mb() -> (f64, f64) {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let field = |name: &str| {
        status
            .lines()
            .find_map(|l| l.strip_prefix(name))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<f64>().ok())
            .map_or(f64::NAN, |kb| kb / 1024.0)
    };
    (field("VmRSS:"), field("VmHWM:"))
}

/// `PSSBA_MINUTES=M`: the flight flown on for M minutes (the survey's rows over and over),
/// streamed into `FlightWindows` as a sensor would give it: each frame simulated when the
/// next window needs it, nothing kept but what the pipeline keeps. Every 5 minutes of flight:
/// the adjustment's time per frame, the process's memory, the keyframes held.
fn long_flight(scene: &Scene, spec: &SimulationSpec, places: Places) {
    const REPORT_FRAMES: usize = 3000;
    let rate_hz = spec.sensor.frame_rate_hz;
    let truth = scene.trajectory.world_from_lidar(spec.frames, rate_hz);
    let initial = drift_poses(&truth, OdometryDrift::default(), spec.seed ^ 0xD81F7);
    let scanner = SceneScanner::new(scene, spec).expect("scanner");
    let windows = WindowSpec {
        window_frames: 100,
        window_stride: 80,
    };
    let mut flight = FlightWindows::new(windows, flight_defaults()).expect("flight");
    let config = PssBaConfig::default();
    println!(
        "{} flight streamed: {} frames ({:.0} min), {} rays",
        scene.name,
        spec.frames,
        spec.frames as f64 / rate_hz / 60.0,
        spec.sensor.rays_per_frame
    );
    println!(
        "| flight min | frames final | adjust ms/frame (these 5 min) | RSS MB | peak RSS MB | keyframes | with clouds | cloud points | closures (these 5 min) | closures' align / graph s (these 5 min) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    let (mut next, mut report_at) = (0, REPORT_FRAMES);
    let (mut adjust_s, mut simulate_s, mut closures) = (0.0, 0.0, 0);
    let (mut align_s, mut graph_s) = (0.0, 0.0);
    let mut reported_final = 0;
    let started = Instant::now();
    loop {
        if flight.windows().next_plan().is_none() {
            if next == truth.len() {
                break;
            }
            let t = Instant::now();
            let points = scanner.frame(next, &truth[next]);
            simulate_s += t.elapsed().as_secs_f64();
            flight
                .push_frame(next as f64 / rate_hz, points, initial[next])
                .expect("frame");
            next += 1;
            if next == truth.len() {
                flight.end_stream();
            }
            continue;
        }
        let t = Instant::now();
        let step = flight
            .run_next_local(&config, Parallelism::Rayon)
            .expect("a window is ready");
        adjust_s += t.elapsed().as_secs_f64();
        closures += usize::from(step.closure.is_some());
        if let Some(c) = &step.closure {
            (align_s, graph_s) = (align_s + c.align_s, graph_s + c.graph_s);
        }
        if let Some(g) = &step.global_pass {
            print_global_pass("", g);
        }
        let finalised = flight.windows().finalised();
        if finalised >= report_at || flight.windows().is_done() {
            let (rss, peak) = memory_mb();
            let keyframes = flight.keyframes();
            println!(
                "| {:.0} | {finalised} | {:.1} | {rss:.0} | {peak:.0} | {} | {} | {} | {closures} | {align_s:.1} / {graph_s:.1} |",
                finalised as f64 / rate_hz / 60.0,
                1000.0 * adjust_s / (finalised - reported_final) as f64,
                keyframes.len(),
                keyframes.iter().filter(|k| !k.points.is_empty()).count(),
                keyframes.iter().map(|k| k.points.len()).sum::<usize>(),
            );
            (adjust_s, closures, reported_final) = (0.0, 0, finalised);
            (align_s, graph_s) = (0.0, 0.0);
            report_at += REPORT_FRAMES;
        }
    }
    eprintln!(
        "wall {:.0} s, of which simulating the frames {simulate_s:.0} s",
        started.elapsed().as_secs_f64()
    );
    let estimate: Vec<Isometry3<f64>> = flight
        .windows()
        .final_poses()
        .into_iter()
        .map(|p| p.expect("every frame is final"))
        .collect();
    let places = places(&truth);
    report_header(&places);
    report_row("initial (drift)", &truth, &places, &initial, 0.0);
    report_row(
        "whole flight",
        &truth,
        &places,
        &estimate,
        started.elapsed().as_secs_f64(),
    );
}

/// The table's header, with the visits of each place.
fn report_header(places: &[Vec<Vec<usize>>]) {
    let visits: Vec<String> = places.iter().map(|p| p.len().to_string()).collect();
    println!(
        "places seen again: {} (visits: {})",
        places.len(),
        visits.join(", ")
    );
    println!(
        "| | each visit alone (worst) | all visits together (worst place) | whole flight | largest jump | wall |"
    );
    println!("|---|---|---|---|---|---|");
}

/// One row of the table: APE of each visit alone, all visits of each place together and the
/// whole flight, the largest jump and the wall time.
fn report_row(
    label: &str,
    truth: &[Isometry3<f64>],
    places: &[Vec<Vec<usize>>],
    estimate: &[Isometry3<f64>],
    seconds: f64,
) {
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
}

/// `FlightSettings::default()` with `PSSBA_FLIGHT="field=value,..."` applied (fields:
/// revisit_radius_m, revisit_min_overlap, overlap_voxel_m, max_alignment_spread_m).
fn flight_defaults() -> FlightSettings {
    let mut s = FlightSettings::default();
    let Ok(overrides) = std::env::var("PSSBA_FLIGHT") else {
        return s;
    };
    for pair in overrides.split(',').filter(|p| !p.is_empty()) {
        let (field, value) = pair.split_once('=').expect("PSSBA_FLIGHT: field=value");
        let value: f64 = value.parse().expect("PSSBA_FLIGHT: a number");
        match field {
            "revisit_radius_m" => s.revisit_radius_m = value,
            "revisit_min_overlap" => s.revisit_min_overlap = value,
            "overlap_voxel_m" => s.overlap_voxel_m = value,
            "max_alignment_spread_m" => s.max_alignment_spread_m = value,
            other => panic!("PSSBA_FLIGHT: unknown field {other}"),
        }
    }
    s
}

/// One line on stderr for the global pass.
fn print_global_pass(indent: &str, g: &GlobalPass) {
    eprintln!(
        "{indent}global pass: {} keyframes, {} loop edges, {} frames moved, cost {:.3e} -> {:.3e} in {} its, {:.3} s",
        g.keyframes,
        g.loop_edges,
        g.moved.len(),
        g.graph.initial_cost,
        g.graph.final_cost,
        g.graph.iterations,
        g.seconds
    );
}

fn main() {
    // RUST_LOG=info shows each closure; warn (the default) the refused ones.
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        .init();
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
    let minutes: Option<f64> = std::env::var("PSSBA_MINUTES")
        .ok()
        .map(|m| m.parse().expect("PSSBA_MINUTES: a number of minutes"));
    let frames = minutes.map_or(frames, |m| (m * 600.0).round() as usize);
    let started = Instant::now();
    let spec = SimulationSpec {
        frames,
        seed: seed as u64,
        sensor,
        ..SimulationSpec::default()
    };
    if minutes.is_some() {
        long_flight(&scene, &spec, places);
        return;
    }
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
    report_header(&places);
    let row = |label: &str, estimate: &[Isometry3<f64>], seconds: f64| {
        report_row(label, truth, &places, estimate, seconds)
    };
    row("initial (drift)", &initial, 0.0);
    let config = PssBaConfig::default();
    let windows = WindowSpec {
        window_frames: 100,
        window_stride: 80,
    };
    let motion_prior =
        std::env::var("PSSBA_MOTION_PRIOR")
            .ok()
            .map_or(flight_defaults().motion_prior, |v| {
                let s: Vec<f64> = v.split(',').map(|x| x.parse().expect("M,RAD")).collect();
                MotionPrior {
                    translation_m: s[0],
                    rotation_rad: s[1],
                }
            });
    let plain = FlightSettings {
        enabled: false,
        motion_prior: MotionPrior::default(),
        ..flight_defaults()
    };
    let motion_only = FlightSettings {
        enabled: false,
        motion_prior,
        ..flight_defaults()
    };
    let whole = FlightSettings {
        motion_prior,
        ..flight_defaults()
    };
    let without_global = FlightSettings {
        global_pass: false,
        ..whole
    };
    for (label, settings) in [
        ("sliding windows", plain),
        ("sliding windows + motion prior", motion_only),
        ("whole flight without the global pass", without_global),
        ("whole flight", whole),
    ] {
        let started = Instant::now();
        let result = adjust_flight(
            &data.frames,
            &initial,
            None,
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
        if let Some(g) = &result.global_pass {
            print_global_pass("  ", g);
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
