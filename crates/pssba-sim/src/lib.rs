//! Synthetic data for PSS-BA tests, the demo and benchmarks (DESIGN.md section 4).
//!
//! Two generators:
//! - **Ray-cast sequences** ([`simulate_scene`]): a Livox Mid-360-like sensor ([`Mid360`])
//!   ray-cast against triangle meshes ([`TriangleMesh`], [`Raycaster`]) along UAV-like
//!   trajectories ([`TrajectorySpec`]), in built-in procedural scenes ([`BuiltinScene`]) or
//!   any mesh ([`Scene::from_mesh`]); initial poses are the ground truth with seeded noise.
//!   File-free: `pssba simulate` reads STL and writes the dataset folder.
//! - **Sampled windows** ([`curved_window`]): points sampled on analytic curved surfaces as
//!   seen from an orbit, with range noise. No ray casting: a point is seen when it is in
//!   range and faces the sensor (self-occlusion only). Fast, for unit tests and the demo.

mod drift;
mod mesh;
mod mid360;
mod raycast;
mod scenes;
mod shapes;
mod simulation;
mod trajectory;

pub use drift::{OdometryDrift, drift_poses};
pub use mesh::{Aabb, TriangleMesh};
pub use mid360::{Mid360, pattern_deg};
pub use raycast::{RaycastError, Raycaster};
pub use scenes::{
    BuiltinScene, CLEARANCE_M, REVISIT_TURN_RADIUS_M, SURVEY_ROW_SPACING_M, SURVEY_ROWS, Scene,
    path_is_free, revisit_frames, revisit_scene, survey_frames, survey_scene,
};
pub use shapes::Shape;
pub use simulation::{
    PoseNoise, SceneScanner, SimulatedDataset, SimulationError, SimulationSpec, simulate_scene,
    simulate_scene_with_progress,
};
pub use trajectory::{TrajectoryKind, TrajectorySpec};

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng, rngs::StdRng};
use rand_distr::{Distribution, Normal};

/// Size and noise of a synthetic window.
#[derive(Debug, Clone, Copy)]
pub struct SceneSpec {
    /// Number of frames (poses along the orbit).
    pub frames: usize,
    /// Points per frame.
    pub points_per_frame: usize,
    /// Range noise sigma (m) along each ray.
    pub range_noise_m: f64,
    /// Largest range (m).
    pub max_range_m: f64,
    /// Seed of every random draw.
    pub seed: u64,
}

impl Default for SceneSpec {
    fn default() -> Self {
        Self {
            frames: 20,
            points_per_frame: 8000,
            range_noise_m: 0.02,
            max_range_m: 30.0,
            seed: 1,
        }
    }
}

/// A simulated window: frames in the sensor frame and their true poses.
#[derive(Debug, Clone)]
pub struct SimulatedWindow {
    /// Points of each frame in its lidar frame (m).
    pub frames: Vec<Vec<Point3<f64>>>,
    /// True world-from-lidar poses.
    pub ground_truth: Vec<Isometry3<f64>>,
    /// Time stamps (s), 10 Hz.
    pub stamps: Vec<f64>,
}

/// The built-in curved scene: a paraboloid ground, two spheres, a vertical and a horizontal
/// cylinder and a torus, all within about 12 m of the origin.
pub fn curved_shapes() -> Vec<Shape> {
    vec![
        Shape::Bowl {
            curvature: 0.01,
            extent_m: 14.0,
        },
        Shape::Sphere {
            centre: Point3::new(4.0, 3.0, 1.5),
            radius_m: 1.5,
        },
        Shape::Sphere {
            centre: Point3::new(-5.0, -2.0, 2.5),
            radius_m: 2.0,
        },
        Shape::Cylinder {
            base: Point3::new(-2.0, 6.0, 0.0),
            axis: Vector3::z(),
            length_m: 4.0,
            radius_m: 1.0,
        },
        Shape::Cylinder {
            base: Point3::new(-3.0, -7.0, 1.2),
            axis: Vector3::x(),
            length_m: 6.0,
            radius_m: 1.2,
        },
        Shape::Torus {
            centre: Point3::new(6.0, -4.0, 0.8),
            major_m: 2.0,
            minor_m: 0.6,
        },
    ]
}

/// True poses on an orbit of radius 9 m around the scene at 2.5 m, yaw along the path, a
/// gentle roll/pitch wobble; `frames` poses over about three quarters of the circle.
pub fn orbit_poses(frames: usize) -> Vec<Isometry3<f64>> {
    (0..frames)
        .map(|k| {
            let s = k as f64 / frames.max(1) as f64;
            let angle = 1.5 * std::f64::consts::PI * s;
            let position = Vector3::new(
                9.0 * angle.cos(),
                9.0 * angle.sin(),
                2.5 + 0.5 * (3.0 * angle).sin(),
            );
            let yaw = angle + std::f64::consts::FRAC_PI_2;
            let rotation = UnitQuaternion::from_euler_angles(
                0.05 * (5.0 * angle).sin(),
                0.05 * (4.0 * angle).cos(),
                yaw,
            );
            Isometry3::from_parts(Translation3::from(position), rotation)
        })
        .collect()
}

