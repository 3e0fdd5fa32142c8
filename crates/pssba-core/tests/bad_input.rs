//! Bad and degenerate input: never a panic, never a non-finite pose. Every case ends in a typed
//! [`CoreError`] or in a finite result whose report says what was skipped.
//!
//! Windows are small (5 frames x 3000 points, a few tenths of a second each). "Accurate
//! enough" means: the translation RMS error of the free frames at least halves from the
//! 0.1 m / 0.5 deg initial perturbation (the full-size end-to-end test asks for far more).
//! With PCA normals over the 12 nearest centroids of the merged voxel cloud (`cloud.rs`) the
//! errors fall 7-25 fold (see `SPARSE_CASE_FRAMES` for the one case that needs more frames).
//! The voxel-cell normals of f471143 (reverted since) failed four of these cases.

use nalgebra::{Isometry3, Point3, Quaternion, Translation3, UnitQuaternion, Vector3};
use pssba_core::{
    AdjustResult, CoreError, Parallelism, PssBaConfig, Window, adjust, adjust_window,
};
use pssba_sim::{
    SceneSpec, Shape, SimulatedWindow, curved_shapes, orbit_poses, perturb_poses, simulate,
};

/// Frames and points of the windows that run the whole pipeline.
const FRAMES: usize = 5;
const POINTS: usize = 3000;

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

/// Poses, smoothed cloud and per-scale numbers are all finite.
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
            s.cost_before.is_finite() && s.cost_after.is_finite() && s.pose_change.is_finite(),
            "{s:?}"
        );
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

fn frames_but(n: usize, skip: &[usize]) -> Vec<usize> {
    (0..n).filter(|k| !skip.contains(k)).collect()
}

/// Asserts "accurate enough" (module doc) for `frames` and returns (before, after).
fn assert_improved(
    what: &str,
    gt: &[Isometry3<f64>],
    initial: &[Isometry3<f64>],
    result: &AdjustResult,
    frames: &[usize],
) -> (f64, f64) {
    let before = translation_rms(gt, initial, frames);
    let after = translation_rms(gt, &result.world_from_lidar, frames);
    eprintln!("{what}: translation RMS {before:.4} -> {after:.4} m");
    assert!(
        after < 0.5 * before,
        "{what}: translation RMS {before:.4} -> {after:.4} m"
    );
    (before, after)
}

// --- Shape of the input ---------------------------------------------------------------------

#[test]
fn frame_and_pose_counts_must_match() {
    let (window, initial) = small_window(3, 200, 1);
    let config = PssBaConfig::default();
    let err = adjust(&window.frames, &initial[..2], &config).expect_err("must be rejected");
    assert_eq!(
        err,
        CoreError::CountMismatch {
            frames: 3,
            poses: 2
        }
    );
    let err = adjust(&window.frames[..2], &initial, &config).expect_err("must be rejected");
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
    let config = PssBaConfig::default();
    let err = adjust(&window.frames[..1], &initial[..1], &config).expect_err("must be rejected");
    assert_eq!(err, CoreError::TooFewFrames(1));
    let err = adjust(&[], &[], &config).expect_err("must be rejected");
    assert_eq!(err, CoreError::TooFewFrames(0));
}

#[test]
fn non_finite_initial_pose_is_reported_with_its_frame() {
    let (window, initial) = small_window(4, 200, 1);
    let config = PssBaConfig::default();
    let mut bad = initial.clone();
    bad[2].translation.vector.y = f64::NAN;
    let err = adjust(&window.frames, &bad, &config).expect_err("must be rejected");
    assert_eq!(err, CoreError::NonFinitePose { frame: 2 });

    let mut bad = initial.clone();
    bad[3].translation.vector.x = f64::INFINITY;
    let err = adjust(&window.frames, &bad, &config).expect_err("must be rejected");
    assert_eq!(err, CoreError::NonFinitePose { frame: 3 });

    // A NaN quaternion (no rotation at all) is caught too, and the first bad frame is named.
    let mut bad = initial;
    bad[1].rotation = UnitQuaternion::new_unchecked(Quaternion::new(f64::NAN, 0.0, 0.0, 0.0));
    bad[3].translation.vector.z = f64::NAN;
    let err = adjust(&window.frames, &bad, &config).expect_err("must be rejected");
    assert_eq!(err, CoreError::NonFinitePose { frame: 1 });
}

