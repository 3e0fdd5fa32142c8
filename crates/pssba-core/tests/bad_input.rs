//! Bad and degenerate input: never a panic, never a non-finite pose. Every case ends in a typed
//! [`CoreError`] or in a finite result whose report says what was skipped.

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use pssba_core::{
    AdjustResult, CoreError, Parallelism, PssBaConfig, Window, adjust, adjust_window,
};
use pssba_sim::{
    SceneSpec, Shape, SimulatedWindow, curved_shapes, orbit_poses, perturb_poses, simulate,
};

/// A small curved window: the first `frames` of 20 poses on the orbit (neighbours overlap
/// well), `points` points per frame, initial poses perturbed by 0.1 m / 0.5 deg RMS, with
/// frame 0 (the gauge) at its true pose so that errors against the truth are absolute.
fn small_window(frames: usize, points: usize, seed: u64) -> (SimulatedWindow, Vec<Isometry3<f64>>) {
    let spec = SceneSpec {
        frames,
        points_per_frame: points,
        seed,
        ..SceneSpec::default()
    };
    let window = simulate(&curved_shapes(), &orbit_poses(20)[..frames], &spec);
    let mut initial = perturb_poses(&window.ground_truth, 0.1, 0.5, seed + 100);
    initial[0] = window.ground_truth[0];
    (window, initial)
}

/// Asserts that `a` and `b` are the same pose up to rounding (a held frame goes through a
/// rotation-matrix round trip, which may flip the quaternion sign or move its last bits).
fn assert_same_pose(a: &Isometry3<f64>, b: &Isometry3<f64>) {
    let dt = (a.translation.vector - b.translation.vector).norm();
    let dr = (a.rotation * b.rotation.inverse()).angle();
    assert!(dt < 1e-12 && dr < 1e-12, "{a:?} vs {b:?}");
}

fn is_finite(pose: &Isometry3<f64>) -> bool {
    pose.to_homogeneous().iter().all(|v| v.is_finite())
}

fn assert_finite(result: &AdjustResult) {
    assert!(
        result.world_from_lidar.iter().all(is_finite),
        "non-finite pose"
    );
    assert!(
        result
            .smoothed_cloud
            .iter()
            .all(|p| p.coords.iter().all(|v| v.is_finite())),
        "non-finite smoothed point"
    );
    for s in &result.scales {
        assert!(
            s.cost_before.is_finite() && s.cost_after.is_finite(),
            "{s:?}"
        );
        assert!(s.pose_change.is_finite(), "{s:?}");
    }
}

/// RMS translation error (m) over `frames`.
fn translation_rms(gt: &[Isometry3<f64>], est: &[Isometry3<f64>], frames: &[usize]) -> f64 {
    let sum: f64 = frames
        .iter()
        .map(|&k| (gt[k].translation.vector - est[k].translation.vector).norm_squared())
        .sum();
    (sum / frames.len() as f64).sqrt()
}

/// RMS rotation error (deg) over `frames`.
fn rotation_rms_deg(gt: &[Isometry3<f64>], est: &[Isometry3<f64>], frames: &[usize]) -> f64 {
    let sum: f64 = frames
        .iter()
        .map(|&k| (est[k].rotation * gt[k].rotation.inverse()).angle().powi(2))
        .sum();
    (sum / frames.len() as f64).sqrt().to_degrees()
}

fn frames_but(n: usize, skip: &[usize]) -> Vec<usize> {
    (0..n).filter(|k| !skip.contains(k)).collect()
}

// --- Shape of the input ---------------------------------------------------------------------

#[test]
fn frame_and_pose_counts_must_match() {
    let (window, initial) = small_window(3, 200, 1);
    let err = adjust(&window.frames, &initial[..2], &PssBaConfig::default()).unwrap_err();
    assert_eq!(
        err,
        CoreError::CountMismatch {
            frames: 3,
            poses: 2
        }
    );
    let err = adjust(&window.frames[..2], &initial, &PssBaConfig::default()).unwrap_err();
    assert_eq!(
        err,
        CoreError::CountMismatch {
            frames: 2,
            poses: 3
        }
    );
}

