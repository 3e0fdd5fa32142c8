//! Weighted polynomial surface fit in the kernel's tangent frame (paper eq. `polynomial` and
//! the weighted least squares after it).
//!
//! `z = f(x, y) = a0 x^2 + a1 y^2 + a2 x y + a3 x + a4 y + a5`. The paper lists five
//! coefficients in one place and six in another; we keep the constant `a5`, which absorbs the
//! kernel point's own noise. The planar model (Point2Plane ablation) keeps `a3, a4, a5`.

use nalgebra::allocator::Allocator;
use nalgebra::{DefaultAllocator, DimDiff, DimName, DimSub, OMatrix, OVector, U1, U3, U6, Vector3};
use serde::{Deserialize, Serialize};

/// Which polynomial the kernels fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum SurfaceModel {
    /// Second-order polynomial, six coefficients.
    Quadratic,
    /// Plane `a3 x + a4 y + a5`.
    Planar,
}

impl SurfaceModel {
    /// Indices of the coefficients this model fits.
    fn active(self) -> &'static [usize] {
        match self {
            SurfaceModel::Quadratic => &[0, 1, 2, 3, 4, 5],
            SurfaceModel::Planar => &[3, 4, 5],
        }
    }
}

/// A fitted polynomial height field over the tangent plane (all lengths in m).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Polynomial {
    /// `[a0, a1, a2, a3, a4, a5]` of `a0 x^2 + a1 y^2 + a2 xy + a3 x + a4 y + a5`.
    pub coefficients: [f64; 6],
}

impl Polynomial {
    /// `f(x, y)`.
    #[inline]
    pub fn height(&self, x: f64, y: f64) -> f64 {
        let a = &self.coefficients;
        a[0] * x * x + a[1] * y * y + a[2] * x * y + a[3] * x + a[4] * y + a[5]
    }

    /// `(df/dx, df/dy)`.
    #[inline]
    pub fn gradient(&self, x: f64, y: f64) -> (f64, f64) {
        let a = &self.coefficients;
        (
            2.0 * a[0] * x + a[2] * y + a[3],
            2.0 * a[1] * y + a[2] * x + a[4],
        )
    }
}

/// Why a kernel's fit was not used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum FitRejection {
    /// Fewer points than the model needs (config `fit_min_points`).
    TooFewPoints,
    /// The normal equations are near singular: points along a line or a single spot.
    IllConditioned,
    /// The weighted RMS of the fit is too large for a smooth surface.
    TooRough,
}

/// Limits a fit must meet.
#[derive(Debug, Clone, Copy)]
pub(crate) struct FitLimits {
    /// Least number of points.
    pub min_points: usize,
    /// Least ratio of smallest to largest eigenvalue of the scaled normal matrix.
    pub min_eigen_ratio: f64,
    /// Largest weighted RMS (m).
    pub max_rms_m: f64,
}

impl FitLimits {
    /// Fewest points a fit of `model` takes: `min_points`, and never fewer than the model's
    /// coefficients.
    pub fn fewest_points(&self, model: SurfaceModel) -> usize {
        self.min_points.max(model.active().len())
    }
}

/// Basis value `i` at scaled coordinates `(u, v)`.
#[inline]
fn basis(i: usize, u: f64, v: f64) -> f64 {
    match i {
        0 => u * u,
        1 => v * v,
        2 => u * v,
        3 => u,
        4 => v,
        _ => 1.0,
    }
}

/// The weighted normal equations of the `D` active basis functions in scaled coordinates
/// `(x, y) / gamma`, checked for conditioning and solved: the scaled coefficients (first `D`
/// entries) and the weight sum.
fn solve_scaled<D>(
    points_tangent: &[Vector3<f64>],
    weights: &[f64],
    gamma_m: f64,
    active: &[usize],
    limits: &FitLimits,
) -> Result<([f64; 6], f64), FitRejection>
where
    D: DimName + DimSub<U1>,
    DefaultAllocator:
        Allocator<D, D> + Allocator<D> + Allocator<D, DimDiff<D, U1>> + Allocator<DimDiff<D, U1>>,
{
    let dim = D::dim();
    debug_assert_eq!(active.len(), dim);
    let mut normal = OMatrix::<f64, D, D>::zeros();
    let mut rhs = OVector::<f64, D>::zeros();
    let mut weight_sum = 0.0;
    let mut phi = [0.0; 6];
    for (s, &w) in points_tangent.iter().zip(weights) {
        let (u, v) = (s.x / gamma_m, s.y / gamma_m);
        for (k, &i) in active.iter().enumerate() {
            phi[k] = basis(i, u, v);
        }
        for r in 0..dim {
            rhs[r] += w * phi[r] * s.z;
            for c in 0..=r {
                normal[(r, c)] += w * phi[r] * phi[c];
            }
        }
        weight_sum += w;
    }
    if weight_sum <= 0.0 || !weight_sum.is_finite() {
        return Err(FitRejection::TooFewPoints);
    }
    for r in 0..dim {
        for c in 0..r {
            normal[(c, r)] = normal[(r, c)];
        }
    }
    let eigen = normal.clone().symmetric_eigenvalues();
    let (min_ev, max_ev) = eigen.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &e| {
        (lo.min(e), hi.max(e))
    });
    if !(max_ev > 0.0 && min_ev / max_ev >= limits.min_eigen_ratio) {
        return Err(FitRejection::IllConditioned);
    }
    let Some(cholesky) = normal.cholesky() else {
        return Err(FitRejection::IllConditioned);
    };
    let solution = cholesky.solve(&rhs);
    let mut scaled = [0.0; 6];
    scaled[..dim].copy_from_slice(solution.as_slice());
    Ok((scaled, weight_sum))
}