/// Samples each frame: area-proportional points on `shapes`, kept when within range and facing
/// the sensor, with Gaussian range noise along the ray, in the sensor frame.
pub fn simulate(shapes: &[Shape], poses: &[Isometry3<f64>], spec: &SceneSpec) -> SimulatedWindow {
    let mut rng = StdRng::seed_from_u64(spec.seed);
    let noise = Normal::new(0.0, spec.range_noise_m.max(0.0))
        .unwrap_or_else(|_| Normal::new(0.0, 0.0).expect("zero sigma"));
    let total_area: f64 = shapes.iter().map(Shape::area_m2).sum();
    let frames = poses
        .iter()
        .map(|pose| {
            let origin = Point3::from(pose.translation.vector);
            let mut points = Vec::with_capacity(spec.points_per_frame);
            let mut attempts = 0usize;
            while points.len() < spec.points_per_frame && attempts < spec.points_per_frame * 200 {
                attempts += 1;
                let mut pick = rng.random_range(0.0..total_area);
                let shape = shapes.iter().find(|s| {
                    pick -= s.area_m2();
                    pick <= 0.0
                });
                let Some(shape) = shape.or(shapes.last()) else {
                    break;
                };
                let (p, n) = shape.sample(&mut rng);
                let ray = p - origin;
                let range = ray.norm();
                if range < 0.5 || range > spec.max_range_m || n.dot(&ray) >= 0.0 {
                    continue;
                }
                let noisy = origin + ray * ((range + noise.sample(&mut rng)) / range);
                points.push(pose.inverse_transform_point(&noisy));
            }
            points
        })
        .collect();
    SimulatedWindow {
        frames,
        ground_truth: poses.to_vec(),
        stamps: (0..poses.len()).map(|k| k as f64 * 0.1).collect(),
    }
}

/// The default curved window: [`curved_shapes`] seen from [`orbit_poses`].
pub fn curved_window(spec: &SceneSpec) -> SimulatedWindow {
    simulate(&curved_shapes(), &orbit_poses(spec.frames), spec)
}

/// Gaussian pose noise with the given RMS (translation m, rotation deg), i.e. per-axis sigma
/// `rms / sqrt(3)`, applied as `R <- Exp(dtheta) R`, `t <- t + dt`. Seeded.
pub fn perturb_poses(
    poses: &[Isometry3<f64>],
    translation_rms_m: f64,
    rotation_rms_deg: f64,
    seed: u64,
) -> Vec<Isometry3<f64>> {
    let mut rng = StdRng::seed_from_u64(seed);
    let sigma_t = translation_rms_m / 3f64.sqrt();
    let sigma_r = rotation_rms_deg.to_radians() / 3f64.sqrt();
    let mut gauss = |sigma: f64| -> Vector3<f64> {
        let n = Normal::new(0.0, sigma.max(0.0))
            .unwrap_or_else(|_| Normal::new(0.0, 0.0).expect("zero sigma"));
        Vector3::new(n.sample(&mut rng), n.sample(&mut rng), n.sample(&mut rng))
    };
    poses
        .iter()
        .map(|pose| {
            let dtheta = gauss(sigma_r);
            let dt = gauss(sigma_t);
            let rotation = UnitQuaternion::from_scaled_axis(dtheta) * pose.rotation;
            Isometry3::from_parts(Translation3::from(pose.translation.vector + dt), rotation)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deterministic_for_a_seed() {
        let spec = SceneSpec {
            frames: 3,
            points_per_frame: 500,
            ..SceneSpec::default()
        };
        let a = curved_window(&spec);
        let b = curved_window(&spec);
        assert_eq!(a.frames, b.frames);
        assert!(a.frames.iter().all(|f| f.len() == 500));
    }

    #[test]
    fn perturbation_has_requested_rms() {
        let gt = orbit_poses(2000);
        let noisy = perturb_poses(&gt, 0.2, 1.0, 3);
        let (mut t, mut r) = (0.0, 0.0);
        for (a, b) in gt.iter().zip(&noisy) {
            t += (a.translation.vector - b.translation.vector).norm_squared();
            r += (b.rotation * a.rotation.inverse()).angle().powi(2);
        }
        let n = gt.len() as f64;
        assert!(((t / n).sqrt() - 0.2).abs() < 0.01);
        assert!(((r / n).sqrt().to_degrees() - 1.0).abs() < 0.05);
    }
}
