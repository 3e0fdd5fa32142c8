//! Point-cluster statistics (BALM2 section "point cluster"): for the points one frame
//! contributes to one voxel, their count, mean and scatter in the lidar frame. The voxel's
//! world covariance at any poses follows from these alone, so cost, gradient and Hessian
//! never loop over raw points.

use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use pssba_core::geometry::Pose;
use serde::Serialize;

/// Count, mean and scatter `sum (p - mean)(p - mean)^T` of one frame's points in one voxel,
/// in that frame's lidar frame. Storing the centred scatter (not `sum p p^T`) keeps the world
/// covariance accurate far from the origin.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PointCluster {
    /// Number of points.
    pub count: usize,
    /// Mean point in the lidar frame (m).
    pub mean_lidar: Vector3<f64>,
    /// Centred scatter matrix in the lidar frame (m^2).
    pub scatter_lidar: Matrix3<f64>,
}

impl PointCluster {
    /// Statistics of `points_lidar` (two passes: mean, then centred scatter).
    pub fn from_points<'a>(points_lidar: impl Iterator<Item = &'a Vector3<f64>> + Clone) -> Self {
        let (count, sum) = points_lidar
            .clone()
            .fold((0usize, Vector3::zeros()), |(n, s), p| (n + 1, s + p));
        let mean_lidar = sum / count.max(1) as f64;
        let scatter_lidar = points_lidar.fold(Matrix3::zeros(), |acc, p| {
            let d = p - mean_lidar;
            acc + d * d.transpose()
        });
        Self {
            count,
            mean_lidar,
            scatter_lidar,
        }
    }

    /// The cluster seen in the world at `world_from_lidar`.
    pub fn in_world(&self, world_from_lidar: &Pose) -> WorldCluster {
        let rotation = &world_from_lidar.rotation;
        let lever_world = rotation * self.mean_lidar;
        WorldCluster {
            count: self.count as f64,
            mean_world: lever_world + world_from_lidar.translation,
            lever_world,
            scatter_world: rotation * self.scatter_lidar * rotation.transpose(),
        }
    }
}

/// A [`PointCluster`] moved into the world by its frame's current pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorldCluster {
    /// Number of points, as a float.
    pub count: f64,
    /// Mean point in the world (m).
    pub mean_world: Vector3<f64>,
    /// `R mean_lidar`: from the frame's origin to the mean, in world axes (m). The lever of a
    /// rotation perturbation about the frame's origin.
    pub lever_world: Vector3<f64>,
    /// `R scatter_lidar R^T` (m^2).
    pub scatter_world: Matrix3<f64>,
}

/// Total count, centroid (world, m) and scatter `S = sum_i W_i + n_i (mu_i - c)(mu_i - c)^T`
/// of a voxel's clusters: `S / N` is the covariance of all its points, and `lambda_min(S)`
/// (= N lambda_min(covariance)) is the sum of squared distances to the best-fit plane.
pub fn combined_scatter(clusters: &[WorldCluster]) -> (f64, Vector3<f64>, Matrix3<f64>) {
    let count: f64 = clusters.iter().map(|c| c.count).sum();
    let centroid = clusters
        .iter()
        .fold(Vector3::zeros(), |acc, c| acc + c.mean_world * c.count)
        / count.max(1.0);
    let scatter = clusters.iter().fold(Matrix3::zeros(), |acc, c| {
        let d = c.mean_world - centroid;
        acc + c.scatter_world + d * d.transpose() * c.count
    });
    (count, centroid, scatter)
}

/// Eigenvalues ascending and their unit eigenvectors (columns in the same order) of a
/// symmetric 3x3 matrix.
pub fn sorted_eigen(symmetric: &Matrix3<f64>) -> ([f64; 3], Matrix3<f64>) {
    let eigen = SymmetricEigen::new(*symmetric);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eigen.eigenvalues[a].total_cmp(&eigen.eigenvalues[b]));
    let values = order.map(|k| eigen.eigenvalues[k]);
    let vectors = Matrix3::from_columns(&order.map(|k| eigen.eigenvectors.column(k).into_owned()));
    (values, vectors)
}
