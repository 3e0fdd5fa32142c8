//! The point-cluster cost equals the cost over raw points, and a rigid motion of all poses
//! leaves it unchanged.

use crate::common::{clusters_of, plane_voxel, random_pose};
use nalgebra::{Matrix3, Vector3};
use pssba_balm::cluster::sorted_eigen;
use pssba_balm::derivatives::voxel_cost;
use pssba_balm::normal_equations::total_cost;
use pssba_balm::voxel::PlaneVoxel;
use pssba_core::geometry::Pose;
use rand::{SeedableRng, rngs::StdRng};

/// `N lambda_min` of the covariance of all raw points moved into the world.
fn raw_cost(points: &[Vec<Vector3<f64>>], poses: &[Pose]) -> f64 {
    let world: Vec<Vector3<f64>> = points
        .iter()
        .zip(poses)
        .flat_map(|(f, pose)| f.iter().map(|p| pose.apply(p)))
        .collect();
    let n = world.len() as f64;
    let mean = world.iter().sum::<Vector3<f64>>() / n;
    let covariance = world.iter().fold(Matrix3::zeros(), |acc, p| {
        acc + (p - mean) * (p - mean).transpose()
    }) / n;
    n * sorted_eigen(&covariance).0[0]
}

#[test]
fn cluster_cost_equals_raw_point_cost() {
    for seed in 0..5 {
        let (poses, points) = plane_voxel(4, 80, 0.03, seed);
        let clusters = clusters_of(&points);
        // At the poses the points were made with, and at unrelated poses.
        let mut rng = StdRng::seed_from_u64(100 + seed);
        let other: Vec<Pose> = (0..4).map(|_| random_pose(&mut rng, 20.0)).collect();
        for p in [&poses, &other] {
            let (cluster, raw) = (voxel_cost(&clusters, p), raw_cost(&points, p));
            assert!(
                (cluster - raw).abs() <= 1e-9 * raw.max(1e-12),
                "{cluster} vs {raw}"
            );
        }
    }
}

#[test]
fn rigid_motion_of_all_poses_leaves_the_cost_unchanged() {
    let mut rng = StdRng::seed_from_u64(5);
    let voxels: Vec<PlaneVoxel> = (0..4)
        .map(|seed| {
            let (_, points) = plane_voxel(6, 40, 0.05, seed);
            PlaneVoxel {
                layer: 0,
                clusters: clusters_of(&points),
            }
        })
        .collect();
    let poses: Vec<Pose> = (0..6).map(|_| random_pose(&mut rng, 20.0)).collect();
    let before = total_cost(&voxels, &poses, pssba_balm::Parallelism::Serial);
    for _ in 0..5 {
        let motion = random_pose(&mut rng, 50.0);
        let moved: Vec<Pose> = poses
            .iter()
            .map(|p| Pose {
                rotation: motion.rotation * p.rotation,
                translation: motion.apply(&p.translation),
            })
            .collect();
        let after = total_cost(&voxels, &moved, pssba_balm::Parallelism::Serial);
        assert!(
            (after - before).abs() < 1e-9 * before,
            "{before} -> {after}"
        );
    }
}
