//! Initial poses as a LiDAR-inertial odometry gives them: each frame-to-frame increment of
//! the true trajectory with a small seeded error, accumulated, so the error is a random walk
//! that grows with the flight (gravity keeps roll and pitch from drifting as far as yaw).

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rand::{SeedableRng, rngs::StdRng};
use rand_distr::{Distribution, Normal};

/// Per-frame sigmas of the increment errors.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdometryDrift {
    /// Translation error per frame and axis (m), in the sensor frame.
    pub translation_m: f64,
    /// Yaw error per frame (deg).
    pub yaw_deg: f64,
    /// Roll and pitch error per frame (deg).
    pub tilt_deg: f64,
}

impl Default for OdometryDrift {
    /// About 0.3-0.6 m and 1 deg after 2000 frames (200 s at 10 Hz), as the held-out flights
    /// of issue 38 drift.
    fn default() -> Self {
        Self {
            translation_m: 0.004,
            yaw_deg: 0.012,
            tilt_deg: 0.002,
        }
    }
}

/// `ground_truth` with the drift of `drift` accumulated from frame 0 (which stays exact).
pub fn drift_poses(
    ground_truth: &[Isometry3<f64>],
    drift: OdometryDrift,
    seed: u64,
) -> Vec<Isometry3<f64>> {
    let mut rng = StdRng::seed_from_u64(seed);
    let normal = |sigma: f64| {
        Normal::new(0.0, sigma.abs()).unwrap_or_else(|_| Normal::new(0.0, 0.0).expect("zero sigma"))
    };
    let (t, yaw, tilt) = (
        normal(drift.translation_m),
        normal(drift.yaw_deg.to_radians()),
        normal(drift.tilt_deg.to_radians()),
    );
    let mut poses = Vec::with_capacity(ground_truth.len());
    let Some(first) = ground_truth.first() else {
        return poses;
    };
    poses.push(*first);
    for pair in ground_truth.windows(2) {
        let increment = pair[0].inverse() * pair[1];
        let error_t = Vector3::new(t.sample(&mut rng), t.sample(&mut rng), t.sample(&mut rng));
        let error_r = UnitQuaternion::from_euler_angles(
            tilt.sample(&mut rng),
            tilt.sample(&mut rng),
            yaw.sample(&mut rng),
        );
        let error = Isometry3::from_parts(Translation3::from(error_t), error_r);
        let previous = poses[poses.len() - 1];
        poses.push(previous * increment * error);
    }
    poses
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn drift_grows_like_a_random_walk_and_is_seeded() {
        let truth: Vec<_> = (0..2000)
            .map(|k| Isometry3::translation(0.15 * k as f64, 0.0, 3.0))
            .collect();
        let a = drift_poses(&truth, OdometryDrift::default(), 3);
        assert_eq!(a, drift_poses(&truth, OdometryDrift::default(), 3));
        assert_eq!(a[0], truth[0]);
        let error_m = |k: usize| (a[k].translation.vector - truth[k].translation.vector).norm();
        assert!(error_m(10) < 0.05, "{}", error_m(10));
        assert!((0.1..5.0).contains(&error_m(1999)), "{}", error_m(1999));
        // Consecutive frames stay close: the error is in the increments, not per frame.
        let step = (a[1001].translation.vector - a[1000].translation.vector).norm();
        assert!((step - 0.15).abs() < 0.05, "{step}");
    }
}