#[test]
fn invalid_config_is_rejected_before_any_work() {
    let (window, initial) = small_window(3, 200, 1);
    let config = PssBaConfig {
        gamma_shrink: 0.9,
        ..PssBaConfig::default()
    };
    let err = adjust(&window.frames, &initial, &config).expect_err("must be rejected");
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
    // The config is checked first, even when the input is bad as well.
    let config = PssBaConfig {
        gamma0_m: f64::NAN,
        ..PssBaConfig::default()
    };
    let err = adjust(&window.frames, &initial[..1], &config).expect_err("must be rejected");
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
            times: None,
        },
        &PssBaConfig::default(),
        Parallelism::Serial,
    )
    .expect_err("must be rejected");
    assert_eq!(err, CoreError::NothingToAdjust);
}

#[test]
fn fixed_mask_of_wrong_length_is_rejected() {
    let (window, initial) = small_window(3, 200, 1);
    let err = adjust_window(
        Window {
            frames: &window.frames,
            world_from_lidar: &initial,
            fixed: Some(&[true, false]),
            times: None,
        },
        &PssBaConfig::default(),
        Parallelism::Serial,
    )
    .expect_err("must be rejected");
    assert_eq!(err, CoreError::FixedMaskLength { frames: 3, mask: 2 });
}

// --- A clean small window: the reference for the cases below --------------------------------

#[test]
fn clean_small_window_is_accurate() {
    let (window, initial) = small_window(FRAMES, POINTS, 2);
    let result = adjust(&window.frames, &initial, &PssBaConfig::default()).expect("adjust");
    assert_finite(&result);
    assert_eq!(result.dropped_nonfinite_points, 0);
    assert!(result.sparse_frames_held.is_empty());
    assert_improved(
        "clean",
        &window.ground_truth,
        &initial,
        &result,
        &frames_but(FRAMES, &[0]),
    );
}

// --- Empty, sparse and non-finite points ------------------------------------------------------

#[test]
fn empty_frame_among_good_ones_is_held_and_reported() {
    let (mut window, initial) = small_window(FRAMES, POINTS, 2);
    window.frames[2].clear();
    let result = adjust(&window.frames, &initial, &PssBaConfig::default()).expect("adjust");
    assert_finite(&result);
    assert_eq!(result.sparse_frames_held, vec![2]);
    assert_same_pose(&result.world_from_lidar[2], &initial[2]);
    assert_improved(
        "one empty frame",
        &window.ground_truth,
        &initial,
        &result,
        &frames_but(FRAMES, &[0, 2]),
    );
}

#[test]
fn all_frames_empty_is_nothing_to_adjust() {
    // Frame 0 is the gauge; every other frame has too few points and is held, so no frame is
    // left free: `NothingToAdjust`. That check comes before any smoothing, so
    // `NoConstraints` is never reached.
    let frames = vec![Vec::<Point3<f64>>::new(); 4];
    let poses = orbit_poses(4);
    let err = adjust(&frames, &poses, &PssBaConfig::default()).expect_err("must be rejected");
    assert_eq!(err, CoreError::NothingToAdjust);
}

