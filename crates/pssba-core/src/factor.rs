//! Factor blocks: what the smoothing step hands to the pose adjustment (DESIGN steps 6-7).
//! A block is self-contained, so it can also travel between processes.

use crate::kernels::fit::Polynomial;
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

/// One smoothing kernel's surface, attached to the frame of its kernel point, so residuals
/// depend on relative poses only (gauge invariant).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Surface {
    /// Frame `a` the kernel point belongs to.
    pub frame: usize,
    /// Kernel point `p_i` in the lidar frame of `a` (m).
    pub kernel_in_lidar: Vector3<f64>,
    /// `M_a = M R_a`: maps lidar-frame offsets of frame `a` into the tangent frame.
    pub tangent_from_lidar: Matrix3<f64>,
    /// The fitted height field over the tangent plane.
    pub polynomial: Polynomial,
    /// Kernel width gamma (m) the surface was fitted at.
    pub gamma_m: f64,
}

/// One residual: point `j` of frame `b` against surface `i` (frame `a != b`).
///
/// Stored in single precision, 24 bytes instead of 40: a 1000-frame window holds 17-22 M
/// residuals at its finest scale (two copies while a block is ordered), and a lidar-frame
/// point within 1 km is kept to 61 um or better (sensors give f32 points anyway); every sum
/// is taken in f64.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FactorPoint {
    /// Index into [`FactorBlock::surfaces`].
    pub surface: u32,
    /// Frame `b` of the point.
    pub frame: u32,
    /// The point in the lidar frame of `b` (m).
    pub point_in_lidar: Vector3<f32>,
    /// Gaussian radial weight `exp(-|s|^2 / gamma^2)`, fixed during the scale.
    pub weight: f32,
}

impl FactorPoint {
    /// A residual point, rounded to single precision.
    pub fn new(surface: u32, frame: u32, point_in_lidar: Vector3<f64>, weight: f64) -> Self {
        Self {
            surface,
            frame,
            point_in_lidar: point_in_lidar.cast(),
            weight: weight as f32,
        }
    }

    /// [`Self::point_in_lidar`] in double precision (m).
    #[inline]
    pub fn point_in_lidar_m(&self) -> Vector3<f64> {
        self.point_in_lidar.cast()
    }

    /// [`Self::weight`] in double precision.
    #[inline]
    pub fn weight_f64(&self) -> f64 {
        f64::from(self.weight)
    }
}

/// Why kernels were not used at one scale.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct KernelRejections {
    /// The kernel point had no PCA normal.
    pub no_normal: usize,
    /// Too few neighbours for a fit (or, with several frame groups, no frame with enough of
    /// its own points to anchor the surface).
    pub too_few_points: usize,
    /// Neighbours along a line or a single spot.
    pub ill_conditioned: usize,
    /// Fit residual too large.
    pub too_rough: usize,
    /// Fitted, but no neighbour from another frame: no pose information.
    pub single_frame: usize,
}

impl KernelRejections {
    /// All rejected kernels.
    pub fn total(&self) -> usize {
        self.no_normal
            + self.too_few_points
            + self.ill_conditioned
            + self.too_rough
            + self.single_frame
    }
}

/// The constraints of one scale: surfaces and the residual points tied to them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct FactorBlock {
    /// Kernel width gamma (m).
    pub gamma_m: f64,
    /// Cauchy loss scale for these residuals (m).
    pub robust_scale_m: f64,
    /// Accepted kernels' surfaces.
    pub surfaces: Vec<Surface>,
    /// Residual points, grouped by surface.
    pub points: Vec<FactorPoint>,
    /// Kernels sampled but not used, by reason.
    pub rejected: KernelRejections,
}
