//! The kernel's local tangent frame F^S (paper: `n2 = n, n1 = [n_y, -n_x, 0], n0 = n1 x n2`).

use nalgebra::{Matrix3, Vector3};

/// Below this `n_x^2 + n_y^2` the paper's `n1` is (nearly) zero: the normal is (nearly)
/// vertical, the most common case (ground, roofs), so another axis is used.
const VERTICAL_EPS: f64 = 1e-6;

/// Rows `[n0; n1; n2]` of the matrix M that maps world offsets into the tangent frame:
/// orthonormal, right-handed, third row = `normal`. `normal` must be unit length.
pub fn tangent_from_world(normal: &Vector3<f64>) -> Matrix3<f64> {
    let n2 = *normal;
    let horizontal = n2.x * n2.x + n2.y * n2.y;
    let n1 = if horizontal > VERTICAL_EPS {
        Vector3::new(n2.y, -n2.x, 0.0) / horizontal.sqrt()
    } else {
        // Vertical normal: project the world y axis onto the tangent plane instead.
        let y = Vector3::y();
        (y - n2 * n2.dot(&y)).normalize()
    };
    let n0 = n1.cross(&n2);
    Matrix3::from_rows(&[n0.transpose(), n1.transpose(), n2.transpose()])
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn assert_orthonormal_right_handed(m: &Matrix3<f64>, normal: &Vector3<f64>) {
        assert!(
            (m * m.transpose() - Matrix3::identity()).norm() < 1e-9,
            "{m}"
        );
        assert!((m.determinant() - 1.0).abs() < 1e-9);
        assert!((m.row(2).transpose() - normal).norm() < 1e-12);
    }

    #[test]
    fn exactly_vertical_normals() {
        for n in [Vector3::z(), -Vector3::z()] {
            assert_orthonormal_right_handed(&tangent_from_world(&n), &n);
        }
    }

    #[test]
    fn nearly_vertical_normals() {
        for eps in [1e-12, 1e-8, 1e-4, 1e-3] {
            let n = Vector3::new(eps, -eps, 1.0).normalize();
            assert_orthonormal_right_handed(&tangent_from_world(&n), &n);
        }
    }

    proptest! {
        #[test]
        fn random_normals(x in -1.0f64..1.0, y in -1.0f64..1.0, z in -1.0f64..1.0) {
            let v = Vector3::new(x, y, z);
            prop_assume!(v.norm() > 1e-3);
            let n = v.normalize();
            assert_orthonormal_right_handed(&tangent_from_world(&n), &n);
        }
    }
}
