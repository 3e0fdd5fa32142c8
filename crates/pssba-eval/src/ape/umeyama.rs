//! Rigid (SE(3), no scale) least-squares alignment of two point sets after
//! Umeyama, "Least-squares estimation of transformation parameters between
//! two point patterns", IEEE PAMI 13(4), 1991 — the same algorithm as evo's
//! `geometry.umeyama_alignment(x, y, with_scale=False)`.

use nalgebra::{DMatrix, Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};

use crate::EvalError;

/// Minimum number of point pairs accepted by [`umeyama_se3`].
pub const MIN_POINTS: usize = 3;

/// Singular values at or below this *absolute* threshold count as zero; this
/// is evo's `np.finfo(float).eps` rank test.
const ABS_RANK_EPS: f64 = f64::EPSILON;

/// Additional *relative* rank test (not in evo): `σ₂ <= REL_RANK_EPS · σ₁`
/// means the points are numerically collinear. evo's purely absolute test
/// accepts exactly collinear points with large coordinates (round-off makes
/// `σ₂ ≈ 1e-16·σ₁ > eps`) and then returns an arbitrary rotation about the
/// line; such inputs are rejected here. Anything evo rejects is rejected too.
const REL_RANK_EPS: f64 = 1e-12;

/// Iteration budget of the SVD (nalgebra's `svd()` uses an unbounded loop).
const SVD_MAX_ITERATIONS: usize = 10_000;

/// Finds the rigid motion `T = (R, t)` minimising `Σ‖dst_i − (R·src_i + t)‖²`,
/// i.e. `dst ≈ T * src`.
///
/// With means `μ_s = (1/n)Σ src_i`, `μ_d = (1/n)Σ dst_i` (Umeyama eq. 34/35)
/// and the cross-covariance `Σ_ds = (1/n)Σ (dst_i − μ_d)(src_i − μ_s)ᵀ`
/// (eq. 38) with SVD `Σ_ds = U D Vᵀ`:
/// * `S = diag(1, 1, −1)` if `det(U)·det(V) < 0`, else `I` (eq. 43, the
///   reflection correction),
/// * `R = U S Vᵀ` (eq. 40), `t = μ_d − R μ_s` (eq. 41 with scale `c = 1`).
///
/// # Errors
/// * [`EvalError::LengthMismatch`] if `src` and `dst` differ in length,
/// * [`EvalError::TooFewPoints`] for fewer than [`MIN_POINTS`] pairs,
/// * [`EvalError::NonFinite`] for a NaN/∞ coordinate,
/// * [`EvalError::DegenerateAlignment`] if `Σ_ds` has rank < 2, i.e. the
///   points coincide or are collinear. evo raises `GeometryException
///   ("Degenerate covariance rank, Umeyama alignment is not possible")` when
///   fewer than 2 singular values exceed machine epsilon (which also covers
///   n < 3, evo has no separate count check); this function applies that
///   test plus the relative test described at `REL_RANK_EPS`. Planar point
///   sets (rank 2) are fine: the reflection correction fixes the rotation.
/// * [`EvalError::SvdFailed`] if the SVD does not converge.
pub fn umeyama_se3(
    src: &[Vector3<f64>],
    dst: &[Vector3<f64>],
) -> Result<Isometry3<f64>, EvalError> {
    if src.len() != dst.len() {
        return Err(EvalError::LengthMismatch {
            left_name: "source points",
            left: src.len(),
            right_name: "destination points",
            right: dst.len(),
        });
    }
    if src.len() < MIN_POINTS {
        return Err(EvalError::TooFewPoints {
            got: src.len(),
            required: MIN_POINTS,
        });
    }
    check_finite(src, "source point")?;
    check_finite(dst, "destination point")?;

    let inv_n = 1.0 / src.len() as f64;
    let mean_src = src.iter().sum::<Vector3<f64>>() * inv_n;
    let mean_dst = dst.iter().sum::<Vector3<f64>>() * inv_n;
    let mut outer_sum = Matrix3::zeros();
    for (s, d) in src.iter().zip(dst) {
        outer_sum += (d - mean_dst) * (s - mean_src).transpose();
    }
    let cov = outer_sum * inv_n;

    // A dynamically sized matrix on purpose: nalgebra routes `Matrix3` SVDs to
    // an eigen-decomposition of ΣᵀΣ, which squares the condition number; the
    // general Golub–Kahan path is accurate for the small singular values the
    // rank test looks at.
    let svd = DMatrix::from_column_slice(3, 3, cov.as_slice())
        .try_svd(true, true, f64::EPSILON * 5.0, SVD_MAX_ITERATIONS)
        .ok_or(EvalError::SvdFailed {
            max_iterations: SVD_MAX_ITERATIONS,
        })?;
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Err(EvalError::SvdFailed {
            max_iterations: SVD_MAX_ITERATIONS,
        });
    };
    // `try_svd` sorts the singular values in descending order.
    let d = [
        svd.singular_values[0],
        svd.singular_values[1],
        svd.singular_values[2],
    ];
    let rank = d.iter().filter(|&&s| s > ABS_RANK_EPS).count();
    if rank < 2 || d[1] <= REL_RANK_EPS * d[0] {
        return Err(EvalError::DegenerateAlignment { singular_values: d });
    }

    let u = Matrix3::from_column_slice(u.as_slice());
    let v_t = Matrix3::from_column_slice(v_t.as_slice());
    let mut s = Matrix3::identity();
    if u.determinant() * v_t.determinant() < 0.0 {
        s[(2, 2)] = -1.0;
    }
    let r = u * s * v_t;
    let t = mean_dst - r * mean_src;
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    Ok(Isometry3::from_parts(Translation3::from(t), rotation))
}

/// Rejects the first point with a NaN or infinite coordinate.
fn check_finite(points: &[Vector3<f64>], what: &'static str) -> Result<(), EvalError> {
    match points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        Some(index) => Err(EvalError::NonFinite { what, index }),
        None => Ok(()),
    }
}