#[test]
fn empty_gauge_frame_leaves_a_finite_result() {
    // Frame 0 is held by default but has no points: nothing ties the window to it, so the
    // absolute pose of the window is unobservable. Frame 0 is not a "sparse frame held" (it
    // was fixed already); the relative poses of the other frames must still improve.
    let (mut window, initial) = small_window(FRAMES, POINTS, 3);
    window.frames[0].clear();
    let result = adjust(&window.frames, &initial, &PssBaConfig::default()).expect("adjust");
    assert_finite(&result);
    assert!(result.sparse_frames_held.is_empty());
    assert_same_pose(&result.world_from_lidar[0], &initial[0]);
    // Poses relative to frame 1, so the unobservable common motion drops out.
    let relative = |poses: &[Isometry3<f64>]| -> Vec<Isometry3<f64>> {
        poses.iter().map(|p| poses[1].inverse() * p).collect()
    };
    let relative_result = AdjustResult {
        world_from_lidar: relative(&result.world_from_lidar),
        ..result
    };
    assert_improved(
        "empty gauge frame (relative to frame 1)",
        &relative(&window.ground_truth),
        &relative(&initial),
        &relative_result,
        &frames_but(FRAMES, &[0, 1]),
    );
}

/// Frames of the sparse-frame case: with two of five frames crippled the other two were
/// barely constrained and their error landed on either side of the bound with summation-order
/// changes alone (0.036-0.050 m from 0.080 m); eight frames leave enough overlap to test
/// what the case is about.
const SPARSE_CASE_FRAMES: usize = 8;

#[test]
fn frames_with_too_few_points() {
    let frames = SPARSE_CASE_FRAMES;
    let (mut window, initial) = small_window(frames, POINTS, 4);
    let config = PssBaConfig::default();
    // Frame 1: one point below `min_points_per_frame`, held. Frame 3: exactly the minimum,
    // so it takes part, but with only a handful of residuals.
    window.frames[1].truncate(config.min_points_per_frame - 1);
    window.frames[3].truncate(config.min_points_per_frame);
    let result = adjust(&window.frames, &initial, &config).expect("adjust");
    assert_finite(&result);
    assert_eq!(result.sparse_frames_held, vec![1]);
    assert_same_pose(&result.world_from_lidar[1], &initial[1]);
    let moved =
        (result.world_from_lidar[3].translation.vector - initial[3].translation.vector).norm();
    let error = |poses: &[Isometry3<f64>]| {
        (poses[3].translation.vector - window.ground_truth[3].translation.vector).norm()
    };
    eprintln!(
        "frame 3 ({} points) moved {moved:.4} m, error {:.4} -> {:.4} m",
        window.frames[3].len(),
        error(&initial),
        error(&result.world_from_lidar)
    );
    // Frame 3's own accuracy is printed, not asserted: with a handful of residuals its pose
    // is barely observable. Measured with 8 frames (seeds 4, 5, 6) it ends 0.21, 0.52 and
    // 0.91 m off (from 0.12, 0.05, 0.07 m): LM lets a barely observed frame wander. Known
    // weakness; `min_points_per_frame` is the only guard so far.
    assert_improved(
        "frames with too few points",
        &window.ground_truth,
        &initial,
        &result,
        &frames_but(frames, &[0, 1, 3]),
    );
}

/// Copies of `frames` with a non-finite point inserted after every `every`-th point (one
/// coordinate NaN, +inf or -inf in turn); returns the frames and how many were inserted.
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
    let (window, initial) = small_window(FRAMES, POINTS, 5);
    let (dirty, inserted) = with_nonfinite_points(&window.frames, 7);
    assert!(inserted > 2000, "{inserted}");
    let config = PssBaConfig::default();
    let run = |frames: &[Vec<Point3<f64>>]| {
        adjust_window(
            Window {
                frames,
                world_from_lidar: &initial,
                fixed: None,
                times: None,
            },
            &config,
            Parallelism::Serial,
        )
        .expect("adjust")
    };
    let result = run(&dirty);
    assert_finite(&result);
    assert_eq!(result.dropped_nonfinite_points, inserted);
    assert!(result.sparse_frames_held.is_empty());
    // Dropping them leaves exactly the clean input, so the serial run is bit for bit the same.
    let clean = run(&window.frames);
    assert_eq!(clean.dropped_nonfinite_points, 0);
    assert_eq!(result.world_from_lidar, clean.world_from_lidar);
    assert_improved(
        "non-finite points",
        &window.ground_truth,
        &initial,
        &result,
        &frames_but(FRAMES, &[0]),
    );
}

