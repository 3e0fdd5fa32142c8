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

/// `J_l(phi) v`, the SO(3) left Jacobian applied to `v`:
/// `J_l = I + (1 - cos th)/th^2 [phi]x + (th - sin th)/th^3 [phi]x^2`, `th = |phi|`.
#[inline]
pub fn left_jacobian_so3_times(phi: &Vector3<f64>, v: &Vector3<f64>) -> Vector3<f64> {
    let th2 = phi.norm_squared();
    let (a, b) = if th2 < 1e-8 {
        (0.5 - th2 / 24.0, 1.0 / 6.0 - th2 / 120.0)
    } else {
        let th = th2.sqrt();
        ((1.0 - th.cos()) / th2, (th - th.sin()) / (th2 * th))
    };
    let cross = phi.cross(v);
    v + a * cross + b * phi.cross(&cross)
}

/// SE(3) logarithm of the motion `(rotation, translation)` as a twist `(phi, rho)`:
/// `phi = Log(R)`, `rho = J_l(phi)^-1 t`, so that [`exp_se3_apply`] undoes it.
pub fn log_se3(
    rotation: &Matrix3<f64>,
    translation: &Vector3<f64>,
) -> (Vector3<f64>, Vector3<f64>) {
    let phi = log_so3(rotation);
    let th2 = phi.norm_squared();
    // J_l^-1 = I - [phi]x / 2 + c [phi]x^2, c = 1/th^2 - (1 + cos th) / (2 th sin th).
    let c = if th2 < 1e-8 {
        1.0 / 12.0 + th2 / 720.0
    } else {
        let th = th2.sqrt();
        1.0 / th2 - (1.0 + th.cos()) / (2.0 * th * th.sin())
    };
    let cross = phi.cross(translation);
    (phi, translation - 0.5 * cross + c * phi.cross(&cross))
}

/// `Exp(phi, rho) p = Exp(phi) p + J_l(phi) rho`: the point `p` moved by the SE(3)
/// exponential of the twist `(phi, rho)`.
#[inline]
pub fn exp_se3_apply(phi: &Vector3<f64>, rho: &Vector3<f64>, p: &Vector3<f64>) -> Vector3<f64> {
    exp_so3(phi) * p + left_jacobian_so3_times(phi, rho)
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

    /// Exp(Log(T)) = T, and a constant twist's exponential is its screw motion (the limit of
    /// many small steps).
    #[test]
    fn se3_exp_log_round_trip_and_screw_motion() {
        let rotation = exp_so3(&Vector3::new(0.4, -0.9, 1.7));
        let translation = Vector3::new(2.0, -1.0, 0.5);
        let (phi, rho) = log_se3(&rotation, &translation);
        let p = Vector3::new(0.3, 4.0, -2.0);
        let direct = rotation * p + translation;
        assert!((exp_se3_apply(&phi, &rho, &p) - direct).norm() < 1e-10);
        let (w, v) = (Vector3::new(0.1, 0.2, 1.1), Vector3::new(3.0, 0.1, -0.2));
        let steps = 20000;
        let (mut r, mut t) = (Matrix3::identity(), Vector3::zeros());
        for _ in 0..steps {
            let h = 1.0 / f64::from(steps);
            t += r * (h * v);
            r *= exp_so3(&(h * w));
        }
        assert!((exp_se3_apply(&w, &v, &p) - (r * p + t)).norm() < 1e-3);
        let small = log_se3(&exp_so3(&Vector3::new(1e-6, 0.0, 0.0)), &translation);
        assert!((small.1 - translation).norm() < 1e-5);
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
