//! Relative point-to-surface residual and its analytic Jacobians (DESIGN step 7).
//!
//! With `a` the surface's frame and `b` the point's frame:
//! `q = R_a^T (R_b p_j + t_b - t_a) - p_i`, `s = M_a q`, `sigma = f(s_x, s_y) - s_z`.
//! With `g = [f_x, f_y, -1]` and `M = M_a R_a^T` (tangent frame in world at the current
//! poses), left perturbations give
//! `d sigma / d(dtheta_b, dt_b) = g^T M [ -[R_b p_j]x , I ]`,
//! `d sigma / d(dtheta_a, dt_a) = g^T M [ [w_j - t_a]x , -I ]`, `w_j` the world point.

#[cfg(test)]
use crate::factor::FactorPoint;
use crate::factor::Surface;
use crate::geometry::Pose;
use crate::kernels::fit::Polynomial;
use nalgebra::{Matrix3, Vector3};

/// A surface at the current pose of its frame `a`: what the residual needs of `a`, computed
/// once per surface instead of once per residual point. With `M = M_a R_a^T`,
/// `s = M_a (R_a^T (w - t_a) - p_i) = M w - (M t_a + M_a p_i)`.
#[derive(Debug, Clone)]
pub struct PlacedSurface<'a> {
    polynomial: &'a Polynomial,
    tangent_from_world: Matrix3<f64>,
    offset: Vector3<f64>,
    /// For [`Self::residual_and_jacobians`].
    #[cfg(test)]
    translation_a: Vector3<f64>,
}

impl<'a> PlacedSurface<'a> {
    /// `surface` with its frame at `pose_a`.
    #[inline]
    pub fn new(surface: &'a Surface, pose_a: &Pose) -> Self {
        let tangent_from_world = surface.tangent_from_lidar * pose_a.rotation.transpose();
        Self {
            polynomial: &surface.polynomial,
            tangent_from_world,
            offset: tangent_from_world * pose_a.translation
                + surface.tangent_from_lidar * surface.kernel_in_lidar,
            #[cfg(test)]
            translation_a: pose_a.translation,
        }
    }

    /// `sigma` of the world point `world` (m).
    #[inline]
    pub fn residual(&self, world: &Vector3<f64>) -> f64 {
        let s = self.tangent_from_world * world - self.offset;
        self.polynomial.height(s.x, s.y) - s.z
    }

    /// `sigma` and `d sigma / d(dtheta_b, dt_b)` of the world point `world` of the frame
    /// whose translation is `translation_b`; `d sigma / d(dtheta_a, dt_a)` follows from it
    /// and `t_b - t_a` (see `normal_equations::PairRun`).
    #[inline]
    pub fn residual_and_point_jacobian(
        &self,
        world: &Vector3<f64>,
        translation_b: &Vector3<f64>,
    ) -> (f64, [f64; 6]) {
        let s = self.tangent_from_world * world - self.offset;
        let sigma = self.polynomial.height(s.x, s.y) - s.z;
        let (fx, fy) = self.polynomial.gradient(s.x, s.y);
        let gm = self.tangent_from_world.transpose() * Vector3::new(fx, fy, -1.0);
        // v^T [u]x = (v x u)^T, so -g^T M [R_b p_j]x = ((w - t_b) x gm)^T.
        let rot_b = (world - translation_b).cross(&gm);
        (sigma, [rot_b.x, rot_b.y, rot_b.z, gm.x, gm.y, gm.z])
    }

    /// `sigma`, `d sigma / d(dtheta_a, dt_a)` and `d sigma / d(dtheta_b, dt_b)` of the world
    /// point `world` of the frame whose translation is `translation_b`: the reference the
    /// tests check against finite differences and the normal equations' sums against.
    #[cfg(test)]
    pub fn residual_and_jacobians(
        &self,
        world: &Vector3<f64>,
        translation_b: &Vector3<f64>,
    ) -> (f64, [f64; 6], [f64; 6]) {
        let (sigma, jac_b) = self.residual_and_point_jacobian(world, translation_b);
        let gm = Vector3::new(jac_b[3], jac_b[4], jac_b[5]);
        let rot_a = gm.cross(&(world - self.translation_a));
        (
            sigma,
            [rot_a.x, rot_a.y, rot_a.z, -gm.x, -gm.y, -gm.z],
            jac_b,
        )
    }
}

