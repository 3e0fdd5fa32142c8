//! The sliding-window driver: one window over everything is exactly `adjust_window`; frames
//! arriving one by one give what a whole sequence gives; every frame gets one final pose; a
//! failing window keeps its frames at their corrected initial poses, is recorded, and the
//! windows after it still run; a solve failing elsewhere is a window failure, not a panic.

use nalgebra::{Isometry3, Point3};
use pssba_core::sliding::{SlidingWindows, WindowError, WindowSpec};
use pssba_core::{CoreError, Parallelism, PssBaConfig, Window, adjust_sliding, adjust_window};
use pssba_sim::{SceneSpec, curved_window, perturb_poses};

/// Frames, initial poses and true poses of a simulated sequence.
struct Scene {
    frames: Vec<Vec<Point3<f64>>>,
    initial: Vec<Isometry3<f64>>,
    truth: Vec<Isometry3<f64>>,
}

fn scene(frames: usize) -> Scene {
    let window = curved_window(&SceneSpec {
        frames,
        points_per_frame: 2000,
        seed: 4,
        ..SceneSpec::default()
    });
    let initial = perturb_poses(&window.ground_truth, 0.1, 0.5, 9);
    Scene {
        frames: window.frames,
        initial,
        truth: window.ground_truth,
    }
}

fn config() -> PssBaConfig {
    PssBaConfig {
        max_scales: 3,
        ..PssBaConfig::default()
    }
}

fn spec(window_frames: usize, window_stride: usize) -> WindowSpec {
    WindowSpec {
        window_frames,
        window_stride,
    }
}

#[test]
fn one_window_over_everything_is_adjust_window() {
    let Scene {
        frames, initial, ..
    } = scene(8);
    let config = config();
    let sliding = adjust_sliding(
        &frames,
        &initial,
        &config,
        spec(100, 80),
        Parallelism::Serial,
    )
    .expect("ok");
    let whole = adjust_window(
        Window {
            frames: &frames,
            world_from_lidar: &initial,
            fixed: None,
            times: None,
        },
        &config,
        Parallelism::Serial,
    )
    .expect("ok");
    assert_eq!(sliding.windows.len(), 1);
    assert_eq!(sliding.world_from_lidar, whole.world_from_lidar);
}

#[test]
fn frames_pushed_one_by_one_give_the_whole_sequence_result_and_one_final_pose_each() {
    let Scene {
        frames,
        initial,
        truth,
    } = scene(14);
    let config = config();
    let whole =
        adjust_sliding(&frames, &initial, &config, spec(6, 4), Parallelism::Serial).expect("ok");
    // Windows end at 6, 10, 14.
    assert_eq!(whole.windows.len(), 3);
    let mut stream = SlidingWindows::new(spec(6, 4)).expect("valid");
    let mut finals = vec![0; frames.len()];
    for (k, (points, pose)) in frames.iter().zip(&initial).enumerate() {
        assert_eq!(stream.push_frame(k as f64, points.clone(), *pose), Ok(k));
        while let Some(outcome) = stream.run_next_local(&config, Parallelism::Serial) {
            assert!(outcome.result.is_ok(), "{:?}", outcome.result.err());
            for f in &outcome.finals {
                finals[f.sequence] += 1;
            }
        }
    }
    assert!(!stream.is_done(), "the stream has not ended");
    stream.end_stream();
    assert!(
        stream
            .run_next_local(&config, Parallelism::Serial)
            .is_none()
    );
    assert!(stream.is_done());
    assert!(finals.iter().all(|&c| c == 1), "{finals:?}");
    let streamed: Vec<_> = stream
        .final_poses()
        .into_iter()
        .map(|p| p.expect("final"))
        .collect();
    assert_eq!(streamed, whole.world_from_lidar);
    // And the windows improved the trajectory.
    let before = pssba_eval::ape_translation_paired(&truth, &initial).expect("APE");
    let after = pssba_eval::ape_translation_paired(&truth, &whole.world_from_lidar).expect("APE");
    assert!(
        after.rmse_m < 0.5 * before.rmse_m,
        "APE {} -> {}",
        before.rmse_m,
        after.rmse_m
    );
    assert_eq!(
        stream.push_frame(99.0, Vec::new(), Isometry3::identity()),
        Err(CoreError::FrameAfterEndOfStream { sequence: 14 })
    );
}