#[test]
fn one_or_zero_frames_are_too_few() {
    let (window, initial) = small_window(2, 200, 1);
    let err = adjust(&window.frames[..1], &initial[..1], &PssBaConfig::default()).unwrap_err();
    assert_eq!(err, CoreError::TooFewFrames(1));
    let err = adjust(&[], &[], &PssBaConfig::default()).unwrap_err();
    assert_eq!(err, CoreError::TooFewFrames(0));
}

#[test]
fn non_finite_initial_pose_is_reported_with_its_frame() {
    let (window, initial) = small_window(4, 200, 1);
    let mut bad = initial.clone();
    bad[2].translation.vector.y = f64::NAN;
    let err = adjust(&window.frames, &bad, &PssBaConfig::default()).unwrap_err();
    assert_eq!(err, CoreError::NonFinitePose { frame: 2 });

    let mut bad = initial.clone();
    bad[3].translation.vector.x = f64::INFINITY;
    let err = adjust(&window.frames, &bad, &PssBaConfig::default()).unwrap_err();
    assert_eq!(err, CoreError::NonFinitePose { frame: 3 });

    // A NaN quaternion (not a rotation at all) is caught as well, and the first bad frame wins.
    let mut bad = initial;
    bad[1].rotation =
        UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(f64::NAN, 0.0, 0.0, 0.0));
    bad[3].translation.vector.z = f64::NAN;
    let err = adjust(&window.frames, &bad, &PssBaConfig::default()).unwrap_err();
    assert_eq!(err, CoreError::NonFinitePose { frame: 1 });
}

#[test]
fn invalid_config_is_rejected_before_any_work() {
    let (window, initial) = small_window(3, 200, 1);
    let config = PssBaConfig {
        gamma_shrink: 0.9,
        ..PssBaConfig::default()
    };
    let err = adjust(&window.frames, &initial, &config).unwrap_err();
    assert!(
        matches!(
            err,
            CoreError::InvalidConfig {
                field: "gamma_shrink",
                ..
            }
        ),
        "{err:?}"
    );
    let config = PssBaConfig {
        gamma0_m: f64::NAN,
        ..PssBaConfig::default()
    };
    // The config is checked first, even when the input itself is also bad.
    let err = adjust(&window.frames, &initial[..1], &config).unwrap_err();
    assert!(
        matches!(
            err,
            CoreError::InvalidConfig {
                field: "gamma0_m",
                ..
            }
        ),
        "{err:?}"
    );
}

#[test]
fn all_frames_fixed_is_nothing_to_adjust() {
    let (window, initial) = small_window(3, 200, 1);
    let err = adjust_window(
        Window {
            frames: &window.frames,
            world_from_lidar: &initial,
            fixed: Some(&[true, true, true]),
        },
        &PssBaConfig::default(),
        Parallelism::Serial,
    )
    .unwrap_err();
    assert_eq!(err, CoreError::NothingToAdjust);
}

// --- Empty, sparse and non-finite points ------------------------------------------------------

#[test]
fn empty_frame_among_good_ones_is_held_and_reported() {
    let (mut window, initial) = small_window(5, 2000, 2);
    window.frames[2].clear();
    let result = adjust(&window.frames, &initial, &PssBaConfig::default()).expect("adjust");
    assert_finite(&result);
    assert_eq!(result.sparse_frames_held, vec![2]);
    assert_eq!(
        result.world_from_lidar[2], initial[2],
        "held frame must not move"
    );
    let free = frames_but(5, &[0, 2]);
    let before = translation_rms(&window.ground_truth, &initial, &free);
    let after = translation_rms(&window.ground_truth, &result.world_from_lidar, &free);
    eprintln!("empty frame: translation RMS {before:.4} -> {after:.4} m");
    assert!(after < 0.5 * before, "{before} -> {after}");
}

