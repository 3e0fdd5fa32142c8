//! Bad input gives a typed error or is skipped, never a panic or a NaN pose.

use crate::common::room::{room_trajectory, scan_room};
use nalgebra::{Isometry3, Point3, Vector3};
use pssba_balm::{BalmConfig, BalmError, Parallelism, adjust};
use pssba_sim::perturb_poses;

fn run(
    frames: &[Vec<Point3<f64>>],
    poses: &[Isometry3<f64>],
) -> Result<pssba_balm::BalmResult, BalmError> {
    adjust(frames, poses, &BalmConfig::default(), Parallelism::Serial)
}

fn scene(frames: usize) -> (Vec<Vec<Point3<f64>>>, Vec<Isometry3<f64>>) {
    let truth = room_trajectory(frames);
    (
        scan_room(&truth, 2000, 0.02, 9),
        perturb_poses(&truth, 0.05, 0.3, 9),
    )
}

fn all_finite(poses: &[Isometry3<f64>]) -> bool {
    poses
        .iter()
        .all(|p| p.to_homogeneous().iter().all(|v| v.is_finite()))
}

#[test]
fn count_mismatch_and_too_few_frames() {
    let (frames, poses) = scene(3);
    assert_eq!(
        run(&frames, &poses[..2]),
        Err(BalmError::CountMismatch {
            frames: 3,
            poses: 2
        })
    );
    assert_eq!(
        run(&frames[..1], &poses[..1]),
        Err(BalmError::TooFewFrames(1))
    );
    assert_eq!(run(&[], &[]), Err(BalmError::TooFewFrames(0)));
}

#[test]
fn non_finite_pose_is_rejected() {
    let (frames, mut poses) = scene(3);
    poses[2].translation.vector.y = f64::NAN;
    assert_eq!(
        run(&frames, &poses),
        Err(BalmError::NonFinitePose { frame: 2 })
    );
}

#[test]
fn non_finite_points_are_dropped_and_counted() {
    let (mut frames, poses) = scene(4);
    frames[1].push(Point3::new(f64::NAN, 0.0, 0.0));
    frames[3].push(Point3::new(1.0, f64::INFINITY, 0.0));
    let result = run(&frames, &poses).expect("runs");
    assert_eq!(result.dropped_nonfinite_points, 2);
    assert!(all_finite(&result.world_from_lidar));
}

#[test]
fn empty_frames_keep_their_pose() {
    let (mut frames, poses) = scene(4);
    frames[2].clear();
    let result = run(&frames, &poses).expect("runs");
    assert_eq!(result.empty_frames, vec![2]);
    let moved = result.world_from_lidar[2].translation.vector - poses[2].translation.vector;
    assert!(moved.norm() < 1e-9, "empty frame moved by {moved}");
    assert!(all_finite(&result.world_from_lidar));
}

#[test]
fn no_plane_voxels_is_a_typed_error() {
    let poses = vec![Isometry3::identity(); 3];
    // All frames empty.
    assert!(matches!(
        run(&vec![Vec::new(); 3], &poses),
        Err(BalmError::NoPlaneVoxels { .. })
    ));
    // Points on a line (never planar), and frames far apart (no shared voxel).
    let line: Vec<Point3<f64>> = (0..500)
        .map(|i| Point3::new(i as f64 * 0.003, 0.0, 0.0))
        .collect();
    assert!(matches!(
        run(&vec![line; 3], &poses),
        Err(BalmError::NoPlaneVoxels { .. })
    ));
    let (frames, _) = scene(3);
    let apart: Vec<Isometry3<f64>> = (0..3)
        .map(|k| Isometry3::translation(100.0 * k as f64, 0.0, 0.0))
        .collect();
    assert!(matches!(
        run(&frames, &apart),
        Err(BalmError::NoPlaneVoxels { .. })
    ));
}

#[test]
fn identical_frames_at_identical_poses_do_not_produce_nan() {
    // A degenerate but valid input: the cost is already minimal.
    let (frames, _) = scene(1);
    let frames = vec![frames[0].clone(); 3];
    let poses = vec![Isometry3::new(Vector3::new(1.0, 2.0, 0.0), Vector3::z() * 0.3); 3];
    let result = run(&frames, &poses).expect("runs");
    assert!(all_finite(&result.world_from_lidar));
}