#[test]
fn frame_of_only_nonfinite_points_is_held() {
    let (mut window, initial) = small_window(FRAMES, POINTS, 6);
    let count = window.frames[3].len();
    for (k, p) in window.frames[3].iter_mut().enumerate() {
        p.coords[k % 3] = if k % 2 == 0 { f64::NAN } else { f64::INFINITY };
    }
    let result = adjust(&window.frames, &initial, &PssBaConfig::default()).expect("adjust");
    assert_finite(&result);
    assert_eq!(result.dropped_nonfinite_points, count);
    assert_eq!(result.sparse_frames_held, vec![3]);
    assert_same_pose(&result.world_from_lidar[3], &initial[3]);
    assert_improved(
        "frame of non-finite points",
        &window.ground_truth,
        &initial,
        &result,
        &frames_but(FRAMES, &[0, 3]),
    );
}

#[test]
fn huge_finite_coordinates_do_not_poison_the_result() {
    // Finite but absurd points (a broken driver's 1e30 or 1e300 m returns) pass the finiteness
    // filter; squared distances of them overflow to inf. They must stay isolated.
    let (mut window, initial) = small_window(FRAMES, POINTS, 7);
    for frame in &mut window.frames {
        for (k, scale) in [1e30, -1e30, 1e300, -1e300, f64::MAX]
            .into_iter()
            .enumerate()
        {
            frame.push(Point3::new(scale, 0.5 * scale, k as f64));
            frame.push(Point3::new(1.0, 2.0, scale));
        }
    }
    let result = adjust(&window.frames, &initial, &PssBaConfig::default()).expect("adjust");
    assert_finite(&result);
    assert_eq!(result.dropped_nonfinite_points, 0);
    assert_improved(
        "huge coordinates",
        &window.ground_truth,
        &initial,
        &result,
        &frames_but(FRAMES, &[0]),
    );
}

// --- Degenerate scenes ------------------------------------------------------------------------

#[test]
fn single_plane_improves_observable_directions() {
    // A flat ground z = 0 observes only z translation, roll and pitch of each frame; x, y and
    // yaw can slide along the plane without changing any residual. Asserted: finite poses,
    // and the RMS errors of z translation and of tilt (the angle between the true and the
    // estimated world up axis in the lidar frame, independent of yaw) at least halve.
    // The in-plane slide is printed, not asserted: nothing in the data fixes it. Before the
    // coarse-scale pose prior it drifted (xy RMS error 0.09 -> 0.57 m); with it, measured
    // 0.0913 -> 0.0912 m.
    let poses = orbit_poses(20)[..FRAMES].to_vec();
    let spec = SceneSpec {
        frames: FRAMES,
        points_per_frame: POINTS,
        seed: 8,
        ..SceneSpec::default()
    };
    let plane = [Shape::Bowl {
        curvature: 0.0,
        extent_m: 14.0,
    }];
    let window = simulate(&plane, &poses, &spec);
    let mut initial = perturb_poses(&window.ground_truth, 0.1, 0.5, 108);
    initial[0] = window.ground_truth[0];
    let result = adjust(&window.frames, &initial, &PssBaConfig::default()).expect("adjust");
    assert_finite(&result);
    let gt = &window.ground_truth;
    let free = frames_but(FRAMES, &[0]);
    let rms = |error: &dyn Fn(&Isometry3<f64>, &Isometry3<f64>) -> f64,
               poses: &[Isometry3<f64>]| {
        let sum: f64 = free.iter().map(|&k| error(&poses[k], &gt[k]).powi(2)).sum();
        (sum / free.len() as f64).sqrt()
    };
    let z_error = |p: &Isometry3<f64>, t: &Isometry3<f64>| p.translation.z - t.translation.z;
    let tilt_error_deg = |p: &Isometry3<f64>, t: &Isometry3<f64>| {
        let up = p.rotation.inverse() * Vector3::z();
        let true_up = t.rotation.inverse() * Vector3::z();
        up.angle(&true_up).to_degrees()
    };
    let xy_error = |p: &Isometry3<f64>, t: &Isometry3<f64>| {
        (p.translation.vector - t.translation.vector).xy().norm()
    };
    let est = &result.world_from_lidar;
    let (z_before, z_after) = (rms(&z_error, &initial), rms(&z_error, est));
    let (tilt_before, tilt_after) = (rms(&tilt_error_deg, &initial), rms(&tilt_error_deg, est));
    eprintln!(
        "plane: z RMS {z_before:.4} -> {z_after:.4} m, tilt RMS {tilt_before:.3} -> \
         {tilt_after:.3} deg, unobservable xy RMS {:.4} -> {:.4} m",
        rms(&xy_error, &initial),
        rms(&xy_error, est)
    );
    assert!(z_after < 0.5 * z_before, "z {z_before} -> {z_after}");
    assert!(
        tilt_after < 0.5 * tilt_before,
        "tilt {tilt_before} -> {tilt_after}"
    );
}