#[test]
fn all_frames_empty_is_nothing_to_adjust() {
    // Frame 0 is the gauge; every other frame has too few points and is held, so no frame is
    // left free: `NothingToAdjust` (checked before any smoothing, so `NoConstraints` never
    // gets a chance).
    let frames = vec![Vec::<Point3<f64>>::new(); 4];
    let poses = orbit_poses(4);
    let err = adjust(&frames, &poses, &PssBaConfig::default()).unwrap_err();
    assert_eq!(err, CoreError::NothingToAdjust);
}

#[test]
fn empty_gauge_frame_leaves_a_finite_result() {
    // Frame 0 is held fixed by default but has no points: nothing ties the window to it, so the
    // absolute pose of the window is unobservable (only the damping keeps it put). The
    // relative poses of the other frames must still be finite and improve.
    let (mut window, initial) = small_window(5, 2000, 3);
    window.frames[0].clear();
    let result = adjust(&window.frames, &initial, &PssBaConfig::default()).expect("adjust");
    assert_finite(&result);
    assert!(
        result.sparse_frames_held.is_empty(),
        "the gauge is not a held sparse frame"
    );
    assert_same_pose(&result.world_from_lidar[0], &initial[0]);
    // Relative translation of frames 2.. with respect to frame 1.
    let relative = |poses: &[Isometry3<f64>]| -> Vec<Isometry3<f64>> {
        poses.iter().map(|p| poses[1].inverse() * p).collect()
    };
    let (gt, init, est) = (
        relative(&window.ground_truth),
        relative(&initial),
        relative(&result.world_from_lidar),
    );
    let others = frames_but(5, &[0, 1]);
    let before = translation_rms(&gt, &init, &others);
    let after = translation_rms(&gt, &est, &others);
    eprintln!("empty gauge: relative translation RMS {before:.4} -> {after:.4} m");
    assert!(after < before, "{before} -> {after}");
}

#[test]
fn frames_with_too_few_points() {
    let (mut window, initial) = small_window(5, 2000, 4);
    let config = PssBaConfig::default();
    // Frame 1: below `min_points_per_frame`, held. Frame 3: just enough to take part, but far
    // too sparse for its own kernels.
    window.frames[1].truncate(config.min_points_per_frame - 1);
    window.frames[3].truncate(config.min_points_per_frame);
    let result = adjust(&window.frames, &initial, &config).expect("adjust");
    assert_finite(&result);
    assert_eq!(result.sparse_frames_held, vec![1]);
    assert_same_pose(&result.world_from_lidar[1], &initial[1]);
    for s in &result.scales {
        eprintln!("{s:?}");
    }
    let moved =
        (result.world_from_lidar[3].translation.vector - initial[3].translation.vector).norm();
    eprintln!("sparse frame 3 moved {moved:.4} m");
    let free = frames_but(5, &[0, 1, 3]);
    let before = translation_rms(&window.ground_truth, &initial, &free);
    let after = translation_rms(&window.ground_truth, &result.world_from_lidar, &free);
    eprintln!("too few points: translation RMS {before:.4} -> {after:.4} m");
    assert!(after < 0.5 * before, "{before} -> {after}");
}

/// Copies of `frames` with a non-finite point inserted after every `every`-th point (NaN,
/// +inf, -inf in turn, in one coordinate); returns the frames and how many were inserted.
fn with_nonfinite_points(
    frames: &[Vec<Point3<f64>>],
    every: usize,
) -> (Vec<Vec<Point3<f64>>>, usize) {
    let bad = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY];
    let mut inserted = 0;
    let out = frames
        .iter()
        .map(|frame| {
            let mut out = Vec::with_capacity(frame.len() + frame.len() / every + 1);
            for (k, p) in frame.iter().enumerate() {
                out.push(*p);
                if k % every == 0 {
                    let mut q = *p;
                    q.coords[inserted % 3] = bad[(inserted / 3) % 3];
                    out.push(q);
                    inserted += 1;
                }
            }
            out
        })
        .collect();
    (out, inserted)
}

