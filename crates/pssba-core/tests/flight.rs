//! The whole flight (issue 38): a flight that leaves a place over open ground and comes back
//! closes its loop (both visits as consistent as each alone, no pose jump); a flight that never
//! comes back gets the sliding windows' poses exactly; with the loop closure and the motion
//! prior off, the flight pipeline is `adjust_sliding`; a closure re-publishes the frames it
//! moved.

use nalgebra::Isometry3;
use pssba_core::{
    FlightSettings, FlightWindows, MotionPrior, Parallelism, PssBaConfig, WindowSpec,
    adjust_flight, adjust_sliding,
};
use pssba_eval::ape_translation_paired;
use pssba_sim::{
    Mid360, OdometryDrift, SimulatedDataset, SimulationSpec, drift_poses, revisit_frames,
    revisit_scene, simulate_scene,
};

/// Frames whose true position is this close to the place (m) are a visit.
const VISIT_RADIUS_M: f64 = 14.0;

struct Flight {
    data: SimulatedDataset,
    initial: Vec<Isometry3<f64>>,
}

/// A CI-sized revisit flight: 60 m out, 3 m/s, 4000 rays of 40 m, twice the default LIO-like
/// drift (the visits end 0.1-0.3 m apart).
fn flight() -> Flight {
    let mut scene = revisit_scene(60.0);
    scene.trajectory.speed_m_s = 3.0;
    let sensor = Mid360 {
        rays_per_frame: 4000,
        max_range_m: 40.0,
        ..Mid360::default()
    };
    let frames = revisit_frames(&scene, sensor.frame_rate_hz);
    let data = simulate_scene(
        &scene,
        &SimulationSpec {
            frames,
            seed: 5,
            sensor,
            ..SimulationSpec::default()
        },
    )
    .expect("simulation");
    let d = OdometryDrift::default();
    let drift = OdometryDrift {
        translation_m: 2.0 * d.translation_m,
        yaw_deg: 2.0 * d.yaw_deg,
        tilt_deg: 2.0 * d.tilt_deg,
    };
    let initial = drift_poses(&data.ground_truth, drift, 11);
    Flight { data, initial }
}

fn spec() -> WindowSpec {
    WindowSpec {
        window_frames: 100,
        window_stride: 80,
    }
}

fn ape_m(truth: &[Isometry3<f64>], estimate: &[Isometry3<f64>], frames: &[usize]) -> f64 {
    let pick = |poses: &[Isometry3<f64>]| frames.iter().map(|&k| poses[k]).collect::<Vec<_>>();
    ape_translation_paired(&pick(truth), &pick(estimate))
        .expect("ape")
        .rmse_m
}

/// Largest frame-to-frame change of the error (m).
fn largest_jump_m(truth: &[Isometry3<f64>], estimate: &[Isometry3<f64>]) -> f64 {
    (1..truth.len())
        .map(|k| {
            let step = |p: &[Isometry3<f64>]| p[k].translation.vector - p[k - 1].translation.vector;
            (step(estimate) - step(truth)).norm()
        })
        .fold(0.0, f64::max)
}

/// The frames of the first and the second visit.
fn visits(truth: &[Isometry3<f64>]) -> (Vec<usize>, Vec<usize>) {
    let near: Vec<bool> = truth
        .iter()
        .map(|p| p.translation.vector.xy().norm() < VISIT_RADIUS_M)
        .collect();
    let first_far = near.iter().position(|&n| !n).expect("the flight leaves");
    let second = (first_far..truth.len()).filter(|&k| near[k]).collect();
    ((0..first_far).collect(), second)
}