/// `sigma_ij = f_i(x_j, y_j) - z_j` (m).
#[cfg(test)]
pub fn residual(surface: &Surface, point: &FactorPoint, pose_a: &Pose, pose_b: &Pose) -> f64 {
    PlacedSurface::new(surface, pose_a).residual(&pose_b.apply(&point.point_in_lidar_m()))
}

/// `sigma`, `d sigma / d(dtheta_a, dt_a)` and `d sigma / d(dtheta_b, dt_b)`.
#[cfg(test)]
pub fn residual_and_jacobians(
    surface: &Surface,
    point: &FactorPoint,
    pose_a: &Pose,
    pose_b: &Pose,
) -> (f64, [f64; 6], [f64; 6]) {
    PlacedSurface::new(surface, pose_a).residual_and_jacobians(
        &pose_b.apply(&point.point_in_lidar_m()),
        &pose_b.translation,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernels::fit::Polynomial;
    use crate::kernels::tangent::tangent_from_world;
    use nalgebra::{Isometry3, Vector3};
    use proptest::prelude::*;

    fn setup(seed: [f64; 12]) -> (Surface, FactorPoint, Pose, Pose) {
        let pose_a = Pose::from_isometry(&Isometry3::new(
            Vector3::new(seed[0], seed[1], seed[2]) * 5.0,
            Vector3::new(seed[3], seed[4], seed[5]),
        ));
        let pose_b = Pose::from_isometry(&Isometry3::new(
            Vector3::new(seed[6], seed[7], seed[8]) * 5.0,
            Vector3::new(seed[9], seed[10], seed[11]),
        ));
        let normal = Vector3::new(seed[1] + 0.1, seed[5], 1.0).normalize();
        let m = tangent_from_world(&normal);
        let surface = Surface {
            frame: 0,
            kernel_in_lidar: Vector3::new(3.0, -1.0, 0.5),
            tangent_from_lidar: m * pose_a.rotation,
            polynomial: Polynomial {
                coefficients: [0.3, -0.2, 0.15, 0.1, -0.05, 0.02],
            },
            gamma_m: 1.0,
        };
        let point = FactorPoint::new(
            0,
            1,
            Vector3::new(seed[2] * 4.0, 2.0 + seed[0], seed[4]),
            1.0,
        );
        (surface, point, pose_a, pose_b)
    }

    proptest! {
        #[test]
        fn jacobians_match_finite_differences(seed in proptest::array::uniform12(-1.0f64..1.0)) {
            let (surface, point, pose_a, pose_b) = setup(seed);
            let (_, jac_a, jac_b) = residual_and_jacobians(&surface, &point, &pose_a, &pose_b);
            let h = 1e-6;
            for k in 0..6 {
                let mut delta = [0.0; 6];
                delta[k] = h;
                let mut minus = [0.0; 6];
                minus[k] = -h;
                let num_a = (residual(&surface, &point, &pose_a.perturbed(&delta), &pose_b)
                    - residual(&surface, &point, &pose_a.perturbed(&minus), &pose_b)) / (2.0 * h);
                let num_b = (residual(&surface, &point, &pose_a, &pose_b.perturbed(&delta))
                    - residual(&surface, &point, &pose_a, &pose_b.perturbed(&minus))) / (2.0 * h);
                prop_assert!((num_a - jac_a[k]).abs() < 1e-5 * (1.0 + num_a.abs()), "a[{k}]: {num_a} vs {}", jac_a[k]);
                prop_assert!((num_b - jac_b[k]).abs() < 1e-5 * (1.0 + num_b.abs()), "b[{k}]: {num_b} vs {}", jac_b[k]);
            }
        }

        #[test]
        fn global_rigid_motion_leaves_residual_unchanged(
            seed in proptest::array::uniform12(-1.0f64..1.0),
            motion in proptest::array::uniform6(-2.0f64..2.0),
        ) {
            let (surface, point, pose_a, pose_b) = setup(seed);
            let before = residual(&surface, &point, &pose_a, &pose_b);
            let g = Isometry3::new(Vector3::new(motion[0], motion[1], motion[2]) * 10.0,
                                   Vector3::new(motion[3], motion[4], motion[5]));
            let moved_a = Pose::from_isometry(&(g * pose_a.to_isometry()));
            let moved_b = Pose::from_isometry(&(g * pose_b.to_isometry()));
            let after = residual(&surface, &point, &moved_a, &moved_b);
            prop_assert!((before - after).abs() < 1e-9, "{before} vs {after}");
        }
    }
}