#[test]
fn nonfinite_points_are_dropped_and_counted() {
    let (window, initial) = small_window(4, 2000, 5);
    let (dirty, inserted) = with_nonfinite_points(&window.frames, 7);
    assert!(inserted > 1000);
    let config = PssBaConfig::default();
    let run = |frames: &[Vec<Point3<f64>>]| {
        adjust_window(
            Window {
                frames,
                world_from_lidar: &initial,
                fixed: None,
            },
            &config,
            Parallelism::Serial,
        )
        .expect("adjust")
    };
    let clean = run(&window.frames);
    let result = run(&dirty);
    assert_finite(&result);
    assert_eq!(result.dropped_nonfinite_points, inserted);
    assert_eq!(clean.dropped_nonfinite_points, 0);
    // Dropping them leaves exactly the clean input, so the serial run is bit for bit the same.
    assert_eq!(result.world_from_lidar, clean.world_from_lidar);
    let free = frames_but(4, &[0]);
    let before = translation_rms(&window.ground_truth, &initial, &free);
    let after = translation_rms(&window.ground_truth, &result.world_from_lidar, &free);
    let rot_before = rotation_rms_deg(&window.ground_truth, &initial, &free);
    let rot_after = rotation_rms_deg(&window.ground_truth, &result.world_from_lidar, &free);
    eprintln!(
        "nonfinite: translation RMS {before:.4} -> {after:.4} m, rotation {rot_before:.3} -> {rot_after:.3} deg"
    );
    assert!(after < 0.5 * before, "{before} -> {after}");
}

#[test]
fn frame_of_only_nonfinite_points_is_held() {
    let (mut window, initial) = small_window(4, 2000, 6);
    let count = window.frames[3].len();
    window.frames[3]
        .iter_mut()
        .for_each(|p| p.coords = Vector3::new(f64::NAN, 0.0, 1.0));
    let result = adjust(&window.frames, &initial, &PssBaConfig::default()).expect("adjust");
    assert_finite(&result);
    assert_eq!(result.dropped_nonfinite_points, count);
    assert_eq!(result.sparse_frames_held, vec![3]);
    assert_same_pose(&result.world_from_lidar[3], &initial[3]);
}

// --- Degenerate scenes ------------------------------------------------------------------------

#[test]
fn single_plane_improves_observable_directions() {
    // A flat ground (z = 0) only observes z translation, roll and pitch of each frame; x, y
    // and yaw slide freely along the plane.
    let poses = orbit_poses(5);
    let spec = SceneSpec {
        frames: 5,
        points_per_frame: 3000,
        seed: 7,
        ..SceneSpec::default()
    };
    let window = simulate(
        &[Shape::Bowl {
            curvature: 0.0,
            extent_m: 14.0,
        }],
        &poses,
        &spec,
    );
    let mut initial = perturb_poses(&window.ground_truth, 0.1, 0.5, 107);
    initial[0] = window.ground_truth[0];
    let result = adjust(&window.frames, &initial, &PssBaConfig::default()).expect("adjust");
    assert_finite(&result);
    for s in &result.scales {
        eprintln!("{s:?}");
    }
    let gt = &window.ground_truth;
    let est = &result.world_from_lidar;
    let free = frames_but(5, &[0]);
    let rms = |f: &dyn Fn(usize, &[Isometry3<f64>]) -> f64, poses: &[Isometry3<f64>]| {
        (free.iter().map(|&k| f(k, poses).powi(2)).sum::<f64>() / free.len() as f64).sqrt()
    };
    let z_err = |k: usize, p: &[Isometry3<f64>]| p[k].translation.z - gt[k].translation.z;
    // Tilt: angle between the world up axis seen from the estimated and from the true pose.
    let tilt_err = |k: usize, p: &[Isometry3<f64>]| {
        let up_est = p[k].rotation.inverse() * Vector3::z();
        let up_gt = gt[k].rotation.inverse() * Vector3::z();
        up_est.angle(&up_gt).to_degrees()
    };
    let xy_move = |k: usize, p: &[Isometry3<f64>]| {
        (p[k].translation.vector - initial[k].translation.vector)
            .xy()
            .norm()
    };
    let z_before = rms(&z_err, &initial);
    let z_after = rms(&z_err, est);
    let tilt_before = rms(&tilt_err, &initial);
    let tilt_after = rms(&tilt_err, est);
    let xy_drift = rms(&xy_move, est);
    eprintln!(
        "plane: z RMS {z_before:.4} -> {z_after:.4} m, tilt {tilt_before:.3} -> {tilt_after:.3} deg, xy drift {xy_drift:.4} m"
    );
    assert!(z_after <= z_before, "z {z_before} -> {z_after}");
    assert!(
        tilt_after <= tilt_before,
        "tilt {tilt_before} -> {tilt_after}"
    );
}

