//! Frames taken while the sensor moves (issue 39): point times are checked; frames whose
//! points all carry time 0 give exactly the poses of frames without times; a helmet flight
//! whose head turns at up to 120 deg/s, simulated with every ray from the pose at its own
//! time, comes out much closer to the truth with its times than without.

use nalgebra::{Isometry3, Point3};
use pssba_core::{
    AdjustResult, CoreError, Parallelism, PointTimes, PssBaConfig, Window, adjust_window,
    deskew_frames,
};
use pssba_sim::{BuiltinScene, Mid360, SimulatedDataset, SimulationSpec, simulate_scene};

/// The curved scene's orbit at `speed_m_s`, the head turning by `yaw_sway_rad` at 0.6 Hz:
/// 30 frames of 5000 rays.
fn flight(speed_m_s: f64, yaw_sway_rad: f64, moving: bool) -> SimulatedDataset {
    let mut scene = BuiltinScene::Curved.build();
    scene.trajectory.speed_m_s = speed_m_s;
    scene.trajectory.yaw_sway_rad = yaw_sway_rad;
    scene.trajectory.yaw_sway_hz = 0.6;
    simulate_scene(
        &scene,
        &SimulationSpec {
            frames: 30,
            seed: 3,
            sensor: Mid360 {
                rays_per_frame: 5000,
                ..Mid360::default()
            },
            motion_within_frames: moving,
            ..SimulationSpec::default()
        },
    )
    .expect("simulation")
}

fn run(
    data: &SimulatedDataset,
    frames: &[Vec<Point3<f64>>],
    times: Option<PointTimes<'_>>,
) -> Result<AdjustResult, CoreError> {
    // The gauge, frame 0, at its true pose: errors at the stamps need no alignment (which
    // would hide a time shift: on an orbit it is a rotation about the centre).
    let mut initial = data.initial.clone();
    initial[0] = data.ground_truth[0];
    adjust_window(
        Window {
            frames,
            world_from_lidar: &initial,
            fixed: None,
            times,
        },
        &PssBaConfig::default(),
        Parallelism::Rayon,
    )
}

/// RMS translation error at the stamps (mm), no alignment.
fn error_mm(truth: &[Isometry3<f64>], estimate: &[Isometry3<f64>]) -> f64 {
    let sum: f64 = truth
        .iter()
        .zip(estimate)
        .map(|(t, e)| (t.translation.vector - e.translation.vector).norm_squared())
        .sum();
    1000.0 * (sum / truth.len() as f64).sqrt()
}

#[test]
fn zero_times_give_exactly_the_poses_without_times() {
    let data = flight(1.5, 0.0, false);
    let zeros: Vec<Vec<f32>> = data.frames.iter().map(|f| vec![0.0; f.len()]).collect();
    let times = PointTimes {
        stamps_s: &data.stamps,
        offsets_s: &zeros,
    };
    let without = run(&data, &data.frames, None).expect("without times");
    let with = run(&data, &data.frames, Some(times)).expect("with times");
    assert_eq!(without.world_from_lidar, with.world_from_lidar);
    assert_eq!(without.scales.len(), with.scales.len());
}

#[test]
fn bad_point_times_are_refused_with_the_frame() {
    let data = flight(1.5, 0.0, false);
    let mut offsets: Vec<Vec<f32>> = data.frames.iter().map(|f| vec![0.0; f.len()]).collect();
    offsets[4][7] = f32::NAN;
    let times = PointTimes {
        stamps_s: &data.stamps,
        offsets_s: &offsets,
    };
    assert_eq!(
        run(&data, &data.frames, Some(times)).err(),
        Some(CoreError::NonFinitePointTime { frame: 4 })
    );
    offsets[4].pop();
    let times = PointTimes {
        stamps_s: &data.stamps,
        offsets_s: &offsets,
    };
    assert!(matches!(
        run(&data, &data.frames, Some(times)),
        Err(CoreError::PointTimesCount { frame: 4, .. })
    ));
    let times = PointTimes {
        stamps_s: &data.stamps[1..],
        offsets_s: &offsets,
    };
    assert!(matches!(
        run(&data, &data.frames, Some(times)),
        Err(CoreError::PointTimesFrames { .. })
    ));
}

