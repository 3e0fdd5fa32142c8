//! Fixtures shared by the integration tests.

pub mod room;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use pssba_balm::cluster::PointCluster;
use pssba_core::geometry::Pose;
use rand::{Rng, SeedableRng, rngs::StdRng};
use rand_distr::{Distribution, Normal};

/// A random pose: rotation from a random rotation vector (|.| < ~2 rad), translation within
/// `spread_m` of the origin.
pub fn random_pose(rng: &mut StdRng, spread_m: f64) -> Pose {
    let mut v = |s: f64| {
        Vector3::new(
            rng.random_range(-s..s),
            rng.random_range(-s..s),
            rng.random_range(-s..s),
        )
    };
    let rotation = UnitQuaternion::from_scaled_axis(v(1.2));
    let translation = v(spread_m);
    Pose::from_isometry(&Isometry3::from_parts(
        Translation3::from(translation),
        rotation,
    ))
}

/// One voxel seen by `frames` frames at random poses: world points near the plane through
/// `(10, -5, 3)` with normal `(0.3, -0.2, 1)` (thickness sigma `thickness_m`) and in-plane
/// extent 1 m, split between frames and expressed in each lidar frame. Returns the poses and
/// each frame's lidar points.
pub fn plane_voxel(
    frames: usize,
    per_frame: usize,
    thickness_m: f64,
    seed: u64,
) -> (Vec<Pose>, Vec<Vec<Vector3<f64>>>) {
    let mut rng = StdRng::seed_from_u64(seed);
    let normal = Vector3::new(0.3, -0.2, 1.0).normalize();
    let e1 = normal.cross(&Vector3::x()).normalize();
    let e2 = normal.cross(&e1);
    let centre = Vector3::new(10.0, -5.0, 3.0);
    let thickness = Normal::new(0.0, thickness_m).expect("sigma");
    let poses: Vec<Pose> = (0..frames).map(|_| random_pose(&mut rng, 20.0)).collect();
    let points = poses
        .iter()
        .map(|pose| {
            (0..per_frame)
                .map(|_| {
                    let world = centre
                        + e1 * rng.random_range(-1.0..1.0)
                        + e2 * rng.random_range(-0.7..0.7)
                        + normal * thickness.sample(&mut rng);
                    pose.rotation.transpose() * (world - pose.translation)
                })
                .collect()
        })
        .collect();
    (poses, points)
}

/// `(frame, cluster)` pairs of per-frame lidar points.
pub fn clusters_of(points: &[Vec<Vector3<f64>>]) -> Vec<(usize, PointCluster)> {
    points
        .iter()
        .enumerate()
        .map(|(k, p)| (k, PointCluster::from_points(p.iter())))
        .collect()
}

/// Runs `f` in a dedicated 4-thread rayon pool (real splitting even on 2 cores).
pub fn in_pool<T: Send>(f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(4)
        .build()
        .expect("rayon pool")
        .install(f)
}
