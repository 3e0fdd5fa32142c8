//! A plane-rich synthetic scene for BALM: a closed box room with a few boxes inside (two of
//! them turned about z), scanned by ray casting from a sensor moving on an ellipse, with
//! Gaussian range noise. Shared by the tests and the `plane_scene` example.

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng, rngs::StdRng};
use rand_distr::{Distribution, Normal};

/// An oriented box: centre, half extents (m) and yaw (rad) about z.
#[derive(Debug, Clone, Copy)]
pub struct Cuboid {
    pub centre: Vector3<f64>,
    pub half_m: Vector3<f64>,
    pub yaw_rad: f64,
}

impl Cuboid {
    /// Entry and exit ray parameters `(t_in, t_out)` of the ray through the box (slab test).
    fn slabs(&self, origin: &Vector3<f64>, dir: &Vector3<f64>) -> (f64, f64) {
        let to_box = UnitQuaternion::from_euler_angles(0.0, 0.0, -self.yaw_rad);
        let o = to_box * (origin - self.centre);
        let d = to_box * dir;
        let (mut t_in, mut t_out) = (f64::NEG_INFINITY, f64::INFINITY);
        for k in 0..3 {
            let (a, b) = (
                (-self.half_m[k] - o[k]) / d[k],
                (self.half_m[k] - o[k]) / d[k],
            );
            t_in = t_in.max(a.min(b));
            t_out = t_out.min(a.max(b));
        }
        (t_in, t_out)
    }
}

/// The room (seen from inside) and the solid boxes in it.
pub fn room_scene() -> (Cuboid, Vec<Cuboid>) {
    let cuboid = |c: [f64; 3], h: [f64; 3], yaw_deg: f64| Cuboid {
        centre: Vector3::from(c),
        half_m: Vector3::from(h),
        yaw_rad: yaw_deg.to_radians(),
    };
    let room = cuboid([0.0, 0.0, 2.0], [8.0, 6.0, 2.0], 0.0);
    let boxes = vec![
        cuboid([1.5, 0.5, 2.0], [0.5, 0.5, 2.0], 0.0),
        cuboid([-2.0, -0.5, 0.6], [1.0, 0.75, 0.6], 30.0),
        cuboid([2.5, -1.2, 1.0], [0.75, 0.5, 1.0], -20.0),
        cuboid([6.0, 4.5, 0.75], [0.6, 0.6, 0.75], 15.0),
    ];
    (room, boxes)
}

/// True poses on an ellipse (5 m x 3.5 m) at about 1.5 m height, yaw along the path, a small
/// roll/pitch wobble; `frames` poses over three quarters of the loop.
pub fn room_trajectory(frames: usize) -> Vec<Isometry3<f64>> {
    (0..frames)
        .map(|k| {
            let angle = 1.5 * std::f64::consts::PI * k as f64 / frames.max(1) as f64;
            let position = Vector3::new(
                5.0 * angle.cos(),
                3.5 * angle.sin(),
                1.5 + 0.3 * (2.0 * angle).sin(),
            );
            let rotation = UnitQuaternion::from_euler_angles(
                0.04 * (3.0 * angle).sin(),
                0.04 * (2.0 * angle).cos(),
                angle + std::f64::consts::FRAC_PI_2,
            );
            Isometry3::from_parts(Translation3::from(position), rotation)
        })
        .collect()
}

/// Scans the room from each pose: `points_per_frame` rays in random directions with
/// |elevation| < ~58 deg, first hit, range noise `range_noise_m`, points in the lidar frame.
pub fn scan_room(
    poses: &[Isometry3<f64>],
    points_per_frame: usize,
    range_noise_m: f64,
    seed: u64,
) -> Vec<Vec<Point3<f64>>> {
    let (room, boxes) = room_scene();
    let mut rng = StdRng::seed_from_u64(seed);
    let noise = Normal::new(0.0, range_noise_m).expect("finite sigma");
    poses
        .iter()
        .map(|pose| {
            let origin = pose.translation.vector;
            let mut points = Vec::with_capacity(points_per_frame);
            while points.len() < points_per_frame {
                let dir = Vector3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-0.85..0.85),
                );
                if dir.norm() > 1.0 || dir.norm() < 0.1 {
                    continue;
                }
                let dir = dir.normalize();
                let mut range = room.slabs(&origin, &dir).1;
                for b in &boxes {
                    let (t_in, t_out) = b.slabs(&origin, &dir);
                    if t_in > 0.0 && t_in < t_out {
                        range = range.min(t_in);
                    }
                }
                if !(0.5..30.0).contains(&range) {
                    continue;
                }
                let hit = origin + dir * (range + noise.sample(&mut rng));
                points.push(pose.inverse_transform_point(&Point3::from(hit)));
            }
            points
        })
        .collect()
}