/// `frames` views of the world segment x in [-10, 10] m, y = z = 0 from `poses`, in the lidar
/// frame, with `noise_m` uniform jitter per coordinate.
fn line_frames(poses: &[Isometry3<f64>], points: usize, noise_m: f64) -> Vec<Vec<Point3<f64>>> {
    use rand::{Rng, SeedableRng, rngs::StdRng};
    let mut rng = StdRng::seed_from_u64(9);
    poses
        .iter()
        .map(|pose| {
            (0..points)
                .map(|_| {
                    let x = rng.random_range(-10.0..10.0);
                    let mut jitter = || {
                        if noise_m > 0.0 {
                            rng.random_range(-noise_m..noise_m)
                        } else {
                            0.0
                        }
                    };
                    let world = Point3::new(x, jitter(), jitter());
                    pose.inverse_transform_point(&world)
                })
                .collect()
        })
        .collect()
}

#[test]
fn single_line_has_no_constraints() {
    let gt: Vec<Isometry3<f64>> = (0..4)
        .map(|k| {
            Isometry3::from_parts(
                Translation3::new(k as f64 - 1.5, 3.0, 2.0),
                UnitQuaternion::from_euler_angles(0.0, 0.0, 0.3 * k as f64),
            )
        })
        .collect();
    let initial = perturb_poses(&gt, 0.05, 0.3, 11);
    for noise in [0.0, 0.01] {
        let frames = line_frames(&gt, 2000, noise);
        let result = adjust(&frames, &initial, &PssBaConfig::default());
        eprintln!("line noise {noise}: {result:?}");
        match result {
            Err(CoreError::NoConstraints {
                gamma_m,
                kernels_rejected,
            }) => {
                assert_eq!(gamma_m, PssBaConfig::default().gamma0_m);
                assert!(kernels_rejected > 0);
            }
            other => panic!("noise {noise}: expected NoConstraints, got {other:?}"),
        }
    }
}

#[test]
fn frames_that_do_not_overlap_have_no_constraints() {
    // Two frames, each seeing a 10 m x 10 m patch of ground 2 m below it, 100 m apart.
    let poses = [
        Isometry3::translation(0.0, 0.0, 2.0),
        Isometry3::translation(100.0, 0.0, 2.0),
    ];
    let patch: Vec<Point3<f64>> = (0..2500)
        .map(|k| {
            Point3::new(
                (k % 50) as f64 * 0.2 - 5.0,
                (k / 50) as f64 * 0.2 - 5.0,
                -2.0,
            )
        })
        .collect();
    let frames = vec![patch.clone(), patch];
    let err = adjust(&frames, &poses, &PssBaConfig::default()).unwrap_err();
    eprintln!("{err:?}");
    assert!(
        matches!(err, CoreError::NoConstraints { kernels_rejected, .. } if kernels_rejected > 0),
        "{err:?}"
    );
}