/// Views of the world segment x in [-10, 10] m, y = z = 0 from `poses`, in the lidar frame,
/// with uniform jitter of +-`noise_m` in y and z.
fn line_frames(poses: &[Isometry3<f64>], points: usize, noise_m: f64) -> Vec<Vec<Point3<f64>>> {
    use rand::{Rng, SeedableRng, rngs::StdRng};
    let mut rng = StdRng::seed_from_u64(9);
    let jitter = move |rng: &mut StdRng| {
        if noise_m > 0.0 {
            rng.random_range(-noise_m..noise_m)
        } else {
            0.0
        }
    };
    poses
        .iter()
        .map(|pose| {
            (0..points)
                .map(|_| {
                    let x = rng.random_range(-10.0..10.0);
                    let world = Point3::new(x, jitter(&mut rng), jitter(&mut rng));
                    pose.inverse_transform_point(&world)
                })
                .collect()
        })
        .collect()
}

#[test]
fn single_line_has_no_constraints() {
    // Every kernel is rejected, so the first scale has no constraint: a typed error, not a
    // guess. (Noise-free, the kernels have no PCA normal; with 1 cm jitter they get normals
    // but every fit along the line is ill-conditioned.)
    let gt: Vec<Isometry3<f64>> = (0..4)
        .map(|k| {
            Isometry3::from_parts(
                Translation3::new(k as f64 - 1.5, 3.0, 2.0),
                UnitQuaternion::from_euler_angles(0.0, 0.0, 0.3 * k as f64),
            )
        })
        .collect();
    let initial = perturb_poses(&gt, 0.05, 0.3, 11);
    let config = PssBaConfig::default();
    for noise_m in [0.0, 0.01] {
        let frames = line_frames(&gt, 2000, noise_m);
        match adjust(&frames, &initial, &config) {
            Err(CoreError::NoConstraints {
                gamma_m,
                kernels_rejected,
            }) => {
                assert_eq!(gamma_m, config.gamma0_m);
                assert!(kernels_rejected > 0);
            }
            other => panic!("noise {noise_m} m: expected NoConstraints, got {other:?}"),
        }
    }
}

#[test]
fn frames_that_do_not_overlap_have_no_constraints() {
    // Two frames, each seeing a 10 m x 10 m patch of ground 2 m below it, 100 m apart: every
    // kernel is fitted but has no other frame's points (`single_frame`).
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
    let err = adjust(&frames, &poses, &PssBaConfig::default()).expect_err("must be rejected");
    assert!(
        matches!(err, CoreError::NoConstraints { kernels_rejected, .. } if kernels_rejected > 0),
        "{err:?}"
    );
}