/// Fits `model` to tangent-frame points `s_j = M (p_j - p_i)` minimising
/// `sum_j w_j (f(x_j, y_j) - z_j)^2`. Coordinates are scaled by `gamma_m` for conditioning.
/// Returns the polynomial and its weighted RMS (m).
pub(crate) fn fit_polynomial(
    points_tangent: &[Vector3<f64>],
    weights: &[f64],
    gamma_m: f64,
    model: SurfaceModel,
    limits: &FitLimits,
) -> Result<(Polynomial, f64), FitRejection> {
    let active = model.active();
    if points_tangent.len() < limits.fewest_points(model) {
        return Err(FitRejection::TooFewPoints);
    }
    // Fixed-size matrices per model (no heap, unrolled loops): the fit runs once per kernel.
    let (scaled, weight_sum) = match model {
        SurfaceModel::Quadratic => {
            solve_scaled::<U6>(points_tangent, weights, gamma_m, active, limits)?
        }
        SurfaceModel::Planar => {
            solve_scaled::<U3>(points_tangent, weights, gamma_m, active, limits)?
        }
    };
    let mut coefficients = [0.0; 6];
    for (k, &i) in active.iter().enumerate() {
        // Undo the scaling: quadratic terms carry 1/gamma^2, linear ones 1/gamma.
        let power = match i {
            0..=2 => 2,
            3 | 4 => 1,
            _ => 0,
        };
        coefficients[i] = scaled[k] / gamma_m.powi(power);
    }
    let polynomial = Polynomial { coefficients };
    let weighted_sq: f64 = points_tangent
        .iter()
        .zip(weights)
        .map(|(s, &w)| w * (polynomial.height(s.x, s.y) - s.z).powi(2))
        .sum();
    let rms = (weighted_sq / weight_sum).sqrt();
    if !rms.is_finite() || coefficients.iter().any(|c| !c.is_finite()) {
        return Err(FitRejection::IllConditioned);
    }
    if rms > limits.max_rms_m {
        return Err(FitRejection::TooRough);
    }
    Ok((polynomial, rms))
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIMITS: FitLimits = FitLimits {
        min_points: 12,
        min_eigen_ratio: 1e-6,
        max_rms_m: 1.0,
    };

    fn grid(f: impl Fn(f64, f64) -> f64) -> Vec<Vector3<f64>> {
        let mut out = Vec::new();
        for i in -5..=5 {
            for j in -5..=5 {
                let (x, y) = (i as f64 * 0.1, j as f64 * 0.13);
                out.push(Vector3::new(x, y, f(x, y)));
            }
        }
        out
    }

    #[test]
    fn recovers_exact_quadratic() {
        let truth = Polynomial {
            coefficients: [0.7, -0.3, 0.25, 0.1, -0.2, 0.05],
        };
        let pts = grid(|x, y| truth.height(x, y));
        let w: Vec<f64> = pts.iter().map(|s| (-s.norm_squared()).exp()).collect();
        let (fit, rms) = fit_polynomial(&pts, &w, 0.8, SurfaceModel::Quadratic, &LIMITS).unwrap();
        for (a, b) in fit.coefficients.iter().zip(truth.coefficients) {
            assert!((a - b).abs() < 1e-9, "{:?}", fit.coefficients);
        }
        assert!(rms < 1e-9);
    }

    #[test]
    fn planar_recovers_plane_and_zeroes_quadratic_terms() {
        let pts = grid(|x, y| 0.3 * x - 0.1 * y + 0.02);
        let w = vec![1.0; pts.len()];
        let (fit, _) = fit_polynomial(&pts, &w, 0.5, SurfaceModel::Planar, &LIMITS).unwrap();
        let expect = [0.0, 0.0, 0.0, 0.3, -0.1, 0.02];
        for (a, b) in fit.coefficients.iter().zip(expect) {
            assert!((a - b).abs() < 1e-10, "{:?}", fit.coefficients);
        }
    }

    #[test]
    fn rejects_points_on_a_line() {
        let pts: Vec<_> = (0..40)
            .map(|i| Vector3::new(i as f64 * 0.05, 0.0, 0.0))
            .collect();
        let w = vec![1.0; pts.len()];
        let err = fit_polynomial(&pts, &w, 1.0, SurfaceModel::Quadratic, &LIMITS).unwrap_err();
        assert_eq!(err, FitRejection::IllConditioned);
    }

    #[test]
    fn rejects_too_few_points() {
        let pts = grid(|_, _| 0.0)[..5].to_vec();
        let w = vec![1.0; 5];
        let err = fit_polynomial(&pts, &w, 1.0, SurfaceModel::Quadratic, &LIMITS).unwrap_err();
        assert_eq!(err, FitRejection::TooFewPoints);
    }
}