#[test]
fn a_revisit_flight_closes_its_loop() {
    let Flight { data, initial } = flight();
    let truth = &data.ground_truth;
    let config = PssBaConfig::default();
    let run = |settings| {
        adjust_flight(
            &data.frames,
            &initial,
            None,
            &config,
            spec(),
            settings,
            Parallelism::Rayon,
        )
        .expect("adjust")
    };
    let windows_only = run(FlightSettings {
        enabled: false,
        ..FlightSettings::default()
    });
    let whole = run(FlightSettings::default());
    let (first, second) = visits(truth);
    let both: Vec<usize> = first.iter().chain(&second).copied().collect();
    let each_m = ape_m(truth, &whole.world_from_lidar, &first).max(ape_m(
        truth,
        &whole.world_from_lidar,
        &second,
    ));
    let both_m = ape_m(truth, &whole.world_from_lidar, &both);
    let open_m = ape_m(truth, &windows_only.world_from_lidar, &both);
    assert!(!whole.closures.is_empty(), "no loop closed");
    // The global pass ran over every keyframe after the last window and moved frames.
    let global = whole
        .global_pass
        .as_ref()
        .expect("a flight that closed a loop");
    assert_eq!(global.keyframes, whole.keyframes.0);
    assert!(!global.moved.is_empty());
    assert!(windows_only.global_pass.is_none());
    assert!(windows_only.closures.is_empty());
    // Without the loop closure the two visits are two maps, with it one.
    assert!(
        open_m > 0.05,
        "the drift should separate the visits: {open_m} m"
    );
    assert!(
        both_m < 2.0 * each_m,
        "both visits {both_m} m, each {each_m} m"
    );
    assert!(both_m < 0.02, "both visits {both_m} m");
    // No jump where the loop closed: the correction is spread.
    let jump_m = largest_jump_m(truth, &whole.world_from_lidar);
    assert!(
        jump_m < 0.05,
        "largest frame-to-frame error change {jump_m} m"
    );
    let all: Vec<usize> = (0..truth.len()).collect();
    assert!(
        ape_m(truth, &whole.world_from_lidar, &all)
            < 0.5 * ape_m(truth, &windows_only.world_from_lidar, &all)
    );
}

#[test]
fn a_flight_that_never_comes_back_keeps_the_sliding_windows_poses() {
    let Flight { data, initial } = flight();
    // Out and not back: the first visit and the way out.
    let frames = 300;
    let config = PssBaConfig::default();
    let run = |enabled| {
        let settings = FlightSettings {
            enabled,
            ..FlightSettings::default()
        };
        adjust_flight(
            &data.frames[..frames],
            &initial[..frames],
            None,
            &config,
            spec(),
            settings,
            Parallelism::Rayon,
        )
        .expect("adjust")
    };
    let (with_closure, without) = (run(true), run(false));
    assert!(with_closure.closures.is_empty());
    assert!(with_closure.global_pass.is_none());
    assert!(with_closure.keyframes.0 > 10);
    assert_eq!(with_closure.world_from_lidar, without.world_from_lidar);
}

#[test]
fn with_everything_off_the_flight_is_adjust_sliding() {
    let Flight { data, initial } = flight();
    let frames = 180;
    let config = PssBaConfig {
        max_scales: 3,
        ..PssBaConfig::default()
    };
    let off = FlightSettings {
        enabled: false,
        motion_prior: MotionPrior::default(),
        ..FlightSettings::default()
    };
    let (frames, initial) = (&data.frames[..frames], &initial[..frames]);
    let flight = adjust_flight(
        frames,
        initial,
        None,
        &config,
        spec(),
        off,
        Parallelism::Serial,
    )
    .expect("flight");
    let sliding =
        adjust_sliding(frames, initial, &config, spec(), Parallelism::Serial).expect("sliding");
    assert_eq!(flight.world_from_lidar, sliding.world_from_lidar);
}

#[test]
fn a_closure_republishes_the_frames_it_moved() {
    let Flight { data, initial } = flight();
    let config = PssBaConfig::default();
    let mut flight = FlightWindows::new(spec(), FlightSettings::default()).expect("flight");
    for (k, (points, pose)) in data.frames.iter().zip(&initial).enumerate() {
        flight
            .push_frame(k as f64 * 0.1, points.clone(), *pose)
            .expect("push");
    }
    flight.end_stream();
    let mut published: Vec<Option<Isometry3<f64>>> = vec![None; data.frames.len()];
    let mut revisions = 0;
    while let Some(step) = flight.run_next_local(&config, Parallelism::Rayon) {
        for fin in &step.outcome.finals {
            assert!(
                published[fin.sequence].is_none(),
                "frame {} twice",
                fin.sequence
            );
            published[fin.sequence] = Some(fin.world_from_lidar);
        }
        if step.closure.is_some() || step.global_pass.is_some() {
            assert!(!step.revised.is_empty());
        }
        for fin in &step.revised {
            assert!(published[fin.sequence].is_some(), "revised before final");
            assert!((fin.stamp_s - fin.sequence as f64 * 0.1).abs() < 1e-12);
            published[fin.sequence] = Some(fin.world_from_lidar);
            revisions += 1;
        }
    }
    assert!(revisions > 0);
    // What a subscriber holds after the last revision is the flight's final trajectory.
    let finals: Vec<_> = flight.windows().final_poses();
    assert_eq!(published, finals);
}