#[test]
fn a_turning_head_comes_out_sharp_with_its_point_times() {
    let moving = flight(1.2, 0.55, true);
    let offsets = moving.point_times_s.as_ref().expect("times");
    let span_s = offsets.iter().flatten().fold(0.0f32, |m, &t| m.max(t));
    assert!(
        (0.09..0.1).contains(&span_s),
        "a 10 Hz frame spans 0.1 s: {span_s}"
    );
    let times = PointTimes {
        stamps_s: &moving.stamps,
        offsets_s: offsets,
    };
    let still = flight(1.2, 0.55, false);
    let deskewed = deskew_frames(&moving.frames, times, &moving.ground_truth).expect("deskew");
    let once = run(&moving, &deskewed, None).expect("de-skewed once");
    let ignored = run(&moving, &moving.frames, None).expect("times ignored");
    let with = run(&moving, &moving.frames, Some(times)).expect("with times");
    let still_result = run(&still, &still.frames, None).expect("still");
    let (once_mm, ignored_mm, with_mm, still_mm) = (
        error_mm(&moving.ground_truth, &once.world_from_lidar),
        error_mm(&moving.ground_truth, &ignored.world_from_lidar),
        error_mm(&moving.ground_truth, &with.world_from_lidar),
        error_mm(&still.ground_truth, &still_result.world_from_lidar),
    );
    eprintln!(
        "helmet: still {still_mm:.2} mm, times ignored {ignored_mm:.2} mm, de-skewed along the \
         truth {once_mm:.2} mm, with times {with_mm:.2} mm"
    );
    // Measured: still 1.7, times ignored 261, along the truth 6.3, with times 5.6 mm (before
    // the SE(3) twist and the change of rate: 5.8 and 11.5). Neither reaches the still
    // frames: a head turning at 0.6 Hz changes its acceleration within a frame too, which
    // rates read from the poses 0.1 s apart do not follow (issue 39 stays open on this).
    assert!(once_mm < 0.05 * ignored_mm, "{once_mm} vs {ignored_mm}");
    assert!(with_mm < 0.1 * ignored_mm, "{with_mm} vs {ignored_mm}");
    assert!(still_mm < once_mm, "{still_mm} vs {once_mm}");
}

/// The whole-flight pipeline (sliding windows) carries the times too: zero times give its
/// poses without times exactly, and the helmet's windows come out far closer to the truth
/// with their times than without.
#[test]
fn sliding_windows_deskew_with_their_point_times() {
    use pssba_core::{FlightSettings, WindowSpec, adjust_flight};
    let moving = flight(1.2, 0.55, true);
    let offsets = moving.point_times_s.as_ref().expect("times");
    let mut initial = moving.initial.clone();
    initial[0] = moving.ground_truth[0];
    let spec = WindowSpec {
        window_frames: 16,
        window_stride: 12,
    };
    let config = PssBaConfig::default();
    let fly = |times: Option<PointTimes<'_>>| {
        adjust_flight(
            &moving.frames,
            &initial,
            times,
            &config,
            spec,
            FlightSettings::default(),
            Parallelism::Rayon,
        )
        .expect("flight")
        .world_from_lidar
    };
    let zeros: Vec<Vec<f32>> = offsets.iter().map(|t| vec![0.0; t.len()]).collect();
    let index_stamps: Vec<f64> = (0..moving.frames.len()).map(|k| k as f64).collect();
    let ignored = fly(None);
    let zero = fly(Some(PointTimes {
        stamps_s: &index_stamps,
        offsets_s: &zeros,
    }));
    assert_eq!(zero, ignored, "zero times change nothing");
    let with = fly(Some(PointTimes {
        stamps_s: &moving.stamps,
        offsets_s: offsets,
    }));
    let (ignored_mm, with_mm) = (
        error_mm(&moving.ground_truth, &ignored),
        error_mm(&moving.ground_truth, &with),
    );
    eprintln!("helmet, sliding windows: times ignored {ignored_mm:.2} mm, with {with_mm:.2} mm");
    // Measured: times ignored 274 mm, with times 6.5 mm.
    assert!(with_mm < 0.2 * ignored_mm, "{with_mm} vs {ignored_mm}");
}
