//! Small SO(3)/SE(3) helpers with the paper's conventions: world from lidar poses
//! `p_world = R p_lidar + t`, left perturbations `R <- Exp(dtheta) R`, `t <- t + dt`
//! (paper eq. `Exp`).

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};

/// A world-from-lidar pose as a plain rotation matrix and translation (fast to apply).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Rotation R (world from lidar).
    pub rotation: Matrix3<f64>,
    /// Translation t (lidar origin in world, m).
    pub translation: Vector3<f64>,
}

impl Pose {
    /// Converts from a nalgebra isometry.
    pub fn from_isometry(world_from_lidar: &Isometry3<f64>) -> Self {
        Self {
            rotation: *world_from_lidar.rotation.to_rotation_matrix().matrix(),
            translation: world_from_lidar.translation.vector,
        }
    }

    /// Converts to a nalgebra isometry (re-orthonormalising the rotation).
    pub fn to_isometry(&self) -> Isometry3<f64> {
        let rotation = UnitQuaternion::from_matrix(&self.rotation);
        Isometry3::from_parts(Translation3::from(self.translation), rotation)
    }

    /// Maps a point from the lidar frame to the world.
    #[inline]
    pub fn apply(&self, p_lidar: &Vector3<f64>) -> Vector3<f64> {
        self.rotation * p_lidar + self.translation
    }

    /// Applies the left perturbation `R <- Exp(dtheta) R`, `t <- t + dt`;
    /// `delta = [dtheta (rad); dt (m)]`.
    pub fn perturbed(&self, delta: &[f64]) -> Self {
        let dtheta = Vector3::new(delta[0], delta[1], delta[2]);
        let dt = Vector3::new(delta[3], delta[4], delta[5]);
        Self {
            rotation: exp_so3(&dtheta) * self.rotation,
            translation: self.translation + dt,
        }
    }

    /// True when every entry is finite.
    pub fn is_finite(&self) -> bool {
        self.rotation.iter().all(|v| v.is_finite())
            && self.translation.iter().all(|v| v.is_finite())
    }
}

/// `[v]x`, the cross-product matrix: `[v]x w = v x w`.
#[inline]
pub fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// SO(3) exponential (Rodrigues, paper eq. `Exp`).
#[inline]
pub fn exp_so3(theta: &Vector3<f64>) -> Matrix3<f64> {
    *Rotation3::new(*theta).matrix()
}

/// SO(3) logarithm as a rotation vector (rad).
pub fn log_so3(rotation: &Matrix3<f64>) -> Vector3<f64> {
    Rotation3::from_matrix(rotation).scaled_axis()
}

/// The per-frame change between two pose sets, stacked `[dtheta; dt]` for each frame, and its
/// Euclidean norm (the quantity compared with T_conv).
pub fn pose_change_norm(before: &[Pose], after: &[Pose]) -> f64 {
    before
        .iter()
        .zip(after)
        .map(|(b, a)| {
            let dtheta = log_so3(&(a.rotation * b.rotation.transpose()));
            let dt = a.translation - b.translation;
            dtheta.norm_squared() + dt.norm_squared()
        })
        .sum::<f64>()
        .sqrt()
}

/// Root mean square of the translation change (m) over the frames where `free` is true (0 when
/// none is).
pub fn translation_change_rms_m(before: &[Pose], after: &[Pose], free: &[bool]) -> f64 {
    let (sum, count) = (before.iter().zip(after).zip(free))
        .filter(|(_, free)| **free)
        .fold((0.0, 0usize), |(sum, count), ((b, a), _)| {
            (
                sum + (a.translation - b.translation).norm_squared(),
                count + 1,
            )
        });
    if count == 0 {
        0.0
    } else {
        (sum / count as f64).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp_log_round_trip() {
        let theta = Vector3::new(0.3, -0.2, 0.1);
        let r = exp_so3(&theta);
        assert!((log_so3(&r) - theta).norm() < 1e-12);
        assert!((r * r.transpose() - Matrix3::identity()).norm() < 1e-12);
    }

    #[test]
    fn skew_is_cross_product() {
        let v = Vector3::new(1.0, 2.0, 3.0);
        let w = Vector3::new(-0.5, 0.25, 4.0);
        assert!((skew(&v) * w - v.cross(&w)).norm() < 1e-12);
    }

    #[test]
    fn isometry_round_trip() {
        let iso = Isometry3::new(Vector3::new(1.0, 2.0, 3.0), Vector3::new(0.1, 0.2, -0.3));
        let back = Pose::from_isometry(&iso).to_isometry();
        assert!((back.to_homogeneous() - iso.to_homogeneous()).norm() < 1e-12);
    }
}