#[test]
fn a_failing_window_keeps_its_frames_recorded_and_later_windows_run() {
    let Scene {
        mut frames,
        initial,
        ..
    } = scene(14);
    // Frames 6..10 hold too few points: the window in which they are new (frames 4..10,
    // anchors 4 and 5) has nothing to adjust.
    for frame in &mut frames[6..10] {
        frame.truncate(3);
    }
    let result = adjust_sliding(
        &frames,
        &initial,
        &config(),
        spec(6, 4),
        Parallelism::Serial,
    )
    .expect("ok");
    assert_eq!(result.windows.len(), 3);
    assert_eq!(result.failures.len(), 1, "{:?}", result.failures);
    let failure = &result.failures[0];
    assert_eq!((failure.index, failure.kept_initial.clone()), (1, 6..10));
    assert!(matches!(
        result.windows[1].result,
        Err(WindowError::Core(CoreError::NothingToAdjust))
    ));
    // The failed frames kept their initial poses moved by the anchors' correction: a rigid
    // motion common to all of them.
    let correction = result.world_from_lidar[6] * initial[6].inverse();
    for (k, start) in initial.iter().enumerate().take(10).skip(6) {
        let moved = correction * start;
        let d = (moved.to_homogeneous() - result.world_from_lidar[k].to_homogeneous()).norm();
        assert!(d < 1e-12, "frame {k}: {d}");
    }
    assert!(result.windows[2].result.is_ok());
}

#[test]
fn a_solve_that_fails_elsewhere_is_a_window_failure() {
    let Scene {
        frames, initial, ..
    } = scene(6);
    let mut stream = SlidingWindows::new(spec(4, 2)).expect("valid");
    for (k, (points, pose)) in frames.iter().zip(&initial).enumerate() {
        stream
            .push_frame(k as f64, points.clone(), *pose)
            .expect("open");
    }
    stream.end_stream();
    let outcome = stream
        .run_next(&config(), Parallelism::Serial, |_, _, _| {
            Err("the adjust stage went away".into())
        })
        .expect("a window");
    let error = outcome.result.expect_err("failed").to_string();
    assert!(
        error.contains("scale 0") && error.contains("went away"),
        "{error}"
    );
    assert_eq!(outcome.finals.len(), 4);
    for f in &outcome.finals {
        assert_eq!(
            f.world_from_lidar, initial[f.sequence],
            "window 0: no correction"
        );
    }
    assert_eq!(stream.failures().len(), 1);
}

#[test]
fn bad_window_specs_are_refused_by_name() {
    for (w, s, field) in [
        (1, 1, "window_frames"),
        (5, 0, "window_stride"),
        (5, 5, "window_stride"),
    ] {
        match SlidingWindows::new(spec(w, s)) {
            Err(CoreError::InvalidConfig { field: got, .. }) => assert_eq!(got, field),
            other => panic!("{w} {s}: {other:?}"),
        }
    }
}

#[test]
fn a_stream_resumed_after_a_window_with_its_anchors_gives_the_unbroken_result() {
    let Scene {
        frames, initial, ..
    } = scene(14);
    let config = config();
    let whole =
        adjust_sliding(&frames, &initial, &config, spec(6, 4), Parallelism::Serial).expect("ok");
    // A process that crashed after window 0 (frames 0..6 final): its successor takes the
    // stream from the W - S = 2 anchors (frames 4 and 5) on, with their final poses.
    let anchors = whole.world_from_lidar[4..6].to_vec();
    let mut stream = SlidingWindows::resume(spec(6, 4), anchors).expect("valid");
    assert_eq!(stream.finalised(), 2);
    let mut finals = Vec::new();
    for (points, pose) in frames[4..].iter().zip(&initial[4..]) {
        stream
            .push_frame(0.0, points.clone(), *pose)
            .expect("pushed");
        while let Some(outcome) = stream.run_next_local(&config, Parallelism::Serial) {
            assert!(outcome.result.is_ok(), "{:?}", outcome.result.err());
            finals.extend(
                outcome
                    .finals
                    .iter()
                    .map(|f| (f.sequence + 4, f.world_from_lidar)),
            );
        }
    }
    stream.end_stream();
    assert!(
        stream
            .run_next_local(&config, Parallelism::Serial)
            .is_none()
    );
    assert!(stream.is_done());
    // Frames 6..14 are made final once each, with the poses of the unbroken stream.
    let sequences: Vec<usize> = finals.iter().map(|f| f.0).collect();
    assert_eq!(sequences, (6..14).collect::<Vec<_>>());
    for (k, pose) in finals {
        assert_eq!(pose, whole.world_from_lidar[k], "frame {k}");
    }
}
