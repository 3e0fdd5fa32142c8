//! The smallest eigenpair of a symmetric 3 x 3 matrix in closed form, for the PCA normals
//! (DESIGN step 2): one per occupied voxel at every scale, so nalgebra's iterative
//! `SymmetricEigen` (tridiagonalisation, then QR sweeps) was 7 % of a 100-frame run's CPU.
//!
//! Eigenvalues by the trigonometric solution of the characteristic cubic (O. K. Smith,
//! "Eigenvalues of a symmetric 3 x 3 matrix", CACM 1961); the eigenvector of the smallest as
//! the longest cross product of two rows of `A - lambda I`, which spans its null space when
//! that eigenvalue is simple. Where it is not (two smallest equal: a line, a blob), the
//! caller falls back to the iterative solver.

use nalgebra::{Matrix3, Vector3};

/// Eigenvalues of `a` in ascending order and a unit eigenvector of the smallest, `None`
/// when the smallest eigenvalue is not clearly simple or `a` is not finite.
pub fn smallest_eigenpair(a: &Matrix3<f64>) -> Option<([f64; 3], Vector3<f64>)> {
    // Scaled to entries of order one, so the cubic's terms neither overflow nor vanish.
    let scale = a.amax();
    if !(scale.is_finite() && scale > 0.0) {
        return None;
    }
    let m = a / scale;
    let off_sq = m[(0, 1)].powi(2) + m[(0, 2)].powi(2) + m[(1, 2)].powi(2);
    let q = m.trace() / 3.0;
    let diag_dev_sq = (m[(0, 0)] - q).powi(2) + (m[(1, 1)] - q).powi(2) + (m[(2, 2)] - q).powi(2);
    let p = ((diag_dev_sq + 2.0 * off_sq) / 6.0).sqrt();
    if p == 0.0 {
        // A multiple of the identity: every direction is an eigenvector.
        return None;
    }
    // The eigenvalues of B = (M - q I) / p are 2 cos(phi + 2 pi k / 3), det B = 2 cos(3 phi).
    let b = (m - Matrix3::identity() * q) / p;
    let half_det = (b.determinant() / 2.0).clamp(-1.0, 1.0);
    let phi = half_det.acos() / 3.0;
    let largest = q + 2.0 * p * phi.cos();
    let smallest = q + 2.0 * p * (phi + 2.0 * std::f64::consts::FRAC_PI_3).cos();
    let middle = 3.0 * q - largest - smallest;
    // Null vector of M - smallest I from its rows.
    let shifted = m - Matrix3::identity() * smallest;
    let (r0, r1, r2) = (
        shifted.row(0).transpose(),
        shifted.row(1).transpose(),
        shifted.row(2).transpose(),
    );
    let crosses = [r0.cross(&r1), r0.cross(&r2), r1.cross(&r2)];
    let best = crosses
        .iter()
        .max_by(|x, y| x.norm_squared().total_cmp(&y.norm_squared()))
        .expect("three candidates");
    // In theory the longest of the three is at least gap^2 / sqrt(3) long (their squared
    // lengths sum to the product of the squared gaps to the other two eigenvalues).
    let gap = middle - smallest;
    if !(gap > 1e-6 && best.norm_squared() > 0.1 * gap.powi(4)) {
        return None;
    }
    let values = [smallest * scale, middle * scale, largest * scale];
    Some((values, best.normalize()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Rotation3, SymmetricEigen};
    use rand::{Rng, SeedableRng, rngs::StdRng};

    /// `R diag(values) R^T` for a random rotation R.
    fn with_eigenvalues(values: [f64; 3], rng: &mut StdRng) -> (Matrix3<f64>, Rotation3<f64>) {
        let axis = Vector3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        );
        let rotation = Rotation3::new(axis * rng.random_range(0.0..3.0));
        let r = rotation.matrix();
        (
            r * Matrix3::from_diagonal(&Vector3::from(values)) * r.transpose(),
            rotation,
        )
    }

    #[test]
    fn matches_the_iterative_solver_on_plane_like_spreads() {
        let mut rng = StdRng::seed_from_u64(11);
        for _ in 0..2000 {
            // A patch: two spreads of 1e-3..10 m^2, a thickness down to 1e-9 of them.
            let big = rng.random_range(1e-3..10.0);
            let mid = big * rng.random_range(0.05..1.0);
            let small = mid * rng.random_range(1e-9..0.5);
            let (a, _) = with_eigenvalues([big, mid, small], &mut rng);
            let (values, v) = smallest_eigenpair(&a).expect("simple smallest eigenvalue");
            let reference = SymmetricEigen::new(a);
            let k = reference.eigenvalues.imin();
            let v_ref = reference.eigenvectors.column(k);
            assert!((v.dot(&v_ref).abs() - 1.0).abs() < 1e-9, "{a} {v} {v_ref}");
            let mut sorted: Vec<f64> = reference.eigenvalues.iter().copied().collect();
            sorted.sort_by(f64::total_cmp);
            for (x, y) in values.iter().zip(&sorted) {
                assert!((x - y).abs() <= 1e-12 * big, "{values:?} {sorted:?}");
            }
            assert!(((a * v) - v * values[0]).norm() <= 1e-10 * big);
        }
    }

    #[test]
    fn a_repeated_smallest_eigenvalue_is_left_to_the_caller() {
        let mut rng = StdRng::seed_from_u64(12);
        // A line (two vanishing spreads), a round blob, a disc seen edge-on twice.
        for values in [[4.0, 0.0, 0.0], [1.0, 1.0, 1.0], [2.0, 0.5, 0.5]] {
            let (a, _) = with_eigenvalues(values, &mut rng);
            assert!(smallest_eigenpair(&a).is_none(), "{values:?}");
        }
        assert!(smallest_eigenpair(&Matrix3::zeros()).is_none());
        assert!(smallest_eigenpair(&Matrix3::from_element(f64::NAN)).is_none());
    }

    #[test]
    fn diagonal_matrices_give_the_axis_of_the_smallest_entry() {
        let a = Matrix3::from_diagonal(&Vector3::new(3.0, 0.01, 2.0));
        let (values, v) = smallest_eigenpair(&a).expect("simple");
        assert!((v.y.abs() - 1.0).abs() < 1e-12);
        assert!((values[0] - 0.01).abs() < 1e-12 && (values[2] - 3.0).abs() < 1e-12);
    }
}
